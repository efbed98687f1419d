"""OpenCL device selection. Never interactive.

Order of choice: an explicit ``spec``; else the ``RIMCL_DEVICE`` environment variable;
else the first GPU; else the first CPU (PoCL).

A ``spec`` is either ``P:D`` (platform and device index, as listed by
``rimcl devices``), ``P`` (first device of platform ``P``), or a case-insensitive
substring of the platform or device name (``pocl``, ``nvidia``, ``h100``).
"""

import functools
import os

from rimcl.core.errors import RimclError

NO_PLATFORM_HELP = (
    'no OpenCL platform found; install the CPU driver with: pip install "rimcl[pocl]" '
    '(or pip install "pyopencl[pocl]")'
)


def _platforms():
    import pyopencl as cl

    try:
        platforms = cl.get_platforms()
    except cl.LogicError:  # PLATFORM_NOT_FOUND_KHR when the ICD loader finds nothing
        platforms = []
    if not platforms:
        raise RimclError(NO_PLATFORM_HELP)
    return platforms


def _all_devices():
    found = []
    for p_index, platform in enumerate(_platforms()):
        try:
            devices = platform.get_devices()
        except Exception:  # a broken ICD must not hide the working ones
            devices = []
        for d_index, device in enumerate(devices):
            found.append((p_index, d_index, device))
    if not found:
        raise RimclError(NO_PLATFORM_HELP)
    return found


_PROBE_SOURCE = "__kernel void probe(__global float *a) { a[0] = sqrt(a[1]); }"


@functools.cache
def build_problem(device):
    """Why ``device`` cannot compile OpenCL C, or ``""`` if it can.

    Some drivers list devices they cannot compile for: the PoCL 3.0 of the pip wheel
    (LLVM 14) fails with "unknown target CPU 'generic'" on CPUs newer than its LLVM
    (AMD Zen 5, for one). Such devices are skipped by :func:`select_device`.
    """
    import pyopencl as cl

    try:
        cl.Program(cl.Context([device]), _PROBE_SOURCE).build()
    except cl.Error as exc:
        lines = [line.strip() for line in str(exc).splitlines() if "error" in line.lower()]
        return (lines[-1] if lines else str(exc).splitlines()[0])[:200]
    return ""


def has_fp64(device):
    """True if ``device`` reports the ``cl_khr_fp64`` extension."""
    return "cl_khr_fp64" in device.extensions


def is_pocl(device):
    """True if ``device`` belongs to the Portable Computing Language (PoCL) platform."""
    return "portable computing language" in device.platform.name.lower()


def describe_device(device):
    """Plain-data description of a device, for tables and output files.

    Only what identifies the device: PoCL reports its global memory as a share of the host's
    memory free at the time, so the size would make two records of the same device differ
    (:func:`list_devices` adds it for display).

    Returns
    -------
    dict
    """
    import pyopencl as cl

    return {
        "platform": device.platform.name.strip(),
        "device": device.name.strip(),
        "type": cl.device_type.to_string(device.type),
        "opencl_version": device.version.strip(),
        "driver_version": device.driver_version.strip(),
        "compute_units": int(device.max_compute_units),
        "fp64": has_fp64(device),
        "images": bool(device.image_support),
        "usable": not build_problem(device),
        "problem": build_problem(device),
    }


def list_devices():
    """All OpenCL devices with their ``P:D`` index.

    Returns
    -------
    list of dict
        :func:`describe_device` entries with added ``"index"`` (``P:D``) and
        ``"default"`` (the device :func:`select_device` picks without a spec) keys.
    """
    found = _all_devices()
    try:
        default = select_device()
    except RimclError:
        default = None
    return [
        {
            "index": f"{p}:{d}",
            "default": device == default,
            "global_memory_mib": int(device.global_mem_size // 2**20),
            **describe_device(device),
        }
        for p, d, device in found
    ]


def _usable(found):
    usable = [entry for entry in found if not build_problem(entry[2])]
    if not usable:
        problems = "; ".join(
            f"{device.name.strip()}: {build_problem(device)}" for _, _, device in found
        )
        raise RimclError(
            f"no OpenCL device can compile kernels ({problems}); the pip PoCL is too old for "
            "this CPU: install the system one (Debian/Ubuntu: apt-get install pocl-opencl-icd)"
        )
    return usable


def _match(spec, found):
    spec = spec.strip()
    parts = spec.split(":")
    if all(part.isdigit() for part in parts) and len(parts) in (1, 2):
        p_want = int(parts[0])
        d_want = int(parts[1]) if len(parts) == 2 else 0
        for p, d, device in found:
            if p == p_want and d == d_want:
                return device
        raise RimclError(f"no OpenCL device {spec!r}; see 'rimcl devices' for the list")
    needle = spec.lower()
    for _, _, device in found:
        # PoCL's platform is named "Portable Computing Language"; its vendor and
        # version strings carry "pocl"
        names = (device.platform.name, device.platform.vendor, device.name, device.version)
        if any(needle in name.lower() for name in names):
            return device
    raise RimclError(f"no OpenCL device matches {spec!r}; see 'rimcl devices' for the list")


def select_device(spec=None, need_fp64=False):
    """Choose an OpenCL device without asking.

    Without a spec (nor ``$RIMCL_DEVICE``): the first usable GPU, then CPU; with
    ``need_fp64`` (the device engine) the first usable GPU, then CPU, with ``cl_khr_fp64``
    comes first (a laptop's integrated GPU often lacks it).

    Parameters
    ----------
    spec : str or pyopencl.Device, optional
        ``"pocl"``, ``"nvidia"``, ``"0:1"``... A device object is returned unchanged.
    need_fp64 : bool

    Returns
    -------
    pyopencl.Device
    """
    import pyopencl as cl

    if isinstance(spec, cl.Device):
        return spec
    found = _all_devices()
    if spec is None:
        spec = os.environ.get("RIMCL_DEVICE") or None
    if spec is not None:
        device = _match(str(spec), found)
        if build_problem(device):
            # the spec may match several platforms (two PoCL installs): take a usable one
            device = _match(str(spec), _usable(found))
        return device
    found = _usable(found)
    for fp64 in (True, False) if need_fp64 else (False,):
        for wanted in (cl.device_type.GPU, cl.device_type.CPU):
            for _, _, device in found:
                if device.type & wanted and (has_fp64(device) or not fp64):
                    return device
    return found[0][2]


@functools.cache
def _context_and_queue(device):
    import pyopencl as cl

    context = cl.Context([device])
    return context, cl.CommandQueue(context, device)


def context_for(device):
    """The one shared context of ``device`` (buffers are cached per context)."""
    return _context_and_queue(device)[0]


def queue_for(device):
    """The one shared in-order command queue of ``device``."""
    return _context_and_queue(device)[1]
