"""Time-resolved PIV: sequences of N frames Δt apart, several realisations per call
(:func:`run_piv_sequence`), with a dense per-pixel truth and the particle table per frame.

Each realisation (one seed) seeds its own tracers as a PIV pair does
(:func:`rimcl.piv.imaging_config.seed_particles`), carries them through the flow over all
``frames`` exposures ``t_k = t_A + k Δt`` (:func:`rimcl.piv.tracer_motion.move_tracers`) and
images exposure ``k`` through the field at ``t_k`` (:func:`rimcl.piv.frame_pair.image_frames`,
either engine; sensor noise frame ``k``, the measured pass
:data:`rimcl.imaging.sensor.MEASURED_PASS`).

**Dense truth**: for every pixel centre on the sheet and every step ``k → k + 1``, the
displacement of a fluid particle starting there at ``t_k`` (the same RK4 integration as the
tracers'), in pixels per frame; with a length scale (metres per field length unit) and a
time scale (seconds per field time unit) also in m/s. Pixels as every PIV output of rimcl
(:func:`rimcl.piv.imaging_config.frame_pixels`): row 0 at the top (highest ``x3``), pixel
``(row i, column j)`` centred at ``(x, y) = (j, i)``, ``dy > 0`` down the frame.

**Reference sequence**: the same tracers at the same instants imaged through a uniform medium
(the fluid's index, :func:`rimcl.ptv.field_source.uniform_like`) with the same sensor noise
draws (common random numbers, as a PIV pair's reference): what the camera would record without
refraction, so that the difference of the two sequences' vectors is refraction's alone.

Files (:func:`write_piv_sequence`): per seed ``PREFIX_seed<s>_<k>.tif`` (``k`` from 000,
through the field), ``PREFIX_seed<s>_uniform_<k>.tif`` (the reference) and
``PREFIX_seed<s>_truth.h5`` (``rimcl_schema = "piv_sequence_truth"``, ``schema_version =
2``), every dataset with named dimensions and ``units`` for ``xarray.open_dataset``:
``times (frame)`` (field time units), ``truth/dx``, ``truth/dy`` (``(step, row, column)``,
``frames - 1`` steps, px per frame), ``truth/u_ms``, ``truth/v_ms`` (with both scales, m/s),
``particles/position`` (``(id, frame, axis)``, field length units), ``particles/col``,
``particles/row`` (``(id, frame)``, pixels), ``particles/intensity`` (sheet intensity),
``particles/image_point`` (mean image point of the collected rays, ``(id, frame,
image_axis)``, ``x2, x3``), ``particles/rays_collected``, and the reference's
``particles/image_point_uniform``, ``particles/rays_collected_uniform``; root attributes ``units``,
``config``, ``versions``.
"""

import dataclasses
from contextlib import ExitStack
from pathlib import Path

import h5py
import numpy as np

from rimcl.core.atomic import atomic_path
from rimcl.core.errors import RimclError
from rimcl.core.outputs import OutputSet
from rimcl.core.provenance import stamp_h5
from rimcl.core.tables_h5 import TRACER_DIMENSIONS, add_scale, write_variable
from rimcl.fields.crop import CroppedSource
from rimcl.imaging.sensor import MEASURED_PASS
from rimcl.piv.analysis import vector_unit, write_tiff
from rimcl.piv.frame_pair import PivFrames, image_frames
from rimcl.piv.imaging_config import (
    frame_pixels,
    frame_points,
    seed_particles,
    sheet_intensity,
)
from rimcl.piv.render import PIV_CAMERA, PivConfig, _piv_scene, _progress
from rimcl.piv.tracer_motion import move_tracers
from rimcl.scene.config import FluidConfig, IntegratorConfig, RunConfig, SensorConfig

SEQUENCE_SCHEMA = "piv_sequence_truth"


@dataclasses.dataclass
class PivSequence:
    """One realisation of a time-resolved PIV sequence.

    Attributes
    ----------
    seed : int
    times : ndarray, shape (F,)
        Exposure times (field time units).
    positions : ndarray, shape (F, N, 3)
        Tracer positions (field length units).
    frames : rimcl.piv.frame_pair.PivFrames
        The F frames through the field.
    uniform : rimcl.piv.frame_pair.PivFrames
        The same F exposures through a uniform medium, the same noise draws.
    truth_px : ndarray, float64, shape (F - 1, rows, columns, 2)
        Dense truth ``(dx, dy)`` per pixel, pixels per frame.
    truth_ms : ndarray or None
        The same in m/s (with both scales).
    pixels : ndarray, shape (F, N, 2)
        Tracer positions in pixels ``(col, row)``.
    intensity : ndarray, shape (F, N)
    config : dict
    device : pyopencl.Device
    """

    seed: int
    times: np.ndarray
    positions: np.ndarray
    frames: PivFrames
    uniform: PivFrames
    truth_px: np.ndarray
    truth_ms: object
    pixels: np.ndarray
    intensity: np.ndarray
    config: dict
    device: object


