"""The LPT scene: ``[rig]`` (cameras), ``[illumination]`` (the seeded slab) and ``[lpt]``.

An LPT scene is a TOML file with these three sections plus the study's ``[field]``,
``[cases]``, ``[tracers]``, ``[time]``, ``[integrator]``, ``[run]``, ``[fluid]``, ``[sensor]``
and ``[mie]``, checked by :func:`rimcl.scene.validate.validate_scene` against the scene keys
(:mod:`rimcl.scene.keys_lpt` holds the LPT ones) and parsed once into a
:class:`rimcl.scene.study_config.StudyConfig` (the LPT sections:
:class:`rimcl.scene.lpt_config.LptConfig`). Every key is optional; unknown keys are refused
with the closest valid name, and so are keys set away from their defaults that LPT does not
use (:mod:`rimcl.scene.usage`: ``field.box``, ``[camera]``, ...). Cameras are
``[[rig.cameras]]`` tables, or a preset (``rig.preset``) builds them from the field's size:

- ``lpt-challenge``: four cameras at -30°, -10°, +10° and +30° from ``x1`` in the
  ``x1``–``x2`` plane (the first LPT challenge): 1920 x 1200 pixels of 10 µm,
  f = 100 mm at f/16, placed so that the field's ``x2`` width fills 96 % of the sensor
  width (a 100 mm wide field puts them ~640 mm from the volume, the challenge's ~600 mm),
  behind a 10 mm glass window.
- ``stereo``: the two cameras at ±30° of the same rig.

Positions and look-at points are in mm in the field's frame (``x1, x2, x3`` from the
field's origin, ``length_m`` metres per field unit); the cameras sit beyond the window,
``x1 > x_end + t``.
"""

import dataclasses
import math
from pathlib import Path

import numpy as np

from rimcl.scene.load import read_scene_file
from rimcl.scene.lpt_config import CameraSpec, IlluminationConfig, LptSettings, RigConfig
from rimcl.scene.study_config import StudyConfig

__all__ = [
    "CameraSpec",
    "IlluminationConfig",
    "LptScene",
    "LptSettings",
    "RigConfig",
    "describe",
    "load_lpt_scene",
    "parse_lpt_scene",
    "preset_cameras",
]

#: Cases an LPT scene runs when ``cases.names`` is not given.
DEFAULT_CASES = ("C1", "C2", "C3")
#: The first LPT challenge's camera angles (degrees from x1, towards +x2).
CHALLENGE_ANGLES = (-30.0, -10.0, 10.0, 30.0)
STEREO_ANGLES = (-30.0, 30.0)


@dataclasses.dataclass(frozen=True)
class LptScene:
    """A checked LPT scene, parsed once (:class:`~rimcl.scene.study_config.StudyConfig`):
    its LPT sections and the study's, typed; the scene's record only for the files."""

    study: StudyConfig

    @property
    def rig(self):
        """:class:`~rimcl.scene.lpt_config.RigConfig`"""
        return self.study.lpt.rig

    @property
    def illumination(self):
        """:class:`~rimcl.scene.lpt_config.IlluminationConfig`"""
        return self.study.lpt.illumination

    @property
    def lpt(self):
        """:class:`~rimcl.scene.lpt_config.LptSettings`"""
        return self.study.lpt.settings

    @property
    def measure(self):
        """The study's shared sections (:class:`rimcl.scene.config.MeasureConfig`)."""
        return self.study.shared


def parse_lpt_scene(raw, where="the scene", given=None):
    """Check an LPT scene mapping (as read from TOML) and fill in the defaults.

    Keys set away from their defaults that LPT does not use (the planar measurement's:
    ``[camera]``, ``[renderer]``, ``[piv]``, ``field.box``, ``tracers.margin``, ...) are
    refused (:func:`rimcl.scene.usage.check_use`).

    Parameters
    ----------
    raw : dict
        ``{section: {key: value}}``.
    where : str
        Named in error messages.
    given : dict of str to str, optional
        Where each key of ``raw`` was set (``{"tracers.count": "the options"}``); the
        keys not named were set in ``where``.

    Returns
    -------
    LptScene
    """
    from rimcl.scene.load import field_scales
    from rimcl.scene.usage import check_use
    from rimcl.scene.validate import validate_scene

    cases_given = "names" in raw.get("cases", {})
    scene = validate_scene(dict(raw), where)
    sources = {
        f"{section}.{name}": where
        for section, table in raw.items()
        if isinstance(table, dict)
        for name in table
    }
    check_use(scene, {**sources, **(given or {})}, "lpt")
    # field.time_s from field.velocity_m_s or the field file, as for a study
    scene = field_scales(scene, where)
    if not cases_given:
        scene["cases"]["names"] = list(DEFAULT_CASES)
    return LptScene(StudyConfig.from_scene(scene, where))


