"""The device engine: rays stay on the OpenCL device from launch to per-tracer rows.

``engine = "device"`` of a measurement. For each batch of tracers, two kernels run on the
device and only per-tracer rows (and the small ray sample) come back:

1. ``cl/fan.cl`` makes each tracer's camera rays from the float64 tracer and aim positions
   with the host's operations (so the trace sees the same input bits as
   :func:`rimcl.trace_rays`; a lens camera behind a window solves its directions as
   :meth:`rimcl.optics.camera.LensCamera.directions` does), traces them (the kernel of
   ``cl/trace.cl``), refracts the exit states through the window (if any), back-projects
   them to the sheet (a lens: to its focus plane) and applies the camera's collection
   test in float64 as the host does, and keeps each ray's image point in pixels;
2. ``cl/image.cl`` renders, digitises and locates each tracer's image
   (:mod:`rimcl.imaging.device`), then again at each variant threshold of
   :data:`rimcl.imaging.frames.THRESHOLD_VARIANTS` from the rays still on the device (the
   same images: the fan kernel does not run again).

The image points and windows are computed with the NumPy engine's float64 operations; the
renders differ only by the summation order of float64 sums (about 1e-16 of a pixel's
light), so where the digitised images agree the centroids agree to the last bit.

Batches are double-buffered: the host prepares and sends batch k + 1 while the device runs
batch k. Deterministic: every sum runs in a fixed order and no floating-point value is
added atomically (only the optional full-frame picture adds integer counts atomically), so
the numbers are the same run to run. Memory is bounded by the batch size and the slots,
whatever the number of tracers. Needs a device with ``cl_khr_fp64`` (CPUs, NVIDIA and AMD
GPUs).

Stage times of a measurement (``RenderResult.timings``): ``trace`` is the fan kernel,
``render`` the image kernel (render and locate: ``centroid`` stays 0), ``engine_host``
the main thread's CPU time in the engine's frame loop (batches prepared, rows read and
turned into columns), of which ``ray_sample`` went to the run's ray sample (a fixed number
of rays per run, whatever the number of tracers).
"""

import dataclasses
import time

import numpy as np

from rimcl.core.errors import RimclError
from rimcl.imaging.device import DeviceImager, event_seconds, profiling_queue, require_fp64
from rimcl.optics.camera import LensCamera, PlaneCamera, PupilCamera
from rimcl.optics.shapes import default_kernel_shape
from rimcl.optics.straight import straight_rays
from rimcl.optics.trace import (
    _RAY_OUT_STRIDE,
    _finish,
    _validate_rays,
    plan_steps,
    prepare_launch,
)
from rimcl.optics.tuning import tuned_entry

_CAM_COUNT = 25  # camera block of cl/fan.cl (CAM_* there)
#: Work-group size of the fan kernel: fixed, so that PoCL compiles its work-group function
#: once (it specialises kernels per local size) and the last, smaller batch reuses it.
FAN_GROUP = 64
#: Rays per work-item of the fan kernel on CPUs: 16 rather than trace_rays' 8 (more rays in
#: flight hide more of the field's memory latency: +13 % ray-steps per CPU-second on the
#: shipped 64³ periodic sample, the same on a 128³ clamped field; results are identical).
FAN_CPU_LANES = 16