def exposure_times(source, start_frame, dt, frames):
    """Times of ``frames`` exposures ``dt`` apart from stored frame ``start_frame``, the
    stored frames spanning them, and each exposure's stored frame (None between frames)."""
    times = np.asarray(source.times, dtype=np.float64)
    if int(frames) < 2:
        raise RimclError(f"a PIV sequence needs at least 2 frames, got {frames}")
    if not 0 <= start_frame < len(times):
        raise RimclError(
            f"start frame {start_frame} does not exist: the field has frames 0..{len(times) - 1}"
        )
    if not (np.isfinite(dt) and dt > 0):
        raise RimclError(f"the time between exposures must be positive, got {dt}")
    wanted = times[start_frame] + dt * np.arange(int(frames))
    slack = 1e-9 * max(1.0, abs(times[-1]))
    if wanted[-1] > times[-1] + slack:
        raise RimclError(
            f"exposure {frames - 1} at t = {wanted[-1]:g} lies beyond the last stored frame "
            f"(t = {times[-1]:g}); use fewer frames or a shorter time between them"
        )
    wanted = np.minimum(wanted, times[-1])
    stored = [
        int(np.flatnonzero(np.abs(times - t) <= slack)[0])
        if np.any(np.abs(times - t) <= slack)
        else None
        for t in wanted
    ]
    last = int(np.searchsorted(times, wanted[-1] - slack, side="left"))
    return wanted, list(range(start_frame, max(last, start_frame) + 1)), stored


def dense_truth(source, scene, renderer, shape, times, frames):
    """Displacement per pixel and frame step of fluid particles starting at the pixel
    centres on the sheet (pixels per frame), shape ``(F - 1, rows, columns, 2)``."""
    rows, cols = shape
    col, row = np.meshgrid(np.arange(cols, dtype=np.float64), np.arange(rows, dtype=np.float64))
    on_sheet = frame_points(renderer, shape, np.column_stack([col.ravel(), row.ravel()]))
    start = np.column_stack([np.full(len(on_sheet), scene.x_sheet), on_sheet])
    steps = []
    for k in range(len(times) - 1):
        moved, _ = move_tracers(source, scene, start, (times[k], times[k + 1]), frames)
        pixels = frame_pixels(renderer, shape, moved[..., 1:])
        steps.append((pixels[1] - pixels[0]).reshape(rows, cols, 2))
    return np.stack(steps)


