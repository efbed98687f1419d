"""Error statistics of synthetic PTV measurements (DESIGN §6.6, §7).

Input: the HDF5 tables written by ``rimcl render`` (one file per refractive-index case).
Output: one ``stats.json`` document, whose shape is documented in the README:

- position error ``ε_x = x' - x^ref`` (measured through the field minus measured through a
  uniform field), summarised by the peak (mode) of the PDF of ``log10(|ε_x| / L)``;
- refraction errors of velocity and acceleration, ``ε_u = u' - u^ref`` and
  ``ε_a = a' - a^ref``, relative to the true ``u`` and ``a``: mean (the paper's
  *systematic* error), standard deviation (the paper's *random* error), and the robust
  companions median, interquartile range and ``rms(ε) / rms(truth)``;
- the finite-difference baseline ``u^ref - u`` and ``a^ref - a`` with the same summaries;
- tracer image shape: peaks of the PDFs of ``ΔA / A`` and of the circularity ``C``.

Relative errors are fractions (not percent). A tracer with any bit of ``flags`` set in any
of its rows (a position that is missing or doubtful) is left out of every statistic of its
case and counted in ``n_excluded`` under each of its flag names; the bits of ``notes``
(what happened to the light of an image still measured as a camera would: a clipped peak,
lost rays) are counted in ``n_noted`` and the tracer is kept. Nothing is dropped without
being counted.
"""

import dataclasses
import json
import math
from pathlib import Path

import numpy as np

from rimcl.errors import RimclError
from rimcl.provenance import atomic_path, to_json, versions

RENDER_SCHEMA = "render"
RENDER_SCHEMA_VERSION = 1
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
#: Optional per-row columns: bits that record an event without excluding the tracer.
NOTE_COLUMN = "notes"
RAY_COLUMNS = ("theta0", "deflection", "n_metric", "path_length", "displacement", "status")
ROOT_ATTRS = ("case", "k_rho", "delta_n_max", "length_L", "pixel_size", "dt", "flag_names")

#: Points of the grid on which kernel density estimates are evaluated to find a peak.
PEAK_GRID_POINTS = 1024


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
        and frame, ``velocity`` and ``acceleration`` one row per tracer, ``rays`` one row
        per sampled frame-0 ray.
    ray_counts : dict of str to dict
        Count of all traced rays (every frame, not only the sampled ones) per status name
        (and ``vignetted``): ``{"measured": {...}, "reference": {...}}``.
    provenance : dict
        ``config``, ``versions`` and ``device`` of the render run, parsed from JSON.
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


def _read_group(h5file, group, columns, path, required=True):
    if group not in h5file:
        if required:
            raise RimclError(f"{path}: group {group!r} is missing (not a rimcl render file?)")
        return {}
    missing = [name for name in columns if name not in h5file[group]]
    if missing:
        raise RimclError(f"{path}: group {group!r} lacks datasets {', '.join(missing)}")
    if "flags" in columns:
        columns = (*columns, NOTE_COLUMN) if NOTE_COLUMN in h5file[group] else columns
    table = {name: np.asarray(h5file[group][name][()]) for name in columns}
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
        lacks an attribute or dataset.
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
        if version != RENDER_SCHEMA_VERSION:
            raise RimclError(
                f"{path}: render schema version {version}, this rimcl reads {RENDER_SCHEMA_VERSION}"
            )
        missing = [key for key in ROOT_ATTRS if key not in attrs]
        if missing:
            raise RimclError(f"{path}: root attributes {', '.join(missing)} are missing")
        tracers = _read_group(h5file, "tracers", TRACER_COLUMNS, path)
        if tracers["id"].size == 0:
            raise RimclError(f"{path}: the tracer table is empty")
        velocity = _read_group(h5file, "velocity", VELOCITY_COLUMNS, path)
        acceleration = _read_group(h5file, "acceleration", ACCELERATION_COLUMNS, path)
        rays = _read_group(h5file, "rays", RAY_COLUMNS, path, required=False)
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
            velocity=velocity,
            acceleration=acceleration,
            rays=rays,
            ray_counts=ray_counts,
            provenance=provenance,
        )


