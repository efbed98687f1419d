"""Import of flow data: JHTDB cut-outs (HDF5 / netCDF-4) and plain ``.npz`` files.

JHTDB cut-outs hold one dataset per variable and time, named ``<Var>_<tttt>`` with the
1-based time index ``tttt`` (``Density_0286`` from the web service and older clients,
``density_0286`` from giverny 3.x), arrays ``(nz, ny, nx, ncomp)`` with ``x`` fastest,
and the 1-D node coordinates ``xcoor, ycoor, zcoor``. netCDF-4 files are HDF5 files; their
dimension-only dataset ``values`` (and any other variable) is skipped. Times may be spread
over several files or held in one.

A ``.npz`` file uses the same conventions: ``density`` ``(nz, ny, nx)`` for one frame or
``(nt, nz, ny, nx)``; optional ``velocity`` ``(nz, ny, nx, 3)`` or ``(nt, nz, ny, nx, 3)``
(components ``u_x, u_y, u_z``); the grid as ``xcoor, ycoor, zcoor`` or as ``origin`` and
``spacing`` (3 numbers each, in ``x, y, z`` order); optional ``times`` ``(nt,)``. Its frames
have time indices 1, 2, ...

Each frame has a time index ``i``; without stored times, its time is
``t0 + (i - 1) dt`` (JHTDB "mixing": ``dt = 0.04``, so index 286 is ``t = 11.4``).
"""

import contextlib
import dataclasses
import math
import re
import zipfile
from pathlib import Path

import h5py
import numpy as np

from rimcl.core.atomic import check_output
from rimcl.core.errors import RimclError, first_line
from rimcl.core.memory import check_array_memory, check_import_memory
from rimcl.fields.derivatives import gradient as compute_gradient
from rimcl.fields.field_layout import check_hdf5_object, real_numbers
from rimcl.fields.field_writer import write_field

DNS_AXES = ("x", "y", "z")
COORDINATES = {"x": "xcoor", "y": "ycoor", "z": "zcoor"}
# array axis of each DNS axis in a (nz, ny, nx) array
_ARRAY_AXIS = {"z": 0, "y": 1, "x": 2}
_VARIABLE = re.compile(r"^(density|velocity)_(\d+)$", re.IGNORECASE)
#: JHTDB "mixing" data set: time between stored frames, and its box period.
JHTDB_DT = 0.04
JHTDB_PERIOD = 2 * math.pi
GRADIENT_METHODS = ("auto", "spectral", "fd2", "fd4", "fd6", "none")
# coordinates count as uniform when every spacing is within this fraction of the mean
# (float32 coordinates near 2π are rounded to ~1e-4 of a 1024-point spacing)
_UNIFORM_TOLERANCE = 1e-3


@dataclasses.dataclass
class ImportedFlow:
    """Flow frames read from files, already in rimcl's axes and array order.

    Attributes
    ----------
    density : list of ndarray, float32, each (n3, n2, n1)
    velocity : list of ndarray, float32, each (n3, n2, n1, 3), or None
        Components along ``x1, x2, x3``.
    times : ndarray, float64, shape (n_frames,)
    indices : list of int
        Time index of each frame.
    origin, spacing : ndarray, float64, shape (3,)
        Along ``x1, x2, x3``.
    boundary : {"clamp", "periodic"}
    attrs : dict
        Provenance: files, axes mapping, crop, stride, times.
    """

    density: list
    velocity: list | None
    times: np.ndarray
    indices: list
    origin: np.ndarray
    spacing: np.ndarray
    boundary: str
    attrs: dict


def parse_axes(axes):
    """DNS axis (``"x"``, ``"y"``, ``"z"``) that becomes ``x1``, ``x2``, ``x3``.

    Parameters
    ----------
    axes : str or sequence of str
        A permutation such as ``"x,y,z"`` (default mapping) or ``"z,y,x"``.

    Returns
    -------
    tuple of 3 str
    """
    letters = axes.replace(" ", "").lower().split(",") if isinstance(axes, str) else list(axes)
    if sorted(letters) != list(DNS_AXES):
        raise RimclError(f"--axes must be a permutation of x,y,z (e.g. 'z,y,x'), got {axes!r}")
    return tuple(letters)


