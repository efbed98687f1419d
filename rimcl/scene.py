"""Scene files of ``rimcl study``: TOML, every key documented, with defaults and checks.

A scene says what to measure: the field, the refractive-index cases, the tracers, the
camera, the renderer and the integrator. Every key is optional; :data:`SCENE_KEYS` lists
them with their defaults, and ``rimcl study --print-default-scene`` prints them as a
commented TOML file. Unknown sections and keys are refused with the closest valid name
suggested, so a misspelt key never silently falls back to its default.

The defaults are sized so that ``rimcl study`` on the shipped 64³ sample finishes in a few
minutes on a 2-core CPU with PoCL; the paper's own settings are given in the comments.
"""

import copy
import dataclasses
import difflib
import json
import math
import sys
import textwrap
from pathlib import Path

from rimcl.errors import RimclError

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover - Python 3.10
    import tomli as tomllib


@dataclasses.dataclass(frozen=True)
class SceneKey:
    """One key of a scene file.

    Attributes
    ----------
    section, name : str
        ``[section]`` and key name.
    default : object
        Value when the key is absent; ``None`` for keys whose default is decided by the
        pipeline (the printed scene shows them commented out, with ``example``).
    kind : {"str", "int", "float", "bool", "names", "thresholds"}
        ``names``: a list of strings; ``thresholds``: a table of case name to number.
    doc : str
        What the key means, with units.
    choices : tuple of str
        Allowed values of a ``str`` key (empty: any).
    minimum : float, optional
        Smallest allowed value of a number.
    positive : bool
        A number that must be strictly positive.
    example : object
        Value shown for a key whose default is ``None``.
    """

    section: str
    name: str
    default: object
    kind: str
    doc: str
    choices: tuple = ()
    minimum: float | None = None
    positive: bool = False
    example: object = None

    @property
    def dotted(self):
        return f"{self.section}.{self.name}"


def _choices():
    from rimcl.camera import CAMERAS
    from rimcl.centroid import CENTROID_WEIGHTS
    from rimcl.render import RENDERERS
    from rimcl.trace import INTERPOLATIONS, PRECISIONS

    return {
        "camera": CAMERAS,
        "weights": CENTROID_WEIGHTS,
        "renderer": RENDERERS,
        "interp": INTERPOLATIONS,
        "precision": PRECISIONS,
    }


