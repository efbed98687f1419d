"""Named dimensions and units on rimcl's HDF5 tables and PIV grids, so that
``xarray.open_dataset`` reads them (netCDF-4 conventions: HDF5 dimension scales, ``units``
and ``coordinates`` attributes).

A per-tracer table of several frames (one row per tracer and frame, frame-major) is written
by :func:`write_tracer_table` as ``(id, frame)`` datasets: ``xarray.open_dataset(path,
group="tracers", engine="h5netcdf")["x2_meas"]`` is then an ``(id, frame)`` array, with
``time`` a coordinate along ``frame``. :func:`read_table` gives any table back as 1-D
frame-major columns, whichever layout it was written in. Other tables (one row per ray) are
labelled by :func:`label_table`: a column of unique values becomes the dimension, else an
added ``row`` scale with the key columns named as coordinates.
"""

import numpy as np

#: The dimension added to a table without a unique index (not a column of the table).
ROW_DIMENSION = "row"
#: Columns that identify a row, named as coordinates of the others.
KEY_COLUMNS = ("id", "frame", "time")
#: Dimensions of a per-tracer table, in the order of its 2-D datasets.
TRACER_DIMENSIONS = ("id", "frame")
#: Columns of a per-tracer table that hold one value per frame (stored along ``frame``).
PER_FRAME_COLUMNS = ("time",)


def unit_of(name, length_unit="L0", time_unit="T0"):
    """The ``units`` text of a render-table column, from its name."""
    stem = name.split("_")[0]
    if stem in ("x2", "x3", "x", "y", "fov", "theta0") or name in ("path_length", "displacement"):
        return "rad" if stem == "theta0" else length_unit
    if stem in ("u2", "u3"):
        return f"{length_unit}/{time_unit}"
    if stem in ("a2", "a3"):
        return f"{length_unit}/{time_unit}^2"
    if name == "time":
        return time_unit
    if stem in ("dx", "dy"):
        return "px"
    if stem == "area":
        return "px^2"
    if stem == "perimeter":
        return "px"
    if name == "deflection":
        return "rad"
    return "1"


def label_table(group, index=None, units=None, row_name=ROW_DIMENSION):
    """Attach a dimension to every dataset of a table group and write their units.

    Parameters
    ----------
    group : h5py.Group
        1-D datasets of one length.
    index : str, optional
        A column whose values are unique: it becomes the dimension (else a ``row`` scale
        is added and the key columns become coordinates).
    units : callable, optional
        Column name to its ``units`` text (default :func:`unit_of`).
    row_name : str
        Name of the added dimension of a table without a unique index.
    """
    names = [name for name in group if group[name].ndim == 1]
    if not names:
        return
    length = group[names[0]].shape[0]
    names = [name for name in names if group[name].shape[0] == length]
    unique = index in names and np.unique(group[index][()]).size == length
    if unique:
        scale_name = index
    else:
        scale_name = row_name
        if scale_name in group:  # a table with a column of that name: leave it unlabelled
            return
        group.create_dataset(scale_name, data=np.arange(length, dtype=np.int64))
    scale = group[scale_name]
    scale.make_scale(scale_name)
    keys = [k for k in KEY_COLUMNS if k in names and k != scale_name]
    units = units or unit_of
    for name in names:
        if name == scale_name:
            continue
        dataset = group[name]
        dataset.dims[0].attach_scale(scale)
        dataset.attrs["units"] = units(name)
        if name not in keys and keys:
            dataset.attrs["coordinates"] = " ".join(keys)


def si_per_unit(length_m=None, time_s=None):
    """The SI value (m, s, m/s, m/s²) of one of the units ``L0``, ``T0``, ``L0/T0`` and
    ``L0/T0^2``, for those the scales give.

    Parameters
    ----------
    length_m, time_s : float, optional
        Metres per field length unit ``L0``, seconds per field time unit ``T0``.

    Returns
    -------
    dict of str to float
    """
    found = {"L0": length_m, "T0": time_s}
    if length_m is not None and time_s is not None:
        found.update({"L0/T0": length_m / time_s, "L0/T0^2": length_m / time_s**2})
    return {unit: float(value) for unit, value in found.items() if value is not None}


def mark_si(group, factors):
    """Write ``si_per_unit`` on each dataset of ``group`` whose ``units`` is in ``factors``
    (:func:`si_per_unit`): ``value × si_per_unit`` is then in SI."""
    for dataset in group.values():
        if hasattr(dataset, "dtype") and dataset.attrs.get("units") in factors:
            dataset.attrs["si_per_unit"] = factors[dataset.attrs["units"]]


def add_scale(group, name, values, units="1"):
    """A 1-D dataset of ``group`` made a dimension scale of its own name, with units.

    Text values are stored as UTF-8 strings (xarray reads them as ``str``).

    Returns
    -------
    h5py.Dataset
    """
    import h5py

    values = np.asarray(values)
    if values.dtype.kind == "U":
        values = values.astype(h5py.string_dtype())
    scale = group.create_dataset(name, data=values)
    scale.make_scale(name)
    scale.attrs["units"] = units
    return scale