def parse_crop(crop):
    """Node index ranges along ``x1, x2, x3`` from ``"a:b,c:d,e:f"`` (blank = all).

    Returns
    -------
    tuple of 3 slice
    """
    if crop is None:
        return (slice(None),) * 3
    if not isinstance(crop, str):
        return tuple(crop)
    parts = crop.replace(" ", "").split(",")
    if len(parts) != 3:
        raise RimclError(f"--crop needs three ranges 'a:b,c:d,e:f' along x1,x2,x3, got {crop!r}")
    ranges = []
    for part in parts:
        bounds = part.split(":") if part else ["", ""]
        if len(bounds) != 2:
            raise RimclError(f"--crop range {part!r} is not 'start:stop'")
        try:
            ranges.append(slice(*(int(b) if b else None for b in bounds)))
        except ValueError:
            raise RimclError(f"--crop range {part!r} must hold integers") from None
    return tuple(ranges)


def parse_stride(stride):
    """Stride along ``x1, x2, x3`` from ``"2"`` or ``"1,2,2"`` (or ints)."""
    if stride is None:
        return (1, 1, 1)
    if isinstance(stride, str):
        try:
            values = [int(s) for s in stride.replace(" ", "").split(",")]
        except ValueError:
            raise RimclError(f"--stride must be integers, got {stride!r}") from None
    else:
        values = [int(s) for s in np.atleast_1d(stride)]
    if len(values) == 1:
        values *= 3
    if len(values) != 3 or min(values) < 1:
        raise RimclError(f"--stride must be one or three positive integers, got {stride!r}")
    return tuple(values)


def parse_frames(frames):
    """Time indices (1-based) from ``"286,287"`` or ``"285-290"`` (or a sequence).

    Returns
    -------
    list of int or None
        Sorted, at least one; None (all frames) for None.
    """
    if frames is None:
        return None
    if not isinstance(frames, str):
        chosen = {int(f) for f in frames}
    else:
        chosen = set()
        for part in frames.replace(" ", "").split(","):
            try:
                if "-" in part[1:]:
                    first, last = (int(b) for b in part.split("-", 1))
                    if last < first:
                        raise RimclError(f"--frames range {part!r} is empty (it counts down)")
                    chosen.update(range(first, last + 1))
                else:
                    chosen.add(int(part))
            except ValueError:
                raise RimclError(
                    f"--frames must be indices or ranges like 285-290, not {part!r}"
                ) from None
    if not chosen:
        raise RimclError("--frames names no frame")
    if min(chosen) < 1:
        raise RimclError(f"--frames are time indices from 1, got {min(chosen)}")
    return sorted(chosen)


def _uniform_spacing(values, name):
    values = np.asarray(values, dtype=np.float64).reshape(-1)
    if values.size < 2:
        raise RimclError(f"{name} needs at least 2 nodes, got {values.size}")
    if not np.all(np.isfinite(values)):
        raise RimclError(f"{name} holds NaN or infinite values")
    spacing = (values[-1] - values[0]) / (values.size - 1)
    steps = np.diff(values)
    if not spacing > 0 or np.max(np.abs(steps - spacing)) > _UNIFORM_TOLERANCE * spacing:
        raise RimclError(
            f"{name} is not uniformly spaced and increasing (spacings from {steps.min():.6g} to "
            f"{steps.max():.6g}); rimcl needs a uniform grid"
        )
    return spacing