def _keys():
    choice = _choices()
    return (
        SceneKey(
            "field",
            "path",
            "",
            "str",
            'rimcl field file with density and velocity; "" = the shipped 64³ sample',
        ),
        SceneKey(
            "field",
            "start_frame",
            0,
            "int",
            "first of the three consecutive frames used (time t0)",
            minimum=0,
        ),
        SceneKey(
            "field",
            "x_sheet",
            None,
            "float",
            "light-sheet plane x1 (field length units); default: the grid's first x1",
            example=0.0,
        ),
        SceneKey(
            "field",
            "depth",
            None,
            "float",
            "traced depth L (field length units); default: the whole grid along x1",
            positive=True,
            example=3.0,
        ),
        SceneKey(
            "cases",
            "names",
            ["C0", "C1", "C2", "C3", "C4"],
            "names",
            'Gladstone–Dale cases: C0..C4 (the paper; C1 air, C4 water) or "G=<value>"',
        ),
        SceneKey(
            "cases",
            "thresholds",
            {},
            "thresholds",
            "grey threshold per case (counts), overriding renderer.threshold "
            "(the paper: 100 for air, 500 for water)",
            example={"C4": 50.0},
        ),
        SceneKey(
            "tracers",
            "count",
            400,
            "int",
            "tracers in the sheet, uniform random (paper: 1e5)",
            positive=True,
        ),
        SceneKey(
            "tracers",
            "seed",
            0,
            "int",
            "seed of tracers and ray samples; the same for every case (common random numbers)",
            minimum=0,
        ),
        SceneKey(
            "tracers",
            "margin",
            0.05,
            "float",
            "edge band of the field of view kept free of tracers (fraction of its width)",
            minimum=0.0,
        ),
        SceneKey(
            "camera",
            "kind",
            "plane",
            "str",
            "plane: rays aimed at a fan x fan grid on the exit plane (the paper); "
            "pupil: rays over a circular lens aperture",
            choices=choice["camera"],
        ),
        SceneKey(
            "camera",
            "fan",
            24,
            "int",
            "plane camera: aim points per side (paper: 100)",
            positive=True,
        ),
        SceneKey(
            "camera", "pupil_rays", 1024, "int", "pupil camera: rays per tracer", positive=True
        ),
        SceneKey(
            "camera",
            "aperture_diameter",
            None,
            "float",
            "pupil diameter (field length units); default: distance / 4",
            positive=True,
            example=3.0,
        ),
        SceneKey(
            "camera",
            "focal_length",
            None,
            "float",
            "with f_number instead of aperture_diameter: D = focal_length / f_number",
            positive=True,
            example=2.0,
        ),
        SceneKey(
            "camera", "f_number", None, "float", "see focal_length", positive=True, example=2.8
        ),
        SceneKey(
            "camera",
            "distance",
            None,
            "float",
            "sheet to pupil centre along the viewing axis (field length units); default: 4 L",
            positive=True,
            example=25.0,
        ),
        SceneKey(
            "camera", "view_angle", 0.0, "float", "viewing axis angle to x1, towards +x2 (degrees)"
        ),
        SceneKey(
            "renderer",
            "kind",
            "exact",
            "str",
            "exact: pixel-integrated Gaussian per ray; paper: nearest-pixel binning, "
            "then a Gaussian filter",
            choices=choice["renderer"],
        ),
        SceneKey(
            "renderer",
            "pixels",
            2048,
            "int",
            "pixels across the field of view (paper: 8192); finer pixels lower the "
            "rounding noise of the centroids, which dominates the errors of the weakest cases",
            positive=True,
        ),
        SceneKey(
            "renderer",
            "psf_sigma",
            7.0,
            "float",
            "Gaussian point-spread sigma (pixels; 2.3 px gives the paper's ~10 px tracer "
            "image); wide enough here that water-like cases (C4), whose rays spread over "
            "~1e-2 L, still image as one blob above threshold",
            positive=True,
        ),
        SceneKey(
            "renderer",
            "threshold",
            40.0,
            "float",
            "grey threshold in camera counts (10 bits: of 1023; the paper: 100 for air); "
            "the peak of a C4 tracer image falls to a few percent of the reference peak",
            minimum=0.0,
        ),
        SceneKey(
            "renderer",
            "centroid_weights",
            "excess",
            "str",
            "excess: grey value minus threshold (smooth); grey: the paper's grey value",
            choices=choice["weights"],
        ),
        SceneKey(
            "renderer",
            "bit_depth",
            10,
            "int",
            "bits per pixel of the camera, 8 to 16 (paper: 10); the rounding to counts moves "
            "centroids by a few 1e-4 pixel at 10 bits, a floor under the weakest cases' "
            "velocity errors (scale the threshold with the full scale 2**bits - 1)",
            positive=True,
        ),
        SceneKey(
            "renderer",
            "max_window",
            512,
            "int",
            "largest per-tracer image window side (pixels)",
            positive=True,
        ),
        SceneKey(
            "integrator",
            "interp",
            "trilinear",
            "str",
            "interpolation of the gridded field",
            choices=choice["interp"],
        ),
        SceneKey(
            "integrator",
            "precision",
            "f32c",
            "str",
            "accumulation: plain float32, compensated float32, float64",
            choices=choice["precision"],
        ),
        SceneKey(
            "integrator",
            "step",
            None,
            "float",
            "integration step in t = s/n (field length units); default: half a cell",
            positive=True,
            example=0.05,
        ),
        SceneKey(
            "run",
            "device",
            "",
            "str",
            'OpenCL device (see "rimcl devices"); "" = $RIMCL_DEVICE, then a GPU, then a CPU',
        ),
        SceneKey(
            "run",
            "ray_sample",
            20000,
            "int",
            "first-frame rays kept per case for the ray diagnostics",
            minimum=0,
        ),
        SceneKey(
            "run",
            "rays_per_batch",
            131072,
            "int",
            "rays traced per batch (bounds the memory)",
            positive=True,
        ),
        SceneKey(
            "run",
            "scheduler",
            "",
            "str",
            'Dask scheduler measuring the cases: "" = this process; "local:N" = N worker '
            'processes here; "tcp://HOST:PORT" = a running scheduler (rimcl[distributed])',
        ),
        SceneKey(
            "run",
            "shard_tracers",
            100,
            "int",
            "tracers per Dask task (one case, one shard of tracers) with run.scheduler; "
            "the results do not depend on it",
            positive=True,
        ),
    )


