"""Error statistics of synthetic PTV measurements (DESIGN §6.6, §7, §13).

Input: the HDF5 tables written by ``rimcl render`` (one file per refractive-index case).
Output: one ``stats.json`` document, whose shape is documented in the README:

- position error ``ε_x = x' - x^ref`` (measured through the field minus measured through a
  uniform field), summarised by the peak (mode) of the PDF of ``log10(|ε_x| / L)`` and the
  median of ``|ε_x| / L``;
- refraction errors of velocity and acceleration, ``ε_u = u' - u^ref`` and
  ``ε_a = a' - a^ref``, relative to the true ``u`` and ``a``: mean (the paper's
  *systematic* error), standard deviation (the paper's *random* error), and the robust
  companions median, interquartile range and ``rms(ε) / rms(truth)``, also over the
  tracers whose truth is not small (``|truth| ≥ CONDITION_FRACTION · rms(truth)``);
- the finite-difference baseline ``u^ref - u`` and ``a^ref - a`` with the same summaries;
- where the render file holds them, the same for the sliding-polynomial-fit tracks
  (``velocity_fit``, ``acceleration_fit``) and the split of the error into ``optics`` (the
  light-weighted mean of the traced ray image points, no pixels) and ``imaging`` (the rest:
  renderer, threshold, centroid);
- tracer image shape: peaks of the PDFs of ``ΔA / A`` and of the circularity ``C``.

Every summary carries a bootstrap 95 % interval (:class:`TracerBootstrap`: tracers resampled
with replacement, all rows of a tracer together), and the headline statistics are given
against the number of tracers (``convergence``), with the ones that keep growing named.

Relative errors are fractions (not percent). A statistic of an empty sample is ``None``
(``null`` in JSON), never 0. A tracer with any bit of ``flags`` set in any of its rows (a
position that is missing or doubtful) is left out of every statistic of its case and counted
in ``n_excluded`` under each of its flag names; the bits of ``notes`` (what happened to the
light of an image still measured as a camera would: a clipped peak, lost rays) are counted in
``n_noted`` and the tracer is kept. Nothing is dropped without being counted.
"""

import dataclasses
import json
import math
from pathlib import Path

import numpy as np

from rimcl.core.errors import RimclError
from rimcl.core.provenance import versions
from rimcl.stats.tables import (
    NOTE_COLUMN,
    angle_deg,
    area_changes,
    flagged_tracers,
    position_error_vectors,
    rows_of,
    write_json,
)

__all__ = [
    "RenderTables",
    "TracerBootstrap",
    "angle_deg",
    "case_statistics",
    "check_cases",
    "compute_stats",
    "error_summary",
    "load_render",
    "pdf_peak",
    "run_stats",
    "write_json",
]

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
#: Columns of the optics part of the error budget (DESIGN §13), all or none of a group:
#: ``<q>_opt`` through the field, ``<q>_opt_ref`` through a uniform medium.
OPTICS_COLUMNS = {
    "x": ("x2_opt", "x3_opt", "x2_opt_ref", "x3_opt_ref"),
    "u": ("u2_opt", "u3_opt", "u2_opt_ref", "u3_opt_ref"),
    "a": ("a2_opt", "a3_opt", "a2_opt_ref", "a3_opt_ref"),
}
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

#: The statistics of one error summary (besides ``n``), in the order they are printed.
SUMMARY_KEYS = ("systematic", "random", "median", "iqr", "rms_normalized")
#: Bootstrap resamples per interval. Measured on 400 tracers: the ends of the rms interval
#: move by 1 % of its width between seeds (2 % for the median), so 2 digits are stable.
BOOTSTRAP_RESAMPLES = 2000
#: Seed of the tracer resampling; the same resamples serve every statistic of a case.
BOOTSTRAP_SEED = 20240611
#: Elements of one block of resample weights (resamples x rows): bounds memory to ~32 MB.
BOOTSTRAP_BLOCK = 4_000_000
#: Conditioned summaries keep the rows with ``|truth| ≥ CONDITION_FRACTION · rms(truth)``:
#: there ``ε / truth`` has bounded denominators and its mean and spread converge.
CONDITION_FRACTION = 0.5
#: Nested subsamples of the convergence check: N / d tracers for each divisor d.
CONVERGENCE_DIVISORS = (16, 8, 4, 2, 1)
#: Seed of the order in which tracers enter the nested subsamples.
CONVERGENCE_SEED = 7
#: Grid points of the binned kernel density estimates whose peaks are reported.
PEAK_BINS = 512


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
    missing = [name for name in columns if name not in h5file[group]]
    if missing:
        raise RimclError(f"{path}: group {group!r} lacks datasets {', '.join(missing)}")
    names = list(columns)
    for extra in (NOTE_COLUMN,), ("frame",), *optional:
        present = [name for name in extra if name in h5file[group]]
        if present and len(present) < len(extra):
            absent = ", ".join(name for name in extra if name not in present)
            raise RimclError(f"{path}: group {group!r} has {present[0]} but lacks {absent}")
        names += [name for name in present if name not in names]
    table = {name: np.asarray(h5file[group][name][()]) for name in names}
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
        if version != RENDER_SCHEMA_VERSION:
            raise RimclError(
                f"{path}: render schema version {version}, this rimcl reads {RENDER_SCHEMA_VERSION}"
            )
        missing = [key for key in ROOT_ATTRS if key not in attrs]
        if missing:
            raise RimclError(f"{path}: root attributes {', '.join(missing)} are missing")
        if "tracers" not in h5file:
            raise RimclError(f"{path}: group 'tracers' is missing (not a rimcl render file?)")
        tracers = _read_group(
            h5file, "tracers", TRACER_COLUMNS, path, (OPTICS_COLUMNS["x"], TRUTH_COLUMNS)
        )
        if tracers["id"].size == 0:
            raise RimclError(f"{path}: the tracer table is empty")
        frames = int(np.unique(tracers["frame"]).size)
        kinematic = {}
        for group, symbol, columns, needed_from in KINEMATIC_GROUPS:
            if group in h5file:
                kinematic[group] = _read_group(
                    h5file, group, columns, path, (OPTICS_COLUMNS[symbol],)
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
            **kinematic,
        )