class _Layout:
    """Maps DNS axes and components to rimcl's ``x1, x2, x3`` and applies crop/stride."""

    def __init__(self, axes, crop, stride, counts):
        self.axes = parse_axes(axes)
        crop = parse_crop(crop)
        stride = parse_stride(stride)
        # per DNS axis: the node range kept, as a slice with the stride folded in
        self.ranges = {}
        for k, letter in enumerate(self.axes):
            start, stop, step = crop[k].indices(counts[letter])
            if step != 1:
                raise RimclError("--crop ranges take no step; use --stride")
            if stop - start < 2:
                raise RimclError(
                    f"--crop leaves {max(stop - start, 0)} node(s) along x{k + 1} "
                    f"(DNS {letter}, {counts[letter]} nodes); at least 2 are needed"
                )
            kept = len(range(start, stop, stride[k]))
            if kept < 2:
                raise RimclError(
                    f"--stride {stride[k]} keeps {kept} node of the {stop - start} along "
                    f"x{k + 1} (DNS {letter}); at least 2 are needed"
                )
            self.ranges[letter] = slice(start, stop, stride[k])
        self.selection = tuple(self.ranges[letter] for letter in ("z", "y", "x"))
        # transpose (nz, ny, nx) into (n3, n2, n1)
        self.order = tuple(_ARRAY_AXIS[self.axes[k]] for k in (2, 1, 0))
        self.components = [DNS_AXES.index(letter) for letter in self.axes]

    def scalar(self, dns_values):
        return np.ascontiguousarray(np.transpose(dns_values, self.order), dtype=np.float32)

    def vector(self, dns_values):
        moved = np.transpose(dns_values, (*self.order, 3))[..., self.components]
        return np.ascontiguousarray(moved, dtype=np.float32)

    def provenance(self, source, paths, indices):
        """Attributes recording where the frames came from and how they were mapped."""
        return {
            "source": source,
            "input_files": [str(p) for p in paths],
            "time_indices": list(indices),
            "axes": ",".join(f"x{k + 1}={a}" for k, a in enumerate(self.axes)),
            "crop_nodes": {a: [r.start, r.stop, r.step] for a, r in self.ranges.items()},
        }

    def grid(self, coordinates, spacings=None):
        """Origin and spacing along ``x1, x2, x3`` and the node counts per axis.

        ``spacings`` (per DNS axis) are used as given when known exactly.
        """
        origin, spacing, counts = [], [], []
        for letter in self.axes:
            nodes = np.asarray(coordinates[letter], dtype=np.float64)[self.ranges[letter]]
            origin.append(nodes[0])
            if spacings is None:
                step = _uniform_spacing(coordinates[letter], COORDINATES[letter])
            else:
                step = spacings[letter]
            spacing.append(step * self.ranges[letter].step)
            counts.append(nodes.size)
        return np.array(origin), np.array(spacing), np.array(counts)


def _boundary(boundary, spacing, counts, period):
    full = np.abs(counts * spacing - period) <= 0.01 * spacing
    if boundary == "auto":
        return "periodic" if np.all(full) else "clamp"
    if boundary == "periodic" and not np.all(full):
        raise RimclError(
            f"--boundary periodic needs a full period of {period:g} along every axis; this grid "
            f"spans {(counts * spacing).tolist()}"
        )
    if boundary not in ("clamp", "periodic"):
        raise RimclError(f"boundary must be auto, clamp or periodic, got {boundary!r}")
    return boundary


def _finite(values, where):
    if not np.all(np.isfinite(values)):
        raise RimclError(f"{where} holds NaN or infinite values")
    return values


#: Depth of groups searched for cut-out datasets (cut-outs are flat; this bounds cycles).
_SEARCH_DEPTH = 8


def _member_names(group, prefix="", depth=0):
    """Paths of the datasets and links below ``group`` (not followed out of the file)."""
    names = []
    for name in group:
        link = group.get(name, getlink=True)
        member = group.get(name) if not isinstance(link, h5py.ExternalLink) else None
        if isinstance(member, h5py.Group):
            if depth < _SEARCH_DEPTH:
                names += _member_names(member, f"{prefix}{name}/", depth + 1)
        else:  # a dataset, or a link whose target the checks below report
            names.append(f"{prefix}{name}")
    return names


def _dataset(path, h5, name):
    """The dataset ``name`` (a path) of an open file, checked (links, kind, dtype)."""
    parent_name, _, leaf = name.rpartition("/")
    parent = h5[parent_name] if parent_name else h5
    dataset = check_hdf5_object(path, parent, leaf, "dataset")
    if dataset is not None and dataset.dtype.kind not in "fiu":
        raise RimclError(
            f"{path}: {name} must hold real numbers (float or integer), got {dataset.dtype}"
        )
    return dataset


