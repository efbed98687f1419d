"""What makes an LPT case's numbers answers rather than accidents: the calibration target
each camera sees, the self-calibration that may find too few particles, the shift no image
resolved, truths that are zero up to round-off, pixel sizes per camera, and the n/a of a
case that kept no tracer.

Each check either refuses before the frames are imaged (one line, naming what to change) or
turns a number that would be an accident into ``None`` with the reason beside it, as the PTV
statistics do (``not_resolved``).
"""

import numpy as np

from rimcl.core.errors import RimclError
from rimcl.lpt.calibration import SOLOFF_EXPONENTS

#: A true velocity or acceleration whose rms is below this fraction of the flow's own scale
#: (the volume's width over the run's duration, or its square) is zero up to round-off: a
#: ratio to it is no measurement (a uniform flow's acceleration is ~1e-17).
ROUNDOFF = 1e-9
#: Fewest calibration points every camera must see: twice the Soloff model's terms.
MIN_TARGET_POINTS = 2 * len(SOLOFF_EXPONENTS)
#: The ratio keys of an :func:`rimcl.stats.summaries.error_summary`.
_RATIO_KEYS = ("systematic", "random", "median", "iqr", "rms_normalized")


def on_sensor(camera, pixels):
    """Whether image points (..., 2) (column, row in pixels) fall on ``camera``'s sensor."""
    columns, rows = pixels[..., 0], pixels[..., 1]
    inside = (columns >= -0.5) & (columns <= camera.pixels[0] - 0.5)
    inside &= (rows >= -0.5) & (rows <= camera.pixels[1] - 0.5)
    return inside & np.all(np.isfinite(pixels), axis=-1)


def visible_target(cameras, target, pixels):
    """The calibration points every camera images on its sensor.

    Parameters
    ----------
    cameras : list of RigCamera
    target : ndarray, shape (P, 3)
    pixels : list of ndarray, each (P, 2)
        Each camera's image of every point.

    Returns
    -------
    ndarray of bool, shape (P,)

    Raises
    ------
    RimclError
        Where fewer than :data:`MIN_TARGET_POINTS` points are seen by every camera.
    """
    seen = [on_sensor(camera, p) for camera, p in zip(cameras, pixels, strict=True)]
    common = np.logical_and.reduce(seen)
    if common.sum() < MIN_TARGET_POINTS:
        worst = int(np.argmin([s.sum() for s in seen]))
        raise RimclError(
            f"camera {cameras[worst].name} images {int(seen[worst].sum())} of the "
            f"{len(target)} calibration points on its sensor, and {int(common.sum())} are "
            f"seen by every camera; the calibration needs {MIN_TARGET_POINTS}: aim the "
            "cameras at the volume, or use larger sensors or shorter lenses"
        )
    return common


def self_calibration(models, pixels, settings):
    """:func:`rimcl.lpt.selfcal.self_calibrate` and its record for the statistics; where too
    few particles fill its sub-volumes (a scene of few tracers) None and ``{"n/a": why}``:
    the case still has an answer."""
    from rimcl.lpt.selfcal import self_calibrate

    try:
        calibrated = self_calibrate(
            models,
            pixels,
            settings.self_calibration_cells,
            settings.self_calibration_iterations,
        )
    except RimclError as exc:
        return None, {"n/a": str(exc)}
    return calibrated, calibrated.describe()


def not_resolved(result, keep):
    """Why a case's refraction errors are no measurement, or None.

    Where the rays' image points moved (the field bends them) but every kept tracer's
    located image equals its reference exactly in every camera and frame, the cameras did
    not resolve the shift: its errors are exactly 0 by construction, not a measured 0.
    """
    if not keep.any():
        return None
    located = result["centroid_meas"][:, :, keep] - result["centroid_ref"][:, :, keep]
    optics = result["optics_meas"][:, :, keep] - result["optics_ref"][:, :, keep]
    located, optics = located[np.isfinite(located)], optics[np.isfinite(optics)]
    if located.size == 0 or np.any(located != 0) or not np.any(optics != 0):
        return None
    return (
        "no located image moved from its reference image although the rays did: the shift "
        "is below what these cameras resolve, so the refraction errors are n/a, not 0"
    )


