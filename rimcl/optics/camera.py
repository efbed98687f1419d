"""The scene of a synthetic PTV measurement: light sheet, exit plane, tracers and ray fans.

An ideal lens focused on the light sheet images every ray to the point where its straight
backward extension meets the sheet (the back-projection done by :func:`rimcl.trace_rays`),
so a camera model only decides which rays leave a tracer and which of them are collected:

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

from rimcl.core.errors import RimclError
from rimcl.optics.layers import aim_through_layers, cross_window

CAMERAS = ("plane", "pupil", "lens")
#: The lens camera's f-number when none is given: f/11 makes a 10 µm tracer at M = 0.2
#: (532 nm) a 2.65 px image on 6.5 µm pixels, above the ~2 px where centroids lock to
#: whole pixels (f/8 gives 1.94 px).
DEFAULT_F_NUMBER = 11.0

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
        """Default scene of a gridded field.

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
            raise RimclError(
                f"the traced depth (field.depth) from the sheet x1 = {x_sheet:g} must be "
                f"positive, got {depth:g}: put the sheet inside the grid ({lo[0]:g} .. "
                f"{hi[0]:g}) or give field.depth"
            )
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


def _toward(aims, starts, aim_index):
    """Unit vectors from ``starts`` (N, 3) to every aim (N, K, 3), or from start i to
    ``aims[aim_index[i]]`` (N, 3): the same operations on each pair."""
    if aim_index is None:
        return _unit(aims[None, :, :] - starts[:, None, :])
    return _unit(aims[np.asarray(aim_index)] - starts)


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

    def directions(self, tracers, aim_index=None):
        """Unit initial directions from each tracer to each aim point.

        Parameters
        ----------
        tracers : ndarray, shape (N, 2)
            Tracer positions ``(x2, x3)`` in the sheet.
        aim_index : ndarray of int, shape (N,), optional
            Only the ray of tracer i towards aim point ``aim_index[i]``.

        Returns
        -------
        ndarray, float64, shape (N, M², 3), or (N, 3) with ``aim_index``
        """
        return _toward(self.aim_points(), self.scene.in_sheet(tracers), aim_index)

    def collected(self, end_pos, end_dir, exit_index=None):
        """Which exit rays the camera records: all of them. Shape (K,) bool.

        ``exit_index`` is accepted for a common signature with :class:`LensCamera`.
        """
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

    def directions(self, tracers, aim_index=None):
        """Unit initial directions from each tracer to each pupil point, shape (N, K, 3)
        (or (N, 3): tracer i towards pupil point ``aim_index[i]``)."""
        return _toward(self.aim_points(), self.scene.in_sheet(tracers), aim_index)

    def collected(self, end_pos, end_dir, exit_index=None):
        """Which exit rays pass through the pupil when continued in a straight line.

        Parameters
        ----------
        end_pos, end_dir : ndarray, shape (K, 3)
            Exit points on ``x1 = x_end`` and unit exit directions (NaN for failed rays).
        exit_index : ndarray, optional
            Unused (no interface on the exit plane); as :meth:`LensCamera.collected`.

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


def _number(value):
    """``float(value)``, or NaN when it is not a number (so range checks reject it)."""
    try:
        return float(value)
    except (TypeError, ValueError):
        return float("nan")


def _field_units(length_mm, length_m):
    """A length in mm as field length units (``length_m`` metres per unit)."""
    return 1e-3 * length_mm / length_m


@dataclasses.dataclass(frozen=True)
class FlatWindow:
    """A plane-parallel window on the exit plane, between the fluid and the camera.

    Its inner face is the exit plane ``x1 = x_end``, its outer face ``thickness_mm`` beyond;
    rays refract at both faces (Snell), so a uniform medium images through it with the
    window's own aberration, which the reference and the measured images then share. A
    thickness of 0 is the bare fluid/outside interface: the glass index then drops out.

    Attributes
    ----------
    thickness_mm : float
    glass_index : float
        Refractive index of the window (e.g. 1.52 BK7, 1.49 PMMA).
    outside_index : float
        Refractive index of the medium between window and lens (1.0003 air).
    """

    thickness_mm: float
    glass_index: float = 1.52
    outside_index: float = 1.0

    def __post_init__(self):
        if not (np.isfinite(_number(self.thickness_mm)) and self.thickness_mm >= 0):
            raise RimclError(f"the window's thickness_mm must be >= 0, got {self.thickness_mm!r}")
        for name in ("glass_index", "outside_index"):
            value = getattr(self, name)
            if not (np.isfinite(_number(value)) and value > 0):
                raise RimclError(f"the window's {name} must be positive, got {value!r}")

    def describe(self):
        return dataclasses.asdict(self)


@dataclasses.dataclass(frozen=True)
class LensCamera:
    """A real camera: a thin lens of given focal length and f-number, focused on the sheet.

    The lens looks along ``-x1`` at the field-of-view centre. Everything follows from the
    optics (thin lens, Raffel et al., *Particle Image Velocimetry*, ch. 2):

    - magnification ``M = f / (s_o - f)``, object distance ``s_o = f (1 + 1/M)``;
    - pixel size on the sheet ``p / M`` (``p`` the sensor's pixel pitch);
    - the pupil, of diameter ``D = f / N`` at ``s_o`` from the (apparent) sheet: a
      :class:`PupilCamera` decides which rays are collected, since an ideal lens focused on
      the sheet images every ray to its back-projection ``r'``;
    - depth of field ``δz = 4 (1 + 1/M)² N² λ``;
    - tracer image diameter ``d_τ = sqrt((M d_p)² + d_diff²)``, ``d_diff = 2.44 (1 + M) λ N``,
      on the sensor; the Gaussian PSF has ``σ = d_τ / 4`` (``d_τ`` is read as the e⁻²
      diameter of a Gaussian; the best-fit Gaussian of an Airy disk alone is
      narrower, ``σ = 0.42 (1 + M) λ N ≈ d_diff / 5.8``).

    With a :class:`FlatWindow`, exit rays refract into the glass and out into the outside
    medium before the pupil test, and ``r'`` is their backward extension to the plane the
    lens is focused on: the paraxial image of the sheet through fluid and window,
    ``x_focus = x_end + t - t n_o / n_g - L1 n_o / n_f`` (:attr:`focus_x1`). The working
    distance is counted from there, in the outside medium.

    Attributes
    ----------
    scene : Scene
    length_m : float
        Metres per field length unit (the field's physical size).
    focal_length_mm, f_number : float
    magnification : float, optional
        ``M > 0``; or give ``working_distance_mm`` (``s_o``); the other is derived.
    working_distance_mm : float, optional
    pixel_pitch_um : float
        Sensor pixel pitch (µm).
    pixels : tuple of 2 int
        Sensor pixels along ``x2`` and ``x3``.
    wavelength_nm : float
        Vacuum wavelength of the light (nm).
    particle_diameter_um : float
        Tracer diameter (µm), for the geometric image.
    fluid_index : float
        Index of the fluid the camera is aimed and focused through (the fluid's mean index;
        only used with a window). Snell at the window's inner face takes each ray's own
        index at its exit point where the caller gives it (``exit_index``).
    window : FlatWindow, optional
        The wall between fluid and lens; thickness 0 is the bare fluid/outside interface.
        None: no interface at all (the lens immersed in the fluid, or a fluid of the
        outside's index); a real camera outside a tank always has one.
    rays : int
        Rays per tracer, spread area-uniformly over the pupil.
    """

    scene: Scene
    length_m: float
    focal_length_mm: float = 50.0
    f_number: float = DEFAULT_F_NUMBER
    magnification: float = None
    working_distance_mm: float = None
    pixel_pitch_um: float = 6.5
    pixels: tuple = (2048, 2048)
    wavelength_nm: float = 532.0
    particle_diameter_um: float = 10.0
    fluid_index: float = 1.0
    window: FlatWindow = None
    rays: int = 1024

    def __post_init__(self):
        for name in (
            "length_m",
            "focal_length_mm",
            "f_number",
            "pixel_pitch_um",
            "wavelength_nm",
            "fluid_index",
        ):
            value = getattr(self, name)
            if not (np.isfinite(_number(value)) and value > 0):
                raise RimclError(f"the lens camera's {name} must be positive, got {value!r}")
        if not (np.isfinite(self.particle_diameter_um) and self.particle_diameter_um >= 0):
            raise RimclError(
                f"the particle diameter must be >= 0 µm, got {self.particle_diameter_um!r}"
            )
        pixels = tuple(int(p) for p in np.broadcast_to(self.pixels, (2,)))
        if min(pixels) < 1:
            raise RimclError(f"the sensor needs at least 1 x 1 pixels, got {self.pixels!r}")
        object.__setattr__(self, "pixels", pixels)
        f = self.focal_length_mm
        if (self.magnification is None) == (self.working_distance_mm is None):
            raise RimclError("give the lens camera a magnification or a working distance (mm)")
        if self.magnification is not None:
            if not (np.isfinite(self.magnification) and self.magnification > 0):
                raise RimclError(f"the magnification must be positive, got {self.magnification}")
            object.__setattr__(self, "working_distance_mm", f * (1.0 + 1.0 / self.magnification))
        else:
            if not (np.isfinite(self.working_distance_mm) and self.working_distance_mm > f):
                raise RimclError(
                    f"the working distance ({self.working_distance_mm} mm) must exceed the "
                    f"focal length ({f} mm) to form an image"
                )
            object.__setattr__(self, "magnification", f / (self.working_distance_mm - f))
        if int(self.rays) < 1:
            raise RimclError(f"the lens camera needs at least 1 ray per tracer, got {self.rays}")
        outer_face = self.scene.x_end + self._thickness
        if self.focus_x1 + self.object_distance <= outer_face:
            raise RimclError(
                f"the lens (working distance {self.working_distance_mm:g} mm = "
                f"{self.object_distance:g} field units) sits inside the field or the window; "
                f"it must lie beyond x1 = {outer_face:g}"
            )

    # --- optics, in physical units --------------------------------------------------------
    @property
    def aperture_mm(self):
        """Entrance pupil diameter ``D = f / N`` (mm)."""
        return self.focal_length_mm / self.f_number

    @property
    def numerical_aperture(self):
        """Object-side numerical aperture ``sin(atan(D / 2 s_o))``."""
        return float(np.sin(np.arctan(0.5 * self.aperture_mm / self.working_distance_mm)))

    @property
    def depth_of_field_mm(self):
        """``δz = 4 (1 + 1/M)² N² λ`` (mm), in the outside medium."""
        wavelength_mm = 1e-6 * self.wavelength_nm
        return 4.0 * (1.0 + 1.0 / self.magnification) ** 2 * self.f_number**2 * wavelength_mm

    @property
    def diffraction_diameter_um(self):
        """``d_diff = 2.44 (1 + M) λ N`` on the sensor (µm)."""
        return 2.44 * (1.0 + self.magnification) * 1e-3 * self.wavelength_nm * self.f_number

    @property
    def image_diameter_um(self):
        """Tracer image diameter ``sqrt((M d_p)² + d_diff²)`` on the sensor (µm)."""
        geometric = self.magnification * self.particle_diameter_um
        return float(np.hypot(geometric, self.diffraction_diameter_um))

    @property
    def psf_sigma_px(self):
        """Gaussian PSF ``σ = d_τ / 4`` in sensor pixels."""
        return self.image_diameter_um / (4.0 * self.pixel_pitch_um)

    # --- geometry, in field units ---------------------------------------------------------
    @property
    def pixel_size(self):
        """Pixel side on the sheet (field length units): the pitch over ``M``."""
        return _field_units(1e-3 * self.pixel_pitch_um / self.magnification, self.length_m)

    @property
    def sensor_fov(self):
        """Field of view the sensor covers on the sheet, ``(x2, x3)`` widths (field units)."""
        return self.pixel_size * np.asarray(self.pixels, dtype=np.float64)

    @property
    def object_distance(self):
        """``s_o`` in field units."""
        return _field_units(self.working_distance_mm, self.length_m)

    @property
    def _thickness(self):
        return 0.0 if self.window is None else _field_units(self.window.thickness_mm, self.length_m)

    @property
    def focus_x1(self):
        """The plane the lens is focused on: the paraxial image of the sheet (x1)."""
        if self.window is None:
            return self.scene.x_sheet
        n_out, n_glass = self.window.outside_index, self.window.glass_index
        return (
            self.scene.x_end
            + self._thickness * (1.0 - n_out / n_glass)
            - self.scene.depth * n_out / self.fluid_index
        )

    @property
    def pupil(self):
        """The entrance pupil as a :class:`PupilCamera` on the ``x1`` axis."""
        distance = self.focus_x1 - self.scene.x_sheet + self.object_distance
        return PupilCamera(
            self.scene, _field_units(self.aperture_mm, self.length_m), distance, 0.0, self.rays
        )

    @property
    def rays_per_tracer(self):
        return int(self.rays)

    def aim_points(self):
        """Points ``(x1, x2, x3)`` spread area-uniformly over the pupil, shape (K, 3)."""
        return self.pupil.aim_points()

    def directions(self, tracers, aim_index=None):
        """Unit initial directions that reach the pupil points through a uniform fluid.

        Without a window, straight lines to the pupil points. With one, each direction is
        solved (Newton, from the paraxial guess) so that the ray refracted by the window
        reaches its pupil point.

        Parameters
        ----------
        tracers : ndarray, shape (N, 2)
        aim_index : ndarray of int, shape (N,), optional
            Only the ray of tracer i towards pupil point ``aim_index[i]``.

        Returns
        -------
        ndarray, float64, shape (N, K, 3), or (N, 3) with ``aim_index``
        """
        return self._directions_to(self.aim_points(), tracers, aim_index)

    def chief_directions(self, tracers):
        """Unit initial directions from each tracer ``(N, 2)`` to the pupil centre through a
        uniform fluid (the chief rays), shape (N, 3)."""
        return self._directions_to(self.pupil.centre[None], tracers, np.zeros(len(tracers), int))

    def _directions_to(self, aims, tracers, aim_index):
        """:meth:`directions` towards the points ``aims`` (K, 3) on the pupil plane."""
        if self.window is None:
            return _toward(aims, self.scene.in_sheet(tracers), aim_index)
        tracers = np.asarray(tracers, dtype=np.float64)
        if aim_index is None:
            lateral = aims[None, :, 1:] - tracers[:, None, :]
        else:
            lateral = aims[np.asarray(aim_index), 1:] - tracers
        depths = np.array(
            [self.scene.depth, self._thickness, aims[0, 0] - self.scene.x_end - self._thickness]
        )
        ratios = np.array(
            [
                1.0,
                self.fluid_index / self.window.glass_index,
                self.fluid_index / self.window.outside_index,
            ]
        )
        return aim_through_layers(lateral, depths, ratios)

    def through_window(self, end_pos, end_dir, exit_index=None):
        """Exit rays after the window (unchanged without one).

        Parameters
        ----------
        end_pos, end_dir : ndarray, shape (K, 3)
            Exit points on ``x1 = x_end`` and unit exit directions.
        exit_index : ndarray, shape (K,), optional
            Fluid index at each exit point (default :attr:`fluid_index`).

        Returns
        -------
        positions, directions : ndarray, shape (K, 3)
            On the window's outer face, and the unit directions outside; NaN for rays
            reflected totally.
        """
        end_pos = np.asarray(end_pos, dtype=np.float64)
        end_dir = np.asarray(end_dir, dtype=np.float64)
        if self.window is None:
            return end_pos, end_dir
        n_fluid = self.fluid_index if exit_index is None else np.asarray(exit_index)
        return cross_window(end_pos, end_dir, self._thickness, n_fluid, self.window)

    def collected(self, end_pos, end_dir, exit_index=None):
        """Which exit rays pass through the pupil (after the window), shape (K,) bool."""
        with np.errstate(invalid="ignore"):
            return self.pupil.collected(*self.through_window(end_pos, end_dir, exit_index))

    def image_points(self, end_pos, end_dir, exit_index=None):
        """Image points ``r'``: the rays' backward extension onto the focus plane.

        Without a window this is the back-projection onto the sheet that
        :func:`rimcl.trace_rays` returns as ``image_pos``.

        Returns
        -------
        ndarray, float64, shape (K, 2)
            ``(x2, x3)``; NaN for rays that do not leave.
        """
        positions, directions = self.through_window(end_pos, end_dir, exit_index)
        with np.errstate(invalid="ignore", divide="ignore"):
            run = (positions[:, 0] - self.focus_x1) / directions[:, 0]
            return positions[:, 1:] - run[:, None] * directions[:, 1:]

    def describe(self):
        return {
            "camera": "lens",
            "length_m": self.length_m,
            "focal_length_mm": self.focal_length_mm,
            "f_number": self.f_number,
            "magnification": self.magnification,
            "working_distance_mm": self.working_distance_mm,
            "pixel_pitch_um": self.pixel_pitch_um,
            "pixels": list(self.pixels),
            "wavelength_nm": self.wavelength_nm,
            "particle_diameter_um": self.particle_diameter_um,
            "aperture_mm": self.aperture_mm,
            "numerical_aperture": self.numerical_aperture,
            "depth_of_field_mm": self.depth_of_field_mm,
            "diffraction_diameter_um": self.diffraction_diameter_um,
            "image_diameter_um": self.image_diameter_um,
            "psf_sigma_px": self.psf_sigma_px,
            "pixel_size": self.pixel_size,
            "sensor_fov_x2_x3": self.sensor_fov.tolist(),
            "focus_x1": self.focus_x1,
            "fluid_index": self.fluid_index,
            "window": None if self.window is None else self.window.describe(),
            "rays_per_tracer": self.rays_per_tracer,
            "pupil_centre": self.pupil.centre.tolist(),
        }
