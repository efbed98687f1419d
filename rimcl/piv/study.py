"""PIV errors of one refractive-index case: images, vectors, errors, statistics.

Per vector of the final PIV grid (pixels; ``dx`` along ``x2``, ``dy`` along ``x3``):

- **refraction** error: the vector measured on the pair seen through the field minus the
  vector measured on the same tracers seen through a uniform medium;
- **optics** part of it: the window average (tracers weighted by ``I_A · I_B``, assigned by
  their true midpoint as the truth is) of the change between exposures of each tracer's
  mean ray image point, through the field minus through the uniform medium (no
  pixels, no correlation); ``refraction - optics`` is what imaging and correlation add;
- **baseline**: the uniform-medium vector minus the window-averaged true displacement (the
  PIV method's own error: finite windows, gradients, lost pairs, sub-pixel fit).

Statistics take the shapes of :mod:`rimcl.stats.summaries` (``error_summary`` of the relative errors
of ``u2``, ``u3`` and ``|u|``, with velocities ``u = d · pixel_size / Δt``), over the vectors
valid in both measurements whose window holds tracers. A vector replaced by the outlier
test in either measurement is left out and counted.

The lead's study calls :func:`run_piv_case` once per case, offering the references made
so far (tracers, truth, uniform-medium frames and vectors are the same for every case of a
configuration; a lens camera, focused in each case's mean index, makes one per case).
"""

import dataclasses
import json
import math
import time
from pathlib import Path

import h5py
import numpy as np

from rimcl.core.atomic import atomic_path
from rimcl.core.errors import RimclError
from rimcl.core.fingerprint import input_changes
from rimcl.core.provenance import stamp_h5, to_json
from rimcl.core.tables_h5 import label_grid
from rimcl.piv.analysis import (
    PivSettings,
    WindowGrid,
    analyze_pair,
    check_piv_memory,
    vector_unit,
)
from rimcl.piv.imaging_config import IMAGE_AXES, PivImaging, frame_pixels
from rimcl.piv.render import PivConfig, run_piv_render
from rimcl.piv.truth import window_means
from rimcl.stats.summaries import error_summary
from rimcl.stats.tables import angle_deg

SCHEMA = "piv_case"
SCHEMA_VERSION = 1
#: Attribute of a study's PIV case file holding the scene it was made for (JSON).
STUDY_RECORD = "study_scene"
#: Folder of the PIV case files in a study directory.
STUDY_FOLDER = "piv"
#: Per-vector arrays of a case (all of shape (rows, columns) of the final PIV grid).
VECTOR_COLUMNS = (
    "x",
    "y",
    "dx_field",
    "dy_field",
    "dx_uniform",
    "dy_uniform",
    "dx_true",
    "dy_true",
    "dx_optics",
    "dy_optics",
    "peak_ratio_field",
    "peak_ratio_uniform",
    "valid_field",
    "valid_uniform",
    "dx_floor",
    "dy_floor",
    "valid_floor",
    "truth_weight",
    "truth_tracers",
    "used",
)


@dataclasses.dataclass
class PivCaseReference:
    """What every case of a study shares: tracers, truth, uniform-medium pair and vectors.

    Attributes
    ----------
    render : rimcl.piv.render.PivReference
    settings : rimcl.piv.analysis.PivSettings
    uniform_vectors : rimcl.piv.analysis.PivResult
    floor_vectors : rimcl.piv.analysis.PivResult
        Of the noise floor's second uniform-medium pair (the uniform vectors on a noiseless
        sensor).
    """

    render: object
    settings: PivSettings
    uniform_vectors: object
    floor_vectors: object = None