def flagged_tracers(tables, column="flags"):
    """Tracers with bits set in a flag column, and the count per flag name.

    Parameters
    ----------
    tables : RenderTables
    column : {"flags", "notes"}
        ``flags``: bits that exclude a tracer; ``notes``: bits that are only counted (a
        file without a ``notes`` column has none).

    Returns
    -------
    ids : ndarray of int
        Sorted ids of the tracers with a bit set in any of their rows (any frame,
        velocity, acceleration).
    counts : dict of str to int
        Number of tracers carrying each bit (a tracer with two bits counts under both),
        for ``flags`` every known flag name (zeros included). Bits missing from
        ``flag_names`` are named ``bit<value>``.
    """
    tables_with = [t for t in (tables.tracers, tables.velocity, tables.acceleration) if column in t]
    ids = np.concatenate([t["id"] for t in tables_with] or [np.empty(0)]).astype(np.int64)
    bits = np.concatenate([t[column] for t in tables_with] or [np.empty(0)]).astype(np.int64)
    counts = {name: 0 for name in tables.flag_names.values()} if column == "flags" else {}
    seen_bits = int(np.bitwise_or.reduce(bits)) if bits.size else 0
    bit = 1
    while bit <= seen_bits:
        if seen_bits & bit:
            name = tables.flag_names.get(bit, f"bit{bit}")
            counts[name] = int(np.unique(ids[(bits & bit) != 0]).size)
        bit <<= 1
    return np.unique(ids[bits != 0]), counts


def _kept(table, excluded_ids):
    keep = ~np.isin(table["id"].astype(np.int64), excluded_ids)
    return {name: values[keep] for name, values in table.items()}


def density_estimate(values, log=False, points=PEAK_GRID_POINTS):
    """Gaussian kernel density estimate of a sample on a regular grid.

    The bandwidth follows Scott's rule, so the estimate of ``c * values`` (with ``log``)
    is the estimate of ``values`` shifted by ``log10(c)``: the peak scales exactly.

    Parameters
    ----------
    values : array_like, 1-D
        The sample; with ``log`` only its positive values are used.
    log : bool
        Estimate the density of ``log10(values)``.
    points : int
        Grid points.

    Returns
    -------
    grid : ndarray, shape (points,) or (1,)
        Where the density is given (``values`` units, not their log, also with ``log``).
    density : ndarray, same shape
        PDF of ``values`` (or of ``log10(values)`` with ``log``), integrating to 1 over
        the grid variable. A sample with a single distinct value (a point mass) gives
        that value alone, with density 1.
    """
    from scipy.stats import gaussian_kde

    sample = np.asarray(values, dtype=np.float64).ravel()
    sample = sample[np.isfinite(sample)]
    if log:
        sample = np.log10(sample[sample > 0])
    if sample.size == 0:
        return np.empty(0), np.empty(0)
    if np.ptp(sample) == 0:
        grid = sample[:1]
        return (10.0**grid if log else grid), np.ones(1)
    kde = gaussian_kde(sample)
    bandwidth = math.sqrt(float(kde.covariance[0, 0]))
    grid = np.linspace(sample.min() - 3 * bandwidth, sample.max() + 3 * bandwidth, points)
    density = kde(grid)
    return (10.0**grid if log else grid), density


def pdf_peak(values, log=False):
    """Position of the peak (mode) of the PDF of a sample, by kernel density estimation.

    Parameters
    ----------
    values : array_like, 1-D
    log : bool
        Peak of the PDF of ``log10(values)`` (positive values only).

    Returns
    -------
    float
        The mode, in ``values`` units; ``0.0`` for a sample with no (positive, with
        ``log``) finite value, such as the position errors of a uniform medium.
    """
    grid, density = density_estimate(values, log=log)
    if grid.size == 0:
        return 0.0
    return float(grid[np.argmax(density)])


def _finite_or_none(value):
    value = float(value)
    return value if math.isfinite(value) else None


