"""OpenCL device selection. Never interactive.

Order of choice: an explicit ``spec``; else the ``RIMCL_DEVICE`` environment variable;
else the first usable GPU; else the first usable CPU. Among devices of one type, PoCL
devices come first, the newest PoCL (then LLVM) first: a machine with the distribution's
PoCL (3.1, LLVM 15) and the pip wheel's (3.0-rc2, LLVM 14) uses the distribution's
whatever order the ICD loader lists them in, because the older LLVM does not know newer
CPUs (it builds for a generic or older target, or fails) and the release candidate
miscompiles rimcl's kernels on some of them. Other devices follow in the loader's order.

A device is usable when it builds what the engines build (:func:`build_problem`): every
kernel file in its default shape, in a child process, since a driver that fails may also
abort the process that asked (PoCL 3.0 on an AMD Zen 4). The answer is kept on disk per
device, driver and kernel sources (:func:`probe_cache_dir`), so the probe runs once.

A ``spec`` is either ``P:D`` (platform and device index, as listed by
``rimcl devices``), ``P`` (first device of platform ``P``), or a case-insensitive
substring of the platform or device name (``pocl``, ``nvidia``, ``h100``).
"""

import functools
import hashlib
import json
import os
import re
import signal
import subprocess
import sys
from pathlib import Path

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


#: Seconds the child process may take to build every kernel file (a first build on a
#: loaded 2-core Xeon took 13 s; PoCL's own cache makes later ones fast).
PROBE_TIMEOUT_S = 300
#: Where rimcl installs its system PoCL from, for the message when nothing can build.
INSTALL_HELP = (
    "install the distribution's PoCL (Debian/Ubuntu: apt-get install pocl-opencl-icd, or "
    "bash tools/install-system-pocl.sh)"
)


def probe_builds(device):
    """What the probe builds on ``device``: the engines' kernel files in their default shape.

    Returns
    -------
    list of (str, list of str, dict)
        ``(file, kernel names, defines)``: the CPU shape (8 and 16 lanes, PoCL's fast
        path) on PoCL, one ray per work-item elsewhere.
    """
    lanes = {"RIMCL_POCL_FAST": 1} if is_pocl(device) else {}
    trace = {"RIMCL_PRECISION": 1, "RIMCL_FIELD": 0, "RIMCL_INTERP": 0}
    return [
        ("trace.cl", ["trace_rays"], {**trace, **lanes, "RIMCL_LANES": 8 if lanes else 1}),
        (
            "fan.cl",
            ["trace_fan", "fan_directions"],
            {**trace, **lanes, "RIMCL_CAMERA": 0, "RIMCL_LANES": 16 if lanes else 1},
        ),
        ("image.cl", ["image_tracers"], {"RIMCL_RENDERER": 0, "RIMCL_CENTROID": 0, **lanes}),
    ]


def _identity(device):
    """What tells a device and its driver apart, across processes."""
    return " | ".join(
        text.strip()
        for text in (
            device.platform.name,
            device.platform.version,
            device.name,
            device.driver_version,
        )
    )


def probe_cache_dir():
    """Directory of the probe's answers: ``$RIMCL_CACHE_DIR``, else ``$XDG_CACHE_HOME/rimcl``,
    else ``~/.cache/rimcl``."""
    if os.environ.get("RIMCL_CACHE_DIR"):
        return Path(os.environ["RIMCL_CACHE_DIR"])
    base = os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache"
    return Path(base) / "rimcl"


def _probe_key(device, builds):
    import pyopencl as cl

    from rimcl.core.program import kernel_dir

    digest = hashlib.sha256()
    for text in (_identity(device), json.dumps(builds, sort_keys=True), cl.VERSION_TEXT):
        digest.update(text.encode() + b"\0")
    for path in sorted(kernel_dir().iterdir(), key=lambda p: p.name):
        if path.name.endswith((".cl", ".h")):
            digest.update(path.name.encode() + b"\0" + path.read_bytes())
    return digest.hexdigest()[:24]


def _probe_command():
    """The child process that builds the kernels (reads the request on stdin)."""
    return [sys.executable, "-m", "rimcl.core.device"]


def _first_error(text):
    """The line of a build log or crash output that says what failed."""
    lines = [line.strip() for line in str(text).splitlines() if line.strip()]
    for marks in (("error:",), ("error", "failed")):
        for line in lines:
            if any(mark in line.lower() for mark in marks):
                return line[:200]
    return (lines[-1] if lines else "no output")[:200]


def _probe_in_child(device, builds):
    request = json.dumps({"identity": _identity(device), "builds": builds})
    try:
        done = subprocess.run(
            _probe_command(),
            input=request,
            capture_output=True,
            text=True,
            timeout=PROBE_TIMEOUT_S,
            check=False,
        )
    except subprocess.TimeoutExpired:
        return None, f"building rimcl's kernels did not finish within {PROBE_TIMEOUT_S} s"
    for line in reversed(done.stdout.splitlines()):
        if line.startswith("{"):
            with_answer = json.loads(line)
            return with_answer["problem"], with_answer["problem"]
    if done.returncode < 0:
        try:
            how = signal.Signals(-done.returncode).name
        except ValueError:
            how = f"signal {-done.returncode}"
    else:
        how = f"exit {done.returncode}"
    problem = f"building rimcl's kernels crashed ({how}): {_first_error(done.stderr)}"
    return problem, problem


