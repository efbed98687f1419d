"""The top of ``summary.md``: the answer a user asked for, in their units, and the warnings
an experimentalist would give about the scene.

:func:`answer_lines` says, per case, the velocity (and acceleration) error at the scene's
Δt in mm/s and px/frame, as a share of the rms velocity, and how much of it refraction
makes; :func:`piv_units` adds the same scales to the PIV results; :func:`scene_warnings`
lists what would make the numbers misleading (peak locking, a thin depth of field, a sheet
thicker than the field, displacements the method does not resolve); :func:`lens_lines`
gives the lens-derived quantities.
"""

import math

from rimcl.stats.units import scales

#: Tracer images narrower than this (px, e⁻² diameter 4σ) peak-lock (Raffel et al. 2018).
PEAK_LOCKING_PX = 2.0
#: Displacements per frame (px) a PTV tracker matches reliably, and PIV's quarter-window
#: rule (Keane & Adrian 1990) as a fraction of the final window.
PTV_MAX_DISPLACEMENT_PX = 10.0
PIV_MAX_WINDOW_FRACTION = 0.25
#: Below this rms displacement (px/frame) the sub-pixel error dominates a vector.
MIN_DISPLACEMENT_PX = 0.5


def _fmt(value, digits=3):
    if value is None or (isinstance(value, float) and not math.isfinite(value)):
        return "n/a"
    if value == 0:
        return "0"
    return f"{value:.{digits}g}"


def _group(units, kind):
    """The fitted group where there is one (what PTV codes report), else finite differences."""
    for group in (f"{kind}_fit", kind):
        if units.get(group):
            return group, units[group]["vector"]
    return None, None


def _speed(entry, physical):
    """``"1.2 mm/s (0.034 px/frame)"`` or the field-unit value where there is no scale."""
    px = entry.get("px_frame")
    value = entry.get(physical)
    unit = {"mm_s": "mm/s", "m_s2": "m/s²"}[physical]
    text = f"{_fmt(value)} {unit}" if value is not None else f"{_fmt(entry['field'])} field units"
    return text + (f" ({_fmt(px)} px/frame)" if px is not None else "")


def answer_lines(stats):
    """``## Your answer`` of ``summary.md``: each case's velocity and acceleration error in
    physical units (where the scene gives them), before the expert detail.

    Returns
    -------
    list of str
    """
    cases = [case for case in stats["cases"] if case.get("units")]
    if not cases:
        return []
    factors = cases[0]["units"]["scales"]
    dt = (
        f"{_fmt(factors['dt_ms'])} ms"
        if factors["dt_ms"] is not None
        else f"{_fmt(cases[0]['dt'])} field time units"
    )
    lines = ["## Your answer", ""]
    if factors["in_field_units"]:
        lines += [f"*In field units*: {cases[0]['units']['note']}.", ""]
    else:
        lines += [
            f"Scales: L = {_fmt(factors['L_mm'])} mm of light path, pixel = "
            f"{_fmt(factors['pixel_um'])} µm on the sheet, Δt = {dt}; every value below is "
            "the normalised one (`stats.json`) times these scales (`units` per case, "
            "`stats.csv`).",
            "",
        ]
    for case in cases:
        units = case["units"]
        group, velocity = _group(units, "velocity")
        position = units.get("position", {}).get("median", {})
        text = f"- **{case['name']}**: median position error {_fmt(position.get('um'))} µm "
        text += f"({_fmt(position.get('px'))} px)"
        if velocity is not None:
            truth = velocity["rms_truth"]
            total = velocity["rms_total"]
            share = _ratio(total["field"], truth["field"])
            text += (
                f"; at your Δt = {dt} ({_fmt(truth.get('px_frame'))} px per frame rms), your "
                f"velocity error (the in-plane vector) is {_speed(total, 'mm_s')} rms, "
                f"{_fmt(share)} % of the rms velocity {_speed(truth, 'mm_s')}; refraction "
                f"alone is {_speed(velocity['rms_refraction'], 'mm_s')}, the measurement "
                f"without refraction {_speed(velocity['rms_baseline'], 'mm_s')}"
                + (
                    f", the camera's noise alone (noise floor) "
                    f"{_speed(velocity['rms_noise_floor'], 'mm_s')}"
                    if "rms_noise_floor" in velocity
                    else ""
                )
                + f" ({'sliding fit' if group.endswith('fit') else 'finite differences'})"
            )
            u3 = units[group].get("u3")
            if u3 is not None:  # the headline tables' number: refraction in u3 alone
                ratio = _ratio(u3["rms_refraction"]["field"], u3["rms_truth"]["field"])
                text += (
                    f"; in u3 alone (the tables' headline) refraction is {_fmt(ratio)} % of rms u3"
                )
        _, acceleration = _group(units, "acceleration")
        if acceleration is not None:
            total, truth = acceleration["rms_total"], acceleration["rms_truth"]
            text += (
                f"; acceleration error {_speed(total, 'm_s2')}, "
                f"{_fmt(_ratio(total['field'], truth['field']))} % of the rms acceleration"
            )
        piv = (case.get("piv") or {}).get("units")
        if piv and piv.get("refraction_rms"):
            refraction, truth = piv["refraction_rms"], piv.get("truth_rms") or {}
            text += (
                f"; PIV: refraction error {_speed(refraction, 'mm_s')} rms of a vector, "
                f"rms displacement {_speed(truth, 'mm_s')}"
                if truth
                else ""
            )
        lines.append(text + ".")
    return [*lines, ""]


