"""PIV image pairs of one case through a refractive-index field, with their ground truth
(:func:`run_piv_render`).

A PIV camera records full frames of many tracers lit by a light sheet of finite thickness:

- **tracers**: uniform at random in a slab ``|x1 - x_sheet| <= thickness`` over the field
  of view and a band of ``band`` pixels around it (so tracers enter the frames as well as
  leave them); ``density`` counts the tracers per pixel inside the sheet's 1/e² thickness
  (``|x1 - x_sheet| <= thickness / 2``), so twice as many are seeded;
- **light sheet**: Gaussian along ``x1``, ``I = exp(-8 (x1 - x_sheet)² / thickness²)``
  (``thickness`` is the full 1/e² width), peak 1 at ``x_sheet``;
- **motion**: with the field's full 3-D velocity, each tracer is carried by it from the
  first exposure to the second (RK4, cubic B-spline in space, linear in time between
  stored frames), so it moves across the sheet, its brightness changes, and pairs are
  lost as in experiments. A field that stores only the in-plane velocity on the sheet
  (``velocity_sheet``, as the shipped sample) moves every tracer, at any depth, with the
  sheet's ``(u2, u3)`` at its ``(x2, x3)`` and keeps its ``x1``: **out-of-plane motion and
  the loss of pairs it causes are then not modelled** (the truth file's ``motion``
  attribute says which);
- **imaging**: each tracer's rays (aimed by any camera of :mod:`rimcl.optics.camera`, built by
  :meth:`rimcl.scene.config.CameraConfig.build`) are traced by :func:`rimcl.trace_rays` from the
  tracer's own position through the field to the exit plane. The plane and pupil cameras
  image each ray where its straight backward extension meets the tracer's own plane
  ``x1 = const`` (``image_pos``; their depth of field is taken to cover the sheet, so
  perspective of out-of-plane positions is not modelled); the lens camera images it on
  the plane it is focused on (:meth:`LensCamera.image_points`, through its window if any),
  which adds the perspective and defocus of tracers off that plane, and sets the pixel
  size, frame and point spread. Every collected ray deposits a pixel-integrated Gaussian
  of σ = d/4 pixels (``d`` the particle image diameter) with weight = the sheet intensity
  at its tracer, by the exact renderer of :mod:`rimcl.imaging.render`, into one full frame (no Mie
  weights);
- **camera counts**: one scale factor for all frames (an isolated tracer at the sheet
  centre, all rays collected, centred on a pixel, peaks at ``peak_fraction`` of full
  scale), rounded and clipped to ``bit_depth`` bits; no sensor noise.

Each pair is imaged twice by the same code: through the field, and through a uniform medium
(``n = 1``, where every ray returns to its tracer). Frames are ``(rows, columns)`` stored
with row 0 at the top of the camera's view (the highest ``x3``) and columns along ``x2``;
pixel centres at integer coordinates (:func:`rimcl.piv.imaging_config.frame_pixels`, the
convention of :mod:`rimcl.piv.analysis`, scikit-image, trackpy and OpenPIV's image
coordinates), so ``dy > 0`` is motion towards lower ``x3``.

The parts: :mod:`rimcl.piv.imaging_config` (imaging, sheet, seeding),
:mod:`rimcl.piv.tracer_motion`, :mod:`rimcl.piv.frame_pair` (tracing and rendering),
:mod:`rimcl.piv.truth` (the truth and the files, :func:`rimcl.piv.truth.write_piv_render`).
"""

import dataclasses
from contextlib import ExitStack

import numpy as np

from rimcl.core.errors import RimclError
from rimcl.fields.crop import CroppedSource
from rimcl.imaging.render import Renderer
from rimcl.imaging.sensor import FLOOR_PASS, MEASURED_PASS, REFERENCE_PASS
from rimcl.optics.camera import Scene
from rimcl.piv.analysis import PivSettings, WindowGrid
from rimcl.piv.frame_pair import PivFrames, image_frames
from rimcl.piv.imaging_config import SEED_HALF_WIDTH, PivImaging, seed_particles
from rimcl.piv.tracer_motion import move_tracers
from rimcl.piv.truth import pair_weights, true_displacement
from rimcl.scene.config import (
    CameraConfig,
    FluidConfig,
    IntegratorConfig,
    RunConfig,
    SensorConfig,
)

#: Default time between exposures (time units): on the shipped sample (velocity rms 0.14
#: on the sheet, frames 0.02 apart) 0.1 moves tracers 1.5 px rms and up to 4.5 px at 512 px,
#: the few pixels PIV is made for, from stored frames only.
DEFAULT_DT = 0.1


