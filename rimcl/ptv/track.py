"""True tracer motion in the sheet, and measured velocities and accelerations of tracks.

Tracers move with the in-plane flow velocity ``(u2, u3)`` of the sheet:
``dx/dt = u(x, t)``, integrated by classical RK4 in time, with ``u`` interpolated by cubic
splines in space and linearly in time between the frames. In space: the periodic cubic
B-spline for a periodic box; otherwise FITPACK's interpolating bicubic spline, which
reproduces every cubic polynomial up to the edges (a B-spline with edge-clamped
coefficients does not: on 33² nodes it bent a solid-body rotation by 4e-3 of the box for
tracers within 3 cells of the edge) and holds the edge value beyond them, like a clamped
field. The true velocity and acceleration along a track are those of this model:
``u(x(t), t)`` and ``Du/Dt = d/dt u(x(t), t)`` (:func:`track_velocity`,
:func:`track_acceleration`).

Measured motion from positions at ``F`` frames ``Δt`` apart, in two ways:

- the paper's finite differences, for every frame where they exist:
  ``u_k = (x_{k+1} - x_k) / Δt`` at frames ``k = 0 … F-2`` (:func:`forward_differences`) and
  ``a_k = (x_{k+1} - 2 x_k + x_{k-1}) / Δt²`` at frames ``k = 1 … F-2``
  (:func:`second_differences`);
- a sliding least-squares polynomial of order ``p`` over ``W`` consecutive frames, as
  Lagrangian PTV codes fit tracks, evaluated at the window's centre frame
  ``c = W//2 … F-1-W//2`` (:func:`sliding_fit`). Least squares is one fixed linear filter
  per derivative (a row of the pseudo-inverse of the Vandermonde matrix of the offsets
  ``-W//2 … W//2``), so a fit over all tracers and windows is ``W`` multiply-adds.
"""

import dataclasses
import functools
import math

import numpy as np
from scipy.interpolate import RectBivariateSpline
from scipy.ndimage import map_coordinates, spline_filter

from rimcl.core.errors import RimclError


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

    @classmethod
    def from_source(cls, source, x_sheet, t_first, t_last):
        """The sheet velocity of a field file over ``[t_first, t_last]``, from every frame.

        Every stored frame from the last at or before ``t_first`` to the first at or after
        ``t_last`` is used, so tracks sampled at a multiple of the stored spacing (or
        between frames) follow the flow as finely as it is stored.

        Parameters
        ----------
        source : rimcl.fields.field_reader.FieldFile
            Or any object with ``times``, ``origin``, ``spacing``, ``boundary`` and
            ``sheet_velocity(time, x1)`` like it.
        x_sheet : float
            The sheet ``x1`` (length units).
        t_first, t_last : float
            The time span the tracks need (time units).

        Returns
        -------
        SheetVelocity
        """
        times = np.asarray(source.times, dtype=np.float64)
        slack = 1e-9 * max(1.0, abs(times[-1] - times[0]))
        if not times[0] - slack <= t_first <= t_last <= times[-1] + slack:
            raise RimclError(
                f"tracks over [{t_first:g}, {t_last:g}] need velocity frames there, but "
                f"{getattr(source, 'path', 'the field')} holds [{times[0]:g}, {times[-1]:g}]"
            )
        first = int(np.searchsorted(times, t_first + slack, side="right")) - 1
        last = int(np.searchsorted(times, t_last - slack, side="left"))
        chosen = times[max(first, 0) : min(last, times.size - 1) + 1]
        planes = [source.sheet_velocity(t, x_sheet) for t in chosen]
        periodic = source.boundary == "periodic"
        return cls(planes, chosen, source.origin[1:], source.spacing[1:], periodic)

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
            x = _rk4_step(velocity, x, times[k - 1] + j * h, h)
        positions[k] = x
    return positions


