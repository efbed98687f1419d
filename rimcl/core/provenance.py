"""Versions, configuration records and atomic writes shared by every output file."""

import json
import platform
import sys
from importlib import metadata
from pathlib import Path

#: File that marks a directory as a rimcl study (rimcl.study.run); other commands never
#: write their outputs into such a directory.
STUDY_MARKER = ".rimcl-study"

_PACKAGES = ("rimcl", "numpy", "scipy", "pyopencl", "h5py", "scikit-image", "click", "tifffile")


def versions():
    """Versions of rimcl, Python and the packages it relies on.

    Returns
    -------
    dict of str to str
    """
    found = {"python": sys.version.split()[0], "platform": platform.platform()}
    for name in _PACKAGES:
        try:
            found[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            found[name] = "not installed"
    return found


def to_json(obj):
    """JSON text of a configuration, with NumPy scalars and arrays made plain."""

    def plain(value):
        if hasattr(value, "tolist"):
            return value.tolist()
        if isinstance(value, Path):
            return str(value)
        raise TypeError(f"cannot record {type(value).__name__} in a configuration")

    return json.dumps(obj, default=plain, sort_keys=True)


def stamp_h5(h5obj, config, device=None):
    """Record configuration, versions and device as JSON attributes of an HDF5 object.

    Parameters
    ----------
    h5obj : h5py.File or h5py.Group
    config : dict
        The full configuration that produced the data.
    device : pyopencl.Device, optional
    """
    h5obj.attrs["config"] = to_json(config)
    h5obj.attrs["versions"] = to_json(versions())
    if device is not None:
        from rimcl.core.device import describe_device

        h5obj.attrs["device"] = to_json(describe_device(device))
