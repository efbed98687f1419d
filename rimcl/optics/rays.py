"""Ray sets for ``rimcl trace`` and its HDF5 output.

A ray set is either the paper's fan (random tracers in the light sheet, each with
``M x M`` rays aimed at an equidistant grid on the exit plane) or rays read
from a file. The output file holds one row per ray.
"""

import warnings
from pathlib import Path

import h5py
import numpy as np

from rimcl.core.atomic import atomic_path
from rimcl.core.errors import RimclError, first_line
from rimcl.core.memory import check_array_memory
from rimcl.core.provenance import stamp_h5, to_json
from rimcl.core.tables_h5 import add_scale, write_variable
from rimcl.fields.field import AnalyticField
from rimcl.optics.camera import PlaneCamera, Scene, seed_tracers
from rimcl.optics.trace import STATUS_NAMES

TRACE_SCHEMA = "trace"
TRACE_SCHEMA_VERSION = 1
#: Units of the trace file's columns (the rest are dimensionless): ``L0`` the field length unit.
TRACE_UNITS = {
    "origin": "L0",
    "image_pos": "L0",
    "end_pos": "L0",
    "deflection": "rad",
    "deflection_angles": "rad",
    "path_length": "L0",
    "optical_path": "L0",
    "n_metric": "1/L0",
}


def analytic_scene(length):
    """Scene for a closed-form field: sheet ``x1 = 0``, exit plane ``x1 = L``,
    field of view ``[-L/2, L/2]²`` (centred on the axis of the GRIN rod and fish-eye)."""
    half = 0.5 * float(length)
    return Scene(0.0, float(length), np.array([-half, -half]), np.array([half, half]), False)


def scene_for(field, length=None, x_sheet=None):
    """Default scene of a gridded or closed-form field (a closed-form one: sheet at 0)."""
    if isinstance(field, AnalyticField):
        return analytic_scene(np.pi if length is None else length)
    return Scene.from_grid(
        field.origin, field.spacing, field.shape, field.boundary, x_sheet=x_sheet, depth=length
    )


def fan_rays(scene, tracers, fan, seed):
    """The paper's ray fan: ``tracers`` random tracers, ``fan x fan`` rays each.

    Returns
    -------
    origins, directions : ndarray, shape (tracers * fan², 3)
    tracer_id : ndarray of int64, shape (tracers * fan²,)
    """
    rng = np.random.default_rng(seed)
    positions = seed_tracers(tracers, scene, rng)
    camera = PlaneCamera(scene, fan)
    directions = camera.directions(positions).reshape(-1, 3)
    per_tracer = camera.rays_per_tracer
    origins = np.repeat(scene.in_sheet(positions), per_tracer, axis=0)
    tracer_id = np.repeat(np.arange(len(positions)), per_tracer)
    return origins, directions, tracer_id


#: Columns of a ray CSV file, as its optional header line names them.
RAY_CSV_COLUMNS = ("x1", "x2", "x3", "d1", "d2", "d3")


def _csv_rays(path):
    """Rays of a CSV file: 6 columns, an optional header line naming them."""
    with open(path, encoding="utf-8") as text:
        first = text.readline()
    header = tuple(cell.strip().lower() for cell in first.split(",")) == RAY_CSV_COLUMNS
    try:
        with warnings.catch_warnings():  # an empty file is reported below, as an error
            warnings.simplefilter("ignore", UserWarning)
            table = np.loadtxt(path, delimiter=",", comments="#", ndmin=2, skiprows=int(header))
    except ValueError as exc:
        raise RimclError(
            f"{path}: a ray CSV holds 6 numbers a line, after an optional header line "
            f"{','.join(RAY_CSV_COLUMNS)} ({first_line(exc)})"
        ) from None
    if table.size == 0:
        raise RimclError(f"{path} holds no rays")
    if table.shape[1] != len(RAY_CSV_COLUMNS):
        raise RimclError(f"{path}: a ray CSV needs 6 columns {','.join(RAY_CSV_COLUMNS)}")
    return {"origins": table[:, :3], "directions": table[:, 3:]}


