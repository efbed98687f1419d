"""The PIV part of a study's ``summary.md``: PIV against PTV per case, and the settings
side by side (like for like, or what differs)."""

from rimcl.piv.comparison import COMPARED
from rimcl.study.summary_format import number, percent_of, significant, table

#: PIV and PTV refraction errors of a case "agree" when the ratio of their
#: rms(ε_|u|)/rms(|u|) lies within this factor either way.
PIV_AGREEMENT_FACTOR = 2.0


def _agreement(stats, key):
    """Cases whose PIV/PTV ratio ``key`` of ``|u|`` lies within the factor, and the others."""
    agree, differ = [], []
    for case in stats["cases"]:
        ratio = case.get("piv_vs_ptv", {}).get("magnitude", {}).get(key)
        if ratio is not None:
            within = 1 / PIV_AGREEMENT_FACTOR <= ratio <= PIV_AGREEMENT_FACTOR
            (agree if within else differ).append(f"{case['name']} ({significant(ratio, 2)})")
    return agree, differ


def _agreement_sentence(agree, differ, what):
    factor = f"a factor {PIV_AGREEMENT_FACTOR:g}"
    if not differ:
        return f"{what} **agree** within {factor} in every case: {', '.join(agree)}."
    if not agree:
        return f"{what} **differ** by more than {factor}: {', '.join(differ)}."
    return (
        f"{what} **agree** within {factor} in {', '.join(agree)} and **differ** in "
        f"{', '.join(differ)}."
    )


def piv_verdict(stats):
    """One line: do the PIV and PTV refraction errors of ``|u|`` agree, case by case (and
    their optics parts, where the PTV cases have them)?"""
    agree, differ = _agreement(stats, "ratio_rms_normalized")
    if not agree and not differ:
        return 'No PTV case to compare with (run.mode = "piv").'
    line = "**Verdict:** " + _agreement_sentence(
        agree, differ, "PIV and PTV errors (PIV/PTV of rms(ε_|u|)/rms(|u|))"
    )
    agree, differ = _agreement(stats, "optics_ratio_rms_normalized")
    if agree or differ:
        line += " " + _agreement_sentence(agree, differ, "Their optics parts (rays only)")
    return line


def _px_and_mm_s(piv, key):
    """An rms displacement of a PIV case in pixels, and in mm/s where the scales give it."""
    text = number(piv["displacement_px"][key])
    mm_s = ((piv.get("units") or {}).get(key) or {}).get("mm_s")
    return text if mm_s is None else f"{text} ({number(mm_s)} mm/s)"


def piv_lines(stats):
    """The PIV section of ``summary.md`` (no lines without PIV results): what was
    measured, the errors per case beside PTV's, and :func:`piv_verdict`."""
    cases = [case for case in stats["cases"] if "piv" in case]
    if not cases:
        return []
    first = cases[0]["piv"]
    settings = first["piv"]
    factors = (first.get("units") or {}).get("scales") or {}
    pixel, dt = f"{first['pixel_size_over_L']:.3g} L", f"{first['dt']:.3g}"
    if factors.get("pixel_um") is not None:
        pixel += f" = {factors['pixel_um']:.3g} µm"
    if factors.get("dt_ms") is not None:
        dt += f" = {factors['dt_ms']:.3g} ms"
    lines = [
        "",
        "## PIV beside PTV",
        "",
        f"PIV frames of {first['n_tracers']} tracers across a Gaussian light sheet "
        f"(pixel = {pixel}), Δt = {dt}, "
        f"{settings['passes']} passes down to {settings['window']} px windows "
        f"(overlap {settings['overlap']:g}); cases in `piv/<case>.h5`, figures "
        f"`figures/piv_*`. Motion: {first['motion']}.",
        "",
        "Refraction error of a vector: measured through the field minus measured through a "
        "uniform medium on the same tracers (pixels, rms over the vectors used); *optics*: "
        "the window average of the rays' image-point shifts; *baseline*: the uniform-medium "
        "vector minus the window-averaged truth (the PIV method's own error). Relative "
        "errors with their bootstrap 95 % intervals (each vector one sample: overlapping "
        "windows share tracers, so the intervals are too narrow); `stats.json`: `piv` and "
        "`piv_vs_ptv` per case. Where the field's scales are known, each rms in pixels is "
        "followed by the same in mm/s (`units` per case).",
        "",
    ]
    header = [
        "case",
        "G",
        "vectors used",
        "truth rms (px)",
        "refraction rms (px)",
        "optics rms (px)",
        "baseline rms (px)",
        "PIV rms(ε)/rms(u3)",
        "PIV rms(ε)/rms(|u|)",
        "PTV rms(ε)/rms(|u|)",
        "PIV/PTV",
        "optics PIV/PTV",
    ]
    rows = []
    for case in cases:
        piv = case["piv"]
        compared = case.get("piv_vs_ptv", {}).get("magnitude", {})
        rows.append(
            [
                case["name"],
                number(piv["G"]),
                f"{piv['n_used']}/{piv['n_vectors']}",
                *(
                    _px_and_mm_s(piv, key)
                    for key in ("truth_rms", "refraction_rms", "optics_rms", "baseline_rms")
                ),
                percent_of(piv["velocity"]["u3"], "rms_normalized"),
                percent_of(piv["velocity"]["magnitude"], "rms_normalized"),
                percent_of(case["velocity"]["magnitude"], "rms_normalized")
                if "velocity" in case
                else "n/a",
                number(compared.get("ratio_rms_normalized")),
                number(compared.get("optics_ratio_rms_normalized")),
            ]
        )
    return [
        *lines,
        *table(header, rows),
        "",
        *_settings_lines(cases),
        piv_verdict(stats),
        "",
    ]


def _settings_lines(cases):
    """PTV's and PIV's settings side by side, and whether the ratios compare like for like."""
    settings = next(
        (c["piv_vs_ptv"]["settings"] for c in cases if "settings" in c.get("piv_vs_ptv", {})),
        None,
    )
    if settings is None:
        return []
    rows = [
        [name, _setting(settings["ptv"][key]), _setting(settings["piv"][key])]
        for key, name in COMPARED
    ]
    names = dict(COMPARED)
    if settings["like_for_like"]:
        verdict = (
            "PTV and PIV measured **like for like**: the same Δt, camera, pixel, rays and bits."
        )
    else:
        differ = ", ".join(names[key] for key in settings["differ"])
        verdict = (
            f"**Not like for like**: PTV and PIV differ in {differ}, so the ratios compare "
            "the two measurements as set up, not the two methods (a velocity error from a "
            "position error scales as 1/Δt). Set `[piv]` `dt`, `rays` and `bit_depth` to "
            "PTV's (`time.dt`, the camera's rays, `renderer.bit_depth`) to compare the "
            "methods."
        )
    return [*table(["setting", "PTV", "PIV"], rows), "", verdict, ""]


def _setting(value):
    if isinstance(value, bool):
        return "on" if value else "off"
    return number(value) if isinstance(value, float) else str(value)
