"""The scene of a synthetic PTV measurement: light sheet, exit plane, tracers and ray fans.

An ideal lens focused on the light sheet images every ray to the point where its straight
backward extension meets the sheet (the back-projection done by :func:`rimcl.trace_rays`),
so a camera model only decides which rays leave a tracer and which of them are collected
(DESIGN §6.2):

- :class:`PlaneCamera` (the paper): rays aimed at an ``M x M`` equidistant grid of points
  on the exit plane covering the field of view; every ray is collected.
- :class:`PupilCamera`: rays aimed at a circular lens aperture (the pupil) on a viewing
  axis through the centre of the field of view; a ray whose straight continuation from
  the exit plane misses the pupil after refraction is vignetted (not collected, counted).

Positions are ``(x1, x2, x3)`` in field length units; tracers sit in the sheet
``x1 = x_sheet`` and are given by their in-plane coordinates ``(x2, x3)``.
"""

import dataclasses

import numpy as np

from rimcl.errors import RimclError

CAMERAS = ("plane", "pupil")

# golden angle (rad): successive points of a Vogel spiral are this far apart in azimuth
_GOLDEN_ANGLE = np.pi * (3.0 - np.sqrt(5.0))


@dataclasses.dataclass(frozen=True)
class Scene:
    """Light sheet, exit plane and field of view.

    Attributes
    ----------
    x_sheet : float
        The light sheet (and image plane) ``x1 = x_sheet``.
    x_end : float
        The exit plane ``x1 = x_end`` where rays leave the refractive field.
    fov_lo, fov_hi : ndarray, shape (2,)
        Field of view in the sheet: lower and upper ``(x2, x3)`` corners.
    periodic : bool
        True for a periodic field (tracers and rays may leave the box and wrap).
    """

    x_sheet: float
    x_end: float
    fov_lo: np.ndarray
    fov_hi: np.ndarray
    periodic: bool

    @classmethod
    def from_grid(cls, origin, spacing, shape, boundary, x_sheet=None, depth=None):
        """Default scene of a gridded field (DESIGN §6).

        The sheet lies at the low ``x1`` edge of the grid and the exit plane one field
        depth ``L1`` beyond it (for a periodic box, one full period); the field of view is
        the grid's ``x2``–``x3`` extent.

        Parameters
        ----------
        origin, spacing : sequence of 3 float
            Grid node ``(0, 0, 0)`` and node spacing along ``x1, x2, x3``.
        shape : sequence of 3 int
            Array shape ``(n3, n2, n1)``.
        boundary : {"clamp", "periodic"}
        x_sheet : float, optional
            Sheet position (default: the grid's lowest ``x1``).
        depth : float, optional
            ``L1 = x_end - x_sheet`` (default: from the sheet to the end of the grid).

        Returns
        -------
        Scene
        """
        origin = np.asarray(origin, dtype=np.float64)
        spacing = np.asarray(spacing, dtype=np.float64)
        counts = np.asarray(shape, dtype=np.int64)[::-1]
        periodic = boundary == "periodic"
        # a periodic grid holds one period (endpoint excluded); a clamped one ends on a node
        extent = spacing * (counts if periodic else counts - 1)
        lo, hi = origin, origin + extent
        x_sheet = float(lo[0] if x_sheet is None else x_sheet)
        if not np.isfinite(x_sheet) or (not periodic and not lo[0] <= x_sheet < hi[0]):
            raise RimclError(
                f"the sheet x1 = {x_sheet} must lie in the field [{lo[0]:g}, {hi[0]:g})"
            )
        depth = float(hi[0] - x_sheet if depth is None else depth)
        if not np.isfinite(depth) or depth <= 0:
            raise RimclError(f"the field depth L1 must be positive, got {depth}")
        x_end = x_sheet + depth
        if not periodic and x_end > hi[0] * (1 + 1e-12) + 1e-12:
            raise RimclError(
                f"the exit plane x1 = {x_end:g} lies beyond the field (x1 <= {hi[0]:g})"
            )
        if np.any(extent[1:] <= 0):
            raise RimclError("the field has no extent across x2 or x3: no field of view")
        return cls(x_sheet, x_end, lo[1:].copy(), hi[1:].copy(), periodic)

    @property
    def depth(self):
        """``L1 = x_end - x_sheet``, the depth of the traced slab (length units)."""
        return self.x_end - self.x_sheet

    @property
    def fov_size(self):
        """Field-of-view widths along ``x2, x3``, shape (2,)."""
        return self.fov_hi - self.fov_lo

    @property
    def fov_centre(self):
        """Field-of-view centre ``(x2, x3)``, shape (2,)."""
        return 0.5 * (self.fov_lo + self.fov_hi)

    def in_sheet(self, points):
        """``(x1, x2, x3)`` positions of in-plane points ``(..., 2)`` on the sheet."""
        points = np.asarray(points, dtype=np.float64)
        sheet = np.full((*points.shape[:-1], 1), self.x_sheet)
        return np.concatenate([sheet, points], axis=-1)

    def describe(self):
        return {
            "x_sheet": self.x_sheet,
            "x_end": self.x_end,
            "depth_L1": self.depth,
            "fov_lo_x2_x3": self.fov_lo.tolist(),
            "fov_hi_x2_x3": self.fov_hi.tolist(),
            "periodic": self.periodic,
        }


