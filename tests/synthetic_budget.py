"""Render files with the optics columns and multi-frame kinematic groups, errors known.

Builds on :func:`synthetic_render.write_render_file` (no OpenCL): the file it writes gets

- the optics columns of the error budget: ``x_opt - x_opt_ref`` is exactly ``optics_share``
  times the total position error ``x_meas - x_ref`` of every row, and likewise for the
  velocity and acceleration, so the optics summaries are the total's times the share and
  the imaging summaries the total's times ``1 - share``;
- optionally ``velocity_fit`` and ``acceleration_fit`` groups with a ``frame`` column (one
  row per tracer and evaluation frame), whose relative errors have exactly the given mean
  and spread and whose baseline ``u_ref - u_true`` is exactly ``fit_baseline`` times the
  truth.
"""

import h5py
import numpy as np
from synthetic_render import standardized, write_render_file


def add_optics_columns(path, optics_share=0.25):
    """Write the ``*_opt`` and ``*_opt_ref`` columns into an existing render file.

    The uniform-medium optics position is the tracer itself (``x_opt_ref = x_true``) and
    ``x_opt = x_opt_ref + share · (x_meas - x_ref)``; the kinematic groups the same way
    about the true values.
    """
    with h5py.File(path, "a") as h5:
        for group, symbol in (("tracers", "x"), ("velocity", "u"), ("acceleration", "a")):
            table = h5[group]
            for component in ("2", "3"):
                true = table[f"{symbol}{component}_true"][()]
                total = (
                    table[f"{symbol}{component}_meas"][()] - table[f"{symbol}{component}_ref"][()]
                )
                table[f"{symbol}{component}_opt_ref"] = true
                table[f"{symbol}{component}_opt"] = true + optics_share * total


def add_fit_groups(
    path,
    frames=4,
    bias=0.002,
    spread=0.01,
    fit_baseline=0.001,
    seed=3,
):
    """Write ``velocity_fit`` and ``acceleration_fit`` with ``frames`` rows per tracer.

    Returns
    -------
    dict
        The injected relative errors per column (``"u3"``, ``"a3"``, ...), row order.
    """
    rng = np.random.default_rng(seed)
    injected = {}
    with h5py.File(path, "a") as h5:
        ids = np.unique(h5["tracers/id"][()])
        row_ids = np.repeat(ids, frames)
        for group, symbol, scale in (("velocity_fit", "u", 1.0), ("acceleration_fit", "a", 20.0)):
            columns = {
                "id": row_ids,
                "frame": np.tile(np.arange(frames), ids.size),
                "flags": np.zeros(row_ids.size, dtype=np.int32),
            }
            for component in ("2", "3"):
                truth = scale * rng.choice([-1.0, 1.0], row_ids.size)
                truth *= rng.uniform(0.5, 1.5, row_ids.size)
                relative = bias + spread * standardized(rng, row_ids.size)
                reference = truth * (1.0 + fit_baseline)
                columns[f"{symbol}{component}_true"] = truth
                columns[f"{symbol}{component}_ref"] = reference
                columns[f"{symbol}{component}_meas"] = reference + relative * truth
                injected[f"{symbol}{component}"] = relative
            for name, values in columns.items():
                h5.create_dataset(f"{group}/{name}", data=values)
    return injected


def write_budget_file(path, optics_share=0.25, fit_frames=None, **render_options):
    """A synthetic render file with the optics columns (and fit groups with ``fit_frames``).

    Returns
    -------
    dict
        ``{"total": <injected of write_render_file>, "fit": <injected of add_fit_groups>}``.
    """
    injected = {"total": write_render_file(path, **render_options)}
    add_optics_columns(path, optics_share)
    if fit_frames:
        injected["fit"] = add_fit_groups(path, frames=fit_frames)
    return injected
