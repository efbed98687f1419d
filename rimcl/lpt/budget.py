"""The LPT error budget of velocity and acceleration: refraction, its optics and imaging
parts, the noise floor and the baseline, from the tracks' sliding polynomial fits.

- **refraction** ``meas − ref``: the tracks through the field against the tracks through the
  uniform fluid; the two images of a tracer share the sensor's noise draws (common random
  numbers), so a uniform medium gives exactly 0;
- **optics** ``opt_meas − opt_ref``: the same for the tracks triangulated from the rays' mean
  image points (no pixels); **imaging** = refraction − optics, what the pixels, the
  threshold and the centroid add;
- **noise floor** ``floor − ref``: a second exposure of the reference images with
  independent sensor noise draws, triangulated and fitted alike: what the camera's noise
  alone does (0 on a noiseless camera);
- **baseline** ``ref − true``: the measurement without refraction (fit, imaging,
  calibration);
- **refraction_self_calibrated** ``vsc − ref`` where the volume self-calibration ran.
"""

from rimcl.lpt.units import ERRORS

#: Track kinds each fitted: the located and the optics tracks of both media, the floor's
#: second exposure, the self-calibrated tracks.
FIT_KINDS = ("meas", "ref", "opt_meas", "opt_ref", "floor", "vsc")
#: The error terms of :func:`kinematic_errors`, in the order they are printed.
TERMS = ERRORS


def kinematic_errors(fits, attribute, truth):
    """The error terms of one fitted quantity.

    Parameters
    ----------
    fits : dict of str to rimcl.ptv.track.TrackFit
        Sliding fits of the tracks of :data:`FIT_KINDS` (``meas`` and ``ref`` at least;
        a kind that is missing gives its terms as None).
    attribute : str
        ``"velocity"`` or ``"acceleration"``.
    truth : ndarray, shape (M, N, 3)
        The true values at the fits' centre frames.

    Returns
    -------
    dict of str to (ndarray (M, N, 3) or None)
        Keyed by :data:`TERMS`.
    """

    def of(kind):
        return getattr(fits[kind], attribute) if kind in fits else None

    reference, measured = of("ref"), of("meas")
    refraction = measured - reference
    optics = None
    if "opt_meas" in fits and "opt_ref" in fits:
        optics = of("opt_meas") - of("opt_ref")
    return {
        "refraction": refraction,
        "optics": optics,
        "imaging": None if optics is None else refraction - optics,
        "noise_floor": None if "floor" not in fits else of("floor") - reference,
        "baseline": reference - truth,
        "refraction_self_calibrated": None if "vsc" not in fits else of("vsc") - reference,
    }


def _percent(summary):
    value = None if summary is None else summary.get("rms_normalized")
    return "n/a" if value is None else f"{100 * value:.3g} %"


def budget_lines(case, components=("x1", "x2", "x3")):
    """Terminal lines of a case's velocity and acceleration budget: per component the
    refraction error, its optics and imaging parts, the noise floor and the baseline, each
    ``rms(ε)/rms(truth)``; refraction is exactly 0 in a uniform medium."""
    lines = []
    for label in ("velocity", "acceleration"):
        block = case[label]
        parts = []
        for k in components:
            terms = block[k]
            parts.append(
                f"{k} {_percent(terms['refraction'])} (optics {_percent(terms.get('optics'))}, "
                f"imaging {_percent(terms.get('imaging'))}; noise floor "
                f"{_percent(terms.get('noise_floor'))}, baseline {_percent(terms['baseline'])})"
            )
        lines.append(f"  {label} refraction rms(ε)/rms(truth): " + "; ".join(parts))
    return lines
