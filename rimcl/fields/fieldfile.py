"""The rimcl field file: an HDF5 file of flow frames on a uniform grid.

Layout (``rimcl_schema = "field"``, ``schema_version = 1``), readable with plain h5py::

    /                      attrs: rimcl_schema, schema_version, title, source, units, axes,
                                  config, versions (JSON) and any extra provenance
    /grid                  attrs: origin (3,), spacing (3,) along x1, x2, x3 (length units),
                                  boundary ("clamp" or "periodic"; missing means "clamp")
    /frames/0000           attrs: time (time units)
        density            (n3, n2, n1) float32, dimensionless density
        or delta_n         (n3, n2, n1) float32, n - n_ref, with attribute n_ref (float64)
        density_gradient   (n3, n2, n1, 3) float32, optional, components along x1, x2, x3
        velocity           (n3, n2, n1, 3) float32, optional, components along x1, x2, x3
        or velocity_sheet  (n3, n2, 2) float32, optional, instead of velocity: the in-plane
                           velocity (u2, u3) on the light-sheet plane x1 = const only, at
                           the nodes (x3, x2), with attribute x1 (float64, length units)
    /frames/0001 ...

Frames are numbered from 0 in time order. A file holds either ``density`` (turned into a
refractive index with a Gladstone–Dale product ``G``: ``δn = G (ρ - mean ρ)``,
``n_ref = 1 + G mean ρ``) or ``delta_n`` directly, in every frame. A velocity, when
stored, is in every frame, and either in full (``velocity``) or on one sheet plane
(``velocity_sheet``, the same ``x1`` in every frame): the sheet plane is all that tracking
tracers in that sheet needs, at 2/(3 n1) of the size, so a file can hold many frames.
"""

import functools
import json
import math
from pathlib import Path

import h5py
import numpy as np

from rimcl.core.errors import RimclError, first_line
from rimcl.core.memory import check_array_memory, check_field_memory
from rimcl.core.provenance import atomic_path, stamp_h5
from rimcl.fields.cases import resolve_k_rho
from rimcl.fields.field import BOUNDARIES, Field

SCHEMA = "field"
SCHEMA_VERSION = 1
#: Dataset name of the sheet-only velocity (see the module docstring).
SHEET_VELOCITY = "velocity_sheet"

# relative slack on times at the ends of the stored range (rounding of t0 + k dt)
_TIME_SLACK = 1e-9


def _frame_name(index):
    return f"{index:04d}"


def _as_frames(values, name, count=None, trailing=()):
    """A list of float arrays, one per frame, checked for shape and finiteness."""
    if values is None:
        return None
    frames = [np.asarray(v) for v in values]
    if count is not None and len(frames) != count:
        raise RimclError(f"{name} has {len(frames)} frames, expected {count}")
    for k, frame in enumerate(frames):
        if frame.ndim != 3 + len(trailing) or frame.shape[3:] != trailing:
            want = "(n3, n2, n1" + "".join(f", {t}" for t in trailing) + ")"
            raise RimclError(f"{name} frame {k} must have shape {want}, got {frame.shape}")
        if not np.all(np.isfinite(frame)):
            raise RimclError(f"{name} frame {k} holds NaN or infinite values")
    return frames