def _read_values(path, dataset, selection=()):
    """Values of a dataset; a damaged one is one line of error."""
    if dataset.chunks is not None:  # HDF5 decompresses whole chunks, however little is read
        check_array_memory(
            dataset.chunks, dataset.dtype.itemsize, f"one chunk of {path}: {dataset.name}"
        )
    try:
        return dataset[selection] if selection else dataset[()]
    except Exception as exc:
        raise RimclError(
            f"{path}: cannot read {dataset.name} ({first_line(exc)}); the file is damaged"
        ) from None


def _scan_cutout(path, inventory, coordinates):
    """Record the density/velocity datasets of one file and check its coordinates."""
    try:
        h5 = h5py.File(path, "r")
    except Exception:
        raise RimclError(
            f"{path} is not an HDF5 or netCDF-4 file (netCDF-3 classic cannot be read)"
        ) from None
    with h5:
        try:
            found = _member_names(h5)
        except Exception as exc:
            raise RimclError(
                f"{path}: cannot list its datasets ({first_line(exc)}); the file is damaged"
            ) from None
        variables = [(n, _VARIABLE.match(n.rsplit("/", 1)[-1])) for n in found]
        variables = [(n, m) for n, m in variables if m]
        if not variables:
            raise RimclError(
                f"{path} holds no Density_<tttt> or Velocity_<tttt> datasets (found: "
                f"{', '.join(found[:8]) or 'none'})"
            )
        for letter, name in COORDINATES.items():
            dataset = _dataset(path, h5, name)
            if dataset is None:
                raise RimclError(
                    f"{path} has no {name} dataset (cut-outs need xcoor, ycoor, zcoor)"
                )
            check_array_memory(dataset.shape, 8, f"reading {path}: {name}")
            values = np.asarray(_read_values(path, dataset), dtype=np.float64).reshape(-1)
            _uniform_spacing(values, f"{path}: {name}")
            if letter not in coordinates:
                coordinates[letter] = values
            elif values.shape != coordinates[letter].shape or not np.allclose(
                values, coordinates[letter], rtol=0, atol=1e-6 * abs(values[-1] - values[0])
            ):
                raise RimclError(f"{path}: {name} differs from the other files' grid")
        for name, match in variables:
            variable, index = match.group(1).lower(), int(match.group(2))
            key = (index, variable)
            if key in inventory:
                raise RimclError(
                    f"{variable} at time index {index} appears twice ({inventory[key][0]} "
                    f"and {path})"
                )
            dataset = _dataset(path, h5, name)
            components = 3 if variable == "velocity" else 1
            shape = tuple(coordinates[a].size for a in ("z", "y", "x"))
            allowed = [(*shape, components)] + ([shape] if components == 1 else [])
            if dataset.shape not in allowed:
                raise RimclError(
                    f"{path}: {name} has shape {dataset.shape}, but the coordinates give "
                    f"(nz, ny, nx, {components}) = {(*shape, components)}"
                )
            stored_time = dataset.attrs.get("time")
            if stored_time is not None:
                stored_time = real_numbers(path, f"time of {name}", stored_time, 1)[0]
            inventory[key] = (path, name, stored_time)


