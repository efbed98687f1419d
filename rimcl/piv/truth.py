"""The ground truth of a PIV render, and its files.

The true in-plane displacement of the tracers, weighted by ``I_A · I_B`` and averaged over
each interrogation window (:func:`true_displacement`).

Files (:func:`write_piv_render`, of a
:class:`rimcl.piv.render.PivRender`): ``<prefix>_field_A.tif``, ``<prefix>_field_B.tif``,
``<prefix>_uniform_A.tif``, ``<prefix>_uniform_B.tif`` (16-bit TIFF) and
``<prefix>_truth.h5`` (``rimcl_schema = "piv_truth"``, ``schema_version = 2``): per tracer
and exposure (``(id, frame)`` datasets, ``frame`` A and B), positions (``x1, x2, x3``, length
units, and ``col, row``, pixels), sheet intensities and the light-weighted mean image points
of its collected rays per medium; the true displacement averaged over each interrogation
window of the final PIV grid (``(row, column)``, px; in m/s too where the field's scales are
known); the motion model (root attribute ``motion``), the scales, the configuration and
versions. Every dataset has named dimensions and ``units``, for ``xarray.open_dataset``.
"""

import math
from pathlib import Path

import h5py
import numpy as np

from rimcl.core.atomic import atomic_paths, check_output
from rimcl.core.provenance import stamp_h5
from rimcl.core.tables_h5 import TRACER_DIMENSIONS, add_scale, label_grid, write_variable
from rimcl.piv.analysis import vector_unit, write_tiff
from rimcl.piv.imaging_config import frame_pixels, sheet_intensity

TRUTH_SCHEMA = "piv_truth"
#: 2: particles as (id, frame) datasets, named dimensions and units (1: a dataset per exposure)
TRUTH_SCHEMA_VERSION = 2
MEDIA = ("field", "uniform")


def window_means(grid, col, row, values, weights):
    """Weighted means of per-tracer values over each interrogation window.

    A tracer belongs to window ``(r, c)`` when it lies on the window's pixels:
    ``cols[c] - 1/2 <= col < cols[c] + size - 1/2`` and the same for rows (pixel centres
    at integer coordinates; overlapping windows share tracers).

    Parameters
    ----------
    grid : rimcl.piv.analysis.WindowGrid
    col, row : ndarray, shape (N,)
        Tracer positions in frame pixels (:func:`rimcl.piv.imaging_config.frame_pixels`).
    values : ndarray, shape (N, K)
    weights : ndarray, shape (N,)
        Non-negative; rows with a non-finite value or weight are left out.

    Returns
    -------
    means : ndarray, float64, shape (rows, columns, K)
        NaN for a window without weight.
    total : ndarray, float64, shape (rows, columns)
        Sum of the weights in each window.
    """
    values = np.asarray(values, dtype=np.float64)
    weights = np.asarray(weights, dtype=np.float64)
    # pixel j spans [j - 1/2, j + 1/2): measure from the pixels' outer edges
    col, row = np.asarray(col) + 0.5, np.asarray(row) + 0.5
    usable = np.isfinite(col) & np.isfinite(row) & np.isfinite(weights)
    usable &= np.all(np.isfinite(values), axis=1)
    col, row, values, weights = col[usable], row[usable], values[usable], weights[usable]
    n_rows, n_cols = grid.shape
    spacing = grid.spacing
    sums = np.zeros((n_rows * n_cols, values.shape[1]))
    total = np.zeros(n_rows * n_cols)
    reach = math.ceil(grid.size / spacing)
    base_c = np.floor((col - grid.cols[0]) / spacing).astype(np.int64)
    base_r = np.floor((row - grid.rows[0]) / spacing).astype(np.int64)
    # a tracer lies in at most ceil(size / spacing) windows along each axis, the ones whose
    # corners are at most ``size`` before it
    for back_r in range(reach):
        r = base_r - back_r
        in_r = (r >= 0) & (r < n_rows)
        in_r &= row >= grid.rows[np.clip(r, 0, n_rows - 1)]
        in_r &= row < grid.rows[np.clip(r, 0, n_rows - 1)] + grid.size
        for back_c in range(reach):
            c = base_c - back_c
            inside = in_r & (c >= 0) & (c < n_cols)
            inside &= col >= grid.cols[np.clip(c, 0, n_cols - 1)]
            inside &= col < grid.cols[np.clip(c, 0, n_cols - 1)] + grid.size
            flat = (r * n_cols + c)[inside]
            total += np.bincount(flat, weights=weights[inside], minlength=total.size)
            for k in range(values.shape[1]):
                sums[:, k] += np.bincount(
                    flat, weights=weights[inside] * values[inside, k], minlength=total.size
                )
    with np.errstate(invalid="ignore", divide="ignore"):
        means = np.where(total[:, None] > 0, sums / total[:, None], np.nan)
    return means.reshape(n_rows, n_cols, -1), total.reshape(n_rows, n_cols)


