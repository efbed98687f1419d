"""The LPT chain: tracks, views through the field, images, calibration, triangulation,
self-calibration, matching, statistics.

For each case of the scene (same tracers, same tracks, common random numbers):

1. the rig is built for the case's fluid (its reference index is the calibration fluid);
2. each camera is calibrated on a target through the uniform fluid (:mod:`.calibration`);
3. the rig's exposure is set from the chief rays through the uniform fluid, and the rays
   per tracer are chosen by convergence of the located image centroid (:mod:`.images`,
   :mod:`.views`);
4. at every frame each tracer is seen by each camera through the field (``meas``) and
   through the uniform fluid (``ref``, with the same sensor noise draws), its image
   rendered, digitised and located, and triangulated on the calibrated models, from the
   located centroids and from the optics centroids (the optics part of the error); a noisy
   camera exposes the reference again with other draws (``floor``: the noise floor);
5. the volume self-calibration corrects the models on the measured images of every frame
   (:mod:`.selfcal`), and the first frame is matched from the images alone
   (:mod:`.matching`);
6. tracks are fitted (sliding polynomial, :func:`rimcl.ptv.track.sliding_fit`) and compared:
   refraction ``meas - ref`` (with and without the self-calibration), its optics and
   imaging parts, the noise floor ``floor - ref`` and the baseline ``ref - true``, per
   component (:mod:`rimcl.lpt.budget`); the headline numbers again with every image located at
   each camera's threshold ×½ and ×2 (:mod:`rimcl.lpt.sensitivity`).

Units: positions in field length units (``length_m`` metres each), image points in pixels,
velocities in length/time units, accelerations in length/time² units; with the scene's time
scale (``field.time_s``, ``time_s`` seconds per field time unit) each case's ``units`` block
also gives them in mm/s and m/s² (:mod:`rimcl.lpt.units`).
"""

import dataclasses
import time
from pathlib import Path

import numpy as np

from rimcl.core.errors import RimclError
from rimcl.imaging.frames import THRESHOLD_VARIANTS
from rimcl.lpt import checks
from rimcl.lpt.budget import FIT_KINDS, budget_lines, kinematic_errors
from rimcl.lpt.calibration import PinholeModel, SoloffModel, target_points, triangulate
from rimcl.lpt.config import CameraSpec, check_run_memory, preset_cameras
from rimcl.lpt.config import describe as describe_scene
from rimcl.lpt.flow import BUILTIN_DT, Volume, builtin_flow, volume_velocity
from rimcl.lpt.frames import recorded_frame
from rimcl.lpt.images import (
    PASSES,
    camera_imaging,
    device_imager,
    locate_view,
    noiseless,
    ray_light,
    rig_exposure,
    unusable,
)
from rimcl.lpt.matching import match_frame
from rimcl.lpt.rig import RigCamera
from rimcl.lpt.sensitivity import band_lines, threshold_sensitivity
from rimcl.lpt.units import COMPONENTS, case_units
from rimcl.lpt.views import Tracer, choose_ray_count, uniform_field, view
from rimcl.optics.camera import FlatWindow
from rimcl.stats.bootstrap import TracerBootstrap
from rimcl.stats.summaries import error_summary

#: Tracers sampled to choose the ray count.
RAY_SAMPLE = 32
#: Flag bits of a tracer: a ray that did not reach the exit face, an image off a sensor.
FLAG_RAY_FAILED = 1
FLAG_OFF_SENSOR = 2
#: An image not located in some camera and frame (below threshold, cut by its window, ...).
FLAG_IMAGE_LOST = 4


@dataclasses.dataclass
class Run:
    """What every case of a run shares.

    Attributes
    ----------
    source : FieldFile
    times : ndarray, shape (F,)
    length_m : float
    volume : Volume
    true : ndarray, shape (F, N, 3)
        True positions.
    u_true, a_true : ndarray, shape (F, N, 3)
    time_s : float or None
        Seconds per field time unit, where the scene gives it.
    """

    source: object
    times: np.ndarray
    length_m: float
    volume: Volume
    true: np.ndarray
    u_true: np.ndarray
    a_true: np.ndarray
    time_s: float | None = None