def read_cutouts(
    paths,
    *,
    axes="x,y,z",
    crop=None,
    stride=None,
    frames=None,
    t0=0.0,
    dt=JHTDB_DT,
    boundary="auto",
    period=JHTDB_PERIOD,
):
    """Read JHTDB cut-outs (HDF5 or netCDF-4; one or several files) into rimcl's axes.

    Parameters
    ----------
    paths : sequence of str or Path
    axes : str
        DNS axis that becomes ``x1, x2, x3``, e.g. ``"x,y,z"`` or ``"z,y,x"``.
    crop : str or sequence of 3 slice, optional
        Node ranges along ``x1, x2, x3`` (after the axes mapping), ``"a:b,c:d,e:f"``.
    stride : int, str or sequence of 3 int, optional
        Keep every ``stride``-th node (along ``x1, x2, x3``), after cropping.
    frames : str or sequence of int, optional
        Time indices ``tttt`` to import (default: every index with a density).
    t0, dt : float
        Time of index 1 and time between indices, used when a dataset has no ``time``
        attribute.
    boundary : {"auto", "clamp", "periodic"}
        ``auto``: periodic when the grid spans a full ``period`` along every axis.
    period : float
        Box period (JHTDB: ``2π``).

    Returns
    -------
    ImportedFlow
    """
    paths = [Path(p) for p in paths]
    if not paths:
        raise RimclError("no input files given")
    for path in paths:
        if path.is_dir():
            raise RimclError(
                f"{path} is a folder without Zarr metadata, not a file or a Zarr store"
            )
        if not path.is_file():
            raise RimclError(f"input file {path} does not exist")
    inventory, coordinates = {}, {}
    for path in paths:
        _scan_cutout(path, inventory, coordinates)
    available = sorted(index for index, variable in inventory if variable == "density")
    if not available:
        raise RimclError("the files hold velocity but no density; rimcl needs the density")
    wanted = parse_frames(frames)
    wanted = available if wanted is None else wanted
    missing = sorted(set(wanted) - set(available))
    if missing:
        raise RimclError(f"no density for time index {missing} (available: {available})")
    with_velocity = [index for index in wanted if (index, "velocity") in inventory]
    if with_velocity and len(with_velocity) != len(wanted):
        lacking = sorted(set(wanted) - set(with_velocity))
        raise RimclError(f"velocity is missing at time index {lacking} but present at others")
    counts = {letter: coordinates[letter].size for letter in DNS_AXES}
    layout = _Layout(axes, crop, stride, counts)
    origin, spacing, nodes = layout.grid(coordinates)
    check_import_memory(nodes[::-1], len(wanted), bool(with_velocity), "importing the cut-outs")
    with contextlib.ExitStack() as stack:
        handles = {}

        def read(index, variable):
            path, name, _ = inventory[index, variable]
            if path not in handles:
                handles[path] = stack.enter_context(h5py.File(path, "r"))
            dataset = handles[path][name]
            selection = layout.selection + ((slice(None),) if dataset.ndim == 4 else ())
            values = _finite(_read_values(path, dataset, selection), f"{path}: {name}")
            return values[..., 0] if variable == "density" and values.ndim == 4 else values

        density = [layout.scalar(read(index, "density")) for index in wanted]
        velocity = None
        if with_velocity:
            velocity = [layout.vector(read(index, "velocity")) for index in wanted]
    stored = [inventory[index, "density"][2] for index in wanted]
    times = np.array(
        [t0 + (index - 1) * dt if t is None else t for index, t in zip(wanted, stored, strict=True)]
    )
    return ImportedFlow(
        density=density,
        velocity=velocity,
        times=times,
        indices=list(wanted),
        origin=origin,
        spacing=spacing,
        boundary=_boundary(boundary, spacing, nodes, period),
        attrs=layout.provenance("JHTDB cut-out", paths, wanted),
    )


