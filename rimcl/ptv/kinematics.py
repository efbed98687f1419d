"""Velocity and acceleration tables of a measurement, from its tracer positions per frame.

:func:`kinematics_tables` gives, for every kind of position (true, reference, measured,
optical centroids), the paper's finite differences and a sliding polynomial fit, each row
carrying the union of the flags of the frames its estimate uses.
"""

import numpy as np

from rimcl.ptv.track import second_differences, sliding_fit


def _frame_rows(ids, frames_used, columns, flags, notes, window):
    """One table of per-tracer estimates at evaluation frames, frame-major.

    ``columns`` maps a name to an ``(M, N)`` array over the ``M`` evaluation frames
    ``frames_used``; each row's flags and notes are the union over the ``window`` frames
    its estimate uses, starting at ``frames_used - offset`` (see :func:`kinematics_tables`).
    """
    frames_used = np.asarray(frames_used)
    first_frames, span = window
    union = np.stack([np.bitwise_or.reduce(flags[f : f + span], axis=0) for f in first_frames])
    union_notes = np.stack(
        [np.bitwise_or.reduce(notes[f : f + span], axis=0) for f in first_frames]
    )
    count = len(ids)
    table = {
        "id": np.tile(ids, len(frames_used)),
        "frame": np.repeat(frames_used, count),
    }
    table.update({name: values.reshape(-1) for name, values in columns.items()})
    table["flags"] = union.reshape(-1)
    table["notes"] = union_notes.reshape(-1)
    return table


def kinematics_tables(ids, positions, truth, flags, notes, dt, time_config):
    """Velocity and acceleration tables of every position kind.

    Parameters
    ----------
    ids : ndarray, shape (N,)
        Tracer ids.
    positions : dict of str to ndarray (F, N, 2)
        Positions per kind (``true``, ``ref``, ``meas``, ``opt``, ``opt_ref``).
    truth : dict
        ``velocity`` and ``acceleration``, each ``(F, N, 2)``: ``u`` and ``Du/Dt`` along
        the true tracks.
    flags, notes : ndarray, int, shape (F, N)
    dt : float
        Frame spacing (time units).
    time_config : rimcl.scene.config.TimeConfig
        The fit window and order.

    ``velocity``: the paper's forward difference ``(x_{k+1} - x_k)/Δt`` at frames
    ``0 … F-2``, truth ``u(x_k, t_k)``; ``acceleration``: the second difference at frames
    ``1 … F-2``, truth the same difference of the true positions (the paper's);
    ``velocity_fit``, ``acceleration_fit``: a sliding polynomial fit over ``fit_window``
    frames at each window centre, truth ``u`` and ``Du/Dt`` there. Tables a run has too
    few frames for are None.
    """
    frames = len(flags)
    measured = {k: v for k, v in positions.items() if k != "true"}
    tables = dict.fromkeys(("velocity", "acceleration", "velocity_fit", "acceleration_fit"))
    if frames >= 2:
        columns = {}
        for kind, track in measured.items():
            u = (track[1:] - track[:-1]) / dt
            columns[f"u2_{kind}"], columns[f"u3_{kind}"] = u[..., 0], u[..., 1]
        u = truth["velocity"][:-1]
        columns["u2_true"], columns["u3_true"] = u[..., 0], u[..., 1]
        used = np.arange(frames - 1)
        tables["velocity"] = _frame_rows(ids, used, columns, flags, notes, (used, 2))
    if frames >= 3:
        columns = {}
        for kind, track in positions.items():
            a = second_differences(track, dt)
            columns[f"a2_{kind}"], columns[f"a3_{kind}"] = a[..., 0], a[..., 1]
        used = np.arange(1, frames - 1)
        tables["acceleration"] = _frame_rows(ids, used, columns, flags, notes, (used - 1, 3))
    window, order = int(time_config.fit_window), int(time_config.fit_order)
    if frames >= window:
        u_columns, a_columns = {}, {}
        centres = None
        for kind, track in measured.items():
            fit = sliding_fit(track, dt, window, order)
            centres = fit.centres
            u_columns[f"u2_{kind}"], u_columns[f"u3_{kind}"] = fit.velocity.transpose(2, 0, 1)
            a_columns[f"a2_{kind}"], a_columns[f"a3_{kind}"] = fit.acceleration.transpose(2, 0, 1)
        u, a = truth["velocity"][centres], truth["acceleration"][centres]
        u_columns["u2_true"], u_columns["u3_true"] = u[..., 0], u[..., 1]
        a_columns["a2_true"], a_columns["a3_true"] = a[..., 0], a[..., 1]
        span = (centres - window // 2, window)
        tables["velocity_fit"] = _frame_rows(ids, centres, u_columns, flags, notes, span)
        tables["acceleration_fit"] = _frame_rows(ids, centres, a_columns, flags, notes, span)
    return tables


def add_variant_columns(tables, variant_tables, suffix):
    """Join a variant's reference and measured estimates and flags to the main tables.

    Parameters
    ----------
    tables : dict
        :func:`kinematics_tables` of the measurement; its tables gain the columns
        ``<q>_ref_<suffix>``, ``<q>_meas_<suffix>`` and ``flags_<suffix>``.
    variant_tables : dict
        :func:`kinematics_tables` of the same tracers and frames located another way
        (the same rows in the same order).
    suffix : str
    """
    for group, table in tables.items():
        if table is None:
            continue
        variant = variant_tables[group]
        for name, values in variant.items():
            if name.endswith(("_ref", "_meas")) or name == "flags":
                table[f"{name}_{suffix}"] = values
