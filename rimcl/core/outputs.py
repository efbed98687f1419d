"""Output sets: every file of a run lands inside its output folder, and a run's files
replace the previous run's as a set.

A command that writes several files (``rimcl lpt render``, ``rimcl piv sequence``,
``rimcl stats`` …) opens one :class:`OutputSet`. Before any work it refuses an earlier
set (unless ``overwrite``) and outputs that are inputs of the run; the run writes every
file into a staging folder beside the outputs (:meth:`OutputSet.path`, which also checks
each name is a plain file name, so a camera called ``../../x`` cannot leave the folder);
only when the whole run succeeded are the staged files renamed into place, the files of
the previous set that the new run did not write removed, and the list of the new set
written to a manifest (``.rimcl-outputs.json`` in a folder, ``.<prefix>.rimcl-outputs.json``
beside the files of a prefix). A failed or killed run leaves the previous set whole.

Files that are not part of a set (anything rimcl did not list in a manifest or does not
claim by the set's own name patterns) are never touched.
"""

import contextlib
import glob
import json
import os
import shutil
import tempfile
from pathlib import Path, PurePosixPath

from rimcl.core.atomic import atomic_path, check_not_input
from rimcl.core.errors import RimclError

#: Manifest of a folder set (a prefix set's is ``.<prefix>`` + this).
MANIFEST = ".rimcl-outputs.json"
#: Prefix of a set's staging folder (removed when the run ends, or by the next run).
STAGING = ".rimcl-staging-"
#: File in a staging folder locked while its run lives.
LOCK = ".lock"


def check_file_name(name, what="a name"):
    """Refuse a name that is not one plain file name (it would leave its folder).

    Parameters
    ----------
    name : str
        A camera's, case's or frame's name, used as (part of) a file name.
    what : str
        What the name is, for the error ("camera name").

    Returns
    -------
    str
    """
    text = str(name)
    bad = (
        not text
        or text in (".", "..")
        or any(c in text for c in "/\\\0")
        or text != text.strip()
        or any(ord(c) < 32 for c in text)
    )
    if bad:
        raise RimclError(
            f"{what} {text!r} is not a plain file name (no '/', '\\', '..', control "
            "characters or surrounding spaces): rimcl names files after it"
        )
    return text


def _relative(text):
    """A manifest entry as a relative path inside the folder, or None if it is not one."""
    path = PurePosixPath(text)
    if path.is_absolute() or not path.parts or any(p in ("", ".", "..") for p in path.parts):
        return None
    return path