def read_npz(
    path,
    *,
    axes="x,y,z",
    crop=None,
    stride=None,
    frames=None,
    t0=0.0,
    dt=JHTDB_DT,
    boundary="auto",
    period=JHTDB_PERIOD,
):
    """Read a ``.npz`` flow file (layout in the module docstring) into rimcl's axes.

    Parameters are those of :func:`read_cutouts`; frames have time indices 1, 2, ...

    Returns
    -------
    ImportedFlow
    """
    path = Path(path)
    with open_npz(path) as archive:
        if "density" not in archive:
            raise RimclError(f"{path} has no 'density' array (found: {sorted(archive.files)})")
        density = _finite(npz_array(archive, path, "density"), f"{path}: density")
        if density.ndim == 3:
            density = density[None]
        if density.ndim != 4:
            raise RimclError(
                f"{path}: density must be (nz, ny, nx) or (nt, nz, ny, nx), got {density.shape}"
            )
        velocity = None
        if "velocity" in archive:
            velocity = _finite(npz_array(archive, path, "velocity"), f"{path}: velocity")
            if velocity.ndim == 4:
                velocity = velocity[None]
            if velocity.shape != (*density.shape, 3):
                raise RimclError(
                    f"{path}: velocity must have shape {(*density.shape, 3)} to match density, "
                    f"got {velocity.shape}"
                )
        shape = dict(zip(("z", "y", "x"), density.shape[1:], strict=True))
        coordinates, spacings = _npz_coordinates(archive, path, shape)
        times = None
        if "times" in archive:
            times = real_numbers(path, "times", npz_array(archive, path, "times"))
            if times.size != density.shape[0]:
                raise RimclError(
                    f"{path}: times has {times.size} entries for {density.shape[0]} frames"
                )
    available = list(range(1, density.shape[0] + 1))
    wanted = parse_frames(frames)
    wanted = available if wanted is None else wanted
    missing = sorted(set(wanted) - set(available))
    if missing:
        raise RimclError(f"{path} has frames 1..{density.shape[0]}; no frame {missing}")
    layout = _Layout(axes, crop, stride, shape)
    origin, spacing, nodes = layout.grid(coordinates, spacings)
    check_import_memory(nodes[::-1], len(wanted), velocity is not None, f"importing {path}")
    picks = [i - 1 for i in wanted]
    return ImportedFlow(
        density=[layout.scalar(density[i][layout.selection]) for i in picks],
        velocity=None
        if velocity is None
        else [layout.vector(velocity[i][(*layout.selection, slice(None))]) for i in picks],
        times=times[picks] if times is not None else t0 + (np.array(wanted) - 1) * dt,
        indices=list(wanted),
        origin=origin,
        spacing=spacing,
        boundary=_boundary(boundary, spacing, nodes, period),
        attrs=layout.provenance("npz", [path], wanted),
    )


def open_npz(path):
    """An ``.npz`` archive opened without pickles; anything else is one line of error.

    Returns
    -------
    numpy.lib.npyio.NpzFile
        A context manager.
    """
    path = Path(path)
    if not zipfile.is_zipfile(path):
        with open(path, "rb") as start:
            single = start.read(6) == b"\x93NUMPY"
        raise RimclError(
            f"{path} is "
            + ("a single .npy array" if single else "not a zip archive")
            + ", not a .npz archive of named arrays"
        )
    try:
        return np.load(path, allow_pickle=False)
    except Exception as exc:
        raise RimclError(f"{path} is not a readable .npz file ({exc})") from None


def npz_array(archive, path, name):
    """One array of an open ``.npz`` archive, after checking from its header that it holds
    real numbers and fits in memory.

    Parameters
    ----------
    archive : numpy.lib.npyio.NpzFile
    path : Path
        The archive, for messages.
    name : str

    Returns
    -------
    ndarray
    """
    try:
        with archive.zip.open(f"{name}.npy") as member:
            version = np.lib.format.read_magic(member)
            read_header = {
                (1, 0): np.lib.format.read_array_header_1_0,
                (2, 0): np.lib.format.read_array_header_2_0,
            }.get(version)
            header = None if read_header is None else read_header(member)
        if header is not None:
            shape, _, dtype = header
            if dtype.kind not in "fiu":
                raise RimclError(
                    f"{path}: {name} must hold real numbers (float or integer), got {dtype}"
                )
            check_array_memory(shape, dtype.itemsize, f"reading {path}: {name}", factor=3)
        values = archive[name]
    except RimclError:
        raise
    except Exception as exc:
        raise RimclError(f"{path}: cannot read array {name!r} ({exc})") from None
    if values.dtype.kind not in "fiu":
        raise RimclError(f"{path}: {name} must hold real numbers, got {values.dtype}")
    return values


