"""Reading a ``rimcl render`` output file (HDF5) into :class:`RenderTables`.

Holds the render file's schema (the columns of each group, the root attributes, the optional
optics, truth and polynomial-fit columns) and :func:`load_render`, which checks a file against
it and refuses a bad one with one :class:`~rimcl.core.errors.RimclError` line.
"""

import dataclasses
import json
import math
from pathlib import Path

import numpy as np

from rimcl.core.errors import RimclError
from rimcl.core.tables_h5 import read_table
from rimcl.imaging.frames import THRESHOLD_VARIANTS
from rimcl.stats.tables import NOTE_COLUMN

RENDER_SCHEMA = "render"
#: Versions this reader reads: 1 wrote each table as 1-D rows, 2 the per-tracer tables as
#: (id, frame) datasets; both read into the same 1-D frame-major columns.
READ_SCHEMA_VERSIONS = (1, 2)
TRACER_COLUMNS = (
    "id",
    "frame",
    "time",
    "x2_true",
    "x3_true",
    "x2_ref",
    "x3_ref",
    "x2_meas",
    "x3_meas",
    "area_ref",
    "area_meas",
    "perimeter_ref",
    "perimeter_meas",
    "circularity_ref",
    "circularity_meas",
    "n_rays",
    "n_rays_ok",
    "flags",
)
VELOCITY_COLUMNS = ("id", "u2_true", "u3_true", "u2_ref", "u3_ref", "u2_meas", "u3_meas", "flags")
ACCELERATION_COLUMNS = (
    "id",
    "a2_true",
    "a3_true",
    "a2_ref",
    "a3_ref",
    "a2_meas",
    "a3_meas",
    "flags",
)
#: Columns of the optics part of the error budget, all or none of a group:
#: ``<q>_opt`` through the field, ``<q>_opt_ref`` through a uniform medium.
OPTICS_COLUMNS = {
    "x": ("x2_opt", "x3_opt", "x2_opt_ref", "x3_opt_ref"),
    "u": ("u2_opt", "u3_opt", "u2_opt_ref", "u3_opt_ref"),
    "a": ("a2_opt", "a3_opt", "a2_opt_ref", "a3_opt_ref"),
}
#: Columns of the noise floor, all or none of a group: the reference exposed a second
#: time with independent sensor noise (``flags_floor``: that exposure's flags, tracers only).
FLOOR_COLUMNS = {
    "x": ("x2_floor", "x3_floor", "flags_floor"),
    "u": ("u2_floor", "u3_floor"),
    "a": ("a2_floor", "a3_floor"),
}
#: Suffixes of the columns of the tracers located again at other thresholds in the same
#: images (:data:`rimcl.imaging.frames.THRESHOLD_VARIANTS`).
THRESHOLD_SUFFIXES = tuple(suffix for suffix, _ in THRESHOLD_VARIANTS)


def threshold_columns(symbol, suffix):
    """The optional columns of one variant threshold in a group of quantity ``symbol``
    (``x``, ``u`` or ``a``), all or none: reference and measured, and the variant's flags."""
    return (
        *(f"{symbol}{c}_{kind}_{suffix}" for kind in ("ref", "meas") for c in (2, 3)),
        f"flags_{suffix}",
    )


#: Kinematic groups of a render file: (group, symbol, columns, required from this many frames).
#: The ``_fit`` groups (sliding polynomial fit over several frames) are optional.
KINEMATIC_GROUPS = (
    ("velocity", "u", VELOCITY_COLUMNS, 2),
    ("acceleration", "a", ACCELERATION_COLUMNS, 3),
    ("velocity_fit", "u", VELOCITY_COLUMNS, None),
    ("acceleration_fit", "a", ACCELERATION_COLUMNS, None),
)
#: Per-frame truth along the tracks (files of many frames): velocity and ``Du/Dt``.
TRUTH_COLUMNS = ("u2_true", "u3_true", "a2_true", "a3_true")
RAY_COLUMNS = ("theta0", "deflection", "n_metric", "path_length", "displacement", "status")
ROOT_ATTRS = ("case", "k_rho", "delta_n_max", "length_L", "pixel_size", "dt", "flag_names")


