"""Full frames of many tracers on the OpenCL device (PIV): ``cl/fan.cl`` then ``cl/frame.cl``.

For each batch of tracers, the fan kernel (:class:`rimcl.imaging.engine.FanStage`, tracers
at their own depth across the light sheet) makes, traces and images their rays on the
device, weighted by Mie intensities where asked; ``tracer_rows`` reduces each tracer's rays
to counts, a pixel bounding box and the sum of its image points; the host bins the tracers
to square tiles of the frame by their boxes (a stable sort: a tile's tracers in increasing
index); ``splat_tiles`` adds each ray's pixel-integrated Gaussian to the tile's pixels, one
work-item per tile. No floating-point value is added atomically and every pixel's sum runs
in one fixed order (batches in order, tracers by index, rays in ray order), so a frame is
the same bits run after run and on any device with the same ndtr and division.

The NumPy reference is :func:`rimcl.piv.frame_pair.deposit_rays` (same footprint, same
products in the same order); frames agree with it to a few ulp of each pixel's light
(``rimcl_ndtr.h``'s ndtr is within a few ulp of scipy's), and counts digitised from them
by the same :class:`rimcl.imaging.sensor.Sensor` agree wherever the light is not within
those ulps of a rounding boundary.
"""

import numpy as np

from rimcl.core.errors import RimclError
from rimcl.imaging.device import event_seconds, profiling_queue, require_fp64
from rimcl.imaging.engine import FanStage
from rimcl.optics.trace import STATUS_NAMES

#: Tile side of ``cl/frame.cl`` (pixels): one work-item per tile; 32 gives a 1024² frame
#: 1024 work-items, enough for CPUs, and a ray's footprint crosses few tile edges.
TILE = 32
#: Work-group size of both frame kernels: fixed, so that PoCL compiles each work-group
#: function once (it specialises kernels per local size) whatever the batch or frame size.
FRAME_GROUP = 8
#: Rays per batch: about 60 MB of device buffers (image point, steps, code, Mie weight).
BATCH_RAYS = 1 << 21
_ROW_COLLECTED, _ROW_VIGNETTED, _ROW_OFF_FRAME, _ROW_STATUS, _ROW_BOX, _ROW_LONGS = (
    0,
    1,
    2,
    3,
    8,
    12,
)


