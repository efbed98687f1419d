"""Cameras of a 3-D tracking rig: a pinhole (the entrance pupil) behind a flat window.

Every camera looks through the exit face ``x1 = x_end``: the fluid fills ``x1 <= x_end``, a
window of thickness ``t`` lies on it, and the camera sits in the outside medium beyond
``x_end + t``. Geometry in field length units, optics in mm and µm.

- **Axis.** The camera is aimed at its look-at point *through* the window: its optical axis
  is the outside direction of the ray from the look-at point that reaches the pupil centre,
  so the look-at point images to the sensor centre.
- **Sensor.** Pixel ``(0, 0)`` is centred on the top-left pixel; columns run along the
  camera's horizontal (``f × e3``: ``+x2`` for a camera looking along ``-x1``), rows
  downwards. A point seen in direction ``v`` from the pupil centre lands where the line
  through it meets the sensor plane at the principal distance ``s_i = f (1 + M)``; an
  optional Scheimpflug tilt turns that plane (and the conjugate focus plane, by
  ``tan θ_o = tan θ_s / M``) about the sensor's vertical axis.
- **Focus and imaging of a ray.** The lens is focused at the apparent distance ``s_o`` of
  the look-at point along its chief ray (each segment's length times ``n_outside / n``);
  an ideal lens images a ray to the image of the point where its (backward) extension
  outside meets the focus plane. For the chief ray (through the pupil centre) that is the
  pinhole projection of its outside direction.
- **Pinhole-plus-window projection** of a point in a uniform fluid: the ray from the point
  through the window to the pupil centre (Snell at both faces, solved exactly), projected.
"""

import dataclasses

import numpy as np

from rimcl.core.errors import RimclError
from rimcl.optics.camera import FlatWindow
from rimcl.optics.layers import aim_through_layers, cross_window

# golden angle (rad): successive points of a Vogel spiral are this far apart in azimuth
_GOLDEN_ANGLE = np.pi * (3.0 - np.sqrt(5.0))


def _unit(vectors):
    return vectors / np.linalg.norm(vectors, axis=-1, keepdims=True)


