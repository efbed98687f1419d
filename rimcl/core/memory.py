"""Memory checks made before large allocations: estimate, compare, refuse with one line.

Every allocation whose size comes from user input (a file's declared grid, a number of
tracers or rays, a grid size) is estimated first and compared with the memory this
process can still obtain: on the host, the smallest of the free physical memory, the
cgroup limit and the address-space limit (``RLIMIT_AS``); on an OpenCL device, its global
memory and largest single buffer. A request that does not fit is refused with a
:class:`~rimcl.core.errors.RimclError` that names both sizes, before any of it is allocated.

The per-element costs below are peaks measured with :mod:`tracemalloc` (rounded up), not
the sizes of the final arrays: loading a frame, for instance, goes through float64
intermediates several times the size of the float32 field it returns.
"""

import math
import os
import re
from pathlib import Path

from rimcl.core.errors import RimclError

#: Peak host bytes per grid node while a field file frame becomes a Field (float64
#: density, δn and gradient intermediates; measured 56-80).
FIELD_LOAD_BYTES_PER_NODE = 96
#: Device bytes per grid node of an uploaded field, per interpolation: δn and ∇n as one
#: float4 (trilinear, texture); one float of B-spline coefficients (bspline3).
FIELD_DEVICE_BYTES_PER_NODE = {"trilinear": 16, "texture": 16, "bspline3": 4, "auto": 16}
#: Peak host bytes per traced ray held at once: inputs, kernel outputs and the
#: TraceResult arrays (measured 430-460).
RAY_HOST_BYTES = 512
#: Host bytes per tracer of a render run with 3 frames: reference and measured images,
#: tracks, the assembled per-frame tables (measured about 1 kB).
RENDER_BYTES_PER_TRACER = 2048
#: Host bytes per pixel of one tracer's image window while it is rendered and labelled
#: (an estimate: float64 sums and weights, counts, labels and masks).
WINDOW_BYTES_PER_PIXEL = 40
#: Host bytes per node and frame an import holds: float32 density, float64 gradient.
IMPORT_BYTES_PER_NODE_PER_FRAME = 4 + 24
#: Host bytes per node of the one-frame peaks of an import: reading and transposing a
#: frame, computing its gradient (spectral: complex spectra and float64 components).
IMPORT_PEAK_BYTES_PER_NODE = 160
#: Host bytes per pixel of a full frame image: 16-bit counts and the sum of a window.
FRAME_IMAGE_BYTES_PER_PIXEL = 4
#: Host bytes per grid node of ``rimcl field synth``: the spectral state, four RK4 stages
#: and the right-hand side's work arrays (measured 425), plus per recorded frame the
#: float64 density, velocity and gradient (56).
SYNTH_BYTES_PER_NODE = 448
SYNTH_BYTES_PER_NODE_PER_FRAME = 64


def format_bytes(count):
    """``count`` bytes as a short human-readable size (``"3.2 GiB"``)."""
    count = float(count)
    if not count < 1024**6:  # beyond any machine: the plain number says it best
        return f"{count:.2g} bytes"
    for unit in ("bytes", "KiB", "MiB", "GiB", "TiB"):
        if count < 1024:
            return f"{count:.0f} {unit}" if unit == "bytes" else f"{count:.1f} {unit}"
        count /= 1024
    return f"{count:.1f} PiB"


def _read_number(path, pattern=None):
    """An integer from a small system file (or from the line matching ``pattern``)."""
    try:
        text = Path(path).read_text()
    except OSError:
        return None
    if pattern is not None:
        found = re.search(pattern, text, re.MULTILINE)
        if found is None:
            return None
        text = found.group(1)
    text = text.strip()
    return int(text) if text.isdigit() else None


def _physical_available():
    kib = _read_number("/proc/meminfo", r"^MemAvailable:\s+(\d+) kB")
    if kib is not None:
        return kib * 1024
    try:
        return os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
    except (ValueError, OSError, AttributeError):
        return None


def _cgroup_available():
    """Room left under a cgroup memory limit (v2, then v1), or None without a limit."""
    for limit_file, usage_file in (
        ("/sys/fs/cgroup/memory.max", "/sys/fs/cgroup/memory.current"),
        (
            "/sys/fs/cgroup/memory/memory.limit_in_bytes",
            "/sys/fs/cgroup/memory/memory.usage_in_bytes",
        ),
    ):
        limit, usage = _read_number(limit_file), _read_number(usage_file)
        # v1 reports "no limit" as a huge number near 2**63
        if limit is not None and usage is not None and limit < 2**60:
            return max(limit - usage, 0)
    return None


