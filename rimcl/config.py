"""The configuration of a synthetic measurement, one object per stage.

A scene file (:mod:`rimcl.scene`) has a section per stage; each section becomes one frozen
dataclass here, and :class:`MeasureConfig` holds them all. Stages take their own object
(the camera its :class:`CameraConfig`, the renderer its :class:`RendererConfig`, …), never
loose keyword arguments. :meth:`MeasureConfig.from_scene` builds one from a scene,
:meth:`MeasureConfig.from_options` from the flat option names of ``rimcl render``.
"""

import dataclasses
import numbers

from rimcl.camera import CAMERAS, PlaneCamera, PupilCamera
from rimcl.errors import RimclError
from rimcl.imaging import Imaging
from rimcl.render import Renderer

DEFAULT_RAYS_PER_BATCH = 1 << 17  # rays traced per batch: ~40 MB of host memory
DEFAULT_RAY_SAMPLE = 20_000
ENGINES = ("device", "numpy")


@dataclasses.dataclass(frozen=True)
class CameraConfig:
    """Which rays leave a tracer and reach the camera (DESIGN §6.2).

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
    """

    kind: str = "plane"
    fan: int = 32
    pupil_rays: int = 1024
    aperture_diameter: float = None
    focal_length: float = None
    f_number: float = None
    distance: float = None
    view_angle: float = 0.0

    def build(self, scene):
        """The camera object for a :class:`rimcl.camera.Scene`."""
        if self.kind not in CAMERAS:
            raise RimclError(f"unknown camera {self.kind!r}; choose from {CAMERAS}")
        if self.kind == "plane":
            return PlaneCamera(scene, int(self.fan))
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


@dataclasses.dataclass(frozen=True)
class RendererConfig:
    """How a tracer image is made and located (DESIGN §6.3–6.4).

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
    """

    kind: str = "exact"
    pixels: int = 8192
    psf_sigma: float = 2.3
    threshold: float = 100.0
    centroid_weights: str = "excess"
    max_window: int = 512
    bit_depth: int = 10

    def build(self, scene):
        """The :class:`rimcl.imaging.Imaging` of this camera over the scene's field of view."""
        if int(self.pixels) < 1:
            raise RimclError(f"the image needs at least 1 pixel, got {self.pixels}")
        pixel_size = float(max(scene.fov_size)) / int(self.pixels)
        renderer = Renderer(
            self.kind,
            pixel_size,
            tuple(scene.fov_lo),
            float(self.psf_sigma),
            int(self.max_window),
            int(self.bit_depth),
        )
        return Imaging(renderer, float(self.threshold), self.centroid_weights)


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
    """Frames imaged: ``frames`` consecutive stored frames from ``start_frame``.

    1 frame gives positions, 2 add velocity, 3 add acceleration.
    """

    frames: int = 3
    start_frame: int = 0

    def __post_init__(self):
        if int(self.frames) not in (1, 2, 3):
            raise RimclError(f"frames must be 1, 2 or 3, got {self.frames}")


@dataclasses.dataclass(frozen=True)
class RunConfig:
    """How the work runs; never changes a result.

    Attributes
    ----------
    device : str or pyopencl.Device, optional
    engine : {"device", "numpy"}
        Where images are rendered and located: on the OpenCL device with the trace
        (:mod:`rimcl.engine`), or tracer by tracer in NumPy (:mod:`rimcl.imaging`, the
        reference).
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
    "interp": ("integrator", "interp"),
    "precision": ("integrator", "precision"),
    "step": ("integrator", "step"),
    "tracers": ("tracers", "count"),
    "seed": ("tracers", "seed"),
    "margin": ("tracers", "margin"),
    "frames": ("time", "frames"),
    "start_frame": ("time", "start_frame"),
    "device": ("run", "device"),
    "engine": ("run", "engine"),
    "rays_per_batch": ("run", "rays_per_batch"),
    "ray_sample": ("run", "ray_sample"),
    "frame_image": ("run", "frame_image"),
    "x_sheet": (None, "x_sheet"),
    "depth": (None, "depth"),
}


@dataclasses.dataclass(frozen=True)
class MeasureConfig:
    """Everything one measurement (one refractive-index case) needs besides the field.

    Attributes
    ----------
    x_sheet, depth : float, optional
        Sheet position and traced depth ``L1`` (defaults: see
        :meth:`rimcl.camera.Scene.from_grid`).
    camera, renderer, integrator, tracers, time, run :
        One object per stage.
    """

    x_sheet: float = None
    depth: float = None
    camera: CameraConfig = CameraConfig()
    renderer: RendererConfig = RendererConfig()
    integrator: IntegratorConfig = IntegratorConfig()
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
        """The configuration of one case of a complete scene (:func:`rimcl.scene.load_scene`)."""
        field, cases, tracers = scene["field"], scene["cases"], scene["tracers"]
        camera, renderer = scene["camera"], scene["renderer"]
        integrator, run = scene["integrator"], scene["run"]
        return cls(
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
            ),
            renderer=RendererConfig(
                kind=renderer["kind"],
                pixels=renderer["pixels"],
                psf_sigma=renderer["psf_sigma"],
                threshold=cases["thresholds"].get(case, renderer["threshold"]),
                centroid_weights=renderer["centroid_weights"],
                max_window=renderer["max_window"],
                bit_depth=renderer["bit_depth"],
            ),
            integrator=IntegratorConfig(
                interp=integrator["interp"],
                precision=integrator["precision"],
                step=integrator["step"],
            ),
            tracers=TracerConfig(
                count=tracers["count"], seed=tracers["seed"], margin=tracers["margin"]
            ),
            time=TimeConfig(frames=3, start_frame=field["start_frame"]),
            run=RunConfig(
                device=run["device"] or None,
                rays_per_batch=run["rays_per_batch"],
                ray_sample=run["ray_sample"],
            ),
        )
