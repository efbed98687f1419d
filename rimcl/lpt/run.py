"""The LPT chain: tracks, views through the field, calibration, triangulation, statistics.

For each case of the scene (same tracers, same tracks, common random numbers):

1. the rig is built for the case's fluid (its reference index is the calibration fluid);
2. each camera is calibrated on a target through the uniform fluid (:mod:`.calibration`);
3. the rays per tracer are chosen by convergence of the image centroid (:mod:`.views`);
4. at every frame each tracer is seen by each camera through the field (``meas``) and
   through the uniform fluid (``ref``), and triangulated on the calibrated models;
5. tracks are fitted (sliding polynomial, :func:`rimcl.ptv.track.sliding_fit`) and compared:
   refraction ``meas - ref`` and baseline ``ref - true``, per component.

Units: positions in field length units (``length_m`` metres each), image points in pixels,
velocities in length/time units, accelerations in length/time² units.
"""

import dataclasses
import time
from pathlib import Path

import numpy as np

from rimcl.core.errors import RimclError
from rimcl.lpt.calibration import PinholeModel, SoloffModel, target_points, triangulate
from rimcl.lpt.config import CameraSpec, preset_cameras
from rimcl.lpt.config import describe as describe_scene
from rimcl.lpt.flow import BUILTIN_DT, Volume, builtin_flow, volume_velocity
from rimcl.lpt.rig import RigCamera
from rimcl.lpt.views import Tracer, choose_ray_count, uniform_field, view
from rimcl.optics.camera import FlatWindow
from rimcl.stats.bootstrap import TracerBootstrap
from rimcl.stats.summaries import error_summary

