"""The configuration of a synthetic measurement, one object per stage.

A scene file (:mod:`rimcl.scene.load`) has a section per stage; each section becomes one frozen
dataclass here, and :class:`MeasureConfig` holds them all. Stages take their own object
(the camera its :class:`CameraConfig`, the renderer its :class:`RendererConfig`, …), never
loose keyword arguments. :meth:`MeasureConfig.from_scene` builds one from a scene,
:meth:`MeasureConfig.from_options` from the flat option names of ``rimcl render``.
"""

import dataclasses
import numbers

from rimcl.core.errors import RimclError
from rimcl.fields.media import Fluid
from rimcl.fields.sample import SAMPLE_LENGTH_M
from rimcl.imaging.frames import Imaging
from rimcl.imaging.mie import MieWeights
from rimcl.imaging.render import Renderer
from rimcl.imaging.sensor import Sensor
from rimcl.optics.camera import (
    CAMERAS,
    DEFAULT_F_NUMBER,
    FlatWindow,
    LensCamera,
    PlaneCamera,
    PupilCamera,
)

DEFAULT_RAYS_PER_BATCH = 1 << 17  # rays traced per batch: ~40 MB of host memory
DEFAULT_RAY_SAMPLE = 20_000
ENGINES = ("device", "numpy")
MAX_FRAMES = 1000
DEFAULT_MAGNIFICATION = 0.2  # the lens camera's M when neither M nor the distance is given
DEFAULT_PSF_SIGMA = 7.0  # the study's PSF (px) when neither the scene nor a lens sets one


@dataclasses.dataclass(frozen=True)
class CameraConfig:
    """Which rays leave a tracer and reach the camera.

    Attributes
    ----------
    kind : {"plane", "pupil"}
        ``plane``: rays aimed at a ``fan x fan`` grid on the exit plane (the paper);
        ``pupil``: ``pupil_rays`` rays aimed over a circular aperture.
    fan : int
        Aim points per side of the plane camera (paper: 100).
    pupil_rays : int
        Rays per tracer of the pupil camera.
    aperture_diameter : float, optional
        Pupil diameter (length units); or ``focal_length`` and ``f_number``. Default: a
        quarter of the camera distance.
    focal_length, f_number : float, optional
    distance : float, optional
        Sheet to pupil centre along the viewing axis (length units; default 4 L1).
    view_angle : float
        Angle of the viewing axis to ``x1``, towards ``+x2`` (degrees).
    length_m : float, optional
        Lens camera: metres per field length unit (the field's physical size).
    focal_length_mm, magnification, working_distance_mm, pixel_pitch_um : float
        Lens camera optics (give the magnification or the working distance).
    sensor_pixels : tuple of 2 int
        Lens camera: sensor pixels along ``x2`` and ``x3``.
    wavelength_nm, particle_diameter_um : float
        Lens camera: light and tracer size (diffraction and geometric image).
    window_thickness_mm, window_index, outside_index : float
        Lens camera: a flat window between fluid and lens (thickness 0: the bare
        fluid/outside interface).
    fluid_index : float
        Lens camera: index of the fluid it is aimed and focused through; None: the
        measured case's mean index.
    """

    kind: str = "plane"
    fan: int = 32
    pupil_rays: int = 1024
    aperture_diameter: float = None
    focal_length: float = None
    f_number: float = None
    distance: float = None
    view_angle: float = 0.0
    length_m: float = None
    focal_length_mm: float = 50.0
    magnification: float = None
    working_distance_mm: float = None
    pixel_pitch_um: float = 6.5
    sensor_pixels: tuple = (2048, 2048)
    wavelength_nm: float = 532.0
    particle_diameter_um: float = 10.0
    window_thickness_mm: float = 0.0
    window_index: float = 1.52
    outside_index: float = 1.0
    fluid_index: float = None

    def build(self, scene, medium_index=None):
        """The camera object for a :class:`rimcl.optics.camera.Scene`.

        ``medium_index`` is the measured case's mean refractive index: a lens camera is
        aimed and focused through it unless ``fluid_index`` is given (default 1).
        """
        if self.kind not in CAMERAS:
            raise RimclError(f"unknown camera {self.kind!r}; choose from {CAMERAS}")
        if self.kind == "plane":
            return PlaneCamera(scene, int(self.fan))
        if self.kind == "lens":
            return self._lens(scene, medium_index)
        distance = 4.0 * scene.depth if self.distance is None else float(self.distance)
        diameter = self.aperture_diameter
        if diameter is None and self.focal_length is None and self.f_number is None:
            diameter = 0.25 * distance
        return PupilCamera.from_optics(
            scene,
            distance,
            diameter=diameter,
            focal_length=self.focal_length,
            f_number=self.f_number,
            view_angle=float(self.view_angle),
            rays=int(self.pupil_rays),
        )

    def _lens(self, scene, medium_index):
        if self.length_m is None:
            raise RimclError(
                "the lens camera (the default) needs the field's physical size: give "
                "field.length_m (metres per field length unit), or use the paper's fan "
                '(--preset paper or camera.kind = "plane"), which needs none'
            )
        # always a wall: thickness 0 is the bare fluid/air interface, which refracts too
        window = FlatWindow(
            float(self.window_thickness_mm), float(self.window_index), float(self.outside_index)
        )
        return LensCamera(
            scene,
            float(self.length_m),
            focal_length_mm=float(self.focal_length_mm),
            f_number=DEFAULT_F_NUMBER if self.f_number is None else float(self.f_number),
            # M = 0.2 unless the working distance sets it: the default camera's
            magnification=self.magnification
            if self.magnification is not None or self.working_distance_mm is not None
            else DEFAULT_MAGNIFICATION,
            working_distance_mm=self.working_distance_mm,
            pixel_pitch_um=float(self.pixel_pitch_um),
            pixels=tuple(int(p) for p in self.sensor_pixels),
            wavelength_nm=float(self.wavelength_nm),
            particle_diameter_um=float(self.particle_diameter_um),
            fluid_index=float(
                self.fluid_index
                if self.fluid_index is not None
                else (1.0 if medium_index is None else medium_index)
            ),
            window=window,
            rays=int(self.pupil_rays),
        )