@dataclasses.dataclass
class PivCase:
    """One case: its images, both vector fields, per-vector errors and statistics.

    Attributes
    ----------
    render : rimcl.piv.render.PivRender
    field_vectors, uniform_vectors : rimcl.piv.analysis.PivResult
    vectors : dict of str to ndarray
        :data:`VECTOR_COLUMNS`, each (rows, columns); displacements in pixels.
    stats : dict
        :func:`case_statistics`.
    reference : PivCaseReference
        Pass it to the next case.
    seconds : dict of str to float
        Wall time: ``render`` (trace and render), ``piv`` (correlation), ``errors``.
    """

    render: object
    field_vectors: object
    uniform_vectors: object
    vectors: dict
    stats: dict
    reference: PivCaseReference
    seconds: dict


def optics_error(render, grid):
    """Window averages of the per-tracer optics displacement error (pixels).

    Per tracer: ``(m_B - m_A)`` through the field minus the same through the uniform
    medium, ``m`` the mean image point of its collected rays. Tracers with no collected ray
    in any of the four images are left out.

    Parameters
    ----------
    render : rimcl.piv.render.PivRender
    grid : rimcl.piv.analysis.WindowGrid

    Returns
    -------
    ndarray, float64, shape (rows, columns, 2)
        ``(dx, dy)`` of the optics part; NaN for a window without tracers.
    """
    field, uniform = render.field.optics, render.uniform.optics
    error = ((field[1] - field[0]) - (uniform[1] - uniform[0])) / render.pixel_size
    error = error * IMAGE_AXES  # (x2, x3) -> image (x, y): y runs down, along -x3
    shape = render.imaging.frame_shape(render.scene, render.camera)
    pixels = frame_pixels(render.renderer, shape, render.reference.positions[..., 1:])
    middle = 0.5 * (pixels[0] + pixels[1])
    means, _ = window_means(grid, middle[:, 0], middle[:, 1], error, render.reference.weights)
    return means


def per_vector(render, field_vectors, uniform_vectors, floor_vectors=None):
    """The per-vector table of a case (:data:`VECTOR_COLUMNS`).

    Parameters
    ----------
    render : rimcl.piv.render.PivRender
    field_vectors, uniform_vectors : rimcl.piv.analysis.PivResult
        On the grid of the truth (same window and overlap).
    floor_vectors : rimcl.piv.analysis.PivResult, optional
        The noise floor's second uniform-medium pair (default: the uniform vectors, a
        noiseless sensor's).

    Returns
    -------
    dict of str to ndarray, each (rows, columns)
    """
    truth = render.reference.truth
    if field_vectors.x.shape != truth["x"].shape or not np.array_equal(field_vectors.x, truth["x"]):
        raise RimclError(
            "the PIV vectors and the truth lie on different window grids: analyse with the "
            "window and overlap the truth was averaged over"
        )
    grid = WindowGrid.for_image(
        field_vectors.image_shape, field_vectors.window, field_vectors.settings.overlap
    )
    optics = optics_error(render, grid)

    def usable(result):
        return result.valid & np.isfinite(result.dx) & np.isfinite(result.dy)

    floor_vectors = uniform_vectors if floor_vectors is None else floor_vectors
    valid_field, valid_uniform = usable(field_vectors), usable(uniform_vectors)
    has_truth = (truth["tracers"] > 0) & np.isfinite(truth["dx"]) & np.isfinite(truth["dy"])
    # copies: the truth and the uniform-medium vectors are shared by every case of a study
    table = {
        "x": field_vectors.x,
        "y": field_vectors.y,
        "dx_field": field_vectors.dx,
        "dy_field": field_vectors.dy,
        "dx_uniform": uniform_vectors.dx,
        "dy_uniform": uniform_vectors.dy,
        "dx_true": truth["dx"],
        "dy_true": truth["dy"],
        "dx_optics": optics[..., 0],
        "dy_optics": optics[..., 1],
        "peak_ratio_field": field_vectors.peak_ratio,
        "peak_ratio_uniform": uniform_vectors.peak_ratio,
        "valid_field": valid_field,
        "valid_uniform": valid_uniform,
        "dx_floor": floor_vectors.dx,
        "dy_floor": floor_vectors.dy,
        "valid_floor": usable(floor_vectors),
        "truth_weight": truth["weight"],
        "truth_tracers": truth["tracers"],
        "used": valid_field & valid_uniform & has_truth,
    }
    return {name: np.array(values) for name, values in table.items()}


