"""The LPT sections of a scene, parsed once: ``[rig]``, ``[illumination]`` and ``[lpt]``.

:func:`lpt_config` turns the three sections of a checked scene
(:func:`rimcl.scene.validate.validate_scene`, which checked every key against
:mod:`rimcl.scene.keys_lpt`) into frozen objects, checking what one key cannot: the
``[[rig.cameras]]`` tables (their keys: :func:`rimcl.scene.keys_lpt.camera_keys`), the
lengths of pairs and triples, and the combinations. The defaults of every dataclass here
are the scene keys' (:mod:`rimcl.scene.keys_lpt`, the one table of names, defaults and
limits).
"""

import dataclasses
import math

import numpy as np

from rimcl.core.errors import RimclError
from rimcl.core.outputs import check_file_name
from rimcl.scene.keys import KEYS_BY_NAME
from rimcl.scene.keys_lpt import CAMERA_SECTION, DEFAULT_PRESET, camera_keys
from rimcl.scene.validate import check_value, suggest

#: The ``[[rig.cameras]]`` keys by name.
CAMERA_KEYS = {key.name: key for key in camera_keys()}
#: The rig presets (``rig.preset``'s choices but "", which asks for the camera tables).
PRESETS = tuple(choice for choice in KEYS_BY_NAME["rig.preset"].choices if choice)


def _tuple(value):
    return tuple(value) if isinstance(value, list) else value


def _default(section, name):
    """The scene key's default, lists as tuples (frozen dataclasses)."""
    key = CAMERA_KEYS[name] if section == CAMERA_SECTION else KEYS_BY_NAME[f"{section}.{name}"]
    return _tuple(key.default)


@dataclasses.dataclass(frozen=True)
class CameraSpec:
    """One ``[[rig.cameras]]`` table (mm, µm; positions in the field's frame)."""

    position_mm: tuple
    look_at_mm: tuple
    focal_length_mm: float = _default(CAMERA_SECTION, "focal_length_mm")
    f_number: float = _default(CAMERA_SECTION, "f_number")
    pixel_pitch_um: float = _default(CAMERA_SECTION, "pixel_pitch_um")
    sensor_pixels: tuple = _default(CAMERA_SECTION, "sensor_pixels")
    scheimpflug_deg: float = _default(CAMERA_SECTION, "scheimpflug_deg")
    name: str = _default(CAMERA_SECTION, "name")


@dataclasses.dataclass(frozen=True)
class RigConfig:
    """``[rig]``: the cameras (or a preset) and the window they share.

    ``preset`` is "" when ``cameras`` holds the ``[[rig.cameras]]`` tables.
    """

    preset: str = DEFAULT_PRESET
    cameras: tuple = ()
    window_thickness_mm: float = _default("rig", "window_thickness_mm")
    window_index: float = _default("rig", "window_index")
    outside_index: float = _default("rig", "outside_index")
    wavelength_nm: float = _default("rig", "wavelength_nm")
    particle_diameter_um: float = _default("rig", "particle_diameter_um")


@dataclasses.dataclass(frozen=True)
class IlluminationConfig:
    """``[illumination]``: the seeded volume (field length units).

    ``thickness`` along ``x1`` (None: 0.3 of the field's ``x2`` width, the challenge's
    30 mm over 100 mm), centred on ``centre`` (None: the field's middle ``x1``);
    ``extent``: the fractions of the field's ``x2`` and ``x3`` widths seeded, centred;
    ``ppp``: tracers per pixel of the first camera (None: ``tracers.count``).
    """

    thickness: float = _default("illumination", "thickness")
    centre: float = _default("illumination", "centre")
    extent: tuple = _default("illumination", "extent")
    ppp: float = _default("illumination", "ppp")


