"""rimcl: measurement errors of tracer velocimetry through inhomogeneous refractive indices.

The public API is imported lazily so that ``import rimcl`` (and ``rimcl --help``)
works without an OpenCL platform.
"""

from importlib import import_module

__version__ = "0.1.0"

# public name -> module that defines it
_EXPORTS = {
    "RimclError": "rimcl.errors",
    "select_device": "rimcl.device",
    "list_devices": "rimcl.device",
    "Field": "rimcl.field",
    "AnalyticField": "rimcl.field",
    "analytic_field": "rimcl.field",
    "trace_rays": "rimcl.tracing",
    "TraceResult": "rimcl.trace",
    "STATUS_NAMES": "rimcl.trace",
    "load_field": "rimcl.flow.fieldfile",
    "write_field": "rimcl.flow.fieldfile",
    "FieldFile": "rimcl.flow.fieldfile",
    "sample_path": "rimcl.flow",
    "run_render": "rimcl.measure",
    "write_render": "rimcl.measure",
    "load_render": "rimcl.stats",
    "compute_stats": "rimcl.stats",
    "run_stats": "rimcl.stats",
    "load_scene": "rimcl.scene",
    "run_study": "rimcl.study",
}

__all__ = ["__version__", *sorted(_EXPORTS)]


def __getattr__(name):
    module = _EXPORTS.get(name)
    if module is None:
        raise AttributeError(f"module 'rimcl' has no attribute {name!r}")
    return getattr(import_module(module), name)