def velocity_table(vectors, pixel_size, dt):
    """Velocities of the used vectors in the column layout of :mod:`rimcl.stats.render_file`.

    Returns
    -------
    dict of str to ndarray, 1-D
        ``u2_true, u3_true`` (window-averaged truth), ``u2_ref, u3_ref`` (uniform medium),
        ``u2_meas, u3_meas`` (through the field), ``u2_opt, u3_opt`` (uniform-medium vector
        plus the optics part), ``u2_floor, u3_floor`` (the noise floor's second uniform
        pair, NaN where its vector is not valid), in length units per time unit.
    """
    used = vectors["used"]
    factor = pixel_size / dt
    table = {}
    for suffix, column in (("true", "true"), ("ref", "uniform"), ("meas", "field")):
        table[f"u2_{suffix}"] = vectors[f"dx_{column}"][used] * factor
        table[f"u3_{suffix}"] = vectors[f"dy_{column}"][used] * factor
    floor_valid = vectors["valid_floor"][used]
    for name, column in (("u2_floor", "dx_floor"), ("u3_floor", "dy_floor")):
        table[name] = np.where(floor_valid, vectors[column][used], np.nan) * factor
    table["u2_opt"] = table["u2_ref"] + vectors["dx_optics"][used] * factor
    table["u3_opt"] = table["u3_ref"] + vectors["dy_optics"][used] * factor
    return table