def prepare(scene, out_dir, timings):
    """Open the field (or make the built-in flow), seed tracers, integrate true tracks."""
    from rimcl.fields.field_reader import FieldFile
    from rimcl.ptv.track import integrate_tracks, track_acceleration, track_velocity

    times = scene.measure.time
    frames, dt = times.frames, times.dt
    if frames < times.fit_window:
        raise RimclError(
            f"time.frames = {frames} is fewer than the fit window time.fit_window = "
            f"{times.fit_window}"
        )
    started = time.perf_counter()
    path = scene.study.field_path
    if not path:
        dt = BUILTIN_DT if dt is None else dt
        path = builtin_flow(out_dir, frames + times.start_frame, dt)
    source = FieldFile(path)
    if dt is None:
        if source.n_frames < 2:
            raise RimclError(f"{path} holds one frame: give time.dt")
        dt = float(source.times[1] - source.times[0])
    first = times.start_frame
    if first >= source.n_frames:
        raise RimclError(f"field.start_frame = {first}, but {path} holds {source.n_frames} frames")
    t0 = float(source.times[first])
    moments = t0 + dt * np.arange(frames)
    timings["flow"] = time.perf_counter() - started
    volume = Volume.of(source, scene.illumination)
    width = volume.hi[1] - volume.lo[1]
    length_m = scene.study.lpt.length_m or 0.1 / width
    started = time.perf_counter()
    velocity = volume_velocity(source, moments[0], moments[-1])
    count = scene.measure.tracers.count
    if scene.illumination.ppp is not None:
        spec = scene.rig.cameras[0] if scene.rig.cameras else CameraSpec((0, 0, 0), (0, 0, 0))
        count = max(
            1, round(scene.illumination.ppp * spec.sensor_pixels[0] * spec.sensor_pixels[1])
        )
    check_run_memory(scene, count, frames)
    start = volume.seed(count, np.random.default_rng(scene.measure.tracers.seed))
    true = integrate_tracks(velocity, start, moments)
    u_true = track_velocity(velocity, true, moments)
    a_true = track_acceleration(velocity, true, moments)
    timings["tracks"] = time.perf_counter() - started
    time_s = scene.study.lpt.time_s
    time_s = None if time_s is None else float(time_s)
    return Run(source, moments, float(length_m), volume, true, u_true, a_true, time_s)


def rig_cameras(rig, volume, length_m, fluid_index):
    """The cameras of a :class:`~rimcl.lpt.config.RigConfig` (its tables, or its preset
    placed for ``volume``) for a calibration fluid of ``fluid_index``."""
    specs = rig.cameras
    if not specs:
        centre = 0.5 * (volume.seed_lo + volume.seed_hi)
        specs = preset_cameras(
            rig.preset,
            look_at=centre,
            x_end=volume.x_end,
            width=volume.hi[1] - volume.lo[1],
            length_m=length_m,
            fluid_index=fluid_index,
            rig=rig,
        )
    # FlatWindow wants a positive thickness; a bare surface (0 mm) passes its own
    window = FlatWindow(rig.window_thickness_mm or 1.0, rig.window_index, rig.outside_index)
    to_field = 1e-3 / length_m
    return [
        RigCamera.build(
            spec.name,
            np.asarray(spec.position_mm) * to_field,
            np.asarray(spec.look_at_mm) * to_field,
            focal_length_mm=spec.focal_length_mm,
            f_number=spec.f_number,
            pixel_pitch_um=spec.pixel_pitch_um,
            pixels=spec.sensor_pixels,
            scheimpflug_deg=spec.scheimpflug_deg,
            length_m=length_m,
            x_end=volume.x_end,
            window=window,
            window_thickness_mm=rig.window_thickness_mm,
            fluid_index=fluid_index,
            wavelength_nm=rig.wavelength_nm,
            particle_diameter_um=rig.particle_diameter_um,
        )
        for spec in specs
    ]


def _tracer(scene, device):
    integrator = scene.measure.integrator
    return Tracer(
        engine=scene.lpt.engine,
        interp=integrator.interp,
        precision=integrator.precision,
        step=integrator.step,
        device=device,
        batch_size=scene.measure.run.rays_per_batch,
    )


def calibrate_rig(cameras, volume, settings):
    """Target through the uniform fluid; per camera the chosen model and the pinhole fit."""
    margin = 0.05 * (volume.seed_hi - volume.seed_lo)
    target = target_points(
        volume.seed_lo - margin,
        volume.seed_hi + margin,
        settings.calibration_planes,
        settings.calibration_grid,
    )
    projected = [camera.project(target) for camera in cameras]
    seen = checks.visible_target(cameras, target, projected)  # fitted and exported: these only
    target = target[seen]
    fitted = []
    for pixels in projected:
        pixels = pixels[seen]
        pinhole = PinholeModel.fit(target, pixels)
        soloff = SoloffModel.fit(target, pixels)
        fitted.append({"pinhole": pinhole, "soloff": soloff, "pixels": pixels})
    return target, fitted