@dataclasses.dataclass(frozen=True)
class PivConfig:
    """One PIV measurement besides the field, the case and the camera.

    Attributes
    ----------
    imaging : PivImaging
        How frames are made.
    settings : rimcl.piv.analysis.PivSettings
        The correlation; its last window and overlap also set the truth's windows.
    dt : float, optional
        Time between exposures A and B (time units); None: the field's stored spacing
        after ``start_frame``. Exposure B's field is a stored frame where ``t_A + dt`` is
        one, else interpolated in time (:meth:`FieldFile.field_at`).
    start_frame : int
        Stored frame of exposure A.
    box : sequence of 3 (lo, hi) pairs, optional
        Measure in this box cut out of the field (as :class:`rimcl.scene.config.MeasureConfig`).
    x_sheet, depth : float, optional
        Sheet centre and traced depth. Defaults: :meth:`Scene.from_grid`; a clamped field
        with full velocity moves its default sheet one seeding half-width inside the grid;
        a field with only the sheet velocity keeps the sheet on its stored plane.
    seed : int
        Seeds the tracers; the same seed gives the same tracers in every case.
    time_s : float, optional
        Seconds per field time unit, where known (``field.time_s``): with the camera's
        ``length_m`` the outputs give the displacements in m/s too.
    """

    # PivImaging is frozen, so one shared default instance is safe
    imaging: PivImaging = PivImaging()  # noqa: RUF009
    settings: PivSettings = dataclasses.field(default_factory=PivSettings)
    dt: float = DEFAULT_DT
    start_frame: int = 0
    box: tuple = None
    x_sheet: float = None
    depth: float = None
    seed: int = 0
    time_s: float = None

    def describe(self):
        return {
            "dt": self.dt,
            "start_frame": int(self.start_frame),
            "box": None if self.box is None else [list(pair) for pair in self.box],
            "x_sheet": self.x_sheet,
            "depth": self.depth,
            "seed": int(self.seed),
            "piv": self.settings.describe(),
        }


#: The camera of ``rimcl piv render`` and :func:`run_piv_render` unless one is given: the
#: paper's plane camera with 8 x 8 rays per tracer (a PIV frame holds thousands of tracers).
PIV_CAMERA = CameraConfig(kind="plane", fan=8)


@dataclasses.dataclass
class PivReference:
    """The case-independent part of a PIV render: tracers, truth and uniform-medium frames.

    Attributes
    ----------
    key : dict
        The configuration it was made for (compared when it is reused).
    positions : ndarray, shape (2, N, 3)
        True tracer positions at exposures A and B.
    weights : ndarray, shape (N,)
        ``I_A · I_B`` per tracer.
    truth : dict
        :func:`rimcl.piv.truth.true_displacement` on the final window grid.
    uniform : PivFrames
        The pair imaged through a uniform medium (with the sensor noise draws the pair
        through the field shares: common random numbers).
    floor : PivFrames or None
        The uniform-medium pair exposed again with independent sensor noise draws (the
        noise floor); None for a noiseless sensor (the same images again).
    """

    key: dict
    positions: np.ndarray
    weights: np.ndarray
    truth: dict
    uniform: PivFrames
    floor: PivFrames = None


@dataclasses.dataclass
class PivRender:
    """Everything :func:`rimcl.piv.truth.write_piv_render` writes.

    Attributes
    ----------
    field : PivFrames
        The pair imaged through the refractive-index field.
    reference : PivReference
        Tracers, truth and uniform-medium pair; pass it to later cases to reuse it.
    config : dict
    case : str
    k_rho : float
        NaN for a fluid case (``dT=…``) or a file of δn.
    delta_n_max : float
        Largest ``max δn - min δn`` of the two exposures' fields.
    dt : float
        Time between exposures (time units).
    motion : str
        :data:`rimcl.piv.tracer_motion.MOTION_3D` or ``MOTION_SHEET``.
    scene : rimcl.optics.camera.Scene
    camera : PlaneCamera, PupilCamera or LensCamera
    imaging : PivImaging
    renderer : rimcl.imaging.render.Renderer
        Pixel size, frame origin and point spread of the frames.
    device : pyopencl.Device
    """

    field: PivFrames
    reference: PivReference
    config: dict
    case: str
    k_rho: float
    delta_n_max: float
    dt: float
    motion: str
    scene: Scene
    camera: object
    imaging: PivImaging
    renderer: Renderer
    device: object

    @property
    def uniform(self):
        """The uniform-medium pair (from the reference)."""
        return self.reference.uniform

    @property
    def pixel_size(self):
        """Length units per pixel."""
        return self.renderer.pixel_size

    @property
    def m_s_per_px(self):
        """Metres per second of one pixel of displacement between the exposures, where the
        field's scales are known (``length_m`` and ``time_s`` of :attr:`config`), else None."""
        length_m, time_s = self.config.get("length_m"), self.config.get("time_s")
        if length_m is None or time_s is None:
            return None
        return self.pixel_size * float(length_m) / (self.dt * float(time_s))