@dataclasses.dataclass(frozen=True)
class RigCamera:
    """One camera of the rig, in the field's frame.

    Build it with :meth:`build`; the derived geometry is computed there.

    Attributes
    ----------
    name : str
    position : ndarray, shape (3,)
        Pupil centre ``(x1, x2, x3)`` (field length units).
    look_at : ndarray, shape (3,)
        The point in the fluid imaged at the sensor centre (field length units).
    focal_length_mm, f_number, pixel_pitch_um : float
    pixels : tuple of 2 int
        Sensor columns and rows.
    scheimpflug_deg : float
        Sensor tilt about its vertical axis (degrees; 0: none).
    length_m : float
        Metres per field length unit.
    x_end : float
        The exit face (window's inner face).
    window : FlatWindow
        Its glass and outside indices (its thickness is ``window_thickness_mm``).
    window_thickness_mm : float
        0 for a bare fluid surface.
    fluid_index : float
        Index of the uniform (calibration) fluid.
    wavelength_nm, particle_diameter_um : float
        For the tracer image diameter.
    forward, right, down : ndarray, shape (3,)
        Camera axes: viewing direction and the sensor's column and row directions.
    focus_distance : float
        ``s_o``, apparent distance of the focus plane (field length units).
    """

    name: str
    position: np.ndarray
    look_at: np.ndarray
    focal_length_mm: float
    f_number: float
    pixel_pitch_um: float
    pixels: tuple
    scheimpflug_deg: float
    length_m: float
    x_end: float
    window: FlatWindow
    window_thickness_mm: float
    fluid_index: float
    wavelength_nm: float
    particle_diameter_um: float
    forward: np.ndarray
    right: np.ndarray
    down: np.ndarray
    focus_distance: float

    @classmethod
    def build(
        cls,
        name,
        position,
        look_at,
        *,
        focal_length_mm,
        f_number,
        pixel_pitch_um,
        pixels,
        length_m,
        x_end,
        window,
        fluid_index,
        scheimpflug_deg=0.0,
        wavelength_nm=532.0,
        particle_diameter_um=10.0,
        window_thickness_mm=None,
    ):
        """A camera at ``position`` (field units) aimed through the window at ``look_at``."""
        position = np.asarray(position, dtype=np.float64).reshape(3)
        look_at = np.asarray(look_at, dtype=np.float64).reshape(3)
        for label, value in (
            ("focal_length_mm", focal_length_mm),
            ("f_number", f_number),
            ("pixel_pitch_um", pixel_pitch_um),
            ("length_m", length_m),
            ("fluid_index", fluid_index),
            ("wavelength_nm", wavelength_nm),
        ):
            if not (np.isfinite(value) and value > 0):
                raise RimclError(f"camera {name}: {label} must be positive, got {value!r}")
        if not (np.all(np.isfinite(position)) and np.all(np.isfinite(look_at))):
            raise RimclError(f"camera {name}: position and look-at must be finite")
        if not -60.0 < scheimpflug_deg < 60.0:
            raise RimclError(
                f"camera {name}: the Scheimpflug tilt must be in (-60, 60) degrees, "
                f"got {scheimpflug_deg}"
            )
        pixels = tuple(int(p) for p in pixels)
        if len(pixels) != 2 or min(pixels) < 1:
            raise RimclError(f"camera {name}: sensor_pixels must be two counts >= 1")
        if window_thickness_mm is None:
            window_thickness_mm = window.thickness_mm
        if not (np.isfinite(window_thickness_mm) and window_thickness_mm >= 0):
            raise RimclError(f"camera {name}: the window thickness must be >= 0 mm")
        thickness = 1e-3 * window_thickness_mm / length_m
        if not position[0] > x_end + thickness:
            raise RimclError(
                f"camera {name} at x1 = {position[0]:g} must sit beyond the window, at "
                f"x1 > {x_end + thickness:g} (field units)"
            )
        if not look_at[0] < x_end:
            raise RimclError(
                f"camera {name}: the look-at point x1 = {look_at[0]:g} must lie in the fluid, "
                f"x1 < {x_end:g}"
            )
        layers = _Layers(x_end, thickness, fluid_index, window)
        direction = layers.aim(look_at[None], position[None])[0]
        exit_pos, outside = layers.cross(look_at[None], direction[None])
        forward = -outside[0]
        across = np.cross(forward, [0.0, 0.0, 1.0])
        if np.linalg.norm(across) < 1e-6:
            raise RimclError(f"camera {name} looks along x3; tilt it off that axis")
        right = _unit(across)
        down = np.cross(forward, right)
        # apparent distance of the look-at point along its chief ray
        first = (x_end - look_at[0]) / direction[0]
        glass = np.linalg.norm(exit_pos[0] - (look_at + first * direction))
        air = np.linalg.norm(position - exit_pos[0])
        n_out = window.outside_index
        apparent = air + glass * n_out / window.glass_index + first * n_out / fluid_index
        focal = 1e-3 * focal_length_mm / length_m
        if not apparent > focal:
            raise RimclError(
                f"camera {name}: the look-at point is {apparent * length_m * 1e3:.4g} mm away "
                f"(apparent), not beyond the focal length {focal_length_mm:g} mm"
            )
        return cls(
            name=str(name),
            position=position,
            look_at=look_at,
            focal_length_mm=float(focal_length_mm),
            f_number=float(f_number),
            pixel_pitch_um=float(pixel_pitch_um),
            pixels=pixels,
            scheimpflug_deg=float(scheimpflug_deg),
            length_m=float(length_m),
            x_end=float(x_end),
            window=window,
            window_thickness_mm=float(window_thickness_mm),
            fluid_index=float(fluid_index),
            wavelength_nm=float(wavelength_nm),
            particle_diameter_um=float(particle_diameter_um),
            forward=forward,
            right=right,
            down=down,
            focus_distance=float(apparent),
        )

    # --- optics -----------------------------------------------------------------------
    @property
    def layers(self):
        return _Layers(self.x_end, self.thickness, self.fluid_index, self.window)

    @property
    def thickness(self):
        """Window thickness (field length units)."""
        return 1e-3 * self.window_thickness_mm / self.length_m

    @property
    def magnification(self):
        """``M = f / (s_o - f)`` at the focus distance."""
        focal = 1e-3 * self.focal_length_mm / self.length_m
        return focal / (self.focus_distance - focal)

    @property
    def principal_distance_mm(self):
        """``s_i = f (1 + M)`` (mm): pupil to sensor."""
        return self.focal_length_mm * (1.0 + self.magnification)

    @property
    def aperture(self):
        """Entrance pupil diameter ``f / N`` (field length units)."""
        return 1e-3 * self.focal_length_mm / self.f_number / self.length_m

    @property
    def pixel_size(self):
        """A pixel's side on the focus plane, pitch / M (field length units)."""
        return 1e-6 * self.pixel_pitch_um / self.magnification / self.length_m

    @property
    def image_diameter_um(self):
        """Tracer image ``sqrt((M d_p)² + d_diff²)``, ``d_diff = 2.44 (1 + M) λ N`` (µm)."""
        diffraction = 2.44 * (1.0 + self.magnification) * 1e-3 * self.wavelength_nm * self.f_number
        return float(np.hypot(self.magnification * self.particle_diameter_um, diffraction))

    @property
    def depth_of_field_mm(self):
        """``4 (1 + 1/M)² N² λ`` (mm, in the outside medium)."""
        lam = 1e-6 * self.wavelength_nm
        return 4.0 * (1.0 + 1.0 / self.magnification) ** 2 * self.f_number**2 * lam

    @property
    def psf_sigma_px(self):
        """Gaussian PSF ``σ = d_τ / 4`` (sensor pixels)."""
        return self.image_diameter_um / (4.0 * self.pixel_pitch_um)

    def _plane_normal(self, tilt):
        return np.cos(tilt) * self.forward + np.sin(tilt) * self.right

    # --- imaging ----------------------------------------------------------------------
    def sensor_position(self, directions):
        """Pixel coordinates of points seen in ``directions`` from the pupil centre.

        Parameters
        ----------
        directions : ndarray, shape (K, 3)
            Vectors from the pupil centre towards the object (any length).

        Returns
        -------
        ndarray, float64, shape (K, 2)
            ``(column, row)`` in pixels; NaN for directions behind the camera.
        """
        tilt = np.radians(self.scheimpflug_deg)
        normal = self._plane_normal(tilt)
        across = np.cos(tilt) * self.right - np.sin(tilt) * self.forward
        distance = self.principal_distance_mm * 1e3 / self.pixel_pitch_um  # in pixels
        with np.errstate(invalid="ignore", divide="ignore"):
            facing = directions @ normal
            scale = distance * np.cos(tilt) / facing
            point = scale[:, None] * directions - distance * self.forward
            columns = point @ across + 0.5 * (self.pixels[0] - 1)
            rows = point @ self.down + 0.5 * (self.pixels[1] - 1)
        behind = ~(directions @ self.forward > 0)
        result = np.column_stack([columns, rows])
        result[behind] = np.nan
        return result

    def project(self, points, fluid_index=None):
        """Pinhole-plus-window projection of points in a uniform fluid.

        Parameters
        ----------
        points : ndarray, shape (K, 3)
            ``(x1, x2, x3)`` in the fluid (``x1 < x_end``).
        fluid_index : float, optional
            Default: the camera's calibration fluid.

        Returns
        -------
        ndarray, float64, shape (K, 2)
            Pixel ``(column, row)``.
        """
        layers = self.layers if fluid_index is None else self.layers.with_fluid(fluid_index)
        points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        directions = layers.aim(points, self.position[None])
        _, outside = layers.cross(points, directions)
        return self.sensor_position(-outside)

    def pupil_points(self, count):
        """Aim points on the entrance pupil, shape (count, 3).

        One point: the pupil centre (the chief ray). An even count: ``count / 2`` points of
        a Vogel spiral (area-uniform, deterministic) and their mirror images through the
        centre, so the points' mean is the centre exactly and a defocused image's centroid
        is the chief ray's for any count (only the field's variation across the bundle
        moves it).
        """
        count = int(count)
        if count < 1 or (count > 1 and count % 2):
            raise RimclError(f"rays per tracer must be 1 or an even count, got {count}")
        if count == 1:
            return self.position[None].copy()
        half = count // 2
        index = np.arange(half)
        radius = 0.5 * self.aperture * np.sqrt((index + 0.5) / half)
        azimuth = index * _GOLDEN_ANGLE
        offsets = (radius * np.cos(azimuth))[:, None] * self.right + (radius * np.sin(azimuth))[
            :, None
        ] * self.down
        return self.position + np.concatenate([offsets, -offsets])

    def aim(self, points, pupil_points):
        """Start directions in the uniform fluid from each point to each pupil point.

        Parameters
        ----------
        points : ndarray, shape (K, 3)
        pupil_points : ndarray, shape (P, 3), or (K, P, 3) per point

        Returns
        -------
        ndarray, float64, shape (K, P, 3)
        """
        points = np.asarray(points, dtype=np.float64).reshape(-1, 1, 3)
        targets = np.asarray(pupil_points, dtype=np.float64)
        return self.layers.aim(points, targets if targets.ndim == 3 else targets[None])

    def pupil_miss(self, end_pos, end_dir, exit_index=None):
        """Where exit rays, carried through the window, cross the pupil plane, relative to
        the pupil centre (the plane through it normal to the axis). Shape (K, 3)."""
        n_fluid = self.fluid_index if exit_index is None else exit_index
        with np.errstate(invalid="ignore", divide="ignore"):
            outer, outside = cross_window(end_pos, end_dir, self.thickness, n_fluid, self.window)
            run = ((self.position - outer) @ self.forward) / (outside @ self.forward)
            return outer + run[:, None] * outside - self.position

    def image_of_rays(self, end_pos, end_dir, exit_index=None):
        """Pixel positions at which the lens images exit rays.

        Parameters
        ----------
        end_pos, end_dir : ndarray, shape (K, 3)
            Exit points on ``x1 = x_end`` and unit directions in the fluid.
        exit_index : float or ndarray, shape (K,), optional
            Fluid index at each exit point (default: the calibration fluid's).

        Returns
        -------
        ndarray, float64, shape (K, 2)
            ``(column, row)``: the image of the point where the ray's straight extension
            outside the window meets the focus plane; NaN for rays that do not leave.
        """
        n_fluid = self.fluid_index if exit_index is None else exit_index
        with np.errstate(invalid="ignore"):
            outer, outside = cross_window(end_pos, end_dir, self.thickness, n_fluid, self.window)
        tilt = np.arctan(np.tan(np.radians(self.scheimpflug_deg)) / self.magnification)
        normal = self._plane_normal(tilt)
        offset = outer - self.position
        with np.errstate(invalid="ignore", divide="ignore"):
            run = (self.focus_distance * (self.forward @ normal) - offset @ normal) / (
                outside @ normal
            )
            seen = offset + run[:, None] * outside
        return self.sensor_position(seen)

    def describe(self):
        """Parameters and derived optics, for file attributes (JSON-able)."""
        return {
            "name": self.name,
            "position": self.position.tolist(),
            "position_mm": (self.position * self.length_m * 1e3).tolist(),
            "look_at": self.look_at.tolist(),
            "forward": self.forward.tolist(),
            "right": self.right.tolist(),
            "down": self.down.tolist(),
            "focal_length_mm": self.focal_length_mm,
            "f_number": self.f_number,
            "pixel_pitch_um": self.pixel_pitch_um,
            "sensor_pixels": list(self.pixels),
            "scheimpflug_deg": self.scheimpflug_deg,
            "focus_distance_mm": self.focus_distance * self.length_m * 1e3,
            "magnification": self.magnification,
            "principal_distance_mm": self.principal_distance_mm,
            "aperture_mm": self.focal_length_mm / self.f_number,
            "depth_of_field_mm": self.depth_of_field_mm,
            "image_diameter_um": self.image_diameter_um,
            "psf_sigma_px": self.psf_sigma_px,
            "pixel_size": self.pixel_size,
            "window": {**self.window.describe(), "thickness_mm": self.window_thickness_mm},
            "fluid_index": self.fluid_index,
            "wavelength_nm": self.wavelength_nm,
        }


