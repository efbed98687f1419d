"""rimcl: measurement errors of tracer velocimetry through inhomogeneous refractive indices.

The public API is imported lazily so that ``import rimcl`` (and ``rimcl --help``)
works without an OpenCL platform.
"""

from importlib import import_module

__version__ = "0.1.0"

# public name -> module that defines it
_EXPORTS = {
    "RimclError": "rimcl.core.errors",
    "select_device": "rimcl.core.device",
    "list_devices": "rimcl.core.device",
    "Field": "rimcl.fields.field",
    "AnalyticField": "rimcl.fields.field",
    "analytic_field": "rimcl.fields.field",
    "trace_rays": "rimcl.optics.tracing",
    "TraceResult": "rimcl.optics.trace",
    "STATUS_NAMES": "rimcl.optics.trace",
    "load_field": "rimcl.fields.field_loading",
    "write_field": "rimcl.fields.field_writer",
    "FieldFile": "rimcl.fields.field_reader",
    "sample_path": "rimcl.fields.sample",
    "run_render": "rimcl.ptv.measure",
    "write_render": "rimcl.ptv.render_file",
    "load_render": "rimcl.stats.render_file",
    "compute_stats": "rimcl.stats.document",
    "run_stats": "rimcl.stats.document",
    "load_scene": "rimcl.scene.load",
    "run_study": "rimcl.study.run",
}

__all__ = ["__version__", *sorted(_EXPORTS)]


def __getattr__(name):
    module = _EXPORTS.get(name)
    if module is None:
        raise AttributeError(f"module 'rimcl' has no attribute {name!r}")
    return getattr(import_module(module), name)
