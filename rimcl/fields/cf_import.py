"""Import of your own flow: CF-convention netCDF-4/HDF5 datasets, Zarr stores (where xarray
and zarr are installed: :mod:`rimcl.fields.zarr_input`) and ``.npz`` files of any scalar that
sets the refractive index.

The scalar is a density, temperature, salinity, refractive index or index difference δn,
found by name, by its CF ``standard_name`` or named by the caller; its ``units`` attribute
(K, degC, kg m-3, g/kg, 1, ...: :mod:`rimcl.fields.cf_units`, through cf-units) says how to
read it, and a temperature, salinity or density without one is refused. Temperature and
salinity become a refractive index through :mod:`rimcl.fields.media` (the fluid named at
import, at its wavelength), so the field file stores ``delta_n`` and runs "as is"; a density stays a
density (``ρ / 1000 kg m-3`` when given in kg m-3, so that the water case C4, ``G = 0.334``,
is water's Gladstone–Dale product). Each file records what its scalar was (root attribute
``scalar``), so that a case is never applied to a scalar it does not fit.

Axes: every spatial dimension gets a letter ``x, y, z`` from its coordinate's ``axis`` or
``standard_name`` attribute, else from its name, else from its place (the last is ``x``).
The caller names the camera's depth axis; it becomes ``x1``, and the two others become
``x2`` (the faster-varying in the file) and ``x3``. Velocity components (``u, v, w``, CF
``*_x_velocity`` names or one ``velocity`` array with a trailing component axis of 3) are
permuted alike; two candidates for one component are refused. A coordinate with
``positive = "down"`` is turned up (values negated, nodes reversed; its velocity component
changes sign unless its ``standard_name`` says upward). Coordinates in any length unit and
times in any time unit (``hours since ...``) give the field's ``length_m`` and ``time_s``
(metres and seconds per field unit), recorded in the file.

``.npz`` files follow the JHTDB convention of :mod:`rimcl.fields.jhtdb` (arrays
``(nz, ny, nx)`` or ``(nt, nz, ny, nx)``, coordinates ``x, y, z`` or ``xcoor, ycoor,
zcoor``, optional ``times``); a 0-d string array ``<name>_units`` gives an array's units.
"""

import dataclasses
import math
import re
import zipfile
from pathlib import Path

import h5py
import numpy as np

from rimcl.core.atomic import check_output
from rimcl.core.errors import RimclError, first_line
from rimcl.core.memory import check_import_memory
from rimcl.fields.cf_units import (
    check_relative_density,
    length_factor,
    scalar_conversion,
    time_factor,
)
from rimcl.fields.cf_velocity import read_velocity, velocity_variables
from rimcl.fields.derivatives import gradient as compute_gradient
from rimcl.fields.field_writer import write_field
from rimcl.fields.jhtdb import (
    JHTDB_PERIOD,
    _boundary,
    _Layout,
    npz_array,
    open_npz,
    parse_frames,
)
from rimcl.fields.media import Fluid
from rimcl.fields.zarr_input import is_zarr_store, zarr_variables

#: What a field file's scalar can be (its root attribute ``scalar``).
QUANTITIES = ("density", "temperature", "salinity", "index", "delta_n")

# CF standard names (and common variable names) of each quantity, most specific first
_STANDARD_NAMES = {
    "temperature": ("sea_water_temperature", "air_temperature", "temperature",
                    "sea_water_potential_temperature", "sea_water_conservative_temperature"),
    "salinity": ("sea_water_salinity", "sea_water_absolute_salinity",
                 "sea_water_practical_salinity", "salinity"),
    "density": ("sea_water_density", "air_density", "density"),
    "index": ("refractive_index",),
}  # fmt: skip
_NAMES = {
    "temperature": ("temperature", "temp", "t", "theta"),
    "salinity": ("salinity", "salt", "s"),
    "density": ("density", "rho"),
    "index": ("refractive_index", "index", "n"),
    "delta_n": ("delta_n", "dn"),
}
_STORED_UNIT = {"temperature": "degC", "salinity": "g/kg", "density": "1 (rho / 1000 kg m-3)",
                "index": "1", "delta_n": "1"}  # fmt: skip