def _address_space_available():
    """Room left under the address-space limit (``ulimit -v``), or None without one."""
    try:
        import resource
    except ImportError:  # pragma: no cover - not on POSIX
        return None
    soft, _ = resource.getrlimit(resource.RLIMIT_AS)
    if soft == resource.RLIM_INFINITY:
        return None
    used_kib = _read_number("/proc/self/status", r"^VmSize:\s+(\d+) kB") or 0
    return max(soft - used_kib * 1024, 0)


def host_available():
    """Bytes of memory this process can still allocate on the host (best estimate).

    The smallest of: free physical memory (``MemAvailable``), the room under a cgroup
    memory limit, and the room under ``RLIMIT_AS``.

    Returns
    -------
    int
    """
    found = [
        value
        for value in (_physical_available(), _cgroup_available(), _address_space_available())
        if value is not None
    ]
    return int(min(found)) if found else 2**62


def check_host(needed, what, hint=""):
    """Refuse, before allocating, ``needed`` bytes of host memory that are not there.

    Parameters
    ----------
    needed : int or float
        Estimated peak bytes.
    what : str
        What needs them, for the message (e.g. ``"frame 0 of f.h5 (1024 x 1024 x 1024
        nodes)"``).
    hint : str
        What would need less, appended after a colon (e.g. ``"use a larger --window"``).

    Raises
    ------
    RimclError
        ``"<what> needs about N GiB of memory, but only M GiB is available[: hint]"``.
    """
    available = host_available()
    if not math.isfinite(needed) or needed > available:
        raise RimclError(
            f"{what} needs about {format_bytes(needed)} of memory, but only "
            f"{format_bytes(available)} is available" + (f": {hint}" if hint else "")
        )


def check_device(needed, device, what):
    """Refuse an upload to an OpenCL device that exceeds its memory or its largest buffer.

    Parameters
    ----------
    needed : int or float
        Bytes of the one buffer uploaded.
    device : pyopencl.Device
    what : str
        What is uploaded, for the message.
    """
    name = device.name.strip()
    if needed > device.global_mem_size:
        raise RimclError(
            f"{what} needs about {format_bytes(needed)} of device memory, but {name} has "
            f"{format_bytes(device.global_mem_size)}"
        )
    if needed > device.max_mem_alloc_size:
        raise RimclError(
            f"{what} needs one buffer of {format_bytes(needed)}, but the largest buffer "
            f"{name} allows is {format_bytes(device.max_mem_alloc_size)}"
        )


def _nodes(shape):
    return math.prod(int(n) for n in shape)


def _shape_text(shape):
    n3, n2, n1 = (int(n) for n in shape)
    return f"{n1} x {n2} x {n3} nodes"


def check_field_memory(shape, what):
    """Refuse to load a field frame of ``shape`` when its peak host memory cannot fit.

    Parameters
    ----------
    shape : tuple of 3 int
        ``(n3, n2, n1)``.
    what : str
        The frame, for the message.
    """
    nodes = _nodes(shape)
    check_host(nodes * FIELD_LOAD_BYTES_PER_NODE, f"{what} ({_shape_text(shape)})")


def check_field_upload(shape, device, interp="trilinear", what="the field"):
    """Refuse to upload a field of ``shape`` that does not fit in the device's memory.

    Parameters
    ----------
    shape : tuple of 3 int
        ``(n3, n2, n1)``.
    device : pyopencl.Device
    interp : str
        Interpolation, which decides the device layout.
    what : str
        For the message.
    """
    per_node = FIELD_DEVICE_BYTES_PER_NODE.get(interp, 16)
    check_device(_nodes(shape) * per_node, device, f"{what} ({_shape_text(shape)}, {interp})")


def check_array_memory(shape, itemsize, what, factor=2):
    """Refuse to read an array of ``shape`` and ``itemsize`` when it cannot fit.

    ``factor`` covers the temporaries of reading and checking it (a float32 copy, a
    finiteness mask).
    """
    count = _nodes(shape) if len(shape) else 1
    check_host(count * int(itemsize) * factor, what)