COMPONENTS = ("x1", "x2", "x3")
#: Tracers sampled to choose the ray count.
RAY_SAMPLE = 32
#: Flag bits of a tracer: a ray that did not reach the exit face, an image off a sensor.
FLAG_RAY_FAILED = 1
FLAG_OFF_SENSOR = 2


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
    """

    source: object
    times: np.ndarray
    length_m: float
    volume: Volume
    true: np.ndarray
    u_true: np.ndarray
    a_true: np.ndarray


def prepare(scene, out_dir, timings):
    """Open the field (or make the built-in flow), seed tracers, integrate true tracks."""
    from rimcl.fields.field_reader import FieldFile
    from rimcl.ptv.track import integrate_tracks, track_acceleration, track_velocity

    study = scene.study
    frames, dt = study["time"]["frames"], study["time"]["dt"]
    if frames < study["time"]["fit_window"]:
        raise RimclError(
            f"time.frames = {frames} is fewer than the fit window time.fit_window = "
            f"{study['time']['fit_window']}"
        )
    started = time.perf_counter()
    path = study["field"]["path"]
    if not path:
        dt = BUILTIN_DT if dt is None else dt
        path = builtin_flow(out_dir, frames + study["field"]["start_frame"], dt)
    source = FieldFile(path)
    if dt is None:
        if source.n_frames < 2:
            raise RimclError(f"{path} holds one frame: give time.dt")
        dt = float(source.times[1] - source.times[0])
    first = study["field"]["start_frame"]
    if first >= source.n_frames:
        raise RimclError(f"field.start_frame = {first}, but {path} holds {source.n_frames} frames")
    t0 = float(source.times[first])
    times = t0 + dt * np.arange(frames)
    timings["flow"] = time.perf_counter() - started
    volume = Volume.of(source, scene.illumination)
    width = volume.hi[1] - volume.lo[1]
    length_m = study["field"]["length_m"] or 0.1 / width
    started = time.perf_counter()
    velocity = volume_velocity(source, times[0], times[-1])
    count = study["tracers"]["count"]
    if scene.illumination.ppp is not None:
        spec = scene.rig.cameras[0] if scene.rig.cameras else CameraSpec((0, 0, 0), (0, 0, 0))
        count = max(
            1, round(scene.illumination.ppp * spec.sensor_pixels[0] * spec.sensor_pixels[1])
        )
    start = volume.seed(count, np.random.default_rng(study["tracers"]["seed"]))
    true = integrate_tracks(velocity, start, times)
    u_true = track_velocity(velocity, true, times)
    a_true = track_acceleration(velocity, true, times)
    timings["tracks"] = time.perf_counter() - started
    return Run(source, times, float(length_m), volume, true, u_true, a_true)


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
    study = scene.study
    return Tracer(
        engine=scene.lpt.engine,
        interp=study["integrator"]["interp"],
        precision=study["integrator"]["precision"],
        step=study["integrator"]["step"],
        device=device,
        batch_size=study["run"]["rays_per_batch"],
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
    fitted = []
    for camera in cameras:
        pixels = camera.project(target)
        if not np.all(np.isfinite(pixels)):
            raise RimclError(f"camera {camera.name} cannot see every calibration point")
        pinhole = PinholeModel.fit(target, pixels)
        soloff = SoloffModel.fit(target, pixels)
        fitted.append({"pinhole": pinhole, "soloff": soloff, "pixels": pixels})
    return target, fitted


def _off_sensor(camera, pixels):
    columns, rows = pixels[..., 0], pixels[..., 1]
    inside = (columns >= -0.5) & (columns <= camera.pixels[0] - 0.5)
    inside &= (rows >= -0.5) & (rows <= camera.pixels[1] - 0.5)
    return ~inside


def run_case(run, scene, case, device=None, progress=None):
    """Measure one case: views, triangulation, tracks (see the module's steps).

    Returns
    -------
    dict
        Arrays (``centroid_meas``/``ref`` (F, C, N, 2), ``x_meas``/``x_ref`` (F, N, 3),
        ``disparity_meas``/``ref`` (F, N, C), ``failed_rays`` (F, C, N), ``flags`` (N,)),
        the cameras, calibration, ray choices and stage ``timings`` (s).
    """
    from rimcl.ptv.field_source import case_of
    from rimcl.scene.config import FluidConfig

    timings = {}
    study = scene.study
    settings = scene.lpt
    index = case_of(run.source, case, None, FluidConfig(**study["fluid"]))
    started = time.perf_counter()
    field0 = index.field(run.source, None, run.times[0])
    timings["field"] = time.perf_counter() - started
    cameras = rig_cameras(scene.rig, run.volume, run.length_m, field0.n_ref)
    started = time.perf_counter()
    target, fitted = calibrate_rig(cameras, run.volume, settings)
    models = [f[settings.model] for f in fitted]
    timings["calibration"] = time.perf_counter() - started
    tracer = _tracer(scene, device)
    uniform = uniform_field(field0)
    started = time.perf_counter()
    sample = run.true[0][:RAY_SAMPLE]
    choices = [
        choose_ray_count(
            field0, camera, sample, tracer, settings.ray_tolerance_px, settings.max_rays
        )
        for camera in cameras
    ]
    timings["ray_choice"] = time.perf_counter() - started
    frames, count, ncam = run.true.shape[0], run.true.shape[1], len(cameras)
    centroid = {kind: np.full((frames, ncam, count, 2), np.nan) for kind in ("meas", "ref")}
    failed = np.zeros((frames, ncam, count), dtype=np.int32)
    timings["views"] = 0.0
    for k, moment in enumerate(run.times):
        started = time.perf_counter()
        field = field0 if k == 0 else index.field(run.source, None, moment)
        timings["field"] += time.perf_counter() - started
        started = time.perf_counter()
        for c, camera in enumerate(cameras):
            rays = choices[c]["rays"]
            seen = view(field, camera, run.true[k], rays, tracer)
            centroid["meas"][k, c] = seen.centroid
            failed[k, c] = seen.failed
            centroid["ref"][k, c] = view(uniform, camera, run.true[k], rays, tracer).centroid
        timings["views"] += time.perf_counter() - started
        if progress:
            progress(case, k + 1, frames)
    started = time.perf_counter()
    positions, disparity = {}, {}
    for kind in ("meas", "ref"):
        solved = [triangulate(models, centroid[kind][k]) for k in range(frames)]
        positions[kind] = np.stack([s[0] for s in solved])
        disparity[kind] = np.stack([s[1] for s in solved])
    pinhole = [f["pinhole"] for f in fitted]
    pinhole_ref = np.stack([triangulate(pinhole, centroid["ref"][k])[0] for k in range(frames)])
    timings["triangulation"] = time.perf_counter() - started
    flags = np.zeros(count, dtype=np.int32)
    flags[np.any(failed > 0, axis=(0, 1))] |= FLAG_RAY_FAILED
    off = np.zeros(count, dtype=bool)
    for c, camera in enumerate(cameras):
        off |= np.any(_off_sensor(camera, centroid["ref"][:, c]), axis=0)
    flags[off] |= FLAG_OFF_SENSOR
    return {
        "case": str(index.name),
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
        "centroid_meas": centroid["meas"],
        "centroid_ref": centroid["ref"],
        "x_meas": positions["meas"],
        "x_ref": positions["ref"],
        "x_ref_pinhole": pinhole_ref,
        "disparity_meas": disparity["meas"],
        "disparity_ref": disparity["ref"],
        "failed_rays": failed,
        "flags": flags,
        "timings": timings,
    }


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

    study = scene.study
    keep = result["flags"] == 0
    frames = run.true.shape[0]
    ids = np.broadcast_to(np.arange(keep.size), (frames, keep.size))[:, keep].ravel()
    bootstrap = TracerBootstrap(np.flatnonzero(keep))
    pixel = result["cameras"][0].pixel_size
    stats = {"tracers": int(keep.size), "tracers_kept": int(keep.sum())}
    stats["excluded"] = {
        "ray_failed": int(np.sum(result["flags"] & FLAG_RAY_FAILED > 0)),
        "off_sensor": int(np.sum(result["flags"] & FLAG_OFF_SENSOR > 0)),
    }
    x_meas, x_ref = result["x_meas"][:, keep], result["x_ref"][:, keep]
    truth = run.true[:, keep]
    position = {}
    for axis, name in enumerate(COMPONENTS):
        refraction = rms_interval((x_meas - x_ref)[..., axis].ravel(), ids, bootstrap)
        baseline = rms_interval((x_ref - truth)[..., axis].ravel(), ids, bootstrap)
        position[name] = {
            "refraction": refraction,
            "baseline": baseline,
            "refraction_rms_px": None if refraction["rms"] is None else refraction["rms"] / pixel,
            "refraction_rms_um": None
            if refraction["rms"] is None
            else refraction["rms"] * run.length_m * 1e6,
        }
    stats["position"] = position
    stats["pixel_size"] = pixel
    disparity = {}
    for kind in ("meas", "ref"):
        worst = np.max(result[f"disparity_{kind}"][:, keep], axis=-1).ravel()
        finite = worst[np.isfinite(worst)]
        disparity[kind] = {
            "median_px": float(np.median(finite)) if finite.size else None,
            "p95_px": float(np.percentile(finite, 95)) if finite.size else None,
            "max_px": float(np.max(finite)) if finite.size else None,
            "lost_fraction": {
                f"{tol:g}px": float(np.mean(worst > tol)) if worst.size else None
                for tol in scene.lpt.match_tolerances_px
            },
        }
    stats["disparity"] = disparity
    window, order = study["time"]["fit_window"], study["time"]["fit_order"]
    dt = float(run.times[1] - run.times[0]) if run.times.size > 1 else None
    fits = {
        kind: sliding_fit(result[f"x_{kind}"][:, keep], dt, window, order)
        for kind in ("meas", "ref")
    }
    centres = fits["meas"].centres
    fit_ids = np.broadcast_to(np.arange(keep.size), (centres.size, keep.size))[:, keep].ravel()
    for label, attribute, true_values in (
        ("velocity", "velocity", run.u_true),
        ("acceleration", "acceleration", run.a_true),
    ):
        measured = getattr(fits["meas"], attribute)
        reference = getattr(fits["ref"], attribute)
        truth = true_values[centres][:, keep]
        block = {}
        for axis, name in enumerate(COMPONENTS):
            block[name] = {
                "refraction": error_summary(
                    (measured - reference)[..., axis].ravel(),
                    truth[..., axis].ravel(),
                    fit_ids,
                    bootstrap,
                    condition=False,
                ),
                "baseline": error_summary(
                    (reference - truth)[..., axis].ravel(),
                    truth[..., axis].ravel(),
                    fit_ids,
                    bootstrap,
                    condition=False,
                ),
                "truth_rms": float(np.sqrt(np.mean(truth[..., axis] ** 2))),
            }
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
    from rimcl.lpt.files import write_case, write_dataset, write_json

    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    stats_path = out_dir / "lpt_stats.json"
    if stats_path.exists() and not overwrite:
        raise RimclError(f"{stats_path} exists; pass --overwrite to replace it")
    timings = {}
    run = prepare(scene, out_dir, timings)
    document = {
        "scene": describe_scene(scene),
        "study_scene": scene.study,
        "volume": run.volume.describe(),
        "length_m": run.length_m,
        "times": run.times.tolist(),
        "tracers": int(run.true.shape[1]),
        "versions": versions(),
        "timings_s": timings,
        "cases": {},
    }
    try:
        for case in scene.study["cases"]["names"]:
            result = run_case(run, scene, case, device, progress)
            stats = case_statistics(run, result, scene)
            stats["rays"] = result["rays"]
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
                name: float(np.sqrt(np.nanmean(pinhole_baseline[..., a] ** 2)))
                for a, name in enumerate(COMPONENTS)
            }
            stats["n_ref"] = result["n_ref"]
            stats["timings_s"] = result["timings"]
            started = time.perf_counter()
            write_case(out_dir / f"lpt_case_{result['case']}.h5", run, result, scene, overwrite)
            if dataset:
                write_dataset(out_dir, run, result, scene, overwrite)
            stats["timings_s"]["write"] = time.perf_counter() - started
            document["cases"][result["case"]] = stats
    finally:
        run.source.close()
    write_json(stats_path, document)
    return document


def _cell(value, scale=1.0, digits=3):
    return "n/a" if value is None else f"{value * scale:.{digits}g}"


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
        pos = case["position"]
        lines.append(
            "  position refraction rms (px): "
            + ", ".join(f"{k} {_cell(pos[k]['refraction_rms_px'])}" for k in COMPONENTS)
        )
        for label in ("velocity", "acceleration"):
            block = case[label]
            lines.append(
                f"  {label} rms(ε)/rms(truth): "
                + ", ".join(
                    f"{k} {_cell(block[k]['refraction']['rms_normalized'])} "
                    f"(baseline {_cell(block[k]['baseline']['rms_normalized'])})"
                    for k in COMPONENTS
                )
            )
        meas = case["disparity"]["meas"]
        lost = ", ".join(f">{k} {_cell(v, 100, 3)} %" for k, v in meas["lost_fraction"].items())
        lines.append(f"  disparity median {_cell(meas['median_px'])} px; matches lost {lost}")
    return lines