def _rk4_step(velocity, x, t, h):
    """One classical RK4 step of ``dx/dt = velocity(x, t)`` from ``(x, t)`` by ``h``."""
    k1 = velocity(x, t)
    k2 = velocity(x + 0.5 * h * k1, t + 0.5 * h)
    k3 = velocity(x + 0.5 * h * k2, t + 0.5 * h)
    k4 = velocity(x + h * k3, t + h)
    return x + (h / 6) * (k1 + 2 * k2 + 2 * k3 + k4)


def track_velocity(velocity, positions, times):
    """True velocity ``u(x_k, t_k)`` at the points of tracks.

    Parameters
    ----------
    velocity : callable
        ``velocity(points (N, 2), t) -> (N, 2)``, e.g. a :class:`SheetVelocity`.
    positions : ndarray, shape (F, N, 2)
        Track positions ``(x2, x3)`` at ``times`` (e.g. from :func:`integrate_tracks`).
    times : array_like, shape (F,)

    Returns
    -------
    ndarray, float64, shape (F, N, 2)
        Velocity (length / time units).
    """
    times = np.asarray(times, dtype=np.float64).reshape(-1)
    points = np.asarray(positions, dtype=np.float64)
    return np.stack([velocity(x, t) for x, t in zip(points, times, strict=True)])


# second-order difference stencils (offsets in steps h, weights): central, forward, backward
_CENTRAL = ((-1, 1), (-0.5, 0.5))
_FORWARD = ((0, 1, 2), (-1.5, 2.0, -0.5))
_BACKWARD = ((-2, -1, 0), (0.5, -2.0, 1.5))
#: Derivative step of :func:`track_acceleration` as a fraction of the frame spacing.
ACCELERATION_STEP = 1e-3


def track_acceleration(velocity, positions, times, step=None):
    """True (Lagrangian) acceleration ``Du/Dt = d/dt u(x(t), t)`` at the points of tracks.

    A second-order difference of the velocity met along the track: from ``(x_k, t_k)`` the
    track is continued by one RK4 step to ``t_k ± h`` (or ``t_k + h, t_k + 2h`` at the first
    time the velocity covers, ``t_k - h, t_k - 2h`` at its last), so no time outside the
    velocity's frames is needed. Between frames a :class:`SheetVelocity` is linear in time,
    so ``∂u/∂t`` jumps at each frame; at a frame the central difference gives the mean of
    the two sides.

    Parameters
    ----------
    velocity : callable
        ``velocity(points (N, 2), t) -> (N, 2)``; its ``times`` attribute (if any) bounds
        the times it may be asked for.
    positions : ndarray, shape (F, N, 2)
        Track positions at ``times``.
    times : array_like, shape (F,)
    step : float, optional
        ``h`` (time units). Default :data:`ACCELERATION_STEP` times the smallest spacing of
        ``velocity.times`` (or of ``times``): the ``O(h²)`` error is then negligible, and
        the round-off of ``u`` over ``h`` stays small (5e-9 of ``|a|`` for a solid-body
        rotation on a FITPACK spline, whose ``u`` carries 1e-13 of round-off).

    Returns
    -------
    ndarray, float64, shape (F, N, 2)
        Acceleration (length / time² units).
    """
    times = np.asarray(times, dtype=np.float64).reshape(-1)
    bounds = np.asarray(getattr(velocity, "times", times), dtype=np.float64).reshape(-1)
    h = _derivative_step(step, bounds, times)
    slack = 1e-9 * max(1.0, abs(bounds[-1] - bounds[0]))
    result = np.empty(np.shape(positions), dtype=np.float64)
    for k, t in enumerate(times):
        room_before, room_after = t - bounds[0] + slack >= h, bounds[-1] - t + slack >= h
        if room_before and room_after:
            offsets, weights = _CENTRAL
        elif room_after and bounds[-1] - t + slack >= 2 * h:
            offsets, weights = _FORWARD
        elif room_before and t - bounds[0] + slack >= 2 * h:
            offsets, weights = _BACKWARD
        else:
            raise RimclError(
                f"the acceleration at t = {t:g} needs the velocity over 2 h = {2 * h:g} "
                f"around it, but it covers [{bounds[0]:g}, {bounds[-1]:g}]; give a smaller step"
            )
        x = np.asarray(positions[k], dtype=np.float64)
        total = 0.0
        for offset, weight in zip(offsets, weights, strict=True):
            moved = x if offset == 0 else _rk4_step(velocity, x, t, offset * h)
            total = total + weight * velocity(moved, t + offset * h)
        result[k] = total / h
    return result