def run_piv_sequence(
    field=None,
    *,
    case=None,
    k_rho=None,
    piv=None,
    frames=2,
    seeds=(0,),
    camera=None,
    integrator=None,
    fluid=None,
    run=None,
    sensor=None,
    mie=None,
    length_m=None,
    time_s=None,
    progress=False,
):
    """Time-resolved PIV sequences of one case, one per seed (module docstring).

    Parameters
    ----------
    field, case, k_rho, piv, camera, integrator, fluid, run, sensor, mie :
        As :func:`rimcl.piv.render.run_piv_render` (``piv.seed`` is replaced by each seed;
        a sensor without its own seed draws with each seed).
    frames : int
        Exposures per sequence, ``piv.dt`` apart (at least 2).
    seeds : sequence of int
        One independent realisation per seed.
    length_m, time_s : float, optional
        Metres per field length unit and seconds per field time unit: with both, the
        dense truth in m/s too. A lens camera's ``length_m`` is the default length scale.
    progress : bool

    Returns
    -------
    list of PivSequence
    """
    from rimcl.core.device import describe_device, select_device
    from rimcl.core.memory import check_sequence_memory
    from rimcl.ptv.field_source import case_of, open_source, reference_step, uniform_like

    piv = PivConfig() if piv is None else piv
    camera_config = PIV_CAMERA if camera is None else camera
    integrator = IntegratorConfig() if integrator is None else integrator
    run = RunConfig() if run is None else run
    sensor = SensorConfig() if sensor is None else sensor
    if integrator.interp == "auto":
        raise RimclError("PIV frames take a fixed interpolation (not auto)")
    seeds = [int(s) for s in seeds]
    if not seeds:
        raise RimclError("give at least one seed")
    imaging = piv.imaging
    results = []
    with ExitStack() as stack:
        source, source_name = open_source(field, stack)
        if piv.box is not None:
            source = CroppedSource(source, piv.box)
        case_index = case_of(source, case, k_rho, FluidConfig() if fluid is None else fluid)
        times, spanned, stored = exposure_times(source, int(piv.start_frame), float(piv.dt), frames)
        scene = _piv_scene(source, piv)
        cam = camera_config.build(scene)
        if length_m is None and getattr(cam, "length_m", None) is not None:
            length_m = float(cam.length_m)
        device = select_device(run.device)
        renderer = imaging.renderer(scene, cam)
        shape = imaging.frame_shape(scene, cam)
        check_sequence_memory(
            source.shape, frames, len(seeds), shape, length_m is not None and time_s is not None
        )
        fields = [case_index.field(source, f, t) for f, t in zip(stored, times, strict=True)]
        options = {"interp": integrator.interp, "precision": integrator.precision}
        options.update(device=device, step=integrator.step)
        truth_px = dense_truth(source, scene, renderer, shape, times, spanned)
        truth_ms = None
        if length_m is not None and time_s is not None:
            truth_ms = truth_px * (renderer.pixel_size * length_m / (float(piv.dt) * time_s))
        thickness = imaging.thickness(scene, cam)
        uniform = uniform_like(source, getattr(cam, "fluid_index", 1.0))
        bar = _progress(progress, None, len(times))
        for seed in seeds:
            rng = np.random.default_rng(np.random.SeedSequence(seed))
            start = seed_particles(scene, imaging, rng, cam)
            positions, motion = move_tracers(source, scene, start, times, spanned)
            if bar is not None:
                bar.reset(total=len(times) * positions.shape[1])
            model = sensor.build(imaging.bit_depth, seed)
            imaging_options = {
                "rays_per_batch": run.rays_per_batch,
                "engine": run.engine,
                "sensor": model,
                "mie": None if mie is None else mie.build(None if fluid is None else fluid.build()),
                "noise": (MEASURED_PASS, 0),
                "bar": bar,
            }
            made = image_frames(fields, positions, scene, cam, imaging, options, **imaging_options)
            if bar is not None:
                bar.reset(total=len(times) * positions.shape[1])
            # the reference: the same exposures through the uniform medium, the same draws
            reference = image_frames(
                [uniform] * len(times),
                positions,
                scene,
                cam,
                imaging,
                {**options, "step": reference_step(integrator.step, source)},
                **imaging_options,
            )
            config = {
                "field": source_name,
                "case": case_index.name,
                "k_rho": case_index.g,
                "times": times.tolist(),
                "dt": float(piv.dt),
                "frames": int(frames),
                "seed": seed,
                "motion": motion,
                "scene": scene.describe(),
                "camera": cam.describe(),
                "imaging": imaging.describe(scene, cam),
                "sensor": model.describe(),
                "engine": run.engine,
                "length_m": length_m,
                "time_s": time_s,
                "device": describe_device(device),
                "n_tracers": int(positions.shape[1]),
            }
            results.append(
                PivSequence(
                    seed=seed,
                    times=times,
                    positions=positions,
                    frames=made,
                    uniform=reference,
                    truth_px=truth_px,
                    truth_ms=truth_ms,
                    pixels=frame_pixels(renderer, shape, positions[..., 1:]),
                    intensity=sheet_intensity(positions[..., 0], scene.x_sheet, thickness),
                    config=config,
                    device=device,
                )
            )
        if bar is not None:
            bar.close()
    return results


def sequence_paths(prefix, seed, frames, medium=""):
    """The files of one realisation: ``frames`` TIFFs (through the field, or with ``medium =
    "uniform"`` the reference's) and the truth file."""
    prefix = Path(prefix)
    tag = f"{medium}_" if medium else ""
    tiffs = [prefix.with_name(f"{prefix.name}_seed{seed}_{tag}{k:03d}.tif") for k in range(frames)]
    return tiffs, prefix.with_name(f"{prefix.name}_seed{seed}_truth.h5")