@dataclasses.dataclass(frozen=True)
class RendererConfig:
    """How a tracer image is made and located.

    Attributes
    ----------
    kind : {"exact", "paper"}
        Pixel-integrated Gaussian per ray, or the paper's binning and Gaussian filter.
    pixels : int
        Pixels across the wider side of the field of view (paper: 8192).
    psf_sigma : float
        Gaussian point-spread σ (pixels).
    threshold : float
        Grey threshold in counts (paper, 10 bits: 100 for air, 500 for water).
    centroid_weights : {"excess", "grey"}
    max_window : int
        Largest per-tracer window side (pixels).
    bit_depth : int
        Bits per pixel of the camera, 8 to 16 (paper: 10).
    scaling : {"reference", "per_image"}
        See :class:`rimcl.imaging.frames.Imaging`.
    split : {"exclude", "brightest"}
        See :class:`rimcl.imaging.frames.Imaging`.
    """

    kind: str = "exact"
    pixels: int = 8192
    psf_sigma: float = 2.3
    threshold: float = 100.0
    centroid_weights: str = "excess"
    max_window: int = 512
    bit_depth: int = 10
    scaling: str = "reference"
    split: str = "exclude"

    def build(self, scene, camera=None, sensor=None):
        """The :class:`rimcl.imaging.frames.Imaging` of a camera over the scene's field of view.

        A lens camera sets the pixel size, the image origin (its sensor centred on the
        field of view) and, where ``psf_sigma`` is None, the PSF; otherwise ``pixels``
        span the wider side of the field of view.
        """
        psf_sigma = self.psf_sigma
        if isinstance(camera, LensCamera):
            pixel_size = camera.pixel_size
            origin = scene.fov_centre - 0.5 * camera.sensor_fov
            psf_sigma = camera.psf_sigma_px if psf_sigma is None else psf_sigma
        else:
            if int(self.pixels) < 1:
                raise RimclError(f"the image needs at least 1 pixel, got {self.pixels}")
            pixel_size = float(max(scene.fov_size)) / int(self.pixels)
            origin = scene.fov_lo
        if psf_sigma is None:
            raise RimclError("renderer.psf_sigma is needed (only a lens camera derives it)")
        renderer = Renderer(
            self.kind,
            pixel_size,
            tuple(float(v) for v in origin),
            float(psf_sigma),
            int(self.max_window),
            int(self.bit_depth),
        )
        sensor = Sensor(bit_depth=int(self.bit_depth)) if sensor is None else sensor
        return Imaging(
            renderer, float(self.threshold), self.centroid_weights, self.scaling, sensor, self.split
        )