def write_variable(group, name, values, dimensions, units, **options):
    """A dataset of ``group`` whose axes are the group's scales named in ``dimensions``.

    ``options`` go to ``h5py.Group.create_dataset`` (compression, ...).

    Returns
    -------
    h5py.Dataset
    """
    dataset = group.create_dataset(name, data=values, **options)
    for axis, dimension in enumerate(dimensions):
        dataset.dims[axis].attach_scale(group[dimension])
    dataset.attrs["units"] = units
    return dataset


def _rectangle(table):
    """``(ids, frames)`` of a frame-major table holding every tracer at every frame
    (``id = tile(ids, F)``, ``frame = repeat(frames, N)``, ids unique), else None."""
    if "id" not in table or "frame" not in table:
        return None
    ids, frames = np.asarray(table["id"]), np.asarray(table["frame"])
    if ids.ndim != 1 or ids.shape != frames.shape or ids.size == 0:
        return None
    _, first = np.unique(frames, return_index=True)
    frame_values = frames[np.sort(first)]
    count = ids.size // frame_values.size
    if count * frame_values.size != ids.size:
        return None
    tracer_ids = ids[:count]
    if (
        np.unique(tracer_ids).size != count
        or not np.array_equal(ids, np.tile(tracer_ids, frame_values.size))
        or not np.array_equal(frames, np.repeat(frame_values, count))
    ):
        return None
    return tracer_ids, frame_values


def write_tracer_table(group, table, units=None):
    """Write a per-tracer table as ``(id, frame)`` datasets with dimension scales and units.

    A table that does not hold every tracer at every frame (frame-major) is written as
    1-D columns labelled by :func:`label_table` instead.

    Parameters
    ----------
    group : h5py.Group
        An empty group.
    table : dict of str to ndarray, 1-D
        One row per tracer and frame, frame-major (all tracers of the first frame first),
        with ``id`` and ``frame`` columns.
    units : callable, optional
        Column name to its ``units`` text (default :func:`unit_of`).
    """
    units = units or unit_of
    shape = _rectangle(table)
    if shape is None:
        for name, values in table.items():
            group.create_dataset(name, data=values)
        label_table(group, "id", units)
        return
    tracer_ids, frame_values = shape
    count, frames = tracer_ids.size, frame_values.size
    for name, values in zip(TRACER_DIMENSIONS, (tracer_ids, frame_values), strict=True):
        add_scale(group, name, values, units(name))
    per_frame = []
    for name, values in table.items():
        if name in TRACER_DIMENSIONS:
            continue
        grid = np.asarray(values).reshape(frames, count).T  # (id, frame)
        if name in PER_FRAME_COLUMNS and np.array_equal(grid, np.repeat(grid[:1], count, 0)):
            write_variable(group, name, grid[0], ("frame",), units(name))
            per_frame.append(name)
        else:
            write_variable(group, name, grid, TRACER_DIMENSIONS, units(name))
    for name in group:
        if name not in TRACER_DIMENSIONS and name not in per_frame and per_frame:
            group[name].attrs["coordinates"] = " ".join(per_frame)


def read_table(group, names=None):
    """The columns of a table group as 1-D arrays, frame-major, in either layout.

    ``(id, frame)`` datasets (:func:`write_tracer_table`) are flattened to one row per
    tracer and frame, with ``id``, ``frame`` and per-frame columns repeated to match; a
    1-D table is read as it is, without an added ``row`` scale.

    Parameters
    ----------
    group : h5py.Group
    names : iterable of str, optional
        Read only these columns (those the group holds); default all.

    Returns
    -------
    dict of str to ndarray, 1-D
    """
    every = {name: group[name] for name in group}
    wanted = every if names is None else {n: every[n] for n in names if n in every}
    if "id" not in every or not any(dataset.ndim == 2 for dataset in every.values()):
        return {
            name: np.asarray(dataset[()])
            for name, dataset in wanted.items()
            if not (name == ROW_DIMENSION and dataset.is_scale)
        }
    count = int(every["id"].shape[0])
    frames = int(every["frame"].shape[0]) if "frame" in every else 1
    columns = {}
    for name, dataset in wanted.items():
        values = np.asarray(dataset[()])
        if name == "id":
            columns[name] = np.tile(values, frames)
        elif values.ndim == 1:  # the frame scale and per-frame columns
            columns[name] = np.repeat(values, count)
        else:
            columns[name] = values.T.reshape(-1)
    return columns


def label_grid(group, rows, columns, units):
    """Attach ``(row, column)`` dimensions to the 2-D datasets of a group (a PIV vector
    grid), with the given 1-D coordinate values, and write their units.

    Parameters
    ----------
    group : h5py.Group
    rows, columns : ndarray, 1-D
        Coordinates along the grid's first and second axis (``row`` and ``column``).
    units : callable
        Column name to its ``units`` text; the scales get ``units(name)`` of their name.
    """
    if "row" in group or "column" in group:
        return
    add_scale(group, "row", rows, units("row"))
    add_scale(group, "column", columns, units("column"))
    shape = (len(rows), len(columns))
    for name in group:
        dataset = group[name]
        if dataset.shape != shape or name in ("row", "column"):
            continue
        for axis, scale in enumerate(("row", "column")):
            dataset.dims[axis].attach_scale(group[scale])
        dataset.attrs["units"] = units(name)
