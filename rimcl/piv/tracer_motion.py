"""How PIV tracers move between exposures A and B (:func:`move_tracers`): carried by the
full 3-D velocity (:class:`FlowVelocity`), or in-plane by a field that stores only the
sheet velocity (the motion model of :mod:`rimcl.piv.render`).
"""

import math

import numpy as np
from scipy.ndimage import map_coordinates, spline_filter

from rimcl.core.errors import RimclError
from rimcl.ptv.imaging_passes import TRACKING_SUBSTEPS
from rimcl.ptv.track import SheetVelocity, integrate_tracks


class FlowVelocity:
    """The 3-D flow velocity of a field file, continuous in space and time.

    Cubic B-spline in space (periodic for a periodic box; edge-clamped otherwise),
    linear in time between stored frames.

    Parameters
    ----------
    source : rimcl.fields.field_reader.FieldFile
    frames : sequence of int
        Consecutive stored frames covering the times asked for.
    """

    def __init__(self, source, frames):
        if not source.has_full_velocity:
            raise RimclError(f"{source.path} holds no full 3-D velocity")
        self.times = np.asarray(source.times, dtype=np.float64)[list(frames)]
        self.origin = np.asarray(source.origin, dtype=np.float64)
        self.spacing = np.asarray(source.spacing, dtype=np.float64)
        self.periodic = source.boundary == "periodic"
        self.counts = np.asarray(source.shape)[::-1]
        mode = "grid-wrap" if self.periodic else "nearest"
        self._mode = mode
        self._coefficients = []
        for frame in frames:
            velocity = source.velocity(frame).astype(np.float64)
            self._coefficients.append(
                [spline_filter(velocity[..., c], order=3, mode=mode) for c in range(3)]
            )

    def _in_frame(self, index, points):
        nodes = (points - self.origin) / self.spacing
        if not self.periodic:
            nodes = np.clip(nodes, 0, self.counts - 1)
        where = nodes[:, ::-1].T  # arrays are (n3, n2, n1)
        return np.stack(
            [
                map_coordinates(c, where, order=3, mode=self._mode, prefilter=False)
                for c in self._coefficients[index]
            ],
            axis=-1,
        )

    def __call__(self, points, time):
        """Velocity ``(u1, u2, u3)`` at points ``(N, 3)`` and ``time``, shape (N, 3)."""
        points = np.asarray(points, dtype=np.float64)
        if len(self.times) == 1:
            return self._in_frame(0, points)
        upper = int(
            np.clip(np.searchsorted(self.times, time, side="right"), 1, len(self.times) - 1)
        )
        weight = (time - self.times[upper - 1]) / (self.times[upper] - self.times[upper - 1])
        weight = min(max(weight, 0.0), 1.0)
        return (1 - weight) * self._in_frame(upper - 1, points) + weight * self._in_frame(
            upper, points
        )


MOTION_3D = "3-D: tracers carried by the full velocity (u1, u2, u3); out-of-plane loss modelled"
MOTION_SHEET = (
    "in-plane only: the field file stores the velocity on the sheet plane alone, so every "
    "tracer, at any depth across the sheet, moves with the sheet's (u2, u3) and keeps its x1; "
    "out-of-plane motion and the loss of pairs it causes are NOT modelled"
)


def move_tracers(source, scene, start, times, frames):
    """True tracer positions at both exposures, and how they were moved.

    With the full velocity, tracers move in 3-D (:class:`FlowVelocity`), across the sheet
    too; with only the sheet velocity (``velocity_sheet``), every tracer moves with the
    sheet's in-plane velocity at its ``(x2, x3)`` and keeps its depth (:mod:`rimcl.piv.render`).
    RK4 with at least :data:`~rimcl.ptv.imaging_passes.TRACKING_SUBSTEPS` steps per stored
    frame interval (the rule of the PTV tracks).

    Parameters
    ----------
    source : FieldFile or CroppedSource
    scene : rimcl.optics.camera.Scene
    start : ndarray, shape (N, 3)
        Positions at exposure A.
    times : sequence of float
        Exposure times (A and B of a pair, or every frame of a sequence), increasing.
    frames : list of int
        The stored frames spanning them.

    Returns
    -------
    positions : ndarray, float64, shape (len(times), N, 3)
    motion : str
        :data:`MOTION_3D` or :data:`MOTION_SHEET`.
    """
    if not source.has_velocity:
        raise RimclError(f"{source.path} holds no velocity, which moving PIV tracers needs")
    stored = np.asarray(source.times, dtype=np.float64)[frames]
    spacing = float(np.min(np.diff(stored))) if len(stored) > 1 else 0.0
    substeps = TRACKING_SUBSTEPS
    if spacing > 0:
        substeps = max(substeps, math.ceil(TRACKING_SUBSTEPS * (times[1] - times[0]) / spacing))
    if getattr(source, "has_full_velocity", False):
        positions = integrate_tracks(FlowVelocity(source, frames), start, times, substeps)
        return positions, MOTION_3D
    velocity = SheetVelocity.from_source(source, scene.x_sheet, times[0], times[-1])
    in_plane = integrate_tracks(velocity, start[:, 1:], times, substeps)
    depth = np.broadcast_to(start[None, :, :1], (len(times), len(start), 1))
    return np.concatenate([depth, in_plane], axis=-1), MOTION_SHEET
