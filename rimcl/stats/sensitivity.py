"""Sensitivity bands: the headline numbers under settings a user could choose differently.

A bootstrap interval says how the number moves with the tracers; it says nothing about the
threshold, the interpolation or the number of rays, which a user chooses and which move
some numbers more (at C4 the threshold moves u3 by a factor 2.5). Each headline
number gets the same number under each variant and a verdict: *stable* where every variant
lies inside the bootstrap 95 % interval, else *depends on X by Y %* (the variant that moves
it most, relative to the number).

Variants:

- ``excluded by optics`` (always; no measurement): the tracers the study leaves out
  (flagged) counted with their optics error (the light-weighted mean of their ray image
  points, against the reference's), the kept ones with their full error;
- ``threshold ×½``, ``threshold ×2``, the other interpolation, ``rays ×4``: the case
  measured again with that one setting changed (``rimcl study --sensitivity``;
  :mod:`rimcl.study.sensitivity`), summarised by :func:`headline_values`.
"""

import numpy as np

from rimcl.stats.render_file import OPTICS_COLUMNS
from rimcl.stats.tables import flagged_tracers, position_error_vectors, rows_of

#: Headline numbers followed: (stats path, group, component). Position: median |ε_x| / L;
#: kinematics: rms(ε) / rms(truth) of the refraction error.
HEADLINES = (
    ("position_error_median_over_L", None, None),
    ("velocity.u3.rms_normalized", "velocity", "u3"),
    ("velocity_fit.u3.rms_normalized", "velocity_fit", "u3"),
    ("acceleration.a3.rms_normalized", "acceleration", "a3"),
    ("acceleration_fit.a3.rms_normalized", "acceleration_fit", "a3"),
)

#: The variant computed from the case's own file.
EXCLUDED_BY_OPTICS = "excluded by optics"
#: The variants that measure the case again (:mod:`rimcl.study.sensitivity`).
MEASURED_VARIANTS = ("threshold ×½", "threshold ×2", "the other interpolation", "rays ×4")


def _rms_ratio(error, truth):
    usable = np.isfinite(error) & np.isfinite(truth)
    if not usable.any():
        return None
    value = float(np.sqrt(np.sum(error[usable] ** 2) / np.sum(truth[usable] ** 2)))
    return value if np.isfinite(value) else None


def _median_over_length(vectors, length):
    magnitude = np.hypot(*vectors)
    magnitude = magnitude[np.isfinite(magnitude)]
    return float(np.median(magnitude) / length) if magnitude.size else None


def headline_values(tables, excluded_by_optics=False):
    """The :data:`HEADLINES` numbers of one case, without intervals.

    Parameters
    ----------
    tables : RenderTables
    excluded_by_optics : bool
        Count the excluded (flagged) tracers too, with their optics error
        (``opt - opt_ref``) in place of the measured one; needs the optics columns.

    Returns
    -------
    dict of str to float or None
        ``{path: value}``; None where nothing was measured (or no optics columns).
    """
    excluded, _ = flagged_tracers(tables)
    all_ids = np.unique(tables.tracers["id"].astype(np.int64))
    kept = np.setdiff1d(all_ids, excluded)
    values = {}
    for path, group, component in HEADLINES:
        if group is None:
            tracers = tables.tracers
            have_optics = all(name in tracers for name in OPTICS_COLUMNS["x"])
            if excluded_by_optics and not have_optics:
                values[path] = None
                continue
            rows = rows_of(tracers, kept)
            error = position_error_vectors(rows)
            if excluded_by_optics:
                others = rows_of(tracers, excluded)
                optics = position_error_vectors(others, "opt", "opt_ref")
                error = tuple(np.concatenate(pair) for pair in zip(error, optics, strict=True))
            values[path] = _median_over_length(error, tables.length)
            continue
        table = getattr(tables, group)
        symbol = component[0]
        if not table or (
            excluded_by_optics and not all(n in table for n in OPTICS_COLUMNS[symbol])
        ):
            values[path] = None
            continue
        rows = rows_of(table, kept)
        error = rows[f"{component}_meas"] - rows[f"{component}_ref"]
        truth = rows[f"{component}_true"]
        if excluded_by_optics:
            others = rows_of(table, excluded)
            error = np.concatenate(
                [error, others[f"{component}_opt"] - others[f"{component}_opt_ref"]]
            )
            truth = np.concatenate([truth, others[f"{component}_true"]])
        values[path] = _rms_ratio(error, truth)
    return values


def _lookup(case, path):
    node = case
    for name in path.split("."):
        node = node.get(name) if isinstance(node, dict) else None
    return node


def _interval(case, path):
    if "." not in path:
        return case.get(f"{path}_ci95")
    group, component, key = path.split(".")
    return (case.get(group, {}).get(component, {}).get("ci95") or {}).get(key)


def bands(case, variants):
    """The verdict of each headline number of a case against its variants.

    Parameters
    ----------
    case : dict
        The case's ``stats.json`` entry (values and ``ci95``).
    variants : dict of str to dict
        ``{variant name: headline_values(...)}``.

    Returns
    -------
    dict of str to dict
        Per headline path: ``value``, ``ci95``, ``variants`` (``{name: value}``),
        ``relative`` (``{name: value / headline - 1}``), ``stable`` (every variant inside
        the interval; None without variants or value) and ``text`` ("stable"; "stable
        against X" while some of the :data:`MEASURED_VARIANTS` were not run; "depends on
        X by +Y %"; or "n/a").
    """
    result = {}
    for path, _, _ in HEADLINES:
        value, interval = _lookup(case, path), _interval(case, path)
        found = {name: values.get(path) for name, values in variants.items()}
        found = {name: v for name, v in found.items() if v is not None}
        entry = {"value": value, "ci95": interval, "variants": found, "relative": {}}
        if value is None or not value or not found:
            entry.update(stable=None, text="n/a")
            result[path] = entry
            continue
        entry["relative"] = {name: v / value - 1.0 for name, v in found.items()}
        inside = interval is not None and all(
            interval[0] <= v <= interval[1] for v in found.values()
        )
        entry["stable"] = bool(inside)
        if inside:
            missing = [name for name in MEASURED_VARIANTS if name not in found]
            entry["text"] = "stable" if not missing else f"stable against {', '.join(found)}"
        else:
            name = max(entry["relative"], key=lambda k: abs(entry["relative"][k]))
            entry["text"] = f"depends on {name} by {100 * entry['relative'][name]:+.0f} %"
        result[path] = entry
    return result
