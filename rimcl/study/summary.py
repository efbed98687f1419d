"""The Markdown summary of a study (``summary.md``): headline numbers with their intervals.

The headline is the set of statistics that converge with the number of tracers: the median
and interquartile range of ``ε/truth``, which a few tracers cannot carry, then
``rms(ε)/rms(truth)``, marked where it has not converged or a few tracers or a heavy tail
carry it (:func:`rimcl.stats.convergence.rms_reasons`), and the same over the tracers whose
truth is not small. The paper's mean and standard deviation of
``ε/truth`` follow, labelled as the paper's, with a mark on those that keep growing with
the number of tracers (:func:`rimcl.stats.convergence.not_converged`). Every value is printed
with its bootstrap 95 % interval, and a statistic of an empty sample reads ``n/a``.
"""

from datetime import datetime, timezone

from rimcl import __version__
from rimcl.optics.camera import DEFAULT_F_NUMBER
from rimcl.stats.sensitivity import FILE_VARIANTS, MEASURED_VARIANTS, THRESHOLD_NAMES
from rimcl.stats.summaries import (
    INFLUENCE_LIMIT,
    TAIL_INDEX_LIMIT,
    TOP_FRACTION,
    TOP_SHARE_LIMIT,
)
from rimcl.study.answer import answer_lines, lens_lines, scene_warnings, warning_lines
from rimcl.study.summary_format import number, percent_of, significant, table, with_interval
from rimcl.study.summary_piv import piv_lines

PAPER_SOURCE = (
    "H. Li, A. Fischer, M. Avila, D. Xu, *Measurement error of tracer-based velocimetry in "
    "single-phase turbulent flows with inhomogeneous refractive indices*"
)
#: The paper's values for air (C1) and water (C4), as its text states them, with where.
#: Relative errors in percent; the position error is an order of magnitude only.
PAPER_VALUES = {
    "C1": {
        "fluid": "air",
        "delta_n_max": "2.40e-5",
        "position_peak_over_L": "O(1e-4)",
        "velocity_systematic": "≈ 0.2 %",
        "velocity_random": "≈ 2 %",
        "acceleration_systematic": "≈ 1 %",
        "acceleration_random": "≈ 300 %",
    },
    "C4": {
        "fluid": "water",
        "delta_n_max": "2.85e-2",
        "position_peak_over_L": "O(1e-2)",
        "velocity_systematic": "≈ 10 %",
        "velocity_random": "≈ 2000 %",
        "acceleration_systematic": "≈ 500 %",
        "acceleration_random": "≈ 1e5 %",
    },
}
PAPER_CITATIONS = (
    "Δn_max: Table 2 (tab:cases). Position error: Sec. 4.2 (sec:position), 'for the air "
    "flow (C1), the magnitudes of position error are up to O(10^-4 L) ... for the water "
    "flow (C4) ... O(10^-2 L)'. Velocity: Sec. 4.3 (sec:velocity), mean and standard "
    "deviation of ε_u3/u3, 'approximately 0.2 % and about 2 %' (air), '10 %' and 'about "
    "2000 %' (water). Acceleration: Sec. 4.4 (sec:acceleration), 'about 1 % and 300 %' "
    "(air), 'about 500 % and 10^5 %' (water); also the Conclusions."
)
#: Mark of a statistic that keeps growing with the number of tracers.
NOT_CONVERGED = "†"
#: Kinematic quantities of the tables: (stats key, component, heading).
QUANTITIES = (
    ("velocity", "u3", "Velocity u3, forward differences (the paper's)"),
    ("velocity_fit", "u3", "Velocity u3, sliding polynomial fit"),
    ("acceleration", "a3", "Acceleration a3, three-point differences (the paper's)"),
    ("acceleration_fit", "a3", "Acceleration a3, sliding polynomial fit"),
)


def _marked(case, path, text):
    """``text`` with the not-converged mark when ``path`` is listed for the case."""
    growing = case.get("convergence", {}).get("not_converged", [])
    return f"{text} {NOT_CONVERGED}" if path in growing else text


