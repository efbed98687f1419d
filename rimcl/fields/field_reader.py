"""Reading a rimcl field file (:class:`FieldFile`): the layout checked on opening, frames
read on demand, interpolated in time and turned into refractive-index fields.

The layout is described in :mod:`rimcl.fields.field_layout`.
"""

import functools
import math
from pathlib import Path

import h5py
import numpy as np

from rimcl.core.errors import RimclError, first_line
from rimcl.core.memory import check_array_memory, check_field_memory
from rimcl.fields.cases import resolve_k_rho
from rimcl.fields.field import BOUNDARIES, Field
from rimcl.fields.field_layout import (
    REAL_KINDS,
    SCHEMA,
    SCHEMA_VERSION,
    SHEET_VELOCITY,
    check_hdf5_object,
    check_sheet_x1,
    plain_attr,
    read_attr,
    real_numbers,
    text_attr,
)

# relative slack on times at the ends of the stored range (rounding of t0 + k dt)
_TIME_SLACK = 1e-9

#: Largest grid coordinate: the float32 kernels square lengths (float32 overflows above
#: 3.4e38), and rays through grids of spacing 1e20 already come out NaN.
_LARGEST_COORDINATE = 1e18
#: Arrays of a frame: name -> trailing shape after (n3, n2, n1).
_FRAME_ARRAYS = {"density": (), "delta_n": (), "density_gradient": (3,), "velocity": (3,)}


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
        schema = plain_attr(read_attr(path, h5, "rimcl_schema"))
        if schema != SCHEMA:
            raise RimclError(
                f"{path} is not a rimcl field file (rimcl_schema = {schema!r}); "
                "import flow data with 'rimcl field import'"
            )
        version = read_attr(path, h5, "schema_version")
        version = -1 if version is None else plain_attr(version)
        if version != SCHEMA_VERSION:
            raise RimclError(f"{path}: field schema version {version!r} is not supported")
        grid = check_hdf5_object(path, h5, "grid", "group")
        frames = check_hdf5_object(path, h5, "frames", "group")
        if grid is None or frames is None:
            raise RimclError(f"{path}: a field file needs the groups 'grid' and 'frames'")
        for name in ("origin", "spacing"):
            if read_attr(path, grid, name) is None:
                raise RimclError(f"{path}: grid needs attributes origin and spacing")
        self.origin = real_numbers(path, "grid origin", read_attr(path, grid, "origin"), 3)
        self.spacing = real_numbers(path, "grid spacing", read_attr(path, grid, "spacing"), 3)
        if not np.all(self.spacing > 0):
            raise RimclError(f"{path}: grid spacing must be positive, got {self.spacing.tolist()}")
        self.boundary = text_attr(path, grid, "boundary", "clamp")
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
            time = read_attr(path, group, "time")
            if time is None:
                raise RimclError(f"{path}: frame {name} has no time attribute")
            times.append(real_numbers(path, f"time of frame {name}", time, 1)[0])
            if self.kind == "delta_n":
                n_ref = read_attr(path, group[self.kind], "n_ref")
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
            self.attrs[key] = plain_attr(read_attr(path, h5, key))

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
            if dataset.dtype.kind not in REAL_KINDS:
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
        check_sheet_x1(x1, self.origin[0], self.spacing[0], self.shape[2], self.boundary, where)
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


def recorded_scales(path):
    """``length_m`` and ``time_s`` a field file records (nothing for a missing or foreign
    file: its errors come where it is opened)."""
    if not path or not Path(path).is_file():
        return {}
    try:
        with h5py.File(path, "r") as h5:
            found = {key: float(h5.attrs[key]) for key in ("length_m", "time_s") if key in h5.attrs}
    except (OSError, TypeError, ValueError):
        return {}
    return {k: v for k, v in found.items() if math.isfinite(v) and v > 0}
