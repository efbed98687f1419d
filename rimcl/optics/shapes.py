"""Kernel shapes of the trace kernels, measured per device.

A :class:`KernelShape` says how ``cl/trace.cl`` and ``cl/fan.cl`` are built and launched:
rays per work-item (vector lanes), the PoCL switch and the work-group size. Every shape
traces the same bits (the lanes of a work-item are independent and do the same operations
in the same order; tests compare them bit for bit), so the choice is one of speed only,
and which is fastest depends on the machine: the vector width and gathers of the CPU, the
driver's compiler, a GPU's warps.

So on first use of a device :func:`rimcl.trace_rays` and the device engine time the shapes
that matter (:func:`rimcl.optics.tuning.tune`: trilinear ``f32c``, the default trace, on a
small seeded field) and keep the fastest, with its measurements, in the user's cache
directory, one entry per device name, driver version and CPU model; this module reads and
writes that cache (it imports nothing of the tracer, which uses it). ``rimcl bench --tune``
measures again; ``rimcl devices`` shows the shape in use. Environment:

- ``RIMCL_TUNE``: ``auto`` (default: tune once per device, then use the cache),
  ``cache`` (use the cache, never tune: the rule-based shape where there is no entry),
  ``off`` (the rule-based shape; the test suite sets it).
- ``RIMCL_SHAPE_CACHE``: the cache file (default ``kernel_shapes.json`` in
  ``platformdirs.user_cache_dir("rimcl")``).
"""

import dataclasses
import json
import logging
import os
import platform
from pathlib import Path

from rimcl.core.errors import RimclError

logger = logging.getLogger(__name__)

#: Rays per work-item on CPUs: 8 lanes (float8: one AVX register in f32/f32c).
CPU_LANES = 8
#: Rays per work-item on PoCL for trilinear float states: 16 lanes, whose field sampler
#: works on all lanes at once (cl/rimcl_field.h; 14-25 % faster than 8 lanes in runs of
#: benchmarks/speed.py on the 2-core AMD EPYC, the same bits).
POCL_FLOAT_LANES = 16
#: Bumped when the kernels change so much that measured shapes must be measured again.
TUNE_VERSION = 1
#: Work-group sizes tried on GPUs (None: the driver's choice).
GPU_GROUPS = (None, 32, 64, 128, 256)
#: Work-group sizes tried on CPUs with the fastest lanes and switch.
CPU_GROUPS = (None, 4, 16, 64)
#: Work-group size of ``trace_rays`` on CPUs where none was measured or given. PoCL compiles
#: a kernel once per work-group size, and its own choice follows the number of rays, so every
#: new ray count cost a fresh compile (4-11 s on a 2-core Xeon) instead of a cache hit; 16
#: work-items of 16 lanes are 256 rays a group, as fast as the driver's choice where measured.
CPU_TRACE_GROUP = 16
#: ``RIMCL_TUNE`` values.
TUNE_MODES = ("auto", "cache", "off")


@dataclasses.dataclass(frozen=True)
class KernelShape:
    """How the trace kernels are built and launched on a device.

    Attributes
    ----------
    lanes : int
        Rays advanced together by one work-item, in vector lanes (1, 2, 4, 8 or 16).
    pocl_fast : bool
        Force helpers inline and keep OpenCL library calls out of the hot loop (PoCL).
    group : int or None
        Work-items per work-group; None: the driver's choice for ``trace_rays`` on GPUs,
        :data:`CPU_TRACE_GROUP` on CPUs, and the fan kernel's fixed ``FAN_GROUP``.
    """

    lanes: int = 1
    pocl_fast: bool = False
    group: int | None = None

    def __post_init__(self):
        if self.lanes not in (1, 2, 4, 8, 16):
            raise RimclError(f"rays per work-item must be 1, 2, 4, 8 or 16, got {self.lanes}")
        if self.group is not None and not (isinstance(self.group, int) and self.group > 0):
            raise RimclError(f"the work-group size must be a positive integer, got {self.group}")

    def describe(self):
        """Plain data, for output files and ``rimcl devices``."""
        return dataclasses.asdict(self)