def _ratio_cell(case, path, summary, key):
    """A paper's ratio statistic with its mark, its influence (the share of Σ(ε/truth)²
    carried by the 3 largest rows) and its conditioned value beside it."""
    text = _marked(case, path, percent_of(summary, key))
    share = summary.get("influence")
    if share is not None and share > INFLUENCE_LIMIT and not text.endswith(NOT_CONVERGED):
        text += f" {NOT_CONVERGED}"  # carried by a few rows, also where not followed over N
    conditioned = summary.get("conditioned")
    extras = []
    if share is not None:
        extras.append(f"top-3 share {significant(share, 2)}")
    if conditioned is not None:
        extras.append(f"conditioned {percent_of(conditioned, key)}")
    return f"{text} ({'; '.join(extras)})" if extras else text


def _case_row(case, block=None):
    """The paper's statistics of one case: position peak, u3 and a3 mean and spread, of
    the refraction errors or of another block of ``case`` (``against_truth``)."""
    source = case if block is None else case[block]
    velocity, acceleration = source["velocity"]["u3"], source["acceleration"]["a3"]
    prefix = "" if block is None else f"{block}."
    return [
        case["name"],
        number(case["G"]),
        number(case["delta_n_max"]),
        f"{case['n_used']}/{case['n_tracers']}",
        _peak_cell(case),
        _ratio_cell(case, f"{prefix}velocity.u3.systematic", velocity, "systematic"),
        _ratio_cell(case, f"{prefix}velocity.u3.random", velocity, "random"),
        _ratio_cell(case, f"{prefix}acceleration.a3.systematic", acceleration, "systematic"),
        _ratio_cell(case, f"{prefix}acceleration.a3.random", acceleration, "random"),
    ]


def _peak_cell(case):
    """The PDF peak of ``|ε_x|/L`` with its interval; where two modes compete, both, said."""
    text = _marked(
        case,
        "position_error_peak_over_L",
        with_interval(
            case["position_error_peak_over_L"], case.get("position_error_peak_over_L_ci95")
        ),
    )
    if case.get("position_error_peak_ambiguous"):
        modes = " and ".join(number(m) for m in case["position_error_modes_over_L"])
        text += f" (two modes, {modes}: no one peak; read the median)"
    return text


def _rms_cell(case, path, summary):
    """The rms ratio with its mark and, where it is marked, why: the share of Σε² its
    largest tracers carry and the errors' tail index (:func:`rms_reasons`)."""
    text = _marked(case, path, percent_of(summary, "rms_normalized"))
    reasons = case.get("convergence", {}).get("reasons", {}).get(path, [])
    extras = []
    if "few tracers" in reasons:
        count = summary["top_tracers"]
        extras.append(
            f"{count} tracer{'s' if count > 1 else ''} carry "
            f"{significant(100 * summary['top_share'], 2)} % of Σε²"
        )
    if "heavy tail" in reasons:
        extras.append(f"tail index {significant(summary['tail_index'], 2)}")
    return f"{text} ({'; '.join(extras)})" if extras else text


def _headline_rows(cases, group, component):
    rows = []
    for case in cases:
        summary = case[group][component]
        conditioned = summary["conditioned"]
        baseline = case["baseline"][group][component]
        path = f"{group}.{component}"
        rows.append(
            [
                case["name"],
                _marked(case, f"{path}.median", percent_of(summary, "median")),
                _marked(case, f"{path}.iqr", percent_of(summary, "iqr")),
                _rms_cell(case, f"{path}.rms_normalized", summary),
                _marked(case, f"{path}.conditioned_median", percent_of(conditioned, "median")),
                _marked(case, f"{path}.conditioned_iqr", percent_of(conditioned, "iqr")),
                _rms_cell(case, f"{path}.conditioned_rms_normalized", conditioned),
                f"{conditioned['n']}/{summary['n']}",
                percent_of(baseline, "rms_normalized"),
            ]
        )
    return rows