def _finite_or_none(value):
    value = float(value)
    return value if math.isfinite(value) else None


class TracerBootstrap:
    """Resamples of a set of tracers, drawn with replacement, the same for every statistic.

    Resample ``b`` draws ``n`` tracers out of the ``n`` given; a statistic of the resample
    weighs each row by how often its tracer was drawn, so all rows (frames) of one tracer
    go together and a statistic of many tables is resampled consistently. The draws are
    seeded per block of resamples, so they do not depend on the tables resampled.

    Parameters
    ----------
    tracer_ids : array_like of int
        The tracers to resample (duplicates are ignored).
    resamples : int
        Number of resamples ``B``.
    seed : int
    """

    def __init__(self, tracer_ids, resamples=BOOTSTRAP_RESAMPLES, seed=BOOTSTRAP_SEED):
        self.tracer_ids = np.unique(np.asarray(tracer_ids, dtype=np.int64))
        self.resamples = int(resamples)
        self.seed = seed
        count = max(self.tracer_ids.size, 1)
        self._block = max(1, min(self.resamples, BOOTSTRAP_BLOCK // count))
        # small sets (the usual study) keep their counts: drawn once, used by every statistic
        self._counts = (
            list(self._draw_counts()) if self.resamples * count <= BOOTSTRAP_BLOCK else None
        )

    def _draw_counts(self):
        """Blocks of ``(n, resamples)`` draw counts, reproducibly seeded per block.

        Rows are tracers and columns resamples: gathering the rows of a table, the
        products and the running sums over rows all then work on contiguous memory.
        float32 holds whole counts exactly and halves the memory traffic.
        """
        n = self.tracer_ids.size
        for index, start in enumerate(range(0, self.resamples, self._block)):
            columns = min(self._block, self.resamples - start)
            rng = np.random.default_rng([self.seed, index])
            draws = rng.integers(0, n, size=(columns, n)) * columns + np.arange(columns)[:, None]
            counts = np.bincount(draws.ravel(), minlength=n * columns)
            yield counts.reshape(n, columns).astype(np.float32)

    def weight_blocks(self, row_ids):
        """Resample weights of table rows, in blocks of resamples.

        Parameters
        ----------
        row_ids : ndarray of int, shape (rows,)
            Tracer id of each row; every id must be one of ``tracer_ids``.

        Yields
        ------
        ndarray of float32, shape (rows, block)
            How often each row's tracer was drawn in each resample of the block.
        """
        index = np.searchsorted(self.tracer_ids, np.asarray(row_ids, dtype=np.int64))
        if self.tracer_ids.size == 0 or index.size == 0:
            return
        step = max(1, BOOTSTRAP_BLOCK // index.size)
        for counts in self._counts if self._counts is not None else self._draw_counts():
            for start in range(0, counts.shape[1], step):
                yield counts[index, start : start + step]


def _running_sums(rows):
    """Cumulative sums over the rows of a ``(rows, copies)`` array (a new array).

    A Python loop of whole-row additions beats ``np.cumsum`` (one element at a time)
    several times over while the rows are few and the copies many, as here. Whole
    counts stay exact in float32 up to 2**24.
    """
    cumulative = np.array(rows)
    for row in range(1, cumulative.shape[0]):
        cumulative[row] += cumulative[row - 1]
    return cumulative


def weighted_quantiles(ordered, weights, probabilities):
    """Quantiles of weighted copies of a sample, as ``np.percentile`` (linear) of each copy.

    The value of rank ``r`` of a copy is the first row whose running weight exceeds ``r``,
    found by one bisection run on all copies and ranks at once.

    Parameters
    ----------
    ordered : ndarray, shape (m,)
        The sample, finite and sorted ascending.
    weights : ndarray, shape (m, B)
        Whole-number repetition counts of each value in each of ``B`` copies.
    probabilities : sequence of float
        In ``[0, 1)``.

    Returns
    -------
    list of ndarray, shape (B,)
        One array per probability; NaN for a copy with no values.
    """
    width, copies = weights.shape
    running = _running_sums(weights)
    total = running[-1].astype(np.float64)
    # every rank of every probability in one bisection: (2 * len(probabilities), B)
    positions = np.outer(probabilities, total - 1.0)
    below = np.floor(positions)
    ranks = np.concatenate([below, below + 1.0])
    columns = np.broadcast_to(np.arange(copies), ranks.shape)
    low, high = np.zeros(ranks.shape, dtype=np.int64), np.full(ranks.shape, width, dtype=np.int64)
    for _ in range(width.bit_length()):
        middle = (low + high) // 2
        right = running[np.minimum(middle, width - 1), columns] <= ranks
        low, high = np.where(right, middle + 1, low), np.where(right, high, middle)
    values = ordered[np.minimum(low, width - 1)]
    first, second = values[: len(probabilities)], values[len(probabilities) :]
    quantiles = first + (positions - below) * (second - first)
    return list(np.where(total > 0, quantiles, np.nan))


def _ratio_statistics(error, truth, weights):
    """The :data:`SUMMARY_KEYS` statistics of ``error / truth`` for each column of weights.

    The rows must be sorted by ``error / truth``. Mean and spread are taken about the
    plain sample mean, so the spread of a sample of identical ratios is exactly 0.
    """
    ratio = error / truth
    centre = np.mean(ratio)
    shifted = ratio - centre
    rows = np.stack([np.ones_like(ratio), shifted, shifted**2, error**2, truth**2])
    # einsum: no threaded BLAS, whose start-up costs more than this product on busy cores
    total, first, second, error_squares, truth_squares = np.einsum(
        "ij,jk->ik", rows.astype(weights.dtype), weights
    )
    with np.errstate(divide="ignore", invalid="ignore"):
        first, second = first / total, second / total
        variance = (second - first**2) * total / (total - 1.0)
        rms = np.sqrt(error_squares / truth_squares)
    q25, q50, q75 = weighted_quantiles(ratio, weights, (0.25, 0.5, 0.75))
    return {
        "systematic": centre + first,
        "random": np.where(total > 1, np.sqrt(np.maximum(variance, 0.0)), np.nan),
        "median": q50,
        "iqr": q75 - q25,
        "rms_normalized": rms,
    }


def _interval(resampled):
    """Percentile 95 % interval of bootstrap values, ``None`` when most are undefined."""
    finite = resampled[np.isfinite(resampled)]
    if finite.size == 0 or finite.size < 0.5 * resampled.size:
        return None
    low, high = np.percentile(finite, [2.5, 97.5])
    return [float(low), float(high)]


def _bootstrap_intervals(statistic, bootstrap, row_ids, keys):
    """Intervals of the statistics ``statistic(weights)`` returns, keyed as ``keys``."""
    blocks = [statistic(weights) for weights in bootstrap.weight_blocks(row_ids)]
    if not blocks:
        return dict.fromkeys(keys)
    return {key: _interval(np.concatenate([block[key] for block in blocks])) for key in keys}


def _own_bootstrap(ids, bootstrap):
    return bootstrap if bootstrap is not None else TracerBootstrap(ids)


def error_summary(error, truth, ids=None, bootstrap=None, condition=True):
    """Summary ``S`` of the relative error ``error / truth`` (fractions, not percent).

    Parameters
    ----------
    error, truth : array_like, 1-D, same shape
        Absolute error and true value; rows whose truth is zero or whose error is not
        finite are left out of the ratios (``n`` says how many remain).
    ids : array_like of int, optional
        Tracer of each row: the rows of a tracer are resampled together. Default: every
        row is its own tracer.
    bootstrap : TracerBootstrap, optional
        The resamples (over a superset of ``ids``); default: new ones over ``ids``.
    condition : bool
        Also summarise the rows with ``|truth| ≥ CONDITION_FRACTION · rms(truth)``.

    Returns
    -------
    dict
        ``systematic`` (mean of ``error/truth``, the paper's), ``random`` (its standard
        deviation, ``ddof=1``, the paper's), ``median``, ``iqr`` (75th minus 25th
        percentile), ``rms_normalized`` (``rms(error) / rms(truth)``, robust where
        ``truth ≈ 0``), ``n``, ``ci95`` (the bootstrap 95 % interval ``[lo, hi]`` of each
        statistic) and, with ``condition``, ``conditioned``: the same over the rows with
        ``|truth| ≥ truth_floor`` plus ``truth_floor`` and ``truth_floor_over_rms``.
        ``None`` where the sample is too small.
    """
    error = np.asarray(error, dtype=np.float64)
    truth = np.asarray(truth, dtype=np.float64)
    ids = np.arange(error.size) if ids is None else np.asarray(ids, dtype=np.int64)
    usable = np.isfinite(error) & np.isfinite(truth) & (truth != 0)
    # sorted by ratio, as the quantiles of the resamples need
    order = np.argsort(error[usable] / truth[usable], kind="stable")
    error, truth, ids = error[usable][order], truth[usable][order], ids[usable][order]
    summary = {key: None for key in SUMMARY_KEYS}
    summary["n"] = int(error.size)
    summary["ci95"] = dict.fromkeys(SUMMARY_KEYS)
    if error.size:
        bootstrap = _own_bootstrap(ids, bootstrap)
        values = _ratio_statistics(error, truth, np.ones((error.size, 1)))
        summary.update({key: _finite_or_none(values[key][0]) for key in SUMMARY_KEYS})
        summary["ci95"] = _bootstrap_intervals(
            lambda weights: _ratio_statistics(error, truth, weights),
            bootstrap,
            ids,
            SUMMARY_KEYS,
        )
        if summary["random"] is None:
            summary["ci95"]["random"] = None
    if condition:
        floor = CONDITION_FRACTION * math.sqrt(np.mean(truth**2)) if truth.size else None
        strong = np.abs(truth) >= floor if floor is not None else np.zeros(0, dtype=bool)
        summary["conditioned"] = {
            "truth_floor": floor,
            "truth_floor_over_rms": CONDITION_FRACTION,
            **error_summary(error[strong], truth[strong], ids[strong], bootstrap, False),
        }
    return summary


def scott_bandwidth(sample):
    """Scott's bandwidth of a Gaussian KDE of a 1-D sample (as ``scipy.stats.gaussian_kde``)."""
    return float(np.std(sample, ddof=1)) * sample.size ** (-0.2)


def kde_modes(sample, bandwidth, weights):
    """Mode of a Gaussian kernel density estimate, for each column of weights.

    The sample is binned linearly onto :data:`PEAK_BINS` points spanning it plus three
    bandwidths on each side, smoothed with the Gaussian (by FFT), and the mode refined by
    a parabola through the highest point and its neighbours: the binning moves it by well
    under 1 % of a bandwidth. The grid follows the sample, so the mode of ``sample + c``
    is the mode of ``sample`` plus ``c``, to rounding.

    Parameters
    ----------
    sample : ndarray, shape (m,)
        Finite values, not all equal.
    bandwidth : float
        Kernel standard deviation (``sample`` units), the same for every column.
    weights : ndarray, shape (m, B)
        Weight of each value in each of ``B`` estimates.

    Returns
    -------
    ndarray, shape (B,)
    """
    from scipy.signal import fftconvolve
    from scipy.sparse import csr_matrix

    low = sample.min() - 3.0 * bandwidth
    spacing = (sample.max() + 3.0 * bandwidth - low) / (PEAK_BINS - 1)
    position = (sample - low) / spacing
    left = np.minimum(np.floor(position).astype(np.int64), PEAK_BINS - 2)
    share = position - left
    rows = np.arange(sample.size)
    binning = csr_matrix(
        (
            np.concatenate([1.0 - share, share]),
            (np.tile(rows, 2), np.concatenate([left, left + 1])),
        ),
        shape=(sample.size, PEAK_BINS),
    )
    counts = np.asarray(binning.T @ weights.astype(np.float64))
    sigma = bandwidth / spacing
    offsets = np.arange(-math.ceil(4.0 * sigma), math.ceil(4.0 * sigma) + 1)
    kernel = np.exp(-0.5 * (offsets / sigma) ** 2)
    density = fftconvolve(counts, kernel[:, None], mode="same", axes=0)
    top = np.clip(np.argmax(density, axis=0), 1, PEAK_BINS - 2)
    copies = np.arange(density.shape[1])
    below, at, above = (density[top + k, copies] for k in (-1, 0, 1))
    curvature = below - 2.0 * at + above
    with np.errstate(divide="ignore", invalid="ignore"):
        offset = np.where(curvature < 0, 0.5 * (below - above) / curvature, 0.0)
    return low + (top + offset) * spacing


def pdf_peak(values, log=False):
    """Position of the peak (mode) of the PDF of a sample, by kernel density estimation.

    Gaussian kernel of Scott's bandwidth, binned (:func:`kde_modes`).

    Parameters
    ----------
    values : array_like, 1-D
    log : bool
        Peak of the PDF of ``log10(values)`` (positive values only): the peak of
        ``c * values`` is then ``c`` times the peak of ``values``.

    Returns
    -------
    float or None
        The mode, in ``values`` units; with ``log``, ``0.0`` for a sample with no positive
        value (the position errors of a uniform medium are all exactly zero); ``None``
        for a sample with no finite value at all.
    """
    sample = np.asarray(values, dtype=np.float64).ravel()
    sample = sample[np.isfinite(sample)]
    if sample.size == 0:
        return None
    if log:
        sample = np.log10(sample[sample > 0])
        if sample.size == 0:
            return 0.0
    if np.ptp(sample) == 0:
        mode = sample[0]
    else:
        mode = kde_modes(sample, scott_bandwidth(sample), np.ones((sample.size, 1)))[0]
    return float(10.0**mode if log else mode)


def position_summary(vectors, ids, length, pixel_size, bootstrap=None):
    """Peak and median of ``|ε_x| / L``, with their bootstrap 95 % intervals.

    Parameters
    ----------
    vectors : tuple of two ndarray, shape (rows,)
        Position errors ``(ε_2, ε_3)`` (field length units), one row per tracer and frame.
    ids : ndarray of int, shape (rows,)
        Tracer of each row.
    length, pixel_size : float
        ``L`` and the pixel size (field length units).
    bootstrap : TracerBootstrap, optional

    Returns
    -------
    dict
        ``position_error_peak_over_L`` (mode of a Gaussian KDE of ``log10(|ε_x| / L)``;
        0 when every error is exactly 0; ``None`` for no finite error),
        ``position_error_peak_px``, ``position_error_median_over_L``, and for each of
        them ``<key>_ci95`` (``[lo, hi]`` or ``None``). The peak's bootstrap keeps the
        full sample's bandwidth.
    """
    values = np.hypot(*vectors) / length
    finite = np.isfinite(values)
    order = np.argsort(values[finite], kind="stable")  # the median's resamples need it
    values, ids = values[finite][order], np.asarray(ids, dtype=np.int64)[finite][order]
    peak = pdf_peak(values, log=True)
    median = _finite_or_none(np.median(values)) if values.size else None
    peak_ci = median_ci = None
    if values.size:
        bootstrap = _own_bootstrap(ids, bootstrap)
        median_ci = _bootstrap_intervals(
            lambda weights: {"median": weighted_quantiles(values, weights, (0.5,))[0]},
            bootstrap,
            ids,
            ("median",),
        )["median"]
        positive = values > 0
        logs = np.log10(values[positive])
        if logs.size > 1 and np.ptp(logs) > 0:
            bandwidth = scott_bandwidth(logs)
            log_ci = _bootstrap_intervals(
                lambda weights: {"peak": kde_modes(logs, bandwidth, weights)},
                bootstrap,
                ids[positive],
                ("peak",),
            )["peak"]
            peak_ci = None if log_ci is None else [10.0 ** log_ci[0], 10.0 ** log_ci[1]]
        elif peak is not None:
            peak_ci = [peak, peak]
    to_px = length / pixel_size
    return {
        "position_error_peak_over_L": peak,
        "position_error_peak_over_L_ci95": peak_ci,
        "position_error_peak_px": None if peak is None else peak * to_px,
        "position_error_peak_px_ci95": None if peak_ci is None else [v * to_px for v in peak_ci],
        "position_error_median_over_L": median,
        "position_error_median_over_L_ci95": median_ci,
    }


def _vector_errors(table, symbol, measured, reference, bootstrap):
    """Relative-error summaries of one vector quantity: components, magnitude, angle.

    ``measured`` and ``reference`` are the vectors ``(v2, v3)`` compared; the error is
    their difference and the truth (denominator) is always the ``true`` column.
    """
    true = (table[f"{symbol}2_true"], table[f"{symbol}3_true"])
    ids = table["id"]
    angles = angle_deg(measured, reference)
    return {
        f"{symbol}2": error_summary(measured[0] - reference[0], true[0], ids, bootstrap),
        f"{symbol}3": error_summary(measured[1] - reference[1], true[1], ids, bootstrap),
        "magnitude": error_summary(
            np.hypot(*measured) - np.hypot(*reference), np.hypot(*true), ids, bootstrap
        ),
        "angle_deg_median": _finite_or_none(np.median(angles)) if angles.size else None,
    }


def _columns(table, symbol, kind):
    return (table[f"{symbol}2_{kind}"], table[f"{symbol}3_{kind}"])


def _empty_kinematic(symbol):
    """A kinematic table with no rows (a render file of too few frames)."""
    names = ["id", *(f"{symbol}{c}_{k}" for c in "23" for k in ("true", "ref", "meas"))]
    return {name: np.zeros(0) for name in names}


def _has_optics(table, symbol):
    return all(name in table for name in OPTICS_COLUMNS[symbol])


def _kinematic_blocks(tables, kept):
    """``{group: (symbol, kept rows)}`` of the kinematic groups the file holds."""
    blocks = {}
    for group, symbol, _, needed_from in KINEMATIC_GROUPS:
        table = getattr(tables, group)
        if table:
            blocks[group] = (symbol, rows_of(table, kept))
        elif needed_from is not None:
            blocks[group] = (symbol, _empty_kinematic(symbol))
    return blocks


def _budget_part(tracers, blocks, length, pixel_size, bootstrap, part):
    """The ``optics`` or ``imaging`` block: position and kinematic errors of that part."""
    optical = position_error_vectors(tracers, "opt", "opt_ref")
    if part == "optics":
        position = optical
    else:
        total = position_error_vectors(tracers)
        position = (total[0] - optical[0], total[1] - optical[1])
    block = position_summary(position, tracers["id"], length, pixel_size, bootstrap)
    for group, (symbol, table) in blocks.items():
        if not _has_optics(table, symbol):
            continue
        opt, opt_ref = _columns(table, symbol, "opt"), _columns(table, symbol, "opt_ref")
        if part == "optics":
            measured, reference = opt, opt_ref
        else:
            # the error the camera adds (total minus optics), on top of the reference
            reference = _columns(table, symbol, "ref")
            meas = _columns(table, symbol, "meas")
            measured = tuple(
                m - (o - o_ref) for m, o, o_ref in zip(meas, opt, opt_ref, strict=True)
            )
        block[group] = _vector_errors(table, symbol, measured, reference, bootstrap)
    return block


#: Position statistics followed for convergence, besides the kinematic ones.
POSITION_HEADLINES = ("position_error_peak_over_L", "position_error_median_over_L")


def _refraction_errors(tables, tracers, blocks, bootstrap):
    """Position summary and per kinematic group the refraction errors (``meas - ref``)."""
    errors = position_summary(
        position_error_vectors(tracers), tracers["id"], tables.length, tables.pixel_size, bootstrap
    )
    for group, (symbol, table) in blocks.items():
        errors[group] = _vector_errors(
            table,
            symbol,
            _columns(table, symbol, "meas"),
            _columns(table, symbol, "ref"),
            bootstrap,
        )
    return errors


def _headlines(errors, blocks):
    """``{path: (value, ci95)}`` of the statistics followed for convergence."""
    pairs = {(key,): (errors[key], errors[f"{key}_ci95"]) for key in POSITION_HEADLINES}
    for group, (symbol, _) in blocks.items():
        for component in (f"{symbol}2", f"{symbol}3", "magnitude"):
            summary = errors[group][component]
            for prefix, part in (("", summary), ("conditioned_", summary["conditioned"])):
                for key in SUMMARY_KEYS:
                    pairs[(group, component, prefix + key)] = (part[key], part["ci95"][key])
    return pairs


def not_converged(values, intervals):
    """Whether a statistic keeps growing with the number of tracers.

    Criterion: its magnitude grows over the last three nested subsamples
    (``|v(N/4)| < |v(N/2)| < |v(N)|``) and the full-sample value lies outside the 95 %
    interval of the ``N/4`` subsample. A statistic that converges fails the first test
    about as often as not and the second only rarely.

    Parameters
    ----------
    values : list of float or None
        The statistic at ``N/16, N/8, N/4, N/2, N`` tracers (the last three are used).
    intervals : list of [lo, hi] or None
        Their bootstrap 95 % intervals.
    """
    if len(values) < 3 or any(v is None for v in values[-3:]) or intervals[-3] is None:
        return False
    quarter, half, full = (abs(v) for v in values[-3:])
    low, high = intervals[-3]
    return quarter < half < full and not low <= values[-1] <= high


def convergence(tables, kept, blocks, full):
    """The headline statistics of the refraction errors against nested tracer subsamples.

    Parameters
    ----------
    tables : RenderTables
    kept : ndarray of int
        Ids of the tracers used (``N``).
    blocks : dict
        ``{group: (symbol, kept rows)}`` (:func:`_kinematic_blocks`).
    full : dict
        The refraction errors of all ``N`` tracers (:func:`_refraction_errors`).

    Returns
    -------
    dict
        ``n_tracers`` (the subsample sizes, ``N/16 … N``, each holding the previous
        ones), ``seed``; per kinematic group and component ``{statistic: {"value": [...],
        "ci95": [...]}}`` for the :data:`SUMMARY_KEYS` and their ``conditioned_`` versions;
        the :data:`POSITION_HEADLINES` likewise; ``not_converged``: the dotted names
        (``velocity.u3.random``) of the statistics :func:`not_converged` marks.
    """
    order = np.random.default_rng(CONVERGENCE_SEED).permutation(kept)
    sizes = sorted({kept.size // d for d in CONVERGENCE_DIVISORS if kept.size // d >= 2})
    levels = []
    for size in sizes:
        if size == kept.size:
            levels.append(_headlines(full, blocks))
            continue
        subset = np.sort(order[:size])
        subset_blocks = {g: (symbol, rows_of(t, subset)) for g, (symbol, t) in blocks.items()}
        errors = _refraction_errors(
            tables, rows_of(tables.tracers, subset), subset_blocks, TracerBootstrap(subset)
        )
        levels.append(_headlines(errors, blocks))
    result = {"n_tracers": sizes, "seed": CONVERGENCE_SEED, "not_converged": []}
    for path in levels[0] if levels else ():
        values = [level[path][0] for level in levels]
        intervals = [level[path][1] for level in levels]
        node = result
        for name in path[:-1]:
            node = node.setdefault(name, {})
        node[path[-1]] = {"value": values, "ci95": intervals}
        if not_converged(values, intervals):
            result["not_converged"].append(".".join(path))
    return result


def discrete_mode(values, resolution):
    """Mode of a sample of values that come in steps of ``resolution`` (e.g. ΔA / A).

    The histogram's bins are whole multiples of the step, at least as wide as the
    Freedman–Diaconis width, centred on multiples of their width: a kernel estimate
    would put peaks between the only values the sample can take.

    Parameters
    ----------
    values : array_like, 1-D
    resolution : float
        The step of the values (> 0).

    Returns
    -------
    float or None
        Centre of the fullest bin; ``None`` for a sample with no finite value.
    """
    sample = np.asarray(values, dtype=np.float64)
    sample = sample[np.isfinite(sample)]
    if sample.size == 0:
        return None
    q25, q75 = np.percentile(sample, [25, 75])
    width = resolution * max(
        1.0, np.round(2.0 * (q75 - q25) * sample.size ** (-1 / 3) / resolution)
    )
    bins = np.round(sample / width).astype(np.int64)
    found, counts = np.unique(bins, return_counts=True)
    return float(found[np.argmax(counts)] * width)


def _area_change_peak(tracers):
    changes = area_changes(tracers)
    area_ref = tracers["area_ref"][tracers["area_ref"] > 0]
    if changes.size == 0:
        return None
    return discrete_mode(changes, 1.0 / float(np.median(area_ref)))


#: |ΔA/A| (90th percentile) above which tracer images count as reshaped in a verdict.
IMAGE_RESHAPED = 0.25


def budget_verdict(case):
    """Which part of the velocity error dominates a case: optics, imaging or the baseline.

    Parameters
    ----------
    case : dict
        A ``stats.json`` case with ``optics`` and ``imaging`` blocks.

    Returns
    -------
    dict or None
        ``quantity`` (the statistic compared: ``velocity.<u3>.rms_normalized``), its
        ``optics``, ``imaging``, ``total`` and ``baseline`` values, ``dominant`` (the
        largest of optics, imaging, baseline) and ``text``, one line for a reader.
        ``None`` without the blocks or the numbers.
    """
    if "optics" not in case or "velocity" not in case["optics"]:
        return None
    parts = {
        "optics": case["optics"]["velocity"]["u3"]["rms_normalized"],
        "imaging": case["imaging"]["velocity"]["u3"]["rms_normalized"],
        "total": case["velocity"]["u3"]["rms_normalized"],
        "baseline": case["baseline"]["velocity"]["u3"]["rms_normalized"],
    }
    if any(value is None for value in parts.values()):
        return None
    contenders = {name: parts[name] for name in ("optics", "imaging", "baseline")}
    dominant = max(contenders, key=contenders.get)
    words = [f"{case['name']}: {dominant} dominates rms(ε_u3)/rms(u3)"]
    optics, imaging = parts["optics"], parts["imaging"]
    if optics > 0 and imaging > 0:
        larger, smaller = ("imaging", "optics") if imaging >= optics else ("optics", "imaging")
        words.append(f"{larger} {max(optics, imaging) / min(optics, imaging):.2g}× {smaller}")
    if parts["total"] > 0:
        words.append(f"baseline {parts['baseline'] / parts['total']:.2g}× refraction")
    area = case.get("area_change_p90")
    if dominant == "imaging" and area is not None:
        # the typical image may keep its size (the peak of ΔA/A at 0) while a tenth changes
        words.append(
            f"tracer images change size (|ΔA/A| 90th percentile {area:.2g}): the ray cloud "
            "reshapes the image and the threshold cuts it"
            if area > IMAGE_RESHAPED
            else f"images keep their size (|ΔA/A| 90th percentile {area:.2g}): rendering and "
            "rounding noise"
        )
    return {
        "quantity": "velocity.u3.rms_normalized",
        **parts,
        "dominant": dominant,
        "text": "; ".join(words),
    }


def case_statistics(tables):
    """The ``stats.json`` entry of one case.

    Parameters
    ----------
    tables : RenderTables

    Returns
    -------
    dict
        Keys documented in the README (``name``, ``G``, ``delta_n_max``, ``n_tracers``,
        ``n_used``, ``n_excluded``, ``position_error_*`` with ``*_ci95``, ``velocity``,
        ``acceleration`` (and ``velocity_fit``, ``acceleration_fit`` where the file has
        them), ``baseline``, ``optics`` and ``imaging`` (where the file has the optics
        columns), ``budget_verdict``, ``convergence``, ``area_change_peak``,
        ``circularity_peak``, ``rays``).
    """
    excluded_ids, excluded_counts = flagged_tracers(tables)
    noted_ids, noted_counts = flagged_tracers(tables, NOTE_COLUMN)
    all_ids = np.unique(tables.tracers["id"].astype(np.int64))
    kept = np.setdiff1d(all_ids, excluded_ids)
    bootstrap = TracerBootstrap(kept)
    tracers = rows_of(tables.tracers, kept)
    blocks = _kinematic_blocks(tables, kept)
    rays_total = int(np.sum(tables.tracers["n_rays"]))
    case = {
        "name": tables.case,
        "G": _finite_or_none(tables.k_rho),
        "delta_n_max": tables.delta_n_max,
        "length_L": tables.length,
        "pixel_size_over_L": tables.pixel_size / tables.length,
        "dt": tables.dt,
        "n_tracers": int(all_ids.size),
        "n_used": int(kept.size),
        "n_excluded": excluded_counts,
        "n_noted": noted_counts,
        "n_used_noted": int(np.setdiff1d(noted_ids, excluded_ids).size),
    }
    refraction = _refraction_errors(tables, tracers, blocks, bootstrap)
    case.update(refraction)
    case["baseline"] = {
        group: _vector_errors(
            table,
            symbol,
            _columns(table, symbol, "ref"),
            _columns(table, symbol, "true"),
            bootstrap,
        )
        for group, (symbol, table) in blocks.items()
    }
    if all(name in tracers for name in OPTICS_COLUMNS["x"]):
        for part in ("optics", "imaging"):
            case[part] = _budget_part(
                tracers, blocks, tables.length, tables.pixel_size, bootstrap, part
            )
    case["area_change_peak"] = _area_change_peak(tracers)
    changes = area_changes(tracers)
    changes = np.abs(changes[np.isfinite(changes)])
    case["area_change_p90"] = float(np.percentile(changes, 90)) if changes.size else None
    case["circularity_peak"] = pdf_peak(tracers["circularity_meas"])
    case["convergence"] = convergence(tables, kept, blocks, refraction)
    case["budget_verdict"] = budget_verdict(case)
    case["rays"] = {
        "n_rays": rays_total,
        "n_rays_ok": int(np.sum(tables.tracers["n_rays_ok"])),
        "status_counts": tables.ray_counts["measured"],
        "reference_status_counts": tables.ray_counts["reference"],
    }
    return case


def check_cases(all_tables):
    """Sort render tables by Δn_max and refuse two files of the same case name."""
    if not all_tables:
        raise RimclError("no render files given")
    names = [tables.case for tables in all_tables]
    duplicates = sorted({name for name in names if names.count(name) > 1})
    if duplicates:
        raise RimclError(f"more than one render file for case {', '.join(duplicates)}")
    # by index difference: G cases of one field in order of G, fluid cases in order of ΔT
    return sorted(all_tables, key=lambda tables: tables.delta_n_max)


METHODS = {
    "position_error_peak": "mode of a Gaussian KDE (Scott) of log10(|x_meas - x_ref| / L)",
    "excluded": "a tracer with any flag in any row is left out of its case",
    "ci95": (
        f"bootstrap percentile interval (2.5 %, 97.5 %) of {BOOTSTRAP_RESAMPLES} resamples "
        f"of the tracers (with replacement, all rows of a tracer together, seed "
        f"{BOOTSTRAP_SEED}); the position peak's resamples keep the full sample's bandwidth"
    ),
    "conditioned": (
        f"rows with |truth| >= {CONDITION_FRACTION} rms(truth) (rms over the component's "
        "usable rows of the case)"
    ),
    "convergence": (
        "nested random subsamples of N/16 ... N tracers; not converged: the magnitude grows "
        "over N/4 < N/2 < N and the value at N lies outside the 95 % interval at N/4"
    ),
    "area_change_peak": "centre of the fullest bin of a histogram of whole-pixel steps",
    "area_change_p90": "90th percentile of |ΔA/A| over the rows with a reference image",
}


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
        **METHODS,
    }
    if config:
        record.update(config)
    return {
        "cases": [case_statistics(tables) for tables in all_tables],
        "config": record,
        "versions": versions(),
    }


def run_stats(paths, out_dir, overwrite=False, figures=True, config=None):
    """Statistics (and figures) of several ``rimcl render`` files: what ``rimcl stats`` does.

    Parameters
    ----------
    paths : sequence of str or Path
        Render files, one per case.
    out_dir : str or Path
        Output directory (created if missing): ``stats.json`` and, with ``figures``, the
        figures with their data (see :mod:`rimcl.stats.figures`).
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
        # figures draw what the statistics computed; they never import this module
        from rimcl.stats.figures import write_figures

        write_figures(all_tables, stats, out_dir / "figures", overwrite=True)
    write_json(stats_path, stats, overwrite=True)
    return stats