def error_summary(error, truth):
    """Summary ``S`` of the relative error ``error / truth`` (fractions, not percent).

    Parameters
    ----------
    error, truth : array_like, 1-D, same shape
        Absolute error and true value; rows whose truth is zero or whose error is not
        finite are left out of the ratios (``n`` says how many remain).

    Returns
    -------
    dict
        ``systematic`` (mean of ``error/truth``), ``random`` (its standard deviation,
        ``ddof=1``), ``median``, ``iqr`` (75th minus 25th percentile),
        ``rms_normalized`` (``rms(error) / rms(truth)``, robust where ``truth ≈ 0``) and
        ``n``. ``None`` where the sample is too small.
    """
    error = np.asarray(error, dtype=np.float64)
    truth = np.asarray(truth, dtype=np.float64)
    usable = np.isfinite(error) & np.isfinite(truth) & (truth != 0)
    ratio = error[usable] / truth[usable]
    summary = {
        "systematic": None,
        "random": None,
        "median": None,
        "iqr": None,
        "rms_normalized": None,
        "n": int(ratio.size),
    }
    if ratio.size:
        q25, q50, q75 = np.percentile(ratio, [25, 50, 75])
        rms_truth = math.sqrt(np.mean(truth[usable] ** 2))
        summary.update(
            systematic=_finite_or_none(np.mean(ratio)),
            median=_finite_or_none(q50),
            iqr=_finite_or_none(q75 - q25),
            rms_normalized=_finite_or_none(math.sqrt(np.mean(error[usable] ** 2)) / rms_truth),
        )
    if ratio.size > 1:
        summary["random"] = _finite_or_none(np.std(ratio, ddof=1))
    return summary


def angle_deg(first, second):
    """Angle between 2-D vectors, in degrees, exactly 0 for identical vectors.

    Parameters
    ----------
    first, second : tuple of two ndarray
        Components ``(v2, v3)`` of each vector, arrays of the same shape.

    Returns
    -------
    ndarray
        Angle in ``[0, 180]`` degrees (``atan2(|a x b|, a . b)``, accurate at small angles).
    """
    cross = first[0] * second[1] - first[1] * second[0]
    dot = first[0] * second[0] + first[1] * second[1]
    return np.degrees(np.arctan2(np.abs(cross), dot))


def _vector_errors(table, symbol, measured, reference):
    """Relative-error summaries of one vector quantity: components, magnitude, angle.

    ``measured`` and ``reference`` name the columns compared (``meas``, ``ref`` or
    ``true``); the truth (denominator) is always the ``true`` column.
    """
    true = (table[f"{symbol}2_true"], table[f"{symbol}3_true"])
    meas = (table[f"{symbol}2_{measured}"], table[f"{symbol}3_{measured}"])
    ref = (table[f"{symbol}2_{reference}"], table[f"{symbol}3_{reference}"])
    angles = angle_deg(meas, ref)
    return {
        f"{symbol}2": error_summary(meas[0] - ref[0], true[0]),
        f"{symbol}3": error_summary(meas[1] - ref[1], true[1]),
        "magnitude": error_summary(np.hypot(*meas) - np.hypot(*ref), np.hypot(*true)),
        "angle_deg_median": _finite_or_none(np.median(angles)) if angles.size else None,
    }


def position_errors(tracers, length):
    """``|ε_x| / L`` per row of a tracer table: ``|x' - x^ref|`` in units of ``L``."""
    return (
        np.hypot(tracers["x2_meas"] - tracers["x2_ref"], tracers["x3_meas"] - tracers["x3_ref"])
        / length
    )


def area_changes(tracers):
    """``ΔA / A = (A' - A^ref) / A^ref`` per row with a non-empty reference image."""
    area_ref = tracers["area_ref"].astype(np.float64)
    usable = area_ref > 0
    return (tracers["area_meas"][usable] - area_ref[usable]) / area_ref[usable]


def case_statistics(tables):
    """The ``stats.json`` entry of one case.

    Parameters
    ----------
    tables : RenderTables

    Returns
    -------
    dict
        Keys documented in the README (``name``, ``G``, ``delta_n_max``, ``n_tracers``,
        ``n_used``, ``n_excluded``, ``position_error_*``, ``velocity``, ``acceleration``,
        ``baseline``, ``area_change_peak``, ``circularity_peak``, ``rays``).
    """
    excluded_ids, excluded_counts = flagged_tracers(tables)
    noted_ids, noted_counts = flagged_tracers(tables, NOTE_COLUMN)
    tracers = _kept(tables.tracers, excluded_ids)
    velocity = _kept(tables.velocity, excluded_ids)
    acceleration = _kept(tables.acceleration, excluded_ids)
    errors_over_length = position_errors(tracers, tables.length)
    peak_over_length = pdf_peak(errors_over_length, log=True)
    n_tracers = int(np.unique(tables.tracers["id"]).size)
    rays_total = int(np.sum(tables.tracers["n_rays"]))
    return {
        "name": tables.case,
        "G": tables.k_rho,
        "delta_n_max": tables.delta_n_max,
        "length_L": tables.length,
        "pixel_size_over_L": tables.pixel_size / tables.length,
        "dt": tables.dt,
        "n_tracers": n_tracers,
        "n_used": n_tracers - int(excluded_ids.size),
        "n_excluded": excluded_counts,
        "n_noted": noted_counts,
        "n_used_noted": int(np.setdiff1d(noted_ids, excluded_ids).size),
        "position_error_peak_over_L": peak_over_length,
        "position_error_peak_px": peak_over_length * tables.length / tables.pixel_size,
        "position_error_median_over_L": (
            _finite_or_none(np.median(errors_over_length)) if errors_over_length.size else None
        ),
        "velocity": _vector_errors(velocity, "u", "meas", "ref"),
        "acceleration": _vector_errors(acceleration, "a", "meas", "ref"),
        "baseline": {
            "velocity": _vector_errors(velocity, "u", "ref", "true"),
            "acceleration": _vector_errors(acceleration, "a", "ref", "true"),
        },
        "area_change_peak": pdf_peak(area_changes(tracers)),
        "circularity_peak": pdf_peak(tracers["circularity_meas"]),
        "rays": {
            "n_rays": rays_total,
            "n_rays_ok": int(np.sum(tables.tracers["n_rays_ok"])),
            "status_counts": tables.ray_counts["measured"],
            "reference_status_counts": tables.ray_counts["reference"],
        },
    }


