"""The flow of an LPT run: the field file (or the built-in flow), the volume, the tracks.

Tracers in a volume move with the full 3-D velocity, which the shipped sample does not
store (it keeps only the sheet's in-plane velocity). Without a ``field.path`` the run
therefore makes the built-in flow with the full velocity: the same Boussinesq solver
(:func:`rimcl.fields.synth.synthesize`, 32³, seed 1, from rest to the kinetic-energy peak,
frames ``time.dt`` apart), written once into the output directory and reused.

True tracks: ``dx/dt = u(x, t)`` by RK4 (:func:`rimcl.ptv.track.integrate_tracks`) with
``u`` the PIV stage's 3-D interpolant (:class:`rimcl.piv.tracer_motion.FlowVelocity`: cubic
B-spline in space, linear in time between stored frames, :func:`volume_velocity`); true
velocity ``u(x_k, t_k)`` and acceleration ``Du/Dt``
(:func:`rimcl.ptv.track.track_acceleration`).
"""

import dataclasses
import json
from pathlib import Path

import numpy as np

from rimcl.core.errors import RimclError
from rimcl.fields.field_reader import FieldFile

#: The built-in flow: grid, seed of the solver.
BUILTIN_GRID = 32
BUILTIN_SEED = 1
BUILTIN_DT = 0.04
BUILTIN_NAME = "builtin_flow.h5"


def builtin_flow(out_dir, frames, dt):
    """The built-in flow with full velocity, made once in ``out_dir`` (reused if it fits).

    Parameters
    ----------
    out_dir : Path
    frames : int
        Frames needed.
    dt : float
        Their spacing (time units).

    Returns
    -------
    pathlib.Path
        The field file.
    """
    from rimcl.fields.synth import synthesize, write_synth

    path = Path(out_dir) / BUILTIN_NAME
    wanted = {"grid": BUILTIN_GRID, "seed": BUILTIN_SEED, "frames": int(frames), "frame_dt": dt}
    if path.is_file():
        with FieldFile(path) as source:
            stored = json.loads(source.attrs.get("config", "{}"))
        if all(stored.get(key) == value for key, value in wanted.items()):
            return path
    result = synthesize(grid=BUILTIN_GRID, seed=BUILTIN_SEED, frames=int(frames), frame_dt=dt)
    return write_synth(result, path, overwrite=True)


@dataclasses.dataclass(frozen=True)
class Volume:
    """The field's box and the seeded volume (field length units).

    Attributes
    ----------
    lo, hi : ndarray, shape (3,)
        The field's extent (a periodic box: one period).
    x_end : float
        The exit face (the field's last ``x1``).
    seed_lo, seed_hi : ndarray, shape (3,)
        The illuminated volume tracers are seeded in.
    periodic : bool
    """

    lo: np.ndarray
    hi: np.ndarray
    x_end: float
    seed_lo: np.ndarray
    seed_hi: np.ndarray
    periodic: bool

    @classmethod
    def of(cls, source, illumination):
        """From a field file's grid and the ``[illumination]`` settings."""
        spacing = np.asarray(source.spacing, dtype=np.float64)
        counts = np.asarray(source.shape)[::-1]
        periodic = source.boundary == "periodic"
        lo = np.asarray(source.origin, dtype=np.float64)
        hi = lo + spacing * (counts if periodic else counts - 1)
        width = hi - lo
        thickness = 0.3 * width[1] if illumination.thickness is None else illumination.thickness
        centre = 0.5 * (lo[0] + hi[0]) if illumination.centre is None else illumination.centre
        seed_lo = np.array([centre - thickness / 2, 0.0, 0.0])
        seed_hi = np.array([centre + thickness / 2, 0.0, 0.0])
        for axis, fraction in zip((1, 2), illumination.extent, strict=True):
            middle = 0.5 * (lo[axis] + hi[axis])
            seed_lo[axis] = middle - 0.5 * fraction * width[axis]
            seed_hi[axis] = middle + 0.5 * fraction * width[axis]
        if not (lo[0] <= seed_lo[0] and seed_hi[0] < hi[0]):
            raise RimclError(
                f"the illuminated slab x1 = {seed_lo[0]:g} .. {seed_hi[0]:g} must lie inside "
                f"the field (x1 = {lo[0]:g} .. {hi[0]:g}); check illumination.thickness/centre"
            )
        return cls(lo, hi, float(hi[0]), seed_lo, seed_hi, periodic)

    def seed(self, count, rng):
        """``count`` tracers uniform at random in the illuminated volume, (count, 3)."""
        if count < 1:
            raise RimclError(f"the number of tracers must be at least 1, got {count}")
        return self.seed_lo + (self.seed_hi - self.seed_lo) * rng.random((int(count), 3))

    def describe(self):
        return {
            "field_lo": self.lo.tolist(),
            "field_hi": self.hi.tolist(),
            "x_end": self.x_end,
            "seeded_lo": self.seed_lo.tolist(),
            "seeded_hi": self.seed_hi.tolist(),
            "periodic": self.periodic,
        }


def volume_velocity(source, t_first, t_last):
    """The full velocity of ``source`` over ``[t_first, t_last]`` (the stored frames
    covering it), as a :class:`rimcl.piv.tracer_motion.FlowVelocity`."""
    from rimcl.piv.tracer_motion import FlowVelocity

    if not source.has_full_velocity:
        raise RimclError(
            f"{source.path} holds no full 3-D velocity (LPT tracers move in 3-D): make one "
            "with 'rimcl field synth' (without a sheet-only velocity) or leave field.path "
            "empty for the built-in flow"
        )
    times = np.asarray(source.times, dtype=np.float64)
    slack = 1e-9 * max(1.0, abs(times[-1] - times[0]))
    if not times[0] - slack <= t_first <= t_last <= times[-1] + slack:
        raise RimclError(
            f"tracks over [{t_first:g}, {t_last:g}] need velocity frames there, but "
            f"{source.path} holds [{times[0]:g}, {times[-1]:g}]"
        )
    first = max(int(np.searchsorted(times, t_first + slack, side="right")) - 1, 0)
    last = min(int(np.searchsorted(times, t_last - slack, side="left")), times.size - 1)
    return FlowVelocity(source, range(first, max(last, first) + 1))
