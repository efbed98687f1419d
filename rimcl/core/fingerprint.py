"""Fingerprints of input files: what a study records of every file it read, so that a
rerun after a file changed measures again instead of keeping results of the old content.

A file up to :data:`FULL_HASH_BYTES` is hashed whole (SHA-256 of its content: a copy or
a ``touch`` keeps it, any changed byte changes it). A larger file is fingerprinted by its
size, modification time and the SHA-256 of :data:`SAMPLES` evenly spaced blocks of
:data:`SAMPLE_BYTES`, so that a multi-gigabyte field is not read whole on every rerun.
"""

import hashlib
import os
from pathlib import Path

from rimcl.core.errors import RimclError

#: Files up to this size are hashed whole (bytes).
FULL_HASH_BYTES = 256 * 1024**2
#: Blocks hashed of a larger file, and their size (bytes).
SAMPLES = 64
SAMPLE_BYTES = 1024**2
_CACHE = {}


def fingerprint(path):
    """A short text that changes when the file's content changes.

    Parameters
    ----------
    path : str or Path

    Returns
    -------
    str
        ``"sha256:<hex>"`` (whole content) or ``"sampled-sha256:<size>:<mtime_ns>:<hex>"``.
    """
    path = Path(path)
    try:
        info = os.stat(path)
    except OSError as exc:
        raise RimclError(f"cannot read {path}: {exc.strerror}") from None
    key = (str(path.resolve()), info.st_size, info.st_mtime_ns, info.st_ino)
    if key not in _CACHE:
        _CACHE[key] = _digest(path, info)
    return _CACHE[key]


def _digest(path, info):
    digest = hashlib.sha256()
    try:
        with open(path, "rb") as handle:
            if info.st_size <= FULL_HASH_BYTES:
                for block in iter(lambda: handle.read(SAMPLE_BYTES), b""):
                    digest.update(block)
                return f"sha256:{digest.hexdigest()}"
            step = (info.st_size - SAMPLE_BYTES) / (SAMPLES - 1)
            for index in range(SAMPLES):
                handle.seek(int(index * step))
                digest.update(handle.read(SAMPLE_BYTES))
    except OSError as exc:
        raise RimclError(f"cannot read {path}: {exc.strerror}") from None
    return f"sampled-sha256:{info.st_size}:{info.st_mtime_ns}:{digest.hexdigest()}"


def describe_change(name, old, new):
    """One line saying that input ``name`` changed (or was not recorded)."""
    if old is None:
        return f"records no fingerprint of its {name} (an older rimcl): cannot tell it is current"
    return f"its {name} changed since ({str(old)[-12:]} -> {str(new)[-12:]})"


def input_changes(old, new):
    """Lines saying which inputs of ``new`` (name to fingerprint) ``old`` recorded
    otherwise (``old``: the record of an earlier result, or None)."""
    old = old if isinstance(old, dict) else {}
    return [
        describe_change(name, old.get(name), value)
        for name, value in new.items()
        if old.get(name) != value
    ]
