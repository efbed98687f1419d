"""The statistics in your units: micrometres and pixels, mm/s and px/frame, m/s², ms.

A field has a length scale (``length_m``, metres per field length unit) and a time scale
(``time_s``, seconds per field time unit). :func:`case_units` gives every headline number of
a case both ways, the normalised value and the physical one, with the scales that connect
them, so that ``physical = normalised × scale`` can be read off the document; without the
scales the physical values are ``None`` and the block says the numbers are in field units.
Pixels need no scale: the pixel size on the sheet is known in field units.

:func:`tidy_rows` flattens a ``stats.json`` document into one row per statistic (case,
quantity, component, statistic, value, lo, hi, unit), written beside it as ``stats.csv`` by
:func:`write_tidy` (``pandas.read_csv`` reads it).
"""

import csv
import io
import math

import numpy as np

from rimcl.core.atomic import atomic_path
from rimcl.stats.error_blocks import kinematic_blocks, vector_columns
from rimcl.stats.summaries import SUMMARY_KEYS
from rimcl.stats.tables import flagged_tracers

#: Kinematic groups reported in physical units, and the physical unit of each symbol.
_GROUPS = ("velocity", "velocity_fit", "acceleration", "acceleration_fit")
#: Errors a kinematic group is split into: (name, measured column kind, reference kind).
_ERRORS = (("total", "meas", "true"), ("refraction", "meas", "ref"), ("baseline", "ref", "true"))


def scales(length, pixel_size, dt, length_m=None, time_s=None):
    """The factors from field units to physical units.

    Parameters
    ----------
    length, pixel_size, dt : float
        Traced depth ``L``, pixel size on the sheet (field length units) and the time
        between frames (field time units).
    length_m, time_s : float, optional
        Metres per field length unit and seconds per field time unit.

    Returns
    -------
    dict
        ``um_per_length``, ``mm_s_per_velocity``, ``m_s2_per_acceleration``, ``dt_ms``,
        ``L_mm`` and ``pixel_um`` (None without the scale they need), ``px_per_length``
        and ``px_frame_per_velocity`` (always), and the two scales themselves.
    """
    has_length = length_m is not None
    has_time = has_length and time_s is not None
    return {
        "length_m": length_m,
        "time_s": time_s,
        "in_field_units": not has_time,
        "L_mm": length * length_m * 1e3 if has_length else None,
        "pixel_um": pixel_size * length_m * 1e6 if has_length else None,
        "dt_ms": dt * time_s * 1e3 if time_s is not None else None,
        "um_per_length": length_m * 1e6 if has_length else None,
        "px_per_length": 1.0 / pixel_size,
        "mm_s_per_velocity": length_m / time_s * 1e3 if has_time else None,
        "px_frame_per_velocity": dt / pixel_size,
        "m_s2_per_acceleration": length_m / time_s**2 if has_time else None,
    }


def _times(value, factor):
    return None if value is None or factor is None else value * factor


def _rms(values):
    values = values[np.isfinite(values)]
    return float(np.sqrt(np.mean(values**2))) if values.size else None


def _vector_rms(first, second):
    return _rms(np.sqrt(np.square(first) + np.square(second)))


def _group_units(table, symbol, factors):
    """rms of the truth and of each error of one kinematic group, both ways."""
    velocity = symbol == "u"
    physical = "mm_s" if velocity else "m_s2"
    factor = factors["mm_s_per_velocity" if velocity else "m_s2_per_acceleration"]
    block = {}

    def both(value):
        entry = {"field": value, physical: _times(value, factor)}
        if velocity:
            entry["px_frame"] = _times(value, factors["px_frame_per_velocity"])
        return entry

    # the rows where truth, reference and measurement are all finite, for every rms alike
    columns = {kind: vector_columns(table, symbol, kind) for kind in ("true", "ref", "meas")}
    usable = np.logical_and.reduce([np.isfinite(c) for pair in columns.values() for c in pair])
    columns = {kind: (pair[0][usable], pair[1][usable]) for kind, pair in columns.items()}
    floor = None
    if f"{symbol}2_floor" in table:  # the noise floor: its finite rows among the usable
        pairs = zip(vector_columns(table, symbol, "floor"), columns["ref"], strict=True)
        floor = tuple(f[usable] - r for f, r in pairs)
    for component, k in ((f"{symbol}2", 0), (f"{symbol}3", 1), ("vector", None)):
        entry = {"rms_truth": both(_pick(columns["true"], k))}
        for name, measured, reference in _ERRORS:
            a, b = columns[measured], columns[reference]
            entry[f"rms_{name}"] = both(_pick((a[0] - b[0], a[1] - b[1]), k))
        if floor is not None:
            entry["rms_noise_floor"] = both(_pick(floor, k))
        block[component] = entry
    return block


def _pick(pair, component):
    """rms of one component of a vector pair, or of the vector's length (None)."""
    if component is None:
        return _vector_rms(*pair)
    return _rms(pair[component])


