"""Render files with injected errors of known statistics, in the layout of ``rimcl render``.

Used by the statistics, figure and study tests to check the numbers against the errors
put in, independently of the measurement pipeline.
"""

import json

import h5py
import numpy as np

FLAG_NAMES = {
    "1": "below_threshold",
    "2": "split",
    "4": "window_edge",
    "16": "rays_failed",
    "128": "saturated",
}


def standardized(rng, size):
    """Normal draws shifted and scaled to sample mean 0 and sample std (ddof=1) 1 exactly."""
    draws = rng.standard_normal(size)
    return (draws - draws.mean()) / draws.std(ddof=1)


def write_render_file(
    path,
    case="C1",
    k_rho=2.82e-4,
    n_tracers=400,
    length=2.0,
    pixel_size=2.0 / 1024,
    dt=0.005,
    position_error_over_length=1e-4,
    position_log10_spread=0.3,
    velocity_bias=0.01,
    velocity_spread=0.05,
    acceleration_bias=0.5,
    acceleration_spread=3.0,
    flagged=None,
    noted=None,
    seed=0,
):
    """Write a render file whose errors have exactly the given statistics.

    Position errors ``|x_meas - x_ref|`` are log-normal: ``log10(|ε_x| / L)`` is normal
    with mean ``log10(position_error_over_length)`` and std ``position_log10_spread``
    (standardized draws, exact sample moments). Relative velocity errors
    ``(u_meas - u_ref) / u_true`` of both components are exactly ``velocity_bias`` in the
    mean and ``velocity_spread`` in the standard deviation (``ddof=1``); likewise the
    acceleration. The baseline ``u_ref - u_true`` is ``u_true / 100`` exactly.

    Parameters
    ----------
    flagged : dict of int to int, optional
        Tracer id to flag bits; those tracers get NaN errors (which must not reach the
        statistics).
    noted : dict of int to int, optional
        Tracer id to note bits (written to a ``notes`` column; the tracer stays valid).

    Returns
    -------
    dict
        The injected relative errors per column (``"u2"``, ...), for reference.
    """
    rng = np.random.default_rng(seed)
    flagged = flagged or {}
    noted = noted or {}
    ids = np.arange(n_tracers)
    frames = 3
    tracer_id = np.repeat(ids, frames)
    frame = np.tile(np.arange(frames), n_tracers)
    rows = tracer_id.size
    x_true = rng.uniform(0.0, length, size=(2, rows))
    x_ref = x_true + 1e-3 * pixel_size * rng.standard_normal((2, rows))
    spread = position_log10_spread * standardized(rng, rows)
    magnitude = length * position_error_over_length * 10.0**spread
    direction = rng.uniform(0.0, 2 * np.pi, rows)
    x_meas = x_ref + magnitude * np.array([np.cos(direction), np.sin(direction)])
    area_ref = np.full(rows, 80.0)
    area_meas = area_ref + np.round(40.0 * k_rho / 3.34e-1 * rng.uniform(0, 2, rows))
    row_flags = np.zeros(rows, dtype=np.int32)
    tracer_flags = np.zeros(n_tracers, dtype=np.int32)
    row_notes = np.zeros(rows, dtype=np.int32)
    tracer_notes = np.zeros(n_tracers, dtype=np.int32)
    for tracer, bits in noted.items():
        row_notes[tracer * frames + 2] = bits
        tracer_notes[tracer] = bits
    for tracer, bits in flagged.items():
        row_flags[tracer * frames + 1] = bits
        tracer_flags[tracer] = bits
        x_meas[:, tracer * frames + 1] = np.nan

    injected = {}

    def kinematic(symbol, bias, spread, scale):
        columns = {"id": ids, "flags": tracer_flags, "notes": tracer_notes}
        for component in ("2", "3"):
            truth = scale * rng.choice([-1.0, 1.0], n_tracers) * rng.uniform(0.5, 1.5, n_tracers)
            relative = bias + spread * standardized(rng, n_tracers)
            reference = truth * 1.01
            columns[f"{symbol}{component}_true"] = truth
            columns[f"{symbol}{component}_ref"] = reference
            columns[f"{symbol}{component}_meas"] = reference + relative * truth
            injected[f"{symbol}{component}"] = relative
        columns[f"{symbol}2_meas"][list(flagged)] = np.nan
        return columns

    velocity = kinematic("u", velocity_bias, velocity_spread, 1.0)
    acceleration = kinematic("a", acceleration_bias, acceleration_spread, 20.0)
    n_rays_sample = 500
    theta0 = rng.uniform(0.0, 0.9, n_rays_sample)
    n_metric = k_rho * 10.0 ** rng.uniform(-2, 0, n_rays_sample)
    path_length = length / np.cos(theta0)
    with h5py.File(path, "w") as h5:
        h5.attrs.update(
            rimcl_schema="render",
            schema_version=1,
            case=case,
            k_rho=k_rho,
            delta_n_max=0.085 * k_rho,
            length_L=length,
            pixel_size=pixel_size,
            dt=dt,
            flag_names=json.dumps(FLAG_NAMES),
            config=json.dumps({"case": case, "tracers": n_tracers, "seed": seed}),
            versions=json.dumps({"rimcl": "test"}),
            device=json.dumps({"device": "synthetic"}),
        )
        tracers = {
            "id": tracer_id,
            "frame": frame,
            "time": frame * dt,
            "x2_true": x_true[0],
            "x3_true": x_true[1],
            "x2_ref": x_ref[0],
            "x3_ref": x_ref[1],
            "x2_meas": x_meas[0],
            "x3_meas": x_meas[1],
            "area_ref": area_ref,
            "area_meas": area_meas,
            "perimeter_ref": np.full(rows, 32.0),
            "perimeter_meas": np.full(rows, 32.0),
            "circularity_ref": np.full(rows, 1.02),
            "circularity_meas": 1.02 + k_rho * rng.uniform(0, 1, rows),
            "n_rays": np.full(rows, 1024),
            "n_rays_ok": np.full(rows, 1024),
            "flags": row_flags,
            "notes": row_notes,
        }
        for group, columns in (
            ("tracers", tracers),
            ("velocity", velocity),
            ("acceleration", acceleration),
        ):
            for name, values in columns.items():
                h5.create_dataset(f"{group}/{name}", data=values)
        rays = {
            "theta0": theta0,
            "deflection": n_metric * path_length,
            "n_metric": n_metric,
            "path_length": path_length,
            "displacement": 0.5 * n_metric * path_length * length,
            "status": np.zeros(n_rays_sample, dtype=np.int8),
        }
        for name, values in rays.items():
            h5.create_dataset(f"rays/{name}", data=values)
        h5["rays"].attrs.update(
            count_ok=n_tracers * frames * 1024,
            count_exit_side=0,
            ref_count_ok=n_tracers * frames * 1024,
        )
    return injected