def load_lpt_scene(path=None, overrides=None):
    """Read and check an LPT scene file (the defaults when ``path`` is None).

    ``overrides``: ``{"section.key": value}`` on top (command-line options; None values
    are ignored); a relative ``field.path`` of the file is relative to the file.
    """
    raw, where = {}, "the default LPT scene"
    if path is not None:
        path = Path(path)
        where = str(path)
        raw = read_scene_file(path)
        field = raw.get("field")
        if isinstance(field, dict) and isinstance(field.get("path"), str) and field["path"]:
            # a scene names its field relative to itself, as rimcl study reads it
            if not Path(field["path"]).is_absolute():
                field["path"] = str((path.parent / field["path"]).resolve())
    given = {}
    for dotted, value in (overrides or {}).items():
        if value is None:
            continue
        section, name = dotted.split(".", 1)
        table = raw.setdefault(section, {})
        if isinstance(table, dict):
            table[name] = value
            given[dotted] = "the options"
    return parse_lpt_scene(raw, where, given)


def preset_cameras(preset, *, look_at, x_end, width, length_m, fluid_index, rig):
    """The cameras of a preset, placed for a field of the given size.

    Each camera's axis makes the preset's angle with ``x1`` in the ``x1``–``x2`` plane
    (outside the window); it is placed along its chief ray through ``look_at`` so that
    its apparent distance is ``s_o = f (1 + 1/M)``, with ``M`` chosen so that the field's
    ``x2`` width fills 96 % of the sensor's width.

    Parameters
    ----------
    preset : {"lpt-challenge", "stereo"}
    look_at : sequence of 3 float
        Volume centre (field units).
    x_end : float
        The exit face (field units).
    width : float
        The field's ``x2`` width (field units).
    length_m : float
    fluid_index : float
        The calibration fluid's index.
    rig : RigConfig

    Returns
    -------
    tuple of CameraSpec
    """
    angles = {"lpt-challenge": CHALLENGE_ANGLES, "stereo": STEREO_ANGLES}[preset]
    spec = CameraSpec(position_mm=(0.0, 0.0, 0.0), look_at_mm=(0.0, 0.0, 0.0))
    width_mm = width * length_m * 1e3
    magnification = 0.96 * spec.sensor_pixels[0] * spec.pixel_pitch_um * 1e-3 / width_mm
    apparent = spec.focal_length_mm * (1.0 + 1.0 / magnification) * 1e-3 / length_m
    look_at = np.asarray(look_at, dtype=np.float64)
    thickness = 1e-3 * rig.window_thickness_mm / length_m
    n_out = rig.outside_index
    look_mm = tuple(float(v) for v in look_at * length_m * 1e3)
    cameras = []
    for index, angle in enumerate(angles):
        sine = math.sin(math.radians(angle))
        layers = []  # (x1 depth, sine in the layer, index)
        for depth, index_layer in (
            (x_end - look_at[0], fluid_index),
            (thickness, rig.window_index),
        ):
            layers.append((depth, n_out * sine / index_layer, index_layer))
        point = look_at.copy()
        used = 0.0
        for depth, s, n in layers:
            cosine = math.sqrt(1.0 - s * s)
            point += depth * np.array([1.0, s / cosine, 0.0])
            used += depth / cosine * n_out / n
        outside = np.array([math.cos(math.radians(angle)), sine, 0.0])
        position = point + (apparent - used) * outside
        cameras.append(
            dataclasses.replace(
                spec,
                name=f"cam{index + 1}",
                position_mm=tuple(float(v) for v in position * length_m * 1e3),
                look_at_mm=look_mm,
            )
        )
    return tuple(cameras)


def describe(scene):
    """The LPT sections as a JSON-able dict."""
    return {
        "rig": dataclasses.asdict(scene.rig),
        "illumination": dataclasses.asdict(scene.illumination),
        "lpt": dataclasses.asdict(scene.lpt),
    }


def check_run_memory(scene, tracers, frames):
    """Refuse, before any track or image is made, an LPT run of ``tracers`` over ``frames``
    that cannot fit in memory (:func:`rimcl.core.memory.check_lpt_memory`); a preset rig
    counts as four cameras of the default sensor."""
    from rimcl.core.memory import check_lpt_memory

    specs = scene.rig.cameras or [CameraSpec((0, 0, 0), (0, 0, 0))] * 4
    pixels = max(int(spec.sensor_pixels[0]) * int(spec.sensor_pixels[1]) for spec in specs)
    check_lpt_memory(tracers, frames, len(specs), pixels)
