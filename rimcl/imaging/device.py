"""The device imaging engine's image stage: ``cl/image.cl`` on its host side.

:class:`DeviceImager` holds the image kernel, its scratch slots and buffers; for a batch of
tracers whose rays' image points are on the device (``cl/fan.cl`` of
:class:`rimcl.imaging.engine.DeviceEngine`, or uploaded by :func:`image_points`), the kernel forms
each tracer's window, renders it (``exact`` or ``paper``), digitises it (the deterministic
camera, or the sensor's noise with the host's Philox draws of the same global pixels:
:mod:`rimcl.imaging.sensor`), finds the 8-connected components above the threshold and the
brightest one, and returns its integer moments, area, edge flag and perimeter histogram,
the peak, the light and the light-weighted mean image point; :meth:`DeviceImager.columns`
turns these rows into the columns of :data:`rimcl.imaging.frames.IMAGE_COLUMNS` with the NumPy
engine's own arithmetic (centroids are exact integer moments divided once), so where the
digitised images agree the centroids agree to the last bit.

One work-item images one tracer at a time, sequentially, in its own scratch slot, and
takes the next tracer from a shared counter: on a CPU a few slots per core, on a GPU
thousands (batches are enlarged to fill them). No floating-point value is added atomically.

So the work-group size changes speed only: every tracer's row is made by one work-item, in
the same order, whatever the group (tested bit for bit). Which size is fastest depends on
the device; :func:`tune_image` times the sizes that matter on a small batch of synthetic
tracers and keeps the fastest in the device's entry of the kernel-shape cache
(:mod:`rimcl.optics.shapes`, beside the trace kernels' shape); :func:`image_group` uses it,
measuring it on first use of the device engine (``RIMCL_TUNE=auto``).
"""

import datetime
import logging
import math
import time

import numpy as np

from rimcl.core.errors import RimclError
from rimcl.imaging.centroid import NO_POSITION, TracerFlag
from rimcl.imaging.frames import VARIANT_COLUMNS, empty_columns
from rimcl.imaging.render import TRUNCATE_SIGMAS
from rimcl.imaging.sensor import PASS_IDS
from rimcl.optics.trace import STATUS_NAMES

logger = logging.getLogger(__name__)

#: Ray code bit of ``cl/fan.cl``: the ray was collected by the camera.
RAY_COLLECTED = 8

#: The exact renderer's Gaussian is cut this many σ from the ray: the light left out is
#: below 7e-16 of the ray's (the NumPy engine integrates over the whole window).
EXACT_SIGMAS = 8.0

# per-tracer rows of cl/image.cl (ROW_* and ROWD_* there)
_ROW_FLAGS, _ROW_USABLE, _ROW_STATUS, _ROW_VIGNETTED, _ROW_STEPS = 0, 1, 2, 7, 8
_ROW_WINDOW, _ROW_OUTSIDE, _ROW_AREA, _ROW_SUM, _ROW_SUM_COL, _ROW_SUM_ROW = 9, 13, 14, 15, 16, 17
_ROW_COLS, _ROW_ROWS, _ROW_PERIMETER, _ROW_LONGS = 18, 19, 20, 30
_ROWD_PEAK, _ROWD_SCALE, _ROWD_LIGHT, _ROWD_LIGHT_X, _ROWD_LIGHT_Y, _ROWD_COUNT = 0, 1, 2, 3, 4, 5
#: Scores of border pixels that have a weight in scikit-image's perimeter (neighborhood=4),
#: in the order of the kernel's perimeter histogram.
PERIMETER_SCORES = (5, 7, 13, 15, 17, 21, 23, 25, 27, 33)

#: Tracer images in flight per CPU core (slots taken from a shared counter: balanced).
CPU_SLOTS_PER_CORE = 4
#: Tracer images in flight per GPU multiprocessor (one work-item each).
GPU_SLOTS_PER_UNIT = 256
#: Work-group size of the image kernel on GPUs unless one was measured.
GPU_GROUP = 64
#: Work-group sizes of the image kernel timed by :func:`tune_image` on CPUs (PoCL runs a
#: work-group's items one after the other on one core: 1 spreads the slots over the cores)
#: and on GPUs.
CPU_IMAGE_GROUPS = (1, 2, 4)
GPU_IMAGE_GROUPS = (32, 64, 128, 256)
#: Sources (rays, or the paper renderer's pixels) the image kernel adds to a window in one
#: pass (each pixel loaded and stored once per block; the same sums in the same order).
SPLAT_BLOCK = 16
#: Pixels of room in the factor tables for the union of a block's footprints (a block
#: whose union is wider is added in runs of consecutive sources whose union fits).
SPLAT_SLACK = 32
#: Largest share of the device memory the image scratch may take.
SCRATCH_SHARE = 0.25
#: Rays per batch up to which batches are enlarged to fill the image slots (about 700 MB of
#: device memory for the rays' image points, steps and codes).
MAX_BATCH_RAYS = 1 << 25
#: Rays per batch below which batches are enlarged (about 30 MB of device memory): the host
#: work per batch (about 1 ms of Python) then costs a few µs per tracer image, not 100.
MIN_BATCH_RAYS = 1 << 20