_AXIS_NAMES = {
    "x": ("x", "xc", "xcoor", "x1", "lon", "longitude", "i", "nx"),
    "y": ("y", "yc", "ycoor", "x2", "lat", "latitude", "j", "ny"),
    "z": ("z", "zc", "zcoor", "x3", "depth", "height", "altitude", "k", "nz", "lev", "level"),
}
_AXIS_STANDARD = {"projection_x_coordinate": "x", "longitude": "x", "grid_longitude": "x",
                  "projection_y_coordinate": "y", "latitude": "y", "grid_latitude": "y",
                  "depth": "z", "height": "z", "altitude": "z"}  # fmt: skip
_TIME_NAMES = ("time", "t", "times")
_NETCDF_DIMENSION_ONLY = "This is a netCDF dimension but not a netCDF variable"


@dataclasses.dataclass
class _Variable:
    """One array of a dataset: its dimension names, attributes and a reader."""

    name: str
    dims: tuple
    attrs: dict
    shape: tuple
    read: object  # callable(selection tuple) -> ndarray


def _text(value):
    if isinstance(value, bytes):
        return value.decode("utf-8", "replace")
    if isinstance(value, np.ndarray) and value.dtype.kind in "SUO" and value.size == 1:
        return _text(value.reshape(-1)[0])
    return value if isinstance(value, str) else None


def _norm_unit(units):
    return " ".join(str(units or "").strip().lower().replace("**", "^").split())


# ---------------------------------------------------------------- reading the containers


def _read_h5(path):
    """Variables of a netCDF-4/HDF5 file (root level), with their dimension names."""
    try:
        h5 = h5py.File(path, "r")
    except Exception:
        raise RimclError(
            f"{path} is not a netCDF-4/HDF5 file (netCDF-3 classic cannot be read: convert it "
            "with nccopy -k nc4)"
        ) from None
    variables = {}
    for name, item in h5.items():
        if not isinstance(item, h5py.Dataset) or item.dtype.kind not in "fiu":
            continue
        attrs = {k: _text(v) if _text(v) is not None else v for k, v in item.attrs.items()}
        if str(attrs.get("NAME", "")).startswith(_NETCDF_DIMENSION_ONLY):
            continue  # a dimension without coordinate values
        dims = []
        for k, dim in enumerate(item.dims):
            # a netCDF dimension without values is a scale whose NAME is netCDF's internal
            # note ("This is a netCDF dimension but not ..."): its dataset's name is the
            # dimension's; a dimension without a scale is named by its position
            scale = dim[0].name if len(dim) else None
            label = dim.label or (scale.rsplit("/", 1)[-1] if scale else f"dim{k}")
            dims.append(label.rsplit("/", 1)[-1])
        variables[name] = _Variable(name, tuple(dims), attrs, item.shape, _reader(path, item))
    return h5, variables


def _reader(path, dataset):
    def read(selection=()):
        try:
            values = dataset[selection] if selection else dataset[()]
        except Exception as exc:
            raise RimclError(
                f"{path}: cannot read {dataset.name} ({first_line(exc)}); the file is damaged"
            ) from None
        return _unpack(values, dataset.attrs)

    return read


def _unpack(values, attrs):
    """CF packing: fill values become NaN, then ``scale_factor`` and ``add_offset``."""
    values = np.asarray(values, dtype=np.float64)
    for key in ("_FillValue", "missing_value"):
        if key in attrs:
            values = np.where(values == np.asarray(attrs[key]).reshape(-1)[0], np.nan, values)
    scale = attrs.get("scale_factor")
    offset = attrs.get("add_offset")
    if scale is not None:
        values = values * float(np.asarray(scale).reshape(-1)[0])
    if offset is not None:
        values = values + float(np.asarray(offset).reshape(-1)[0])
    return values