def pair_weights(positions, x_sheet, thickness):
    """Weight of each tracer in a window average: ``I_A · I_B`` (its correlation share)."""
    intensity = sheet_intensity(positions[..., 0], x_sheet, thickness)
    return intensity[0] * intensity[1]


def true_displacement(positions, renderer, shape, grid, weights):
    """The true in-plane displacement averaged over each interrogation window (pixels).

    Tracers are assigned to windows by the midpoint of their two true image positions (a
    deformed window measures the displacement at its centre, central-difference).

    Parameters
    ----------
    positions : ndarray, shape (2, N, 3)
    renderer : rimcl.imaging.render.Renderer
        Maps ``(x2, x3)`` to pixels.
    shape : (int, int)
        Frame ``(rows, columns)``.
    grid : rimcl.piv.analysis.WindowGrid
        The final-pass windows.
    weights : ndarray, shape (N,)

    Returns
    -------
    dict
        ``x, y`` (window centres, px, shape (rows, columns)), ``dx, dy`` (px, ``dy > 0``
        down the frame; NaN for an empty window), ``weight`` (sum of the weights) and
        ``tracers`` (count of tracers with weight above 1e-3 whose midpoint is in the
        window).
    """
    pixels = frame_pixels(renderer, shape, positions[..., 1:])
    middle = 0.5 * (pixels[0] + pixels[1])
    motion = pixels[1] - pixels[0]
    means, total = window_means(grid, middle[:, 0], middle[:, 1], motion, weights)
    bright = (weights > 1e-3).astype(np.float64)
    _, count = window_means(grid, middle[:, 0], middle[:, 1], np.zeros((len(bright), 1)), bright)
    x, y = np.meshgrid(grid.x.astype(np.float64), grid.y.astype(np.float64))
    return {
        "x": x,
        "y": y,
        "dx": means[..., 0],
        "dy": means[..., 1],
        "weight": total,
        "tracers": count.astype(np.int64),
    }


def output_paths(prefix):
    """The files :func:`write_piv_render` writes for ``prefix``, by role.

    Returns
    -------
    dict of str to Path
        ``field_A``, ``field_B``, ``uniform_A``, ``uniform_B`` (TIFF) and ``truth`` (HDF5).
    """
    prefix = Path(prefix)
    paths = {
        f"{medium}_{frame}": prefix.with_name(f"{prefix.name}_{medium}_{frame}.tif")
        for medium in MEDIA
        for frame in "AB"
    }
    paths["truth"] = prefix.with_name(f"{prefix.name}_truth.h5")
    return paths


def check_outputs(prefix, overwrite=False, inputs=()):
    """Refuse, before any work, outputs that exist (unless ``overwrite``), cannot be
    written, or are one of ``inputs`` (the run's input files)."""
    for path in output_paths(prefix).values():
        check_output(path, overwrite, inputs)


def write_piv_render(prefix, result, overwrite=True):
    """Write the four TIFF frames and the ground-truth HDF5 file of a :class:`PivRender`,
    as one set: all five are renamed into place once all are written, so a failure leaves
    the files of an earlier run whole (:func:`rimcl.core.atomic.atomic_paths`).

    Parameters
    ----------
    prefix : str or Path
        Path prefix; see :func:`output_paths`.
    result : PivRender
    overwrite : bool

    Returns
    -------
    dict of str to Path
    """
    paths = output_paths(prefix)
    with atomic_paths(paths, overwrite) as temps:
        _write_set(temps, result)
    return paths


