"""The imaging passes of a measurement: the reference, noise-floor and measured images.

Tracers are imaged by the same code through a uniform medium along their true tracks
(:func:`make_reference`, case-independent, reusable) and through each frame's
refractive-index field (:func:`make_measured`). The measured and the reference image of a
tracer share the sensor's noise draws (common random numbers), so their difference is
refraction alone; a noisy sensor's reference is exposed a second time with independent
draws (the *noise floor*: what the camera's noise alone does to a measurement). Work
proceeds in batches of tracers (the *fused path*): a batch's rays are traced, rendered into
per-tracer windows and centroided, and only per-tracer numbers are kept, so memory does not
grow with the number of tracers or rays. :class:`RaySampler` keeps a random subset of the
measured rays for the output file.
"""

import dataclasses
import math
import time

import numpy as np

from rimcl.core.errors import RimclError
from rimcl.imaging.centroid import TracerFlag
from rimcl.imaging.frames import empty_columns, image_batch
from rimcl.imaging.sensor import FLOOR_PASS, MEASURED_PASS, REFERENCE_PASS
from rimcl.optics.aiming import aim
from rimcl.optics.straight import straight_path_limit, straight_rays
from rimcl.optics.trace import STATUS_NAMES
from rimcl.optics.tracing import trace_rays
from rimcl.ptv.field_source import reference_step, uniform_like
from rimcl.ptv.render_file import Reference
from rimcl.ptv.track import SheetVelocity, integrate_tracks, track_acceleration, track_velocity

TRACKING_SUBSTEPS = 8  # RK4 steps between frames (error ~1e-9 of the motion at Δt = 0.005)
#: The image columns kept of the noise-floor exposure.
FLOOR_COLUMNS = ("x2", "x3", "flags")


class _Pass:
    """One imaging pass (reference, noise floor or measured) over all tracers of all frames."""

    def __init__(self, pass_id, frames, tracers):
        self.pass_id = pass_id
        self.images = empty_columns((frames, tracers))
        self.status_counts = np.zeros(len(STATUS_NAMES), dtype=np.int64)
        self.vignetted = 0
        self.ray_steps = 0

    def counts(self):
        """Trace status counts of every ray of this pass, plus the vignetted ones."""
        counts = {name: int(c) for name, c in zip(STATUS_NAMES, self.status_counts, strict=True)}
        counts["vignetted"] = int(self.vignetted)
        return counts


def _image_frame(setup, pass_, frame, field, positions, scales=None, extras=None):
    """Trace, render and locate every tracer of one frame, one batch at a time (stage 1–3).

    Parameters
    ----------
    setup : Setup
    pass_ : _Pass
        Receives the image columns of frame ``frame`` and the ray counts.
    field : rimcl.Field
        The refractive-index field of this frame (or the uniform one).
    positions : ndarray, shape (N, 2)
        Tracer positions at this frame.
    scales : ndarray, shape (N,), optional
        The reference pass's scale factors (None in the reference pass).
    extras : dict, optional
        ``sampler`` (a :class:`RaySampler`), ``canvas`` (a :class:`FrameImage`) and
        ``bar`` (a progress bar), each optional.
    """
    # a lens's rays aimed at its pupil through this field (the same aim for both engines)
    start = time.perf_counter()
    aimed = aim(setup.camera, field, positions, setup.trace_options)
    aim_from = aimed.origins
    setup.timings["trace"] += time.perf_counter() - start
    if setup.engine is not None:
        setup.engine.image_frame(
            setup, pass_, frame, field, positions, scales, extras, aim_from=aim_from
        )
    else:
        _image_batches(setup, pass_, frame, field, positions, scales, extras, aim_from)
    # a tracer the field images several times (several aims reach the pupil), noted
    several = np.where(aimed.branches > 1, int(TracerFlag.MULTIPLE_IMAGES), 0)
    pass_.images["flags"][frame] |= several


