"""The synthetic PTV measurement of one case: tracers → rays → images → centroids → tracks.

:func:`run_render` runs the stages in order: the configuration resolved against the field
(:mod:`rimcl.ptv.run_setup`); the true tracks and the reference images through a uniform
medium, then the measured images through each frame's field (:mod:`rimcl.ptv.imaging_passes`);
velocities and accelerations (:mod:`rimcl.ptv.kinematics`); the output tables, a
:class:`rimcl.ptv.render_file.RenderResult`.

The reference does not depend on the refractive-index case. :func:`run_render` returns it
in :attr:`RenderResult.reference`; pass it to later calls with the same configuration
(and seed) to skip recomputing it, as a study over cases does.

Output file (``rimcl_schema = "render"``, ``schema_version = 2``), written by
:func:`rimcl.ptv.render_file.write_render`; the docs' render file format page documents
every dataset.
"""

import json
import math
from contextlib import ExitStack

import numpy as np

from rimcl.core.errors import RimclError
from rimcl.fields.crop import CroppedSource
from rimcl.imaging.centroid import EXCLUDING, NOTES, TracerFlag, flag_names
from rimcl.imaging.frames import THRESHOLD_VARIANTS
from rimcl.imaging.render import FrameImage
from rimcl.ptv.field_source import case_of, open_source, reference_step
from rimcl.ptv.imaging_passes import TRACKING_SUBSTEPS, RaySampler, make_measured, make_reference
from rimcl.ptv.kinematics import add_variant_columns, kinematics_tables
from rimcl.ptv.render_file import SCHEMA, SCHEMA_VERSION, RenderResult
from rimcl.ptv.run_setup import resolve_setup
from rimcl.scene.config import MeasureConfig


def _progress(enabled, total):
    if not enabled:
        return None
    from tqdm.auto import tqdm

    return tqdm(total=total, unit="tracer", desc="render", disable=None)


def run_render(
    field=None, *, case=None, k_rho=None, config=None, reference=None, shard=None, progress=False
):
    """Run the synthetic PTV measurement of one refractive-index case.

    The stages: resolve the configuration against the field
    (:class:`rimcl.ptv.run_setup.Setup`); the true tracks and the reference images through a
    uniform medium (:func:`rimcl.ptv.imaging_passes.make_reference`, skipped when
    ``reference`` is given); the measured images through each frame's field; velocities,
    accelerations and the output tables.

    Parameters
    ----------
    field : str, Path or FieldFile, optional
        A rimcl field file (default: the shipped sample).
    case : str, optional
        ``"C0"`` … ``"C4"``; or give ``k_rho``. Not for files storing ``delta_n``.
    k_rho : float, optional
        Gladstone–Dale product ``G`` (``n = 1 + G ρ``); 0 is a uniform medium.
    config : rimcl.scene.config.MeasureConfig, optional
        Camera, renderer, integrator, tracers, time and run settings (defaults: the
        dataclasses' defaults).
    reference : Reference or sequence of Reference, optional
        From an earlier result with the same configuration: skips the reference pass. A
        sequence offers candidates: the one made for this configuration is used, and
        the reference pass runs when none is (a lens camera's reference depends on the
        case's mean index).
    shard : (int, int), optional
        Measure only tracers ``first..stop-1`` of the run (the same tracers, rays and
        numbers as in the whole run); :func:`rimcl.ptv.render_file.merge_results` joins
        shards.
    progress : bool
        Show a progress bar.

    Returns
    -------
    RenderResult
    """
    config = MeasureConfig() if config is None else config
    with ExitStack() as stack:
        source, source_name = open_source(field, stack)
        if config.box is not None:
            source = CroppedSource(source, config.box)
        case_index = case_of(source, case, k_rho, config.fluid)
        streams = np.random.SeedSequence(int(config.tracers.seed)).spawn(2)
        setup, calibration = resolve_setup(source, source_name, case_index, config, streams, shard)
        count = len(setup.start_positions)
        frames = len(setup.frame_ids)
        bar = _progress(progress, (frames if reference is not None else 2 * frames) * count)
        try:
            if isinstance(reference, (list, tuple)):
                reference = next((r for r in reference if r.key == setup.key), None)
            if reference is None:
                reference = make_reference(setup, bar)
            elif reference.key != setup.key:
                changed = sorted(k for k in setup.key if reference.key.get(k) != setup.key[k])
                raise RimclError(
                    "the reference was made for another configuration (differs in: "
                    f"{', '.join(changed)})"
                )
            sampler = RaySampler(
                config.tracers.count * setup.camera.rays_per_tracer,
                config.run.ray_sample,
                np.random.default_rng(streams[1]),
            )
            canvas = None
            if config.run.frame_image:
                pixel_size = setup.imaging.renderer.pixel_size
                extent = np.ceil(setup.scene.fov_size / pixel_size).astype(int)
                canvas = FrameImage(extent[0], extent[1], setup.imaging.renderer.full_scale)
            measured, delta_n_max = make_measured(
                setup, case_index, reference, sampler, canvas, bar
            )
        finally:
            if bar is not None:
                bar.close()
        run_config = {
            **setup.key,
            "case": case_index.name,
            "k_rho": None if math.isnan(case_index.g) else case_index.g,
            "fluid": None
            if case_index.fluid is None
            else {**case_index.fluid.describe(), "difference": case_index.difference},
            "start_frame": int(config.time.start_frame),
            "rays_per_batch": int(config.run.rays_per_batch),
            "ray_sample": int(config.run.ray_sample),
            "engine": config.run.engine,
            "tracking_substeps": TRACKING_SUBSTEPS,
            "reference_step": reference_step(config.integrator.step, source),
            "length_m": config.camera.length_m,
            "time_s": config.time.time_s,
        }
        if calibration is not None:
            run_config["auto"] = calibration
    result = _assemble(setup, run_config, reference, measured, sampler, delta_n_max)
    result.frame_image = None if canvas is None else canvas.counts
    return result