def _derivative_step(step, bounds, times):
    """The step ``h`` of :func:`track_acceleration` (given, or from the frame spacing)."""
    if step is not None:
        if not (isinstance(step, (int, float, np.floating)) and math.isfinite(step) and step > 0):
            raise RimclError(f"the acceleration step must be a positive time, got {step!r}")
        return float(step)
    for spaced in (bounds, times):
        if spaced.size > 1:
            return ACCELERATION_STEP * float(np.min(np.diff(spaced)))
    raise RimclError("one time and a steady velocity: give the acceleration step explicitly")


def first_difference(positions, dt):
    """Velocity ``(x_1 - x_0) / Δt`` from positions ``(F >= 2, N, 2)``; shape (N, 2)."""
    return (positions[1] - positions[0]) / dt


def second_difference(positions, dt):
    """Acceleration ``(x_2 - 2 x_1 + x_0) / Δt²`` from positions (F >= 3, N, 2); shape (N, 2)."""
    return (positions[2] - 2 * positions[1] + positions[0]) / dt**2


def forward_differences(positions, dt):
    """The paper's velocity ``u_k = (x_{k+1} - x_k) / Δt`` at every frame ``k = 0 … F-2``.

    Parameters
    ----------
    positions : ndarray, shape (F >= 2, N, 2)
        Positions at ``F`` frames ``dt`` apart.
    dt : float
        Frame spacing (time units).

    Returns
    -------
    ndarray, shape (F - 1, N, 2)
        Row ``k`` belongs to frame ``k``; the paper's truth there is ``u(x_k, t_k)``.
    """
    positions = _frames_of(positions, 2, "forward differences")
    return (positions[1:] - positions[:-1]) / dt


def second_differences(positions, dt):
    """The paper's acceleration ``(x_{k+1} - 2 x_k + x_{k-1}) / Δt²`` at frames ``1 … F-2``.

    Parameters
    ----------
    positions : ndarray, shape (F >= 3, N, 2)
    dt : float

    Returns
    -------
    ndarray, shape (F - 2, N, 2)
        Row ``j`` belongs to the centre frame ``k = j + 1``; the paper's truth is the same
        difference of the true positions (or ``Du/Dt`` at frame ``k``).
    """
    positions = _frames_of(positions, 3, "second differences")
    return (positions[2:] - 2 * positions[1:-1] + positions[:-2]) / dt**2


def _frames_of(positions, least, what):
    positions = np.asarray(positions, dtype=np.float64)
    if positions.ndim < 1 or positions.shape[0] < least:
        raise RimclError(
            f"{what} need positions at {least} frames or more, got shape {positions.shape}"
        )
    return positions


@dataclasses.dataclass
class TrackFit:
    """Position, velocity and acceleration of tracks from :func:`sliding_fit`.

    Attributes
    ----------
    centres : ndarray, int, shape (M,)
        The frame each row belongs to (the centre of its window): ``W//2 … F-1-W//2``,
        ``M = F - W + 1``.
    position, velocity, acceleration : ndarray, float64, each (M, N, 2)
        The fitted polynomial and its first and second time derivatives at the centre frame
        (length, length/time, length/time² units).
    """

    centres: np.ndarray
    position: np.ndarray
    velocity: np.ndarray
    acceleration: np.ndarray


