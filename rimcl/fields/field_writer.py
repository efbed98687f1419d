"""Writing a rimcl field file (:func:`write_field`), atomically and stamped with provenance.

The layout is described in :mod:`rimcl.fields.field_layout`. Every frame group also holds
HDF5 dimension scales (:func:`attach_scales`: coordinates ``x1``, ``x2``, ``x3``, the frame's
``time``, the vector ``component``), so that ``xarray.open_dataset(path,
group="frames/0000", engine="h5netcdf")`` gives named dimensions with units; rimcl's own
reader ignores them. :func:`label_field_file` adds them to a file written without them.
"""

import json
import shutil
from pathlib import Path

import h5py
import numpy as np

from rimcl.core.atomic import atomic_path
from rimcl.core.errors import RimclError
from rimcl.core.provenance import stamp_h5, versions
from rimcl.core.tables_h5 import add_scale
from rimcl.fields.field import BOUNDARIES
from rimcl.fields.field_layout import SCHEMA, SCHEMA_VERSION, SHEET_VELOCITY, check_sheet_x1
from rimcl.fields.field_reader import FieldFile


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
        check_sheet_x1(sheet_x1, origin[0], spacing[0], shape[2], boundary, "sheet_x1")
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
        attach_scales(h5)
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


#: Dimensions of a frame's arrays, in the order of their axes.
_DIMENSIONS = {
    "density": ("x3", "x2", "x1"),
    "delta_n": ("x3", "x2", "x1"),
    "density_gradient": ("x3", "x2", "x1", "component"),
    "velocity": ("x3", "x2", "x1", "component"),
    SHEET_VELOCITY: ("x3", "x2", "sheet_component"),
}
#: Labels of the vector components (the trailing axis of vectors and of the sheet velocity).
_COMPONENTS = {"component": ["x1", "x2", "x3"], "sheet_component": ["x2", "x3"]}
#: Units of the scales' text when the file records no physical scale.
FIELD_LENGTH_UNITS = "field length units"
FIELD_TIME_UNITS = "field time units"


def _scale_text(value):
    """A physical scale as the shortest text that reads back as the same float."""
    return repr(float(value))


def unit_texts(length_m=None, time_s=None):
    """The ``units`` attributes of a field file's coordinates and arrays.

    Parameters
    ----------
    length_m, time_s : float, optional
        Metres per field length unit and seconds per field time unit (the file's root
        attributes); without them the units are the field's own.

    Returns
    -------
    dict of str to str
        ``length``, ``time``, ``velocity``, ``gradient`` (of the density) and
        ``dimensionless``: e.g. ``"0.3 m"`` (a value in field units times 0.3 is metres),
        ``"0.6 m/s"``, else ``"field length units"``.
    """
    length = FIELD_LENGTH_UNITS if length_m is None else f"{_scale_text(length_m)} m"
    time = FIELD_TIME_UNITS if time_s is None else f"{_scale_text(time_s)} s"
    if length_m is not None and time_s is not None:
        velocity = f"{_scale_text(length_m / time_s)} m/s"
    else:
        velocity = f"({length})/({time})"
    gradient = f"1/({length})" if length_m is None else f"{_scale_text(1 / length_m)} m^-1"
    return {
        "length": length,
        "time": time,
        "velocity": velocity,
        "gradient": gradient,
        "dimensionless": "1",
    }


def _physical_scale(h5, name):
    """A positive finite root attribute ``length_m``/``time_s``, else None."""
    try:
        value = float(h5.attrs[name])
    except (KeyError, TypeError, ValueError):
        return None
    return value if np.isfinite(value) and value > 0 else None


def attach_scales(h5):
    """Give every frame of an open field file dimension scales and units (for xarray).

    Each frame group gets the coordinates ``x1``, ``x2``, ``x3`` (``origin + i spacing``,
    float64, length units), a scalar ``time`` (time units, named as a coordinate of the
    arrays), and ``component`` (``x1, x2, x3``) and ``sheet_component`` (``x2, x3``)
    labels where a vector is stored; every array gets its dimensions and ``units``. A
    frame that already holds an ``x1`` is left as it is. The arrays' values are untouched.

    Parameters
    ----------
    h5 : h5py.File
        A field file open for writing, with its ``grid`` and ``frames``.
    """
    origin = np.asarray(h5["grid"].attrs["origin"], dtype=np.float64)
    spacing = np.asarray(h5["grid"].attrs["spacing"], dtype=np.float64)
    units = unit_texts(_physical_scale(h5, "length_m"), _physical_scale(h5, "time_s"))
    array_units = {
        "density": units["dimensionless"],
        "delta_n": units["dimensionless"],
        "density_gradient": units["gradient"],
        "velocity": units["velocity"],
        SHEET_VELOCITY: units["velocity"],
    }
    for group in h5["frames"].values():
        if "x1" in group:
            continue
        arrays = [name for name in _DIMENSIONS if name in group]
        scalar = group["density" if "density" in group else "delta_n"]
        n3, n2, n1 = scalar.shape
        for axis, count in (("x1", n1), ("x2", n2), ("x3", n3)):
            k = int(axis[1]) - 1
            add_scale(group, axis, origin[k] + spacing[k] * np.arange(count), units["length"])
        for name, labels in _COMPONENTS.items():
            if any(name in _DIMENSIONS[array] for array in arrays):
                add_scale(group, name, labels)
        group.create_dataset("time", data=np.float64(group.attrs["time"]))
        group["time"].attrs["units"] = units["time"]
        for name in arrays:
            dataset = group[name]
            for axis, dimension in enumerate(_DIMENSIONS[name]):
                dataset.dims[axis].attach_scale(group[dimension])
            dataset.attrs["units"] = array_units[name]
            dataset.attrs["coordinates"] = "time"


def label_field_file(path):
    """Add the dimension scales of :func:`attach_scales` to a field file written without
    them (atomically: a copy is labelled, then renamed onto the file).

    The arrays are not rewritten: their stored bytes, and all that
    :class:`rimcl.fields.field_reader.FieldFile` reads, stay the same. The root attribute
    ``dimension_scales`` records when and with which software the scales were added.

    Parameters
    ----------
    path : str or Path
        A rimcl field file.

    Returns
    -------
    bool
        Whether scales were added (False: every frame had them already).
    """
    path = Path(path)
    with FieldFile(path):  # refuses a foreign or damaged file with one line
        pass
    with h5py.File(path, "r") as h5:
        if all("x1" in group for group in h5["frames"].values()):
            return False
    with atomic_path(path, overwrite=True) as tmp:
        shutil.copyfile(path, tmp)
        with h5py.File(tmp, "r+") as h5:
            attach_scales(h5)
            h5.attrs["dimension_scales"] = json.dumps(
                {"added_by": "rimcl.fields.field_writer.label_field_file", "versions": versions()}
            )
    return True
