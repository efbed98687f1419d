"""The LPT scene: ``[rig]`` (cameras), ``[illumination]`` (the seeded slab) and ``[lpt]``.

An LPT scene is a TOML file with these three sections plus the study's ``[field]``,
``[cases]``, ``[tracers]``, ``[time]``, ``[integrator]``, ``[run]``, ``[fluid]``, ``[sensor]``
and ``[mie]``
(checked by :func:`rimcl.scene.load.validate_scene`). Every key is optional; unknown keys
are refused with the closest valid name. Cameras are ``[[rig.cameras]]`` tables, or a
preset (``rig.preset``) builds them from the field's size:

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
import difflib
import math
import sys
from pathlib import Path

import numpy as np

from rimcl.core.errors import RimclError

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover - Python 3.10
    import tomli as tomllib

PRESETS = ("lpt-challenge", "stereo")
MODELS = ("soloff", "pinhole")
ENGINES = ("device", "numpy")
#: Sections of the study's scene that an LPT scene uses (checked by the study's loader).
STUDY_SECTIONS = (
    "field",
    "cases",
    "tracers",
    "time",
    "integrator",
    "run",
    "fluid",
    "sensor",
    "mie",
)
#: Cases an LPT scene runs when ``cases.names`` is not given.
DEFAULT_CASES = ("C1", "C2", "C3")
#: The first LPT challenge's camera angles (degrees from x1, towards +x2).
CHALLENGE_ANGLES = (-30.0, -10.0, 10.0, 30.0)
STEREO_ANGLES = (-30.0, 30.0)


@dataclasses.dataclass(frozen=True)
class CameraSpec:
    """One ``[[rig.cameras]]`` table (mm, µm; positions in the field's frame)."""

    position_mm: tuple
    look_at_mm: tuple
    focal_length_mm: float = 100.0
    f_number: float = 16.0
    pixel_pitch_um: float = 10.0
    sensor_pixels: tuple = (1920, 1200)
    scheimpflug_deg: float = 0.0
    name: str = ""


@dataclasses.dataclass(frozen=True)
class RigConfig:
    """``[rig]``: the cameras (or a preset) and the window they share."""

    preset: str = "lpt-challenge"
    cameras: tuple = ()
    window_thickness_mm: float = 10.0
    window_index: float = 1.52
    outside_index: float = 1.0
    wavelength_nm: float = 532.0
    particle_diameter_um: float = 10.0


@dataclasses.dataclass(frozen=True)
class IlluminationConfig:
    """``[illumination]``: the seeded volume (field length units).

    ``thickness`` along ``x1`` (None: 0.3 of the field's ``x2`` width, the challenge's
    30 mm over 100 mm), centred on ``centre`` (None: the field's middle ``x1``);
    ``extent``: the fractions of the field's ``x2`` and ``x3`` widths seeded, centred;
    ``ppp``: tracers per pixel of the first camera (None: ``tracers.count``).
    """

    thickness: float = None
    centre: float = None
    extent: tuple = (0.8, 0.5)
    ppp: float = None


@dataclasses.dataclass(frozen=True)
class LptSettings:
    """``[lpt]``: rays, calibration, triangulation and the engine."""

    ray_tolerance_px: float = 0.01
    max_rays: int = 128
    calibration_planes: int = 5
    calibration_grid: tuple = (13, 9)
    model: str = "soloff"
    engine: str = "device"
    match_tolerances_px: tuple = (0.5, 1.0, 2.0)
    images: bool = True
    bit_depth: int = 16
    exposure: float = 0.5
    threshold: float = 0.05
    self_calibration: bool = True
    self_calibration_cells: tuple = (3, 5, 5)
    self_calibration_iterations: int = 3


@dataclasses.dataclass(frozen=True)
class LptScene:
    """A checked LPT scene: the three LPT sections and the study's scene mapping."""

    rig: RigConfig
    illumination: IlluminationConfig
    lpt: LptSettings
    study: dict


# key tables: name -> (kind, check); kinds: float, pfloat (> 0), int, str, bool, vec3, pair
_CAMERA_KEYS = {
    "name": "str",
    "position_mm": "vec3",
    "look_at_mm": "vec3",
    "focal_length_mm": "pfloat",
    "f_number": "pfloat",
    "pixel_pitch_um": "pfloat",
    "sensor_pixels": "pair_int",
    "scheimpflug_deg": "float",
}
_RIG_KEYS = {
    "preset": "str",
    "cameras": "cameras",
    "window_thickness_mm": "nnfloat",
    "window_index": "pfloat",
    "outside_index": "pfloat",
    "wavelength_nm": "pfloat",
    "particle_diameter_um": "nnfloat",
}
_ILLUMINATION_KEYS = {
    "thickness": "pfloat",
    "centre": "float",
    "extent": "pair_fraction",
    "ppp": "pfloat",
}
_LPT_KEYS = {
    "ray_tolerance_px": "pfloat",
    "max_rays": "int",
    "calibration_planes": "int",
    "calibration_grid": "pair_int",
    "model": "str",
    "engine": "str",
    "match_tolerances_px": "pfloats",
    "images": "bool",
    "bit_depth": "int",
    "exposure": "pfloat",
    "threshold": "pfloat",
    "self_calibration": "bool",
    "self_calibration_cells": "triple_int",
    "self_calibration_iterations": "int",
}
_CHOICES = {"rig.preset": ("", *PRESETS), "lpt.model": MODELS, "lpt.engine": ENGINES}


def _suggest(word, candidates):
    close = difflib.get_close_matches(str(word), list(candidates), n=1, cutoff=0.5)
    return f"; did you mean {close[0]!r}?" if close else ""


def _number(value, name):
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise RimclError(f"{name} must be a finite number, got {value!r}")
    return float(value)


def _value(kind, value, name):
    """``value`` converted to ``kind``; one clear error naming the key otherwise."""
    if kind == "str":
        if not isinstance(value, str):
            raise RimclError(f"{name} must be a string, got {value!r}")
        choices = _CHOICES.get(name)
        if choices and value not in choices:
            shown = ", ".join(repr(c) for c in choices)
            raise RimclError(
                f"{name} must be one of {shown}, got {value!r}{_suggest(value, choices)}"
            )
        return value
    if kind == "bool":
        if not isinstance(value, bool):
            raise RimclError(f"{name} must be true or false, got {value!r}")
        return value
    if kind == "int":
        if isinstance(value, bool) or not isinstance(value, int) or value < 1:
            raise RimclError(f"{name} must be a whole number >= 1, got {value!r}")
        return int(value)
    if kind in ("float", "pfloat", "nnfloat"):
        number = _number(value, name)
        if kind == "pfloat" and not number > 0:
            raise RimclError(f"{name} must be positive, got {value!r}")
        if kind == "nnfloat" and not number >= 0:
            raise RimclError(f"{name} must be >= 0, got {value!r}")
        return number
    if kind == "vec3":
        if not isinstance(value, list) or len(value) != 3:
            raise RimclError(f"{name} must be three numbers [x1, x2, x3] (mm), got {value!r}")
        return tuple(_number(v, name) for v in value)
    if kind == "pair_int":
        if not isinstance(value, list) or len(value) != 2:
            raise RimclError(f"{name} must be two whole numbers, got {value!r}")
        return tuple(_value("int", v, name) for v in value)
    if kind == "triple_int":
        if not isinstance(value, list) or len(value) != 3:
            raise RimclError(f"{name} must be three whole numbers (x1, x2, x3), got {value!r}")
        return tuple(_value("int", v, name) for v in value)
    if kind == "pair_fraction":
        if not isinstance(value, list) or len(value) != 2:
            raise RimclError(f"{name} must be two fractions in (0, 1], got {value!r}")
        pair = tuple(_number(v, name) for v in value)
        if not all(0 < v <= 1 for v in pair):
            raise RimclError(f"{name} must be two fractions in (0, 1], got {value!r}")
        return pair
    if kind == "pfloats":
        if not isinstance(value, list) or not value:
            raise RimclError(f"{name} must be a list of positive numbers, got {value!r}")
        return tuple(_value("pfloat", v, name) for v in value)
    raise AssertionError(kind)


def _table(raw, keys, section, where):
    if not isinstance(raw, dict):
        raise RimclError(f"[{section}] in {where} must be a table of keys")
    out = {}
    for name, value in raw.items():
        if name not in keys:
            raise RimclError(f"unknown key {section}.{name} in {where}{_suggest(name, keys)}")
        if keys[name] == "cameras":
            out[name] = _cameras(value, where)
        else:
            out[name] = _value(keys[name], value, f"{section}.{name}")
    return out


def _cameras(raw, where):
    if not isinstance(raw, list) or not all(isinstance(t, dict) for t in raw):
        raise RimclError(f"rig.cameras in {where} must be [[rig.cameras]] tables")
    cameras = []
    for index, table in enumerate(raw):
        values = _table(table, _CAMERA_KEYS, f"rig.cameras[{index}]", where)
        for needed in ("position_mm", "look_at_mm"):
            if needed not in values:
                raise RimclError(f"rig.cameras[{index}] in {where} needs {needed}")
        values.setdefault("name", f"cam{index + 1}")
        cameras.append(CameraSpec(**values))
    names = [c.name for c in cameras]
    if len(set(names)) != len(names):
        raise RimclError(f"rig.cameras in {where}: camera names must differ, got {names}")
    return tuple(cameras)


def _sections(raw_rig, raw_illumination, raw_lpt, where):
    """The three LPT sections checked and filled in."""
    rig = _table(raw_rig, _RIG_KEYS, "rig", where)
    if rig.get("cameras"):
        # cameras given: the preset is only what the user names
        rig.setdefault("preset", "")
        if rig["preset"]:
            raise RimclError(f"{where}: give rig.preset or [[rig.cameras]], not both")
    elif rig.get("preset", "lpt-challenge") == "":
        raise RimclError(f'{where}: rig.preset = "" needs [[rig.cameras]] tables')
    if not rig.get("cameras"):
        rig.pop("cameras", None)
    illumination = _table(raw_illumination, _ILLUMINATION_KEYS, "illumination", where)
    settings = LptSettings(**_table(raw_lpt, _LPT_KEYS, "lpt", where))
    if settings.calibration_planes < 3:
        raise RimclError(f"lpt.calibration_planes in {where}: the Soloff fit needs at least 3")
    if not 8 <= settings.bit_depth <= 16:
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
    return RigConfig(**rig), IlluminationConfig(**illumination), settings


def parse_lpt_scene(raw, where="the scene"):
    """Check an LPT scene mapping (as read from TOML) and fill in the defaults.

    Parameters
    ----------
    raw : dict
        ``{section: {key: value}}``.
    where : str
        Named in error messages.

    Returns
    -------
    LptScene
    """
    from rimcl.scene.load import field_scales
    from rimcl.scene.validate import validate_scene

    raw = dict(raw)
    sections = _sections(raw.pop("rig", {}), raw.pop("illumination", {}), raw.pop("lpt", {}), where)
    for section in raw:
        if section not in STUDY_SECTIONS:
            known = (*STUDY_SECTIONS, "rig", "illumination", "lpt")
            raise RimclError(
                f"section [{section}] in {where} does not apply to LPT (its sections: "
                f"{', '.join(known)}){_suggest(section, known)}"
            )
    cases_given = "names" in raw.get("cases", {})
    # field.time_s from field.velocity_m_s or the field file, as for a study
    study = field_scales(validate_scene(raw, where), where)
    if not cases_given:
        study["cases"]["names"] = list(DEFAULT_CASES)
    return LptScene(*sections, study)


def lpt_scene_from_study(scene, where="the scene"):
    """The LPT scene of a complete, checked study scene (``rimcl study``, ``run.mode =
    "lpt"``): its ``[rig]``, ``[illumination]`` and ``[lpt]`` sections (keys left to the
    pipeline omitted) and the whole scene as the study's part."""
    raw = [
        {name: value for name, value in scene[section].items() if value is not None}
        for section in ("rig", "illumination", "lpt")
    ]
    return LptScene(*_sections(*raw, where), scene)


def load_lpt_scene(path=None):
    """Read and check an LPT scene file (the defaults when ``path`` is None)."""
    if path is None:
        return parse_lpt_scene({}, "the default LPT scene")
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as exc:
        raise RimclError(f"cannot read scene file {path}: {exc.strerror}") from None
    except UnicodeDecodeError:
        raise RimclError(f"scene file {path} is not text (a TOML scene is UTF-8 text)") from None
    try:
        raw = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise RimclError(f"{path} is not valid TOML: {exc}") from None
    return parse_lpt_scene(raw, str(path))


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