def _sensor_and_mie(scene, n_ref):
    """The sensor (``[sensor]``, ``lpt.bit_depth`` bits) and the Mie weights (``[mie]``; the
    particle's surroundings default to the case's reference fluid), or None with Mie off."""
    measure = scene.measure
    sensor = measure.sensor.build(scene.lpt.bit_depth, measure.tracers.seed)
    mie = measure.mie
    if mie.fluid_index is None:
        mie = dataclasses.replace(mie, fluid_index=float(n_ref))
    return sensor, mie.build()


def _choose_rays(field, cameras, imagings, exposure, sensor, mie, points, tracer, settings, device):
    """Per camera, the ray count whose located centroid (noiseless sensor) has converged
    (imaged on ``device``, or by the NumPy engine without one)."""
    choices = []
    for c, camera in enumerate(cameras):
        quiet = dataclasses.replace(imagings[c], sensor=noiseless(sensor))

        def located(seen, quiet=quiet, c=c):
            light = ray_light(seen, mie)
            key = (PASSES["meas"], 0, c)
            imager = device_imager(quiet, light.shape[1], len(light), device)
            return locate_view(
                quiet, seen, light, exposure.counts_per_light, key, imager=imager
            ).centroid

        choices.append(
            choose_ray_count(
                field,
                camera,
                points,
                tracer,
                settings.ray_tolerance_px,
                settings.max_rays,
                centroid=located,
            )
        )
    return choices


