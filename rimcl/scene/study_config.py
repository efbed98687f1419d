"""The configuration of a study (``rimcl study``): a scene parsed once, at the entry.

:meth:`StudyConfig.from_scene` turns a checked scene (:func:`rimcl.scene.load.load_scene`)
into frozen objects: the field file, the cases with their thresholds, the measurement they
share (:class:`rimcl.scene.config.MeasureConfig`; :meth:`StudyConfig.measure` gives each
case's), how the study runs, the Δt sweep, the PIV section and the LPT sections
(:class:`rimcl.scene.lpt_config.LptConfig`). Every stage after the entry (case files, Dask
tasks, PIV, LPT, statistics, summary) takes these objects; none reads the
scene's dict. The scene itself travels only as one JSON text made at the entry
(:attr:`StudyConfig.scene_json`): the record written to ``scene.toml`` and ``stats.json``
and stamped into case files, never read for a setting.
"""

import dataclasses
import json

from rimcl.scene.config import MeasureConfig
from rimcl.scene.load import scene_text
from rimcl.scene.lpt_config import LptConfig, lpt_config


@dataclasses.dataclass(frozen=True)
class StudyCase:
    """One refractive-index case of a study: its name and grey threshold (counts)."""

    name: str
    threshold: float


@dataclasses.dataclass(frozen=True)
class StudyRunConfig:
    """How a study runs, beside :class:`rimcl.scene.config.RunConfig` (never changes a number).

    Attributes
    ----------
    mode : {"ptv", "piv", "both", "lpt"}
    scheduler : str
        Dask scheduler (``"local:N"`` or an address); "" = this process.
    shard_tracers : int
        Tracers per Dask task.
    numerics : bool
        Run the Appendix A check (:mod:`rimcl.ptv.numerics`).
    sensitivity : bool
        Measure every case again under the settings a user could choose differently
        (:mod:`rimcl.study.sensitivity`).
    """

    mode: str = "ptv"
    scheduler: str = ""
    shard_tracers: int = 100
    numerics: bool = True
    sensitivity: bool = False


@dataclasses.dataclass(frozen=True)
class PivStudyConfig:
    """The scene's ``[piv]`` section (:func:`rimcl.piv.study.configs_from_study`).

    Attributes
    ----------
    pixels : int
        Pixels across the field of view of the PIV frames (a lens camera: its sensor).
    density : float
        Particle image density: tracers per pixel inside the sheet's 1/e² thickness.
    diameter : float
        Particle image diameter ``4 σ`` (pixels).
    sheet_thickness : float, optional
        Light-sheet thickness between its 1/e² points (length units); None: 8 pixels.
    bit_depth : int
    rays : int
        Rays per tracer (a plane camera: a fan of ``round(√rays)`` per side).
    dt : float
        Time between exposures A and B (time units).
    window : int
        Interrogation window of the last pass (pixels, even).
    overlap : float
        Overlap of neighbouring windows (fraction).
    passes : int
        Correlation passes (2 and more deform the windows).
    """

    pixels: int = 512
    density: float = 0.03
    diameter: float = 3.0
    sheet_thickness: float = None
    bit_depth: int = 16
    rays: int = 64
    dt: float = 0.1
    window: int = 32
    overlap: float = 0.5
    passes: int = 3


@dataclasses.dataclass(frozen=True)
class StudyConfig:
    """Everything a study needs, parsed once from its scene (small and picklable).

    Attributes
    ----------
    field_path : str
        The field file; "" = the shipped sample.
    cases : tuple of StudyCase
        The scene's cases (``cases.names``) with their thresholds (``cases.thresholds``,
        else ``renderer.threshold``).
    shared : rimcl.scene.config.MeasureConfig
        The measurement every case shares, at ``renderer.threshold``.
    run : StudyRunConfig
    dt_multiples : tuple of int
        ``time.dt_multiples`` (the Δt sweep, :mod:`rimcl.ptv.sweep`).
    piv : PivStudyConfig
    lpt : rimcl.scene.lpt_config.LptConfig
        ``[rig]``, ``[illumination]`` and ``[lpt]`` (``run.mode = "lpt"``).
    scene_json : str
        The checked scene as JSON text: the record of what was asked (``scene.toml``,
        ``stats.json``, the stamps of case files).
    """

    field_path: str
    cases: tuple
    shared: MeasureConfig
    run: StudyRunConfig
    dt_multiples: tuple
    piv: PivStudyConfig
    lpt: LptConfig
    scene_json: str

    @classmethod
    def from_scene(cls, scene, where="the scene"):
        """The study of a checked scene (:func:`rimcl.scene.load.load_scene`); ``where``
        is named in the errors of the checks that span keys (the LPT sections')."""
        thresholds, default = scene["cases"]["thresholds"], scene["renderer"]["threshold"]
        run = scene["run"]
        return cls(
            field_path=scene["field"]["path"],
            cases=tuple(
                StudyCase(name, thresholds.get(name, default)) for name in scene["cases"]["names"]
            ),
            shared=MeasureConfig.from_scene(scene, None),
            run=StudyRunConfig(
                mode=run["mode"],
                scheduler=run["scheduler"],
                shard_tracers=run["shard_tracers"],
                numerics=run["numerics"],
                sensitivity=run["sensitivity"],
            ),
            dt_multiples=dt_multiples(scene["time"]),
            piv=PivStudyConfig(**scene["piv"]),
            lpt=lpt_config(scene, where),
            scene_json=json.dumps(scene),
        )

    @property
    def names(self):
        """The case names, in the scene's order."""
        return [case.name for case in self.cases]

    def threshold(self, name):
        """The grey threshold of case ``name`` (counts; another name: ``renderer.threshold``)."""
        return next(
            (case.threshold for case in self.cases if case.name == name),
            self.shared.renderer.threshold,
        )

    def measure(self, name):
        """The :class:`rimcl.scene.config.MeasureConfig` of case ``name``."""
        renderer = dataclasses.replace(self.shared.renderer, threshold=self.threshold(name))
        return dataclasses.replace(self.shared, renderer=renderer)

    def scene_record(self):
        """The scene as a dict (a fresh copy), for records only."""
        return json.loads(self.scene_json)

    @property
    def text(self):
        """The scene as TOML (:func:`rimcl.scene.load.scene_text`), for ``scene.toml``."""
        return scene_text(self.scene_record())


def dt_multiples(time):
    """The Δt sweep's multiples of a scene's ``[time]``: those listed, or every ``m`` from 1
    to ``time.frames - 1`` (the default)."""
    listed = time["dt_multiples"]
    return tuple(range(1, int(time["frames"]))) if listed is None else tuple(listed)