@functools.cache
def build_problem(device):
    """Why ``device`` cannot build rimcl's kernels, or ``""`` if it can.

    Builds every kernel file in its default shape (:func:`probe_builds`) and creates
    its kernels, in a child process: some drivers list devices they cannot compile for
    (the pip wheel's PoCL 3.0, LLVM 14: "unknown target CPU 'generic'" on AMD Zen 5; on
    Zen 4 a failed build of ``fma`` on ``double8``, then ``clCreateKernel`` failing with
    INVALID_KERNEL_NAME and an abort when the process exits). Such devices are skipped by
    :func:`select_device`. The answer is cached on disk (:func:`probe_cache_dir`), keyed
    by the device, its driver, pyopencl and the kernel sources.
    """
    builds = probe_builds(device)
    path = probe_cache_dir() / f"device-probe-{_probe_key(device, builds)}.json"
    try:
        return json.loads(path.read_text())["problem"]
    except (OSError, ValueError, KeyError, TypeError):
        pass
    keep, problem = _probe_in_child(device, builds)
    if keep is not None:
        from rimcl.core.atomic import atomic_path

        try:
            path.parent.mkdir(parents=True, exist_ok=True)
            with atomic_path(path, overwrite=True) as tmp:
                Path(tmp).write_text(json.dumps({"device": _identity(device), "problem": keep}))
        except OSError:
            pass  # a read-only home: the probe runs again next time
    return problem


def _probe_child():
    """The child of :func:`build_problem`: build what stdin asks on the device it names,
    print ``{"problem": ...}`` (a crash prints nothing: the parent reads the exit)."""
    import pyopencl as cl

    from rimcl.core.program import kernel_dir

    request = json.loads(sys.stdin.read())
    found = [d for _, _, d in _all_devices() if _identity(d) == request["identity"]]
    if not found:
        print(json.dumps({"problem": "the device is not found again in a child process"}))
        return
    context = cl.Context([found[0]])
    for filename, kernels, defines in request["builds"]:
        options = [f"-I{kernel_dir()}", *(f"-D{k}={v}" for k, v in sorted(defines.items()))]
        try:
            program = cl.Program(context, f'#include "{filename}"\n').build(options=options)
            for name in kernels:
                cl.Kernel(program, name)
        except cl.Error as exc:
            problem = f"{filename}: {_first_error(exc)}"
            print(json.dumps({"problem": problem}), flush=True)
            return
    print(json.dumps({"problem": ""}), flush=True)


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
        "platform_version": device.platform.version.strip(),
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
            f"{device.name.strip()} ({device.platform.version.strip()}): {build_problem(device)}"
            for _, _, device in found
        )
        raise RimclError(f"no OpenCL device can build rimcl's kernels ({problems}); {INSTALL_HELP}")
    return usable


def pocl_versions(device):
    """``(PoCL version, LLVM version)`` of a PoCL device, or None for another driver.

    Versions are tuples ``(major, minor, patch, release)``, ``release`` 0 for a release
    candidate ("3.0-rc2") and 1 otherwise, so that they order as releases do.
    """
    if not is_pocl(device):
        return None
    text = device.platform.version

    def version(name):
        found = re.search(name + r" (\d+)(?:\.(\d+))?(?:\.(\d+))?(-rc\d*)?", text)
        if found is None:
            return (0, 0, 0, 0)
        numbers = tuple(int(part or 0) for part in found.groups()[:3])
        return (*numbers, 0 if found.group(4) else 1)

    return version("PoCL"), version("LLVM")


def _preferred_first(found):
    """``found`` with PoCL devices first, newest PoCL then LLVM first; the rest in order."""
    return sorted(found, key=lambda entry: pocl_versions(entry[2]) or (), reverse=True)


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

    Without a spec (nor ``$RIMCL_DEVICE``): the first usable GPU, then CPU (PoCL devices
    first among them, newest first: module docstring); with
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
    found = _preferred_first(found)
    if spec is not None:
        device = _match(str(spec), found)
        if build_problem(device):
            # the spec may match several platforms (two PoCL installs): take a usable one
            usable = [entry for entry in found if not build_problem(entry[2])]
            try:
                return _match(str(spec), usable)
            except RimclError:
                raise RimclError(
                    f"OpenCL device {device.name.strip()} ({spec}) cannot build rimcl's "
                    f"kernels ({build_problem(device)}); choose another (see 'rimcl "
                    f"devices') or {INSTALL_HELP}"
                ) from None
        return device
    for fp64 in (True, False) if need_fp64 else (False,):
        for wanted in (cl.device_type.GPU, cl.device_type.CPU):
            for _, _, device in found:
                if (
                    device.type & wanted
                    and (has_fp64(device) or not fp64)
                    and not build_problem(device)
                ):
                    return device
    return _usable(found)[0][2]


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


if __name__ == "__main__":
    _probe_child()