def run_case(run, scene, case, device=None, progress=None, frame_sink=None):
    """Measure one case: views, images, triangulation, tracks (see the module's steps).

    Parameters
    ----------
    frame_sink : callable, optional
        ``frame_sink(case, kind, camera, frame, counts)`` receives every camera frame
        (``kind`` ``"meas"`` or ``"ref"``, counts uint16 (rows, columns)).

    Returns
    -------
    dict
        Arrays (``centroid_meas``/``ref`` (F, C, N, 2) located, ``optics_meas``/``ref``
        (F, C, N, 2) the rays' mean image points, ``x_meas``/``x_ref`` and
        ``x_opt_meas``/``x_opt_ref`` (F, N, 3), ``disparity_*`` (F, N, C), ``image_flags_*``
        (F, C, N), ``failed_rays`` (F, C, N), ``flags`` (N,); per variant threshold suffix
        ``s`` of :data:`~rimcl.imaging.frames.THRESHOLD_VARIANTS` ``centroid_<kind>_s``,
        ``image_flags_<kind>_s`` and ``x_<kind>_s``), the cameras, calibration,
        exposure, ray choices and stage ``timings`` (s).
    """
    from rimcl.ptv.field_source import case_of

    timings = {}
    settings = scene.lpt
    index = case_of(run.source, case, None, scene.measure.fluid)
    started = time.perf_counter()
    field0 = index.field(run.source, None, run.times[0])
    timings["field"] = time.perf_counter() - started
    cameras = rig_cameras(scene.rig, run.volume, run.length_m, field0.n_ref)
    started = time.perf_counter()
    target, fitted = calibrate_rig(cameras, run.volume, settings)
    models = [f[settings.model] for f in fitted]
    timings["calibration"] = time.perf_counter() - started
    # run.engine: tracer images on the device (its image kernel, which needs fp64; the
    # rays are traced there too) or by the NumPy engine
    imaging_device = None
    if scene.measure.run.engine == "device":
        from rimcl.core.device import select_device

        imaging_device = select_device(device, need_fp64=True)
    tracer = _tracer(scene, imaging_device or device)
    uniform = uniform_field(field0)
    sensor, mie = _sensor_and_mie(scene, field0.n_ref)
    started = time.perf_counter()
    chief = [view(uniform, camera, run.true[0], 1, tracer) for camera in cameras]
    exposure = rig_exposure(cameras, chief, mie, sensor, settings.exposure, settings.threshold)
    imagings = [camera_imaging(camera, c, exposure, sensor) for c, camera in enumerate(cameras)]
    sample = run.true[0][:RAY_SAMPLE]
    choices = _choose_rays(
        field0, cameras, imagings, exposure, sensor, mie, sample, tracer, settings, imaging_device
    )
    frames, count, ncam = run.true.shape[0], run.true.shape[1], len(cameras)
    imagers = [
        device_imager(imagings[c], choices[c]["rays"], count, imaging_device) for c in range(ncam)
    ]
    timings["ray_choice"] = time.perf_counter() - started
    kinds = ("meas", "ref")
    exposures = (*kinds, "floor")  # floor: the reference exposed again, other noise draws
    centroid = {kind: np.full((frames, ncam, count, 2), np.nan) for kind in exposures}
    optics = {kind: np.full((frames, ncam, count, 2), np.nan) for kind in exposures}
    image_flags = {kind: np.zeros((frames, ncam, count), dtype=np.int64) for kind in exposures}
    peaks = {kind: np.full((frames, ncam, count), np.nan) for kind in exposures}
    # the same images located at each variant threshold: (centroids, flags) per kind
    variants = {
        (kind, suffix): (np.full((frames, ncam, count, 2), np.nan), np.zeros_like(peaks[kind], int))
        for kind in kinds
        for suffix, _ in THRESHOLD_VARIANTS
    }
    failed = np.zeros((frames, ncam, count), dtype=np.int32)
    timings["views"] = timings["images"] = 0.0
    for k, moment in enumerate(run.times):
        started = time.perf_counter()
        field = field0 if k == 0 else index.field(run.source, None, moment)
        timings["field"] += time.perf_counter() - started
        for c, camera in enumerate(cameras):
            for kind, medium in (("meas", field), ("ref", uniform), ("floor", None)):
                if kind == "floor" and not sensor.noise:
                    continue  # a noiseless camera exposes the same image twice
                started = time.perf_counter()
                if medium is not None:  # the floor images the reference's rays again
                    seen = view(medium, camera, run.true[k], choices[c]["rays"], tracer)
                middle = time.perf_counter()
                light = ray_light(seen, mie)
                key = (PASSES[kind], k, c)
                found = locate_view(
                    imagings[c], seen, light, exposure.scale, key, imager=imagers[c]
                )
                timings["views"] += middle - started
                timings["images"] += time.perf_counter() - middle
                if kind == "meas":
                    failed[k, c] = seen.failed
                centroid[kind][k, c] = found.centroid
                optics[kind][k, c] = found.optics
                image_flags[kind][k, c] = found.flags
                peaks[kind][k, c] = found.peak
                for suffix, (points, bits) in found.variants.items() if medium else ():
                    variants[kind, suffix][0][k, c], variants[kind, suffix][1][k, c] = points, bits
                if frame_sink and medium is not None:
                    frame = recorded_frame(
                        imagings[c], seen, light, exposure.scale, key, camera.pixels
                    )
                    frame_sink(str(index.name), kind, camera, k, frame)
        if progress:
            progress(case, k + 1, frames)
    if not sensor.noise:
        centroid["floor"], image_flags["floor"] = centroid["ref"], image_flags["ref"]
    started = time.perf_counter()
    positions, disparity = {}, {}
    for kind in kinds:
        for label, points in ((kind, centroid[kind]), (f"opt_{kind}", optics[kind])):
            positions[label], disparity[label] = triangulate_frames(models, points)
    positions["floor"] = triangulate_frames(models, centroid["floor"])[0]
    pinhole = [f["pinhole"] for f in fitted]
    pinhole_ref = triangulate_frames(pinhole, centroid["ref"])[0]
    timings["triangulation"] = time.perf_counter() - started
    calibrated, calibration_record = None, None
    if settings.self_calibration:
        started = time.perf_counter()
        every = np.moveaxis(centroid["meas"], 1, 0).reshape(ncam, frames * count, 2)
        calibrated, calibration_record = checks.self_calibration(models, every, settings)
        if calibrated is not None:
            positions["vsc"], disparity["vsc"] = triangulate_frames(
                calibrated.models, centroid["meas"]
            )
        timings["self_calibration"] = time.perf_counter() - started
    matching = None
    if settings.model == "soloff":
        started = time.perf_counter()
        chosen = {"meas": models, "ref": models}
        if calibrated is not None:
            chosen["vsc"] = calibrated.models
        matching = {
            kind: [
                match_frame(chosen[kind], centroid["ref" if kind == "ref" else "meas"][0], tol)
                for tol in settings.match_tolerances_px
            ]
            for kind in chosen
        }
        timings["matching"] = time.perf_counter() - started
    flags = np.zeros(count, dtype=np.int32)
    flags[np.any(failed > 0, axis=(0, 1))] |= FLAG_RAY_FAILED
    off = np.zeros(count, dtype=bool)
    for c, camera in enumerate(cameras):
        off |= np.any(~checks.on_sensor(camera, optics["ref"][:, c]), axis=0)
    flags[off] |= FLAG_OFF_SENSOR
    lost = np.zeros(count, dtype=bool)
    for kind in kinds:
        lost |= np.any(unusable(image_flags[kind]), axis=(0, 1))
    flags[lost] |= FLAG_IMAGE_LOST
    result = {
        "case": str(index.name),
        "abscissa": _abscissa(index),
        "n_ref": float(field0.n_ref),
        "cameras": cameras,
        "calibration": [
            {
                "pinhole": f["pinhole"].describe(),
                "soloff": f["soloff"].describe(),
                "model": settings.model,
            }
            for f in fitted
        ],
        "target": target,
        "target_pixels": np.stack([f["pixels"] for f in fitted]),
        "rays": choices,
        "exposure": exposure.describe(),
        "sensor": sensor.describe(),
        "mie": None if mie is None else mie.describe(),
        "self_calibration": calibration_record,
        "matching": matching,
        "x_ref_pinhole": pinhole_ref,
        "failed_rays": failed,
        "flags": flags,
        "timings": timings,
    }
    for kind in kinds:
        result[f"centroid_{kind}"] = centroid[kind]
        result[f"optics_{kind}"] = optics[kind]
        result[f"image_flags_{kind}"] = image_flags[kind]
        result[f"peak_{kind}"] = peaks[kind]
        for label in (kind, f"opt_{kind}"):
            result[f"x_{label}"] = positions[label]
            result[f"disparity_{label}"] = disparity[label]
    result["x_floor"], result["centroid_floor"] = positions["floor"], centroid["floor"]
    result["image_flags_floor"] = image_flags["floor"]
    if calibrated is not None:
        result["x_vsc"], result["disparity_vsc"] = positions["vsc"], disparity["vsc"]
    for (kind, suffix), (points, bits) in variants.items():
        result[f"centroid_{kind}_{suffix}"], result[f"image_flags_{kind}_{suffix}"] = points, bits
        result[f"x_{kind}_{suffix}"] = triangulate_frames(models, points)[0]
    return result


