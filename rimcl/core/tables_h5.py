"""Named dimensions and units on rimcl's HDF5 tables and PIV grids, so that
``xarray.open_dataset`` reads them (netCDF-4 conventions: HDF5 dimension scales, ``units``
and ``coordinates`` attributes).

A table is a group of 1-D datasets of one length. :func:`label_table` makes its index column
a dimension scale when its values are unique (``id`` of a per-tracer table, ``ray``), and
otherwise adds a ``row`` scale with the key columns (``id``, ``frame``, ``time``) named as
coordinates: ``xarray.open_dataset(path, group="tracers").set_index(row=["id", "frame"])
.unstack("row")`` then gives ``(id, frame)`` arrays. Readers that take columns by name are
unaffected.
"""

import numpy as np

#: The dimension added to a table without a unique index (not a column of the table).
ROW_DIMENSION = "row"
#: Columns that identify a row, named as coordinates of the others.
KEY_COLUMNS = ("id", "frame", "time")


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
    scales = []
    for name, values in (("row", rows), ("column", columns)):
        if name in group:
            return
        group.create_dataset(name, data=np.asarray(values))
        group[name].make_scale(name)
        group[name].attrs["units"] = units(name)
        scales.append(group[name])
    shape = (len(rows), len(columns))
    for name in group:
        dataset = group[name]
        if dataset.shape != shape or name in ("row", "column"):
            continue
        for axis, scale in enumerate(scales):
            dataset.dims[axis].attach_scale(scale)
        dataset.attrs["units"] = units(name)