def _image_batches(setup, pass_, frame, field, positions, scales, extras, aim_from):
    """The NumPy engine's part of :func:`_image_frame`: trace, render and locate the
    tracers batch by batch, their rays aimed from ``aim_from`` (``(N, 2)``)."""
    extras = extras or {}
    camera, scene, timings = setup.camera, setup.scene, setup.timings
    rays = camera.rays_per_tracer
    for first in range(0, len(positions), setup.batch):
        ids = np.arange(first, min(first + setup.batch, len(positions)))
        origins = np.repeat(scene.in_sheet(positions[ids]), rays, axis=0)
        directions = camera.directions(aim_from[ids]).reshape(-1, 3)
        start = time.perf_counter()
        if field.is_uniform:  # the reference medium, G = 0: straight lines, no steps
            options = setup.trace_options
            limit = straight_path_limit(
                field, options["step"], scene.x_end, origins, directions, options["precision"]
            )
            result = straight_rays(field, origins, directions, x_end=scene.x_end, max_length=limit)
        else:
            result = trace_rays(
                field, origins, directions, x_end=scene.x_end, **setup.trace_options
            )
        timings["trace"] += time.perf_counter() - start
        ok = result.status == 0
        collected = ok & camera.collected(result.end_pos, result.end_dir, result.exit_index)
        pass_.status_counts += np.bincount(result.status, minlength=len(STATUS_NAMES))
        pass_.vignetted += int(np.count_nonzero(ok & ~collected))
        pass_.ray_steps += int(result.steps.sum())
        if extras.get("sampler") is not None:
            extras["sampler"].take((setup.first_tracer + ids[0]) * rays, result, collected)
        ok = ok.reshape(len(ids), rays)
        collected = collected.reshape(len(ids), rays)
        flags = np.where(ok.all(axis=1), 0, int(TracerFlag.RAYS_FAILED))
        flags |= np.where((ok & ~collected).any(axis=1), int(TracerFlag.RAYS_VIGNETTED), 0)
        if hasattr(camera, "image_points"):  # a lens behind a window images through it
            points = camera.image_points(result.end_pos, result.end_dir, result.exit_index)
        else:
            points = result.image_pos[:, 1:]
        weights = 1.0 if setup.mie is None else setup.mie.weights(directions)
        columns = image_batch(
            setup.imaging,
            points.reshape(len(ids), rays, 2),
            collected,
            np.reshape(weights, (len(ids), rays)) if setup.mie is not None else weights,
            flags,
            scales=None if scales is None else scales[ids],
            timings=timings,
            canvas=extras.get("canvas"),
            noise=(pass_.pass_id, frame, setup.first_tracer + ids),
        )
        for name, values in columns.items():
            pass_.images[name][frame, ids] = values
        if extras.get("bar") is not None:
            extras["bar"].update(len(ids))


class RaySampler:
    """Keeps a fixed random subset of rays (by global ray index) as batches go by."""

    def __init__(self, total, count, rng):
        count = min(int(count), total)
        self.chosen = np.sort(rng.choice(total, size=count, replace=False))
        self.parts = []

    def take(self, offset, result, collected):
        """Keep the chosen rays among rays ``offset, offset + 1, ...`` of a whole batch.

        Parameters
        ----------
        offset : int
            Run-wide index of the batch's first ray.
        result : rimcl.optics.trace.TraceResult
            Every ray of the batch.
        collected : ndarray, bool, shape (rays of the batch,)
        """
        lo, hi = np.searchsorted(self.chosen, [offset, offset + len(result.status)])
        local = self.chosen[lo:hi] - offset
        self.keep(self.chosen[lo:hi], result, collected, local)

    def keep(self, rays, result, collected, rows=slice(None)):
        """Keep rays ``rays`` (run-wide indices, increasing), whose records are the
        ``rows`` of ``result`` and ``collected`` (default: all of them, in order)."""
        d0 = result.directions[rows]
        self.parts.append(
            {
                "ray": rays,
                "theta0": np.arctan2(np.linalg.norm(d0[:, 1:], axis=1), d0[:, 0]),
                "deflection": result.deflection[rows],
                "n_metric": np.linalg.norm(result.n_metric[rows], axis=1),
                "path_length": result.path_length[rows],
                "displacement": np.linalg.norm(
                    result.image_pos[rows, 1:] - result.origins[rows, 1:], axis=1
                ),
                "status": result.status[rows],
                "collected": collected[rows],
            }
        )

    def table(self, rays_per_tracer):
        """The kept rays, one column per name (empty columns when none was kept)."""
        empty = {
            "ray": np.int64,
            "theta0": np.float64,
            "deflection": np.float64,
            "n_metric": np.float64,
            "path_length": np.float64,
            "displacement": np.float64,
            "status": np.int8,
            "collected": bool,
        }
        parts = self.parts or [{name: np.zeros(0, kind) for name, kind in empty.items()}]
        table = {name: np.concatenate([p[name] for p in parts]) for name in empty}
        table["tracer_id"] = table["ray"] // rays_per_tracer
        return table