@dataclasses.dataclass(frozen=True)
class _Layers:
    """Fluid (``x1 <= x_end``), window, outside: the flat layers every camera looks through."""

    x_end: float
    thickness: float
    fluid_index: float
    window: FlatWindow

    def with_fluid(self, fluid_index):
        return dataclasses.replace(self, fluid_index=float(fluid_index))

    def aim(self, starts, targets):
        """Unit directions in the fluid from ``starts`` (..., 3) to ``targets`` (..., 3)
        outside, broadcast together."""
        starts, targets = np.broadcast_arrays(starts, targets)
        depths = np.stack(
            [
                self.x_end - starts[..., 0],
                np.full(starts.shape[:-1], self.thickness),
                targets[..., 0] - self.x_end - self.thickness,
            ],
            axis=-1,
        )
        ratios = np.array(
            [
                1.0,
                self.fluid_index / self.window.glass_index,
                self.fluid_index / self.window.outside_index,
            ]
        )
        return aim_through_layers(targets[..., 1:] - starts[..., 1:], depths, ratios)

    def cross(self, starts, directions):
        """Straight rays from ``starts`` (K, 3) in the uniform fluid, through the window:
        outer-face points and outside directions."""
        run = (self.x_end - starts[:, 0]) / directions[:, 0]
        exits = starts + run[:, None] * directions
        exits[:, 0] = self.x_end
        return cross_window(exits, directions, self.thickness, self.fluid_index, self.window)