def _budget_lines(cases):
    with_budget = [case for case in cases if "optics" in case]
    if not with_budget:
        return []
    lines = [
        "## Error budget: optics, imaging, total, noise floor, baseline",
        "",
        "*Optics*: the light-weighted mean of the traced ray image points (no pixels) "
        "through the field against a uniform medium; *imaging*: what the renderer, the "
        "threshold and the centroid add (total minus optics); the measured and reference "
        "images share the sensor's noise draws, so refraction (*total*) holds no noise of "
        "its own. *Noise floor*: two independent exposures through the uniform medium, what "
        "the camera's noise alone does; *baseline*: finite differences and rendering "
        "without refraction. Velocity u3: rms(ε)/rms(u3).",
        "",
    ]
    header = [
        "case",
        "median |ε_x|/L: optics",
        "imaging",
        "total",
        "noise floor",
        "u3: optics",
        "imaging",
        "total",
        "noise floor",
        "baseline",
    ]
    rows = []
    for case in with_budget:
        parts = (case["optics"], case["imaging"], case)
        floor = case.get("noise_floor")
        row = [case["name"]]
        row += [
            with_interval(
                part["position_error_median_over_L"],
                part["position_error_median_over_L_ci95"],
            )
            for part in parts
        ]
        row.append(
            "n/a (no floor in the render file)"
            if floor is None
            else with_interval(
                floor["position_error_median_over_L"], floor["position_error_median_over_L_ci95"]
            )
        )
        row += [percent_of(part["velocity"]["u3"], "rms_normalized") for part in parts]
        row.append(
            "n/a" if floor is None else percent_of(floor["velocity"]["u3"], "rms_normalized")
        )
        row.append(percent_of(case["baseline"]["velocity"]["u3"], "rms_normalized"))
        rows.append(row)
    lines += table(header, rows)
    verdicts = [case["budget_verdict"]["text"] for case in with_budget if case["budget_verdict"]]
    lines += [
        "",
        "Which part dominates, and refraction against the noise floor and the baseline:",
        "",
    ]
    lines += [f"- {line}" for line in verdicts]
    return [*lines, ""]


def _convergence_lines(cases):
    lines = [
        "## Convergence with the number of tracers",
        "",
        f"`{NOT_CONVERGED}` marks a statistic that has not converged with the number of "
        "tracers N: its value at N lies outside the 95 % interval at N/4 or at N/2 (nested "
        "random subsamples; a jump either way), or, for the paper's systematic and random "
        "errors, its 3 largest rows carry more than half of Σ(ε/truth)² (a truth near "
        "zero), or, for an rms ratio, a few tracers or a heavy tail carry it (above). "
        "Such a number describes a few tracers of this sample, not the measurement; "
        "`stats.json` holds every statistic against N under `convergence` (with the reasons), "
        "and `figures/convergence.png` draws them.",
        "",
    ]
    for case in cases:
        growing = case.get("convergence", {}).get("not_converged", [])
        names = ", ".join(f"`{name}`" for name in growing) if growing else "none"
        lines.append(f"- {case['name']}: not converged: {names}")
    return [*lines, ""]


#: Headline numbers of the sensitivity table: (stats path, heading).
SENSITIVITY_HEADINGS = (
    ("position_error_median_over_L", "median |ε_x|/L"),
    ("velocity.u3.rms_normalized", "u3 rms ratio"),
    ("velocity_fit.u3.rms_normalized", "u3 fit rms ratio"),
    ("acceleration.a3.rms_normalized", "a3 rms ratio"),
    ("acceleration_fit.a3.rms_normalized", "a3 fit rms ratio"),
)


def _sensitivity_cell(band, path):
    if band is None or band["value"] is None:
        return "n/a"
    scale, unit = (1.0, "") if "." not in path else (100.0, " %")
    text = with_interval(band["value"], band["ci95"], scale, unit)
    return f"{text}: **{band['text']}**" if band["text"] != "n/a" else text


def _kept_cell(case):
    """Tracers kept at the threshold ×½, ×1 and ×2 (n/a where the file lacks a variant)."""
    variants = case["sensitivity"]["variants"]
    counts = [variants.get(name, {}).get("n_used") for name in THRESHOLD_NAMES]
    counts.insert(1, case["n_used"])
    return " / ".join("n/a" if n is None else str(n) for n in counts)


