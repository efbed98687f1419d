"""Summary of a field file: grid, frames, value ranges, memory, Δn_max per case."""

import numpy as np

from rimcl.flow.cases import CASE_FLUIDS, CASES, PAPER_DELTA_N_MAX
from rimcl.flow.fieldfile import FieldFile

# bytes per voxel of a frame held as a Field: δn + ∇n as float4 (trilinear, texture),
# and one float of B-spline coefficients (bspline3)
_BYTES_TRILINEAR = 16
_BYTES_BSPLINE = 4


def describe_field_file(path):
    """Grid, frames, ranges, memory needs and Δn_max per case of a field file.

    Parameters
    ----------
    path : str or Path

    Returns
    -------
    dict
        Plain data (JSON-ready). ``delta_n_max`` maps each case ``C0`` … ``C4`` to
        ``G (max ρ - min ρ)`` over all frames, next to the paper's value, for density
        files; for ``delta_n`` files it holds the stored range.
    """
    with FieldFile(path) as ff:
        n3, n2, n1 = ff.shape
        voxels = n1 * n2 * n3
        extent = ff.spacing * (np.array([n1, n2, n3]) - (0 if ff.boundary == "periodic" else 1))
        frames = []
        for k in range(ff.n_frames):
            if ff.kind == "density":
                values = ff.density(k)
            else:
                values = ff.delta_n(k)[0]
            frame = {
                "frame": k,
                "time": float(ff.times[k]),
                "min": float(values.min()),
                "max": float(values.max()),
                "mean": float(values.mean(dtype=np.float64)),
                "std": float(values.std(dtype=np.float64)),
            }
            if ff.has_velocity:
                # a sheet-only file has (u2, u3) on its plane: rms of those two
                if ff.has_full_velocity:
                    velocity = ff.velocity(k).astype(np.float64)
                else:
                    velocity = ff.sheet_velocity(ff.times[k], ff.velocity_sheet_x1)
                components = velocity.reshape(-1, velocity.shape[-1])
                frame["velocity_rms"] = np.sqrt(np.mean(components**2, axis=0)).tolist()
                frame["speed_max"] = float(np.sqrt(np.max(np.sum(components**2, axis=-1))))
            frames.append(frame)
        velocity_bytes = 0
        if ff.has_full_velocity:
            velocity_bytes = voxels * 12
        elif ff.has_velocity:
            velocity_bytes = n3 * n2 * 8
        spread = max(f["max"] for f in frames) - min(f["min"] for f in frames)
        if ff.kind == "density":
            delta_n_max = {
                name: {"k_rho": g, "delta_n_max": g * spread, "paper": PAPER_DELTA_N_MAX[name]}
                for name, g in CASES.items()
            }
        else:
            delta_n_max = {"stored": {"delta_n_max": spread}}
        return {
            "path": str(ff.path),
            "title": ff.attrs.get("title", ""),
            "source": ff.attrs.get("source", ""),
            "kind": ff.kind,
            "shape_n3_n2_n1": [n3, n2, n1],
            "spacing": ff.spacing.tolist(),
            "origin": ff.origin.tolist(),
            "extent": extent.tolist(),
            "boundary": ff.boundary,
            "n_frames": ff.n_frames,
            "times": ff.times.tolist(),
            "has_velocity": ff.has_velocity,
            "velocity_sheet_x1": None if ff.has_full_velocity else ff.velocity_sheet_x1,
            "has_density_gradient": ff.has_density_gradient,
            "frames": frames,
            "file_bytes": ff.path.stat().st_size,
            "memory_bytes_per_frame": {
                "field_trilinear": voxels * _BYTES_TRILINEAR,
                "field_bspline3": voxels * _BYTES_BSPLINE,
                "velocity": velocity_bytes,
            },
            "delta_n_max": delta_n_max,
        }


def _mib(count):
    return f"{count / 2**20:.1f} MiB"


def format_description(info):
    """Human-readable text of :func:`describe_field_file`'s result."""
    n3, n2, n1 = info["shape_n3_n2_n1"]
    sheet = info.get("velocity_sheet_x1")
    velocity_header = ""
    if sheet is not None:
        velocity_header = "  sheet velocity rms (x2, x3)   |u|max"
    elif info["has_velocity"]:
        velocity_header = "  velocity rms (x1, x2, x3)     |u|max"
    lines = [
        f"{info['path']}",
        f"  title     {info['title'] or '-'}",
        f"  source    {info['source'] or '-'}",
        f"  grid      n1 x n2 x n3 = {n1} x {n2} x {n3}, boundary {info['boundary']}",
        "  spacing   " + ", ".join(f"{h:.6g}" for h in info["spacing"]) + "  (x1, x2, x3)",
        "  origin    " + ", ".join(f"{o:.6g}" for o in info["origin"]),
        "  extent    " + ", ".join(f"{e:.6g}" for e in info["extent"]),
        f"  frames    {info['n_frames']}, times "
        + ", ".join(f"{t:.6g}" for t in info["times"][:8])
        + (" ..." if info["n_frames"] > 8 else ""),
        f"  holds     {info['kind']}"
        + (" + density_gradient" if info["has_density_gradient"] else "")
        + (" + velocity" if info["has_velocity"] and sheet is None else "")
        + (f" + velocity_sheet (u2, u3 on x1 = {sheet:g})" if sheet is not None else ""),
        f"  memory    file {_mib(info['file_bytes'])}; per frame as a field: "
        f"{_mib(info['memory_bytes_per_frame']['field_trilinear'])} (trilinear), "
        f"{_mib(info['memory_bytes_per_frame']['field_bspline3'])} (bspline3)",
        "",
        f"  {'frame':>5}  {'time':>10}  {info['kind'] + ' min':>13}  {'max':>11}  {'mean':>11}"
        f"  {'std':>10}" + velocity_header,
    ]
    for f in info["frames"]:
        row = (
            f"  {f['frame']:>5}  {f['time']:>10.6g}  {f['min']:>13.6g}  {f['max']:>11.6g}"
            f"  {f['mean']:>11.6g}  {f['std']:>10.4g}"
        )
        if info["has_velocity"]:
            rms = ", ".join(f"{v:.4g}" for v in f["velocity_rms"])
            row += f"  {rms:<28}  {f['speed_max']:.4g}"
        lines.append(row)
    lines.append("")
    if info["kind"] == "density":
        lines.append(
            "  case  K*rho       delta_n_max  (paper)    = K*rho (max rho - min rho), all frames"
        )
        for name, entry in info["delta_n_max"].items():
            fluid = f" {CASE_FLUIDS[name]}" if name in CASE_FLUIDS else ""
            lines.append(
                f"  {name:<4}  {entry['k_rho']:<10.3g}  {entry['delta_n_max']:<11.3e}  "
                f"({entry['paper']:.2e}){fluid}"
            )
    else:
        lines.append(f"  delta_n_max {info['delta_n_max']['stored']['delta_n_max']:.3e}")
    return "\n".join(lines)