def check_trace_memory(rays, what="tracing"):
    """Refuse a trace of ``rays`` rays held at once that cannot fit in host memory.

    The kernel itself runs in batches of fixed size, so the device side is bounded; the
    host keeps every ray's inputs and results until they are written.

    Parameters
    ----------
    rays : int
    what : str
        For the message.
    """
    rays = int(rays)
    check_host(rays * RAY_HOST_BYTES, f"{what} {rays:,} rays")


def check_render_memory(
    tracers,
    rays_per_tracer,
    rays_per_batch,
    frames=3,
    max_window=512,
    pixels=None,
    psf_sigma=0.0,
    frame_image=False,
):
    """Refuse a render run whose tracer tables, one ray batch or images cannot fit.

    Tracers are traced in batches of ``max(1, rays_per_batch // rays_per_tracer)``, so a
    batch holds at least one tracer's rays; the per-tracer tables of every frame are held
    to the end. The kernel runs in batches of fixed size, so the device side is bounded.

    Parameters
    ----------
    tracers : int
        Tracers in the sheet.
    rays_per_tracer : int
        Rays per tracer (``fan²`` for the plane camera).
    rays_per_batch : int
        Rays traced per batch.
    frames : int
        Frames imaged (1 to 3).
    max_window : int
        Largest tracer image window side (pixels).
    pixels : int, optional
        Pixels across the field of view: a window never spans more than the frame and its
        point-spread margin; with ``frame_image`` the whole frame is held.
    psf_sigma : float
        Point-spread σ (pixels).
    frame_image : bool
        A full frame image (16 bits per pixel) is kept.
    """
    tracers, rays_per_tracer = int(tracers), int(rays_per_tracer)
    batch_tracers = min(max(1, int(rays_per_batch) // max(rays_per_tracer, 1)), tracers)
    per_batch = batch_tracers * rays_per_tracer
    tables = tracers * RENDER_BYTES_PER_TRACER * max(int(frames), 1) / 3
    side = float(max_window)
    if pixels is not None:
        side = min(side, float(pixels) + 8 * float(psf_sigma) + 2)
    images = side**2 * WINDOW_BYTES_PER_PIXEL
    if frame_image and pixels is not None:
        images += float(pixels) ** 2 * FRAME_IMAGE_BYTES_PER_PIXEL
    check_host(
        tables + per_batch * RAY_HOST_BYTES + images,
        f"rendering {tracers:,} tracers x {rays_per_tracer:,} rays "
        f"({per_batch:,} rays a batch, image windows up to {side:.0f} px"
        + (f", a {int(pixels)}-pixel frame image" if frame_image and pixels is not None else "")
        + ")",
    )


#: Host bytes per grid node of one field frame a PIV sequence holds (float32 δn and ∇n).
SEQUENCE_FIELD_BYTES_PER_NODE = 16
#: Host bytes per pixel of one step of a PIV sequence's dense truth (dx, dy float64).
SEQUENCE_TRUTH_BYTES_PER_PIXEL = 16


def check_sequence_memory(shape, frames, seeds, frame_shape, physical=False):
    """Refuse a PIV sequence whose frames cannot fit, before any is made.

    A sequence holds every frame's field (:data:`SEQUENCE_FIELD_BYTES_PER_NODE`), the dense
    truth of every step (twice with the m/s copy) and, until they are written, every
    seed's frames through the field and through the uniform medium
    (:data:`FRAME_IMAGE_BYTES_PER_PIXEL` each).

    Parameters
    ----------
    shape : tuple of 3 int
        The field's grid ``(n3, n2, n1)``.
    frames, seeds : int
        Exposures per sequence and realisations.
    frame_shape : tuple of 2 int
        ``(rows, columns)`` of a frame, px.
    physical : bool
        Whether the truth is also kept in m/s.
    """
    nodes, pixels = _nodes(shape), int(frame_shape[0]) * int(frame_shape[1])
    needed = frames * nodes * SEQUENCE_FIELD_BYTES_PER_NODE + nodes * FIELD_LOAD_BYTES_PER_NODE
    needed += (frames - 1) * pixels * SEQUENCE_TRUTH_BYTES_PER_PIXEL * (2 if physical else 1)
    needed += 2 * seeds * frames * pixels * FRAME_IMAGE_BYTES_PER_PIXEL
    check_host(
        needed,
        f"{seeds} sequence(s) of {frames} frames of {frame_shape[0]} x {frame_shape[1]} px "
        f"over a {_shape_text(shape)} field",
        "use fewer --frames or --seeds, or smaller frames",
    )


#: Host bytes per tracer and frame of an LPT run: the true, measured and reference tracks
#: and their threshold variants (about 25 float64 columns), rounded up. An estimate from
#: the arrays held, not a measured peak.
LPT_BYTES_PER_TRACER_FRAME = 256
#: The same per camera: centroids, image points, disparities, flags and peaks of both
#: passes and of the threshold variants (about 30 float64 values), rounded up; an estimate.
LPT_BYTES_PER_TRACER_FRAME_CAMERA = 512
#: Host bytes per sensor pixel of one camera frame while it is rendered and located
#: (float64 sums, counts, labels and masks of both passes); an estimate.
LPT_BYTES_PER_PIXEL = 48


def check_lpt_memory(tracers, frames, cameras, pixels):
    """Refuse an LPT run whose tracks and images cannot fit, before any is made.

    Parameters
    ----------
    tracers, frames, cameras : int
    pixels : int
        Pixels of the largest sensor.
    """
    per_frame = LPT_BYTES_PER_TRACER_FRAME + cameras * LPT_BYTES_PER_TRACER_FRAME_CAMERA
    needed = tracers * frames * per_frame + cameras * pixels * LPT_BYTES_PER_PIXEL
    check_host(
        needed,
        f"LPT of {tracers} tracers over {frames} frames with {cameras} cameras",
        "use fewer tracers (tracers.count, illumination.ppp) or frames",
    )


def check_import_memory(shape, frames, velocity, what):
    """Refuse an import of ``frames`` frames of ``shape`` nodes that cannot fit in memory.

    An import holds every frame's density (float32), velocity (float32) and computed
    density gradient (float64) until the file is written, plus the peak of reading one
    frame and computing one gradient.

    Parameters
    ----------
    shape : tuple of 3 int
        Nodes kept per frame, ``(n3, n2, n1)``.
    frames : int
    velocity : bool
        Whether velocity is imported too.
    what : str
        For the message.
    """
    per_frame = IMPORT_BYTES_PER_NODE_PER_FRAME + (12 if velocity else 0)
    needed = _nodes(shape) * (int(frames) * per_frame + IMPORT_PEAK_BYTES_PER_NODE)
    check_host(needed, f"{what} ({int(frames)} frames of {_shape_text(shape)})")


def check_synth_memory(grid, frames):
    """Refuse a ``rimcl field synth`` run on ``grid³`` nodes that cannot fit in memory."""
    nodes = int(grid) ** 3
    needed = nodes * (SYNTH_BYTES_PER_NODE + SYNTH_BYTES_PER_NODE_PER_FRAME * int(frames))
    check_host(needed, f"the solver on a {int(grid)}³ grid with {int(frames)} frames")


def rays_per_tracer(camera, fan, pupil_rays):
    """Rays each tracer sends: ``fan²`` for the plane camera, ``pupil_rays`` for the pupil."""
    return int(fan) ** 2 if camera == "plane" else int(pupil_rays)


def check_render_request(
    shape,
    where,
    *,
    tracers,
    camera="plane",
    fan=32,
    pupil_rays=1024,
    rays_per_batch=1 << 17,
    frames=3,
    max_window=512,
    pixels=None,
    psf_sigma=0.0,
    frame_image=False,
    interp="trilinear",
    device=None,
):
    """Refuse, before any work, a render run that cannot fit in host or device memory.

    Checks the field frame (its shape from the file's metadata), the tracer tables, one ray
    batch and the images on the host, and the field upload on ``device``.

    Parameters
    ----------
    shape : tuple of int
        Nodes of a field frame, ``(n3, n2, n1)`` (from the file's metadata).
    where : str
        The field, for the messages (e.g. its path).
    tracers, camera, fan, pupil_rays, rays_per_batch, frames, max_window, pixels, \
psf_sigma, frame_image, interp
        As :func:`rimcl.ptv.measure.run_render`.
    device : pyopencl.Device, optional
        Also check the field upload to this device.
    """
    check_field_memory(shape, f"a frame of {where}")
    check_render_memory(
        tracers,
        rays_per_tracer(camera, fan, pupil_rays),
        rays_per_batch,
        frames,
        max_window,
        pixels,
        psf_sigma,
        frame_image,
    )
    if device is not None:
        check_field_upload(shape, device, interp, f"the field of {where}")