def _chunks(shape):
    """Chunks of whole (n2, n1) planes, about 1 MiB each, so that gzip sees long runs."""
    plane = int(np.prod(shape[1:])) * 4
    depth = max(1, min(shape[0], (1 << 20) // max(plane, 1)))
    return (depth, *shape[1:])


def _attr_value(value):
    """An HDF5-storable form of a provenance value (dicts and None become JSON text)."""
    if value is None or (isinstance(value, (dict, list, tuple)) and not _numeric_list(value)):
        return json.dumps(value)
    return value


def _numeric_list(value):
    return isinstance(value, (list, tuple)) and all(
        isinstance(v, (int, float, np.number)) for v in value
    )


def write_field(
    path,
    *,
    density=None,
    delta_n=None,
    n_ref=None,
    times,
    origin,
    spacing,
    velocity=None,
    velocity_sheet=None,
    sheet_x1=None,
    density_gradient=None,
    boundary="clamp",
    attrs=None,
    config=None,
    overwrite=False,
):
    """Write frames of a flow to a rimcl field file (atomically, stamped with provenance).

    Parameters
    ----------
    path : str or Path
        Output ``.h5`` file.
    density : sequence of ndarray, each (n3, n2, n1), optional
        Dimensionless density per frame. Exactly one of ``density`` and ``delta_n``.
    delta_n : sequence of ndarray, each (n3, n2, n1), optional
        ``n - n_ref`` per frame, with ``n_ref``.
    n_ref : float or sequence of float, optional
        Reference refractive index (one for all frames, or one per frame); only with
        ``delta_n``.
    times : sequence of float
        Time of each frame (time units), strictly increasing.
    origin, spacing : sequence of 3 float
        Position of node ``(0, 0, 0)`` and the grid spacing along ``x1, x2, x3``.
    velocity : sequence of ndarray, each (n3, n2, n1, 3), optional
        Flow velocity, components along ``x1, x2, x3``.
    velocity_sheet : sequence of ndarray, each (n3, n2, 2), optional
        Instead of ``velocity``: the in-plane velocity ``(u2, u3)`` on the plane
        ``x1 = sheet_x1`` only, at the nodes ``(x3, x2)``.
    sheet_x1 : float, optional
        The plane of ``velocity_sheet`` (length units): within the grid along ``x1``, or
        anywhere for a periodic grid. Only with ``velocity_sheet``.
    density_gradient : sequence of ndarray, each (n3, n2, n1, 3), optional
        ``∇ρ`` (1/length) along ``x1, x2, x3``; only with ``density``. When absent,
        readers compute it.
    boundary : {"clamp", "periodic"}
        ``periodic``: the grid holds one full period of a periodic box (endpoint excluded).
    attrs : dict, optional
        Extra root attributes (title, source, units, axes, ...). Dicts and None are stored
        as JSON text.
    config : dict, optional
        The configuration that produced the data, recorded with the software versions
        (default: ``attrs``).
    overwrite : bool
        Replace an existing file.

    Returns
    -------
    pathlib.Path
        The written file.
    """
    if (density is None) == (delta_n is None):
        raise RimclError("give exactly one of density and delta_n")
    if boundary not in BOUNDARIES:
        raise RimclError(f"boundary must be one of {BOUNDARIES}, got {boundary!r}")
    times = np.asarray(times, dtype=np.float64).reshape(-1)
    if times.size == 0:
        raise RimclError("a field file needs at least one frame")
    if not np.all(np.isfinite(times)) or np.any(np.diff(times) <= 0):
        raise RimclError(f"times must be finite and strictly increasing, got {times.tolist()}")
    count = times.size
    kind = "density" if density is not None else "delta_n"
    scalars = _as_frames(density if density is not None else delta_n, kind, count)
    shape = scalars[0].shape
    if any(s.shape != shape for s in scalars):
        raise RimclError(f"all {kind} frames must have the same shape")
    if kind == "delta_n":
        if n_ref is None:
            raise RimclError("delta_n needs n_ref")
        refs = np.broadcast_to(np.asarray(n_ref, dtype=np.float64), (count,))
        if not np.all(np.isfinite(refs)) or np.any(refs <= 0):
            raise RimclError(f"n_ref must be positive, got {refs.tolist()}")
    elif n_ref is not None:
        raise RimclError("n_ref only goes with delta_n (density files get it from K*rho)")
    if density_gradient is not None and kind != "density":
        raise RimclError("density_gradient only goes with density")
    vectors = {
        "velocity": _as_frames(velocity, "velocity", count, (3,)),
        "density_gradient": _as_frames(density_gradient, "density_gradient", count, (3,)),
    }
    for name, frames in vectors.items():
        if frames is not None and any(f.shape[:3] != shape for f in frames):
            raise RimclError(f"{name} frames must have shape {(*shape, 3)}")
    sheet = _sheet_frames(velocity_sheet, sheet_x1, velocity, shape, count)
    origin = np.asarray(origin, dtype=np.float64).reshape(-1)
    spacing = np.asarray(spacing, dtype=np.float64).reshape(-1)
    if origin.size != 3 or not np.all(np.isfinite(origin)):
        raise RimclError(f"origin must be 3 finite numbers, got {origin.tolist()}")
    if spacing.size != 3 or not np.all(np.isfinite(spacing)) or np.any(spacing <= 0):
        raise RimclError(f"spacing must be 3 positive numbers, got {spacing.tolist()}")
    if sheet is not None:
        _check_sheet_x1(sheet_x1, origin[0], spacing[0], shape[2], boundary, "sheet_x1")
    attrs = dict(attrs or {})
    written = Path(path)
    with atomic_path(written, overwrite=overwrite) as tmp, h5py.File(tmp, "w") as h5:
        h5.attrs["rimcl_schema"] = SCHEMA
        h5.attrs["schema_version"] = SCHEMA_VERSION
        for key, value in attrs.items():
            h5.attrs[key] = _attr_value(value)
        stamp_h5(h5, config if config is not None else attrs)
        grid = h5.create_group("grid")
        grid.attrs["origin"] = origin
        grid.attrs["spacing"] = spacing
        grid.attrs["boundary"] = boundary
        frames_group = h5.create_group("frames")
        for k in range(count):
            group = frames_group.create_group(_frame_name(k))
            group.attrs["time"] = times[k]
            dataset = _write_array(group, kind, scalars[k])
            if kind == "delta_n":
                dataset.attrs["n_ref"] = float(refs[k])
            for name, frames in vectors.items():
                if frames is not None:
                    _write_array(group, name, frames[k])
            if sheet is not None:
                _write_array(group, SHEET_VELOCITY, sheet[k]).attrs["x1"] = float(sheet_x1)
    return written


def _sheet_frames(velocity_sheet, sheet_x1, velocity, shape, count):
    """The ``velocity_sheet`` frames of :func:`write_field`, checked, or None."""
    if velocity_sheet is None:
        if sheet_x1 is not None:
            raise RimclError("sheet_x1 only goes with velocity_sheet")
        return None
    if velocity is not None:
        raise RimclError("give either velocity or velocity_sheet, not both")
    if sheet_x1 is None:
        raise RimclError("velocity_sheet needs sheet_x1, the x1 of its plane")
    frames = [np.asarray(v) for v in velocity_sheet]
    if len(frames) != count:
        raise RimclError(f"velocity_sheet has {len(frames)} frames, expected {count}")
    want = (*shape[:2], 2)
    for k, frame in enumerate(frames):
        if frame.shape != want:
            raise RimclError(f"velocity_sheet frame {k} must have shape {want}, got {frame.shape}")
        if not np.all(np.isfinite(frame)):
            raise RimclError(f"velocity_sheet frame {k} holds NaN or infinite values")
    return frames


def _check_sheet_x1(x1, origin1, spacing1, n1, boundary, what):
    """Refuse a sheet plane ``x1`` that is not finite, or outside a clamped grid."""
    try:
        x1 = float(x1)
    except (TypeError, ValueError):
        raise RimclError(f"{what} must be a number, got {x1!r}") from None
    hi = origin1 + (n1 - 1) * spacing1
    if not math.isfinite(x1) or (boundary != "periodic" and not origin1 <= x1 <= hi):
        raise RimclError(f"{what} = {x1:g} must lie in the field along x1 ({origin1:g} .. {hi:g})")


def _write_array(group, name, values):
    values = np.ascontiguousarray(values, dtype=np.float32)
    return group.create_dataset(
        name,
        data=values,
        chunks=_chunks(values.shape),
        compression="gzip",
        compression_opts=4,
        shuffle=True,
    )


def _plain_attr(value):
    if isinstance(value, bytes):
        return value.decode("utf-8", "replace")
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, np.generic):
        return value.item()
    return value


#: Kinds of NumPy dtype a field array may hold: floating point and integers (booleans,
#: complex numbers, strings and compound records are refused, not cast).
_REAL_KINDS = "fiu"
#: Largest grid coordinate: the float32 kernels square lengths (float32 overflows above
#: 3.4e38), and rays through grids of spacing 1e20 already come out NaN.
_LARGEST_COORDINATE = 1e18
#: Arrays of a frame: name -> trailing shape after (n3, n2, n1).
_FRAME_ARRAYS = {"density": (), "delta_n": (), "density_gradient": (3,), "velocity": (3,)}


def check_hdf5_object(path, parent, name, kind):
    """An object of an HDF5 file, checked to be what a reader expects, or None if absent.

    Refuses links that leave the file (external links, datasets stored in external files,
    virtual datasets), dangling links, objects of the wrong kind and objects the HDF5
    library cannot open (a damaged file), each with one line naming the file and object.

    Parameters
    ----------
    path : Path
        The file, for messages.
    parent : h5py.Group
    name : str
        Member of ``parent``.
    kind : {"group", "dataset"}

    Returns
    -------
    h5py.Group, h5py.Dataset or None
    """
    where = f"{path}: {parent.name.rstrip('/')}/{name}"
    try:
        link = parent.get(name, getlink=True)
    except Exception as exc:  # h5py raises KeyError, RuntimeError or OSError by damage
        raise RimclError(
            f"{where} cannot be read ({first_line(exc)}); the file is damaged"
        ) from None
    if link is None:
        return None
    if isinstance(link, h5py.ExternalLink):
        raise RimclError(
            f"{where} is a link to {link.filename}:{link.path}; a file must hold its own data"
        )
    try:
        found = parent.get(name)
    except Exception as exc:
        raise RimclError(
            f"{where} cannot be opened ({first_line(exc)}); the file is damaged"
        ) from None
    if found is None:
        target = link.path if isinstance(link, h5py.SoftLink) else "?"
        raise RimclError(f"{where} is a link to {target}, which does not exist")
    wanted = h5py.Group if kind == "group" else h5py.Dataset
    if not isinstance(found, wanted):
        other = "a group" if isinstance(found, h5py.Group) else "a dataset"
        raise RimclError(f"{where} must be a {kind}, but it is {other}")
    if kind == "dataset" and (found.external or found.is_virtual):
        storage = "virtual" if found.is_virtual else "external"
        raise RimclError(
            f"{where} keeps its data in other files ({storage} storage); a file must hold "
            "its own data"
        )
    return found


def _attr(path, obj, name):
    """An attribute's raw value, or None if absent; a damaged one is one line of error."""
    try:
        if name not in obj.attrs:
            return None
        return obj.attrs[name]
    except Exception as exc:
        raise RimclError(
            f"{path}: attribute {name!r} of {obj.name} cannot be read ({first_line(exc)})"
        ) from None


def real_numbers(path, where, value, count=None):
    """``value`` as a float64 array of real, finite numbers (``count`` of them if given).

    Raises
    ------
    RimclError
        Naming ``path`` and ``where`` for text, booleans, complex numbers, records, the
        wrong count, NaN or infinity.
    """
    array = np.asarray(value)
    if array.dtype.kind not in _REAL_KINDS:
        wanted = "a real number" if count == 1 else "real numbers"
        raise RimclError(f"{path}: {where} must be {wanted}, got {array.dtype} {value!r}")
    array = array.astype(np.float64).reshape(-1)
    if count is not None and array.size != count:
        wanted = "one number" if count == 1 else f"{count} numbers"
        raise RimclError(f"{path}: {where} must be {wanted}, got {array.size}")
    if not np.all(np.isfinite(array)):
        raise RimclError(f"{path}: {where} must be finite, got {array.tolist()}")
    return array


def _text_attr(path, obj, name, default):
    value = _attr(path, obj, name)
    if value is None:
        return default
    value = _plain_attr(value)
    if not isinstance(value, str):
        raise RimclError(f"{path}: attribute {name!r} of {obj.name} must be text, got {value!r}")
    return value


class FieldFile:
    """Read access to a rimcl field file; a context manager.

    Opening reads and checks the layout (metadata only); frame data is read on demand, after
    a check that it fits in memory (:mod:`rimcl.core.memory`).

    Parameters
    ----------
    path : str or Path

    Attributes
    ----------
    path : pathlib.Path
    times : ndarray, float64, shape (n_frames,)
        Frame times (time units), increasing.
    origin, spacing : ndarray, float64, shape (3,)
        Grid along ``x1, x2, x3`` (length units).
    shape : tuple of int
        ``(n3, n2, n1)``.
    boundary : {"clamp", "periodic"}
    kind : {"density", "delta_n"}
        What the frames hold.
    n_refs : ndarray, float64, shape (n_frames,) or None
        ``n_ref`` of each frame of a ``delta_n`` file.
    attrs : dict
        Root attributes (title, source, provenance...).
    """

    def __init__(self, path):
        self.path = Path(path)
        if not self.path.is_file():
            problem = "is not a regular file" if self.path.exists() else "does not exist"
            raise RimclError(f"field file {self.path} {problem}")
        try:
            self._h5 = h5py.File(self.path, "r")
        except Exception as exc:
            raise RimclError(
                f"{self.path} is not a readable HDF5 file ({first_line(exc)})"
            ) from None
        try:
            self._read_layout()
        except RimclError:
            self._h5.close()
            raise
        except Exception as exc:  # whatever else a damaged file raises inside h5py
            self._h5.close()
            raise RimclError(
                f"{self.path}: cannot read the file's layout ({type(exc).__name__}: "
                f"{first_line(exc)}); the file is damaged"
            ) from None
        self._plane_cache = {}

    def _read_layout(self):
        h5, path = self._h5, self.path
        schema = _plain_attr(_attr(path, h5, "rimcl_schema"))
        if schema != SCHEMA:
            raise RimclError(
                f"{path} is not a rimcl field file (rimcl_schema = {schema!r}); "
                "import flow data with 'rimcl field import'"
            )
        version = _attr(path, h5, "schema_version")
        version = -1 if version is None else _plain_attr(version)
        if version != SCHEMA_VERSION:
            raise RimclError(f"{path}: field schema version {version!r} is not supported")
        grid = check_hdf5_object(path, h5, "grid", "group")
        frames = check_hdf5_object(path, h5, "frames", "group")
        if grid is None or frames is None:
            raise RimclError(f"{path}: a field file needs the groups 'grid' and 'frames'")
        for name in ("origin", "spacing"):
            if _attr(path, grid, name) is None:
                raise RimclError(f"{path}: grid needs attributes origin and spacing")
        self.origin = real_numbers(path, "grid origin", _attr(path, grid, "origin"), 3)
        self.spacing = real_numbers(path, "grid spacing", _attr(path, grid, "spacing"), 3)
        if not np.all(self.spacing > 0):
            raise RimclError(f"{path}: grid spacing must be positive, got {self.spacing.tolist()}")
        self.boundary = _text_attr(path, grid, "boundary", "clamp")
        if self.boundary not in BOUNDARIES:
            raise RimclError(f"{path}: unknown boundary {self.boundary!r}")
        names = sorted(frames)
        if not names:
            raise RimclError(f"{path} holds no frames")
        self._frames = [check_hdf5_object(path, frames, name, "group") for name in names]
        first = self._frames[0]
        self.kind = "density" if "density" in first else "delta_n"
        self.shape = None
        times, n_refs = [], []
        for name, group in zip(names, self._frames, strict=True):
            self._check_frame(name, group)
            time = _attr(path, group, "time")
            if time is None:
                raise RimclError(f"{path}: frame {name} has no time attribute")
            times.append(real_numbers(path, f"time of frame {name}", time, 1)[0])
            if self.kind == "delta_n":
                n_ref = _attr(path, group[self.kind], "n_ref")
                if n_ref is None:
                    raise RimclError(f"{path}: delta_n of frame {name} has no n_ref attribute")
                n_ref = real_numbers(path, f"n_ref of frame {name}", n_ref, 1)[0]
                if not n_ref > 0:
                    raise RimclError(f"{path}: n_ref of frame {name} must be positive, got {n_ref}")
                n_refs.append(n_ref)
        far_corner = self.origin + self.spacing * np.array(self.shape[::-1], dtype=np.float64)
        if not np.all(np.abs(far_corner) < _LARGEST_COORDINATE):
            raise RimclError(
                f"{path}: the grid (origin {self.origin.tolist()}, spacing "
                f"{self.spacing.tolist()}) reaches {far_corner.tolist()}, beyond the "
                f"coordinates rimcl can trace (|x| < {_LARGEST_COORDINATE:g})"
            )
        self.times = np.array(times)
        if np.any(np.diff(self.times) <= 0):
            raise RimclError(f"{path}: frame times must increase, got {times}")
        self.n_refs = np.array(n_refs) if n_refs else None
        self.attrs = {}
        for key in h5.attrs:
            self.attrs[key] = _plain_attr(_attr(path, h5, key))

    def _check_frame(self, name, group):
        """Check one frame's arrays (metadata only): kind, shapes and dtypes."""
        path = self.path
        arrays = {}
        for array_name in _FRAME_ARRAYS:
            found = check_hdf5_object(path, group, array_name, "dataset")
            if found is not None:
                arrays[array_name] = found
        if self.kind not in arrays:
            raise RimclError(f"{path}: frame {name} needs a {self.kind} dataset")
        if {"density", "delta_n"} <= set(arrays):
            raise RimclError(f"{path}: frame {name} holds both density and delta_n")
        if self.shape is None:
            self.shape = tuple(int(n) for n in arrays[self.kind].shape)
            if len(self.shape) != 3 or min(self.shape) < 1:
                raise RimclError(
                    f"{path}: {self.kind} must be (n3, n2, n1) with at least one node along "
                    f"each axis, got {self.shape}"
                )
        for array_name, dataset in arrays.items():
            want = (*self.shape, *_FRAME_ARRAYS[array_name])
            if array_name == "density_gradient" and self.kind != "density":
                raise RimclError(f"{path}: frame {name} holds density_gradient with delta_n")
            if dataset.shape != want:
                raise RimclError(
                    f"{path}: frame {name} {array_name} must have shape {want}, got {dataset.shape}"
                )
            if dataset.dtype.kind not in _REAL_KINDS:
                raise RimclError(
                    f"{path}: frame {name} {array_name} must hold real numbers (float or "
                    f"integer), got {dataset.dtype}"
                )

    def close(self):
        """Close the file."""
        self._h5.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc_info):
        self.close()

    @property
    def n_frames(self):
        return len(self._frames)

    @property
    def has_velocity(self):
        """Whether every frame holds a velocity: in full, or on one sheet plane."""
        return self.has_full_velocity or self.velocity_sheet_x1 is not None

    @property
    def has_full_velocity(self):
        """Whether every frame holds the full 3-D ``velocity``."""
        return all("velocity" in group for group in self._frames)

    @functools.cached_property
    def velocity_sheet_x1(self):
        """The ``x1`` of the stored sheet-only velocity (float), or None if there is none.

        Raises RimclError when only some frames hold it, or with different planes or shapes.
        """
        holding = [SHEET_VELOCITY in group for group in self._frames]
        if not any(holding):
            return None
        if not all(holding):
            missing = [g.name for g, has in zip(self._frames, holding, strict=True) if not has]
            raise RimclError(f"{self.path}: {SHEET_VELOCITY} is missing from {missing[0]}")
        planes = set()
        for group in self._frames:
            dataset = group[SHEET_VELOCITY]
            if dataset.shape != (*self.shape[:2], 2):
                raise RimclError(
                    f"{self.path}: {group.name}/{SHEET_VELOCITY} must have shape "
                    f"{(*self.shape[:2], 2)}, got {dataset.shape}"
                )
            if "x1" not in dataset.attrs:
                raise RimclError(f"{self.path}: {group.name}/{SHEET_VELOCITY} has no x1 attribute")
            planes.add(float(dataset.attrs["x1"]))
        if len(planes) > 1:
            raise RimclError(
                f"{self.path}: {SHEET_VELOCITY} lies on different planes x1 = {sorted(planes)}"
            )
        x1 = planes.pop()
        where = f"{self.path}: {SHEET_VELOCITY} x1"
        _check_sheet_x1(x1, self.origin[0], self.spacing[0], self.shape[2], self.boundary, where)
        return x1

    @property
    def has_density_gradient(self):
        """Whether every frame holds a stored density gradient."""
        return all("density_gradient" in group for group in self._frames)

    def _index(self, frame):
        """The stored frame ``frame`` (negative counts from the end) as an index >= 0."""
        index = int(frame)
        if not -self.n_frames <= index < self.n_frames:
            raise RimclError(
                f"{self.path} has frames 0..{self.n_frames - 1}; frame {frame} does not exist"
            )
        return index % self.n_frames

    def _group(self, frame):
        return self._frames[self._index(frame)]

    def _read(self, frame, name, selection=()):
        group = self._group(frame)
        if name not in group:
            raise RimclError(f"{self.path}: frame {group.name} holds no {name}")
        dataset = group[name]
        where = f"{name} of frame {group.name}"
        if not selection:
            check_array_memory(dataset.shape, 4, f"reading {where} of {self.path}", factor=3)
        elif dataset.chunks is not None:
            # HDF5 decompresses whole chunks, however small the part read
            check_array_memory(
                dataset.chunks, dataset.dtype.itemsize, f"one chunk of {where} of {self.path}"
            )
        try:
            values = dataset[selection] if selection else dataset[()]
        except Exception as exc:  # damaged chunks or B-trees surface as several h5py errors
            raise RimclError(
                f"{self.path}: cannot read {where} ({first_line(exc)}); the file is damaged"
            ) from None
        if not np.all(np.isfinite(values)):
            raise RimclError(f"{self.path}: {where} holds NaN or inf")
        return values

    def read_slab(self, frame, name, rows):
        """Rows ``rows`` (a slice along ``x3``) of the array ``name`` of one frame.

        For streaming through frames too large to hold: memory is that of the slab.

        Returns
        -------
        ndarray, shape (rows, n2, n1) or (rows, n2, n1, 3)
        """
        return self._read(frame, name, (rows,))

    def storage(self):
        """What each array of the frames is stored as, and how much of it is on disk.

        Returns
        -------
        dict of str to dict
            Per array name: ``dtype``, ``declared_bytes`` (all frames, uncompressed) and
            ``stored_bytes`` (all frames, as written; far smaller for fill values).
        """
        found = {}
        for group in self._frames:
            for name in _FRAME_ARRAYS:
                if name not in group:
                    continue
                dataset = group[name]
                entry = found.setdefault(
                    name, {"dtype": str(dataset.dtype), "declared_bytes": 0, "stored_bytes": 0}
                )
                entry["declared_bytes"] += int(dataset.size) * dataset.dtype.itemsize
                entry["stored_bytes"] += int(dataset.id.get_storage_size())
        return found

    def density(self, frame):
        """Density of one frame, float32 ``(n3, n2, n1)`` (dimensionless)."""
        if self.kind != "density":
            raise RimclError(f"{self.path} stores delta_n, not density")
        return self._read(frame, "density")

    def delta_n(self, frame):
        """``(δn, n_ref)`` of a file storing ``delta_n``: float32 ``(n3, n2, n1)``, float."""
        if self.kind != "delta_n":
            raise RimclError(f"{self.path} stores density; use field() with a K*rho")
        values = self._read(frame, "delta_n")
        return values, float(self.n_refs[int(frame)])

    def density_gradient(self, frame):
        """Stored ``∇ρ`` of one frame, float32 ``(n3, n2, n1, 3)``, or None if absent."""
        if "density_gradient" not in self._group(frame):
            return None
        return self._read(frame, "density_gradient")

    def velocity(self, frame):
        """Velocity of one frame, float32 ``(n3, n2, n1, 3)``, components along x1, x2, x3."""
        if not self.has_full_velocity and self.velocity_sheet_x1 is not None:
            raise RimclError(
                f"{self.path} stores only the in-plane velocity on the sheet "
                f"x1 = {self.velocity_sheet_x1:g}, not the full velocity"
            )
        return self._read(frame, "velocity")

    def time_weights(self, time, method="auto"):
        """Frames and weights that interpolate the stored frames to ``time``.

        Parameters
        ----------
        time : float
            Within the stored times (no extrapolation).
        method : {"auto", "linear", "cubic"}
            ``cubic`` is a 4-point Lagrange interpolation on the frames around ``time``
            (needs 4 frames); ``auto`` uses it when there are 4 or more frames.

        Returns
        -------
        list of (int, float)
            ``(frame, weight)``; the weights sum to 1. A stored time gives one frame.
        """
        if method not in ("auto", "linear", "cubic"):
            raise RimclError(f"time interpolation must be auto, linear or cubic, not {method!r}")
        time = float(time)
        first, last = self.times[0], self.times[-1]
        slack = _TIME_SLACK * max(last - first, abs(last), 1.0)
        if not first - slack <= time <= last + slack:
            raise RimclError(f"time {time:g} is outside the stored frames ({first:g} .. {last:g})")
        exact = np.flatnonzero(np.abs(self.times - time) <= slack)
        if exact.size:
            return [(int(exact[0]), 1.0)]
        right = int(np.searchsorted(self.times, time))
        cubic = method == "cubic" or (method == "auto" and self.n_frames >= 4)
        if cubic and self.n_frames < 4:
            raise RimclError("cubic time interpolation needs at least 4 frames")
        if not cubic:
            t0, t1 = self.times[right - 1], self.times[right]
            frac = (time - t0) / (t1 - t0)
            return [(right - 1, 1.0 - frac), (right, frac)]
        start = min(max(right - 2, 0), self.n_frames - 4)
        nodes = self.times[start : start + 4]
        weights = []
        for i in range(4):
            others = np.delete(nodes, i)
            weights.append(float(np.prod((time - others) / (nodes[i] - others))))
        return list(zip(range(start, start + 4), weights, strict=True))

    def _blend(self, time, read, method):
        total = None
        for frame, weight in self.time_weights(time, method):
            part = weight * read(frame).astype(np.float64)
            total = part if total is None else total + part
        return total

    def field(self, frame=0, k_rho=None, *, case=None):
        """The refractive-index field of one stored frame.

        Parameters
        ----------
        frame : int
        k_rho : float, optional
            Gladstone–Dale product ``G``; or give ``case`` (``"C0"`` … ``"C4"``).
            Needed for density files, refused for ``delta_n`` files.
        case : str, optional

        Returns
        -------
        rimcl.Field
            ``δn = G (ρ - mean ρ)``, ``n_ref = 1 + G mean ρ``, ``∇n = G ∇ρ`` (stored, or
            computed: spectral for periodic grids, 4th-order differences otherwise).
        """
        index = self._index(frame)
        check_field_memory(self.shape, f"frame {index} of {self.path}")
        attrs = {"frame": index, "time": float(self.times[index])}
        if self.kind == "delta_n":
            self._refuse_case(case, k_rho)
            values, n_ref = self.delta_n(frame)
            return self._make_field(values.astype(np.float64), n_ref, None, attrs)
        density = self.density(frame).astype(np.float64)
        gradient = self.density_gradient(frame)
        return self._density_field(density, gradient, case, k_rho, attrs)

    def field_at(self, time, k_rho=None, *, case=None, method="auto"):
        """The refractive-index field at any ``time`` within the stored frames.

        The density (and its stored gradient, or ``δn`` and ``n_ref``) is interpolated in
        time between frames (see :meth:`time_weights`); arguments as :meth:`field`.

        Returns
        -------
        rimcl.Field
        """
        weights = self.time_weights(time, method)
        if len(weights) == 1:
            return self.field(weights[0][0], k_rho, case=case)
        check_field_memory(self.shape, f"time {float(time):g} of {self.path}")
        attrs = {"time": float(time), "frames": [f for f, _ in weights]}
        if self.kind == "delta_n":
            self._refuse_case(case, k_rho)
            values = self._blend(time, lambda f: self.delta_n(f)[0], method)
            n_ref = sum(w * self.delta_n(f)[1] for f, w in weights)
            return self._make_field(values, n_ref, None, attrs)
        density = self._blend(time, self.density, method)
        gradient = None
        if self.has_density_gradient:
            gradient = self._blend(time, self.density_gradient, method)
        return self._density_field(density, gradient, case, k_rho, attrs)

    def velocity_at(self, time, method="auto"):
        """Velocity at ``time`` (interpolated between frames), float64 ``(n3, n2, n1, 3)``."""
        # float64 result, a float64 term and the float32 frame: 60 bytes per node
        check_array_memory((*self.shape, 3), 20, f"velocity at time {float(time):g} of {self.path}")
        return self._blend(time, self.velocity, method)

    def sheet_velocity(self, time, x1, method="auto"):
        """In-plane velocity ``(u2, u3)`` on the light sheet ``x1 = const``.

        Linear in ``x1`` between the two nearest node planes, interpolated in time between
        frames. Only the two planes are read from the file (and cached).

        Parameters
        ----------
        time : float
        x1 : float
            Sheet position (length units); inside the grid unless the field is periodic.
        method : {"auto", "linear", "cubic"}
            Time interpolation.

        Returns
        -------
        ndarray, float64, shape (n3, n2, 2)
            ``u2, u3`` at the nodes ``(x3, x2)`` of the sheet.

        Notes
        -----
        A file that stores only ``velocity_sheet`` gives the stored plane (interpolated in
        time) and refuses any other ``x1``.
        """
        if not self.has_full_velocity and self.velocity_sheet_x1 is not None:
            return self._stored_sheet_velocity(time, x1, method)
        n1 = self.shape[2]
        position = (float(x1) - self.origin[0]) / self.spacing[0]
        if self.boundary == "periodic":
            position %= n1
            below = min(math.floor(position), n1 - 1)
            above = (below + 1) % n1
        else:
            tolerance = 1e-9 * max(n1, 1)
            if not -tolerance <= position <= n1 - 1 + tolerance:
                hi = self.origin[0] + (n1 - 1) * self.spacing[0]
                raise RimclError(
                    f"sheet x1 = {x1:g} is outside the field ({self.origin[0]:g} .. {hi:g})"
                )
            position = min(max(position, 0.0), n1 - 1.0)
            below = min(math.floor(position), max(n1 - 2, 0))
            above = min(below + 1, n1 - 1)
        frac = position - below

        def plane(frame):
            lower, upper = self._sheet_planes(frame, below, above)
            return (1.0 - frac) * lower + frac * upper

        return self._blend(time, plane, method)

    def _stored_sheet_velocity(self, time, x1, method):
        """:meth:`sheet_velocity` from the stored ``velocity_sheet`` plane."""
        stored = self.velocity_sheet_x1
        offset = float(x1) - stored
        if self.boundary == "periodic":
            period = self.shape[2] * self.spacing[0]
            offset -= period * round(offset / period)
        # a millionth of a cell: the same plane written and asked for in different roundings
        if not abs(offset) <= 1e-6 * self.spacing[0]:
            raise RimclError(
                f"{self.path} stores the sheet velocity only on x1 = {stored:g}, "
                f"not on x1 = {float(x1):g}; put the sheet there or use a file with full velocity"
            )
        return self._blend(time, lambda frame: self._read(frame, SHEET_VELOCITY), method)

    def _sheet_planes(self, frame, below, above):
        """The velocity planes ``(u2, u3)`` at x1 nodes ``below`` and ``above``, cached."""
        frame = int(frame) % self.n_frames
        stale = [key for key in self._plane_cache if key[1] not in (below, above)]
        for key in stale:
            del self._plane_cache[key]
        planes = []
        for node in (below, above):
            if (frame, node) not in self._plane_cache:
                selection = (slice(None), slice(None), node, slice(1, 3))
                values = self._read(frame, "velocity", selection)
                self._plane_cache[frame, node] = values.astype(np.float64)
            planes.append(self._plane_cache[frame, node])
        return planes

    @staticmethod
    def _refuse_case(case, k_rho):
        if case is not None or k_rho is not None:
            raise RimclError("this file stores delta_n directly; a case or K*rho does not apply")

    def _density_field(self, density, gradient, case, k_rho, attrs):
        name, g = resolve_k_rho(case, k_rho)
        mean = float(np.mean(density))
        attrs.update(case=name, k_rho=g, density_mean=mean)
        grad_n = None if gradient is None else g * np.asarray(gradient, dtype=np.float64)
        return self._make_field(g * (density - mean), 1.0 + g * mean, grad_n, attrs)

    def _make_field(self, delta_n, n_ref, gradient, attrs):
        attrs = {"source": str(self.path), **attrs}
        return Field.from_arrays(
            delta_n,
            spacing=self.spacing,
            origin=self.origin,
            n_ref=n_ref,
            gradient=gradient,
            boundary=self.boundary,
            attrs=attrs,
        )