def rule_shape(device, precision="f32c", interp="trilinear"):
    """The shape without measurements: on CPUs 8 lanes, 16 on PoCL for a trilinear float
    state, the PoCL switch and work-groups of :data:`CPU_TRACE_GROUP`; one ray per
    work-item elsewhere (GPUs), in the driver's work-groups."""
    import pyopencl as cl

    from rimcl.core.device import is_pocl

    if device.type & cl.device_type.CPU:
        pocl = is_pocl(device)
        wide = pocl and _tuned_class(precision, interp)
        lanes = POCL_FLOAT_LANES if wide else CPU_LANES
        return KernelShape(lanes=lanes, pocl_fast=pocl, group=CPU_TRACE_GROUP)
    return KernelShape(lanes=1, pocl_fast=False)


def _tuned_class(precision, interp):
    """Settings that take the measured shape whole: the 16-lane field sampler is for
    trilinear float states; f64, texture and bspline3 take at most CPU_LANES lanes."""
    return interp == "trilinear" and precision != "f64"


def default_kernel_shape(device, precision="f32c", interp="trilinear"):
    """The kernel shape for ``device``: the measured one in the cache (measured on first use
    by :func:`rimcl.optics.tuning.tuned_entry`), else :func:`rule_shape`.

    Parameters
    ----------
    device : pyopencl.Device
    precision : str
        A key of :data:`rimcl.optics.trace.PRECISIONS`.
    interp : str
        A key of :data:`rimcl.optics.trace.INTERPOLATIONS`.

    Returns
    -------
    KernelShape
    """
    entry = cached_entry(device)
    if entry is None:
        return rule_shape(device, precision, interp)
    shape = KernelShape(**entry["shape"])
    if not _tuned_class(precision, interp):
        shape = dataclasses.replace(shape, lanes=min(shape.lanes, CPU_LANES))
    return shape


def tune_mode():
    """``RIMCL_TUNE`` (default ``auto``)."""
    mode = os.environ.get("RIMCL_TUNE", "auto").strip().lower() or "auto"
    if mode not in TUNE_MODES:
        raise RimclError(f"RIMCL_TUNE must be one of {', '.join(TUNE_MODES)}, got {mode!r}")
    return mode


def cache_path():
    """The shape cache file (``RIMCL_SHAPE_CACHE``, else the user's cache directory)."""
    explicit = os.environ.get("RIMCL_SHAPE_CACHE")
    if explicit:
        return Path(explicit)
    import platformdirs

    return Path(platformdirs.user_cache_dir("rimcl")) / "kernel_shapes.json"


def cpu_model():
    """The host CPU's model name (``/proc/cpuinfo``; elsewhere what Python reports)."""
    try:
        with open("/proc/cpuinfo", encoding="utf-8", errors="replace") as info:
            for line in info:
                if line.lower().startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine() or "unknown"


def device_key(device):
    """What a measured shape belongs to: device name, driver version and CPU model."""
    return " | ".join(
        (device.name.strip(), device.driver_version.strip(), cpu_model(), f"v{TUNE_VERSION}")
    )


def _read_cache(path):
    try:
        with open(path, encoding="utf-8") as handle:
            data = json.load(handle)
    except FileNotFoundError:
        return {}
    except (OSError, ValueError) as exc:
        logger.warning("ignoring the unreadable kernel-shape cache %s (%s)", path, exc)
        return {}
    entries = data.get("entries") if isinstance(data, dict) else None
    return entries if isinstance(entries, dict) else {}


def _write_cache(path, key, entry):
    """Add ``entry`` under ``key``, keeping the other devices' entries; atomic."""
    from rimcl.core.atomic import atomic_path
    from rimcl.core.provenance import to_json

    path.parent.mkdir(parents=True, exist_ok=True)
    entries = _read_cache(path)
    entries[key] = entry
    with atomic_path(path) as tmp:
        tmp.write_text(to_json({"format": "rimcl kernel shapes", "entries": entries}))