def _sensitivity_lines(cases, study):
    """Each headline number with its verdict against the settings' variants."""
    with_bands = [case for case in cases if "sensitivity" in case]
    if not with_bands:
        return []
    ran = [
        name
        for name in (*FILE_VARIANTS, *MEASURED_VARIANTS)
        if any(name in case["sensitivity"]["variants"] for case in with_bands)
    ]
    not_run = [name for name in MEASURED_VARIANTS if name not in ran]
    lines = [
        "## Sensitivity to settings",
        "",
        "The bootstrap interval says how a number moves with the tracers; the settings a "
        "user chooses move it too. Each headline number (refraction errors) is computed "
        "again under: "
        + ", ".join(f"*{name}*" for name in ran)
        + ". **stable**: every one of these inside the 95 % interval (the largest move "
        "beside it where one moves it by 0.5 % or more, and *not run: …* after it where the "
        "band lacks a measured variant: stable over what ran only); otherwise *depends on "
        "X by Y %* names the variant that moves it most. *excluded by optics*: the "
        "tracers left out (flagged) counted with their optics error; *threshold ×½* and "
        "*×2*: every tracer located again at that threshold in the same digitised images "
        "(reference and measured; no tracing again), with its own exclusions. ",
    ]
    if not_run:
        lines[-1] += (
            "The band does not include "
            + " and ".join(f"*{name}*" for name in not_run)
            + f", which need each case measured again ({len(not_run)} studies more): "
            "`rimcl study --sensitivity`."
        )
    else:
        lines[-1] += (
            "The other interpolation (trilinear ↔ bspline3) and rays ×4: each case measured "
            "again (`sensitivity/<variant>/cases/<case>.h5`)."
        )
    lines[-1] += " `stats.json`: `sensitivity` per case."
    lines.append("")
    header = [
        "case",
        "tracers kept (threshold ×½ / ×1 / ×2)",
        *(heading for _, heading in SENSITIVITY_HEADINGS),
    ]
    rows = [
        [
            case["name"],
            _kept_cell(case),
            *(
                _sensitivity_cell(case["sensitivity"]["bands"].get(path), path)
                for path, _ in SENSITIVITY_HEADINGS
            ),
        ]
        for case in with_bands
    ]
    return [*lines, *table(header, rows), ""]


def _physical_lines(cases):
    """What each case's Δn_max means in air, water and salt water."""
    if not all("physical_equivalent" in case for case in cases):
        return []
    lines = [
        "## What the cases are physically",
        "",
        "The temperature (or salt) difference between the light and the heavy fluid that gives "
        "each case's Δn_max (IAPWS 1997 water, Ciddor 1996 air, Quan & Fry 1995 salt water).",
        "",
    ]
    for case in cases:
        equivalents = case["physical_equivalent"]
        lines.append(
            f"- {case['name']} (Δn_max {number(case['delta_n_max'])}): "
            + "; ".join(equivalents[name] for name in ("air", "water", "saltwater"))
        )
    return [*lines, ""]


def _dt_sweep_lines(sweep):
    """Where refraction rises above the baseline as the frames move apart."""
    if not sweep:
        return []
    dts = ", ".join(f"{dt:g}" for dt in sweep["dt"])
    lines = [
        "## Frame spacing: when refraction dominates",
        "",
        f"The same tracks sampled every m-th frame (Δt = {dts}); `figures/dt_sweep.png` draws "
        "the refraction error and the baseline against Δt. Δt at which rms(ε)/rms(truth) of "
        "refraction exceeds the baseline's, and the noise floor's (two independent exposures "
        "through the uniform medium: below it, refraction is smaller than the camera's own "
        "noise):",
        "",
    ]
    for name, quantities in sweep["cases"].items():
        for key, words in (
            ("refraction_dominates_dt", "above the baseline"),
            ("refraction_above_floor_dt", "above the noise floor"),
        ):
            parts = []
            for quantity, entry in quantities.items():
                where = entry.get(key, [])
                parts.append(f"{quantity}: " + (", ".join(f"{dt:g}" for dt in where) or "none"))
            lines.append(f"- {name}, refraction {words}: " + "; ".join(parts))
    return [*lines, ""]