def _h5_rays(path):
    from rimcl.fields.field_layout import check_hdf5_object

    arrays = {}
    with h5py.File(path, "r") as data:
        for name in ("origins", "directions"):
            dataset = check_hdf5_object(path, data, name, "dataset")
            if dataset is None:
                continue
            check_array_memory(dataset.shape, 8, f"reading {path}: {name}")
            arrays[name] = dataset[()]
    return arrays


def _npz_rays(path):
    from rimcl.fields.jhtdb import npz_array, open_npz

    with open_npz(path) as data:
        return {
            name: npz_array(data, path, name) for name in ("origins", "directions") if name in data
        }


def read_rays(path):
    """Rays from a file: ``.npz`` or HDF5 with arrays ``origins`` and ``directions``
    (``(N, 3)``, ``x1, x2, x3``), or ``.csv`` with columns ``x1,x2,x3,d1,d2,d3`` (the first
    line may be that header).

    Returns
    -------
    origins, directions : ndarray, float64, shape (N, 3)
    """
    path = Path(path)
    if not path.is_file():
        raise RimclError(f"ray file {path} does not exist")
    suffix = path.suffix.lower()
    readers = {".npz": _npz_rays, ".csv": _csv_rays}
    try:
        arrays = readers.get(suffix, _h5_rays)(path)
    except RimclError:
        raise
    except Exception as exc:  # text, zip and HDF5 errors of a damaged or foreign file
        raise RimclError(f"cannot read rays from {path}: {first_line(exc)}") from None
    missing = {"origins", "directions"} - set(arrays)
    if missing:
        raise RimclError(f"{path} lacks {', '.join(sorted(missing))}")
    rays = []
    for name in ("origins", "directions"):
        values = np.asarray(arrays[name])
        if values.dtype.kind not in "fiu":
            raise RimclError(f"{path}: {name} must hold real numbers, got {values.dtype}")
        if values.ndim != 2 or values.shape[1] != 3:
            raise RimclError(f"{path}: {name} must have shape (N, 3), got {values.shape}")
        rays.append(values.astype(np.float64))
    return tuple(rays)


def write_trace(path, result, config, device=None, tracer_id=None, overwrite=False):
    """Write a :class:`rimcl.TraceResult` as an HDF5 file, atomically.

    Layout: root attributes ``rimcl_schema = "trace"``, ``schema_version``,
    ``status_counts`` (JSON), ``status_names``, ``config``, ``versions``, ``device``;
    group ``rays`` with one row per ray: ``origin``, ``direction``, ``image_pos``,
    ``end_pos``, ``end_dir`` (N, 3), ``deflection``, ``path_length``, ``optical_path``
    (N,), ``deflection_angles``, ``n_metric`` (N, 3), ``steps``, ``status`` (N,) and,
    for fans, ``tracer_id`` (N,).
    """
    columns = {
        "origin": result.origins,
        "direction": result.directions,
        "image_pos": result.image_pos,
        "end_pos": result.end_pos,
        "end_dir": result.end_dir,
        "deflection": result.deflection,
        "deflection_angles": result.deflection_angles,
        "path_length": result.path_length,
        "optical_path": result.optical_path,
        "n_metric": result.n_metric,
        "steps": result.steps.astype(np.int32),
        "status": result.status,
    }
    if tracer_id is not None:
        columns["tracer_id"] = tracer_id
    with atomic_path(path, overwrite=overwrite) as tmp, h5py.File(tmp, "w") as out:
        out.attrs["rimcl_schema"] = TRACE_SCHEMA
        out.attrs["schema_version"] = TRACE_SCHEMA_VERSION
        out.attrs["status_names"] = to_json(list(STATUS_NAMES))
        out.attrs["status_counts"] = to_json(result.counts)
        stamp_h5(out, {**config, "trace": result.config}, device)
        # named dimensions (ray, axis) and units, for xarray.open_dataset(path, group="rays")
        rays = out.create_group("rays")
        add_scale(rays, "ray", np.arange(len(result.status)))
        add_scale(rays, "axis", ["x1", "x2", "x3"])
        for name, values in columns.items():
            dimensions = ("ray", "axis")[: np.ndim(values)]
            write_variable(
                rays, name, values, dimensions, TRACE_UNITS.get(name, "1"),
                compression="gzip", shuffle=True,
            )  # fmt: skip