def seed_tracers(count, scene, rng, margin=0.05):
    """Tracers uniform at random over the field of view, away from its edges.

    Parameters
    ----------
    count : int
        Number of tracers, at least 1.
    scene : Scene
    rng : numpy.random.Generator
        The study's seeded generator (same seed → same tracers in every case).
    margin : float
        Band left free along each edge, as a fraction of the field-of-view width, in
        ``[0, 0.5)``.

    Returns
    -------
    ndarray, float64, shape (count, 2)
        Tracer positions ``(x2, x3)`` in the sheet.
    """
    count = int(count)
    if count < 1:
        raise RimclError(f"the number of tracers must be at least 1, got {count}")
    if not 0 <= margin < 0.5:
        raise RimclError(f"the tracer margin must be in [0, 0.5), got {margin}")
    lo = scene.fov_lo + margin * scene.fov_size
    hi = scene.fov_hi - margin * scene.fov_size
    return lo + (hi - lo) * rng.random((count, 2))


def _unit(vectors):
    return vectors / np.linalg.norm(vectors, axis=-1, keepdims=True)


@dataclasses.dataclass(frozen=True)
class PlaneCamera:
    """The paper's camera: from each tracer, rays aimed at an ``M x M`` grid on the exit plane.

    The aim points are the centres of ``M x M`` equal cells tiling the field of view on the
    plane ``x1 = x_end`` (paper: ``M = 100`` over ``[0, L]²``). Every ray is collected.

    Attributes
    ----------
    scene : Scene
    fan : int
        ``M``, aim points per side.
    """

    scene: Scene
    fan: int

    def __post_init__(self):
        if int(self.fan) < 1:
            raise RimclError(f"the ray fan needs at least 1 x 1 aim points, got {self.fan}")

    @property
    def rays_per_tracer(self):
        return int(self.fan) ** 2

    def aim_points(self):
        """Aim points ``(x1, x2, x3)`` on the exit plane, shape (M², 3)."""
        fan = int(self.fan)
        fractions = (np.arange(fan) + 0.5) / fan
        x2 = self.scene.fov_lo[0] + self.scene.fov_size[0] * fractions
        x3 = self.scene.fov_lo[1] + self.scene.fov_size[1] * fractions
        grid3, grid2 = np.meshgrid(x3, x2, indexing="ij")
        x1 = np.full(grid2.size, self.scene.x_end)
        return np.stack([x1, grid2.ravel(), grid3.ravel()], axis=-1)

    def directions(self, tracers):
        """Unit initial directions from each tracer to each aim point.

        Parameters
        ----------
        tracers : ndarray, shape (N, 2)
            Tracer positions ``(x2, x3)`` in the sheet.

        Returns
        -------
        ndarray, float64, shape (N, M², 3)
        """
        starts = self.scene.in_sheet(tracers)
        return _unit(self.aim_points()[None, :, :] - starts[:, None, :])

    def collected(self, end_pos, end_dir):
        """Which exit rays the camera records: all of them. Shape (K,) bool."""
        return np.ones(len(end_pos), dtype=bool)

    def describe(self):
        return {"camera": "plane", "fan": int(self.fan), "rays_per_tracer": self.rays_per_tracer}