def _abscissa(index):
    """What a case is plotted against: ``G``, or a fluid case's ``ΔT``/``ΔS``."""
    if index.fluid is not None:
        symbol = "ΔS" if index.fluid.kind == "saltwater" else "ΔT"
        return {"name": symbol, "value": float(index.difference), "unit": index.fluid.unit}
    if np.isfinite(index.g):
        return {"name": "G", "value": float(index.g), "unit": ""}
    return {"name": "delta_n", "value": None, "unit": ""}


#: Bin edges of the disparity histograms (px): log-spaced, 1e-3 to 1e2 px.
DISPARITY_EDGES = np.logspace(-3, 2, 41)


def triangulate_frames(models, pixels):
    """:func:`~rimcl.lpt.calibration.triangulate` of every frame of ``pixels`` (F, C, N, 2).

    Returns
    -------
    positions : ndarray, shape (F, N, 3)
    disparity : ndarray, shape (F, N, C)
    """
    frames, cameras, count = pixels.shape[:3]
    flat = np.moveaxis(pixels, 1, 0).reshape(cameras, frames * count, 2)
    positions, disparity = triangulate(models, flat)  # every frame at once: one Newton loop
    return positions.reshape(frames, count, 3), disparity.reshape(frames, count, cameras)


def rms_interval(values, ids, bootstrap):
    """rms of ``values`` and its bootstrap 95 % interval (rows of a tracer drawn together).

    Returns
    -------
    dict
        ``rms``, ``mean``, ``ci95`` (``[lo, hi]`` of the rms) and ``n``; None where empty.
    """
    values = np.asarray(values, dtype=np.float64)
    ids = np.asarray(ids)
    keep = np.isfinite(values)
    values, ids = values[keep], ids[keep]
    if not values.size:
        return {"rms": None, "mean": None, "ci95": None, "n": 0}
    resampled = []
    for weights in bootstrap.weight_blocks(ids):
        total = weights.sum(axis=0)
        with np.errstate(invalid="ignore", divide="ignore"):
            resampled.append(np.sqrt((values**2) @ weights / total))
    spread = np.concatenate(resampled)
    spread = spread[np.isfinite(spread)]
    return {
        "rms": float(np.sqrt(np.mean(values**2))),
        "mean": float(np.mean(values)),
        "ci95": [float(v) for v in np.percentile(spread, [2.5, 97.5])] if spread.size else None,
        "n": int(values.size),
    }