def _read_npz(path):
    """Variables of an ``.npz`` file, dimensions by the JHTDB convention."""
    archive = open_npz(path)
    names = set(archive.files)
    units = {}
    for name in sorted(names):
        if name.endswith("_units"):
            with archive.zip.open(f"{name}.npy") as member:
                value = np.lib.format.read_array(member, allow_pickle=False)
            units[name[: -len("_units")]] = _text(value) or ""
    variables = {}
    for name in sorted(names - {f"{n}_units" for n in units}):
        values = npz_array(archive, path, name)
        if name in ("x", "y", "z", "xcoor", "ycoor", "zcoor", "times", "time"):
            dims = ({"xcoor": "x", "ycoor": "y", "zcoor": "z", "times": "time"}.get(name, name),)
        elif values.ndim in (3, 4):
            dims = (("time",) if values.ndim == 4 else ()) + ("z", "y", "x")
        elif values.ndim == 5 and values.shape[-1] == 3:
            dims = ("time", "z", "y", "x", "component")
        elif values.ndim == 4 and values.shape[-1] == 3:
            dims = ("z", "y", "x", "component")
        else:
            dims = tuple(f"dim{k}" for k in range(values.ndim))
        if name == "velocity" and values.ndim == 4:
            dims = ("z", "y", "x", "component")
        attrs = {"units": units[name]} if name in units else {}
        key = {"xcoor": "x", "ycoor": "y", "zcoor": "z", "times": "time"}.get(name, name)
        variables[key] = _Variable(
            key, dims, attrs, values.shape, lambda sel=(), v=values: np.asarray(v, float)[sel]
        )
    archive.close()
    return variables


# ---------------------------------------------------------------- what is what


def _choose_scalar(variables, variable, quantity, path):
    """The scalar variable and its quantity."""
    if variable is not None:
        if variable not in variables:
            raise RimclError(
                f"{path} has no variable {variable!r} (found: {', '.join(sorted(variables))})"
            )
        return variables[variable], quantity or _quantity_of(variables[variable], path)
    found = []
    for var in variables.values():
        if len([d for d in var.dims if d not in _TIME_NAMES and d != "component"]) != 3:
            continue
        guessed = _quantity_of(var, path, strict=False)
        if guessed is not None and (quantity is None or guessed == quantity):
            found.append((var, guessed))
    if not found:
        raise RimclError(
            f"{path} holds no density, temperature, salinity, refractive index or delta_n "
            f"variable on a 3-D grid (found: {', '.join(sorted(variables)) or 'none'}); "
            "name it with --variable"
        )
    if len(found) > 1:
        names = ", ".join(f"{v.name} ({q})" for v, q in found)
        raise RimclError(f"{path} holds several scalars ({names}); choose one with --variable")
    return found[0]


def _quantity_of(var, path, strict=True):
    standard = str(var.attrs.get("standard_name", "")).lower()
    for quantity, names in _STANDARD_NAMES.items():
        if standard in names:
            return quantity
    name = var.name.lower()
    for quantity, names in _NAMES.items():
        if name in names:
            return quantity
    if strict:
        raise RimclError(
            f"{path}: cannot tell what {var.name!r} is (no known name or standard_name); "
            f"say it with --quantity ({', '.join(QUANTITIES)})"
        )
    return None


def _axis_letters(spatial, variables):
    """Letter ``x, y, z`` of each spatial dimension (in the variable's order)."""
    letters = {}
    for dim in spatial:
        coordinate = variables.get(dim)
        attrs = coordinate.attrs if coordinate is not None else {}
        axis = str(attrs.get("axis", "")).lower()
        letter = axis if axis in ("x", "y", "z") else None
        letter = letter or _AXIS_STANDARD.get(str(attrs.get("standard_name", "")).lower())
        if letter is None:
            letter = next((a for a, names in _AXIS_NAMES.items() if dim.lower() in names), None)
        letters[dim] = letter
    named = [v for v in letters.values() if v]
    if len(named) != len(set(named)):  # two dimensions claim one letter: go by place
        letters = dict.fromkeys(spatial)
    # dimensions left unnamed take the letters left over, the last dimension being x
    free = [a for a in ("z", "y", "x") if a not in letters.values()]
    for dim in spatial:
        if letters[dim] is None:
            letters[dim] = free.pop(0)
    return letters


def _depth_letter(depth_axis, letters, path):
    if depth_axis is None:
        raise RimclError(
            f"name the camera's depth axis with --depth-axis (one of "
            f"{', '.join(f'{d} ({a})' for d, a in letters.items())} in {path})"
        )
    text = str(depth_axis).strip()
    if text in letters:
        return letters[text]
    if text.lower() in ("x", "y", "z"):
        return text.lower()
    raise RimclError(
        f"--depth-axis {depth_axis!r} is not a dimension of the scalar "
        f"({', '.join(f'{d} ({a})' for d, a in letters.items())})"
    )