#: The files ``rimcl piv sequence`` writes for a prefix (an earlier run's are replaced as a
#: set, :class:`rimcl.core.outputs.OutputSet`).
SEQUENCE_OWNED = (
    "{prefix}_seed*_[0-9][0-9][0-9]*.tif",
    "{prefix}_seed*_uniform_[0-9][0-9][0-9]*.tif",
    "{prefix}_seed*_truth.h5",
)


def open_sequence_outputs(prefix, overwrite=False, inputs=()):
    """The output set of ``rimcl piv sequence`` with ``prefix``: an earlier run's files
    (every seed and frame of it) are refused before any work unless ``overwrite``, and
    replaced as a set only when the whole run succeeded; no input may be an output."""
    return OutputSet(prefix, overwrite=overwrite, prefix=True, owned=SEQUENCE_OWNED, inputs=inputs)


def write_piv_sequence(outputs, sequence):
    """Write one realisation's frames and truth (module docstring) into the output set
    ``outputs`` (:func:`open_sequence_outputs`); returns the final paths."""
    prefix = outputs.folder / outputs.prefix
    tiffs, truth = sequence_paths(prefix, sequence.seed, len(sequence.times))
    uniform_tiffs, _ = sequence_paths(prefix, sequence.seed, len(sequence.times), "uniform")
    for path, image in zip(tiffs, sequence.frames.images, strict=True):
        write_tiff(outputs.path(path.name), image, sequence.config)
    reference_config = {**sequence.config, "medium": "uniform (the reference sequence)"}
    for path, image in zip(uniform_tiffs, sequence.uniform.images, strict=True):
        write_tiff(outputs.path(path.name), image, reference_config)
    final = truth
    truth = outputs.path(truth.name)
    with atomic_path(truth) as tmp, h5py.File(tmp, "w") as h5:
        h5.attrs["rimcl_schema"] = SEQUENCE_SCHEMA
        h5.attrs["schema_version"] = 2  # 2: (id, frame) particles, named dimensions
        # u_ms, v_ms only where both scales are known (named only then)
        in_m_s = "; u_ms, v_ms in m/s" if sequence.truth_ms is not None else ""
        h5.attrs["units"] = (
            "times in field time units; positions in field length units; col, row, dx, dy "
            f"in pixels (dx, dy per frame){in_m_s}; x along image columns, y along image rows"
        )
        # named dimensions and units on every dataset, for xarray.open_dataset(path, group=...)
        frames = len(sequence.times)
        add_scale(h5, "frame", np.arange(frames))
        write_variable(h5, "times", sequence.times, ("frame",), "T0")
        group = h5.create_group("truth")
        steps, rows, columns = sequence.truth_px.shape[:3]
        add_scale(group, "step", np.arange(steps))  # exposure k to k + 1
        add_scale(group, "row", np.arange(rows), "px")
        add_scale(group, "column", np.arange(columns), "px")
        dense = {"dx": sequence.truth_px[..., 0], "dy": sequence.truth_px[..., 1]}
        if sequence.truth_ms is not None:
            dense.update(u_ms=sequence.truth_ms[..., 0], v_ms=sequence.truth_ms[..., 1])
        for name, values in dense.items():
            write_variable(group, name, values, ("step", "row", "column"), vector_unit(name))
        group.attrs["definition"] = (
            "displacement from exposure k to k + 1 of a fluid particle starting at each "
            "pixel centre on the sheet at exposure k"
        )
        particles = h5.create_group("particles")
        add_scale(particles, "id", np.arange(sequence.positions.shape[1]))
        add_scale(particles, "frame", np.arange(frames))
        add_scale(particles, "axis", ["x1", "x2", "x3"])
        add_scale(particles, "image_axis", ["x2", "x3"])
        columns = {
            "position": (sequence.positions, "axis", "L0"),
            "col": (sequence.pixels[..., 0], None, "px"),
            "row": (sequence.pixels[..., 1], None, "px"),
            "intensity": (sequence.intensity, None, "1"),
            "image_point": (sequence.frames.optics, "image_axis", "L0"),
            "rays_collected": (sequence.frames.collected, None, "1"),
            "image_point_uniform": (sequence.uniform.optics, "image_axis", "L0"),
            "rays_collected_uniform": (sequence.uniform.collected, None, "1"),
        }
        for name, (values, last, units) in columns.items():
            dimensions = (*TRACER_DIMENSIONS, last) if last else TRACER_DIMENSIONS
            write_variable(particles, name, np.swapaxes(values, 0, 1), dimensions, units)
        stamp_h5(h5, sequence.config, sequence.device)
    return [*tiffs, *uniform_tiffs, final]