def _exposure_times(source, start_frame, dt):
    """Times of exposures A and B, Δt, the stored frames spanning them, and B's stored
    frame (None where B falls between stored frames)."""
    times = np.asarray(source.times, dtype=np.float64)
    if not 0 <= start_frame < len(times):
        raise RimclError(
            f"start frame {start_frame} does not exist: the field has frames 0..{len(times) - 1}"
        )
    t_a = float(times[start_frame])
    if dt is None:
        if start_frame + 1 >= len(times):
            raise RimclError(
                f"frame {start_frame} is the last stored frame: give the time between exposures"
            )
        dt = float(times[start_frame + 1] - t_a)
    dt = float(dt)
    if not (np.isfinite(dt) and dt > 0):
        raise RimclError(f"the time between exposures must be positive, got {dt}")
    t_b = t_a + dt
    slack = 1e-9 * max(1.0, abs(times[-1]))
    if t_b > times[-1] + slack:
        raise RimclError(
            f"the second exposure at t = {t_b:g} lies beyond the last stored frame "
            f"(t = {times[-1]:g}); use a shorter time between exposures (at most "
            f"{times[-1] - t_a:g} from frame {start_frame})"
        )
    last = int(np.searchsorted(times, t_b - slack, side="left"))
    stored_b = np.flatnonzero(np.abs(times - t_b) <= slack)
    frame_b = int(stored_b[0]) if stored_b.size else None
    t_b = min(t_b, float(times[-1]))
    return t_a, t_b, dt, list(range(start_frame, max(last, start_frame) + 1)), frame_b


def _piv_scene(source, piv):
    """The scene: as :meth:`Scene.from_grid`; the sheet of a field with only a sheet
    velocity sits on that plane; a clamped field's default sheet moves one seeding
    half-width inside it."""
    sheet_plane = None if getattr(source, "has_full_velocity", False) else _sheet_plane(source)
    x_sheet = piv.x_sheet if piv.x_sheet is not None else sheet_plane
    scene = Scene.from_grid(
        source.origin, source.spacing, source.shape, source.boundary, x_sheet, piv.depth
    )
    thickness = piv.imaging.thickness(scene)
    n1 = int(source.shape[-1])
    extent = float(source.spacing[0]) * (n1 if scene.periodic else n1 - 1)
    if 2 * SEED_HALF_WIDTH * thickness > extent:
        # the tracers would be seeded beyond the field (or over several of its periods):
        # most of them outside it, the density far below the one asked for
        half = SEED_HALF_WIDTH * thickness
        raise RimclError(
            f"the light sheet ({thickness:g} thick, tracers seeded ± {half:g} around it) "
            f"is thicker than the field along x1 ({extent:g}); use a sheet "
            f"thickness (--sheet-thickness, piv.sheet_thickness) up to "
            f"{extent / (2 * SEED_HALF_WIDTH):g}"
        )
    if scene.periodic or sheet_plane is not None:
        # tracers below a clamped grid see its edge values (the clamped boundary)
        return scene
    half = SEED_HALF_WIDTH * piv.imaging.thickness(scene)
    low = float(source.origin[0])
    if x_sheet is None:
        return Scene.from_grid(
            source.origin, source.spacing, source.shape, source.boundary, low + half, piv.depth
        )
    if scene.x_sheet - half < low or scene.x_sheet + half > low + extent:
        raise RimclError(
            f"the tracers around the sheet x1 = {scene.x_sheet:g} (± {half:g}) reach beyond "
            f"the field ({low:g} <= x1 <= {low + extent:g}); move the sheet inside or make "
            "it thinner"
        )
    return scene


def check_piv_scene(field, piv):
    """Refuse, before anything is rendered, a PIV measurement whose sheet does not fit the
    field (as :func:`run_piv_render` would, after a study had written files).

    Parameters
    ----------
    field : str, Path or None
        The field file (None: the shipped sample).
    piv : PivConfig
    """
    from rimcl.ptv.field_source import open_source

    with ExitStack() as stack:
        source, _ = open_source(field, stack)
        if piv.box is not None:
            source = CroppedSource(source, piv.box)
        _piv_scene(source, piv)


