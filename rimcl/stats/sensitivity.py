"""Sensitivity bands: the headline numbers under settings a user could choose differently.

A bootstrap interval says how the number moves with the tracers; it says nothing about the
threshold, the interpolation or the number of rays, which a user chooses and which move
some numbers more (at C4 the threshold moves u3 by a factor 2.5). Each headline
number gets the same number under each variant and a verdict: *stable* where every variant
lies inside the bootstrap 95 % interval, else *depends on X by Y %* (the variant that moves
it most, relative to the number).

Variants every study computes from the case's own file (no measurement again):

- ``excluded by optics``: the tracers the study leaves out (flagged) counted with their
  optics error (the light-weighted mean of their ray image points, against the
  reference's), the kept ones with their full error;
- ``threshold ×½``, ``threshold ×2``: every tracer located again at that threshold in the
  same digitised images (reference and measured; columns ``*_threshold_half``,
  ``*_threshold_double`` of the render file), with its own exclusions and kinematics.

Variants that measure the case again (``rimcl study --sensitivity``;
:mod:`rimcl.study.sensitivity`), summarised by :func:`headline_values`: the other
interpolation and ``rays ×4``.
"""

import numpy as np

from rimcl.stats.render_file import OPTICS_COLUMNS, THRESHOLD_SUFFIXES, threshold_columns
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
#: The variants located again in the case's own images: ``{name: column suffix}``.
THRESHOLD_NAMES = dict(zip(("threshold ×½", "threshold ×2"), THRESHOLD_SUFFIXES, strict=True))
#: The variants every study computes from the case's file.
FILE_VARIANTS = (EXCLUDED_BY_OPTICS, *THRESHOLD_NAMES)
#: A move below this (percent of the number) reads plain "stable"; a larger one inside the
#: interval is named beside it.
STILL_PERCENT = 0.5
#: The variants that measure the case again (:mod:`rimcl.study.sensitivity`).
MEASURED_VARIANTS = ("the other interpolation", "rays ×4")


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


def headline_values(tables, excluded_by_optics=False, threshold=None):
    """The :data:`HEADLINES` numbers of one case, without intervals.

    Parameters
    ----------
    tables : RenderTables
    excluded_by_optics : bool
        Count the excluded (flagged) tracers too, with their optics error
        (``opt - opt_ref``) in place of the measured one; needs the optics columns.
    threshold : str, optional
        A suffix of :data:`rimcl.stats.render_file.THRESHOLD_SUFFIXES`: the tracers as
        located at that threshold (their positions, kinematics and exclusions); needs
        the file's columns of that threshold.

    Returns
    -------
    dict
        ``{path: value}`` (None where nothing was measured, or without the columns it
        needs) and ``n_used``, the tracers counted (None without the columns).
    """
    suffix = "" if threshold is None else f"_{threshold}"
    flags = f"flags{suffix}"
    if threshold is not None and not all(
        name in tables.tracers for name in threshold_columns("x", threshold)
    ):
        return {**dict.fromkeys(path for path, _, _ in HEADLINES), "n_used": None}
    excluded, _ = flagged_tracers(tables, flags)
    all_ids = np.unique(tables.tracers["id"].astype(np.int64))
    kept = np.setdiff1d(all_ids, excluded)
    values = {"n_used": int(kept.size)}
    if excluded_by_optics and all(name in tables.tracers for name in OPTICS_COLUMNS["x"]):
        # an excluded tracer counts where it has an optics image, in any frame (none where
        # no ray reached the camera: its optics error is NaN and adds nothing)
        others = rows_of(tables.tracers, excluded)
        vectors = position_error_vectors(others, "opt", "opt_ref")
        imaged = np.isfinite(vectors[0]) & np.isfinite(vectors[1])
        values["n_used"] += int(np.unique(others["id"][imaged]).size)
    for path, group, component in HEADLINES:
        if group is None:
            tracers = tables.tracers
            have_optics = all(name in tracers for name in OPTICS_COLUMNS["x"])
            if excluded_by_optics and not have_optics:
                values[path] = None
                continue
            rows = rows_of(tracers, kept)
            error = position_error_vectors(rows, f"meas{suffix}", f"ref{suffix}")
            if excluded_by_optics:
                others = rows_of(tracers, excluded)
                optics = position_error_vectors(others, "opt", "opt_ref")
                error = tuple(np.concatenate(pair) for pair in zip(error, optics, strict=True))
            values[path] = _median_over_length(error, tables.length)
            continue
        table = getattr(tables, group)
        symbol = component[0]
        if (
            not table
            or (excluded_by_optics and not all(n in table for n in OPTICS_COLUMNS[symbol]))
            or (threshold is not None and flags not in table)
        ):
            values[path] = None
            continue
        rows = rows_of(table, kept)
        error = rows[f"{component}_meas{suffix}"] - rows[f"{component}_ref{suffix}"]
        truth = rows[f"{component}_true"]
        if excluded_by_optics:
            others = rows_of(table, excluded)
            error = np.concatenate(
                [error, others[f"{component}_opt"] - others[f"{component}_opt_ref"]]
            )
            truth = np.concatenate([truth, others[f"{component}_true"]])
        values[path] = _rms_ratio(error, truth)
    return values


