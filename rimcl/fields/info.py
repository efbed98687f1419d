"""Summary of a field file: grid, frames, storage, memory, and (streamed) values.

:func:`describe_field_file` reads metadata only, so it answers at once whatever grid a file
declares; with ``values=True`` it also streams every frame in slabs of bounded size for
value ranges and Δn_max per case, never holding a whole frame.
"""

import math

import numpy as np

from rimcl.core.memory import format_bytes
from rimcl.fields.cases import CASE_FLUIDS, CASES, PAPER_DELTA_N_MAX
from rimcl.fields.field_reader import FieldFile

# bytes per voxel of a frame held as a Field: δn + ∇n as float4 (trilinear, texture),
# and one float of B-spline coefficients (bspline3)
_BYTES_TRILINEAR = 16
_BYTES_BSPLINE = 4
#: Values read at once when streaming a dataset: bounds the memory of ``values=True``.
SLAB_VALUES = 1 << 22


class _Moments:
    """Running count, minimum, maximum, mean and squared deviations (Chan et al.)."""

    def __init__(self):
        self.count, self.mean, self.m2 = 0, 0.0, 0.0
        self.low, self.high = math.inf, -math.inf

    def add(self, values):
        values = np.asarray(values, dtype=np.float64).reshape(-1)
        count = values.size
        mean = float(values.mean())
        m2 = float(np.sum((values - mean) ** 2))
        total = self.count + count
        delta = mean - self.mean
        self.m2 += m2 + delta**2 * self.count * count / total
        self.mean += delta * count / total
        self.count = total
        self.low = min(self.low, float(values.min()))
        self.high = max(self.high, float(values.max()))

    @property
    def std(self):
        return math.sqrt(self.m2 / self.count)


