"""The Δt sweep: the same study's errors at multiples of its frame spacing.

A study images ``F`` frames ``Δt`` apart; every ``m``-th of them is a measurement with
frames ``m Δt`` apart. The velocity and acceleration tables (the paper's differences and
the sliding fit) are rebuilt from the positions of those frames alone, so a
sweep costs no tracing: each multiple gives a ``stats.json`` document, and the figure of
:func:`rimcl.stats.figures_dt_sweep.write_dt_sweep_figure` shows at which Δt refraction rises
above the baseline (finite differences, rendering and rounding) and above the noise floor
(two independent exposures through the uniform medium).
"""

import dataclasses

import numpy as np

from rimcl.imaging.frames import THRESHOLD_VARIANTS
from rimcl.ptv.kinematics import add_variant_columns, kinematics_tables
from rimcl.scene.config import TimeConfig

#: Position kinds of a render file's ``tracers`` table (columns ``x2_<kind>``, ``x3_<kind>``).
KINDS = ("true", "ref", "meas", "opt", "opt_ref", "floor")


def _by_frame(column, frames):
    return np.asarray(column).reshape(frames, -1)


def every_mth_frame(tables, multiple, time_config):
    """Render tables of a study case as if imaged every ``multiple``-th frame.

    Parameters
    ----------
    tables : rimcl.stats.render_file.RenderTables
    multiple : int
        ``m >= 1``; frames ``0, m, 2m, …`` are kept, ``m Δt`` apart.
    time_config : rimcl.scene.config.TimeConfig
        The fit window and order (the fitted tables need as many kept frames).

    Returns
    -------
    rimcl.stats.render_file.RenderTables or None
        None when fewer than 2 frames are left.
    """
    tracers = tables.tracers
    frames = len(np.unique(tracers["frame"]))
    kept = np.arange(0, frames, int(multiple))
    if len(kept) < 2 or "u2_true" not in tracers:
        return None
    columns = {name: _by_frame(values, frames)[kept] for name, values in tracers.items()}
    positions = {
        kind: np.stack([columns[f"x2_{kind}"], columns[f"x3_{kind}"]], axis=-1)
        for kind in KINDS
        if f"x2_{kind}" in columns
    }
    truth = {
        name: np.stack([columns[f"{symbol}2_true"], columns[f"{symbol}3_true"]], axis=-1)
        for name, symbol in (("velocity", "u"), ("acceleration", "a"))
    }
    dt = float(tables.dt) * int(multiple)
    kinematics = kinematics_tables(
        columns["id"][0],
        positions,
        truth,
        columns["flags"],
        columns["notes"],
        dt,
        time_config,
    )
    for suffix, _ in THRESHOLD_VARIANTS:
        # the tracers located at the other thresholds: their kinematics at this Δt too, as
        # the measurement makes them (rimcl.ptv.measure)
        if f"flags_{suffix}" not in columns:
            continue
        variant = {"true": positions["true"]}
        for kind in ("ref", "meas"):
            variant[kind] = np.stack(
                [columns[f"x2_{kind}_{suffix}"], columns[f"x3_{kind}_{suffix}"]], axis=-1
            )
        variant_tables = kinematics_tables(
            columns["id"][0],
            variant,
            truth,
            columns[f"flags_{suffix}"],
            columns["notes"],
            dt,
            time_config,
        )
        add_variant_columns(kinematics, variant_tables, suffix)
    return dataclasses.replace(
        tables,
        dt=dt,
        tracers={name: values.reshape(-1) for name, values in columns.items()},
        **{name: table or {} for name, table in kinematics.items()},
    )


def sweep_stats(all_tables, multiples, time, compute):
    """``stats.json`` documents of a study at every multiple of its frame spacing.

    Parameters
    ----------
    all_tables : list of rimcl.stats.render_file.RenderTables
        The study's cases.
    multiples : sequence of int
        ``m`` values (``time.dt_multiples``).
    time : rimcl.scene.config.TimeConfig
        The study's (its fit window and order).
    compute : callable
        ``compute(list of RenderTables) -> stats document``
        (:func:`rimcl.stats.document.compute_stats`).

    Returns
    -------
    dict of float to dict
        Δt → the stats document of the cases imaged that far apart (multiples that leave
        fewer than 2 frames are skipped).
    """
    time_config = TimeConfig(frames=1, fit_window=time.fit_window, fit_order=time.fit_order)
    documents = {}
    for multiple in sorted(set(int(m) for m in multiples)):
        strided = [every_mth_frame(t, multiple, time_config) for t in all_tables]
        if any(t is None for t in strided):
            continue
        documents[float(strided[0].dt)] = compute(strided)
    return documents