def field_kind(path):
    """What a field file stores, ``"density"`` or ``"delta_n"`` (metadata only)."""
    with FieldFile(path) as ff:
        return ff.kind


#: The Gladstone–Dale case of a density file when none is given (air).
DEFAULT_CASE = "C1"


def case_arguments(path=None, case=None, k_rho=None):
    """The ``case`` and ``k_rho`` to use with a field file, from its metadata.

    A file storing ``delta_n`` carries its own refractive index and takes neither (giving
    one is refused); a density file takes the given case or ``K*rho``, else
    :data:`DEFAULT_CASE`.

    Parameters
    ----------
    path : str or Path, optional
        Field file; None is the shipped sample.
    case : str, optional
    k_rho : float, optional

    Returns
    -------
    case, k_rho : str or None, float or None
    """
    if path is None:
        from rimcl.fields.sample import sample_path

        path = sample_path()
    if field_kind(path) == "delta_n":
        if case is not None or k_rho is not None:
            raise RimclError(
                f"{path} stores delta_n (its own refractive index); a case or K*rho does not apply"
            )
        return None, None
    if case is None and k_rho is None:
        return DEFAULT_CASE, None
    return case, k_rho


def load_field(path=None, frame=0, *, k_rho=None, case=None, time=None):
    """Load one frame (or a time between frames) of a field file as a :class:`rimcl.Field`.

    Parameters
    ----------
    path : str or Path, optional
        A rimcl field file; None loads the shipped sample (:func:`rimcl.flow.sample_path`).
    frame : int
        Stored frame (ignored when ``time`` is given).
    k_rho : float, optional
        Gladstone–Dale product ``G``; or give ``case``. Needed for density files.
    case : str, optional
        ``"C0"`` … ``"C4"`` (see :data:`rimcl.fields.cases.CASES`).
    time : float, optional
        Interpolate in time between stored frames (linear; cubic with 4+ frames).

    Returns
    -------
    rimcl.Field
    """
    if path is None:
        from rimcl.fields.sample import sample_path

        path = sample_path()
    with FieldFile(path) as ff:
        if time is not None:
            return ff.field_at(time, k_rho, case=case)
        return ff.field(frame, k_rho, case=case)
