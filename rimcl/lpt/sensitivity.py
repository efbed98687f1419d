"""An LPT case's threshold band: its headline numbers with every image located again at
each camera's threshold ×½ and ×2.

The image kernel (either engine) locates every tracer image a second and third time in the
same digitised image, at the camera's threshold times each factor of
:data:`rimcl.imaging.frames.THRESHOLD_VARIANTS`: no new rays, no new pixels. Each variant's
centroids are triangulated on the same calibrated models (``x_<kind>_<suffix>`` of
:func:`rimcl.lpt.run.run_case`), its tracers kept by its own exclusions (a tracer whose
image the variant threshold loses in some camera and frame is left out of that variant
only), its tracks fitted by the same sliding polynomial, and the headline numbers of
:data:`HEADLINES` computed as the case's statistics compute them. The verdict per number is
PTV's rule (:func:`rimcl.stats.sensitivity.bands`): *stable* where every variant lies in
the number's bootstrap 95 % interval, else *depends on threshold ×2 by +Y %*; a variant that
kept no tracer makes the band n/a and says so, and one that kept fewer than half the case's
tracers is named with its count.
"""

import numpy as np

from rimcl.lpt.images import unusable
from rimcl.lpt.units import COMPONENTS
from rimcl.stats.convergence import rms_reasons
from rimcl.stats.sensitivity import THRESHOLD_NAMES, bands

#: The headline numbers per group, dotted paths into a case of ``lpt_stats.json`` (``{}`` the
#: component): the rms of the refraction position error (field length units), and
#: rms(ε)/rms(truth) of the fitted velocity and acceleration refraction errors.
PATHS = {
    "position": "position.{}.refraction.rms",
    "velocity": "velocity.{}.refraction.rms_normalized",
    "acceleration": "acceleration.{}.refraction.rms_normalized",
}
#: Every headline number, per group and component.
HEADLINES = tuple(path.format(name) for path in PATHS.values() for name in COMPONENTS)


def _rms(values):
    values = values[np.isfinite(values)]
    return float(np.sqrt(np.mean(values**2))) if values.size else None


def _rms_normalized(error, truth):
    usable = np.isfinite(error) & np.isfinite(truth) & (truth != 0)
    if not usable.any():
        return None
    value = np.sqrt(np.sum(error[usable] ** 2) / np.sum(truth[usable] ** 2))
    return float(value) if np.isfinite(value) else None


def headline_values(run, x_meas, x_ref, keep, window, order):
    """The :data:`HEADLINES` numbers of one set of positions, without intervals.

    Parameters
    ----------
    run : rimcl.lpt.run.Run
        The true tracks (``u_true``, ``a_true``) and the frame times.
    x_meas, x_ref : ndarray, shape (F, N, 3)
        Triangulated positions through the field and through the uniform fluid (field
        length units).
    keep : ndarray of bool, shape (N,)
        The tracers counted.
    window, order : int
        The sliding fit (``time.fit_window``, ``time.fit_order``).

    Returns
    -------
    dict
        ``{path: value}`` (None where nothing was measured) and ``n_used``.
    """
    from rimcl.ptv.track import sliding_fit

    values = dict.fromkeys(HEADLINES)
    values["n_used"] = int(keep.sum())
    if not keep.any():
        return values
    meas, ref = x_meas[:, keep], x_ref[:, keep]
    for axis, name in enumerate(COMPONENTS):
        values[PATHS["position"].format(name)] = _rms((meas - ref)[..., axis].ravel())
    dt = float(run.times[1] - run.times[0]) if run.times.size > 1 else None
    fit_meas, fit_ref = (sliding_fit(x, dt, window, order) for x in (meas, ref))
    for group, truth in (("velocity", run.u_true), ("acceleration", run.a_true)):
        error = getattr(fit_meas, group) - getattr(fit_ref, group)
        truth = truth[fit_meas.centres][:, keep]
        for axis, name in enumerate(COMPONENTS):
            values[PATHS[group].format(name)] = _rms_normalized(
                error[..., axis].ravel(), truth[..., axis].ravel()
            )
    return values