# ---------------------------------------------------------------- the import


@dataclasses.dataclass
class ImportedScalar:
    """A dataset read into rimcl's axes: the scalar's frames and what they are.

    Attributes
    ----------
    quantity : str
        One of :data:`QUANTITIES` (of the input).
    values : list of ndarray, float64, each (n3, n2, n1)
        In °C, g/kg or dimensionless.
    velocity : list of ndarray, float32, each (n3, n2, n1, 3), or None
        Components along ``x1, x2, x3``, in field length per field time.
    times, origin, spacing : ndarray
    boundary : str
    length_m, time_s : float or None
        Metres per length unit and seconds per time unit, where the file says.
    attrs : dict
    """

    quantity: str
    values: list
    velocity: list | None
    times: np.ndarray
    origin: np.ndarray
    spacing: np.ndarray
    boundary: str
    length_m: float | None
    time_s: float | None
    attrs: dict


def is_cf_input(paths, variable=None):
    """Whether the inputs are for this importer rather than JHTDB cut-outs or a density
    ``.npz`` (:mod:`rimcl.fields.jhtdb`)."""
    paths = [Path(p) for p in paths]
    if variable is not None:
        return True
    if len(paths) != 1:
        return False
    path = paths[0]
    if is_zarr_store(path):
        return True
    if path.suffix.lower() == ".npz":
        if not zipfile.is_zipfile(path):
            return False
        with zipfile.ZipFile(path) as archive:
            names = {n[:-4] for n in archive.namelist()}
        return "density" not in names or any(n in names for n in ("x", "y", "z", "time"))
    try:
        with h5py.File(path, "r") as h5:
            return not any(
                re.match(r"^(density|velocity)_\d+$", name, re.IGNORECASE) for name in h5
            )
    except Exception:
        return False


def read_dataset(
    path,
    *,
    depth_axis=None,
    variable=None,
    quantity=None,
    units=None,
    velocity=None,
    crop=None,
    stride=None,
    frames=None,
    t0=0.0,
    dt=1.0,
    boundary="auto",
    period=JHTDB_PERIOD,
):
    """Read a CF netCDF-4/HDF5 dataset, a Zarr store or an ``.npz`` file into rimcl's axes.

    Parameters
    ----------
    path : str or Path
    depth_axis : str
        Dimension name or axis letter (``x, y, z``) the camera looks along; it becomes ``x1``.
    variable : str, optional
        The scalar's variable (default: the one density, temperature, salinity, index or
        δn variable found by ``standard_name`` or name).
    quantity : str, optional
        What the scalar is (:data:`QUANTITIES`), when its names do not say.
    units : str, optional
        Its units, overriding the ``units`` attribute.
    velocity : str, optional
        ``"u,v,w"``: the velocity variables along ``x, y, z`` (default: found by name).
    crop, stride, frames
        As :func:`rimcl.fields.jhtdb.read_cutouts` (ranges along ``x1, x2, x3``).
    t0, dt : float
        Times of the frames when the file holds none (``t0 + k dt``).
    boundary, period
        As :func:`rimcl.fields.jhtdb.read_cutouts`.

    Returns
    -------
    ImportedScalar
    """
    path = Path(path)
    if not path.exists():
        raise RimclError(f"input file {path} does not exist")
    if quantity is not None and quantity not in QUANTITIES:
        raise RimclError(f"--quantity must be one of {', '.join(QUANTITIES)}, got {quantity!r}")
    handle = None
    if path.suffix.lower() == ".npz":
        variables = _read_npz(path)
    elif is_zarr_store(path):
        variables = {
            name: _Variable(
                name, dims, attrs, shape, lambda sel=(), r=read, a=attrs: _unpack(r(sel), a)
            )
            for name, (dims, attrs, shape, read) in zarr_variables(path).items()
        }
    else:
        handle, variables = _read_h5(path)
    try:
        return _read(path, variables, depth_axis, variable, quantity, units, velocity, crop,
                     stride, frames, t0, dt, boundary, period)  # fmt: skip
    finally:
        if handle is not None:
            handle.close()