def check_cases(all_tables):
    """Sort render tables by ``G`` and refuse two files of the same case name."""
    if not all_tables:
        raise RimclError("no render files given")
    names = [tables.case for tables in all_tables]
    duplicates = sorted({name for name in names if names.count(name) > 1})
    if duplicates:
        raise RimclError(f"more than one render file for case {', '.join(duplicates)}")
    return sorted(all_tables, key=lambda tables: tables.k_rho)


def compute_stats(all_tables, config=None):
    """The ``stats.json`` document of several cases.

    Parameters
    ----------
    all_tables : list of RenderTables
        One per case; sorted by ``G`` in the output.
    config : dict, optional
        Extra configuration to record (the study's scene, for instance).

    Returns
    -------
    dict
        ``{"cases": [...], "config": {...}, "versions": {...}}``.
    """
    all_tables = check_cases(all_tables)
    record = {
        "inputs": [
            {"path": str(tables.path), "case": tables.case, **tables.provenance}
            for tables in all_tables
        ],
        "position_error_peak": "mode of a Gaussian KDE (Scott) of log10(|x_meas - x_ref| / L)",
        "excluded": "a tracer with any flag in any row is left out of its case",
    }
    if config:
        record.update(config)
    return {
        "cases": [case_statistics(tables) for tables in all_tables],
        "config": record,
        "versions": versions(),
    }


def write_json(path, document, overwrite=True):
    """Write a JSON document atomically (NumPy values made plain, NaN refused).

    Parameters
    ----------
    path : str or Path
    document : dict
    overwrite : bool
    """
    text = json.dumps(json.loads(to_json(document)), indent=2, allow_nan=False)
    with atomic_path(path, overwrite=overwrite) as tmp:
        Path(tmp).write_text(text + "\n")


def run_stats(paths, out_dir, overwrite=False, figures=True, config=None):
    """Statistics (and figures) of several ``rimcl render`` files: what ``rimcl stats`` does.

    Parameters
    ----------
    paths : sequence of str or Path
        Render files, one per case.
    out_dir : str or Path
        Output directory (created if missing): ``stats.json`` and, with ``figures``, the
        figures with their data (see :mod:`rimcl.figures`).
    overwrite : bool
        Replace existing outputs; otherwise an existing ``stats.json`` is an error.
    figures : bool
        Also draw the figures.
    config : dict, optional
        Extra configuration recorded in every output.

    Returns
    -------
    dict
        The ``stats.json`` document.
    """
    out_dir = Path(out_dir)
    all_tables = check_cases([load_render(path) for path in paths])
    stats_path = out_dir / "stats.json"
    for existing in (stats_path, out_dir / "figures") if figures else (stats_path,):
        if existing.exists() and not overwrite:
            raise RimclError(f"{existing} exists (use --overwrite to replace it)")
    try:
        out_dir.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise RimclError(f"cannot create output directory {out_dir}: {exc}") from None
    stats = compute_stats(all_tables, config=config)
    if figures:
        from rimcl.figures import write_figures

        write_figures(all_tables, stats, out_dir / "figures", overwrite=True)
    write_json(stats_path, stats, overwrite=True)
    return stats