@dataclasses.dataclass(frozen=True)
class SensorConfig:
    """The camera's sensor (:class:`rimcl.imaging.sensor.Sensor`); ``noise = False`` is the
    deterministic camera (scale, round, clip). The seed defaults to the tracers' seed."""

    noise: bool = False
    peak_electrons: float = 10_000.0
    read_noise_e: float = 2.0
    background_e: float = 0.0
    full_well_e: float = 30_000.0
    gain_e_per_count: float = None
    seed: int = None

    def build(self, bit_depth, default_seed):
        return Sensor(
            bit_depth=int(bit_depth),
            noise=bool(self.noise),
            peak_electrons=float(self.peak_electrons),
            read_noise_e=float(self.read_noise_e),
            background_e=float(self.background_e),
            full_well_e=float(self.full_well_e),
            gain_e_per_count=self.gain_e_per_count,
            seed=int(default_seed if self.seed is None else self.seed),
        )


@dataclasses.dataclass(frozen=True)
class MieConfig:
    """Mie weights of the rays (:class:`rimcl.imaging.mie.MieWeights`); uniform when not enabled.

    ``fluid_index`` None: the index of the medium around the tracers, the measured case's
    mean index (the fluid's base index, else 1, without one).
    """

    enabled: bool = False
    diameter_um: float = 10.0
    particle_index: float = 1.59
    particle_absorption: float = 0.0
    fluid_index: float = None
    wavelength_nm: float = 532.0
    sheet_direction: tuple = (0.0, 1.0, 0.0)
    polarisation: str = "unpolarised"
    polarisation_direction: tuple = (0.0, 0.0, 1.0)

    def build(self, fluid=None, medium_index=None):
        """The weights, or None when off (``medium_index``: the case's mean index)."""
        if not self.enabled:
            return None
        fluid_index = self.fluid_index
        if fluid_index is None:
            fluid_index = medium_index
        if fluid_index is None:
            fluid_index = 1.0 if fluid is None else float(fluid.index())
        polarisation = self.polarisation
        if polarisation == "linear":
            polarisation = tuple(float(v) for v in self.polarisation_direction)
        return MieWeights(
            diameter_um=float(self.diameter_um),
            particle_index=float(self.particle_index),
            fluid_index=float(fluid_index),
            wavelength_nm=float(self.wavelength_nm),
            sheet_direction=tuple(float(v) for v in self.sheet_direction),
            polarisation=polarisation,
            particle_absorption=float(self.particle_absorption),
        )


@dataclasses.dataclass(frozen=True)
class FluidConfig:
    """The fluid of ``dT=…`` / ``dS=…`` cases (:class:`rimcl.fields.media.Fluid`); ``kind = ""``
    for none. ``light_density``, ``heavy_density``: the field's two fluids (dimensionless;
    None: those the field file records, else 1 and 1.105)."""

    kind: str = ""
    temperature_c: float = 20.0
    salinity_g_kg: float = 0.0
    pressure_pa: float = 101_325.0
    relative_humidity: float = 0.0
    wavelength_nm: float = 532.0
    light_density: float = None
    heavy_density: float = None

    def build(self):
        """The fluid, or None without one."""
        if not self.kind:
            return None
        return Fluid(
            self.kind,
            temperature_c=float(self.temperature_c),
            wavelength_nm=float(self.wavelength_nm),
            salinity_g_kg=float(self.salinity_g_kg),
            pressure_pa=float(self.pressure_pa),
            relative_humidity=float(self.relative_humidity),
        )


@dataclasses.dataclass(frozen=True)
class IntegratorConfig:
    """The ray integrator: see :func:`rimcl.trace_rays`.

    Attributes
    ----------
    interp : {"trilinear", "texture", "bspline3", "auto"}
    precision : {"f32", "f32c", "f64"}
    step : float, optional
        Step in ``t`` (length units); None: half a cell.
    """

    interp: str = "trilinear"
    precision: str = "f32c"
    step: float = None

    def __post_init__(self):
        if self.step is not None and not (isinstance(self.step, numbers.Real) and self.step > 0):
            raise RimclError(
                f"the step must be a positive number (or None: half a cell), got {self.step!r}"
            )


@dataclasses.dataclass(frozen=True)
class TracerConfig:
    """The tracers: ``count`` seeded uniformly over the field of view, ``margin`` (fraction of
    its width) left free at the edges; the same ``seed`` gives the same tracers and ray
    subsample in every case (common random numbers)."""

    count: int = 1000
    seed: int = 0
    margin: float = 0.05


