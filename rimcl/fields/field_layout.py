"""The rimcl field file's layout, and the checks its reader and writer share.

A rimcl field file is an HDF5 file of flow frames on a uniform grid, written by
:func:`rimcl.fields.field_writer.write_field` and read by
:class:`rimcl.fields.field_reader.FieldFile`.

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
        x1, x2, x3         float64 node coordinates, HDF5 dimension scales of the arrays
        time               scalar float64, the frame's time; component, sheet_component:
                           text labels of the vectors' last axis (for xarray; see
                           :func:`rimcl.fields.field_writer.attach_scales`)
    /frames/0001 ...

Frames are numbered from 0 in time order. A file holds either ``density`` (turned into a
refractive index with a Gladstone–Dale product ``G``: ``δn = G (ρ - mean ρ)``,
``n_ref = 1 + G mean ρ``) or ``delta_n`` directly, in every frame. A velocity, when
stored, is in every frame, and either in full (``velocity``) or on one sheet plane
(``velocity_sheet``, the same ``x1`` in every frame): the sheet plane is all that tracking
tracers in that sheet needs, at 2/(3 n1) of the size, so a file can hold many frames.
"""

import math

import h5py
import numpy as np

from rimcl.core.errors import RimclError, first_line

SCHEMA = "field"
SCHEMA_VERSION = 1
#: Dataset name of the sheet-only velocity (see the layout above).
SHEET_VELOCITY = "velocity_sheet"

#: Kinds of NumPy dtype a field array may hold: floating point and integers (booleans,
#: complex numbers, strings and compound records are refused, not cast).
REAL_KINDS = "fiu"


def check_sheet_x1(x1, origin1, spacing1, n1, boundary, what):
    """Refuse a sheet plane ``x1`` that is not finite, or outside a clamped grid."""
    try:
        x1 = float(x1)
    except (TypeError, ValueError):
        raise RimclError(f"{what} must be a number, got {x1!r}") from None
    hi = origin1 + (n1 - 1) * spacing1
    if not math.isfinite(x1) or (boundary != "periodic" and not origin1 <= x1 <= hi):
        raise RimclError(f"{what} = {x1:g} must lie in the field along x1 ({origin1:g} .. {hi:g})")


def plain_attr(value):
    """An attribute value as plain Python: text for bytes, lists for arrays, scalars."""
    if isinstance(value, bytes):
        return value.decode("utf-8", "replace")
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, np.generic):
        return value.item()
    return value


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


def read_attr(path, obj, name):
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
    if array.dtype.kind not in REAL_KINDS:
        wanted = "a real number" if count == 1 else "real numbers"
        raise RimclError(f"{path}: {where} must be {wanted}, got {array.dtype} {value!r}")
    array = array.astype(np.float64).reshape(-1)
    if count is not None and array.size != count:
        wanted = "one number" if count == 1 else f"{count} numbers"
        raise RimclError(f"{path}: {where} must be {wanted}, got {array.size}")
    if not np.all(np.isfinite(array)):
        raise RimclError(f"{path}: {where} must be finite, got {array.tolist()}")
    return array


def text_attr(path, obj, name, default):
    """A text attribute, ``default`` if absent; anything but text is one line of error."""
    value = read_attr(path, obj, name)
    if value is None:
        return default
    value = plain_attr(value)
    if not isinstance(value, str):
        raise RimclError(f"{path}: attribute {name!r} of {obj.name} must be text, got {value!r}")
    return value