def case_statistics(run, result, scene):
    """Errors per component and the lost-match fractions of one case (JSON-able)."""
    from rimcl.ptv.track import sliding_fit

    keep = result["flags"] == 0
    frames = run.true.shape[0]
    ids = np.broadcast_to(np.arange(keep.size), (frames, keep.size))[:, keep].ravel()
    bootstrap = TracerBootstrap(np.flatnonzero(keep))
    pixel_per_camera, pixel = checks.pixel_sizes(result["cameras"])
    stats = {"tracers": int(keep.size), "tracers_kept": int(keep.sum())}
    stats["excluded"] = {
        "ray_failed": int(np.sum(result["flags"] & FLAG_RAY_FAILED > 0)),
        "off_sensor": int(np.sum(result["flags"] & FLAG_OFF_SENSOR > 0)),
        "image_lost": int(np.sum(result["flags"] & FLAG_IMAGE_LOST > 0)),
    }
    x_meas, x_ref = result["x_meas"][:, keep], result["x_ref"][:, keep]
    optics = result["x_opt_meas"][:, keep] - result["x_opt_ref"][:, keep]
    x_vsc = result["x_vsc"][:, keep] if "x_vsc" in result else None
    x_floor = result["x_floor"][:, keep]
    truth = run.true[:, keep]
    position = {}
    for axis, name in enumerate(COMPONENTS):
        refraction = rms_interval((x_meas - x_ref)[..., axis].ravel(), ids, bootstrap)
        baseline = rms_interval((x_ref - truth)[..., axis].ravel(), ids, bootstrap)
        position[name] = {
            "refraction": refraction,
            "optics": rms_interval(optics[..., axis].ravel(), ids, bootstrap),
            "imaging": rms_interval((x_meas - x_ref - optics)[..., axis].ravel(), ids, bootstrap),
            "noise_floor": rms_interval((x_floor - x_ref)[..., axis].ravel(), ids, bootstrap),
            "baseline": baseline,
            "refraction_self_calibrated": None
            if x_vsc is None
            else rms_interval((x_vsc - x_ref)[..., axis].ravel(), ids, bootstrap),
            "refraction_rms_px": None if refraction["rms"] is None else refraction["rms"] / pixel,
            "refraction_rms_px_per_camera": None
            if refraction["rms"] is None
            else {name: refraction["rms"] / size for name, size in pixel_per_camera.items()},
            "refraction_rms_um": None
            if refraction["rms"] is None
            else refraction["rms"] * run.length_m * 1e6,
        }
    stats["position"] = position
    stats["pixel_size"] = pixel  # the mean of the cameras': their order does not matter
    stats["pixel_size_per_camera"] = pixel_per_camera
    stats["no_tracer"] = checks.no_tracer_reason(stats)
    stats["not_resolved"] = checks.not_resolved(result, keep)
    disparity = {}
    for kind in ("meas", "ref", "opt_meas", "opt_ref", "vsc"):
        if f"disparity_{kind}" not in result:
            continue
        worst = np.max(result[f"disparity_{kind}"][:, keep], axis=-1).ravel()
        finite = worst[np.isfinite(worst)]
        counts, _ = np.histogram(finite, bins=DISPARITY_EDGES)
        disparity[kind] = {
            "histogram": {
                "edges_px": DISPARITY_EDGES.tolist(),
                "pdf_per_px": (counts / max(finite.size, 1) / np.diff(DISPARITY_EDGES)).tolist(),
                "below_first_edge": int(np.sum(finite < DISPARITY_EDGES[0])),
                "above_last_edge": int(np.sum(finite > DISPARITY_EDGES[-1])),
            },
            "median_px": float(np.median(finite)) if finite.size else None,
            "p95_px": float(np.percentile(finite, 95)) if finite.size else None,
            "max_px": float(np.max(finite)) if finite.size else None,
            "lost_fraction": {
                f"{tol:g}px": float(np.mean(worst > tol)) if worst.size else None
                for tol in scene.lpt.match_tolerances_px
            },
        }
    stats["disparity"] = disparity
    window, order = scene.measure.time.fit_window, scene.measure.time.fit_order
    dt = float(run.times[1] - run.times[0]) if run.times.size > 1 else None
    fits = {
        kind: sliding_fit(result[f"x_{kind}"][:, keep], dt, window, order)
        for kind in FIT_KINDS
        if f"x_{kind}" in result
    }
    centres = fits["meas"].centres
    fit_ids = np.broadcast_to(np.arange(keep.size), (centres.size, keep.size))[:, keep].ravel()
    for label, attribute, true_values in (
        ("velocity", "velocity", run.u_true),
        ("acceleration", "acceleration", run.a_true),
    ):
        truth = true_values[centres][:, keep]
        errors = kinematic_errors(fits, attribute, truth)
        block = {}
        for axis, name in enumerate(COMPONENTS):
            block[name] = {
                kind: None
                if error is None
                else error_summary(
                    error[..., axis].ravel(),
                    truth[..., axis].ravel(),
                    fit_ids,
                    bootstrap,
                    condition=False,
                )
                for kind, error in errors.items()
            }
            # the errors themselves (field units), for their values in mm/s and m/s²
            block[name]["absolute"] = {
                kind: None
                if error is None
                else rms_interval(error[..., axis].ravel(), fit_ids, bootstrap)
                for kind, error in errors.items()
            }
            # n/a where no tracer was kept (every image lost): nothing was measured
            block[name]["truth_rms"] = (
                float(np.sqrt(np.mean(truth[..., axis] ** 2))) if truth.size else None
            )
            checks.guard_ratios(block[name], label, checks.roundoff_floor(run, label))
        stats[label] = block
    stats["fit"] = {"window": window, "order": order, "dt": dt}
    return stats