@functools.lru_cache(maxsize=32)
def fit_filters(window, order):
    """The least-squares filters of :func:`sliding_fit`: position, ``Δt`` u, ``Δt²`` a.

    Rows of the pseudo-inverse ``V⁺`` of the Vandermonde matrix ``V[j, p] = τ_j^p`` of the
    offsets ``τ_j = j - W//2`` (in frames): the polynomial's value, slope and twice its
    curvature at ``τ = 0``.

    Parameters
    ----------
    window : int
        ``W``, odd, ``>= 3``, ``> order``.
    order : int
        Polynomial order ``p >= 2``.

    Returns
    -------
    ndarray, float64, shape (3, W), read-only
        ``x_fit = f[0] · x``, ``u_fit = f[1] · x / Δt``, ``a_fit = f[2] · x / Δt²`` for the
        positions ``x`` of one window in time order.
    """
    if not isinstance(order, (int, np.integer)) or order < 2:
        raise RimclError(f"the fit order must be an integer of at least 2, got {order!r}")
    if (
        not isinstance(window, (int, np.integer))
        or window < 3
        or window % 2 == 0
        or window <= order
    ):
        raise RimclError(
            f"the fit window must be an odd number of frames, at least 3 and more than the "
            f"order {order}, got {window!r}"
        )
    offsets = np.arange(window, dtype=np.float64) - window // 2
    vandermonde = offsets[:, None] ** np.arange(order + 1)
    inverse = np.linalg.pinv(vandermonde)
    filters = np.stack([inverse[0], inverse[1], 2.0 * inverse[2]])
    filters.flags.writeable = False
    return filters


def fit_noise_std(window, order, dt, position_std=1.0):
    """Standard deviations of :func:`sliding_fit`'s estimates for white position noise.

    Parameters
    ----------
    window, order : int
        As :func:`fit_filters`.
    dt : float
        Frame spacing (time units).
    position_std : float
        Standard deviation of independent noise on each position component (length units).

    Returns
    -------
    ndarray, float64, shape (3,)
        Std of the fitted position, velocity and acceleration: ``s ‖f_d‖ / Δt^d``.
    """
    gains = np.linalg.norm(fit_filters(window, order), axis=1)
    return position_std * gains / float(dt) ** np.arange(3)


def sliding_fit(positions, dt, window=7, order=2):
    """Least-squares polynomial fit of each track over a sliding window of frames.

    For every run of ``W`` consecutive frames (equally spaced, ``dt`` apart) a polynomial
    of order ``p`` in time is fitted to each tracer's ``x2`` and ``x3``; its value and
    derivatives at the centre frame are the estimates. A polynomial track of order ``<= p``
    is recovered exactly; for a smooth track the acceleration is biased by
    ``O(Δt² d⁴x/dt⁴)`` (order 2 or 3) and noise of std ``s`` on positions gives the stds of
    :func:`fit_noise_std`.

    Parameters
    ----------
    positions : ndarray, shape (F, N, 2)
        Positions at ``F >= W`` frames; NaN spreads to every window holding it.
    dt : float
        Frame spacing (time units).
    window : int
        ``W``: odd, at least 3 and more than ``order``.
    order : int
        ``p``, at least 2 (2 or 3 as PTV codes use; for a window centred on its frame, order
        3 changes the velocity but not the acceleration of order 2).

    Returns
    -------
    TrackFit
        Rows for the centre frames ``W//2 … F-1-W//2``.
    """
    filters = fit_filters(window, order)
    positions = _frames_of(positions, window, f"a fit over {window} frames")
    if not (isinstance(dt, (int, float, np.floating)) and math.isfinite(dt) and dt > 0):
        raise RimclError(f"the frame spacing must be a positive time, got {dt!r}")
    count = positions.shape[0] - window + 1
    estimates = np.zeros((3, count, *positions.shape[1:]))
    for j in range(window):
        # every window at once: frame j of window i is frame i + j
        estimates += filters[:, j].reshape(3, *(1,) * positions.ndim) * positions[j : j + count]
    return TrackFit(
        centres=np.arange(count) + window // 2,
        position=estimates[0],
        velocity=estimates[1] / dt,
        acceleration=estimates[2] / dt**2,
    )