def lane_order(camera):
    """The order in which the fan kernel gives a tracer's rays to its lanes (work-items on
    GPUs): the aim points along a Z-order curve, so that rays traced side by side aim at
    nearby points and end after nearly the same number of steps (the lanes of a
    work-item, or the work-items of a GPU warp, all step until the longest ends).

    The aim points of a plane camera's ``M x M`` grid by their grid indices (aligned
    ``4 x 4`` blocks of 16 rays); any other camera's by their positions on a 1024 x 1024
    grid over the points' extent. Measured on the paper's fan (100 x 100): 3.0 % of the
    lane-steps of 16 consecutive rays are idle, 0.7 % of a 4 x 4 block's; the fan kernel
    ran 5-7 % faster in this order (2-core AMD EPYC, PoCL, 16 lanes).

    Parameters
    ----------
    camera : PlaneCamera, PupilCamera or LensCamera

    Returns
    -------
    ndarray, int32, shape (K,)
        Aim-point indices, a permutation of ``range(K)``.
    """
    points = np.asarray(camera.aim_points())[:, 1:]
    if isinstance(camera, PlaneCamera):
        fan = int(camera.fan)
        index = np.arange(fan * fan)
        cells = np.stack([index % fan, index // fan], axis=-1)  # (x2, x3) columns, rows
    else:
        lo, size = points.min(axis=0), np.ptp(points, axis=0)
        scaled = (points - lo) / np.where(size > 0, size, 1.0)
        cells = np.minimum((scaled * 1024).astype(np.int64), 1023)
    code = np.zeros(len(points), dtype=np.int64)
    for bit in range(11):
        code |= ((cells[:, 0] >> bit) & 1) << (2 * bit)
        code |= ((cells[:, 1] >> bit) & 1) << (2 * bit + 1)
    return np.argsort(code, kind="stable").astype(np.int32)


def tracer_directions(camera, positions, aim_from=None):
    """Initial unit directions of each tracer's rays from its own position ``(x1, x2, x3)``,
    shape (N, K, 3): what PIV traces across a light sheet (``cl/fan.cl`` with
    ``RIMCL_TRACER_DEPTH`` makes the same on the device).

    Aimed from each tracer's own depth at the camera's aim points; a lens behind a window
    solves its directions from the sheet (:meth:`LensCamera.directions`) at ``aim_from``
    (``(N, 2)``: the aim origins of :func:`rimcl.optics.aiming.aim_origins`; default the
    tracers' own ``(x2, x3)``), which moves the rays of a tracer a fraction of the sheet
    thickness off the pupil points it aims at: the pupil test after tracing still decides
    which are collected.
    """
    if isinstance(camera, LensCamera) and camera.window is not None:
        return camera.directions(positions[:, 1:] if aim_from is None else aim_from)
    aim = camera.aim_points()[None, :, :] - positions[:, None, :]
    return aim / np.linalg.norm(aim, axis=-1, keepdims=True)


@dataclasses.dataclass
class _Frame:
    """What the batches of one frame share (``DeviceEngine.image_frame``'s arguments, the
    field and its step plan)."""

    setup: object
    pass_: object
    frame: int
    scales: object
    sampler: object
    bar: object
    positions: np.ndarray
    field: object
    plan: object
    aim_from: np.ndarray


@dataclasses.dataclass
class _Batch:
    """One batch in flight: its tracers, host arrays and pending events."""

    ids: np.ndarray
    host: dict
    events: list
    fan_event: object
    image_events: list
    sample_rays: np.ndarray = None


class FanStage:
    """``cl/fan.cl`` for one camera: its aim points, lane order and camera block on the
    device, and its kernel for a field (shared by the PTV :class:`DeviceEngine` and the PIV
    frames of :mod:`rimcl.imaging.frame_device`).

    Parameters
    ----------
    camera : PlaneCamera, PupilCamera or LensCamera
    scene : rimcl.optics.camera.Scene
    renderer : rimcl.imaging.render.Renderer
        Image origin and pixel size of the rays' image points.
    device : pyopencl.Device
    mie : rimcl.imaging.mie.MieWeights, optional
        Weigh each ray by its Mie intensity (made by the kernel from its initial direction).
    depth : bool
        Tracers at their own depth ``(x1, x2, x3)`` (PIV across a light sheet), imaged on
        their own plane (plane and pupil cameras) or the lens's focus plane; else
        ``(x2, x3)`` on the sheet (PTV).
    """

    def __init__(self, camera, scene, renderer, device, mie=None, depth=False):
        import pyopencl as cl

        from rimcl.core.device import context_for

        self.camera, self.scene, self.renderer, self.device = camera, scene, renderer, device
        self.depth = bool(depth)
        self.rays = camera.rays_per_tracer
        context = context_for(device)
        ro = cl.mem_flags.READ_ONLY | cl.mem_flags.COPY_HOST_PTR
        self.aims = cl.Buffer(context, ro, hostbuf=np.ascontiguousarray(camera.aim_points()))
        self.order = cl.Buffer(context, ro, hostbuf=lane_order(camera))
        self.camera_block = cl.Buffer(context, ro, hostbuf=self._camera_block())
        self.mie_mode, self.mie_table = 0, self.aims
        if mie is not None:
            self.mie_mode, table = mie.device_table()
            self.mie_table = cl.Buffer(context, ro, hostbuf=table)
            self.mie_terms = np.int32((len(table) - 6) // 4)
        self.straight_args = None

    def mie_args(self, weight_buffer):
        """The kernel's Mie arguments, the rays' weights written to ``weight_buffer``."""
        if not self.mie_mode:
            return (self.aims, np.int32(0), self.aims)
        return (self.mie_table, self.mie_terms, weight_buffer)

    def _camera_kind(self):
        """``RIMCL_CAMERA`` of ``cl/fan.cl``: 0 plane, 1 pupil (and a lens without a
        window: its pupil, imaging onto the sheet), 2 lens behind a window."""
        camera = self.camera
        if isinstance(camera, LensCamera):
            return 1 if camera.window is None else 2
        return int(isinstance(camera, PupilCamera))

    def _camera_block(self):
        """The ``camera`` argument of ``cl/fan.cl`` (offsets ``CAM_*`` there), with the
        host's own float64 values of every constant the camera's methods use."""
        block = np.zeros(_CAM_COUNT, dtype=np.float64)
        block[0] = self.scene.x_sheet
        block[1:3] = self.renderer.origin
        block[3] = self.renderer.pixel_size
        camera = self.camera
        pupil = camera.pupil if isinstance(camera, LensCamera) else camera
        if isinstance(pupil, PupilCamera):
            block[4:7] = pupil.axis
            block[7:10] = pupil.centre
            block[10] = 0.5 * pupil.diameter
        if self._camera_kind() == 2:
            # as LensCamera.directions, through_window and image_points compute them
            window, aims = camera.window, camera.aim_points()
            thickness = camera._thickness
            depths = np.array(
                [camera.scene.depth, thickness, aims[0, 0] - camera.scene.x_end - thickness]
            )
            ratios = np.array(
                [
                    1.0,
                    camera.fluid_index / window.glass_index,
                    camera.fluid_index / window.outside_index,
                ]
            )
            block[11:14] = depths
            block[14:17] = ratios
            block[17:20] = depths * ratios
            block[20] = np.sum(depths * ratios)
            block[21] = 0.999 / ratios.max()
            block[22] = camera.focus_x1
            block[23] = window.glass_index
            block[24] = window.outside_index
        return block

    def kernel(self, field, trace_options, positions, name="trace_fan"):
        """The fan kernel (``name`` of ``cl/fan.cl``) and its trace arguments for this field
        and settings; sets :attr:`straight_args`.

        Parameters
        ----------
        field : Field or AnalyticField
        trace_options : dict
            ``step``, ``interp``, ``precision``.
        positions : ndarray, shape (N, 2), or (N, 3) with ``depth``
            The tracers (the step plan is made for the deepest).

        Returns
        -------
        kernel, launch, plan
        """
        import pyopencl as cl

        from rimcl.core.device import context_for
        from rimcl.core.program import build_program, get_kernel

        device = self.device
        if self.depth:
            probe = positions[[int(np.argmin(positions[:, 0]))]]
            directions = tracer_directions(self.camera, probe)[0]
        else:
            probe = self.scene.in_sheet(positions[:1])
            directions = self.camera.directions(positions[:1])[0]
        origins = np.repeat(probe, len(directions), axis=0)
        x_end = self.scene.x_end
        precision = trace_options["precision"]
        plan = plan_steps(field, trace_options["step"], x_end, origins, precision)
        launch = prepare_launch(
            field,
            x_end=x_end,
            plan=plan,
            interp=trace_options["interp"],
            precision=precision,
            device=device,
            origins=origins,
            directions=directions,
            kernel_shape=self.shape(),
        )
        defines = {
            **launch.defines,
            "RIMCL_CAMERA": self._camera_kind(),
            "RIMCL_MIE": self.mie_mode,
            "RIMCL_STRAIGHT": int(field.is_uniform),
            "RIMCL_TRACER_DEPTH": int(self.depth),
            # plane and pupil cameras image a tracer at its own depth on its own plane
            "RIMCL_IMAGE_PLANE": int(self.depth and not isinstance(self.camera, LensCamera)),
        }
        # a uniform field's straight rays: the exit plane and the lateral box, in float64
        self.straight_args = (
            np.float64(x_end),
            np.float64(launch.max_steps * plan.step * field.n_ref),  # straight_path_limit
            cl.cltypes.make_double4(
                field.box_lo[1], field.box_hi[1], field.box_lo[2], field.box_hi[2]
            ),
            np.float64(field.n_ref),  # the exit index of its straight rays
        )
        kernel = get_kernel(build_program(context_for(device), "fan.cl", defines), name)
        return kernel, launch, plan

    def shape(self):
        """The fan kernel's shape: the device's measured trace shape (the fan kernel's hot
        loop is the trace's, rimcl.optics.shapes), else :data:`FAN_CPU_LANES` on CPUs;
        work-groups of :data:`FAN_GROUP` unless a size was measured."""
        import pyopencl as cl

        measured = tuned_entry(self.device)  # measured on first use of the device
        shape = default_kernel_shape(self.device)
        if measured is None and self.device.type & cl.device_type.CPU:
            shape = dataclasses.replace(shape, lanes=FAN_CPU_LANES)
        if measured is None or shape.group is None:  # the rule's group is trace_rays'
            shape = dataclasses.replace(shape, group=FAN_GROUP)
        return shape

    def enqueue(
        self, queue, kernel, launch, tracers, rays, n_rays, ray_buffers, sample_args, mie_args
    ):
        """Set ``trace_fan``'s arguments (``cl/fan.cl``) and enqueue it over ``n_rays`` rays
        (``rays`` per tracer) in work-groups of the launch's shape; returns its event."""
        import pyopencl as cl

        kernel.set_args(
            launch.field_buffer,
            launch.counts,
            launch.params,
            tracers,
            self.aims,
            self.order,
            self.camera_block,
            np.int32(rays),
            np.int32(n_rays),
            np.int32(launch.max_steps),
            *ray_buffers,
            *sample_args,
            *mie_args,
            *self.straight_args,
        )
        items = -(-n_rays // launch.shape.lanes)  # work-items: rays in lanes, rounded up
        group = launch.shape.group
        items = -(-items // group) * group
        return cl.enqueue_nd_range_kernel(queue, kernel, (items,), (group,))


class DeviceEngine:
    """The device pipeline of one measurement (:class:`rimcl.ptv.run_setup.Setup`).

    Device buffers are made once per run; the field of a frame is uploaded once (and kept
    with the field); batches are double-buffered: the host prepares and sends batch k + 1
    while the device runs batch k.

    Parameters
    ----------
    camera : PlaneCamera, PupilCamera or LensCamera
    scene : rimcl.optics.camera.Scene
    imaging : rimcl.imaging.frames.Imaging
    device : pyopencl.Device
    batch : int
        Tracers per batch (raised on GPUs to fill the image slots: :class:`DeviceImager`).
    tracers : int, optional
        Tracers of the run (of its shard): no image slot beyond them is made.
    """

    def __init__(
        self, camera, scene, imaging, device, batch, first_tracer=0, mie=None, tracers=None
    ):
        import pyopencl as cl

        from rimcl.core.device import context_for

        require_fp64(device)
        self.camera, self.scene, self.imaging, self.device = camera, scene, imaging, device
        self.first_tracer = int(first_tracer)  # of a shard: the sampler counts rays run-wide
        self.rays = camera.rays_per_tracer
        self.queue = profiling_queue(device)
        self.imager = DeviceImager(imaging, self.rays, batch, device, self.queue, tracers=tracers)
        self.batch = self.imager.max_tracers
        self.fan = FanStage(camera, scene, imaging.renderer, device, mie)
        self.mie_mode = self.fan.mie_mode
        context = context_for(device)
        size = self.batch * self.rays
        rw = cl.mem_flags.READ_WRITE
        # (x2, x3) of each tracer and the point its rays are aimed from (cl/fan.cl)
        self.tracers = cl.Buffer(context, cl.mem_flags.READ_ONLY, size=self.batch * 32)
        self.ray_buffers = (
            cl.Buffer(context, rw, size=size * 16),
            cl.Buffer(context, rw, size=size * 4),
            cl.Buffer(context, rw, size=size),
        )
        self.sample_size = 0
        self.sample_buffers = None
        # Mie weights: made by the fan kernel from each ray's initial direction
        self.mie_args = self.fan.mie_args(
            cl.Buffer(context, rw, size=size * 8) if mie is not None else None
        )
        # two sets: the host fills one while the device works from the other
        self.host_sets = [self._host_arrays(), self._host_arrays()]

    def initial_directions(self, field, trace_options, positions):
        """The initial directions the fan kernel traces from each tracer (made on the
        device, as the host's ``camera.directions`` and ``trace_rays`` make them).

        Parameters
        ----------
        field : rimcl.Field
        trace_options : dict
            ``step``, ``interp`` and ``precision``, as a measurement's.
        positions : ndarray, shape (N, 2)
            Tracer positions ``(x2, x3)``; at most one batch.

        Returns
        -------
        ndarray, float64, shape (N, K, 3)
        """
        import pyopencl as cl

        positions = np.ascontiguousarray(positions, dtype=np.float64)
        if not 0 < len(positions) <= self.batch:
            raise RimclError(f"give 1 to {self.batch} tracers, got {len(positions)}")
        kernel, _, _ = self.fan.kernel(field, trace_options, positions, "fan_directions")
        n_rays = len(positions) * self.rays
        out = np.empty((len(positions), self.rays, 3), dtype=np.float64)
        directions = cl.Buffer(self.queue.context, cl.mem_flags.WRITE_ONLY, size=out.nbytes)
        # each tracer aimed from itself (cl/fan.cl's layout: position, then aim origin)
        cl.enqueue_copy(self.queue, self.tracers, np.concatenate([positions, positions], axis=1))
        kernel.set_args(
            self.tracers,
            self.fan.aims,
            self.fan.camera_block,
            np.int32(self.rays),
            np.int32(n_rays),
            directions,
        )
        items = -(-n_rays // FAN_GROUP) * FAN_GROUP
        cl.enqueue_nd_range_kernel(self.queue, kernel, (items,), (FAN_GROUP,))
        cl.enqueue_copy(self.queue, out, directions)
        return out

    def _sample_buffers(self, count):
        import pyopencl as cl

        if count > self.sample_size:
            context = self.queue.context
            self.sample_size = count
            self.sample_buffers = (
                cl.Buffer(context, cl.mem_flags.READ_ONLY, size=count * 4),
                cl.Buffer(context, cl.mem_flags.READ_WRITE, size=count * _RAY_OUT_STRIDE * 4),
                cl.Buffer(context, cl.mem_flags.READ_WRITE, size=count * 16),
            )
        return self.sample_buffers

    def image_frame(
        self,
        setup,
        pass_,
        frame,
        field,
        positions,
        scales=None,
        extras=None,
        weights=1.0,
        aim_from=None,
    ):
        """Trace, render and locate every tracer of one frame on the device.

        The device counterpart of the NumPy path of ``rimcl.ptv.imaging_passes._image_frame``, with
        the same parameters, plus ``weights``: light per ray, a number, ``(K,)`` (the same
        fan weights for every tracer, as Mie weights of the initial directions) or
        ``(N, K)``; ``aim_from``: ``(N, 2)``, the points the tracers' rays are aimed from
        (:func:`rimcl.optics.aiming.aim_origins`; default the tracers themselves).
        """
        started = time.thread_time()
        extras = extras or {}
        sampler, canvas, bar = extras.get("sampler"), extras.get("canvas"), extras.get("bar")
        kernel, launch, plan = self.fan.kernel(field, setup.trace_options, positions)
        aim_from = positions if aim_from is None else aim_from
        context = _Frame(
            setup, pass_, frame, scales, sampler, bar, positions, field, plan, aim_from
        )
        if canvas is not None:
            self.imager.use_canvas(canvas.counts.shape)
        per_tracer_weights = np.ndim(weights) == 2
        shared = None if per_tracer_weights else self.imager.set_weights(weights, 0)
        host_sets = self.host_sets
        pending = None
        for number, first in enumerate(range(0, len(positions), self.batch)):
            ids = np.arange(first, min(first + self.batch, len(positions)))
            host = host_sets[number % 2]
            job = self._launch(
                kernel,
                launch,
                ids,
                host,
                positions,
                aim_from,
                None if scales is None else scales[ids],
                weights[ids] if per_tracer_weights else shared,
                sampler,
                canvas is not None,
                (pass_.pass_id, frame, self.first_tracer + int(ids[0])),
            )
            self.queue.flush()
            if pending is not None:
                self._collect(pending, context)
            pending = job
        if pending is not None:
            self._collect(pending, context)
        if canvas is not None:
            summed = self.imager.read_canvas()
            total = canvas.counts.astype(np.int64) + summed
            canvas.counts[...] = np.minimum(total, canvas.full_scale).astype(np.uint16)
        self.queue.finish()
        setup.timings["engine_host"] = setup.timings.get("engine_host", 0.0) + (
            time.thread_time() - started
        )

    def _host_arrays(self):
        return {
            "tracers": np.empty((self.batch, 4), dtype=np.float64),
            **dict(zip(("rows_l", "rows_d"), self.imager.empty_rows(self.batch), strict=True)),
            "variants": self.imager.variant_rows(self.batch),
        }

    def _launch(
        self,
        kernel,
        launch,
        ids,
        host,
        positions,
        aim_from,
        scales,
        weights,
        sampler,
        canvas,
        noise,
    ):
        import pyopencl as cl

        count = len(ids)
        n_rays = count * self.rays
        tracers = host["tracers"][:count]
        tracers[:, :2] = positions[ids]
        tracers[:, 2:] = aim_from[ids]
        cl.enqueue_copy(self.queue, self.tracers, tracers, is_blocking=False)
        sample_rays = None
        sample_args = (self.tracers, np.int32(0), self.tracers, self.tracers)
        if sampler is not None:
            offset = (self.first_tracer + int(ids[0])) * self.rays
            lo, hi = np.searchsorted(sampler.chosen, [offset, offset + n_rays])
            sample_rays = (sampler.chosen[lo:hi] - offset).astype(np.int32)
            if len(sample_rays):
                wanted, out, info = self._sample_buffers(len(sample_rays))
                cl.enqueue_copy(self.queue, wanted, sample_rays, is_blocking=False)
                sample_args = (wanted, np.int32(len(sample_rays)), out, info)
        fan_event = self.fan.enqueue(
            self.queue,
            kernel,
            launch,
            self.tracers,
            self.rays,
            n_rays,
            self.ray_buffers,
            sample_args,
            self.mie_args,
        )
        events = []
        if sample_rays is not None and len(sample_rays):
            host["sample_out"] = np.empty((len(sample_rays), _RAY_OUT_STRIDE), dtype=np.float32)
            host["sample_info"] = np.empty((len(sample_rays), 4), dtype=np.int32)
            events.append(
                cl.enqueue_copy(self.queue, host["sample_out"], sample_args[2], is_blocking=False)
            )
            events.append(
                cl.enqueue_copy(self.queue, host["sample_info"], sample_args[3], is_blocking=False)
            )
        if self.mie_mode:
            weight_arg = (self.mie_args[2], 1)
        elif isinstance(weights, tuple):
            weight_arg = weights
        else:
            weight_arg = self.imager.set_weights(weights, count)
        image_event = self.imager.enqueue(
            self.ray_buffers, count, weight_arg, scales, canvas, noise
        )
        events += self.imager.enqueue_read(host["rows_l"][:count], host["rows_d"][:count])
        # the variant thresholds: the image kernel again on the rays already here
        reads, variant_events = self.imager.enqueue_variants(
            self.ray_buffers, count, weight_arg, scales, noise, host["variants"]
        )
        events += reads
        return _Batch(ids, host, events, fan_event, [image_event, *variant_events], sample_rays)

    def _collect(self, job, context):
        import pyopencl as cl

        cl.wait_for_events(job.events)
        count = len(job.ids)
        rows_l, rows_d = job.host["rows_l"][:count], job.host["rows_d"][:count]
        scales, pass_, timings = context.scales, context.pass_, context.setup.timings
        batch_scales = None if scales is None else scales[job.ids]
        columns = self.imager.columns(rows_l, rows_d, batch_scales)
        self.imager.add_variants(columns, job.host["variants"], batch_scales)
        for name, values in columns.items():
            pass_.images[name][context.frame, job.ids] = values
        status_counts, vignetted, steps = self.imager.ray_totals(rows_l)
        pass_.status_counts += status_counts
        pass_.vignetted += vignetted
        pass_.ray_steps += steps
        timings["trace"] += event_seconds(job.fan_event)
        timings["render"] += sum(event_seconds(event) for event in job.image_events)
        if job.sample_rays is not None and len(job.sample_rays):
            started = time.thread_time()
            self._take_sample(job, context)
            timings["ray_sample"] = timings.get("ray_sample", 0.0) + (time.thread_time() - started)
        if context.bar is not None:
            context.bar.update(count)

    def _take_sample(self, job, context):
        """Hand the sampled rays to the run's sampler as the NumPy path does (their
        directions made on the host for the sampled rays only; through a uniform field
        the host's straight rays)."""
        local = job.sample_rays.astype(np.int64)
        positions, field = context.positions, context.field
        tracer = job.ids[local // self.rays]
        directions = self.camera.directions(context.aim_from[tracer], local % self.rays)
        origins = self.scene.in_sheet(positions[tracer])
        if field.is_uniform:
            limit = self.fan.straight_args[1]
            rows = straight_rays(
                field, origins, directions, x_end=self.scene.x_end, max_length=limit
            )
        else:
            origins, directions = _validate_rays(origins, directions)
            out, info = job.host["sample_out"], job.host["sample_info"]
            rows = _finish(origins, directions, out, info, context.plan.step, {})
        collected = rows.ok & self.camera.collected(rows.end_pos, rows.end_dir, rows.exit_index)
        context.sampler.keep(
            (self.first_tracer + int(job.ids[0])) * self.rays + local, rows, collected
        )