def run_lpt(scene, out_dir, device=None, progress=None, overwrite=False, dataset=False):
    """Run every case of an LPT scene; write case files and ``lpt_stats.json``.

    Parameters
    ----------
    scene : rimcl.lpt.config.LptScene
    out_dir : str or Path
    device : optional
        OpenCL device (see :func:`rimcl.select_device`).
    progress : callable, optional
        ``progress(case, frame, frames)`` after each frame.
    overwrite : bool
        Replace existing outputs.
    dataset : bool
        Also write the files for LPT codes (:func:`rimcl.lpt.files.write_dataset`).

    Returns
    -------
    dict
        The statistics document written to ``lpt_stats.json``.
    """
    from rimcl.core.provenance import versions
    from rimcl.lpt.files import open_outputs

    out_dir = Path(out_dir)
    # an earlier run refused before any work; its files replaced only by a whole new set
    with open_outputs(out_dir, scene, overwrite) as outputs:
        return _run_cases(scene, out_dir, outputs, device, progress, dataset, versions())


def _run_cases(scene, out_dir, outputs, device, progress, dataset, versions):
    """:func:`run_lpt`'s cases, written into the output set ``outputs``."""
    from rimcl.lpt.files import frame_writer, lpt_inputs, write_case, write_dataset, write_json

    timings = {}
    run = prepare(scene, out_dir, timings)
    document = {
        "scene": describe_scene(scene),
        "study_scene": scene.study.scene_record(),
        "inputs": lpt_inputs(scene.study.field_path),
        "volume": run.volume.describe(),
        "length_m": run.length_m,
        "time_s": run.time_s,
        "times": run.times.tolist(),
        "tracers": int(run.true.shape[1]),
        "versions": versions,
        "timings_s": timings,
        "cases": {},
    }
    try:
        for case in scene.study.names:
            sink = frame_writer(outputs, scene) if dataset and scene.lpt.images else None
            result = run_case(run, scene, case, device, progress, sink)
            stats = case_statistics(run, result, scene)
            stats["rays"] = result["rays"]
            for name in ("exposure", "sensor", "mie", "self_calibration", "matching"):
                stats[name] = result[name]
            stats["calibration_residual_px"] = {
                cam.name: {
                    "pinhole": cal["pinhole"]["residual_px"],
                    "soloff": cal["soloff"]["residual_px"],
                }
                for cam, cal in zip(result["cameras"], result["calibration"], strict=True)
            }
            pinhole_baseline = (
                result["x_ref_pinhole"][:, result["flags"] == 0] - run.true[:, result["flags"] == 0]
            )
            stats["pinhole_baseline_rms"] = {
                name: checks.finite_rms(pinhole_baseline[..., a])
                for a, name in enumerate(COMPONENTS)
            }
            stats["n_ref"] = result["n_ref"]
            stats["abscissa"] = result["abscissa"]
            stats["timings_s"] = result["timings"]
            depth = float(run.volume.hi[0] - run.volume.lo[0])
            stats["units"] = case_units(stats, depth, run.length_m, run.time_s)
            kept = (result["flags"] & ~FLAG_IMAGE_LOST) == 0  # each variant loses its own
            stats["sensitivity"] = threshold_sensitivity(run, result, stats, kept, scene)
            started = time.perf_counter()
            write_case(outputs.path(f"lpt_case_{result['case']}.h5"), run, result, scene)
            if dataset:
                write_dataset(outputs, run, result, scene)
            stats["timings_s"]["write"] = time.perf_counter() - started
            document["cases"][result["case"]] = stats
    finally:
        run.source.close()
    write_json(outputs.path("lpt_stats.json"), document)
    return document