@dataclasses.dataclass(frozen=True)
class LptSettings:
    """``[lpt]``: rays, calibration, triangulation, images and the ray-tracing engine."""

    ray_tolerance_px: float = _default("lpt", "ray_tolerance_px")
    max_rays: int = _default("lpt", "max_rays")
    calibration_planes: int = _default("lpt", "calibration_planes")
    calibration_grid: tuple = _default("lpt", "calibration_grid")
    model: str = _default("lpt", "model")
    engine: str = _default("lpt", "engine")
    match_tolerances_px: tuple = _default("lpt", "match_tolerances_px")
    images: bool = _default("lpt", "images")
    bit_depth: int = _default("lpt", "bit_depth")
    exposure: float = _default("lpt", "exposure")
    threshold: float = _default("lpt", "threshold")
    self_calibration: bool = _default("lpt", "self_calibration")
    self_calibration_cells: tuple = _default("lpt", "self_calibration_cells")
    self_calibration_iterations: int = _default("lpt", "self_calibration_iterations")


@dataclasses.dataclass(frozen=True)
class LptConfig:
    """The LPT sections of a scene.

    Attributes
    ----------
    rig : RigConfig
    illumination : IlluminationConfig
    settings : LptSettings
    length_m : float, optional
        ``field.length_m``: metres per field length unit (None: the field's ``x2`` width is
        100 mm, the LPT challenge's).
    time_s : float, optional
        ``field.time_s``: seconds per field time unit (None: outputs in field time units).
    """

    rig: RigConfig = RigConfig()
    illumination: IlluminationConfig = IlluminationConfig()
    settings: LptSettings = LptSettings()
    length_m: float = None
    time_s: float = None


def _length(values, count, name, where, what):
    if len(values) != count:
        raise RimclError(f"{name} in {where} must be {what}, got {list(values)!r}")
    return tuple(values)


def _cameras(tables, where):
    cameras = []
    for index, table in enumerate(tables):
        section = f"{CAMERA_SECTION}[{index}]"
        values = {}
        for name, value in table.items():
            key = CAMERA_KEYS.get(name)
            if key is None:
                raise RimclError(
                    f"unknown key {section}.{name} in {where}" + suggest(name, list(CAMERA_KEYS))
                )
            key = dataclasses.replace(key, section=section)  # named with its table's index
            values[name] = _tuple(check_value(key, value, where))
        for needed in ("position_mm", "look_at_mm"):
            if needed not in values:
                raise RimclError(f"{section} in {where} needs {needed}")
        if "sensor_pixels" in values:
            _length(values["sensor_pixels"], 2, f"{section}.sensor_pixels", where, "two numbers")
        values["name"] = values.get("name") or f"cam{index + 1}"
        # the dataset's files are named after the camera: one plain file name
        check_file_name(values["name"], f"{section}.name in {where}:")
        cameras.append(CameraSpec(**values))
    names = [c.name for c in cameras]
    if len(set(names)) != len(names):
        raise RimclError(f"rig.cameras in {where}: camera names must differ, got {names}")
    return tuple(cameras)


#: Smallest angle (degrees) between two cameras' positions seen from the volume: below it
#: their lines of sight cross so flatly that the depth of a tracer is not defined (the
#: depth error grows as 1 / sin of the angle; the presets' pairs are 20° to 60° apart).
MIN_BASELINE_DEG = 5.0


def baseline_angles(cameras):
    """The angle (degrees) between each pair of cameras, seen from the middle of their
    look-at points: ``{(name_a, name_b): angle}``."""
    centre = np.mean([c.look_at_mm for c in cameras], axis=0)
    rays = [np.asarray(c.position_mm, dtype=np.float64) - centre for c in cameras]
    angles = {}
    for i, a in enumerate(cameras):
        for j in range(i + 1, len(cameras)):
            norms = np.linalg.norm(rays[i]) * np.linalg.norm(rays[j])
            cosine = np.dot(rays[i], rays[j]) / norms if norms > 0 else 1.0
            angles[a.name, cameras[j].name] = math.degrees(math.acos(min(max(cosine, -1), 1)))
    return angles


