"""Checks of a scene: every section, key and value, with one clear error per mistake.

:func:`validate_scene` fills in the defaults and refuses an unknown section or key (naming
the closest valid one, so a misspelt key never silently falls back to its default), a value
of the wrong type, out of range or not among its choices, and cases that cannot run.
"""

import dataclasses
import difflib
import math

from rimcl.core.errors import RimclError
from rimcl.scene.keys import KEYS_BY_NAME, SCENE_KEYS, SECTIONS, default_scene


def suggest(word, candidates):
    """The hint "; did you mean NAME?" for the closest of ``candidates``, or ""."""
    close = difflib.get_close_matches(word, list(candidates), n=1, cutoff=0.5)
    return f"; did you mean {close[0]!r}?" if close else ""


def _shown(choice):
    """A choice as an error names it ("" written out)."""
    return choice or '""'


def check_value(key, value, where):
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
                f"{name} must be one of {', '.join(map(_shown, key.choices))}, got {value!r}"
                + suggest(value, key.choices)
            )
        return value
    if key.kind == "ints":
        if (
            not isinstance(value, list)
            or not value
            or not all(isinstance(v, int) and not isinstance(v, bool) and v >= 1 for v in value)
        ):
            raise RimclError(f"{name} must be a list of whole numbers >= 1, got {value!r}")
        return [int(v) for v in value]
    if key.kind == "floats":
        if not (
            isinstance(value, list)
            and value
            and all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in value)
            and all(math.isfinite(v) for v in value)
        ):
            raise RimclError(f"{name} must be a list of numbers, got {value!r}")
        return [float(v) for v in value]
    if key.kind == "tables":
        # the stage that uses them checks their keys (rig.cameras: rimcl.lpt.config)
        if not isinstance(value, list) or not all(isinstance(v, dict) for v in value):
            raise RimclError(f"{name} must be a list of tables ([[{key.dotted}]]), got {value!r}")
        return value
    if key.kind == "vector":
        if not (
            isinstance(value, list)
            and len(value) == 3
            and all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in value)
            and all(math.isfinite(v) for v in value)
        ):
            raise RimclError(f"{name} must be three numbers [x1, x2, x3], got {value!r}")
        return [float(v) for v in value]
    if key.kind == "box":
        pairs_ok = isinstance(value, list) and len(value) == 3
        pairs_ok = pairs_ok and all(isinstance(p, list) and len(p) == 2 for p in value)
        if not pairs_ok or not all(
            isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)
            for pair in value
            for v in pair
        ):
            raise RimclError(
                f"{name} must be three [lo, hi] pairs of numbers (x1, x2, x3), got {value!r}"
            )
        if any(lo >= hi for lo, hi in value):
            raise RimclError(f"{name} needs lo < hi along every axis, got {value!r}")
        return [[float(lo), float(hi)] for lo, hi in value]
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
    from rimcl.fields.cases import CASES, fluid_case, resolve_k_rho

    resolved = []
    for case in names:
        try:
            if fluid_case(case) is not None or case.strip() == "delta_n":
                resolved.append(case.strip())
                continue
            resolved.append(resolve_k_rho(case=case)[0])
        except RimclError as exc:
            raise RimclError(f"{where}: {exc}{suggest(case.upper(), CASES)}") from None
    # one case however written: dT=3 and dT=3.0 are the same fluid difference
    same = [fluid_case(name) or name for name in resolved]
    repeated = [name for name, key in zip(resolved, same, strict=True) if same.count(key) > 1]
    duplicates = sorted(set(repeated))
    if duplicates:
        raise RimclError(f"{where} names case {', '.join(duplicates)} more than once")
    return resolved


def _check_combinations(scene, raw, where):
    """Refuse keys that each pass but together ask for something that cannot be."""
    time, camera, sensor = scene["time"], scene["camera"], scene["sensor"]
    frames, window = time["frames"], time["fit_window"]
    if window % 2 == 0:
        raise RimclError(f"time.fit_window in {where} must be odd (centred fits), got {window}")
    if window > frames and "fit_window" not in raw.get("time", {}):
        # the default window on fewer frames (the paper's 3): fit what there is, never drop it
        window = time["fit_window"] = frames if frames % 2 else frames - 1
    if window > frames:
        raise RimclError(
            f"time.fit_window = {window} in {where} needs at least {window} frames, but "
            f"time.frames = {frames}: raise time.frames or lower time.fit_window"
        )
    if time["fit_order"] >= window:
        raise RimclError(
            f"time.fit_order = {time['fit_order']} in {where} needs more than that many "
            f"frames in its window (time.fit_window = {window})"
        )
    too_far = [m for m in time["dt_multiples"] or () if m > frames - 1]
    if too_far:
        raise RimclError(
            f"time.dt_multiples {too_far} in {where} ask for frames {too_far[0]} apart, but "
            f"time.frames = {frames} holds at most {frames - 1}: raise time.frames or drop them"
        )
    if len(camera["sensor_pixels"]) != 2:
        raise RimclError(
            f"camera.sensor_pixels in {where} must be two numbers [along x2, along x3], got "
            f"{camera['sensor_pixels']}"
        )
    if sensor["peak_electrons"] > sensor["full_well_e"]:
        raise RimclError(
            f"sensor.peak_electrons = {sensor['peak_electrons']:g} in {where} is above the "
            f"full well ({sensor['full_well_e']:g} e-): every tracer's peak would saturate"
        )


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
            raise RimclError(f"unknown section [{section}] in {where}" + suggest(section, SECTIONS))
        if not isinstance(table, dict):
            raise RimclError(f"[{section}] in {where} must be a table of keys")
        for name, value in table.items():
            key = KEYS_BY_NAME.get(f"{section}.{name}")
            if key is None:
                elsewhere = [k.dotted for k in SCENE_KEYS if k.name == name]
                hint = (
                    f"; did you mean {elsewhere[0]!r}?"
                    if elsewhere
                    else suggest(name, [k.name for k in SCENE_KEYS if k.section == section])
                )
                raise RimclError(f"unknown key {section}.{name} in {where}{hint}")
            scene[section][name] = check_value(key, value, where)
    from rimcl.fields.cases import fluid_case

    fluid_cases = [c for c in scene["cases"]["names"] if fluid_case(c) is not None]
    if fluid_cases and not scene["fluid"]["kind"]:
        raise RimclError(
            f"cases {', '.join(fluid_cases)} in {where} need a fluid: set [fluid] kind "
            "(water, air or saltwater)"
        )
    _check_combinations(scene, raw, where)
    unknown = set(scene["cases"]["thresholds"]) - set(scene["cases"]["names"])
    if unknown:
        raise RimclError(
            f"cases.thresholds in {where} names {', '.join(sorted(unknown))}, "
            "which cases.names does not run"
        )
    return scene