def summary_markdown(stats, study):
    """The study's summary as Markdown, beside the paper's values for air and water.

    Parameters
    ----------
    stats : dict
        The ``stats.json`` document.
    study : rimcl.scene.study_config.StudyConfig

    Returns
    -------
    str
    """
    lead = [*answer_lines(stats), *warning_lines(scene_warnings(stats, study)), *lens_lines(stats)]
    if study.run.mode == "piv":
        title = f"# rimcl study: {len(stats['cases'])} cases, PIV"
        return "\n".join([title, "", *lead, *piv_lines(stats)])
    cases = stats["cases"]
    first = cases[0]
    camera, renderer = study.shared.camera, study.shared.renderer
    rays = (
        f"plane camera (the paper's fan, NA ≈ 0.8), {camera.fan}×{camera.fan} rays per tracer"
        if camera.kind == "plane"
        else f"{camera.kind} camera, {camera.pupil_rays} rays per tracer"
    )
    if camera.kind == "lens":
        f_number = DEFAULT_F_NUMBER if camera.f_number is None else camera.f_number
        wall = camera.window_thickness_mm
        rays = (
            f"lens camera ({camera.focal_length_mm:g} mm f/{f_number:g}"
            + (f", M = {camera.magnification:g}" if camera.magnification else "")
            + f", {camera.sensor_pixels[0]}×{camera.sensor_pixels[1]} pixels of "
            f"{camera.pixel_pitch_um:g} µm, behind "
            + (f"a {wall:g} mm wall" if wall else "the bare fluid/air interface")
            + f"), {camera.pupil_rays} rays per tracer"
        )
    field = study.field_path or "the shipped 64³ sample (buoyancy-driven mixing)"
    stamp = datetime.now(timezone.utc).strftime("%Y-%m-%d %H:%M UTC")
    devices = ", ".join(
        sorted({str(entry.get("device", {}).get("device")) for entry in stats["config"]["inputs"]})
    )
    lines = [
        f"# rimcl study: {len(cases)} cases",
        "",
        f"rimcl {__version__}, {stamp}. Field: {field}. {study.shared.tracers.count} tracers, "
        f"{rays}, {renderer.kind} renderer"
        + (f", {renderer.pixels} pixels across the field of view" if camera.kind != "lens" else "")
        + f" (pixel = {first['pixel_size_over_L']:.3g} L), Mie weights "
        + ("on" if study.shared.mie.enabled else "off")
        + ", sensor noise "
        + ("on" if study.shared.sensor.noise else "off")
        + f", {renderer.bit_depth} bits, "
        f"L = {first['length_L']:.4g}, Δt = {first['dt']:.3g}.",
        f"Device: {devices}. Configuration: `scene.toml`; every number and the software "
        "versions: `stats.json` (one row per statistic: `stats.csv`); figures with their "
        "data: `figures/`.",
        "",
        *lead,
        "## Headline: statistics that converge",
        "",
        "Errors from refraction only: position `ε_x = x' − x^ref`, velocity "
        "`ε_u = u' − u^ref`, acceleration `ε_a = a' − a^ref` (measured through the field "
        "minus measured through a uniform medium), relative to the true value, in percent "
        "(`stats.json` holds fractions). Each value is followed by its bootstrap 95 % "
        "interval [lo, hi] (tracers resampled with replacement). *Truth not small*: the "
        "tracers with |truth| ≥ ½ rms(truth), where ε/truth has no near-zero denominators. "
        "*Baseline*: finite differences and rendering without refraction (`u^ref − u`), "
        "which every PTV measurement has. The median and the IQR of ε/truth are the "
        "headline: a few tracers cannot carry them. The rms ratio is one only without "
        f"`{NOT_CONVERGED}`: that marks it where it has not converged, where the largest "
        f"{100 * TOP_FRACTION:g} % of the tracers carry more than "
        f"{100 * TOP_SHARE_LIMIT:g} % of Σε² (*few tracers*), or where the "
        f"errors' tail index is below {TAIL_INDEX_LIMIT:g} (*heavy tail*: the "
        "rms of a larger sample can lie far outside its interval, which then does not "
        "cover; see Convergence).",
        "",
    ]
    header = ["case", "G = Kρ", "Δn_max", "tracers used", "peak |ε_x| / L", "median |ε_x| / L"]
    rows = [
        [
            case["name"],
            number(case["G"]),
            number(case["delta_n_max"]),
            f"{case['n_used']}/{case['n_tracers']}",
            _peak_cell(case),
            _marked(
                case,
                "position_error_median_over_L",
                with_interval(
                    case["position_error_median_over_L"],
                    case.get("position_error_median_over_L_ci95"),
                ),
            ),
        ]
        for case in cases
    ]
    lines += [*table(header, rows), ""]
    for group, component, heading in QUANTITIES:
        if not all(group in case for case in cases):
            continue
        symbol = component
        header = [
            "case",
            f"median ε/{symbol}",
            f"IQR ε/{symbol}",
            f"rms(ε)/rms({symbol})",
            "truth not small: median",
            "IQR",
            "rms ratio",
            "tracers: not small/all",
            "baseline rms ratio",
        ]
        lines += [f"**{heading}**", "", *table(header, _headline_rows(cases, group, component))]
        lines.append("")
    lines += _budget_lines(cases)
    lines += _sensitivity_lines(cases, study)
    lines += [
        "## The paper's statistics",
        "",
        "*Systematic* = mean of `ε/truth`, *random* = its standard deviation: the paper's "
        "statistics, for the `x3` components, in percent, with bootstrap 95 % intervals, of "
        "the refraction errors (`ε = u' − u^ref`). Both are ratios whose denominators come "
        "close to zero for some tracers, so a few slow tracers can carry them: beside each, "
        "the share of Σ(ε/truth)² its 3 largest rows carry (*top-3 share*; 1 means one "
        "tracer is the number) and the conditioned value (|truth| ≥ ½ rms). "
        f"`{NOT_CONVERGED}` marks the ones that have not converged (below).",
        "",
    ]
    header = [
        "case",
        "G = Kρ",
        "Δn_max",
        "tracers used",
        "position-error peak / L",
        "u3 systematic",
        "u3 random",
        "a3 systematic",
        "a3 random",
    ]
    lines += table(header, [_case_row(case) for case in cases])
    excluded = [
        f"{case['name']}: "
        + (", ".join(f"{n} {name}" for name, n in case["n_excluded"].items() if n) or "none")
        for case in cases
    ]
    lines += ["", "Tracers left out (a tracer may carry several flags): " + "; ".join(excluded)]
    several = [
        f"{case['name']}: {case['n_noted'].get('multiple_images', 0)}"
        for case in cases
        if "multiple_images" in case.get("n_noted", {})
    ]
    if several:
        lines += [
            "",
            "Tracers the field images several times (several aims of the lens reach its "
            "pupil; physics, noted and kept): " + "; ".join(several),
        ]
    lines += ["", *_convergence_lines(cases)]
    lines += _physical_lines(cases)
    lines += _dt_sweep_lines(stats.get("dt_sweep"))
    lines += [
        "## Against the paper (air C1, water C4)",
        "",
        "**The flows differ.** The paper traced a 1024³ JHTDB direct numerical simulation "
        "of homogeneous buoyancy-driven turbulence (Re = 12500) over its own depth L, with "
        "1e5 tracers, 100×100 rays each and 8192² pixels; this study uses the field, depth "
        "and sizes above. Only orders of magnitude and trends with G can agree; no "
        "agreement of the numbers themselves is expected. The paper's errors are against "
        "the truth (`ε = u' − u`, refraction plus the finite-difference baseline): rimcl's "
        "rows give both definitions, *vs truth* (the paper's) and *vs reference* "
        "(refraction alone).",
        "",
    ]
    by_name = {case["name"]: case for case in cases}
    header = [
        "",
        "Δn_max",
        "position-error peak / L",
        "velocity systematic",
        "velocity random",
        "acceleration systematic",
        "acceleration random",
    ]
    rows = []
    for name, paper in PAPER_VALUES.items():
        rows.append(
            [
                f"paper, {paper['fluid']} ({name})",
                paper["delta_n_max"],
                paper["position_peak_over_L"],
                paper["velocity_systematic"],
                paper["velocity_random"],
                paper["acceleration_systematic"],
                paper["acceleration_random"],
            ]
        )
        case = by_name.get(name)
        if case is None:
            rows.append([f"rimcl, {name}", *["not run"] * 6])
            continue
        row = _case_row(case)
        if "against_truth" in case:
            truth_row = _case_row(case, "against_truth")
            rows.append([f"rimcl, {name}, vs truth (the paper's ε)", row[2], "—", *truth_row[5:]])
        rows.append([f"rimcl, {name}, vs reference (refraction)", row[2], row[4], *row[5:]])
    lines += table(header, rows)
    lines += ["", f"Paper: {PAPER_SOURCE}. Where: {PAPER_CITATIONS}", ""]
    return "\n".join(lines + piv_lines(stats))