@dataclasses.dataclass(frozen=True)
class TimeConfig:
    """Frames imaged and how velocity and acceleration are estimated from them.

    Attributes
    ----------
    frames : int
        Frames imaged, ``dt`` apart from stored frame ``start_frame``: 1 gives positions,
        2 velocity, 3 or more acceleration.
    start_frame : int
        Stored frame of the first imaged frame (time ``t_0``).
    dt : float, optional
        Time between imaged frames (time units); default the stored spacing. A time
        between stored frames is interpolated in time (:meth:`FieldFile.field_at`).
    fit_window, fit_order : int
        The sliding polynomial fit of the tracks (as Lagrangian PTV codes do): odd window
        of frames and polynomial order; fitted estimates need ``frames >= fit_window``.
    time_s : float, optional
        Seconds per field time unit (recorded in the outputs for physical units).
    """

    frames: int = 3
    start_frame: int = 0
    dt: float = None
    fit_window: int = 5
    fit_order: int = 2
    time_s: float = None

    def __post_init__(self):
        if not 1 <= int(self.frames) <= MAX_FRAMES:
            raise RimclError(f"frames must be 1 to {MAX_FRAMES}, got {self.frames}")
        if self.dt is not None and not (isinstance(self.dt, numbers.Real) and self.dt > 0):
            raise RimclError(f"the frame spacing dt must be a positive number, got {self.dt!r}")
        window, order = int(self.fit_window), int(self.fit_order)
        if order < 2 or window < 3 or window % 2 == 0 or window <= order:
            raise RimclError(
                "the fit window must be an odd number of frames, at least 3 and more than "
                f"the fit order (at least 2); got window {self.fit_window}, order {self.fit_order}"
            )


@dataclasses.dataclass(frozen=True)
class RunConfig:
    """How the work runs; never changes a result.

    Attributes
    ----------
    device : str or pyopencl.Device, optional
    engine : {"device", "numpy"}
        Where images are rendered and located: on the OpenCL device with the trace
        (:mod:`rimcl.imaging.engine`), or tracer by tracer in NumPy
        (:mod:`rimcl.imaging.frames`, the reference).
    rays_per_batch : int
        Rays traced per batch; bounds the memory.
    ray_sample : int
        Measured rays of the first frame kept for diagnostics.
    frame_image : bool
        Also keep a full image of all tracers of the first frame (measured).
    """

    device: object = None
    engine: str = "device"
    rays_per_batch: int = DEFAULT_RAYS_PER_BATCH
    ray_sample: int = DEFAULT_RAY_SAMPLE
    frame_image: bool = False

    def __post_init__(self):
        if self.engine not in ENGINES:
            raise RimclError(f"unknown engine {self.engine!r}; choose from {ENGINES}")


#: ``rimcl render`` option name → (section, field) of this configuration
RENDER_OPTIONS = {
    "camera": ("camera", "kind"),
    "fan": ("camera", "fan"),
    "pupil_rays": ("camera", "pupil_rays"),
    "aperture_diameter": ("camera", "aperture_diameter"),
    "focal_length": ("camera", "focal_length"),
    "f_number": ("camera", "f_number"),
    "camera_distance": ("camera", "distance"),
    "view_angle": ("camera", "view_angle"),
    "renderer": ("renderer", "kind"),
    "pixels": ("renderer", "pixels"),
    "psf_sigma": ("renderer", "psf_sigma"),
    "threshold": ("renderer", "threshold"),
    "centroid_weights": ("renderer", "centroid_weights"),
    "max_window": ("renderer", "max_window"),
    "bit_depth": ("renderer", "bit_depth"),
    "scaling": ("renderer", "scaling"),
    "interp": ("integrator", "interp"),
    "precision": ("integrator", "precision"),
    "step": ("integrator", "step"),
    "tracers": ("tracers", "count"),
    "seed": ("tracers", "seed"),
    "margin": ("tracers", "margin"),
    "frames": ("time", "frames"),
    "start_frame": ("time", "start_frame"),
    "dt": ("time", "dt"),
    "fit_window": ("time", "fit_window"),
    "fit_order": ("time", "fit_order"),
    "device": ("run", "device"),
    "engine": ("run", "engine"),
    "rays_per_batch": ("run", "rays_per_batch"),
    "ray_sample": ("run", "ray_sample"),
    "frame_image": ("run", "frame_image"),
    "box": (None, "box"),
    "x_sheet": (None, "x_sheet"),
    "depth": (None, "depth"),
}