def _ratio(value, reference):
    if value is None or not reference:
        return None
    return 100.0 * value / reference


def piv_units(piv, length_m, time_s):
    """The ``units`` block of a PIV case: its rms displacements in px, µm and mm/s.

    Parameters
    ----------
    piv : dict
        The case's ``piv`` statistics (``displacement_px``, ``length_L``,
        ``pixel_size_over_L``, ``dt``).
    length_m, time_s : float or None

    Returns
    -------
    dict
        ``scales`` and per rms displacement ``{"px_frame", "field", "mm_s"}``:
        ``field = px × pixel / Δt`` and ``mm_s = field × mm_s_per_velocity``.
    """
    pixel = piv["pixel_size_over_L"] * piv["length_L"]
    factors = scales(piv["length_L"], pixel, piv["dt"], length_m, time_s)
    block = {"scales": factors}
    for key, px in piv["displacement_px"].items():
        if not key.endswith("_rms") or px is None:
            continue
        field = px * pixel / piv["dt"]
        mm_s = (
            None if factors["mm_s_per_velocity"] is None else field * factors["mm_s_per_velocity"]
        )
        block[key] = {"px_frame": px, "field": field, "mm_s": mm_s}
    return block


def _camera(stats):
    inputs = stats.get("config", {}).get("inputs") or [{}]
    return (inputs[0].get("config") or {}).get("camera") or {}


def lens_lines(stats):
    """The lens-derived quantities of a lens camera (none for the others)."""
    camera = _camera(stats)
    if camera.get("camera") != "lens":
        return []
    pixel_um = camera["pixel_pitch_um"] / camera["magnification"]
    image_px = camera["image_diameter_um"] / camera["pixel_pitch_um"]
    return [
        "## The lens",
        "",
        f"{camera['focal_length_mm']:g} mm at f/{camera['f_number']:g}, M = "
        f"{camera['magnification']:g} ({camera['working_distance_mm']:.4g} mm working "
        f"distance): pixel on the sheet {_fmt(pixel_um)} µm, object-side NA "
        f"{_fmt(camera['numerical_aperture'])}, depth of field "
        f"{_fmt(camera['depth_of_field_mm'])} mm, diffraction spot "
        f"{_fmt(camera['diffraction_diameter_um'])} µm, tracer image "
        f"{_fmt(camera['image_diameter_um'])} µm = {_fmt(image_px)} px "
        f"(σ {_fmt(camera['psf_sigma_px'])} px).",
        "",
    ]