def _write_set(paths, result):
    """The five files of :func:`write_piv_render` at ``paths`` (temporary names)."""
    frames = {"field": result.field, "uniform": result.uniform}
    for medium, pair in frames.items():
        for index, frame in enumerate("AB"):
            write_tiff(paths[f"{medium}_{frame}"], pair.images[index], result.config)
    reference = result.reference
    shape = result.imaging.frame_shape(result.scene, result.camera)
    pixels = frame_pixels(result.renderer, shape, reference.positions[..., 1:])
    thickness = result.imaging.thickness(result.scene, result.camera)
    with h5py.File(paths["truth"], "w") as h5:
        h5.attrs["rimcl_schema"] = TRUTH_SCHEMA
        h5.attrs["schema_version"] = TRUTH_SCHEMA_VERSION
        h5.attrs["case"] = result.case
        h5.attrs["k_rho"] = result.k_rho
        h5.attrs["delta_n_max"] = result.delta_n_max
        h5.attrs["dt"] = result.dt
        h5.attrs["pixel_size"] = result.pixel_size
        h5.attrs["motion"] = result.motion
        h5.attrs["coordinates"] = (
            "positions x1, x2, x3 in field length units; col, row in pixels of the TIFF "
            "frames: row 0 at the top (highest x3), columns along x2, pixel centres at "
            "integer coordinates (pixel (row i, column j) centred at col = j, row = i); "
            "truth dx along columns, dy along rows (dy > 0: down the frame, towards lower x3)"
        )
        m_s_per_px = result.m_s_per_px
        for name in ("length_m", "time_s"):
            if result.config.get(name) is not None:
                h5.attrs[name] = float(result.config[name])
        if m_s_per_px is not None:
            h5.attrs["m_s_per_px"] = m_s_per_px
        # per tracer and exposure: (id, frame[, axis]) datasets with named dimensions
        particles = h5.create_group("particles")
        add_scale(particles, "id", np.arange(reference.positions.shape[1]))
        add_scale(particles, "frame", ["A", "B"])
        add_scale(particles, "axis", ["x1", "x2", "x3"])
        add_scale(particles, "image_axis", ["x2", "x3"])
        intensity = sheet_intensity(reference.positions[..., 0], result.scene.x_sheet, thickness)
        columns = {
            "position": (reference.positions, "axis", "L0"),
            "col": (pixels[..., 0], None, "px"),
            "row": (pixels[..., 1], None, "px"),
            "intensity": (intensity, None, "1"),
        }
        for medium, pair in frames.items():
            columns[f"image_point_{medium}"] = (pair.optics, "image_axis", "L0")
            columns[f"rays_collected_{medium}"] = (pair.collected, None, "1")
        for name, (values, last, units) in columns.items():
            dimensions = (*TRACER_DIMENSIONS, last) if last else TRACER_DIMENSIONS
            write_variable(particles, name, np.swapaxes(values, 0, 1), dimensions, units)
        truth = h5.create_group("truth")
        for name, values in reference.truth.items():
            truth[name] = values
        if m_s_per_px is not None:  # along image columns and rows, as dx and dy
            truth["u_ms"] = reference.truth["dx"] * m_s_per_px
            truth["v_ms"] = reference.truth["dy"] * m_s_per_px
        truth.attrs["definition"] = (
            "true in-plane displacement B - A (px), weighted by I_A * I_B, averaged over the "
            "tracers whose midpoint image position lies in the final interrogation window; "
            "u_ms, v_ms: the same in m/s"
        )
        x, y = reference.truth["x"], reference.truth["y"]
        label_grid(truth, y[:, 0], x[0, :], vector_unit)
        for medium, pair in frames.items():
            group = h5.create_group(f"rays_{medium}")
            for name, value in pair.ray_counts.items():
                group.attrs[name] = value
            group.attrs["saturated_pixels"] = np.asarray(pair.saturated_pixels)
        stamp_h5(h5, result.config, result.device)