def _assemble(setup, config, reference, measured, sampler, delta_n_max):
    """The output tables of one run (stage 4): positions, velocities, accelerations."""
    frames, count = reference.tracks.shape[:2]
    ref, meas = reference.images, measured.images
    truth_flags = np.where(reference.outside, int(TracerFlag.OUTSIDE_FIELD), 0)
    excluding, noting = int(EXCLUDING), int(NOTES)
    if setup.imaging.split == "brightest":  # located by the brightest component, noted
        located = int(TracerFlag.SPLIT | TracerFlag.RAYS_OUTSIDE_WINDOW)
        excluding, noting = excluding & ~located, noting | located
    every = ref["flags"] | meas["flags"] | truth_flags
    flags, notes = every & excluding, every & noting

    def rows(values):
        return np.asarray(values).reshape(-1)

    camera, renderer, scene = setup.camera, setup.imaging.renderer, setup.scene
    ids = np.arange(setup.first_tracer, setup.first_tracer + count)
    tracers = {
        "id": np.tile(ids, frames),
        "frame": np.repeat(np.arange(frames), count),
        "time": np.repeat(setup.times, count),
        "x2_true": rows(reference.tracks[..., 0]),
        "x3_true": rows(reference.tracks[..., 1]),
    }
    for suffix, images in (("ref", ref), ("meas", meas)):
        tracers[f"x2_{suffix}"] = rows(images["x2"])
        tracers[f"x3_{suffix}"] = rows(images["x3"])
    tracers.update(
        {
            "x2_opt": rows(meas["x2_opt"]),
            "x3_opt": rows(meas["x3_opt"]),
            "x2_opt_ref": rows(ref["x2_opt"]),
            "x3_opt_ref": rows(ref["x3_opt"]),
        }
    )
    # the noise floor: the reference exposed again with independent sensor noise, its
    # positions NaN where that exposure lost or split the tracer (flags_floor says why)
    floor = reference.floor_images
    floor_lost = (floor["flags"] & int(EXCLUDING)) != 0
    floor_position = np.stack([floor["x2"], floor["x3"]], axis=-1)
    floor_position[floor_lost] = np.nan
    tracers["x2_floor"] = rows(floor_position[..., 0])
    tracers["x3_floor"] = rows(floor_position[..., 1])
    tracers["flags_floor"] = rows(floor["flags"])
    for name in ("area", "perimeter", "circularity"):
        tracers[f"{name}_ref"] = rows(ref[name])
        tracers[f"{name}_meas"] = rows(meas[name])
    tracers.update(
        {
            "n_rays": np.full(frames * count, camera.rays_per_tracer, dtype=np.int64),
            "n_rays_ok": rows(meas["n_rays_ok"]),
            "n_rays_ok_ref": rows(ref["n_rays_ok"]),
            "peak_ref": rows(ref["peak"]),
            "peak_meas": rows(meas["peak"]),
            "flags": rows(flags),
            "notes": rows(notes),
            "flags_ref": rows(ref["flags"]),
            "flags_meas": rows(meas["flags"]),
        }
    )
    positions = {
        "true": reference.tracks,
        "ref": np.stack([ref["x2"], ref["x3"]], axis=-1),
        "meas": np.stack([meas["x2"], meas["x3"]], axis=-1),
        "opt": np.stack([meas["x2_opt"], meas["x3_opt"]], axis=-1),
        "opt_ref": np.stack([ref["x2_opt"], ref["x3_opt"]], axis=-1),
        "floor": floor_position,
    }
    truth = {"velocity": reference.true_velocity, "acceleration": reference.true_acceleration}
    kinematics = kinematics_tables(ids, positions, truth, flags, notes, setup.dt, setup.time)
    for suffix, _ in THRESHOLD_VARIANTS:
        # the same tracers located at another threshold in the same images: their own
        # positions, flags and kinematics (columns <name>_<suffix>)
        variant = {"true": reference.tracks}
        for kind, images in (("ref", ref), ("meas", meas)):
            x2, x3 = images[f"x2_{suffix}"], images[f"x3_{suffix}"]
            tracers[f"x2_{kind}_{suffix}"], tracers[f"x3_{kind}_{suffix}"] = rows(x2), rows(x3)
            variant[kind] = np.stack([x2, x3], axis=-1)
        every = ref[f"flags_{suffix}"] | meas[f"flags_{suffix}"] | truth_flags
        variant_flags = every & excluding
        tracers[f"flags_{suffix}"] = rows(variant_flags)
        add_variant_columns(
            kinematics,
            kinematics_tables(ids, variant, truth, variant_flags, notes, setup.dt, setup.time),
            suffix,
        )
    if reference.true_velocity is not None:
        for name, values in (("u", reference.true_velocity), ("a", reference.true_acceleration)):
            tracers[f"{name}2_true"] = rows(values[..., 0])
            tracers[f"{name}3_true"] = rows(values[..., 1])
    attrs = {
        "rimcl_schema": SCHEMA,
        "schema_version": SCHEMA_VERSION,
        "case": config["case"],
        "k_rho": float("nan") if config["k_rho"] is None else config["k_rho"],
        "delta_n_max": delta_n_max,
        "length_L": scene.depth,
        "pixel_size": renderer.pixel_size,
        "dt": setup.dt,
        "flag_names": json.dumps(flag_names()),
        "note_bits": noting,
        "n_tracers": count,
        "n_frames": frames,
        "rays_per_tracer": camera.rays_per_tracer,
        "renderer": renderer.kind,
        "camera": config["camera"]["camera"],
        "threshold": config["render"]["threshold"],
        "psf_sigma_px": renderer.psf_sigma,
        "x_sheet": scene.x_sheet,
        "x_end": scene.x_end,
        "fov_lo": scene.fov_lo,
        "fov_hi": scene.fov_hi,
        "field": config["field"],
    }
    for scale in ("length_m", "time_s"):  # metres and seconds per field unit, where known
        if config.get(scale) is not None:
            attrs[scale] = float(config[scale])
    ray_attrs = {f"count_{k}": v for k, v in measured.counts().items()}
    ray_attrs.update({f"ref_count_{k}": v for k, v in reference.ray_counts.items()})
    ray_attrs["ray_steps"] = measured.ray_steps
    ray_attrs["ref_ray_steps"] = reference.ray_steps
    ray_attrs["sampled_from_frame"] = 0
    return RenderResult(
        attrs=attrs,
        config=config,
        tracers=tracers,
        kinematics=kinematics,
        rays=sampler.table(camera.rays_per_tracer),
        ray_attrs=ray_attrs,
        reference=reference,
        timings=dict(setup.timings),
        frame_image=None,
        device=setup.trace_options["device"],
    )