def _slabs(ff, frame, name):
    """The dataset ``name`` of ``frame`` in slabs along ``x3`` of at most SLAB_VALUES."""
    plane = math.prod(ff.shape[1:]) * (3 if name in ("velocity", "density_gradient") else 1)
    depth = max(1, SLAB_VALUES // max(plane, 1))
    for first in range(0, ff.shape[0], depth):
        yield ff.read_slab(frame, name, slice(first, min(first + depth, ff.shape[0])))


def _frame_values(ff, frame):
    """Value summary of one frame, streamed."""
    moments = _Moments()
    for slab in _slabs(ff, frame, ff.kind):
        moments.add(slab)
    summary = {
        "frame": frame,
        "time": float(ff.times[frame]),
        "min": moments.low,
        "max": moments.high,
        "mean": moments.mean,
        "std": moments.std,
    }
    if ff.has_velocity and not ff.has_full_velocity:
        # a sheet-only file holds (u2, u3) on one plane: the rms of those two
        plane = ff.sheet_velocity(ff.times[frame], ff.velocity_sheet_x1).reshape(-1, 2)
        summary["velocity_rms"] = np.sqrt(np.mean(plane**2, axis=0)).tolist()
        summary["speed_max"] = float(np.sqrt(np.max(np.sum(plane**2, axis=1))))
    elif ff.has_velocity:
        squares, speed_max = np.zeros(3), 0.0
        for slab in _slabs(ff, frame, "velocity"):
            slab = np.asarray(slab, dtype=np.float64).reshape(-1, 3)
            squares += np.sum(slab**2, axis=0)
            speed_max = max(speed_max, float(np.sqrt(np.max(np.sum(slab**2, axis=1)))))
        summary["velocity_rms"] = np.sqrt(squares / math.prod(ff.shape)).tolist()
        summary["speed_max"] = speed_max
    return summary


def describe_field_file(path, values=False):
    """Grid, frames, storage and memory needs of a field file; with ``values``, also the
    value ranges and Δn_max per case.

    Parameters
    ----------
    path : str or Path
    values : bool
        Stream every frame (in slabs of :data:`SLAB_VALUES` values, so memory stays bounded
        whatever the grid) for per-frame min, max, mean, std, velocity rms and Δn_max.
        Without it, only metadata is read.

    Returns
    -------
    dict
        Plain data (JSON-ready). With ``values``: ``frames`` (one summary per frame) and
        ``delta_n_max``, which maps each case ``C0`` … ``C4`` to ``G (max ρ - min ρ)`` over
        all frames, next to the paper's value, for density files, and holds the stored
        range for ``delta_n`` files.
    """
    with FieldFile(path) as ff:
        n3, n2, n1 = ff.shape
        voxels = n1 * n2 * n3
        extent = ff.spacing * (np.array([n1, n2, n3]) - (0 if ff.boundary == "periodic" else 1))
        described = {
            "path": str(ff.path),
            "title": ff.attrs.get("title", ""),
            "source": ff.attrs.get("source", ""),
            "kind": ff.kind,
            # what the stored scalar was made from, and the field's physical scales
            "scalar": ff.attrs.get("scalar"),
            "scalar_units": ff.attrs.get("scalar_units"),
            "axes": ff.attrs.get("axes"),
            "length_m": ff.attrs.get("length_m"),
            "time_s": ff.attrs.get("time_s"),
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
            "storage": ff.storage(),
            "file_bytes": ff.path.stat().st_size,
            "memory_bytes_per_frame": {
                "field_trilinear": voxels * _BYTES_TRILINEAR,
                "field_bspline3": voxels * _BYTES_BSPLINE,
                "velocity": voxels * 12
                if ff.has_full_velocity
                else (n3 * n2 * 8 if ff.has_velocity else 0),
            },
        }
        if ff.kind == "delta_n":
            described["n_ref"] = ff.n_refs.tolist()
        if not values:
            return described
        frames = [_frame_values(ff, k) for k in range(ff.n_frames)]
    spread = max(f["max"] for f in frames) - min(f["min"] for f in frames)
    if described["kind"] == "density":
        delta_n_max = {
            name: {"k_rho": g, "delta_n_max": g * spread, "paper": PAPER_DELTA_N_MAX[name]}
            for name, g in CASES.items()
        }
    else:
        delta_n_max = {"stored": {"delta_n_max": spread}}
    return {**described, "frames": frames, "delta_n_max": delta_n_max}


def _mib(count):
    return f"{count / 2**20:.1f} MiB"


def format_description(info):
    """Human-readable text of :func:`describe_field_file`'s result."""
    n3, n2, n1 = info["shape_n3_n2_n1"]
    sheet = info.get("velocity_sheet_x1")
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
        + (
            f" (from {info['scalar']} in {info['scalar_units']}, axes {info['axes']})"
            if info.get("scalar") and info["scalar"] != info["kind"]
            else ""
        )
        + (" + density_gradient" if info["has_density_gradient"] else "")
        + (" + velocity" if info["has_velocity"] and sheet is None else "")
        + (f" + velocity_sheet (u2, u3 on x1 = {sheet:g})" if sheet is not None else ""),
        "  units     "
        + (f"length {info['length_m']:g} m" if info.get("length_m") else "length: field units")
        + (f", time {info['time_s']:g} s" if info.get("time_s") else ", time: field units"),
        f"  memory    file {_mib(info['file_bytes'])}; per frame as a field: "
        f"{_mib(info['memory_bytes_per_frame']['field_trilinear'])} (trilinear), "
        f"{_mib(info['memory_bytes_per_frame']['field_bspline3'])} (bspline3)",
        "  stored    "
        + "; ".join(
            f"{name} {entry['dtype']}, {format_bytes(entry['declared_bytes'])} in all frames, "
            f"{format_bytes(entry['stored_bytes'])} on disk"
            for name, entry in info["storage"].items()
        ),
    ]
    if "frames" not in info:
        lines.append("  values    not read (add --values to stream them: ranges, Δn_max per case)")
        return "\n".join(lines)
    lines += [
        "",
        f"  {'frame':>5}  {'time':>10}  {info['kind'] + ' min':>13}  {'max':>11}  {'mean':>11}"
        f"  {'std':>10}"
        + (
            (
                "  sheet velocity rms (x2, x3)   |u|max"
                if sheet is not None
                else "  velocity rms (x1, x2, x3)     |u|max"
            )
            if info["has_velocity"]
            else ""
        ),
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
