"""Scene files of ``rimcl study``: read from TOML, presets applied, checked, written back.

A scene says what to measure: the field, the refractive-index cases, the tracers, the
camera, the renderer and the integrator. Every key is optional;
:data:`rimcl.scene.keys.SCENE_KEYS` lists them with their defaults, and
``rimcl study --print-default-scene`` prints them as a commented TOML file
(:func:`default_scene_text`). :func:`load_scene` reads a file, applies a preset and
command-line overrides, and checks the result (:func:`rimcl.scene.validate.validate_scene`);
:func:`scene_text` writes a complete scene back as TOML.

The defaults are sized so that ``rimcl study`` on the shipped 64³ sample finishes in a few
minutes on a 2-core CPU with PoCL; the paper's own settings are given in the comments.
"""

import copy
import json
import math
import sys
import textwrap
from pathlib import Path

from rimcl.core.errors import RimclError
from rimcl.fields.field_reader import recorded_scales
from rimcl.scene.keys import SCENE_KEYS, SECTIONS, default_scene
from rimcl.scene.validate import validate_scene

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover - Python 3.10
    import tomli as tomllib


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
        "# rimcl scene (study, render, piv render, trace). Every key is optional: a missing",
        "# key takes the value shown; command-line options override keys.",
        "# Lengths are in field length units (the field file's grid), angles in degrees.",
        "# Keys commented out default to what the pipeline decides (see their comment).",
    ]
    for section in SECTIONS:
        lines += ["", f"[{section}]"]
        for key in (k for k in SCENE_KEYS if k.section == section):
            shown = ", ".join(choice or '""' for choice in key.choices)
            note = f" (one of: {shown})" if key.choices else ""
            lines += textwrap.wrap(
                key.doc + note, width=88, initial_indent="# ", subsequent_indent="#   "
            )
            if key.default is None or key.default == {}:
                lines.append(f"# {key.name} = {_toml_value(key.example)}")
            else:
                lines.append(f"{key.name} = {_toml_value(key.default)}")
    return "\n".join(lines) + "\n"


#: Named scenes (``rimcl study --preset NAME``): keys that differ from the defaults.
PRESETS = {
    # The paper's own setting (its §3.2): the 100 x 100 fan, nearest-pixel binning then a
    # Gaussian filter, 8192 px over the traced box, a ~10 px tracer image (σ 2.3 px at a
    # threshold of 100 of 1023), thresholds 100 (air-like) and 500 (water-like), every
    # image rescaled to its own 10-bit range, on a π³ clamped eighth of the 2π sample
    # (the paper traced a 512³ eighth of the 1024³ box). Each ray weighs the Mie intensity
    # of its initial direction (its §3.2: 10 µm tracers, 532 nm; polystyrene and unpolarised
    # light assumed), in the case's mean index; a noiseless 10-bit camera. The fan is a lens
    # of NA ≈ 0.8, which averages opposite shifts: the default lens (NA 0.0076) sees more.
    "paper": {
        "field": {"box": [[0.0, math.pi], [0.0, math.pi], [0.0, math.pi]]},
        "cases": {"thresholds": {"C0": 100.0, "C1": 100.0, "C2": 100.0, "C3": 500.0, "C4": 500.0}},
        "camera": {"kind": "plane", "fan": 100},
        "renderer": {
            "kind": "paper",
            "pixels": 8192,
            "psf_sigma": 2.3,
            "threshold": 100.0,
            "centroid_weights": "grey",
            "scale": "per_image",
            "split": "brightest",
            "bit_depth": 10,
        },
        "sensor": {"noise": False},
        "mie": {
            "enabled": True,
            "diameter_um": 10.0,
            "particle_index": 1.59,
            "wavelength_nm": 532.0,
            "polarisation": "unpolarised",
        },
    },
}


def read_scene_file(path):
    """The tables of a TOML scene file, or one clear error (unreadable, not text, not TOML).

    Parameters
    ----------
    path : pathlib.Path

    Returns
    -------
    dict
    """
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as exc:
        raise RimclError(f"cannot read scene file {path}: {exc.strerror}") from None
    except UnicodeDecodeError:
        raise RimclError(f"scene file {path} is not text (a TOML scene is UTF-8 text)") from None
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise RimclError(f"{path} is not valid TOML: {exc}") from None