def case_units(tables, length_m=None, time_s=None, case=None):
    """The ``units`` block of one case of ``stats.json``.

    Parameters
    ----------
    tables : RenderTables
    length_m, time_s : float, optional
        The field's scales (default: those the render file records).
    case : dict, optional
        The case's statistics, for its position peak and median.

    Returns
    -------
    dict
        ``scales`` (:func:`scales`), ``position`` (peak and median ``|ε_x|`` in ``L``,
        µm and px), and per kinematic group and component (``u2``, ``u3``, ``vector``):
        ``rms_truth``, ``rms_total`` (measured − true), ``rms_refraction`` (measured −
        reference), ``rms_baseline`` (reference − true) and, where the render file has
        the floor's columns, ``rms_noise_floor`` (second reference exposure − reference),
        each ``{"field", "mm_s",
        "px_frame"}`` for velocities and ``{"field", "m_s2"}`` for accelerations, over the
        tracers the statistics use; ``displacement_rms_px``, the rms tracer displacement
        per frame.
    """
    length_m = getattr(tables, "length_m", None) if length_m is None else length_m
    time_s = getattr(tables, "time_s", None) if time_s is None else time_s
    factors = scales(tables.length, tables.pixel_size, tables.dt, length_m, time_s)
    excluded, _ = flagged_tracers(tables)
    kept = np.setdiff1d(np.unique(tables.tracers["id"].astype(np.int64)), excluded)
    block = {"scales": factors, "note": scale_note(factors)}
    if case is not None:
        block["position"] = {}
        for name in ("peak", "median"):
            over_l = case.get(f"position_error_{name}_over_L")
            block["position"][name] = {
                "over_L": over_l,
                "um": _times(_times(over_l, tables.length), factors["um_per_length"]),
                "px": _times(_times(over_l, tables.length), factors["px_per_length"]),
            }
    for group, (symbol, table) in kinematic_blocks(tables, kept).items():
        if group in _GROUPS and len(table["id"]):
            block[group] = _group_units(table, symbol, factors)
    velocity = block.get("velocity", {}).get("vector", {}).get("rms_truth", {})
    block["displacement_rms_px"] = velocity.get("px_frame")
    return block


def scale_note(factors):
    """The sentence saying which units a block of :func:`scales` ``factors`` allows."""
    if factors["length_m"] is None:
        return (
            "field units: positions in L and px only; set field.length_m (and field.time_s) "
            "for µm, mm/s and m/s²"
        )
    if factors["time_s"] is None:
        return "lengths in µm and px; velocities in field units: --time-s (field.time_s) for mm/s"
    return "physical values = normalised values × scales"


# ---------------------------------------------------------------- the tidy table

TIDY_COLUMNS = ("case", "quantity", "component", "statistic", "value", "lo", "hi", "unit")


def _summary_rows(case, quantity, component, summary, prefix=""):
    ci = summary.get("ci95") or {}
    for key in SUMMARY_KEYS:
        interval = ci.get(key) or (None, None)
        yield (case, quantity, component, prefix + key, summary.get(key), *interval, "1")
    yield (case, quantity, component, prefix + "n", summary.get("n"), None, None, "count")


def tidy_rows(stats):
    """One row per statistic of a ``stats.json`` document (:data:`TIDY_COLUMNS`).

    Relative errors are fractions (unit ``1``); the physical rows repeat the ``units``
    block's values (``mm/s``, ``px/frame``, ``m/s2``, ``um``, ``px``, ``L``, ``ms``).

    Returns
    -------
    list of tuple
    """
    rows = []
    for case in stats.get("cases", []):
        name = case["name"]
        for key, unit in (("peak", "L"), ("median", "L")):
            value = case.get(f"position_error_{key}_over_L")
            lo, hi = case.get(f"position_error_{key}_over_L_ci95") or (None, None)
            rows.append((name, "position_error", "magnitude", key, value, lo, hi, unit))
        for block in ("", "baseline", "noise_floor", "optics", "imaging"):
            source = case if not block else case.get(block) or {}
            for group in _GROUPS:
                for component, summary in (source.get(group) or {}).items():
                    if not isinstance(summary, dict):
                        continue
                    quantity = f"{group}_error" + (f"_{block}" if block else "")
                    rows += _summary_rows(name, quantity, component, summary)
                    conditioned = summary.get("conditioned")
                    if conditioned:
                        rows += _summary_rows(
                            name, quantity, component, conditioned, "conditioned_"
                        )
        rows += _unit_rows(name, case.get("units"))
        piv = (case.get("piv") or {}).get("units") or {}
        for key, values in piv.items():
            if key == "scales":
                continue
            for field, unit in (("px_frame", "px/frame"), ("field", "field"), ("mm_s", "mm/s")):
                rows.append((name, "piv_displacement", key, "rms", values[field], None, None, unit))
    return rows


def _unit_rows(name, units):
    if not units:
        return []
    rows = []
    factors = units["scales"]
    for key, unit in (("dt_ms", "ms"), ("pixel_um", "um"), ("L_mm", "mm")):
        rows.append((name, "scale", "", key, factors.get(key), None, None, unit))
    for key, entry in (units.get("position") or {}).items():
        for field, unit in (("um", "um"), ("px", "px")):
            rows.append((name, "position_error", "magnitude", key, entry[field], None, None, unit))
    for group in _GROUPS:
        for component, entry in (units.get(group) or {}).items():
            for statistic, values in entry.items():
                for field, value in values.items():
                    unit = {"field": "field", "mm_s": "mm/s", "px_frame": "px/frame",
                            "m_s2": "m/s2"}[field]  # fmt: skip
                    rows.append((name, group, component, statistic, value, None, None, unit))
    return rows


def write_tidy(path, stats):
    """Write :func:`tidy_rows` as CSV (empty cells for None), atomically."""
    buffer = io.StringIO()
    writer = csv.writer(buffer, lineterminator="\n")
    writer.writerow(TIDY_COLUMNS)
    for row in tidy_rows(stats):
        writer.writerow(["" if _missing(v) else v for v in row])
    with atomic_path(path, overwrite=True) as tmp:
        with open(tmp, "w", encoding="utf-8") as handle:
            handle.write(buffer.getvalue())
    return path


def _missing(value):
    return value is None or (isinstance(value, float) and not math.isfinite(value))
