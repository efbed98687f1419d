"""True tracer motion in the sheet, and velocities and accelerations by finite differences.

Tracers move with the in-plane flow velocity ``(u2, u3)`` of the sheet (DESIGN §6.5):
``dx/dt = u(x, t)``, integrated by classical RK4 in time, with ``u`` interpolated by cubic
splines in space and linearly in time between the frames. In space: the periodic cubic
B-spline for a periodic box; otherwise FITPACK's interpolating bicubic spline, which
reproduces every cubic polynomial up to the edges (a B-spline with edge-clamped
coefficients does not: on 33² nodes it bent a solid-body rotation by 4e-3 of the box for
tracers within 3 cells of the edge) and holds the edge value beyond them, like a clamped
field. Measured motion uses the finite differences of DESIGN §6.6:
``u = (x_1 - x_0) / Δt`` and ``a = (x_2 - 2 x_1 + x_0) / Δt²``.
"""

import numpy as np
from scipy.interpolate import RectBivariateSpline
from scipy.ndimage import map_coordinates, spline_filter

from rimcl.errors import RimclError


class SheetVelocity:
    """The in-plane velocity ``(u2, u3)`` of the sheet, continuous in space and time.

    Parameters
    ----------
    planes : array_like, shape (F, n3, n2, 2)
        ``(u2, u3)`` on the sheet's grid nodes at each frame.
    times : array_like, shape (F,)
        Frame times, increasing.
    origin : sequence of 2 float
        ``(x2, x3)`` of node ``(0, 0)``.
    spacing : sequence of 2 float
        Node spacing along ``x2, x3``.
    periodic : bool
        True: the plane wraps (one period, endpoint excluded); False: beyond the edge
        nodes the velocity is that at the nearest edge point.
    """

    def __init__(self, planes, times, origin, spacing, periodic):
        planes = np.asarray(planes, dtype=np.float64)
        times = np.asarray(times, dtype=np.float64).reshape(-1)
        if planes.ndim != 4 or planes.shape[-1] != 2 or planes.shape[0] != times.size:
            raise RimclError(
                f"sheet velocity must have shape (frames, n3, n2, 2) with {times.size} "
                f"frames, got {planes.shape}"
            )
        if times.size > 1 and np.any(np.diff(times) <= 0):
            raise RimclError(f"frame times must increase, got {times.tolist()}")
        if not np.all(np.isfinite(planes)):
            raise RimclError("the sheet velocity holds NaN or infinite values")
        if min(planes.shape[1:3]) < 4:
            raise RimclError(
                f"cubic interpolation of the sheet velocity needs at least 4 x 4 nodes, "
                f"got {planes.shape[1:3]}"
            )
        self.times = times
        self.origin = np.asarray(origin, dtype=np.float64)
        self.spacing = np.asarray(spacing, dtype=np.float64)
        self.periodic = bool(periodic)
        self._shape = planes.shape[1:3]
        self._frames = [[self._interpolant(plane[..., c]) for c in range(2)] for plane in planes]

    def _interpolant(self, values):
        """``f(x2, x3) -> values`` for one frame and component; arrays are (x3, x2)."""
        if self.periodic:
            # coefficients once per frame and component: map_coordinates then only sums
            coefficients = spline_filter(values, order=3, mode="grid-wrap")

            def evaluate(x2, x3):
                rows = (x3 - self.origin[1]) / self.spacing[1]
                cols = (x2 - self.origin[0]) / self.spacing[0]
                return map_coordinates(
                    coefficients,
                    np.stack([rows, cols]),
                    order=3,
                    mode="grid-wrap",
                    prefilter=False,
                )

            return evaluate
        n3, n2 = values.shape
        x3 = self.origin[1] + self.spacing[1] * np.arange(n3)
        x2 = self.origin[0] + self.spacing[0] * np.arange(n2)
        spline = RectBivariateSpline(x3, x2, values, kx=3, ky=3, s=0)
        return lambda a2, a3: spline.ev(a3, a2)

    def inside(self, points):
        """Whether sheet points ``(x2, x3)``, shape (N, 2), lie on the velocity grid, (N,) bool."""
        points = np.asarray(points, dtype=np.float64)
        if self.periodic:
            return np.ones(len(points), dtype=bool)
        n3, n2 = self._shape
        hi = self.origin + self.spacing * (np.array([n2, n3]) - 1)
        return np.all((points >= self.origin) & (points <= hi), axis=-1)

    def _in_frame(self, frame, points):
        return np.stack([f(points[:, 0], points[:, 1]) for f in self._frames[frame]], axis=-1)

    def __call__(self, points, time):
        """Velocity ``(u2, u3)`` at sheet points ``(x2, x3)``, shape (N, 2), at ``time``."""
        points = np.asarray(points, dtype=np.float64)
        times = self.times
        span = 1e-9 * max(1.0, abs(times[-1] - times[0]))
        if not times[0] - span <= time <= times[-1] + span:
            raise RimclError(
                f"time {time} lies outside the velocity frames [{times[0]}, {times[-1]}]"
            )
        if times.size == 1:
            return self._in_frame(0, points)
        upper = int(np.clip(np.searchsorted(times, time, side="right"), 1, times.size - 1))
        weight = (time - times[upper - 1]) / (times[upper] - times[upper - 1])
        if weight <= 0:
            return self._in_frame(upper - 1, points)
        if weight >= 1:
            return self._in_frame(upper, points)
        return (1 - weight) * self._in_frame(upper - 1, points) + weight * self._in_frame(
            upper, points
        )


def integrate_tracks(velocity, start, times, substeps=8):
    """True tracer positions at each frame time, by RK4.

    Parameters
    ----------
    velocity : callable
        ``velocity(points (N, 2), t) -> (N, 2)``, e.g. a :class:`SheetVelocity`.
    start : ndarray, shape (N, 2)
        Positions ``(x2, x3)`` at ``times[0]``.
    times : array_like, shape (F,)
        Frame times.
    substeps : int
        RK4 steps between consecutive frames.

    Returns
    -------
    ndarray, float64, shape (F, N, 2)
    """
    times = np.asarray(times, dtype=np.float64)
    positions = np.empty((times.size, *np.shape(start)))
    positions[0] = start
    x = np.array(start, dtype=np.float64)
    for k in range(1, times.size):
        h = (times[k] - times[k - 1]) / substeps
        for j in range(substeps):
            t = times[k - 1] + j * h
            k1 = velocity(x, t)
            k2 = velocity(x + 0.5 * h * k1, t + 0.5 * h)
            k3 = velocity(x + 0.5 * h * k2, t + 0.5 * h)
            k4 = velocity(x + h * k3, t + h)
            x = x + (h / 6) * (k1 + 2 * k2 + 2 * k3 + k4)
        positions[k] = x
    return positions


def first_difference(positions, dt):
    """Velocity ``(x_1 - x_0) / Δt`` from positions ``(F >= 2, N, 2)``; shape (N, 2)."""
    return (positions[1] - positions[0]) / dt


def second_difference(positions, dt):
    """Acceleration ``(x_2 - 2 x_1 + x_0) / Δt²`` from positions (F >= 3, N, 2); shape (N, 2)."""
    return (positions[2] - 2 * positions[1] + positions[0]) / dt**2