def pixel_sizes(cameras):
    """Each camera's pixel at the object (field length units) by name, and their mean (the
    scale of a position error "in pixels": independent of the cameras' order)."""
    sizes = {camera.name: float(camera.pixel_size) for camera in cameras}
    return sizes, float(np.mean(list(sizes.values())))


def roundoff_floor(run, group):
    """The rms below which a true ``velocity`` or ``acceleration`` is zero up to
    round-off: :data:`ROUNDOFF` × the volume's width over the run's duration (squared
    for an acceleration)."""
    width = float(np.max(run.volume.hi - run.volume.lo))
    duration = float(run.times[-1] - run.times[0]) if run.times.size > 1 else 1.0
    duration = duration if duration > 0 else 1.0
    power = 1 if group == "velocity" else 2
    return ROUNDOFF * width / duration**power


def guard_ratios(block, group, floor):
    """Set the ratios of one component's errors to None where its truth is zero up to
    round-off (``truth_rms`` < ``floor``), and say why (``ratio_na``)."""
    truth = block.get("truth_rms")
    if truth is None or truth >= floor:
        return block
    for summary in block.values():
        if isinstance(summary, dict) and "rms_normalized" in summary:
            for key in _RATIO_KEYS:
                summary[key] = None
                if isinstance(summary.get("ci95"), dict):
                    summary["ci95"][key] = None
    block["ratio_na"] = (
        f"the true {group} is 0 up to round-off (rms {truth:.2g} field units): ratios to it "
        "are n/a; the absolute errors stand"
    )
    return block


def finite_rms(values):
    """rms of the finite values, or None where there are none (JSON has no NaN)."""
    values = np.asarray(values, dtype=np.float64)
    values = values[np.isfinite(values)]
    return float(np.sqrt(np.mean(values**2))) if values.size else None


def no_tracer_reason(stats):
    """Why no tracer was kept (the exclusion counts), or None where some were."""
    if stats["tracers_kept"]:
        return None
    causes = {
        "ray_failed": "a ray failed",
        "off_sensor": "the image fell off a sensor",
        "image_lost": "an image was not found (too dim for the threshold, or cut)",
    }
    parts = [f"{n} {causes[k]}" for k, n in stats["excluded"].items() if n]
    return (
        f"no tracer kept of {stats['tracers']} ({'; '.join(parts) or 'none seeded'}): every "
        "number is n/a; brighten the cameras (lpt.exposure, sensor.peak_electrons), seed "
        "more tracers or aim the cameras at the volume"
    )


def reason_lines(case):
    """The summary's lines saying why a case's numbers are n/a (no tracer kept, a shift not
    resolved, a self-calibration without particles, ratios to a round-off truth)."""
    lines = [f"  n/a: {case[key]}" for key in ("no_tracer", "not_resolved") if case.get(key)]
    record = case.get("self_calibration") or {}
    if "n/a" in record:
        lines.append(f"  self-calibration n/a: {record['n/a']}")
    for group in ("velocity", "acceleration"):
        notes = {c: case[group][c].get("ratio_na") for c in case.get(group, {})}
        named = [c for c, note in notes.items() if note]
        if named:
            lines.append(f"  {group} {'/'.join(named)}: {notes[named[0]]}")
    return lines


def calibration_lines(case):
    """The summary's line of each camera's calibration fit residual (px): the rms distance,
    over the calibration target, between each fitted model's projection (the pinhole DLT and
    the Soloff polynomial of the OpenLPT POLYNOMIAL file) and the target's images.

    Parameters
    ----------
    case : dict
        One case of ``lpt_stats.json`` (``calibration_residual_px``: per camera ``{model:
        px}``).

    Returns
    -------
    list of str
        One line (none without residuals).
    """
    residuals = case.get("calibration_residual_px") or {}
    labels = {"pinhole": "pinhole", "soloff": "Soloff"}

    def cell(value):
        return "n/a" if value is None else f"{value:.3g}"

    parts = [
        f"{camera} "
        + ", ".join(f"{labels[k]} {cell(fits[k])}" for k in ("pinhole", "soloff") if k in fits)
        for camera, fits in residuals.items()
    ]
    return ["  calibration fit residual per camera (px): " + "; ".join(parts)] if parts else []