@dataclasses.dataclass(frozen=True)
class PupilCamera:
    """A circular aperture on a viewing axis through the centre of the field of view.

    The axis leaves the sheet at the field-of-view centre, tilted by ``view_angle`` from
    ``x1`` towards ``+x2``; the pupil is the disk of diameter ``diameter`` perpendicular to
    the axis at ``distance`` from the sheet. Rays from a tracer are aimed at ``rays``
    points spread area-uniformly over the pupil (a Vogel spiral: deterministic,
    low-discrepancy), so a uniform medium delivers every ray to the pupil.

    Attributes
    ----------
    scene : Scene
    diameter : float
        Aperture diameter (length units).
    distance : float
        Distance from the sheet to the pupil centre along the axis (length units).
    view_angle : float
        Angle between the viewing axis and ``x1`` (degrees, in ``(-90, 90)``).
    rays : int
        Rays per tracer.
    """

    scene: Scene
    diameter: float
    distance: float
    view_angle: float = 0.0
    rays: int = 1024

    def __post_init__(self):
        if not (np.isfinite(self.diameter) and self.diameter > 0):
            raise RimclError(f"the aperture diameter must be positive, got {self.diameter}")
        if not (np.isfinite(self.distance) and self.distance > 0):
            raise RimclError(f"the camera distance must be positive, got {self.distance}")
        if not -90 < self.view_angle < 90:
            raise RimclError(f"the view angle must be in (-90, 90) degrees, got {self.view_angle}")
        if int(self.rays) < 1:
            raise RimclError(f"the pupil needs at least 1 ray per tracer, got {self.rays}")
        # the whole pupil must lie beyond the exit plane: rays are continued straight to it
        angle = np.radians(self.view_angle)
        nearest_x1 = (
            self.scene.x_sheet
            + self.distance * np.cos(angle)
            - 0.5 * self.diameter * abs(np.sin(angle))
        )
        if nearest_x1 <= self.scene.x_end:
            raise RimclError(
                f"the pupil (distance {self.distance:g}, diameter {self.diameter:g}, view angle "
                f"{self.view_angle:g} deg) reaches x1 = {nearest_x1:g}, inside the field; it must "
                f"lie beyond the exit plane x1 = {self.scene.x_end:g}"
            )

    @classmethod
    def from_optics(cls, scene, distance, diameter=None, focal_length=None, f_number=None, **kw):
        """Pupil from its diameter, or from focal length / f-number (``D = F / N``)."""
        if diameter is None:
            if focal_length is None or f_number is None:
                raise RimclError(
                    "the pupil camera needs --aperture-diameter, or both --focal-length "
                    "and --f-number"
                )
            if not (focal_length > 0 and f_number > 0):
                raise RimclError("the focal length and the f-number must be positive")
            diameter = focal_length / f_number
        elif focal_length is not None or f_number is not None:
            raise RimclError(
                "give either the aperture diameter or focal length and f-number, not both"
            )
        return cls(scene, float(diameter), float(distance), **kw)

    @property
    def rays_per_tracer(self):
        return int(self.rays)

    @property
    def axis(self):
        """Unit viewing axis ``(x1, x2, x3)``, pointing from the sheet to the pupil."""
        angle = np.radians(self.view_angle)
        return np.array([np.cos(angle), np.sin(angle), 0.0])

    @property
    def centre(self):
        """Pupil centre ``(x1, x2, x3)``."""
        return self.scene.in_sheet(self.scene.fov_centre) + self.distance * self.axis

    def aim_points(self):
        """Points ``(x1, x2, x3)`` spread area-uniformly over the pupil, shape (K, 3)."""
        count = int(self.rays)
        index = np.arange(count)
        radius = 0.5 * self.diameter * np.sqrt((index + 0.5) / count)
        azimuth = index * _GOLDEN_ANGLE
        angle = np.radians(self.view_angle)
        across = np.array([-np.sin(angle), np.cos(angle), 0.0])  # in the pupil, along ~x2
        up = np.array([0.0, 0.0, 1.0])
        offsets = (radius * np.cos(azimuth))[:, None] * across + (radius * np.sin(azimuth))[
            :, None
        ] * up
        return self.centre + offsets

    def directions(self, tracers):
        """Unit initial directions from each tracer to each pupil point, shape (N, K, 3)."""
        starts = self.scene.in_sheet(tracers)
        return _unit(self.aim_points()[None, :, :] - starts[:, None, :])

    def collected(self, end_pos, end_dir):
        """Which exit rays pass through the pupil when continued in a straight line.

        Parameters
        ----------
        end_pos, end_dir : ndarray, shape (K, 3)
            Exit points on ``x1 = x_end`` and unit exit directions (NaN for failed rays).

        Returns
        -------
        ndarray, bool, shape (K,)
            False for vignetted rays and for rays with non-finite exits.
        """
        axis = self.axis
        towards = end_dir @ axis
        with np.errstate(invalid="ignore", divide="ignore"):
            run = ((self.centre - end_pos) @ axis) / towards
            hit = end_pos + run[:, None] * end_dir
            off_axis = np.linalg.norm(hit - self.centre, axis=-1)
            return (towards > 0) & (run >= 0) & (off_axis <= 0.5 * self.diameter)

    def describe(self):
        return {
            "camera": "pupil",
            "aperture_diameter": self.diameter,
            "camera_distance": self.distance,
            "view_angle_deg": self.view_angle,
            "rays_per_tracer": self.rays_per_tracer,
            "pupil_centre": self.centre.tolist(),
        }
