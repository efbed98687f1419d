"""Zarr stores as input of :mod:`rimcl.fields.cf_import`, read through xarray's Zarr backend
(``xarray.open_zarr``) where xarray and zarr are installed (neither is a dependency of rimcl).

The variables come back undecoded (``decode_cf=False``): the importer applies CF packing
(``_FillValue``, ``scale_factor``, ``add_offset``) and reads the units itself, as it does for
a netCDF-4 file, so a Zarr store and the netCDF file it was written from import alike.
"""

import warnings
from pathlib import Path

import numpy as np

from rimcl.core.errors import RimclError, first_line

#: Files that mark a directory as a Zarr store (format 2: ``.zgroup``...; format 3:
#: ``zarr.json``).
_MARKERS = (".zgroup", ".zattrs", ".zmetadata", "zarr.json")


def is_zarr_store(path):
    """Whether ``path`` is a Zarr store: a directory named ``*.zarr`` or holding Zarr
    metadata."""
    path = Path(path)
    return path.is_dir() and (
        path.suffix.lower() == ".zarr" or any((path / name).is_file() for name in _MARKERS)
    )


def zarr_variables(path):
    """The numeric variables of a Zarr store, undecoded.

    Parameters
    ----------
    path : str or Path

    Returns
    -------
    dict of str to (tuple of str, dict, tuple of int, callable)
        Per variable its dimension names, attributes (with ``_FillValue`` where the store
        gives one), shape, and a reader ``read(selection=())`` of its raw values.

    Raises
    ------
    RimclError
        Without xarray or zarr installed, or for a store xarray cannot open.
    """
    try:
        import xarray as xr
        import zarr  # noqa: F401  (xarray's Zarr backend needs it)
    except ImportError:
        raise RimclError(
            f"{path} is a Zarr store: reading it needs xarray and zarr "
            "(pip install xarray zarr), or convert it to netCDF-4 with "
            "xarray.open_zarr(...).to_netcdf(...)"
        ) from None
    try:
        # a store without consolidated metadata (RuntimeWarning), or a format-3 store with it
        # (zarr's warning that it is no part of the format), opens alike
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            dataset = xr.open_zarr(path, decode_cf=False, chunks=None)
    except Exception as exc:  # zarr and xarray raise many types for a bad store
        raise RimclError(f"{path} is not a readable Zarr store ({first_line(exc)})") from None
    variables = {}
    for name, variable in dataset.variables.items():
        if variable.dtype.kind not in "fiu":
            continue
        attrs = dict(variable.attrs)
        fill = variable.encoding.get("_FillValue", attrs.get("_FillValue"))
        if fill is not None:
            attrs["_FillValue"] = fill

        def read(selection=(), variable=variable, name=name):
            try:
                return np.asarray(variable[selection].values if selection else variable.values)
            except Exception as exc:
                raise RimclError(
                    f"{path}: cannot read {name} ({first_line(exc)}); the store is damaged"
                ) from None

        variables[str(name)] = (tuple(map(str, variable.dims)), attrs, variable.shape, read)
    return variables