def _sheet_plane(source):
    """The ``x1`` of a stored sheet velocity, or None."""
    inner = getattr(source, "source", source)  # a CroppedSource reads its file's plane
    return getattr(inner, "velocity_sheet_x1", None)


def _progress(enabled, tracers, exposures):
    """A progress bar over the tracers of every exposure to image (None when off)."""
    if not enabled:
        return None
    from tqdm.auto import tqdm

    total = None if tracers is None else tracers * exposures
    return tqdm(total=total, unit="tracer", desc="piv render", disable=None)


def run_piv_render(
    field=None,
    *,
    case=None,
    k_rho=None,
    piv=None,
    camera=None,
    integrator=None,
    fluid=None,
    run=None,
    reference=None,
    sensor=None,
    mie=None,
    progress=False,
):
    """PIV frame pairs of one refractive-index case, through the field and a uniform medium.

    Parameters
    ----------
    field : str, Path or FieldFile, optional
        A rimcl field file with velocity, full or on the sheet only (default: the
        shipped sample, which stores the sheet velocity only).
    case, k_rho :
        The case: ``"C0"`` … ``"C4"``, ``"G=…"``, ``"dT=…"``/``"dS=…"`` (with ``fluid``),
        or the Gladstone–Dale product ``k_rho`` (as :func:`rimcl.ptv.measure.run_render`).
    piv : PivConfig, optional
    camera : rimcl.scene.config.CameraConfig, optional
        Default :data:`PIV_CAMERA`. A lens camera sets the frame (its sensor, pixel size
        and tracer image); ``imaging.pixels`` and ``imaging.diameter`` then do not apply.
    integrator : rimcl.scene.config.IntegratorConfig, optional
        Interpolation, precision and step of :func:`rimcl.trace_rays` (not ``auto``).
    fluid : rimcl.scene.config.FluidConfig, optional
        The fluid of ``dT=…``/``dS=…`` cases.
    run : rimcl.scene.config.RunConfig, optional
        Device, engine (``device``: frames made on the OpenCL device; ``numpy``: the
        reference) and rays per batch.
    reference : PivReference or sequence of PivReference, optional
        From an earlier case with the same configuration: skips tracers, truth and the
        uniform-medium pair. A sequence offers candidates: the one made for this
        configuration is used, and the reference pair is made when none is (a lens
        camera's reference depends on the case's mean index).
    sensor : rimcl.scene.config.SensorConfig, optional
        The camera's sensor (default: deterministic, ``imaging.bit_depth`` bits); its seed
        defaults to ``piv.seed``. Noise draws: the uniform-medium frames and the field's
        share pass 0 (common random numbers), the noise floor's second uniform pair pass 1;
        exposure A frame 0, B frame 1.
    mie : rimcl.scene.config.MieConfig, optional
        Mie weights of the rays (default: off).
    progress : bool
        A progress bar over the tracers imaged (on a terminal).

    Returns
    -------
    PivRender
    """
    from rimcl.core.device import describe_device, select_device
    from rimcl.ptv.field_source import case_of, open_source, reference_step, uniform_like

    piv = PivConfig() if piv is None else piv
    camera_config = PIV_CAMERA if camera is None else camera
    integrator = IntegratorConfig() if integrator is None else integrator
    run = RunConfig() if run is None else run
    if integrator.interp == "auto":
        raise RimclError("PIV frames take a fixed interpolation (not auto)")
    imaging, settings = piv.imaging, piv.settings
    with ExitStack() as stack:
        source, source_name = open_source(field, stack)
        if piv.box is not None:
            source = CroppedSource(source, piv.box)
        case_index = case_of(source, case, k_rho, FluidConfig() if fluid is None else fluid)
        t_a, t_b, dt, frames, frame_b = _exposure_times(source, int(piv.start_frame), piv.dt)
        scene = _piv_scene(source, piv)
        # the case's mean index: a lens is focused through it (as PTV's), the tracers
        # scatter in it, and the uniform medium of the reference pair has it
        medium_index = case_index.mean_index(source, int(piv.start_frame), t_a)
        cam = camera_config.build(scene, medium_index)
        device = select_device(run.device)
        renderer = imaging.renderer(scene, cam)
        sensor_model = (SensorConfig() if sensor is None else sensor).build(
            imaging.bit_depth, piv.seed
        )
        mie_weights = (
            None
            if mie is None
            else mie.build(None if fluid is None else fluid.build(), medium_index)
        )
        grid = WindowGrid.for_image(
            imaging.frame_shape(scene, cam), int(settings.window), float(settings.overlap)
        )
        key = {
            "field": source_name,
            "box": piv.describe()["box"],
            "times": [t_a, t_b],
            "scene": scene.describe(),
            "camera": cam.describe(),
            "imaging": imaging.describe(scene, cam),
            "truth_windows": {"window": int(settings.window), "overlap": float(settings.overlap)},
            "seed": int(piv.seed),
            "sensor": sensor_model.describe(),
            "mie": None if mie_weights is None else mie_weights.describe(),
            "trace": {
                "interp": integrator.interp,
                "precision": integrator.precision,
                "step": None if integrator.step is None else float(integrator.step),
                "device": describe_device(device),
            },
        }
        options = {"interp": integrator.interp, "precision": integrator.precision}
        options["device"] = device
        if isinstance(reference, (list, tuple)):  # candidates: the one made for this key
            reference = next(
                (r for r in reference if {k: v for k, v in r.key.items() if k != "motion"} == key),
                None,
            )
        n_tracers = None if reference is None else reference.positions.shape[1]
        bar = _progress(progress, n_tracers, 4 if reference is None else 2)
        imaging_options = {
            "rays_per_batch": run.rays_per_batch,
            "engine": run.engine,
            "sensor": sensor_model,
            "mie": mie_weights,
            "bar": bar,
        }
        if reference is None:
            rng = np.random.default_rng(np.random.SeedSequence(int(piv.seed)))
            start = seed_particles(scene, imaging, rng, cam)
            positions, motion = move_tracers(source, scene, start, (t_a, t_b), frames)
            weights = pair_weights(positions, scene.x_sheet, imaging.thickness(scene, cam))
            uniform = uniform_like(source, getattr(cam, "fluid_index", 1.0))
            if bar is not None:
                bar.reset(total=(6 if sensor_model.noise else 4) * positions.shape[1])
            uniform_frames = image_frames(
                (uniform, uniform),
                positions,
                scene,
                cam,
                imaging,
                {**options, "step": reference_step(integrator.step, source)},
                noise=(REFERENCE_PASS, 0),
                **imaging_options,
            )
            floor_frames = None
            if sensor_model.noise:
                # the same pair again with independent draws: the camera's noise alone
                floor_frames = image_frames(
                    (uniform, uniform),
                    positions,
                    scene,
                    cam,
                    imaging,
                    {**options, "step": reference_step(integrator.step, source)},
                    noise=(FLOOR_PASS, 0),
                    **imaging_options,
                )
            reference = PivReference(
                key={**key, "motion": motion},
                positions=positions,
                weights=weights,
                truth=true_displacement(
                    positions, renderer, imaging.frame_shape(scene, cam), grid, weights
                ),
                uniform=uniform_frames,
                floor=floor_frames,
            )
        elif {k: v for k, v in reference.key.items() if k != "motion"} != key:
            changed = sorted(k for k in key if reference.key.get(k) != key[k])
            raise RimclError(
                "the PIV reference was made for another configuration (differs in: "
                f"{', '.join(changed)})"
            )
        fields = (
            case_index.field(source, int(piv.start_frame), t_a),
            case_index.field(source, frame_b, t_b),
        )
        delta_n_max = max(f.delta_n_range for f in fields)
        measured = image_frames(
            fields,
            reference.positions,
            scene,
            cam,
            imaging,
            {**options, "step": integrator.step},
            noise=(MEASURED_PASS, 0),
            **imaging_options,
        )
        if bar is not None:
            bar.close()
    config = {
        **reference.key,
        "case": case_index.name,
        "k_rho": case_index.g,
        "dt": dt,
        "start_frame": int(piv.start_frame),
        "velocity_frames": frames,
        "n_tracers": int(reference.positions.shape[1]),
        "rays_per_batch": int(run.rays_per_batch),
        # metres per field length unit and seconds per field time unit, where known
        "length_m": camera_config.length_m,
        "time_s": piv.time_s,
        "image_rows": "row 0 at the top (highest x3), rows along -x3, columns along x2; "
        "pixel centres at integer coordinates",
    }
    return PivRender(
        field=measured,
        reference=reference,
        config=config,
        case=case_index.name,
        k_rho=case_index.g,
        delta_n_max=delta_n_max,
        dt=dt,
        motion=reference.key["motion"],
        scene=scene,
        camera=cam,
        imaging=imaging,
        renderer=renderer,
        device=device,
    )
