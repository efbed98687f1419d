"""Per-tracer samples of render tables, shared by statistics and figures.

A render file (:func:`rimcl.stats.render_file.load_render`) holds one table per group (``tracers``,
``velocity``, ``acceleration``, ...), each a dict of equally long 1-D columns. The helpers
here pick the rows that count (no excluding flag on the tracer) and turn them into the error
samples both the statistics and the figures use, so the two never disagree on a number.
Nothing here imports either of those modules.
"""

import json
import math
from pathlib import Path

import numpy as np

from rimcl.core.atomic import atomic_path
from rimcl.core.provenance import to_json

#: Points of the grid on which kernel density estimates are evaluated to find a peak.
PEAK_GRID_POINTS = 1024
#: Optional per-row columns: bits that record an event without excluding the tracer.
NOTE_COLUMN = "notes"


def flagged_tracers(tables, column="flags"):
    """Tracers with bits set in a flag column, and the count per flag name.

    Parameters
    ----------
    tables : RenderTables
    column : {"flags", "notes"}
        ``flags``: bits that exclude a tracer; ``notes``: bits that are only counted (a
        file without a ``notes`` column has none).

    Returns
    -------
    ids : ndarray of int
        Sorted ids of the tracers with a bit set in any of their rows (any frame,
        any kinematic table).
    counts : dict of str to int
        Number of tracers carrying each bit (a tracer with two bits counts under both),
        for ``flags`` every known flag name (zeros included). Bits missing from
        ``flag_names`` are named ``bit<value>``.
    """
    tables_with = [t for t in tables.all_tables() if column in t]
    ids = np.concatenate([t["id"] for t in tables_with] or [np.empty(0)]).astype(np.int64)
    bits = np.concatenate([t[column] for t in tables_with] or [np.empty(0)]).astype(np.int64)
    counts = {name: 0 for name in tables.flag_names.values()} if column == "flags" else {}
    seen_bits = int(np.bitwise_or.reduce(bits)) if bits.size else 0
    bit = 1
    while bit <= seen_bits:
        if seen_bits & bit:
            name = tables.flag_names.get(bit, f"bit{bit}")
            counts[name] = int(np.unique(ids[(bits & bit) != 0]).size)
        bit <<= 1
    return np.unique(ids[bits != 0]), counts


def rows_of(table, tracer_ids):
    """The rows of a table that belong to the given tracers (all columns, order kept)."""
    keep = np.isin(table["id"].astype(np.int64), tracer_ids)
    return {name: values[keep] for name, values in table.items()}


def kept_rows(tables, table):
    """The rows of ``table`` (a group of ``tables``) whose tracer carries no excluding flag."""
    excluded_ids, _ = flagged_tracers(tables)
    keep = ~np.isin(table["id"].astype(np.int64), excluded_ids)
    return {name: values[keep] for name, values in table.items()}


def first_frame_rows(table):
    """Rows of the earliest frame of a table (all rows when it has no ``frame`` column)."""
    if "frame" not in table or table["frame"].size == 0:
        return table
    first = table["frame"] == np.min(table["frame"])
    return {name: values[first] for name, values in table.items()}


def position_errors(tracers, length, measured="meas", reference="ref"):
    """``|x_measured - x_reference| / L`` per row of a tracer table.

    Parameters
    ----------
    tracers : dict of str to ndarray
        Columns ``x2_<kind>``, ``x3_<kind>`` (field length units).
    length : float
        The depth ``L`` (field length units).
    measured, reference : str
        Column suffixes compared: ``meas`` and ``ref`` (the total refraction error),
        ``opt`` and ``opt_ref`` (the optics part).

    Returns
    -------
    ndarray, shape (rows,)
    """
    return np.hypot(*position_error_vectors(tracers, measured, reference)) / length


def position_error_vectors(tracers, measured="meas", reference="ref"):
    """``(ε_2, ε_3) = x_measured - x_reference`` per row (field length units)."""
    return tuple(tracers[f"x{c}_{measured}"] - tracers[f"x{c}_{reference}"] for c in ("2", "3"))


def area_changes(tracers):
    """``ΔA / A = (A' - A^ref) / A^ref`` per row with a non-empty reference image."""
    area_ref = tracers["area_ref"].astype(np.float64)
    usable = area_ref > 0
    return (tracers["area_meas"][usable] - area_ref[usable]) / area_ref[usable]


def angle_deg(first, second):
    """Angle between 2-D vectors, in degrees, exactly 0 for identical vectors.

    Parameters
    ----------
    first, second : tuple of two ndarray
        Components ``(v2, v3)`` of each vector, arrays of the same shape.

    Returns
    -------
    ndarray
        Angle in ``[0, 180]`` degrees (``atan2(|a x b|, a . b)``, accurate at small angles).
    """
    cross = first[0] * second[1] - first[1] * second[0]
    dot = first[0] * second[0] + first[1] * second[1]
    return np.degrees(np.arctan2(np.abs(cross), dot))


def density_estimate(values, log=False, points=PEAK_GRID_POINTS):
    """Gaussian kernel density estimate of a sample on a regular grid.

    The bandwidth follows Scott's rule, so the estimate of ``c * values`` (with ``log``)
    is the estimate of ``values`` shifted by ``log10(c)``: the peak scales exactly.

    Parameters
    ----------
    values : array_like, 1-D
        The sample; with ``log`` only its positive values are used.
    log : bool
        Estimate the density of ``log10(values)``.
    points : int
        Grid points.

    Returns
    -------
    grid : ndarray, shape (points,) or (1,) or (0,)
        Where the density is given (``values`` units, not their log, also with ``log``).
    density : ndarray, same shape
        PDF of ``values`` (or of ``log10(values)`` with ``log``), integrating to 1 over
        the grid variable. A sample with a single distinct value (a point mass) gives
        that value alone, with density 1; an empty sample gives empty arrays.
    """
    from scipy.stats import gaussian_kde

    sample = np.asarray(values, dtype=np.float64).ravel()
    sample = sample[np.isfinite(sample)]
    if log:
        sample = np.log10(sample[sample > 0])
    if sample.size == 0:
        return np.empty(0), np.empty(0)
    if np.ptp(sample) == 0:
        grid = sample[:1]
        return (10.0**grid if log else grid), np.ones(1)
    kde = gaussian_kde(sample)
    bandwidth = math.sqrt(float(kde.covariance[0, 0]))
    grid = np.linspace(sample.min() - 3 * bandwidth, sample.max() + 3 * bandwidth, points)
    density = kde(grid)
    return (10.0**grid if log else grid), density


def write_json(path, document, overwrite=True):
    """Write a JSON document atomically (NumPy values made plain, NaN refused).

    Parameters
    ----------
    path : str or Path
    document : dict
    overwrite : bool
    """
    text = json.dumps(json.loads(to_json(document)), indent=2, allow_nan=False)
    with atomic_path(path, overwrite=overwrite) as tmp:
        Path(tmp).write_text(text + "\n")