def window_blocks(shape, overlap):
    """Bootstrap groups of a vector grid: blocks of ``k x k`` neighbouring vectors, ``k``
    the number of grid steps one window spans (2 at 50 % overlap), so that vectors whose
    windows share pixels are mostly resampled together.

    Parameters
    ----------
    shape : tuple of int
        ``(rows, columns)`` of the vector grid.
    overlap : float
        Window overlap, fraction in ``[0, 1)``.

    Returns
    -------
    ids : ndarray of int, shape ``shape``
        The block of each vector.
    k : int
    """
    k = max(1, math.ceil(1.0 / (1.0 - overlap) - 1e-9))
    rows, columns = np.indices(shape)
    return (rows // k) * -(-shape[1] // k) + columns // k, k


def vector_errors(table, measured, reference, ids=None):
    """Relative-error summaries of the velocity: ``u2``, ``u3``, magnitude and angle.

    The PIV counterpart of the PTV velocity block of :mod:`rimcl.stats.error_blocks` (same keys and
    :func:`rimcl.stats.summaries.error_summary` shapes); each vector is one sample.

    Parameters
    ----------
    table : dict of str to ndarray
        :func:`velocity_table`.
    measured, reference : str
        Suffixes of the columns compared (``meas``, ``opt``, ``ref`` or ``true``); the
        truth (denominator) is always the ``true`` column.
    ids : ndarray of int, optional
        Bootstrap group of each vector (:func:`window_blocks`); default: each its own.

    Returns
    -------
    dict
        ``u2, u3, magnitude`` summaries and ``angle_deg_median``.
    """
    true, meas, ref = ((table[f"u2_{k}"], table[f"u3_{k}"]) for k in ("true", measured, reference))
    angles = angle_deg(meas, ref)
    angles = angles[np.isfinite(angles)]  # the floor's invalid vectors are NaN
    return {
        "u2": error_summary(meas[0] - ref[0], true[0], ids),
        "u3": error_summary(meas[1] - ref[1], true[1], ids),
        "magnitude": error_summary(np.hypot(*meas) - np.hypot(*ref), np.hypot(*true), ids),
        "angle_deg_median": float(np.median(angles)) if angles.size else None,
    }


def _rms(values):
    values = np.asarray(values, dtype=np.float64)
    values = values[np.isfinite(values)]
    return float(np.sqrt(np.mean(values**2))) if values.size else None


def _max_abs(values):
    values = np.abs(np.asarray(values, dtype=np.float64))
    values = values[np.isfinite(values)]
    return float(values.max()) if values.size else None


def case_statistics(render, vectors, settings):
    """Statistics of one case, in the shapes of :func:`rimcl.stats.document.case_statistics`.

    Returns
    -------
    dict
        ``name, G, delta_n_max, length_L, pixel_size_over_L, dt``, ``length_m`` and
        ``time_s`` (the field's scales, None where unknown), ``motion`` (the motion
        model, :data:`rimcl.piv.tracer_motion.MOTION_SHEET` or ``MOTION_3D``), ``n_tracers,
        n_vectors, n_used, n_excluded`` (by reason), ``velocity`` (refraction error ``u' - u^ref``:
        ``u2, u3, magnitude`` error summaries and ``angle_deg_median``), ``optics`` (the
        optics part, same shape), ``baseline`` (``{"velocity": ...}``, ``u^ref - u``),
        ``displacement_px`` (rms and largest per-vector errors in pixels, by part),
        ``rays`` (status counts per medium), ``piv`` (settings); the intervals resample
        blocks of ``bootstrap_block_vectors`` x ``bootstrap_block_vectors`` neighbouring
        vectors together (:func:`window_blocks`: overlapping windows share pixels).
    """
    used = vectors["used"]
    table = velocity_table(vectors, render.pixel_size, render.dt)
    refraction = np.hypot(
        vectors["dx_field"] - vectors["dx_uniform"], vectors["dy_field"] - vectors["dy_uniform"]
    )[used]
    optics = np.hypot(vectors["dx_optics"], vectors["dy_optics"])[used]
    baseline = np.hypot(
        vectors["dx_uniform"] - vectors["dx_true"], vectors["dy_uniform"] - vectors["dy_true"]
    )[used]
    imaging = np.hypot(
        vectors["dx_field"] - vectors["dx_uniform"] - vectors["dx_optics"],
        vectors["dy_field"] - vectors["dy_uniform"] - vectors["dy_optics"],
    )[used]
    truth = np.hypot(vectors["dx_true"], vectors["dy_true"])[used]
    floor = np.hypot(
        vectors["dx_floor"] - vectors["dx_uniform"], vectors["dy_floor"] - vectors["dy_uniform"]
    )[used & vectors["valid_floor"]]
    length = render.scene.depth
    blocks, block_side = window_blocks(used.shape, settings.overlap)
    ids = blocks[used]
    return {
        "name": render.case,
        "G": render.k_rho if math.isfinite(render.k_rho) else None,  # fluid cases: none
        "delta_n_max": render.delta_n_max,
        "length_L": length,
        "pixel_size_over_L": render.pixel_size / length,
        "dt": render.dt,
        # metres per field length unit and seconds per field time unit, None where unknown
        "length_m": render.config.get("length_m"),
        "time_s": render.config.get("time_s"),
        "motion": render.motion,
        "n_tracers": int(render.reference.positions.shape[1]),
        "n_vectors": int(used.size),
        "n_used": int(np.count_nonzero(used)),
        "n_excluded": {
            "outlier_field": int(np.count_nonzero(~vectors["valid_field"])),
            "outlier_uniform": int(np.count_nonzero(~vectors["valid_uniform"])),
            "no_tracers": int(np.count_nonzero(vectors["truth_tracers"] == 0)),
        },
        "velocity": vector_errors(table, "meas", "ref", ids),
        "optics": vector_errors(table, "opt", "ref", ids),
        "baseline": {"velocity": vector_errors(table, "ref", "true", ids)},
        "noise_floor": {"velocity": vector_errors(table, "floor", "ref", ids)},
        "bootstrap_block_vectors": block_side,
        "displacement_px": {
            "truth_rms": _rms(truth),
            "refraction_rms": _rms(refraction),
            "refraction_max": _max_abs(refraction),
            "optics_rms": _rms(optics),
            "imaging_rms": _rms(imaging),
            "baseline_rms": _rms(baseline),
            "noise_floor_rms": _rms(floor),
        },
        "rays": {"field": render.field.ray_counts, "uniform": render.uniform.ray_counts},
        "saturated_pixels": {
            "field": render.field.saturated_pixels,
            "uniform": render.uniform.saturated_pixels,
        },
        "piv": settings.describe(),
    }


def run_piv_case(
    field=None,
    *,
    case=None,
    k_rho=None,
    piv=None,
    camera=None,
    integrator=None,
    fluid=None,
    run=None,
    reference=None,
    sensor=None,
    mie=None,
    progress=False,
):
    """PIV errors of one refractive-index case (module docstring).

    Parameters
    ----------
    field : str, Path or FieldFile, optional
        A rimcl field file with velocity (default: the shipped sample).
    case, k_rho :
        The case (``"C0"`` … ``"C4"``, ``"G=…"``, ``"dT=…"``, or ``k_rho``; 0 is a
        uniform medium).
    piv : rimcl.piv.render.PivConfig, optional
        Imaging, timing and correlation (``piv.settings``).
    camera, integrator, fluid, run, sensor, mie : optional
        The :mod:`rimcl.scene.config` objects of :func:`rimcl.piv.render.run_piv_render`.
    reference : PivCaseReference or sequence of PivCaseReference, optional
        ``PivCase.reference`` of an earlier case of the same configuration; a sequence
        offers candidates, the one made for this case's configuration is used (a lens is
        focused in each case's mean index: its reference is made per index).
    progress : bool
        A progress bar over the tracers imaged (on a terminal).

    Returns
    -------
    PivCase
    """
    piv = PivConfig() if piv is None else piv
    settings = piv.settings
    candidates = list(reference) if isinstance(reference, (list, tuple)) else [reference]
    candidates = [r for r in candidates if r is not None]
    if any(r.settings != settings for r in candidates):
        raise RimclError("the PIV reference was made with other correlation settings")
    start = time.perf_counter()
    render = run_piv_render(
        field,
        case=case,
        k_rho=k_rho,
        piv=piv,
        camera=camera,
        integrator=integrator,
        fluid=fluid,
        run=run,
        reference=[r.render for r in candidates]
        if isinstance(reference, (list, tuple))
        else (None if reference is None else reference.render),
        sensor=sensor,
        mie=mie,
        progress=progress,
    )
    middle = time.perf_counter()
    reference = next((r for r in candidates if r.render is render.reference), None)
    if reference is None:
        uniform_vectors = analyze_pair(*render.uniform.images, settings)
        floor = render.reference.floor
        floor_vectors = uniform_vectors if floor is None else analyze_pair(*floor.images, settings)
        reference = PivCaseReference(render.reference, settings, uniform_vectors, floor_vectors)
    field_vectors = analyze_pair(*render.field.images, settings)
    piv_done = time.perf_counter()
    vectors = per_vector(render, field_vectors, reference.uniform_vectors, reference.floor_vectors)
    stats = case_statistics(render, vectors, settings)
    end = time.perf_counter()
    seconds = {"render": middle - start, "piv": piv_done - middle, "errors": end - piv_done}
    stats["seconds"] = seconds
    return PivCase(
        render=render,
        field_vectors=field_vectors,
        uniform_vectors=reference.uniform_vectors,
        vectors=vectors,
        stats=stats,
        reference=reference,
        seconds=seconds,
    )


def write_piv_case(path, case, overwrite=True, record=None):
    """Write one case's per-vector table and statistics to HDF5 (``rimcl_schema = "piv_case"``).

    Datasets: :data:`VECTOR_COLUMNS` (pixels; ``x`` along ``x2``, ``y`` along ``x3``), and
    where the field's scales are known ``u_true_ms``, ``v_true_ms`` (the truth in m/s). Root
    attributes: ``case``, ``k_rho``, ``dt``, ``pixel_size``, ``motion``, ``stats`` (JSON),
    ``config``, ``versions``, ``length_m``, ``time_s`` and ``m_s_per_px`` where known, and
    with ``record`` (a study's scene) ``study_scene`` (JSON).
    """
    with atomic_path(path, overwrite=overwrite) as tmp, h5py.File(tmp, "w") as h5:
        h5.attrs["rimcl_schema"] = SCHEMA
        h5.attrs["schema_version"] = SCHEMA_VERSION
        h5.attrs["case"] = case.render.case
        h5.attrs["k_rho"] = case.render.k_rho
        h5.attrs["dt"] = case.render.dt
        h5.attrs["pixel_size"] = case.render.pixel_size
        h5.attrs["motion"] = case.render.motion
        h5.attrs["stats"] = to_json(case.stats)
        if record is not None:
            h5.attrs[STUDY_RECORD] = to_json(record)
        for name in VECTOR_COLUMNS:
            h5.create_dataset(name, data=case.vectors[name])
        # the field's scales, where known: the truth in m/s too (u along x2, v down the rows)
        m_s_per_px = case.render.m_s_per_px
        for name in ("length_m", "time_s"):
            if case.render.config.get(name) is not None:
                h5.attrs[name] = float(case.render.config[name])
        if m_s_per_px is not None:
            h5.attrs["m_s_per_px"] = m_s_per_px
            h5.create_dataset("u_true_ms", data=case.vectors["dx_true"] * m_s_per_px)
            h5.create_dataset("v_true_ms", data=case.vectors["dy_true"] * m_s_per_px)
        # named dimensions (row along x3, column along x2; window centres in pixels) and
        # units, for xarray.open_dataset(path)
        x, y = np.asarray(case.vectors["x"]), np.asarray(case.vectors["y"])
        label_grid(h5, y[:, 0], x[0, :], vector_unit)
        stamp_h5(h5, case.render.config, case.render.device)


def load_piv_case(path):
    """Read a file of :func:`write_piv_case`.

    Returns
    -------
    vectors : dict of str to ndarray
    stats : dict
    """
    try:
        with h5py.File(path, "r") as h5:
            schema = h5.attrs.get("rimcl_schema")
            if schema != SCHEMA:
                raise RimclError(f"{path} is not a rimcl PIV case file (rimcl_schema {schema!r})")
            vectors = {name: h5[name][()] for name in VECTOR_COLUMNS}
            stats = json.loads(h5.attrs["stats"])
    except OSError as exc:
        raise RimclError(f"{path} is not a readable HDF5 file ({exc})") from None
    return vectors, stats


def _ratio(numerator, denominator):
    if numerator is None or not denominator:
        return None
    ratio = numerator / denominator
    return ratio if math.isfinite(ratio) else None


def agreement_with_ptv(piv_stats, ptv_stats):
    """PIV against PTV refraction errors of the same case, side by side.

    Parameters
    ----------
    piv_stats : dict
        :func:`case_statistics` of one case.
    ptv_stats : dict
        The ``stats.json`` entry of the same case (:func:`rimcl.stats.document.case_statistics`).

    Returns
    -------
    dict
        For ``u2, u3, magnitude``: ``rms_normalized`` and ``median`` of each method and the
        ratio PIV / PTV of ``rms_normalized``; where the PTV entry has its optics part,
        also both optics parts' ``rms_normalized`` and their ratio (None where undefined).
    """
    ptv_optics = ptv_stats.get("optics", {}).get("velocity")
    result = {}
    for key in ("u2", "u3", "magnitude"):
        piv, ptv = piv_stats["velocity"][key], ptv_stats["velocity"][key]
        result[key] = {
            "piv_rms_normalized": piv["rms_normalized"],
            "ptv_rms_normalized": ptv["rms_normalized"],
            "piv_median": piv["median"],
            "ptv_median": ptv["median"],
            "ratio_rms_normalized": _ratio(piv["rms_normalized"], ptv["rms_normalized"]),
        }
        if ptv_optics is not None:
            piv_part = piv_stats["optics"][key]["rms_normalized"]
            ptv_part = ptv_optics[key]["rms_normalized"]
            result[key].update(
                piv_optics_rms_normalized=piv_part,
                ptv_optics_rms_normalized=ptv_part,
                optics_ratio_rms_normalized=_ratio(piv_part, ptv_part),
            )
    return result


def configs_from_study(study):
    """The PIV measurement of a study (``[piv]`` and the shared sections of its scene).

    The field, box, sheet, start frame, camera kind and optics, integrator, fluid, sensor,
    Mie weights, engine, device and tracer seed are the scene's (those of the PTV cases); the
    camera aims
    ``piv.rays`` rays per tracer (a plane camera a fan of ``round(√rays)²``).

    Parameters
    ----------
    study : rimcl.scene.study_config.StudyConfig

    Returns
    -------
    piv : rimcl.piv.render.PivConfig
    configs : dict
        ``camera``, ``integrator``, ``fluid``, ``run``, ``sensor``, ``mie`` for
        :func:`run_piv_case`.
    """
    shared, section = study.shared, study.piv
    rays = int(section.rays)
    piv = PivConfig(
        imaging=PivImaging(
            pixels=section.pixels,
            density=section.density,
            diameter=section.diameter,
            sheet_thickness=section.sheet_thickness,
            bit_depth=section.bit_depth,
        ),
        settings=PivSettings(window=section.window, overlap=section.overlap, passes=section.passes),
        dt=section.dt,
        start_frame=shared.time.start_frame,
        box=shared.box,
        x_sheet=shared.x_sheet,
        depth=shared.depth,
        seed=shared.tracers.seed,
        time_s=shared.time.time_s,
    )
    # the windows must fit the frames, and the analysis the memory, before a study writes
    check_piv_memory((piv.imaging.pixels,) * 2, piv.settings, "the study's PIV")
    camera = dataclasses.replace(shared.camera, fan=max(1, round(math.sqrt(rays))), pupil_rays=rays)
    configs = {
        "camera": camera,
        "integrator": shared.integrator,
        "fluid": shared.fluid,
        "run": shared.run,
        "sensor": shared.sensor,
        "mie": shared.mie,
    }
    return piv, configs


def study_case_path(out_dir, case):
    """PIV case file of one case in a study directory: ``DIR/piv/<case>.h5``."""
    return Path(out_dir) / STUDY_FOLDER / f"{case}.h5"


def case_file_problem(path, record, case):
    """Why a study's PIV case file cannot be kept, or None if it can.

    It is kept only if it is a complete PIV case file of ``case`` (its ``case``
    attribute, as the PTV case files are checked) made for the scene ``record``.

    Returns
    -------
    str or None
        One line saying why the file must be measured again.
    """
    try:
        with h5py.File(path, "r") as h5:
            complete = h5.attrs.get("rimcl_schema") == SCHEMA and "stats" in h5.attrs
            if not (complete and all(name in h5 for name in VECTOR_COLUMNS)):
                return "unreadable or incomplete"
            held = h5.attrs.get("case")
            recorded = h5.attrs.get(STUDY_RECORD)
            if held != case:
                return f"holds case {held!r}, not {case!r}"
            recorded = {} if recorded is None else json.loads(recorded)
            current = json.loads(to_json(record))
            if recorded != current:
                if _without_inputs(recorded) != _without_inputs(current):
                    return "made for another scene"
                # the same scene, a field file rewritten since: said as such
                changes = input_changes(recorded.get("inputs"), record.get("inputs", {}))
                return "; ".join(changes) if changes else "made for another scene"
    except (OSError, ValueError) as exc:
        return f"unreadable ({type(exc).__name__})"
    return None


def _without_inputs(record):
    return {key: value for key, value in record.items() if key != "inputs"}


def run_study_cases(
    study, out_dir, record, cases, *, force=False, report=None, before_write=None, progress=False
):
    """The PIV case files of a study: one per case, atomic and resumable.

    A case whose file has no :func:`case_file_problem` is kept (unless ``force``); the
    others are measured (one line saying why), each on the tracers, truth and
    uniform-medium vectors of an earlier case made for its configuration (a plane camera:
    the first case's; a lens, focused in each case's mean index: its own).

    Parameters
    ----------
    study : rimcl.scene.study_config.StudyConfig
    out_dir : str or Path
        The study directory; files go to ``DIR/piv/<case>.h5``.
    record : dict
        What identifies the scene (stored in each file, compared on resume).
    cases : list of (str, str or None)
        ``(name, case argument)`` pairs (:func:`rimcl.study.run.study_cases`).
    force : bool
        Measure every case again.
    report : callable, optional
        Called with one line of text per step.
    before_write : callable, optional
        Called without arguments before the first case file is written (the study writes
        its ``scene.toml`` then, once the scene has proven itself).
    progress : bool
        A progress bar over each case's tracers imaged (on a terminal).

    Returns
    -------
    paths : list of Path
        One per case, in the scene's order.
    ran : list of str
        Cases measured in this call.
    """
    say = report or (lambda line: None)
    piv, configs = configs_from_study(study)
    folder = Path(out_dir) / STUDY_FOLDER
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise RimclError(f"cannot create {folder}: {exc.strerror}") from None
    paths, ran, references = [], [], []
    for index, (name, argument) in enumerate(cases, start=1):
        path = study_case_path(out_dir, name)
        paths.append(path)
        step = f"[PIV {index}/{len(cases)}] {name}"
        reason = None if force or not path.exists() else case_file_problem(path, record, name)
        if path.exists() and not force and reason is None:
            say(f"{step}: finished earlier, kept ({path})")
            continue
        again = f"{path.name} {reason}; imaging and correlating again"
        say(f"{step}: " + (again if reason else "imaging and correlating"))
        start = time.perf_counter()
        case = run_piv_case(
            study.field_path or None,
            case=argument,
            piv=piv,
            reference=references,
            progress=progress,
            **configs,
        )
        if all(r is not case.reference for r in references):
            references.append(case.reference)
        if before_write is not None:
            before_write()
        write_piv_case(path, case, overwrite=True, record=record)
        ran.append(name)
        say(f"{step}: done in {time.perf_counter() - start:.1f} s")
    return paths, ran


def add_study_results(stats, paths):
    """Put the PIV results of a study's case files into its ``stats.json`` document.

    Each case entry gains ``piv`` (:func:`case_statistics`) and, where the PTV case ran,
    ``piv_vs_ptv`` (:func:`agreement_with_ptv`); a case without a PTV entry (``mode =
    "piv"``) gets one with ``name``, ``G``, ``delta_n_max`` and ``piv``.

    Parameters
    ----------
    stats : dict
        The ``stats.json`` document (``cases`` may be empty); changed in place.
    paths : list of Path
        PIV case files (:func:`write_piv_case`).

    Returns
    -------
    list of (dict, dict)
        The loaded cases (vectors, statistics), for
        :func:`rimcl.piv.figures.write_piv_figures`.
    """
    cases = [load_piv_case(path) for path in paths]
    entries = {entry["name"]: entry for entry in stats["cases"]}
    for _, piv_stats in cases:
        entry = entries.get(piv_stats["name"])
        if entry is None:
            entry = {key: piv_stats[key] for key in ("name", "G", "delta_n_max")}
            stats["cases"].append(entry)
        entry["piv"] = piv_stats
        if "velocity" in entry:
            entry["piv_vs_ptv"] = agreement_with_ptv(piv_stats, entry)
    return cases