class OutputSet:
    """The files of one run, written into staging and put in place as a set.

    Use as a context manager: the set is committed when the block ends normally and
    discarded (the previous set left whole) when it raises.

    Parameters
    ----------
    target : str or Path
        The output folder (``prefix=False``, created if missing) or the path prefix of the
        files (``prefix=True``: files ``<prefix>_...`` in the prefix's folder, which must
        exist).
    overwrite : bool
        Replace an earlier set; without it an earlier set is refused before any work.
    prefix : bool
    owned : sequence of str
        Glob patterns (relative to the folder; ``{prefix}`` stands for the prefix's name)
        of the files this command writes: an earlier set without a manifest (rimcl before
        the manifests) is found by them.
    inputs : sequence of (str or Path)
        The run's input files: none of them may be an output.
    """

    def __init__(self, target, *, overwrite=False, prefix=False, owned=(), inputs=()):
        target = Path(target)
        self.prefix = target.name if prefix else None
        self.folder = target.parent if prefix else target
        self.inputs = [Path(p) for p in inputs if p is not None and str(p) != ""]
        name = f".{self.prefix}{MANIFEST}" if prefix else MANIFEST
        self.manifest = self.folder / name
        self.label = str(target) + ("_*" if prefix else "")
        stem = glob.escape(self.prefix) if prefix else ""
        self.owned = [pattern.replace("{prefix}", stem) for pattern in owned]
        self.staging = None
        self.created = False
        self._check_folder(prefix)
        previous = self.previous_files()
        if previous and not overwrite:
            first = self.folder / self._principal(previous)
            others = len(previous) - 1
            raise RimclError(
                f"{first} exists (use --overwrite to replace it"
                + (f" and the {others} other file(s) of that run)" if others else ")")
            )
        for source in self.inputs:
            if Path(os.path.abspath(source)) == Path(os.path.abspath(self.folder)):
                raise RimclError(f"output folder {self.folder} is an input of this run")
        self._remove_stale_staging()
        try:
            self.staging = Path(tempfile.mkdtemp(prefix=self._staging_prefix(), dir=self.folder))
            # held while this run lives: another run sees it is not stale
            self._lock = _locked(self.staging / LOCK)
        except OSError as exc:
            raise RimclError(f"cannot write in {self.folder}: {exc.strerror}") from None

    def _principal(self, files):
        """The file an error names: the first of the command's own patterns (its main
        file, e.g. ``stats.json``), else the first in order."""
        for pattern in self.owned:
            for name in files:
                if PurePosixPath(name).match(pattern) and "/" not in pattern.replace("**/", ""):
                    return name
        return files[0]

    def _check_folder(self, prefix):
        if prefix:
            if not self.folder.is_dir():
                raise RimclError(f"output directory {self.folder} does not exist")
        else:
            if self.folder.exists() and not self.folder.is_dir():
                raise RimclError(f"output {self.folder} exists and is not a folder")
            self.created = not self.folder.exists()
            try:
                self.folder.mkdir(parents=True, exist_ok=True)
            except OSError as exc:
                raise RimclError(
                    f"cannot create output folder {self.folder}: {exc.strerror}"
                ) from None
        if not os.access(self.folder, os.W_OK):
            raise RimclError(f"output directory {self.folder} is not writable")

    def _staging_prefix(self):
        return STAGING + (f"{self.prefix}-" if self.prefix else "")

    def _remove_stale_staging(self):
        """Staging folders a killed run of this same set left behind."""
        pattern = glob.escape(self._staging_prefix()) + "*"
        for stale in self.folder.glob(pattern):
            if not stale.is_dir() or stale.is_symlink():
                continue
            try:
                held = _locked(stale / LOCK, wait=False)
            except OSError:
                raise RimclError(
                    f"another rimcl run is writing {self.label} ({stale.name}); wait for it, "
                    "or choose another output"
                ) from None
            held.close()
            shutil.rmtree(stale, ignore_errors=True)

    # -- the set --------------------------------------------------------------------------

    def previous_files(self):
        """The files of the earlier set (relative paths, sorted): those its manifest lists
        and those matching the command's own patterns."""
        found = set()
        with contextlib.suppress(OSError, ValueError, TypeError, AttributeError):
            listed = json.loads(self.manifest.read_text())["files"]
            found |= {str(p) for p in map(_relative, listed) if p is not None}
        for pattern in self.owned:
            for path in self.folder.glob(pattern):
                if path.is_file() and not path.name.startswith("."):
                    found.add(path.relative_to(self.folder).as_posix())
        return sorted(
            p for p in found if (self.folder / p).is_file() or (self.folder / p).is_symlink()
        )

    def path(self, *parts):
        """The staging path of an output ``folder/part/part/…`` (parent folders created).

        Every part must be a plain file name (:func:`check_file_name`); the final output
        must not be an input of the run.

        Returns
        -------
        Path
        """
        if self.staging is None:
            raise RimclError("this output set is closed")
        names = [check_file_name(p, "output name") for p in parts]
        if not names:
            raise RimclError("an output needs a name")
        check_not_input(self.folder.joinpath(*names), self.inputs)
        staged = self.staging.joinpath(*names)
        staged.parent.mkdir(parents=True, exist_ok=True)
        return staged

    def folder_path(self, *parts):
        """The staging folder ``folder/part/…`` (created), for writers that take a folder."""
        names = [check_file_name(p, "output name") for p in parts]
        staged = self.staging.joinpath(*names)
        staged.mkdir(parents=True, exist_ok=True)
        return staged

    def final(self, staged):
        """Where a staged path will be once the set is committed."""
        return self.folder / Path(staged).relative_to(self.staging)

    def _staged_files(self):
        staged = []
        for root, _, files in os.walk(self.staging):
            for name in files:
                path = Path(root) / name
                rel = path.relative_to(self.staging)
                if (name.startswith(".") and name.endswith(".part")) or rel == Path(LOCK):
                    continue  # an atomic write's partial file, the lock
                if self.prefix is not None and len(rel.parts) != 1:
                    raise RimclError(f"output {rel} of a prefix set is in a subfolder")
                staged.append(rel)
        return sorted(staged)

    def commit(self):
        """Put the staged files in place, remove the earlier set's other files, write the
        manifest. Everything is checked before the first file moves."""
        staged = self._staged_files()
        inside = Path(os.path.realpath(self.folder))
        for rel in staged:
            final = self.folder / rel
            check_not_input(final, self.inputs)
            parent = final.parent
            while not parent.exists():
                parent = parent.parent
            if not Path(os.path.realpath(parent)).is_relative_to(inside):
                raise RimclError(
                    f"{parent} leads outside {self.folder} (a link); nothing was replaced"
                )
            if final.is_dir() and not final.is_symlink():
                raise RimclError(f"{final} is a folder; nothing was replaced")
        previous = self.previous_files()
        for rel in staged:
            final = self.folder / rel
            final.parent.mkdir(parents=True, exist_ok=True)
            os.replace(self.staging / rel, final)
        written = {rel.as_posix() for rel in staged}
        for rel in previous:
            if rel in written:
                continue
            old = self.folder / rel
            if any(_same(old, source) for source in self.inputs):
                continue
            if not Path(os.path.realpath(old.parent)).is_relative_to(inside):
                continue  # listed under a folder that now links elsewhere: not ours
            old.unlink(missing_ok=True)
            self._prune(old.parent)
        with atomic_path(self.manifest, overwrite=True) as tmp:
            Path(tmp).write_text(
                json.dumps({"rimcl_outputs": 1, "files": sorted(written)}, indent=1)
            )
        self.discard()

    def _prune(self, folder):
        """Remove folders the earlier set's files left empty (up to the output folder)."""
        while folder != self.folder and self.folder in folder.parents:
            try:
                folder.rmdir()
            except OSError:
                return
            folder = folder.parent

    def discard(self):
        """Remove the staging folder (the earlier set stays as it was)."""
        if self.staging is not None:
            shutil.rmtree(self.staging, ignore_errors=True)
            self.staging = None
            self._lock.close()
            if self.created and not self.manifest.exists():
                # a folder this set made and never filled: not left behind
                with contextlib.suppress(OSError):
                    self.folder.rmdir()

    def __enter__(self):
        return self

    def __exit__(self, kind, value, traceback):
        if kind is None:
            try:
                self.commit()
            finally:
                self.discard()
        else:
            self.discard()
        return False


def _locked(path, wait=True):
    """An open file holding an exclusive lock on ``path`` (created); without ``wait`` an
    ``OSError`` when another process holds it. No lock where ``fcntl`` is missing."""
    handle = open(path, "a+b")
    try:
        import fcntl
    except ImportError:  # pragma: no cover - not on POSIX: no lock
        return handle
    try:
        fcntl.flock(handle, fcntl.LOCK_EX | (0 if wait else fcntl.LOCK_NB))
    except OSError:
        handle.close()
        raise
    return handle


def _same(path, other):
    try:
        return os.path.samefile(path, other)
    except OSError:
        return False