def _read(path, variables, depth_axis, variable, quantity, units, velocity, crop, stride,
          frames, t0, dt, boundary, period):  # fmt: skip
    scalar, quantity = _choose_scalar(variables, variable, quantity, path)
    time_dims = [d for d in scalar.dims if d.lower() in _TIME_NAMES or _is_time(variables, d)]
    spatial = [d for d in scalar.dims if d not in time_dims]
    if len(spatial) != 3 or len(time_dims) > 1 or (time_dims and scalar.dims[0] != time_dims[0]):
        raise RimclError(
            f"{path}: {scalar.name} has dimensions {scalar.dims}; rimcl needs (time, a, b, c) "
            "or (a, b, c) with three spatial dimensions"
        )
    letters = _axis_letters(spatial, variables)
    depth = _depth_letter(depth_axis, letters, path)
    # a coordinate with positive = "down" (a depth) is turned up: its values negated and
    # its nodes (and the data along it) reversed, so that rimcl's axes stay right-handed
    down = [d for d in spatial if _positive_down(variables.get(d))]
    others = [letters[d] for d in spatial if letters[d] != depth]
    axes = (depth, others[1], others[0])  # x2: the faster-varying of the two others
    dim_of = {letter: dim for dim, letter in letters.items()}
    counts = dict(zip((letters[d] for d in spatial), scalar.shape[-3:], strict=True))
    layout = _Layout(",".join(axes), crop, stride, counts)
    # order the file's spatial axes as (z, y, x), the layout's input order
    to_zyx = tuple(spatial.index(dim_of[a]) for a in ("z", "y", "x"))
    coordinates, length_m = _coordinates(variables, dim_of, counts, path)
    for dim in down:
        coordinates[letters[dim]] = -coordinates[letters[dim]][::-1]
    origin, spacing, nodes = layout.grid(coordinates)
    n_frames = scalar.shape[0] if time_dims else 1
    times, time_s = _times(variables, time_dims, n_frames, t0, dt, path)
    unit_text = units if units is not None else scalar.attrs.get("units", "")
    # refused before any frame is read: units missing, unknown or of another quantity
    factor, offset = scalar_conversion(
        quantity, unit_text, scalar.name, scalar.attrs.get("standard_name", "")
    )
    wanted = parse_frames(frames)
    wanted = list(range(1, n_frames + 1)) if wanted is None else wanted
    if max(wanted) > n_frames:
        raise RimclError(f"{path} has frames 1..{n_frames}; no frame {max(wanted)}")
    vel = velocity_variables(variables, velocity, path)
    check_import_memory(nodes[::-1], len(wanted), vel is not None, f"importing {path}")
    flip_axes = tuple(spatial.index(d) for d in down)

    def frame_of(var, k):
        selection = (k - 1,) if time_dims else ()
        values = var.read(selection)
        if values.shape != tuple(counts[letters[d]] for d in spatial):
            raise RimclError(f"{path}: {var.name} does not match the grid of {scalar.name}")
        values = np.flip(values, flip_axes) if flip_axes else values
        zyx = np.transpose(values, to_zyx)[layout.selection]
        if not np.all(np.isfinite(zyx)):
            raise RimclError(f"{path}: {var.name} holds NaN, fill or infinite values")
        return zyx

    values = []
    for k in wanted:
        converted = frame_of(scalar, k) * factor + offset
        values.append(np.ascontiguousarray(np.transpose(converted, layout.order)))
    scalar_range = [float(min(v.min() for v in values)), float(max(v.max() for v in values))]
    if quantity == "density":
        check_relative_density(scalar_range, unit_text, scalar.name)
    flow_velocity, velocity_note = None, None
    if vel is not None:
        up = {letters[d] for d in down}
        flow_velocity, velocity_note, time_s = read_velocity(
            variables,
            vel,
            wanted,
            frame_of,
            layout,
            length_m,
            time_s,
            up,
            timed=bool(time_dims) and time_dims[0] in variables and time_s is None,
        )
    attrs = {
        **layout.provenance(_container(path), [path], wanted),
        "axes": ",".join(f"x{k + 1}={dim_of[a]}" for k, a in enumerate(axes)),
        "scalar": quantity,
        "scalar_variable": scalar.name,
        "scalar_units": str(unit_text),
        "scalar_range": scalar_range,
        "scalar_stored_unit": _STORED_UNIT[quantity],
    }
    if velocity_note:
        attrs["velocity_units"] = velocity_note
    if down:
        attrs["turned_up"] = ",".join(down)  # positive = "down" in the input
    for key in ("n_ref", "reference_index"):
        if quantity == "delta_n" and key in scalar.attrs:
            attrs["n_ref"] = float(np.asarray(scalar.attrs[key]).reshape(-1)[0])
    return ImportedScalar(
        quantity=quantity,
        values=values,
        velocity=flow_velocity,
        times=times[[k - 1 for k in wanted]],
        origin=origin,
        spacing=spacing,
        boundary=_boundary(boundary, spacing, nodes, period),
        length_m=length_m,
        time_s=time_s,
        attrs=attrs,
    )