@dataclasses.dataclass(frozen=True)
class MeasureConfig:
    """Everything one measurement (one refractive-index case) needs besides the field.

    Attributes
    ----------
    box : sequence of 3 (lo, hi) pairs, optional
        Measure in this box cut out of the field (clamped;
        :class:`rimcl.fields.crop.CroppedSource`).
    x_sheet, depth : float, optional
        Sheet position and traced depth ``L1`` (defaults: see
        :meth:`rimcl.optics.camera.Scene.from_grid`).
    camera, renderer, integrator, sensor, mie, fluid, tracers, time, run :
        One object per stage.
    """

    box: tuple = None
    x_sheet: float = None
    depth: float = None
    camera: CameraConfig = CameraConfig()
    renderer: RendererConfig = RendererConfig()
    integrator: IntegratorConfig = IntegratorConfig()
    sensor: SensorConfig = SensorConfig()
    mie: MieConfig = MieConfig()
    fluid: FluidConfig = FluidConfig()
    tracers: TracerConfig = TracerConfig()
    time: TimeConfig = TimeConfig()
    run: RunConfig = RunConfig()

    @classmethod
    def from_options(cls, **options):
        """A configuration from ``rimcl render``'s flat option names (:data:`RENDER_OPTIONS`)."""
        sections, top = {}, {}
        for name, value in options.items():
            if name not in RENDER_OPTIONS:
                raise RimclError(f"unknown measurement option {name!r}")
            section, field = RENDER_OPTIONS[name]
            if section is None:
                top[field] = value
            else:
                sections.setdefault(section, {})[field] = value
        parts = {
            section: dataclasses.replace(getattr(cls, section), **values)
            for section, values in sections.items()
        }
        return cls(**top, **parts)

    @classmethod
    def from_scene(cls, scene, case):
        """The configuration of one case of a scene (:func:`~rimcl.scene.load.load_scene`);
        the case decides only the threshold (``case`` None: ``renderer.threshold``)."""
        field, cases, tracers = scene["field"], scene["cases"], scene["tracers"]
        camera, renderer = scene["camera"], scene["renderer"]
        integrator, run = scene["integrator"], scene["run"]
        box = field["box"]
        fluid = FluidConfig(**scene["fluid"])
        return cls(
            box=None if box is None else tuple(tuple(pair) for pair in box),
            x_sheet=field["x_sheet"],
            depth=field["depth"],
            camera=CameraConfig(
                kind=camera["kind"],
                fan=camera["fan"],
                pupil_rays=camera["pupil_rays"],
                aperture_diameter=camera["aperture_diameter"],
                focal_length=camera["focal_length"],
                f_number=camera["f_number"],
                distance=camera["distance"],
                view_angle=camera["view_angle"],
                length_m=field["length_m"]
                if field["length_m"] is not None or field["path"]
                else SAMPLE_LENGTH_M,
                focal_length_mm=camera["focal_length_mm"],
                magnification=camera["magnification"],
                working_distance_mm=camera["working_distance_mm"],
                pixel_pitch_um=camera["pixel_pitch_um"],
                sensor_pixels=tuple(camera["sensor_pixels"]),
                wavelength_nm=camera["wavelength_nm"],
                particle_diameter_um=camera["particle_diameter_um"],
                window_thickness_mm=camera["window_thickness_mm"],
                window_index=camera["window_index"],
                outside_index=camera["outside_index"],
            ),
            renderer=RendererConfig(
                kind=renderer["kind"],
                pixels=renderer["pixels"],
                psf_sigma=renderer["psf_sigma"]
                if renderer["psf_sigma"] is not None or camera["kind"] == "lens"
                else DEFAULT_PSF_SIGMA,
                threshold=cases["thresholds"].get(case, renderer["threshold"]),
                centroid_weights=renderer["centroid_weights"],
                max_window=renderer["max_window"],
                bit_depth=renderer["bit_depth"],
                scaling=renderer["scale"],
                split=renderer["split"],
            ),
            integrator=IntegratorConfig(
                interp=integrator["interp"],
                precision=integrator["precision"],
                step=integrator["step"],
            ),
            sensor=SensorConfig(**scene["sensor"]),
            mie=MieConfig(
                **{
                    **scene["mie"],
                    "sheet_direction": tuple(scene["mie"]["sheet_direction"]),
                    "polarisation_direction": tuple(scene["mie"]["polarisation_direction"]),
                }
            ),
            fluid=fluid,
            tracers=TracerConfig(
                count=tracers["count"], seed=tracers["seed"], margin=tracers["margin"]
            ),
            time=TimeConfig(
                frames=scene["time"]["frames"],
                start_frame=field["start_frame"],
                dt=scene["time"]["dt"],
                fit_window=scene["time"]["fit_window"],
                fit_order=scene["time"]["fit_order"],
                time_s=field["time_s"],
            ),
            run=RunConfig(
                device=run["device"] or None,
                rays_per_batch=run["rays_per_batch"],
                ray_sample=run["ray_sample"],
                engine=run["engine"],
            ),
        )