_memo = {}


def cached_entry(device):
    """The cache entry of ``device``, or None (never tunes: on first use
    :func:`rimcl.optics.tuning.tuned_entry` measures it).

    Returns
    -------
    dict or None
        ``shape`` (:meth:`KernelShape.describe`), ``measurements`` and provenance.
    """
    mode = tune_mode()
    if mode == "off":
        return None
    path, key = cache_path(), device_key(device)
    if (path, key) in _memo:
        return _memo[(path, key)]
    entry = _read_cache(path).get(key)
    if entry is not None and not _valid_entry(entry):
        logger.warning("ignoring a malformed kernel-shape entry for %s in %s", key, path)
        entry = None
    if entry is not None:
        _memo[(path, key)] = entry
    return entry


def add_to_entry(device, name, part, path=None):
    """Store ``part`` under ``name`` in ``device``'s cache entry, beside its trace shape
    (the image kernel's measured work-group size: :func:`rimcl.imaging.device.tune_image`).

    Returns
    -------
    bool
        False (nothing written) where the device has no entry yet.
    """
    path = cache_path() if path is None else Path(path)
    key = device_key(device)
    entry = _read_cache(path).get(key)
    if entry is None or not _valid_entry(entry):
        return False
    entry[name] = part
    _write_cache(path, key, entry)
    _memo[(path, key)] = entry
    return True


def launch_group(shape, device):
    """The work-group size ``trace_rays`` launches ``shape`` with on ``device``: the shape's,
    else the driver's choice (None) on GPUs and :data:`CPU_TRACE_GROUP` on CPUs."""
    import pyopencl as cl

    if shape.group is None and device.type & cl.device_type.CPU:
        return CPU_TRACE_GROUP
    return shape.group


def shape_in_use(device):
    """The shape ``device`` traces with now, and where it comes from, without tuning.

    Returns
    -------
    dict
        :meth:`KernelShape.describe` of the default trace's shape, plus ``source``:
        ``measured`` (with ``measured``, the time, and ``ray_steps_per_s``), ``rule``
        (``RIMCL_TUNE=off``, or not yet measured: it is on first use in mode ``auto``);
        ``image_group``: the image kernel's measured work-group size, or None (its rule).
    """
    mode = tune_mode()
    entry = None
    if mode != "off":
        entry = _read_cache(cache_path()).get(device_key(device))
        entry = entry if entry is not None and _valid_entry(entry) else None
    if entry is None:
        return {
            **rule_shape(device).describe(),
            "source": "rule",
            "mode": mode,
            "image_group": None,
        }
    rates = [m.get("ray_steps_per_s") for m in entry.get("measurements", [])]
    rates = [rate for rate in rates if isinstance(rate, (int, float))]
    measured = KernelShape(**entry["shape"])
    return {
        **measured.describe(),
        "group": launch_group(measured, device),
        "source": "measured",
        "mode": mode,
        "measured": entry.get("measured"),
        "ray_steps_per_s": max(rates) if rates else None,
        "image_group": _image_group(entry),
    }


def describe_shape(shape):
    """One line for tables: ``16 lanes, PoCL switch, group 64`` (and ``image group 2``
    where the image kernel's was measured)."""
    parts = [f"{shape['lanes']} lane{'s' if shape['lanes'] > 1 else ''}"]
    if shape["pocl_fast"]:
        parts.append("PoCL switch")
    parts.append(f"group {shape['group']}" if shape["group"] else "group auto")
    if shape.get("image_group"):
        parts.append(f"image group {shape['image_group']}")
    return ", ".join(parts)


def _image_group(entry):
    """The measured image-kernel work-group size of a cache entry, or None."""
    image = entry.get("image")
    group = image.get("group") if isinstance(image, dict) else None
    return group if isinstance(group, int) and group > 0 else None


def _valid_entry(entry):
    try:
        KernelShape(**entry["shape"])
    except (KeyError, TypeError, RimclError):
        return False
    return True