#: Every key of a scene file, in the order of the printed default scene.
SCENE_KEYS = _keys()
SECTIONS = tuple(dict.fromkeys(key.section for key in SCENE_KEYS))
_BY_NAME = {key.dotted: key for key in SCENE_KEYS}


def default_scene():
    """The scene with every key at its default.

    Returns
    -------
    dict of str to dict
        ``{section: {key: value}}``; ``None`` where the pipeline decides.
    """
    scene = {section: {} for section in SECTIONS}
    for key in SCENE_KEYS:
        scene[key.section][key.name] = copy.deepcopy(key.default)
    return scene


def _toml_value(value):
    """TOML text of a scene value, inline (arrays and tables on one line)."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, str):
        return json.dumps(value, ensure_ascii=False)  # a valid TOML basic string
    if isinstance(value, float):
        return repr(value) if math.isfinite(value) else str(value)
    if isinstance(value, int):
        return str(value)
    if isinstance(value, list):
        return "[" + ", ".join(_toml_value(item) for item in value) + "]"
    if isinstance(value, dict):
        items = ", ".join(f"{json.dumps(k)} = {_toml_value(v)}" for k, v in value.items())
        return "{ " + items + " }" if items else "{}"
    raise TypeError(f"no TOML form for {value!r}")


def default_scene_text():
    """The default scene as a commented TOML file: every key, its meaning and default.

    Returns
    -------
    str
    """
    lines = [
        "# rimcl study scene. Every key is optional: a missing key takes the value shown.",
        "# Lengths are in field length units (the field file's grid), angles in degrees.",
        "# Keys commented out default to what the pipeline decides (see their comment).",
    ]
    for section in SECTIONS:
        lines += ["", f"[{section}]"]
        for key in (k for k in SCENE_KEYS if k.section == section):
            note = f" (one of: {', '.join(key.choices)})" if key.choices else ""
            lines += textwrap.wrap(
                key.doc + note, width=88, initial_indent="# ", subsequent_indent="#   "
            )
            if key.default is None or key.default == {}:
                lines.append(f"# {key.name} = {_toml_value(key.example)}")
            else:
                lines.append(f"{key.name} = {_toml_value(key.default)}")
    return "\n".join(lines) + "\n"


def _suggest(word, candidates):
    close = difflib.get_close_matches(word, list(candidates), n=1, cutoff=0.5)
    return f"; did you mean {close[0]!r}?" if close else ""


def _check_value(key, value, where):
    """The value of ``key`` converted and checked; raises RimclError naming ``where``."""
    name = f"{key.dotted} in {where}"
    if key.kind == "names":
        if not isinstance(value, list) or not all(isinstance(v, str) for v in value):
            raise RimclError(f"{name} must be a list of case names, got {value!r}")
        if not value:
            raise RimclError(f"{name} must name at least one case")
        return _check_cases(value, name)
    if key.kind == "thresholds":
        if not isinstance(value, dict):
            raise RimclError(f"{name} must be a table of case name = threshold, got {value!r}")
        return {
            _check_cases([case], name)[0]: _check_number(
                dataclasses.replace(key, kind="float", minimum=0.0), count, name
            )
            for case, count in value.items()
        }
    if key.kind == "str":
        if not isinstance(value, str):
            raise RimclError(f"{name} must be a string, got {value!r}")
        if key.choices and value not in key.choices:
            raise RimclError(
                f"{name} must be one of {', '.join(key.choices)}, got {value!r}"
                + _suggest(value, key.choices)
            )
        return value
    if key.kind == "bool":
        if not isinstance(value, bool):
            raise RimclError(f"{name} must be true or false, got {value!r}")
        return value
    return _check_number(key, value, name)


def _check_number(key, value, name):
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise RimclError(f"{name} must be a number, got {value!r}")
    if key.kind == "int":
        if isinstance(value, float) and not value.is_integer():
            raise RimclError(f"{name} must be a whole number, got {value!r}")
        value = int(value)
    else:
        value = float(value)
        if not math.isfinite(value):
            raise RimclError(f"{name} must be finite, got {value!r}")
    if key.positive and not value > 0:
        raise RimclError(f"{name} must be positive, got {value!r}")
    if key.minimum is not None and value < key.minimum:
        raise RimclError(f"{name} must be at least {key.minimum}, got {value!r}")
    return value


def _check_cases(names, where):
    from rimcl.flow.cases import CASES, resolve_k_rho

    resolved = []
    for case in names:
        try:
            resolved.append(resolve_k_rho(case=case)[0])
        except RimclError as exc:
            raise RimclError(f"{where}: {exc}{_suggest(case.upper(), CASES)}") from None
    duplicates = sorted({name for name in resolved if resolved.count(name) > 1})
    if duplicates:
        raise RimclError(f"{where} names case {', '.join(duplicates)} more than once")
    return resolved


def validate_scene(raw, where="the scene"):
    """Check a scene mapping and fill in the defaults.

    Parameters
    ----------
    raw : dict
        ``{section: {key: value}}`` as read from TOML (missing keys allowed).
    where : str
        Named in error messages (a file name).

    Returns
    -------
    dict
        The complete scene, every key present (``None`` for pipeline defaults).

    Raises
    ------
    RimclError
        For an unknown section or key (with the closest valid name), a value of the wrong
        type, out of range, or not among the choices.
    """
    scene = default_scene()
    for section, table in raw.items():
        if section not in scene:
            raise RimclError(
                f"unknown section [{section}] in {where}" + _suggest(section, SECTIONS)
            )
        if not isinstance(table, dict):
            raise RimclError(f"[{section}] in {where} must be a table of keys")
        for name, value in table.items():
            key = _BY_NAME.get(f"{section}.{name}")
            if key is None:
                elsewhere = [k.dotted for k in SCENE_KEYS if k.name == name]
                hint = (
                    f"; did you mean {elsewhere[0]!r}?"
                    if elsewhere
                    else _suggest(name, [k.name for k in SCENE_KEYS if k.section == section])
                )
                raise RimclError(f"unknown key {section}.{name} in {where}{hint}")
            scene[section][name] = _check_value(key, value, where)
    unknown = set(scene["cases"]["thresholds"]) - set(scene["cases"]["names"])
    if unknown:
        raise RimclError(
            f"cases.thresholds in {where} names {', '.join(sorted(unknown))}, "
            "which cases.names does not run"
        )
    return scene


def load_scene(path=None, overrides=None):
    """Read a scene file (or the defaults), apply overrides, check everything.

    Parameters
    ----------
    path : str or Path, optional
        A TOML scene file; the default scene when omitted.
    overrides : dict, optional
        ``{"section.key": value}`` applied on top (command-line options); ``None`` values
        are ignored.

    Returns
    -------
    dict
        The complete, checked scene (see :func:`validate_scene`).
    """
    raw = {}
    where = "the default scene"
    if path is not None:
        path = Path(path)
        where = str(path)
        try:
            text = path.read_text()
        except OSError as exc:
            raise RimclError(f"cannot read scene file {path}: {exc.strerror}") from None
        try:
            raw = tomllib.loads(text)
        except tomllib.TOMLDecodeError as exc:
            raise RimclError(f"{path} is not valid TOML: {exc}") from None
        field_path = (
            raw.get("field", {}).get("path") if isinstance(raw.get("field"), dict) else None
        )
        if isinstance(field_path, str) and field_path and not Path(field_path).is_absolute():
            # a scene names its field relative to itself, wherever it is run from
            raw["field"]["path"] = str((path.parent / field_path).resolve())
    for dotted, value in (overrides or {}).items():
        if value is None:
            continue
        section, name = dotted.split(".", 1)
        raw.setdefault(section, {})[name] = value
    return validate_scene(raw, where)


def scene_text(scene):
    """A complete scene as TOML (keys left to the pipeline are omitted).

    Parameters
    ----------
    scene : dict
        As returned by :func:`load_scene`.

    Returns
    -------
    str
        Readable again by :func:`load_scene`.
    """
    lines = ["# the scene of this study; run it again with: rimcl study scene.toml --out DIR"]
    for section, table in scene.items():
        lines += ["", f"[{section}]"]
        lines += [f"{name} = {_toml_value(v)}" for name, v in table.items() if v is not None]
    return "\n".join(lines) + "\n"