def _container(path):
    if path.suffix.lower() == ".npz":
        return "npz"
    return "CF Zarr store" if is_zarr_store(path) else "CF dataset"


def _positive_down(coordinate):
    """Whether a coordinate variable says its values grow downwards (CF ``positive``)."""
    if coordinate is None:
        return False
    return str(coordinate.attrs.get("positive", "")).strip().lower() == "down"


def _is_time(variables, dim):
    coordinate = variables.get(dim)
    if coordinate is None:
        return False
    attrs = coordinate.attrs
    return (
        str(attrs.get("axis", "")).upper() == "T"
        or str(attrs.get("standard_name", "")).lower() == "time"
        or " since " in _norm_unit(attrs.get("units"))
    )


def _coordinates(variables, dim_of, counts, path):
    """Node coordinates per axis letter and metres per length unit (None: unknown)."""
    coordinates, factors = {}, {}
    for letter, dim in dim_of.items():
        var = variables.get(dim)
        if var is None or len(var.dims) != 1:
            unnamed = dim.startswith("dim") and dim[3:].isdigit()
            raise RimclError(
                f"{path}: axis {letter} "
                + (f"(unnamed dimension {dim[3:]})" if unnamed else f"(dimension {dim!r})")
                + " has no coordinate values; rimcl needs the node positions: a 1-D variable "
                "named after the dimension"
                + (" (name the dimensions)" if unnamed else f" ({dim}, with units)")
            )
        values = var.read(()).reshape(-1)
        if values.size != counts[letter]:
            raise RimclError(
                f"{path}: coordinate {dim} has {values.size} values, not {counts[letter]}"
            )
        coordinates[letter] = values
        factors[letter] = length_factor(var.attrs.get("units"), f"{path}: {dim}")
    known = set(factors.values())
    if None in known:
        return coordinates, None
    if len(known) > 1:  # mixed units: everything in metres
        coordinates = {a: v * factors[a] for a, v in coordinates.items()}
        return coordinates, 1.0
    return coordinates, known.pop()


def _times(variables, time_dims, n_frames, t0, dt, path):
    """Frame times and seconds per time unit (None: unknown)."""
    if time_dims and time_dims[0] in variables:
        var = variables[time_dims[0]]
        times = var.read(()).reshape(-1)
        if times.size != n_frames:
            raise RimclError(f"{path}: {var.name} has {times.size} values for {n_frames} frames")
        return times, time_factor(var.attrs.get("units"), f"{path}: {var.name}")
    return t0 + dt * np.arange(n_frames), None


def _index_of(imported, fluid):
    """Refractive index (float64) of each frame of a temperature, salinity or index field."""
    quantity = imported.quantity
    if quantity == "index":
        return list(imported.values)
    if quantity == "temperature":  # salt water: at its base salinity
        return [fluid.index(temperature_c=v) for v in imported.values]
    if fluid.kind != "saltwater":
        raise RimclError("a salinity field needs --fluid saltwater")
    return [fluid.index(salinity_g_kg=v) for v in imported.values]