def _true_motion(source, scene, tracers, times):
    """True tracks ``(F, N, 2)``, velocity and acceleration along them (``(F, N, 2)`` each,
    None for one frame) and the outside-grid mask ``(F, N)``."""
    if len(times) == 1:
        return tracers[None], None, None, np.zeros((1, len(tracers)), dtype=bool)
    if not source.has_velocity:
        raise RimclError(
            f"{getattr(source, 'path', 'the field')} holds no velocity, which tracking the "
            "tracers over several frames needs (use --frames 1 for positions only)"
        )
    velocity = SheetVelocity.from_source(source, scene.x_sheet, times[0], times[-1])
    stored_spacing = float(np.min(np.diff(velocity.times))) if len(velocity.times) > 1 else 0
    substeps = TRACKING_SUBSTEPS
    if stored_spacing > 0:
        # RK4 steps no longer than the reference's 1/8 of the stored spacing
        substeps = max(
            substeps, math.ceil(TRACKING_SUBSTEPS * (times[1] - times[0]) / stored_spacing)
        )
    tracks = integrate_tracks(velocity, tracers, times, substeps)
    outside = np.stack([~velocity.inside(p) for p in tracks])
    true_velocity = track_velocity(velocity, tracks, times)
    true_acceleration = track_acceleration(velocity, tracks, times)
    return tracks, true_velocity, true_acceleration, outside


def make_reference(setup, bar=None):
    """True tracks and the reference images (through a uniform medium) of every frame.

    Parameters
    ----------
    setup : Setup
    bar : tqdm progress bar, optional

    Returns
    -------
    Reference
    """
    start = time.perf_counter()
    tracks, true_velocity, true_acceleration, outside = _true_motion(
        setup.source, setup.scene, setup.start_positions, setup.times
    )
    setup.timings["track"] += time.perf_counter() - start
    # the uniform medium of the camera's fluid: a wall refracts the reference rays alike
    uniform = uniform_like(setup.source, getattr(setup.camera, "fluid_index", 1.0))
    reference_setup = dataclasses.replace(
        setup,
        trace_options={
            **setup.trace_options,
            "step": reference_step(setup.trace_options["step"], setup.source),
        },
    )
    ref = _Pass(REFERENCE_PASS, len(setup.frame_ids), len(setup.start_positions))
    for f in range(len(setup.frame_ids)):
        _image_frame(reference_setup, ref, f, uniform, tracks[f], extras={"bar": bar})
    if ref.status_counts[0] == ref.vignetted:
        raise RimclError(
            "no ray of any tracer reaches the camera even through a uniform medium: "
            "check the camera geometry (distance, view angle, aperture) against the field"
        )
    floor_images = ref.images  # a noiseless camera exposes the same image twice
    if setup.imaging.sensor.noise:
        # the same light again, independent draws: the camera's own noise (the floor)
        floor = _Pass(FLOOR_PASS, len(setup.frame_ids), len(setup.start_positions))
        for f in range(len(setup.frame_ids)):
            _image_frame(
                reference_setup, floor, f, uniform, tracks[f], scales=ref.images["scale"][f]
            )
        floor_images = floor.images
    return Reference(
        key=setup.key,
        tracks=tracks,
        true_velocity=true_velocity,
        true_acceleration=true_acceleration,
        outside=outside,
        images=ref.images,
        floor_images={name: floor_images[name] for name in FLOOR_COLUMNS},
        ray_counts=ref.counts(),
        ray_steps=ref.ray_steps,
    )


def make_measured(setup, case_index, reference, sampler, canvas, bar):
    """The measured pass: every frame through its field, with the reference's scales."""
    measured = _Pass(MEASURED_PASS, len(setup.frame_ids), len(setup.start_positions))
    delta_n_max = 0.0
    for f, frame in enumerate(setup.frame_ids):
        field = case_index.field(setup.source, frame, setup.times[f])
        delta_n_max = max(delta_n_max, field.delta_n_range)
        extras = {"bar": bar}
        if f == 0:
            extras.update(sampler=sampler, canvas=canvas)
        _image_frame(
            setup,
            measured,
            f,
            field,
            reference.tracks[f],
            scales=reference.images["scale"][f],
            extras=extras,
        )
        del field
    return measured, delta_n_max
