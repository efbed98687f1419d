"""Error statistics of synthetic PTV measurements.

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
- the noise floor ``x^floor - x^ref``, ``u^floor - u^ref``, ``a^floor - a^ref``: a second
  exposure of the reference with independent sensor noise against the first (the measured
  and reference images share the camera's noise draws, so the refraction errors hold none);
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

from pathlib import Path

import numpy as np

from rimcl.core.errors import RimclError
from rimcl.core.outputs import OutputSet
from rimcl.core.provenance import STUDY_MARKER, versions
from rimcl.stats.bootstrap import BOOTSTRAP_RESAMPLES, BOOTSTRAP_SEED, TracerBootstrap
from rimcl.stats.consistency import scene_mismatches
from rimcl.stats.convergence import convergence
from rimcl.stats.error_blocks import (
    budget_part,
    kinematic_blocks,
    noise_floor,
    refraction_errors,
    vector_columns,
    vector_errors,
)
from rimcl.stats.peaks import discrete_mode, pdf_peak
from rimcl.stats.render_file import OPTICS_COLUMNS, load_render
from rimcl.stats.sensitivity import bands, file_variants
from rimcl.stats.summaries import CONDITION_FRACTION, finite_or_none
from rimcl.stats.tables import NOTE_COLUMN, area_changes, flagged_tracers, rows_of, write_json
from rimcl.stats.units import case_units, write_tidy


def _area_change_peak(tracers):
    changes = area_changes(tracers)
    area_ref = tracers["area_ref"][tracers["area_ref"] > 0]
    if changes.size == 0:
        return None
    return discrete_mode(changes, 1.0 / float(np.median(area_ref)))


#: |ΔA/A| (90th percentile) above which tracer images count as reshaped in a verdict.
IMAGE_RESHAPED = 0.25


#: How the verdict names the contenders of the velocity error.
PART_NAMES = {
    "optics": "optics",
    "imaging": "imaging",
    "noise_floor": "noise floor",
    "baseline": "baseline",
}


def _u3(block):
    """``velocity.u3.rms_normalized`` of a stats block, or None."""
    return ((block or {}).get("velocity") or {}).get("u3", {}).get("rms_normalized")


def _against(refraction, other, name):
    """``below the noise floor (0.62 %, refraction 0.18×)``: refraction against a named term."""
    if other is None:
        return None
    if other == 0:
        return f"the {name} is 0"
    relation = "above" if refraction > other else "below"
    return f"{relation} the {name} ({100 * other:.3g} %, refraction {refraction / other:.2g}×)"


def budget_verdict(case):
    """How the velocity error of a case compares: refraction (optics, imaging) against the
    noise floor and the baseline.

    Parameters
    ----------
    case : dict
        A ``stats.json`` case with ``optics`` and ``imaging`` blocks (and ``noise_floor``
        where the render file has the floor's columns).

    Returns
    -------
    dict or None
        ``quantity`` (the statistic compared: ``velocity.<u3>.rms_normalized``), its
        ``optics``, ``imaging``, ``total`` (refraction), ``noise_floor`` (None without the
        block) and ``baseline`` values; ``dominant`` (the largest of refraction, noise
        floor and baseline, refraction named by its larger part, optics or imaging);
        ``refraction_over_floor`` and
        ``refraction_over_baseline`` (None where the other term is missing or 0);
        ``resolved`` (False where refraction is exactly 0: nothing measured); ``text``, one
        line for a reader naming each term. ``None`` without the blocks or the numbers.
    """
    if "optics" not in case or "velocity" not in case["optics"]:
        return None
    parts = {
        "optics": _u3(case["optics"]),
        "imaging": _u3(case["imaging"]),
        "total": case["velocity"]["u3"]["rms_normalized"],
        "baseline": _u3(case["baseline"]),
    }
    if any(value is None for value in parts.values()):
        return None
    parts["noise_floor"] = _u3(case.get("noise_floor"))
    total = parts["total"]
    # refraction (its larger part speaking for it) against the two terms that are not
    # refraction: the noise floor and the baseline
    contenders = {
        "optics" if parts["optics"] >= parts["imaging"] else "imaging": total,
        **{name: parts[name] for name in ("noise_floor", "baseline") if parts[name] is not None},
    }
    dominant = max(contenders, key=contenders.get)
    words = [f"{case['name']}: {PART_NAMES[dominant]} dominates rms(ε_u3)/rms(u3)"]
    if total == 0:
        words.append("refraction not resolved (exactly 0: measured and reference images agree)")
        for name in ("noise_floor", "baseline"):
            if parts[name] is not None:
                words.append(f"the {PART_NAMES[name]} {100 * parts[name]:.3g} %")
    else:
        words.append(f"refraction {100 * total:.3g} %")
        for name in ("noise_floor", "baseline"):
            words.append(_against(total, parts[name], PART_NAMES[name]))
        if parts["noise_floor"] is None:
            words.append("no noise floor in these render files")
    optics, imaging = parts["optics"], parts["imaging"]
    if optics > 0 and imaging > 0:
        larger, smaller = ("imaging", "optics") if imaging >= optics else ("optics", "imaging")
        words.append(f"{larger} {max(optics, imaging) / min(optics, imaging):.2g}× {smaller}")
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

    def ratio(other):
        return None if other is None or other == 0 else total / other

    return {
        "quantity": "velocity.u3.rms_normalized",
        **parts,
        "dominant": dominant,
        "refraction_over_floor": ratio(parts["noise_floor"]),
        "refraction_over_baseline": ratio(parts["baseline"]),
        "resolved": total != 0,
        "text": "; ".join(word for word in words if word),
    }


def _not_resolved(tracers, tables):
    """Why a case's refraction errors are no measurement, or None.

    Where the index varies (Δn_max > 0) but every kept tracer's measured image point equals
    its reference exactly, the camera and renderer did not resolve the shift (whole-pixel
    rendering, coarse pixels): its errors are exactly 0 by construction, not measured 0.
    """
    if not tables.delta_n_max:
        return None
    moved = np.hypot(tracers["x2_meas"] - tracers["x2_ref"], tracers["x3_meas"] - tracers["x3_ref"])
    moved = moved[np.isfinite(moved)]
    if moved.size == 0 or np.any(moved > 0):
        return None
    return (
        "no measured image moved from its reference image although the index varies: the "
        "shift is below what this camera and renderer resolve, so its errors are n/a, not 0"
    )


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
        them), ``against_truth`` (the same groups against the truth, the paper's
        definition; see :data:`ERROR_DEFINITIONS`), ``baseline``, ``noise_floor`` (where
        the file has the floor's columns), ``optics`` and
        ``imaging`` (where the file has the optics columns), ``budget_verdict``,
        ``convergence``, ``sensitivity`` (:mod:`rimcl.stats.sensitivity`),
        ``area_change_peak``, ``circularity_peak``, ``rays``).
    """
    excluded_ids, excluded_counts = flagged_tracers(tables)
    noted_ids, noted_counts = flagged_tracers(tables, NOTE_COLUMN)
    all_ids = np.unique(tables.tracers["id"].astype(np.int64))
    kept = np.setdiff1d(all_ids, excluded_ids)
    bootstrap = TracerBootstrap(kept)
    tracers = rows_of(tables.tracers, kept)
    blocks = kinematic_blocks(tables, kept)
    rays_total = int(np.sum(tables.tracers["n_rays"]))
    case = {
        "name": tables.case,
        "G": finite_or_none(tables.k_rho),
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
    refraction = refraction_errors(tables, tracers, blocks, bootstrap)
    case.update(refraction)
    case["not_resolved"] = _not_resolved(tracers, tables)
    # the paper's definition: measured minus the truth (refraction plus the baseline)
    case["against_truth"] = {
        group: vector_errors(
            table,
            symbol,
            vector_columns(table, symbol, "meas"),
            vector_columns(table, symbol, "true"),
            bootstrap,
        )
        for group, (symbol, table) in blocks.items()
    }
    case["baseline"] = {
        group: vector_errors(
            table,
            symbol,
            vector_columns(table, symbol, "ref"),
            vector_columns(table, symbol, "true"),
            bootstrap,
        )
        for group, (symbol, table) in blocks.items()
    }
    floor = noise_floor(tables, tracers, blocks, bootstrap)
    if floor is not None:
        case["noise_floor"] = floor
    if all(name in tracers for name in OPTICS_COLUMNS["x"]):
        for part in ("optics", "imaging"):
            case[part] = budget_part(
                tracers, blocks, tables.length, tables.pixel_size, bootstrap, part
            )
    case["area_change_peak"] = _area_change_peak(tracers)
    changes = area_changes(tracers)
    changes = np.abs(changes[np.isfinite(changes)])
    case["area_change_p90"] = float(np.percentile(changes, 90)) if changes.size else None
    case["circularity_peak"] = pdf_peak(tracers["circularity_meas"])
    case["convergence"] = convergence(tables, kept, blocks, refraction)
    case["budget_verdict"] = budget_verdict(case)
    case["units"] = case_units(tables, case=case)
    # the method's part of the uncertainty: the variants the file holds (the excluded
    # tracers by their optics, the thresholds ×½ and ×2 located in the same images)
    variants = file_variants(tables)
    case["sensitivity"] = {"variants": variants, "bands": bands(case, variants)}
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


#: The two error definitions of stats.json, named.
ERROR_DEFINITIONS = {
    "refraction": (
        "measured minus reference (the same tracers imaged through a uniform medium): "
        "refraction alone; the blocks position_error_*, velocity, acceleration, "
        "velocity_fit, acceleration_fit, optics, imaging"
    ),
    "against_truth": (
        "measured minus truth, the paper's ε = u' - u: refraction plus the baseline "
        "(finite differences or fit, and imaging, without refraction); the block "
        "against_truth"
    ),
    "baseline": "reference minus truth: the measurement's own error without refraction",
    "noise_floor": (
        "a second exposure of the reference (independent sensor noise draws) minus the "
        "reference: the camera's own noise, located and differenced as every other block; "
        "the measured and reference images share their draws, so refraction holds none"
    ),
}

METHODS = {
    "error_definitions": ERROR_DEFINITIONS,
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
        "nested random subsamples of N/16 ... N tracers; not converged: the value at N lies "
        "outside the 95 % interval at N/4 or at N/2 (either direction), or, for the ratio "
        "statistics (systematic, random), the largest 3 rows carry more than half of "
        "sum((error/truth)^2)"
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


#: The files ``rimcl stats`` writes in its output folder (replaced as a set).
STATS_OWNED = ("stats.json", "stats.csv", "figures/**/*")


def run_stats(paths, out_dir, overwrite=False, figures=True, config=None, mixed=False):
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
    mixed : bool
        Compare render files of different scenes (:mod:`rimcl.stats.consistency`); by
        default they are refused, naming what differs.

    Returns
    -------
    dict
        The ``stats.json`` document.

    Raises
    ------
    RimclError
        Files of different scenes (unless ``mixed``), two files of one case, an output
        that exists (unless ``overwrite``) or a study directory as ``out_dir`` (its
        ``stats.json`` is the study's: never replaced, even with ``overwrite``).
    """
    out_dir = Path(out_dir)
    if (out_dir / STUDY_MARKER).exists() or (
        (out_dir / "scene.toml").is_file() and (out_dir / "cases").is_dir()
    ):
        raise RimclError(
            f"{out_dir} is a rimcl study directory: its stats.json and figures belong to the "
            "study (rerun rimcl study there); write these statistics to another --out"
        )
    all_tables = check_cases([load_render(path) for path in paths])
    differences = [] if mixed else scene_mismatches(all_tables)
    if differences:
        shown = "; ".join(differences[:3]) + ("; ..." if len(differences) > 3 else "")
        raise RimclError(
            f"the render files come from different scenes ({shown}); compare them anyway "
            "with --mixed-scenes"
        )
    # stats.json, stats.csv and figures/ are one set: an earlier run's are refused before
    # any work (unless overwrite) and replaced whole, old figures included
    with OutputSet(out_dir, overwrite=overwrite, owned=STATS_OWNED, inputs=paths) as outputs:
        stats = compute_stats(all_tables, config=config)
        if figures:
            # figures draw what the statistics computed; they never import this module
            from rimcl.stats.figures import write_figures

            write_figures(all_tables, stats, outputs.folder_path("figures"), overwrite=True)
        write_json(outputs.path("stats.json"), stats, overwrite=True)
        write_tidy(outputs.path("stats.csv"), stats)
    return stats