def _cell(value, scale=1.0, digits=3):
    return "n/a" if value is None else f"{value * scale:.{digits}g}"


def _px(summary, case):
    return (
        None if summary is None or summary["rms"] is None else summary["rms"] / case["pixel_size"]
    )


def summary_lines(document):
    """Short text lines of a run's results (one block per case), for a terminal."""
    lines = [
        f"{document['tracers']} tracers, {len(document['times'])} frames, "
        f"length {document['length_m'] * 1e3:.4g} mm per field unit"
    ]
    for name, case in document["cases"].items():
        rays = ", ".join(str(r["rays"]) for r in case["rays"])
        residual = max(r["soloff"] for r in case["calibration_residual_px"].values())
        lines.append(
            f"{name}: n_ref {case['n_ref']:.6f}; rays per tracer {rays}; Soloff calibration "
            f"residual up to {residual:.3g} px; {case['tracers_kept']}/{case['tracers']} tracers"
        )
        lines.extend(checks.reason_lines(case))
        lines.extend(checks.calibration_lines(case))
        pos = case["position"]
        lines.append(
            "  position refraction rms (px): "
            + ", ".join(f"{k} {_cell(pos[k]['refraction_rms_px'])}" for k in COMPONENTS)
        )
        lines.extend(budget_lines(case))
        lines.append("  " + _physical_line(case.get("units")))
        lines.extend(band_lines(case))
        for kind, label in (("meas", ""), ("vsc", " (self-calibrated)")):
            if kind not in case["disparity"]:
                continue
            block = case["disparity"][kind]
            lost = ", ".join(
                f">{k} {_cell(v, 100, 3)} %" for k, v in block["lost_fraction"].items()
            )
            lines.append(
                f"  disparity{label} median {_cell(block['median_px'])} px; matches lost {lost}"
            )
        for kind, label in (("meas", "field"), ("vsc", "self-calibrated")):
            rows = (case.get("matching") or {}).get(kind)
            if rows:
                lines.append(
                    f"  matching from the images ({label}, first frame): "
                    + "; ".join(
                        f"{r['tolerance_px']:g} px: {r['ghosts']} ghosts, "
                        f"{r['missed']} missed of {case['tracers']}"
                        for r in rows
                    )
                )
        if case.get("self_calibration"):
            lines.append(
                "  self-calibrated position refraction rms (px): "
                + ", ".join(
                    f"{k} {_cell(_px(pos[k]['refraction_self_calibrated'], case))}"
                    for k in COMPONENTS
                )
            )
    return lines


def _physical_line(units):
    """The refraction errors of velocity and acceleration in mm/s and m/s², or the note
    that says they are in field units."""
    if not units or units["scales"]["time_s"] is None:
        return "velocity and acceleration in field units: --time-s (field.time_s) for mm/s, m/s²"
    parts = []
    for group, key, unit in (("velocity", "mm_s", "mm/s"), ("acceleration", "m_s2", "m/s²")):
        values = "/".join(_cell(units[group][k]["rms_refraction"][key]) for k in COMPONENTS)
        parts.append(f"{group} {values} {unit}")
    return (
        f"refraction rms x1/x2/x3 (frames {units['scales']['dt_ms']:.4g} ms apart): "
        + "; ".join(parts)
    )