@dataclasses.dataclass(eq=False)
class RenderTables:
    """The contents of one ``rimcl render`` output file.

    Attributes
    ----------
    path : Path
    case : str
        Case name (``C0`` ... ``C4`` or a custom name).
    k_rho : float
        Gladstone–Dale product ``G = K ρ`` (dimensionless).
    delta_n_max : float
        Largest spatial difference of the refractive index in the traced field.
    length : float
        Depth ``L`` of the traced slab (field length units), the normaliser of positions.
    pixel_size : float
        Image pixel size (field length units).
    dt : float
        Time between frames (field time units).
    flag_names : dict of int to str
        Flag bit value (1, 2, 4, ...) to its name.
    tracers, velocity, acceleration, rays : dict of str to ndarray
        The 1-D columns of the groups of the same name; ``tracers`` has one row per tracer
        and frame, ``velocity`` and ``acceleration`` one row per tracer (or per tracer and
        evaluation frame, with a ``frame`` column), ``rays`` one row per sampled frame-0
        ray. A group the file does not hold (a one-frame render has no velocity) is ``{}``.
    ray_counts : dict of str to dict
        Count of all traced rays (every frame, not only the sampled ones) per status name
        (and ``vignetted``): ``{"measured": {...}, "reference": {...}}``.
    provenance : dict
        ``config``, ``versions`` and ``device`` of the render run, parsed from JSON.
    velocity_fit, acceleration_fit : dict of str to ndarray
        Velocity and acceleration of a sliding polynomial fit over several frames, same
        columns as ``velocity`` and ``acceleration``; ``{}`` when the file has none.
    length_m, time_s : float or None
        Metres per field length unit and seconds per field time unit, where the file
        records them (root attributes of the same names).
    """

    path: Path
    case: str
    k_rho: float
    delta_n_max: float
    length: float
    pixel_size: float
    dt: float
    flag_names: dict
    tracers: dict
    velocity: dict
    acceleration: dict
    rays: dict
    ray_counts: dict
    provenance: dict
    velocity_fit: dict = dataclasses.field(default_factory=dict)
    acceleration_fit: dict = dataclasses.field(default_factory=dict)
    length_m: float | None = None
    time_s: float | None = None

    def all_tables(self):
        """The per-tracer tables: tracers, then every kinematic group (empty ones too)."""
        return [self.tracers, *(getattr(self, group) for group, *_ in KINEMATIC_GROUPS)]


def _text(value):
    return value.decode() if isinstance(value, bytes) else str(value)


def _json_attr(attrs, key, path):
    try:
        return json.loads(_text(attrs[key]))
    except (KeyError, json.JSONDecodeError) as exc:
        raise RimclError(f"{path}: attribute {key!r} is missing or not JSON ({exc})") from None


def _flag_bits(raw, path):
    """Flag names keyed by bit value; the file stores ``{"<bit value>": name}``."""
    bits = {}
    for key, name in raw.items():
        try:
            bit = int(key)
        except ValueError:
            raise RimclError(f"{path}: flag_names key {key!r} is not an integer") from None
        if bit <= 0 or bit & (bit - 1):
            raise RimclError(f"{path}: flag_names key {key!r} is not a power of two")
        bits[bit] = str(name)
    return bits


def _read_group(h5file, group, columns, path, optional=()):
    """Columns of one group; ``optional`` column sets are read when all of a set is there."""
    present = set(h5file[group])
    missing = [name for name in columns if name not in present]
    if missing:
        raise RimclError(f"{path}: group {group!r} lacks datasets {', '.join(missing)}")
    names = list(columns)
    for extra in (NOTE_COLUMN,), ("frame",), *optional:
        held = [name for name in extra if name in present]
        if held and len(held) < len(extra):
            absent = ", ".join(name for name in extra if name not in present)
            raise RimclError(f"{path}: group {group!r} has {held[0]} but lacks {absent}")
        names += [name for name in held if name not in names]
    table = read_table(h5file[group], names)
    lengths = {name: values.shape for name, values in table.items()}
    if len(set(lengths.values())) != 1 or any(len(shape) != 1 for shape in lengths.values()):
        raise RimclError(f"{path}: datasets of group {group!r} differ in shape: {lengths}")
    return table