def _npz_coordinates(archive, path, shape):
    """Coordinates of an npz file's nodes per DNS axis, and its spacings if given exactly.

    Returns
    -------
    coordinates : dict of str to ndarray
    spacings : dict of str to float, or None
        From a ``spacing`` array; None when the grid came as ``xcoor, ycoor, zcoor``.
    """
    if all(name in archive for name in COORDINATES.values()):
        coordinates = {}
        for letter, name in COORDINATES.items():
            values = real_numbers(path, name, npz_array(archive, path, name))
            if values.size != shape[letter]:
                raise RimclError(
                    f"{path}: {name} has {values.size} nodes but density has {shape[letter]} "
                    f"along {letter}"
                )
            coordinates[letter] = values
        return coordinates, None
    if "spacing" not in archive:
        raise RimclError(f"{path} needs xcoor, ycoor, zcoor or spacing (and origin) arrays")
    spacing = real_numbers(path, "spacing", npz_array(archive, path, "spacing"))
    origin = np.zeros(3)
    if "origin" in archive:
        origin = real_numbers(path, "origin", npz_array(archive, path, "origin"))
    if spacing.size != 3 or origin.size != 3 or not np.all(spacing > 0):
        raise RimclError(f"{path}: spacing and origin must be 3 numbers (x, y, z), spacing > 0")
    coordinates = {
        letter: origin[k] + spacing[k] * np.arange(shape[letter])
        for k, letter in enumerate(DNS_AXES)
    }
    return coordinates, dict(zip(DNS_AXES, spacing.tolist(), strict=True))


def import_flow(
    paths,
    output,
    *,
    axes="x,y,z",
    crop=None,
    stride=None,
    frames=None,
    t0=0.0,
    dt=JHTDB_DT,
    boundary="auto",
    period=JHTDB_PERIOD,
    gradient="auto",
    title=None,
    overwrite=False,
):
    """Import JHTDB cut-outs or one ``.npz`` file into a rimcl field file.

    Parameters
    ----------
    paths : sequence of str or Path
        HDF5/netCDF-4 cut-outs, or a single ``.npz``.
    output : str or Path
        The field file to write (atomically; nothing is written on error).
    gradient : {"auto", "spectral", "fd2", "fd4", "fd6", "none"}
        Density gradient to store: ``auto`` is spectral for a periodic box and 4th-order
        central differences otherwise; ``none`` stores none (readers compute it).
    axes, crop, stride, frames, t0, dt, boundary, period
        As :func:`read_cutouts`.
    title : str, optional
    overwrite : bool

    Returns
    -------
    pathlib.Path
    """
    if gradient not in GRADIENT_METHODS:
        raise RimclError(f"gradient must be one of {GRADIENT_METHODS}, got {gradient!r}")
    check_output(output, overwrite)
    paths = [Path(p) for p in paths]
    options = dict(
        axes=axes, crop=crop, stride=stride, frames=frames, t0=t0, dt=dt,
        boundary=boundary, period=period,
    )  # fmt: skip
    if any(p.suffix.lower() == ".npz" for p in paths):
        if len(paths) != 1:
            raise RimclError("import one .npz file at a time (it holds all its frames)")
        flow = read_npz(paths[0], **options)
    else:
        flow = read_cutouts(paths, **options)
    periodic = flow.boundary == "periodic"
    method = ("spectral" if periodic else "fd4") if gradient == "auto" else gradient
    gradients = None
    if method != "none":
        gradients = [
            compute_gradient(d, flow.spacing, method=method, periodic=periodic)
            for d in flow.density
        ]
    attrs = {
        "title": title or f"{flow.attrs['source']} import",
        **flow.attrs,
        "density_gradient": method,
        "length_unit": "as in the input coordinates",
        "time_unit": "as in the input times",
    }
    config = {"inputs": [str(p) for p in paths], "output": str(output), "gradient": method,
              **{k: v if isinstance(v, (int, float, str)) or v is None else str(v)
                 for k, v in options.items()}}  # fmt: skip
    return write_field(
        output,
        density=flow.density,
        velocity=flow.velocity,
        density_gradient=gradients,
        times=flow.times,
        origin=flow.origin,
        spacing=flow.spacing,
        boundary=flow.boundary,
        attrs=attrs,
        config=config,
        overwrite=overwrite,
    )