def import_dataset(
    path,
    output,
    *,
    fluid="water",
    wavelength_nm=532.0,
    temperature_c=20.0,
    n_ref=None,
    gradient="auto",
    title=None,
    overwrite=False,
    **options,
):
    """Import a CF dataset or ``.npz`` file (:func:`read_dataset`) as a rimcl field file.

    Temperature and salinity become the fluid's refractive index (stored as ``delta_n``
    about its mean, with ``n_ref``); an index is stored alike; ``delta_n`` is stored with
    ``n_ref`` (the ``n_ref`` attribute of the variable, the argument, else the fluid's
    index at its base state); a density is stored as a density (with its gradient).

    Parameters
    ----------
    path, output : str or Path
    fluid : {"water", "air", "saltwater"}
        The fluid of a temperature or salinity field (its ``n(T)``, ``n(S)``).
    wavelength_nm : float
        Vacuum wavelength of the light (nm).
    temperature_c : float
        Base temperature of the fluid (°C): the temperature of a salinity field.
    n_ref : float, optional
        Reference index of a ``delta_n`` field.
    gradient : str
        Density gradient of a density field (as :func:`rimcl.fields.jhtdb.import_flow`).
    title : str, optional
    overwrite : bool
    **options
        Passed to :func:`read_dataset`.

    Returns
    -------
    pathlib.Path
    """
    check_output(output, overwrite)
    flow = read_dataset(path, **options)
    medium = Fluid(fluid, temperature_c=float(temperature_c), wavelength_nm=float(wavelength_nm))
    attrs = {
        "title": title or f"{flow.quantity} field imported from {Path(path).name}",
        **flow.attrs,
        "length_unit": "m" if flow.length_m == 1.0 else (
            f"{flow.length_m:g} m" if flow.length_m else "as in the input coordinates"),
        "time_unit": "s" if flow.time_s == 1.0 else (
            f"{flow.time_s:g} s" if flow.time_s else "as in the input times"),
    }  # fmt: skip
    if flow.length_m is not None:
        attrs["length_m"] = float(flow.length_m)
    if flow.time_s is not None:
        attrs["time_s"] = float(flow.time_s)
    config = {"input": str(path), "output": str(output), "fluid": fluid,
              "wavelength_nm": wavelength_nm, "temperature_c": temperature_c, "n_ref": n_ref,
              **{k: v if isinstance(v, (int, float, str)) or v is None else str(v)
                 for k, v in options.items()}}  # fmt: skip
    common = dict(
        times=flow.times, origin=flow.origin, spacing=flow.spacing, velocity=flow.velocity,
        boundary=flow.boundary, config=config, overwrite=overwrite,
    )  # fmt: skip
    if flow.quantity == "density":
        periodic = flow.boundary == "periodic"
        method = ("spectral" if periodic else "fd4") if gradient == "auto" else gradient
        density = [v.astype(np.float32) for v in flow.values]
        gradients = None
        if method != "none":
            gradients = [
                compute_gradient(d, flow.spacing, method=method, periodic=periodic) for d in density
            ]
        attrs["density_gradient"] = method
        return write_field(output, density=density, density_gradient=gradients,
                           attrs=attrs, **common)  # fmt: skip
    if flow.quantity == "delta_n":
        stored = attrs.pop("n_ref", None)
        reference = next(v for v in (n_ref, stored, float(medium.index())) if v is not None)
        if not (math.isfinite(float(reference)) and float(reference) > 0):
            raise RimclError(f"n_ref must be a positive number, got {reference!r}")
        attrs["n_ref_source"] = (
            "given" if n_ref is not None else "the variable's n_ref" if stored is not None
            else f"the fluid's base index ({medium.label()}, {wavelength_nm:g} nm)"
        )  # fmt: skip
        return write_field(output, delta_n=[v.astype(np.float32) for v in flow.values],
                           n_ref=float(reference), attrs=attrs, **common)  # fmt: skip
    index = _index_of(flow, medium)
    first = index[0].flat[0]
    # one reference for all frames (the mean), taken about a sample so a uniform field
    # gives δn = 0 exactly
    reference = float(first + np.mean([np.mean(n - first) for n in index]))
    if flow.quantity in ("temperature", "salinity"):
        attrs["fluid"] = medium.describe()
    return write_field(output, delta_n=[(n - reference).astype(np.float32) for n in index],
                       n_ref=reference, attrs=attrs, **common)  # fmt: skip