def load_render(path):
    """Read one ``rimcl render`` output file.

    Parameters
    ----------
    path : str or Path

    Returns
    -------
    RenderTables

    Raises
    ------
    RimclError
        If the file is missing, not HDF5, not a render file of a known schema version, or
        lacks an attribute, a dataset, or a kinematic group its frame count calls for.
    """
    import h5py

    path = Path(path)
    if not path.is_file():
        raise RimclError(f"{path}: no such file")
    try:
        h5file = h5py.File(path, "r")
    except OSError as exc:
        raise RimclError(f"{path}: not a readable HDF5 file ({exc})") from None
    with h5file:
        attrs = h5file.attrs
        schema = _text(attrs.get("rimcl_schema", ""))
        if schema != RENDER_SCHEMA:
            raise RimclError(f"{path}: not a rimcl render file (rimcl_schema = {schema!r})")
        version = int(attrs.get("schema_version", -1))
        if version not in READ_SCHEMA_VERSIONS:
            known = " and ".join(str(v) for v in READ_SCHEMA_VERSIONS)
            raise RimclError(f"{path}: render schema version {version}, this rimcl reads {known}")
        missing = [key for key in ROOT_ATTRS if key not in attrs]
        if missing:
            raise RimclError(f"{path}: root attributes {', '.join(missing)} are missing")
        if "tracers" not in h5file:
            raise RimclError(f"{path}: group 'tracers' is missing (not a rimcl render file?)")
        variants = [threshold_columns("x", suffix) for suffix in THRESHOLD_SUFFIXES]
        tracers = _read_group(
            h5file,
            "tracers",
            TRACER_COLUMNS,
            path,
            (OPTICS_COLUMNS["x"], FLOOR_COLUMNS["x"], TRUTH_COLUMNS, *variants),
        )
        if tracers["id"].size == 0:
            raise RimclError(f"{path}: the tracer table is empty")
        frames = int(np.unique(tracers["frame"]).size)
        kinematic = {}
        for group, symbol, columns, needed_from in KINEMATIC_GROUPS:
            if group in h5file:
                variants = [threshold_columns(symbol, suffix) for suffix in THRESHOLD_SUFFIXES]
                kinematic[group] = _read_group(
                    h5file,
                    group,
                    columns,
                    path,
                    (OPTICS_COLUMNS[symbol], FLOOR_COLUMNS[symbol], *variants),
                )
            elif needed_from is not None and frames >= needed_from:
                raise RimclError(
                    f"{path}: group {group!r} is missing, but the tracers have {frames} frames"
                )
            else:
                kinematic[group] = {}
        rays = _read_group(h5file, "rays", RAY_COLUMNS, path) if "rays" in h5file else {}
        ray_counts = {"measured": {}, "reference": {}}
        for key, value in h5file["rays"].attrs.items() if "rays" in h5file else ():
            for prefix, kind in (("ref_count_", "reference"), ("count_", "measured")):
                if key.startswith(prefix):
                    ray_counts[kind][key[len(prefix) :]] = int(value)
                    break
        provenance = {
            key: _json_attr(attrs, key, path)
            for key in ("config", "versions", "device")
            if key in attrs
        }
        length = float(attrs["length_L"])
        if not length > 0:
            raise RimclError(f"{path}: length_L must be positive, got {length}")
        return RenderTables(
            path=path,
            case=_text(attrs["case"]),
            k_rho=float(attrs["k_rho"]),
            delta_n_max=float(attrs["delta_n_max"]),
            length=length,
            pixel_size=float(attrs["pixel_size"]),
            dt=float(attrs["dt"]),
            flag_names=_flag_bits(_json_attr(attrs, "flag_names", path), path),
            tracers=tracers,
            rays=rays,
            ray_counts=ray_counts,
            provenance=provenance,
            length_m=_optional_scale(attrs, "length_m"),
            time_s=_optional_scale(attrs, "time_s"),
            **kinematic,
        )


def _optional_scale(attrs, key):
    """A positive finite scale attribute, or None where absent (or not a number > 0)."""
    try:
        value = float(attrs[key])
    except (KeyError, TypeError, ValueError):
        return None
    return value if math.isfinite(value) and value > 0 else None