def load_scene(path=None, overrides=None, preset=None, command=None, report=None):
    """Read a scene file (or the defaults), apply overrides, check everything.

    Parameters
    ----------
    path : str or Path, optional
        A TOML scene file; the default scene when omitted.
    overrides : dict, optional
        ``{"section.key": value}`` applied on top (command-line options); ``None`` values
        are ignored.
    preset : str, optional
        A name of :data:`PRESETS`, applied under the file's keys.
    command : str, optional
        The command the scene is for (a tag of :data:`rimcl.scene.usage.COMMANDS`): keys set
        that it does not use are refused or noted (:func:`rimcl.scene.usage.check_use`).
        None: no such check (a study reading back its own ``scene.toml``).
    report : callable, optional
        Given the note of :func:`~rimcl.scene.usage.check_use`, if any.

    Returns
    -------
    dict
        The complete, checked scene (see :func:`rimcl.scene.validate.validate_scene`).
    """
    raw = {}
    where = "the default scene"
    given = {}  # dotted key -> where it was set
    if preset is not None:
        if preset not in PRESETS:
            raise RimclError(f"unknown preset {preset!r}; choose from {', '.join(PRESETS)}")
        raw = copy.deepcopy(PRESETS[preset])
        where = f"the {preset} preset"
        given.update(_dotted(raw, f"--preset {preset}"))
    if path is not None:
        path = Path(path)
        where = str(path)
        from_file = read_scene_file(path)
        given.update(_dotted(from_file, path.name))
        for section, table in from_file.items():
            if isinstance(table, dict) and isinstance(raw.get(section), dict):
                raw[section] = {**raw[section], **table}
            else:
                raw[section] = table
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
        given[dotted] = "the options"
    camera = raw.get("camera")
    if isinstance(camera, dict) and "fan" in camera and "kind" not in camera:
        # a fan size and no camera asks for the paper's fan (--fan N), not the default lens
        camera["kind"] = "plane"
    if preset is not None:
        # the preset's thresholds cover every paper case; keep those of the cases run
        names = raw.get("cases", {}).get("names", default_scene()["cases"]["names"])
        preset_thresholds = PRESETS[preset].get("cases", {}).get("thresholds", {})
        thresholds = raw.get("cases", {}).get("thresholds", {})
        for case in set(preset_thresholds) - set(names):
            if thresholds.get(case) == preset_thresholds[case]:
                del thresholds[case]
    scene = validate_scene(raw, where)
    if command is not None:
        from rimcl.scene.usage import check_use

        note = check_use(scene, given, command)
        if note and report is not None:
            report(note)
    return field_scales(scene, where)


def _dotted(raw, source):
    """``{"section.key": source}`` for every key of a TOML mapping."""
    return {
        f"{section}.{name}": source
        for section, table in raw.items()
        if isinstance(table, dict)
        for name in table
    }


def field_scales(scene, where):
    """Fill ``field.length_m`` and ``field.time_s`` from ``field.velocity_m_s`` and from
    what the field file records (``rimcl field import`` writes both where its input says).

    Without ``field.path`` (the shipped sample) only the sample's ``time_s`` is taken: its
    ``length_m`` is the default lens camera's, while an LPT rig scales the field to its own
    size (:data:`rimcl.fields.sample.SAMPLE_LENGTH_M`)."""
    field = scene["field"]
    recorded = {}
    if field["length_m"] is None or field["time_s"] is None:
        if field["path"]:
            recorded = recorded_scales(field["path"])
        else:
            from rimcl.fields.sample import sample_path

            recorded = {"time_s": recorded_scales(sample_path()).get("time_s")}
    if field["length_m"] is None:
        field["length_m"] = recorded.get("length_m")
    if field["velocity_m_s"] is not None:
        if field["length_m"] is None:
            raise RimclError(f"field.velocity_m_s in {where} needs field.length_m")
        time_s = field["length_m"] / field["velocity_m_s"]
        if field["time_s"] is not None and not math.isclose(field["time_s"], time_s, rel_tol=1e-9):
            raise RimclError(
                f"field.time_s ({field['time_s']:g} s) and field.length_m / field.velocity_m_s "
                f"({time_s:g} s) disagree in {where}: give one of them"
            )
        field["time_s"] = time_s
    elif field["time_s"] is None:
        field["time_s"] = recorded.get("time_s")
    return scene


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