def _perimeter_weights():
    """scikit-image's weights of the 50 border scores (``skimage.measure.perimeter``)."""
    weights = np.zeros(50, dtype=np.float64)
    weights[[5, 7, 15, 17, 25, 27]] = 1
    weights[[21, 33]] = math.sqrt(2)
    weights[[13, 23]] = (1 + math.sqrt(2)) / 2
    return weights


def _paper_kernel(sigma, radius):
    """scipy.ndimage's normalised Gaussian of ``gaussian_filter`` (its order-0 kernel)."""
    x = np.arange(-radius, radius + 1)
    phi = np.exp(-0.5 / (sigma * sigma) * x**2)
    return phi / phi.sum()


def require_fp64(device):
    """Refuse a device without ``cl_khr_fp64`` with one clear line."""
    from rimcl.core.device import has_fp64

    if not has_fp64(device):
        raise RimclError(
            f"engine 'device' needs cl_khr_fp64, which {device.name.strip()} lacks; "
            "use engine 'numpy'"
        )


def event_seconds(event):
    """Seconds an OpenCL event ran on the device (a profiling queue's)."""
    return (event.profile.end - event.profile.start) * 1e-9


def profiling_queue(device):
    """An in-order queue with profiling on ``device`` (kernel times from events)."""
    import pyopencl as cl

    from rimcl.core.device import context_for

    return cl.CommandQueue(
        context_for(device), device, properties=cl.command_queue_properties.PROFILING_ENABLE
    )