def file_variants(tables):
    """The headline numbers of the :data:`FILE_VARIANTS` of one case (those whose columns
    the file has): ``{variant name: headline_values(...)}``."""
    variants = {EXCLUDED_BY_OPTICS: headline_values(tables, excluded_by_optics=True)}
    for name, suffix in THRESHOLD_NAMES.items():
        values = headline_values(tables, threshold=suffix)
        if values["n_used"] is not None:
            variants[name] = values
    return variants


def _lookup(case, path):
    node = case
    for name in path.split("."):
        node = node.get(name) if isinstance(node, dict) else None
    return node


def _interval(case, path):
    """The 95 % interval of the number at ``path``: ``<path>_ci95`` at the top level, else
    its block's ``ci95``, per statistic (a dict) or of the block's one statistic (a list)."""
    if "." not in path:
        return case.get(f"{path}_ci95")
    parent, key = path.rsplit(".", 1)
    block = _lookup(case, parent)
    interval = block.get("ci95") if isinstance(block, dict) else None
    return interval.get(key) if isinstance(interval, dict) else interval


def bands(case, variants, paths=None, measured=MEASURED_VARIANTS):
    """The verdict of each headline number of a case against its variants.

    Parameters
    ----------
    case : dict
        The case's ``stats.json`` entry (values and ``ci95``).
    variants : dict of str to dict
        ``{variant name: {path: value}}`` (:func:`headline_values`).
    paths : sequence of str, optional
        The headline numbers' dotted paths in ``case`` (default: those of
        :data:`HEADLINES`); each number's interval is its block's ``ci95``.
    measured : sequence of str
        The variants a run could measure again (default :data:`MEASURED_VARIANTS`): those
        not in ``variants`` are the band's ``not_run``.

    Returns
    -------
    dict of str to dict
        Per headline path: ``value``, ``ci95``, ``variants`` (``{name: value}``),
        ``relative`` (``{name: value / headline - 1}``), ``stable`` (every variant inside
        the interval; None without variants or value; False where a variant keeps no
        tracer), ``not_run`` (the :data:`MEASURED_VARIANTS` not measured: the band does
        not include them) and ``text`` ("stable" where no variant moves it by
        :data:`STILL_PERCENT`; "stable (X: +Y %)" naming the largest move inside the
        interval; either followed by "; not run: …" naming ``not_run``; "depends on X by
        +Y %"; "depends on X: it keeps no tracer"; or "n/a").
    """
    result = {}
    for path in [path for path, _, _ in HEADLINES] if paths is None else paths:
        value, interval = _lookup(case, path), _interval(case, path)
        found = {name: values.get(path) for name, values in variants.items()}
        found = {name: v for name, v in found.items() if v is not None}
        entry = {"value": value, "ci95": interval, "variants": found, "relative": {}}
        entry["not_run"] = [name for name in measured if name not in variants]
        # a variant that keeps no tracer has no number, and cannot leave it stable
        empty = [name for name, values in variants.items() if values.get("n_used") == 0]
        if value is not None and value and empty:
            entry.update(stable=False, text=f"depends on {empty[0]}: it keeps no tracer")
            result[path] = entry
            continue
        if value is None or not value or not found:
            entry.update(stable=None, text="n/a")
            result[path] = entry
            continue
        entry["relative"] = {name: v / value - 1.0 for name, v in found.items()}
        inside = interval is not None and all(
            interval[0] <= v <= interval[1] for v in found.values()
        )
        entry["stable"] = bool(inside)
        name = max(entry["relative"], key=lambda k: abs(entry["relative"][k]))
        move = 100 * entry["relative"][name]
        if not inside:
            entry["text"] = f"depends on {name} by {move:+.0f} %"
        else:
            # inside the interval, but how far the settings move it still shows, and a
            # band without the measured variants is stable only over what ran
            entry["text"] = (
                "stable" if abs(move) < STILL_PERCENT else f"stable ({name}: {move:+.0f} %)"
            )
            if entry["not_run"]:
                entry["text"] += f"; not run: {', '.join(entry['not_run'])}"
        result[path] = entry
    return result