def bin_to_tiles(boxes, collected, pad, shape, tile=TILE):
    """Tracers by the tiles their rays' footprints reach (CSR, increasing tracer index).

    Parameters
    ----------
    boxes : ndarray, int64, shape (B, 4)
        Lowest column, lowest row, highest column, highest row of each tracer's collected
        rays' own pixels.
    collected : ndarray, shape (B,)
        Collected rays per tracer (0: not binned).
    pad : int
        Pixels a ray's footprint reaches beyond its own pixel.
    shape : (int, int)
        Frame ``(rows, columns)``.
    tile : int

    Returns
    -------
    start : ndarray, int32, shape (n_tiles + 1,)
    tracers : ndarray, int32
        Tracers of tile ``t`` are ``tracers[start[t]:start[t + 1]]``, increasing.
    tiles_x : int
        Tiles along a row.
    """
    rows, cols = shape
    tiles_x, tiles_y = -(-cols // tile), -(-rows // tile)
    lo = np.maximum(boxes[:, :2] - pad, 0)
    hi = np.minimum(boxes[:, 2:] + pad, [cols - 1, rows - 1])
    seen = (collected > 0) & np.all(lo <= hi, axis=1)
    ids = np.flatnonzero(seen)
    first, last = lo[ids] // tile, hi[ids] // tile
    span = last - first + 1
    count = span[:, 0] * span[:, 1]
    owner = np.repeat(np.arange(len(ids)), count)
    local = np.arange(owner.size) - np.repeat(np.cumsum(count) - count, count)
    tx = first[owner, 0] + local % span[owner, 0]
    ty = first[owner, 1] + local // span[owner, 0]
    tile_of = ty * tiles_x + tx
    order = np.argsort(tile_of, kind="stable")  # tracers stay increasing within a tile
    start = np.searchsorted(tile_of[order], np.arange(tiles_x * tiles_y + 1)).astype(np.int32)
    return start, ids[owner[order]].astype(np.int32), tiles_x


class DeviceFrames:
    """Full frames of tracers at their own depths, rendered on the device.

    Parameters
    ----------
    camera : PlaneCamera, PupilCamera or LensCamera
    scene : rimcl.optics.camera.Scene
    renderer : rimcl.imaging.render.Renderer
        Pixel size, image origin and point spread (``psf_sigma``, ``pad``) of the frames.
    shape : (int, int)
        Frame ``(rows, columns)``.
    device : pyopencl.Device
    mie : rimcl.imaging.mie.MieWeights, optional
    """

    def __init__(self, camera, scene, renderer, shape, device, mie=None):
        import pyopencl as cl

        from rimcl.core.device import context_for, is_pocl
        from rimcl.core.program import build_program, get_kernel

        require_fp64(device)
        self.renderer, self.shape, self.device = renderer, tuple(int(v) for v in shape), device
        self.rays = camera.rays_per_tracer
        self.queue = profiling_queue(device)
        self.fan = FanStage(camera, scene, renderer, device, mie, depth=True)
        self.batch = max(1, BATCH_RAYS // self.rays)
        context = context_for(device)
        size = self.batch * self.rays
        rw = cl.mem_flags.READ_WRITE
        # per tracer (x1, x2, x3) and the (x2, x3) its rays are aimed from (cl/fan.cl)
        self.tracers = cl.Buffer(context, cl.mem_flags.READ_ONLY, size=self.batch * 40)
        self.intensity = cl.Buffer(context, cl.mem_flags.READ_ONLY, size=self.batch * 8)
        self.ray_buffers = (
            cl.Buffer(context, rw, size=size * 16),
            cl.Buffer(context, rw, size=size * 4),
            cl.Buffer(context, rw, size=size),
        )
        self.weights = cl.Buffer(context, rw, size=size * 8) if mie is not None else None
        self.rows_l = cl.Buffer(context, rw, size=self.batch * _ROW_LONGS * 8)
        self.rows_d = cl.Buffer(context, rw, size=self.batch * 16)
        self.light = cl.Buffer(context, rw, size=self.shape[0] * self.shape[1] * 8)
        defines = {"RIMCL_MIE": int(mie is not None), "RIMCL_TILE": TILE}
        defines["RIMCL_POCL_FAST"] = int(is_pocl(device))
        program = build_program(context, "frame.cl", defines)
        self.rows_kernel = get_kernel(program, "tracer_rows")
        self.splat_kernel = get_kernel(program, "splat_tiles")

    def expose(self, field, positions, intensity, trace_options, bar=None, aim_from=None):
        """The light of one frame: every tracer's rays traced through ``field`` and splatted.

        Parameters
        ----------
        field : Field or AnalyticField
        positions : ndarray, float64, shape (N, 3)
            Tracers ``(x1, x2, x3)``.
        intensity : ndarray, shape (N,)
            Sheet intensity of each tracer (the light of each of its rays).
        trace_options : dict
            ``step``, ``interp``, ``precision``.
        bar : optional
            A progress bar, advanced by the tracers of each batch.
        aim_from : ndarray, float64, shape (N, 2), optional
            The points ``(x2, x3)`` each tracer's rays are aimed from
            (:func:`rimcl.optics.aiming.aim_origins`; default the tracers themselves).

        Returns
        -------
        light : ndarray, float64, shape ``shape``
            Unscaled light per pixel.
        optics : ndarray, float64, shape (N, 2)
            Mean image point ``(x2, x3)`` of each tracer's collected rays (length units; NaN
            where none was collected).
        collected : ndarray, int64, shape (N,)
        totals : dict
            ``status`` (counts by trace status), ``vignetted``, ``off_frame`` and
            ``seconds`` (``trace``: the fan kernel; ``render``: rows and splat kernels).
        """
        import pyopencl as cl

        positions = np.ascontiguousarray(positions, dtype=np.float64)
        intensity = np.ascontiguousarray(intensity, dtype=np.float64)
        if positions.ndim != 2 or positions.shape[1] != 3 or len(intensity) != len(positions):
            raise RimclError("give tracer positions (N, 3) and one sheet intensity per tracer")
        aim_from = positions[:, 1:] if aim_from is None else np.asarray(aim_from, np.float64)
        if aim_from.shape != (len(positions), 2):
            raise RimclError("give one aim origin (x2, x3) per tracer")
        tracers = np.ascontiguousarray(np.concatenate([positions, aim_from], axis=1))
        rows, cols = self.shape
        cl.enqueue_fill_buffer(self.queue, self.light, np.float64(0.0), 0, rows * cols * 8)
        sums = np.zeros((len(positions), 2))
        collected = np.zeros(len(positions), dtype=np.int64)
        totals = {
            "status": np.zeros(len(STATUS_NAMES), dtype=np.int64),
            "vignetted": 0,
            "off_frame": 0,
            "seconds": {"trace": 0.0, "render": 0.0},
        }
        if len(positions):
            kernel, launch, _ = self.fan.kernel(field, trace_options, positions)
            for first in range(0, len(positions), self.batch):
                ids = slice(first, min(first + self.batch, len(positions)))
                self._batch(
                    kernel,
                    launch,
                    tracers[ids],
                    intensity[ids],
                    totals,
                    sums[ids],
                    collected[ids],
                )
                if bar is not None:
                    bar.update(ids.stop - ids.start)
        light = np.empty(self.shape, dtype=np.float64)
        cl.enqueue_copy(self.queue, light, self.light)
        renderer = self.renderer
        origin = np.asarray(renderer.origin, dtype=np.float64)
        with np.errstate(invalid="ignore", divide="ignore"):
            optics = origin + sums / collected[:, None] * renderer.pixel_size
        optics[collected == 0] = np.nan
        return light, optics, collected, totals

    def _batch(self, kernel, launch, tracers, intensity, totals, sums, collected):
        import pyopencl as cl

        count = len(tracers)
        n_rays = count * self.rays
        rows, cols = self.shape
        cl.enqueue_copy(self.queue, self.tracers, np.ascontiguousarray(tracers))
        cl.enqueue_copy(self.queue, self.intensity, intensity)
        no_sample = (self.tracers, np.int32(0), self.tracers, self.tracers)
        fan_event = self.fan.enqueue(
            self.queue,
            kernel,
            launch,
            self.tracers,
            self.rays,
            n_rays,
            self.ray_buffers,
            no_sample,
            self.fan.mie_args(self.weights),
        )
        ray_pixel, _, ray_code = self.ray_buffers
        self.rows_kernel.set_args(
            ray_pixel,
            ray_code,
            np.int32(self.rays),
            np.int32(count),
            np.int32(cols),
            np.int32(rows),
            self.rows_l,
            self.rows_d,
        )
        rows_event = cl.enqueue_nd_range_kernel(
            self.queue, self.rows_kernel, (_padded(count),), (FRAME_GROUP,)
        )
        rows_l = np.empty((count, _ROW_LONGS), dtype=np.int64)
        rows_d = np.empty((count, 2), dtype=np.float64)
        cl.enqueue_copy(self.queue, rows_l, self.rows_l)
        cl.enqueue_copy(self.queue, rows_d, self.rows_d)
        collected[...] = rows_l[:, _ROW_COLLECTED]
        sums[...] = rows_d
        totals["status"] += rows_l[:, _ROW_STATUS : _ROW_STATUS + len(STATUS_NAMES)].sum(axis=0)
        totals["vignetted"] += int(rows_l[:, _ROW_VIGNETTED].sum())
        totals["off_frame"] += int(rows_l[:, _ROW_OFF_FRAME].sum())
        start, tracers, tiles_x = bin_to_tiles(
            rows_l[:, _ROW_BOX : _ROW_BOX + 4], collected, self.renderer.pad, self.shape
        )
        context = self.queue.context
        ro = cl.mem_flags.READ_ONLY | cl.mem_flags.COPY_HOST_PTR
        start_buffer = cl.Buffer(context, ro, hostbuf=start)
        tracer_buffer = cl.Buffer(context, ro, hostbuf=np.append(tracers, np.int32(0)))
        n_tiles = len(start) - 1
        self.splat_kernel.set_args(
            ray_pixel,
            ray_code,
            self.weights if self.weights is not None else ray_pixel,
            self.intensity,
            start_buffer,
            tracer_buffer,
            np.int32(self.rays),
            np.int32(tiles_x),
            np.int32(n_tiles),
            np.int32(cols),
            np.int32(rows),
            np.int32(self.renderer.pad),
            np.float64(self.renderer.psf_sigma),
            self.light,
        )
        splat_event = cl.enqueue_nd_range_kernel(
            self.queue, self.splat_kernel, (_padded(n_tiles),), (FRAME_GROUP,)
        )
        splat_event.wait()
        totals["seconds"]["trace"] += event_seconds(fan_event)
        totals["seconds"]["render"] += event_seconds(rows_event) + event_seconds(splat_event)


def _padded(count):
    """``count`` work-items rounded up to whole work-groups (the kernels skip the extra)."""
    return -(-int(count) // FRAME_GROUP) * FRAME_GROUP