def check_rig_geometry(cameras, where):
    """Refuse, before any work, ``[[rig.cameras]]`` tables that cannot triangulate: one
    camera, or cameras whose widest pair is under :data:`MIN_BASELINE_DEG` apart."""
    if not cameras:
        return  # a preset: its geometry is fixed
    if len(cameras) < 2:
        raise RimclError(
            f"rig.cameras in {where}: LPT triangulates from two cameras at least, got one "
            f"({cameras[0].name}); add a [[rig.cameras]] table (or use a preset, "
            'rig.preset = "stereo", instead of tables)'
        )
    for camera in cameras:
        if np.allclose(camera.position_mm, camera.look_at_mm):
            raise RimclError(
                f"rig.cameras in {where}: camera {camera.name} looks at its own position"
            )
    angles = baseline_angles(cameras)
    pair, widest = max(angles.items(), key=lambda item: item[1])
    if widest < MIN_BASELINE_DEG:
        raise RimclError(
            f"rig.cameras in {where}: the cameras are {widest:.3g}° apart at most "
            f"({pair[0]}–{pair[1]}, seen from their look-at point); LPT needs a baseline "
            f"angle of {MIN_BASELINE_DEG:g}° at least to find depth: move them apart"
        )


def lpt_config(scene, where="the scene"):
    """The LPT sections of a checked scene (every key present, ``None`` where the
    pipeline decides), checked together.

    Parameters
    ----------
    scene : dict
        From :func:`rimcl.scene.validate.validate_scene`.
    where : str
        Named in error messages.

    Returns
    -------
    LptConfig
    """
    rig = dict(scene["rig"])
    cameras = _cameras(rig.pop("cameras") or [], where)
    if cameras and rig["preset"]:
        raise RimclError(f"{where}: give rig.preset or [[rig.cameras]], not both")
    if rig["preset"] == "" and not cameras:
        raise RimclError(f'{where}: rig.preset = "" needs [[rig.cameras]] tables')
    check_rig_geometry(cameras, where)
    rig["preset"] = "" if cameras else rig["preset"] or DEFAULT_PRESET
    illumination = dict(scene["illumination"])
    extent = _length(illumination["extent"], 2, "illumination.extent", where, "two fractions")
    if not all(0 < v <= 1 for v in extent):
        raise RimclError(f"illumination.extent in {where} must be two fractions in (0, 1]")
    illumination["extent"] = extent
    lpt = {name: _tuple(value) for name, value in scene["lpt"].items()}
    _length(lpt["calibration_grid"], 2, "lpt.calibration_grid", where, "two whole numbers")
    _length(
        lpt["self_calibration_cells"],
        3,
        "lpt.self_calibration_cells",
        where,
        "three whole numbers (x1, x2, x3)",
    )
    if not all(v > 0 for v in lpt["match_tolerances_px"]):
        raise RimclError(f"lpt.match_tolerances_px in {where} must be positive numbers")
    settings = LptSettings(**lpt)
    if settings.bit_depth > 16:
        raise RimclError(f"lpt.bit_depth in {where} must be 8 to 16, got {settings.bit_depth}")
    for name in ("exposure", "threshold"):
        if not getattr(settings, name) < 1:
            raise RimclError(f"lpt.{name} in {where} must be a fraction below 1")
    if settings.self_calibration and settings.model != "soloff":
        raise RimclError(
            f"{where}: lpt.self_calibration corrects Soloff models; set lpt.model = "
            '"soloff" or lpt.self_calibration = false'
        )
    if min(settings.calibration_grid) < 4:
        raise RimclError(f"lpt.calibration_grid in {where}: at least 4 x 4 points per plane")
    return LptConfig(
        RigConfig(cameras=cameras, **rig),
        IlluminationConfig(**illumination),
        settings,
        scene["field"]["length_m"],
        scene["field"].get("time_s"),
    )