def scene_warnings(stats, study):
    """What an experimentalist would warn about in this scene, one sentence each.

    Parameters
    ----------
    stats : dict
        The ``stats.json`` document (its inputs' camera and renderer, the cases' units).
    study : rimcl.scene.study_config.StudyConfig

    Returns
    -------
    list of str
    """
    warnings = []
    camera = _camera(stats)
    inputs = stats.get("config", {}).get("inputs") or [{}]
    render = (inputs[0].get("config") or {}).get("render") or {}
    sigma = render.get("psf_sigma_px", camera.get("psf_sigma_px"))
    if sigma is not None and 4 * sigma < PEAK_LOCKING_PX:
        warnings.append(
            f"tracer images are {4 * sigma:.2g} px across (4σ), below ~{PEAK_LOCKING_PX:g} px: "
            "real centroids and correlation peaks lock to whole pixels (peak locking); "
            "defocus slightly or use a smaller magnification"
        )
    piv = next((c["piv"] for c in stats["cases"] if c.get("piv")), None)
    if piv is not None:
        depth = piv["length_L"]
        # the sheet's 1/e² thickness: the scene's, else PIV's default of 8 pixels
        sheet = study.piv.sheet_thickness or 8 * piv["pixel_size_over_L"] * depth
        length_m = study.shared.camera.length_m
        dof = camera.get("depth_of_field_mm")
        if dof is not None and length_m is not None and dof < sheet * length_m * 1e3:
            warnings.append(
                f"the depth of field ({dof:.3g} mm) is thinner than the light sheet "
                f"({sheet * length_m * 1e3:.3g} mm): tracers off the focal plane image blurred"
            )
        if sheet > depth:
            warnings.append(
                f"the light sheet ({sheet:.3g}) is thicker than the traced depth of the field "
                f"({depth:.3g}): tracers outside the field are lit"
            )
    for case in stats["cases"]:
        if case.get("not_resolved"):
            warnings.append(f"{case['name']}: {case['not_resolved']}")
        warnings += _displacement_warnings(case)
    return list(dict.fromkeys(warnings))


def _displacement_warnings(case):
    found = []
    units = case.get("units") or {}
    moved = units.get("displacement_rms_px")
    if moved is not None and moved > PTV_MAX_DISPLACEMENT_PX:
        found.append(
            f"{case['name']}: tracers move {moved:.3g} px per frame rms, more than the "
            f"~{PTV_MAX_DISPLACEMENT_PX:g} px a PTV tracker matches reliably: shorten Δt"
        )
    if moved is not None and moved < MIN_DISPLACEMENT_PX:
        found.append(
            f"{case['name']}: tracers move {moved:.3g} px per frame rms, below "
            f"{MIN_DISPLACEMENT_PX:g} px: centroid errors of a few 0.01 px become a large "
            "share of each velocity; lengthen Δt if the flow allows"
        )
    piv = case.get("piv")
    if piv:
        truth = (piv.get("displacement_px") or {}).get("truth_rms")
        window = piv.get("piv", {}).get("window")
        if truth is not None and window and truth > PIV_MAX_WINDOW_FRACTION * window:
            found.append(
                f"{case['name']}: PIV displacements {truth:.3g} px rms exceed a quarter of "
                f"the {window} px window (the one-quarter rule): shorten Δt or widen windows"
            )
        if truth is not None and truth < MIN_DISPLACEMENT_PX:
            found.append(
                f"{case['name']}: PIV displacements are {truth:.3g} px rms, below "
                f"{MIN_DISPLACEMENT_PX:g} px: the sub-pixel error dominates; lengthen Δt"
            )
    return found


def warning_lines(warnings):
    """The ``## Warnings`` section (none without warnings)."""
    if not warnings:
        return []
    return ["## Warnings", "", *(f"- {w}." for w in warnings), ""]