def threshold_sensitivity(run, result, case, kept_but_images, scene):
    """The ``sensitivity`` block of one case of ``lpt_stats.json``.

    Parameters
    ----------
    run : rimcl.lpt.run.Run
    result : dict
        :func:`rimcl.lpt.run.run_case`'s arrays, with each variant's ``x_meas_<suffix>``,
        ``x_ref_<suffix>`` and ``image_flags_meas_<suffix>``, ``image_flags_ref_<suffix>``.
    case : dict
        The case's statistics (values and ``ci95``).
    kept_but_images : ndarray of bool, shape (N,)
        The tracers no flag but a lost image leaves out: each variant keeps those of them
        whose images it locates in every camera and frame.
    scene : rimcl.lpt.config.LptScene
        The sliding fit's ``time.fit_window`` and ``time.fit_order``.

    Returns
    -------
    dict
        ``variants`` (``{"threshold ×½": {path: value, …, "n_used"}, "threshold ×2": …}``)
        and ``bands`` (:func:`rimcl.stats.sensitivity.bands` of :data:`HEADLINES`).
    """
    times = scene.measure.time
    variants = {}
    for name, suffix in THRESHOLD_NAMES.items():
        lost = np.zeros_like(kept_but_images)
        for kind in ("meas", "ref"):
            lost |= np.any(unusable(result[f"image_flags_{kind}_{suffix}"]), axis=(0, 1))
        variants[name] = headline_values(
            run,
            result[f"x_meas_{suffix}"],
            result[f"x_ref_{suffix}"],
            kept_but_images & ~lost,
            times.fit_window,
            times.fit_order,
        )
    return {
        "variants": variants,
        "bands": _tracers_lost(
            bands(case, variants, HEADLINES, measured=()), variants, case["tracers_kept"]
        ),
    }


def _tracers_lost(entries, variants, kept):
    """Say it in each band where a variant kept no tracer (its numbers are missing, so the
    band cannot be stable) or fewer than half the case's ``kept``."""
    empty = [name for name, values in variants.items() if values["n_used"] == 0]
    thin = [
        f"{name} kept {values['n_used']} of {kept} tracers"
        for name, values in variants.items()
        if 0 < values["n_used"] < 0.5 * kept
    ]
    if not (empty or thin) or not kept:  # a case without tracers says so once, itself
        return entries
    for entry in entries.values():
        if empty:
            entry["stable"] = None
            entry["text"] = f"n/a: {' and '.join(empty)} lost every tracer"
        else:
            entry["text"] += f" ({'; '.join(thin)})"
        entry["tracers_lost"] = empty + thin
    return entries


def tail_lines(case):
    """The summary's line naming the rms ratios of a case that a tail carries (PTV's rule,
    :func:`rimcl.stats.convergence.rms_reasons`): they are no headline, their median and
    IQR are."""
    marked = []
    for group in ("velocity", "acceleration"):
        for name in COMPONENTS:
            summary = ((case.get(group) or {}).get(name) or {}).get("refraction")
            reasons = rms_reasons(summary) if summary else []
            if reasons:
                marked.append(f"{group} {name} ({', '.join(reasons)})")
    if not marked:
        return []
    return [
        "  † rms(ε)/rms(truth) that a tail carries (its interval cannot cover a larger "
        "sample; read the median and IQR of ε/truth in lpt_stats.json): " + "; ".join(marked)
    ]


def band_lines(case):
    """The summary's lines of a case's threshold band: per headline number its verdict,
    and the rms ratios a tail carries (:func:`tail_lines`)."""
    block = case.get("sensitivity")
    if not block:
        return tail_lines(case)
    bands_of = block["bands"]
    return [
        f"  threshold ×½/×2 band, {group}: "
        + "; ".join(
            f"{name} {bands_of.get(path.format(name), {}).get('text', 'n/a')}"
            for name in COMPONENTS
        )
        for group, path in PATHS.items()
    ] + tail_lines(case)
