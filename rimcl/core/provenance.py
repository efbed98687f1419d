"""Versions, configuration records and atomic writes shared by every output file."""

import contextlib
import json
import os
import platform
import sys
import tempfile
from importlib import metadata
from pathlib import Path

from rimcl.core.errors import RimclError

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


def check_output(path, overwrite=True):
    """Refuse, before any work is done, an output that exists (unless ``overwrite``) or
    whose directory is missing or not writable.

    Returns
    -------
    Path
    """
    path = Path(path)
    if path.exists() and not overwrite:
        raise RimclError(f"{path} exists (use --overwrite to replace it)")
    parent = path.parent
    if not parent.is_dir():
        raise RimclError(f"output directory {parent} does not exist")
    if not os.access(parent, os.W_OK):
        raise RimclError(f"output directory {parent} is not writable")
    return path


def _temporary_beside(path):
    """A new empty ``.<name>.<random>.part`` file beside ``path``, with the usual mode."""
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".part", dir=path.parent)
    os.close(fd)
    tmp = Path(tmp)
    # mkstemp makes the file private (0600); give it the usual umask-based mode
    umask = os.umask(0)
    os.umask(umask)
    tmp.chmod(0o666 & ~umask)
    return tmp


@contextlib.contextmanager
def atomic_paths(paths, overwrite=True):
    """Temporary paths beside several outputs, renamed onto them once all are written.

    A failure while any of them is written leaves every old file as it was (the set
    stays whole), and an ``OSError`` of the writing becomes a :class:`RimclError` naming
    the outputs, not the temporary files.

    Parameters
    ----------
    paths : dict of str to (str or Path)
        The outputs, by role.
    overwrite : bool
        If False and any output exists, raise :class:`RimclError` before doing any work.

    Yields
    ------
    dict of str to Path
        The temporary path of each role.
    """
    finals = {key: check_output(path, overwrite) for key, path in paths.items()}
    temps = {}
    try:
        for key, path in finals.items():
            temps[key] = _temporary_beside(path)
        try:
            yield temps
        except OSError as exc:
            text = str(exc)
            for key, tmp in temps.items():
                text = text.replace(str(tmp), str(finals[key])).replace(tmp.name, finals[key].name)
            folders = sorted({str(path.parent) for path in finals.values()})
            raise RimclError(
                f"writing {len(finals)} files in {', '.join(folders)} failed, the old ones are "
                f"unchanged: {text}"
            ) from None
        for key, tmp in temps.items():
            os.replace(tmp, finals[key])
    finally:
        for tmp in temps.values():
            if tmp.exists():
                tmp.unlink()


@contextlib.contextmanager
def atomic_path(path, overwrite=True):
    """Yield a temporary path beside ``path``; rename it onto ``path`` on success.

    A killed or failed run leaves either the old file or none, never half of one.

    Parameters
    ----------
    path : str or Path
        Final destination.
    overwrite : bool
        If False and ``path`` exists, raise :class:`RimclError` before doing any work.
    """
    path = check_output(path, overwrite)
    tmp = _temporary_beside(path)
    try:
        yield tmp
        os.replace(tmp, path)
    finally:
        if tmp.exists():
            tmp.unlink()
