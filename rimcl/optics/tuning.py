"""Measuring the kernel shapes of a device: :func:`tune` and, on first use, :func:`tuned_entry`.

:mod:`rimcl.optics.shapes` holds the shapes, the rule and the cache; this module times the
candidates through the tracer itself (so it sits above :mod:`rimcl.optics.trace`, which
only reads the cache).
"""

import dataclasses
import datetime
import logging
import math
import time
from pathlib import Path

import numpy as np

from rimcl.optics.shapes import (
    CPU_GROUPS,
    CPU_LANES,
    GPU_GROUPS,
    POCL_FLOAT_LANES,
    KernelShape,
    _memo,
    _write_cache,
    cache_path,
    cached_entry,
    cpu_model,
    device_key,
    tune_mode,
)

logger = logging.getLogger(__name__)


def tuned_entry(device):
    """The cache entry of ``device``, measuring it first (:func:`tune`) in mode ``auto``.

    Returns
    -------
    dict or None
        ``shape`` (:meth:`KernelShape.describe`), ``measurements`` and provenance; None in
        mode ``off``, or ``cache`` without an entry.
    """
    entry = cached_entry(device)
    if entry is None and tune_mode() == "auto":
        path = cache_path()
        key = device_key(device)
        logger.info("measuring the kernel shapes of %s once (cached in %s)", key, path)
        entry = tune(device, path=path)
    return entry


def candidate_shapes(device):
    """The shapes :func:`tune` times first (work-group sizes come after, for the best).

    CPUs: 1, 8 and 16 lanes, with and without the PoCL switch on PoCL; GPUs: one ray
    per work-item.
    """
    import pyopencl as cl

    from rimcl.core.device import is_pocl

    if not device.type & cl.device_type.CPU:
        return [KernelShape(1, False)]
    switches = (False, True) if is_pocl(device) else (False,)
    return [
        KernelShape(lanes, fast) for lanes in (1, CPU_LANES, POCL_FLOAT_LANES) for fast in switches
    ]


def _tuning_field(nodes):
    """A seeded smooth random field of ``nodes³`` (Δn as air, clamped), like speed.py's."""
    from rimcl.fields.field import Field
    from rimcl.optics.bench import synthetic_density

    density = synthetic_density(nodes, seed=3)
    k_rho = 2.82e-4
    return Field.from_arrays(
        k_rho * (density - density.mean()),
        spacing=(1 / (nodes - 1),) * 3,
        n_ref=1.0 + k_rho * density.mean(),
        boundary="clamp",
    )


def tune(
    device, *, path=None, nodes=32, rays=16384, repeats=3, shapes=None, groups=None, write=True
):
    """Time the kernel shapes on ``device`` and keep the fastest (see the module).

    Each candidate traces the same rays through a small field (trilinear ``f32c``, fixed
    step), warm, in interleaved rounds; its time is the best of ``repeats`` kernel runs.
    A shape whose results differ in any bit from the first one's is left out (a driver
    bug; it is logged). Then the work-group sizes are timed for the fastest shape.

    Parameters
    ----------
    device : pyopencl.Device
    path : Path, optional
        Cache file; default :func:`cache_path`.
    nodes : int
        Grid nodes per axis of the field (about ``2 nodes`` steps per ray).
    rays : int
    repeats : int
    shapes : list of KernelShape, optional
        Default :func:`candidate_shapes`.
    groups : sequence of int, optional
        Work-group sizes tried with the fastest shape; default :data:`CPU_GROUPS` or
        :data:`GPU_GROUPS` (each is another kernel build on PoCL).
    write : bool
        Store the result in the cache.

    Returns
    -------
    dict
        ``shape``, ``measurements`` (per shape: ray-steps/s, seconds of each run),
        ``device``, ``cpu``, ``workload``, ``measured`` (UTC time) and ``seconds``.
    """
    import pyopencl as cl

    from rimcl.core.device import describe_device
    from rimcl.optics.rays import fan_rays, scene_for
    from rimcl.optics.trace import _validate_rays, plan_steps, run_trace

    started = time.perf_counter()
    field = _tuning_field(int(nodes))
    scene = scene_for(field)
    fan = max(1, round(math.sqrt(rays / 16)))
    origins, directions, _ = fan_rays(scene, 16, fan, seed=0)
    origins, directions = _validate_rays(origins, directions)
    plan = plan_steps(field, None, scene.x_end, origins)

    def trace(shape):
        return run_trace(
            field,
            origins,
            directions,
            x_end=scene.x_end,
            plan=plan,
            interp="trilinear",
            precision="f32c",
            device=device,
            kernel_shape=shape,
        )

    def time_shapes(shapes, first):
        seconds = {shape: [] for shape in shapes}
        steps = None
        for shape in shapes:  # build and warm up; check the bits
            result = trace(shape)
            same = all(
                np.array_equal(getattr(result, name), getattr(first, name), equal_nan=True)
                for name in ("end_pos", "end_dir", "path_length", "n_metric", "status")
            )
            if not same:
                logger.warning("kernel shape %s traces other bits on %s: left out", shape, key)
                del seconds[shape]
            steps = int(result.config["sharma_steps"])
        for _ in range(repeats):
            for shape in seconds:
                seconds[shape].append(trace(shape).config["kernel_seconds"])
        return seconds, steps

    key = device_key(device)
    candidates = candidate_shapes(device) if shapes is None else list(shapes)
    first = trace(candidates[0])
    seconds, steps = time_shapes(candidates, first)
    best = min(seconds, key=lambda shape: min(seconds[shape]))
    if groups is None:
        groups = CPU_GROUPS if device.type & cl.device_type.CPU else GPU_GROUPS
    largest = int(device.max_work_group_size)
    more = [
        dataclasses.replace(best, group=group)
        for group in groups
        if group is not None and group <= largest
    ]
    if more:  # the best shape again beside its work-group sizes, under the same load
        for shape, runs in time_shapes([best, *more], first)[0].items():
            seconds.setdefault(shape, []).extend(runs)
    best = min(seconds, key=lambda shape: min(seconds[shape]))
    measurements = [
        {
            **shape.describe(),
            "ray_steps_per_s": steps / min(runs),
            "kernel_seconds": runs,
        }
        for shape, runs in seconds.items()
    ]
    entry = {
        "shape": best.describe(),
        "measurements": measurements,
        "device": describe_device(device),
        "cpu": cpu_model(),
        "workload": {
            "field_nodes": int(nodes),
            "rays": len(origins),
            "sharma_steps": steps,
            "interp": "trilinear",
            "precision": "f32c",
            "repeats": int(repeats),
        },
        "measured": datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds"),
        "seconds": time.perf_counter() - started,
    }
    if write:
        path = cache_path() if path is None else Path(path)
        _write_cache(path, key, entry)
        _memo[(path, key)] = entry
    return entry
