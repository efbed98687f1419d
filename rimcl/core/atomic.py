"""Writing files safely: an output is checked before work starts and appears whole or not at all.

:func:`atomic_path` (one file) and :func:`atomic_paths` (a set written as one) write beside the
outputs and rename onto them once written, so a killed or failed run leaves the old files or
none, never half of one; :func:`check_output` refuses what must not be replaced.
"""

import contextlib
import os
import tempfile
from pathlib import Path

from rimcl.core.errors import RimclError


def check_not_input(output, inputs):
    """Refuse an output path that is one of the run's input files (writing it would
    destroy the input)."""
    output = Path(output)
    for source in inputs:
        if source is None or str(source) == "":
            continue
        same = Path(os.path.abspath(output)) == Path(os.path.abspath(source))
        with contextlib.suppress(OSError):
            same = same or os.path.samefile(output, source)
        if same:
            raise RimclError(
                f"output {output} is an input of this run ({source}); choose another output"
            )
    return output


def check_output(path, overwrite=True, inputs=()):
    """Refuse, before any work is done, an output that exists (unless ``overwrite``),
    that is one of ``inputs`` (the run's input files), or whose directory is missing or
    not writable.

    Returns
    -------
    Path
    """
    path = check_not_input(path, inputs)
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