class DeviceImager:
    """The image kernel (``cl/image.cl``) with its scratch, for one camera and batch size.

    Parameters
    ----------
    imaging : rimcl.imaging.frames.Imaging
    rays_per_tracer : int
        ``K``, rays of each tracer.
    max_tracers : int
        Largest batch (raised to the number of scratch slots and to
        :data:`MIN_BATCH_RAYS` rays, at most :data:`MAX_BATCH_RAYS` rays: a GPU needs
        thousands of tracer images in flight).
    device : pyopencl.Device
    queue : pyopencl.CommandQueue
        An in-order queue with profiling.
    group : int, optional
        Work-items per work-group (results do not depend on it); default
        :func:`image_group`.
    tracers : int, optional
        Tracers the run images in all, where known: image slots beyond it would only idle
        and hold device memory (a GPU's 256 slots per multiprocessor are gigabytes of
        scratch, and several processes or imagers share the device).
    """

    def __init__(
        self, imaging, rays_per_tracer, max_tracers, device, queue, group=None, tracers=None
    ):
        import pyopencl as cl

        from rimcl.core.device import context_for, is_pocl
        from rimcl.core.program import build_program, get_kernel

        require_fp64(device)
        self.imaging = imaging
        self.rays = int(rays_per_tracer)
        self.queue = queue
        renderer = imaging.renderer
        sigma = float(renderer.psf_sigma)
        if renderer.kind == "exact":
            self.radius = math.ceil(EXACT_SIGMAS * sigma)
            kernel = np.zeros(0)
        else:
            self.radius = int(TRUNCATE_SIGMAS * sigma + 0.5)
            kernel = _paper_kernel(sigma, self.radius)
        window = int(renderer.max_window)
        # a footprint's edges, plus room for the union of a block of nearby footprints
        self.table_width = (min(2 * self.radius + 2 + SPLAT_SLACK, window + 1) + 15) // 8 * 8
        cpu = bool(device.type & cl.device_type.CPU)
        self.group = image_group(device) if group is None else int(group)
        if not 0 < self.group <= device.max_work_group_size:
            raise RimclError(
                f"the image kernel's work-group size must be 1 to "
                f"{device.max_work_group_size} on {device.name.strip()}, got {self.group}"
            )
        context = context_for(device)
        sensor = imaging.sensor
        defines = {
            "RIMCL_RENDERER": 0 if renderer.kind == "exact" else 1,
            "RIMCL_CENTROID": 0 if imaging.centroid_weights == "excess" else 1,
            "RIMCL_POCL_FAST": int(is_pocl(device)),
            "RIMCL_SPLAT_BLOCK": SPLAT_BLOCK,
        }
        if sensor.noise:
            defines["RIMCL_NOISE"] = 1
        self.kernel = get_kernel(build_program(context, "image.cl", defines), "image_tracers")
        rw, ro = cl.mem_flags.READ_WRITE, cl.mem_flags.READ_ONLY | cl.mem_flags.COPY_HOST_PTR
        # the reference peak: full scale, or with noise peak_electrons (Sensor.scale_for)
        self.scale_target = float(sensor.peak_electrons if sensor.noise else renderer.full_scale)
        electrons = [sensor.background_e, sensor.full_well_e, sensor.read_noise_e, sensor.gain]
        recurrence = [math.exp(-32.0 / sigma**2), math.exp(-64.0 / sigma**2)]  # image.cl

        def consts_for(threshold):
            camera = [sigma, threshold, float(renderer.full_scale), self.scale_target]
            consts = np.concatenate([camera, electrons, recurrence, kernel]).astype(np.float64)
            return cl.Buffer(context, ro, hostbuf=consts), round(threshold * 65536)

        #: per threshold (None: the camera's; else a suffix of THRESHOLD_VARIANTS): the
        #: kernel's constants and its threshold in 1/65536 counts
        self.thresholds = {None: (float(imaging.threshold), *consts_for(imaging.threshold))}
        for suffix, value in imaging.variant_thresholds():
            self.thresholds[suffix] = (value, *consts_for(value))
        area = window * window
        slot_bytes = area * 24 + self.rays * 24 + 16 * SPLAT_BLOCK * self.table_width
        budget = SCRATCH_SHARE * device.global_mem_size
        wanted = (CPU_SLOTS_PER_CORE if cpu else GPU_SLOTS_PER_UNIT) * device.max_compute_units
        if tracers is not None:
            wanted = min(wanted, -(-int(tracers) // self.group) * self.group)
        self.slots = max(1, min(int(wanted), int(budget // slot_bytes)))
        self.slots = max(self.group, self.slots // self.group * self.group)  # whole groups
        fill = min(
            max(self.slots, MIN_BATCH_RAYS // self.rays), max(1, MAX_BATCH_RAYS // self.rays)
        )
        self.max_tracers = max(int(max_tracers), fill)
        self.scratch = [
            cl.Buffer(context, rw, size=self.slots * (area + 8) * 8),
            cl.Buffer(context, rw, size=self.slots * area * 16),
            cl.Buffer(context, rw, size=self.slots * self.rays * 16),
            cl.Buffer(context, rw, size=self.slots * self.rays * 8),
            cl.Buffer(context, rw, size=self.slots * 2 * SPLAT_BLOCK * self.table_width * 8),
        ]
        self.counter = cl.Buffer(context, rw, size=4)
        self.rows_l = cl.Buffer(context, rw, size=self.max_tracers * _ROW_LONGS * 8)
        self.rows_d = cl.Buffer(context, rw, size=self.max_tracers * _ROWD_COUNT * 8)
        self.scales = cl.Buffer(context, cl.mem_flags.READ_ONLY, size=self.max_tracers * 8)
        self.shared_weights = cl.Buffer(context, cl.mem_flags.READ_ONLY, size=self.rays * 8)
        self.ray_weights = None
        self._weights_key = None
        self.canvas = None
        self.canvas_shape = (0, 0)
        self.perimeter_weights = _perimeter_weights()

    def set_weights(self, weights, n_tracers):
        """Upload ray weights: a number, ``(K,)`` shared by every tracer, or ``(B, K)``.

        Returns
        -------
        (buffer, per_ray) : the weights buffer and whether it holds one weight per ray.
        """
        import pyopencl as cl

        weights = np.asarray(weights, dtype=np.float64)
        if weights.ndim == 2:
            if weights.shape != (n_tracers, self.rays):
                raise RimclError(
                    f"ray weights of shape {weights.shape} do not match {n_tracers} tracers "
                    f"x {self.rays} rays"
                )
            if self.ray_weights is None:
                self.ray_weights = cl.Buffer(
                    self.queue.context,
                    cl.mem_flags.READ_ONLY,
                    size=self.max_tracers * self.rays * 8,
                )
            cl.enqueue_copy(
                self.queue, self.ray_weights, np.ascontiguousarray(weights), is_blocking=False
            )
            return self.ray_weights, 1
        shared = np.broadcast_to(weights, (self.rays,))
        key = shared.tobytes()
        if key != self._weights_key:
            cl.enqueue_copy(
                self.queue, self.shared_weights, np.ascontiguousarray(shared), is_blocking=False
            )
            self._weights_key = key
        return self.shared_weights, 0

    def use_canvas(self, shape):
        """Add every window's counts into a device frame of ``shape = (rows, columns)``."""
        import pyopencl as cl

        if self.canvas is None or self.canvas_shape != tuple(shape):
            self.canvas = cl.Buffer(
                self.queue.context, cl.mem_flags.READ_WRITE, size=max(4, shape[0] * shape[1] * 4)
            )
            self.canvas_shape = tuple(shape)
        cl.enqueue_fill_buffer(self.queue, self.canvas, np.int32(0), 0, shape[0] * shape[1] * 4)

    def read_canvas(self):
        """The summed counts of the device frame, ``(rows, columns)`` int32."""
        import pyopencl as cl

        out = np.empty(self.canvas_shape, dtype=np.int32)
        cl.enqueue_copy(self.queue, out, self.canvas)
        return out

    @property
    def own_scale(self):
        """Whether every image is scaled to its own peak (``per_image`` scaling)."""
        return self.imaging.scaling == "per_image"

    def enqueue(
        self, rays, n_tracers, weights, scales=None, canvas=False, noise=None, variant=None
    ):
        """Image ``n_tracers`` tracers whose rays are in the device buffers ``rays``.

        Parameters
        ----------
        rays : tuple of pyopencl.Buffer
            ``(ray_pixel, ray_steps, ray_code)`` as ``cl/fan.cl`` writes them.
        n_tracers : int
        weights : (pyopencl.Buffer, int)
            From :meth:`set_weights`.
        scales : ndarray, shape (n_tracers,), optional
            The reference pass's scales; None for the reference pass (ignored with
            ``per_image`` scaling: every image sets its own).
        canvas : bool
            Add the counts into the canvas of :meth:`use_canvas`.
        noise : (int, int, int), optional
            ``(pass_id, frame, tracer0)`` of a noisy sensor's draws
            (:class:`rimcl.imaging.sensor.NoiseKey`): tracer ``t`` of the batch draws as the global
            tracer ``tracer0 + t``.
        variant : str, optional
            Locate the tracers at this variant threshold (a suffix of
            :data:`rimcl.imaging.frames.THRESHOLD_VARIANTS`) instead of the camera's: the
            same images (the same noise draws) rendered again from the rays on the device.

        Returns
        -------
        pyopencl.Event
            The kernel's event.
        """
        import pyopencl as cl

        own_scale = scales is None or self.own_scale
        stream, tracer0 = self._noise_words(noise, n_tracers)
        if not own_scale:
            # non-blocking: the queue keeps the host array until the copy is done
            host = np.ascontiguousarray(scales, dtype=np.float64)
            cl.enqueue_copy(self.queue, self.scales, host, is_blocking=False)
        cl.enqueue_fill_buffer(self.queue, self.counter, np.int32(0), 0, 4)
        weight_buffer, per_ray = weights
        canvas_buffer = self.canvas if canvas else self.counter
        height, width = self.canvas_shape if canvas else (0, 0)
        renderer = self.imaging.renderer
        _, consts, threshold_fixed = self.thresholds[variant]
        self.kernel.set_args(
            consts,
            np.int32(n_tracers),
            np.int32(self.rays),
            np.int32(renderer.max_window),
            np.int32(renderer.pad),
            np.int32(self.radius),
            np.int32(self.table_width),
            np.int32(per_ray),
            np.int32(own_scale),
            np.int64(threshold_fixed),
            *rays,
            weight_buffer,
            self.scales,
            self.counter,
            *self.scratch,
            self.rows_l,
            self.rows_d,
            canvas_buffer,
            np.int32(width),
            np.int32(height),
            np.uint32(self.imaging.sensor.seed & 0xFFFFFFFF),
            np.uint32(self.imaging.sensor.seed >> 32),
            np.uint32(stream),
            np.uint32(tracer0),
        )
        return cl.enqueue_nd_range_kernel(self.queue, self.kernel, (self.slots,), (self.group,))

    def _noise_words(self, noise, n_tracers):
        """The kernel's noise stream ``2 frame + pass`` and first tracer (0, 0 without noise),
        checked as :func:`rimcl.imaging.sensor.pixel_uniforms` checks its key."""
        if not self.imaging.sensor.noise:
            return 0, 0
        if noise is None:
            raise RimclError("a noisy sensor needs a NoiseKey (pass, frame, tracer) per image")
        pass_id, frame, tracer0 = (int(v) for v in noise)
        if pass_id not in PASS_IDS or not 0 <= frame < 1 << 31:
            raise RimclError(f"bad noise key {noise!r}: pass must be 0 or 1, frame in [0, 2**31)")
        if not (0 <= tracer0 and tracer0 + n_tracers <= 1 << 32):
            raise RimclError(f"the tracer ids must be in [0, 2**32), got {tracer0} onwards")
        return 2 * frame + pass_id, tracer0

    def enqueue_read(self, rows_l, rows_d):
        """Non-blocking reads of the rows of the last launch into host arrays."""
        import pyopencl as cl

        first = cl.enqueue_copy(self.queue, rows_l, self.rows_l, is_blocking=False)
        return [first, cl.enqueue_copy(self.queue, rows_d, self.rows_d, is_blocking=False)]

    def enqueue_variants(self, rays, n_tracers, weights, scales, noise, rows):
        """Locate the tracers of the last :meth:`enqueue` again at each variant threshold.

        The image kernel runs once per variant on the same rays (no tracing; the same
        images, the same noise draws), each launch's rows read into ``rows[suffix]``
        (host arrays of :meth:`empty_rows`, at least ``n_tracers`` long) before the next.

        Returns
        -------
        reads, kernels : list of pyopencl.Event
        """
        reads, kernels = [], []
        for suffix, (rows_l, rows_d) in rows.items():
            kernels.append(self.enqueue(rays, n_tracers, weights, scales, False, noise, suffix))
            reads += self.enqueue_read(rows_l[:n_tracers], rows_d[:n_tracers])
        return reads, kernels

    def variant_rows(self, count):
        """Host arrays for :meth:`enqueue_variants`: ``{suffix: (rows_l, rows_d)}``."""
        return {suffix: self.empty_rows(count) for suffix in self.thresholds if suffix}

    def add_variants(self, out, rows, scales=None):
        """Fill the variant columns of ``out`` (:meth:`columns`) from the variant rows."""
        for suffix, (rows_l, rows_d) in rows.items():
            count = len(out["flags"])
            located = self.columns(rows_l[:count], rows_d[:count], scales, suffix)
            for name in VARIANT_COLUMNS:
                out[f"{name}_{suffix}"] = located[name]

    @staticmethod
    def empty_rows(count):
        """Host arrays for the rows of ``count`` tracers: ``(rows_l, rows_d)``."""
        return (
            np.empty((count, _ROW_LONGS), dtype=np.int64),
            np.empty((count, _ROWD_COUNT), dtype=np.float64),
        )

    @staticmethod
    def ray_totals(rows_l):
        """The rays' status counts ``(5,)``, vignetted rays and steps of a batch's rows."""
        status = rows_l[:, _ROW_STATUS : _ROW_STATUS + len(STATUS_NAMES)].sum(axis=0)
        return status, int(rows_l[:, _ROW_VIGNETTED].sum()), int(rows_l[:, _ROW_STEPS].sum())

    def columns(self, rows_l, rows_d, scales=None, variant=None):
        """Per-tracer rows → the columns of :data:`rimcl.imaging.frames.IMAGE_COLUMNS`.

        Parameters
        ----------
        rows_l : ndarray, int64, shape (B, 30)
        rows_d : ndarray, float64, shape (B, 5)
        scales : ndarray, shape (B,), optional
            The scales the kernel was given (None: the reference pass; ignored with
            ``per_image`` scaling).
        variant : str, optional
            The variant threshold the rows were located at (:meth:`enqueue`).

        Returns
        -------
        dict of str to ndarray, shape (B,)
        """
        renderer = self.imaging.renderer
        count = len(rows_l)
        out = empty_columns(count)
        flags = rows_l[:, _ROW_FLAGS].copy()
        area = rows_l[:, _ROW_AREA]
        origin = np.asarray(renderer.origin, dtype=np.float64)
        pixel_size = renderer.pixel_size
        light = rows_d[:, _ROWD_LIGHT]
        with np.errstate(invalid="ignore", divide="ignore"):
            out["x2_opt"] = origin[0] + rows_d[:, _ROWD_LIGHT_X] / light * pixel_size
            out["x3_opt"] = origin[1] + rows_d[:, _ROWD_LIGHT_Y] / light * pixel_size
            if scales is None or self.own_scale:
                # Sensor.scale_for: the peak to full scale, or with noise to peak_electrons
                scale = self.scale_target / rows_d[:, _ROWD_PEAK]
                scale[~(rows_d[:, _ROWD_PEAK] > 0)] = np.nan
            else:
                scale = np.asarray(scales, dtype=np.float64).copy()
            out["peak"] = rows_d[:, _ROWD_PEAK] * scale
        out["scale"] = scale
        out["n_rays_ok"] = rows_l[:, _ROW_USABLE]
        out["flags"] = flags
        found = (flags & int(NO_POSITION)) == 0
        out["area"] = np.where(found, area, 0)
        threshold = self.thresholds[variant][0]
        total = rows_l[:, _ROW_SUM].astype(np.float64)
        moment_col = rows_l[:, _ROW_SUM_COL].astype(np.float64)
        moment_row = rows_l[:, _ROW_SUM_ROW].astype(np.float64)
        if self.imaging.centroid_weights == "excess":
            total = total - threshold * area
            moment_col = moment_col - threshold * rows_l[:, _ROW_COLS]
            moment_row = moment_row - threshold * rows_l[:, _ROW_ROWS]
        with np.errstate(invalid="ignore", divide="ignore"):
            col = moment_col / 2 / total
            row = moment_row / 2 / total
        pixels = np.stack([rows_l[:, _ROW_WINDOW] + col, rows_l[:, _ROW_WINDOW + 1] + row], axis=-1)
        positions = renderer.to_sheet(pixels[found])
        out["x2"][found], out["x3"][found] = positions[:, 0], positions[:, 1]
        histogram = np.zeros((count, 50), dtype=np.int64)
        histogram[:, list(PERIMETER_SCORES)] = rows_l[:, _ROW_PERIMETER : _ROW_PERIMETER + 10]
        for k in np.flatnonzero(found):
            # as skimage: the histogram of scores times the weights, one dot product
            out["perimeter"][k] = histogram[k] @ self.perimeter_weights
        out["circularity"][found] = out["perimeter"][found] ** 2 / (4 * np.pi * area[found])
        return out


class PointImager:
    """The image kernel for image points computed on the host, kept for many calls: the
    kernel, its scratch and the rays' buffers are made once (one camera's imaging and ray
    count; :func:`image_points` makes one for a single call).

    Parameters
    ----------
    imaging : rimcl.imaging.frames.Imaging
    rays_per_tracer : int
    device : pyopencl.Device
    max_tracers : int
        Tracers per launch at least (:class:`DeviceImager` may raise it); more are imaged
        in several launches.
    group : int, optional
        The image kernel's work-group size (default :func:`image_group`).
    """

    def __init__(self, imaging, rays_per_tracer, device, max_tracers=1, group=None):
        import pyopencl as cl

        from rimcl.core.device import context_for

        self.imaging = imaging
        self.queue = profiling_queue(device)
        self.imager = DeviceImager(imaging, rays_per_tracer, max_tracers, device, self.queue, group)
        size = self.imager.max_tracers * self.imager.rays
        context = context_for(device)
        ro = cl.mem_flags.READ_ONLY
        # no step counts for rays traced elsewhere: the kernel's step totals stay 0
        self.buffers = (
            cl.Buffer(context, ro, size=size * 16),
            cl.Buffer(context, ro | cl.mem_flags.COPY_HOST_PTR, hostbuf=np.zeros(size, np.int32)),
            cl.Buffer(context, ro, size=size),
        )

    def image(self, points, usable, weights, flags, scales=None, canvas=None, noise=None):
        """Render, digitise and locate each tracer: :func:`image_points`'s parameters
        (without ``imaging`` and ``device``) and columns."""
        import pyopencl as cl

        imager = self.imager
        count, rays = usable.shape
        if rays != imager.rays:
            raise RimclError(f"this imager takes {imager.rays} rays per tracer, got {rays}")
        first_id = None
        if noise is not None:
            ids = np.asarray(noise[2], dtype=np.int64).reshape(-1)
            if len(ids) != count or (count and np.any(ids != ids[0] + np.arange(count))):
                raise RimclError("the device engine draws noise for consecutive tracer ids only")
            first_id = int(ids[0]) if count else 0
        pixels = self.imaging.renderer.to_pixels(points.reshape(-1, 2))
        pixels[~usable.reshape(-1)] = np.nan
        # unusable rays enter as failed ones; the flags of the caller replace the kernel's
        code = np.where(usable.reshape(-1), RAY_COLLECTED, 1).astype(np.uint8)
        if canvas is not None:
            imager.use_canvas(canvas.counts.shape)
        weights = np.asarray(weights, dtype=np.float64)
        per_tracer = weights.ndim == 2
        shared = None if per_tracer else imager.set_weights(weights, 0)
        parts = []
        for first in range(0, count, imager.max_tracers):
            last = min(first + imager.max_tracers, count)
            rows = slice(first * rays, last * rays)
            cl.enqueue_copy(self.queue, self.buffers[0], np.ascontiguousarray(pixels[rows]))
            cl.enqueue_copy(self.queue, self.buffers[2], code[rows])
            some = None if scales is None else np.asarray(scales)[first:last]
            weight_arg = (
                imager.set_weights(weights[first:last], last - first) if per_tracer else shared
            )
            key = None if noise is None else (noise[0], noise[1], first_id + first)
            imager.enqueue(self.buffers, last - first, weight_arg, some, canvas is not None, key)
            rows_l, rows_d = imager.empty_rows(last - first)
            reads = imager.enqueue_read(rows_l, rows_d)
            # the same images located again at the variant thresholds (no new rays)
            variants = imager.variant_rows(last - first)
            reads += imager.enqueue_variants(
                self.buffers, last - first, weight_arg, some, key, variants
            )[0]
            cl.wait_for_events(reads)
            part = imager.columns(rows_l, rows_d, some)
            imager.add_variants(part, variants, some)
            parts.append(part)
        out = (
            {name: np.concatenate([part[name] for part in parts]) for name in parts[0]}
            if parts
            else empty_columns(0)
        )
        known = int(TracerFlag.RAYS_FAILED | TracerFlag.RAYS_VIGNETTED)
        for column in ("flags", *(f"flags_{suffix}" for suffix in imager.thresholds if suffix)):
            out[column] = (out[column] & ~known) | np.asarray(flags, dtype=np.int64)
        if canvas is not None:
            total = canvas.counts.astype(np.int64) + imager.read_canvas()
            canvas.counts[...] = np.minimum(total, canvas.full_scale).astype(np.uint16)
        return out


def rule_image_group(device):
    """The image kernel's work-group size without measurements: 1 on CPUs (a work-group
    per slot, so that slots spread over the cores), :data:`GPU_GROUP` on GPUs."""
    import pyopencl as cl

    return 1 if device.type & cl.device_type.CPU else GPU_GROUP


def image_group(device):
    """The image kernel's work-group size on ``device``: the measured one of its
    kernel-shape cache entry (measured by :func:`tune_image` on first use in
    ``RIMCL_TUNE=auto``, with the trace kernels' shape), else :func:`rule_image_group`."""
    from rimcl.optics.shapes import shape_in_use, tune_mode
    from rimcl.optics.tuning import tuned_entry

    mode = tune_mode()
    if mode == "off" or tuned_entry(device) is None:
        return rule_image_group(device)
    group = shape_in_use(device)["image_group"]
    if group is not None and group <= device.max_work_group_size:
        return int(group)
    return tune_image(device)["group"] if mode == "auto" else rule_image_group(device)


def _tuning_batch(rng, tracers, rays, pixel_size):
    """Image points ``(tracers, rays, 2)`` of :func:`tune_image`: clouds of 0.5 to 3 px
    around tracers spread over a unit field of view."""
    centres = rng.uniform(0.1, 0.9, size=(tracers, 1, 2))
    widths = rng.uniform(0.5, 3.0, size=(tracers, 1, 1)) * pixel_size
    return centres + widths * rng.normal(size=(tracers, rays, 2))


def tune_image(device, *, path=None, rays=256, repeats=3, groups=None, write=True):
    """Time the image kernel's work-group sizes on ``device``; keep the fastest.

    A batch of synthetic tracers (clouds of image points, the exact renderer, σ 2 px,
    12 bits, at least 1024 tracers and one per slot) is imaged once per size, in
    interleaved rounds; a size's time is the best of ``repeats`` kernel runs. A size
    whose rows differ in any bit from the first size's is left out (a driver bug; logged).

    Parameters
    ----------
    device : pyopencl.Device
    path : Path, optional
        Cache file; default :func:`rimcl.optics.shapes.cache_path`.
    rays : int
        Rays per tracer.
    repeats : int
    groups : sequence of int, optional
        Default :data:`CPU_IMAGE_GROUPS` or :data:`GPU_IMAGE_GROUPS` (those the device allows).
    write : bool
        Store the result under ``image`` in the device's cache entry (where it has one:
        :func:`rimcl.optics.tuning.tune` makes it).

    Returns
    -------
    dict
        ``group``, ``measurements`` (per size: ``tracers_per_s``, ``kernel_seconds`` of
        each run), ``workload``, ``measured`` (UTC time), ``seconds`` and ``stored``.
    """
    import pyopencl as cl

    from rimcl.core.device import context_for
    from rimcl.imaging.frames import Imaging
    from rimcl.imaging.render import Renderer
    from rimcl.optics.shapes import add_to_entry

    started = time.perf_counter()
    cpu = bool(device.type & cl.device_type.CPU)
    if groups is None:
        groups = CPU_IMAGE_GROUPS if cpu else GPU_IMAGE_GROUPS
    groups = [int(g) for g in groups if 0 < int(g) <= device.max_work_group_size] or [
        min(rule_image_group(device), int(device.max_work_group_size))
    ]
    pixel_size = 1 / 512
    imaging = Imaging(Renderer("exact", pixel_size, (0.0, 0.0), 2.0, 64, 12), 200.0)
    queue = profiling_queue(device)
    imagers = {g: DeviceImager(imaging, rays, 256, device, queue, g) for g in groups}
    # every slot busy (a GPU has thousands), within every imager's rows
    tracers = max(1024, *(i.slots for i in imagers.values()))
    tracers = min(tracers, *(i.max_tracers for i in imagers.values()))
    points = _tuning_batch(np.random.default_rng(0), tracers, rays, pixel_size)
    pixels = np.ascontiguousarray(imaging.renderer.to_pixels(points.reshape(-1, 2)))
    context = context_for(device)
    ro = cl.mem_flags.READ_ONLY | cl.mem_flags.COPY_HOST_PTR
    buffers = (
        cl.Buffer(context, ro, hostbuf=pixels),
        cl.Buffer(context, ro, hostbuf=np.zeros(len(pixels), dtype=np.int32)),
        cl.Buffer(context, ro, hostbuf=np.full(len(pixels), RAY_COLLECTED, dtype=np.uint8)),
    )

    def run(imager):
        event = imager.enqueue(buffers, tracers, imager.set_weights(1.0, tracers))
        rows = imager.empty_rows(tracers)
        cl.wait_for_events(imager.enqueue_read(*rows))
        return event_seconds(event), rows

    first = None
    seconds = {}
    for group, imager in imagers.items():  # build and warm up; check the bits
        rows = run(imager)[1]
        first = rows if first is None else first
        if all(np.array_equal(a, b, equal_nan=True) for a, b in zip(rows, first, strict=True)):
            seconds[group] = []
        else:
            logger.warning(
                "image work-group size %d gives other rows on %s: left out", group, device.name
            )
    for _ in range(repeats):
        for group in seconds:
            seconds[group].append(run(imagers[group])[0])
    best = min(seconds, key=lambda group: min(seconds[group]))
    result = {
        "group": int(best),
        "measurements": [
            {"group": g, "tracers_per_s": tracers / min(runs), "kernel_seconds": runs}
            for g, runs in seconds.items()
        ],
        "workload": {
            "tracers": int(tracers),
            "rays": int(rays),
            "renderer": imaging.renderer.describe(),
            "repeats": int(repeats),
        },
        "measured": datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds"),
        "seconds": time.perf_counter() - started,
    }
    result["stored"] = bool(write and add_to_entry(device, "image", result, path))
    return result


def image_points(
    imaging,
    points,
    usable,
    weights,
    flags,
    scales=None,
    device=None,
    canvas=None,
    noise=None,
    group=None,
):
    """Render, digitise and locate each tracer of a batch on the device.

    The device counterpart of :func:`rimcl.imaging.frames.image_batch`, with its parameters and
    columns, for image points computed elsewhere (the device pipeline of a measurement
    makes them on the device instead; :class:`PointImager` keeps the kernel for many calls).

    Parameters
    ----------
    imaging : rimcl.imaging.frames.Imaging
    points : ndarray, float64, shape (B, K, 2)
    usable : ndarray, bool, shape (B, K)
    weights : float or ndarray, shape (K,) or (B, K)
    flags : ndarray, int, shape (B,)
    scales : ndarray, shape (B,), optional
    device : str or pyopencl.Device, optional
    canvas : rimcl.imaging.render.FrameImage, optional
    noise : (int, int, ndarray), optional
        ``(pass_id, frame, tracer_ids)`` as :func:`rimcl.imaging.frames.image_batch`; the kernel
        numbers tracers from the first id, so ``tracer_ids`` must be consecutive.
    group : int, optional
        The image kernel's work-group size (:class:`DeviceImager`; for tests and tuning).

    Returns
    -------
    dict of str to ndarray, shape (B,)
    """
    from rimcl.core.device import select_device

    device = select_device(device, need_fp64=True)
    imager = PointImager(imaging, usable.shape[1], device, max(len(usable), 1), group)
    return imager.image(points, usable, weights, flags, scales, canvas, noise)
