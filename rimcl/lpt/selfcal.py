"""Volume self-calibration (Wieneke 2008) on the measured images.

An LPT experiment calibrated on a target corrects the residual misalignment of its
cameras with the particles themselves: every particle seen by every camera is
triangulated, and each camera's **disparity** (its image point minus the projection of the
triangulated point) is collected in sub-volumes of the measured box. Averaged over every
frame of the run (so over the time-mean distortion of the field), the disparities of a
sub-volume form a **disparity map** per camera; the mapping functions are then corrected so
that they carry each sub-volume's mean triangulated point onto its mean image point, and
the whole repeats until the maps no longer change.

Here the correction is a Soloff polynomial of its own (the same 19 terms in the same
normalised coordinates, fitted by least squares to the sub-volumes' mean disparities), added
to the model's coefficients: ``P'_c(X) = P_c(X) + D_c(X)``. With fewer sub-volumes than twice
the terms, the correction is linear (terms of total degree <= 1). Sub-volumes with fewer
than :data:`MIN_POINTS` points are skipped. The correspondence is the truth's (each image
point belongs to a known tracer), so the median disparity of a sub-volume stands in for the
peak of Wieneke's disparity histogram.

A self-calibration only absorbs what makes the cameras disagree: a displacement that every
camera's line of sight shares (the same apparent shift through the field) is invisible to
it, and so is which camera is wrong: every camera is corrected towards the common
least-squares point, so the positions stay near the first triangulation's while the
disparities vanish (the lost matches come back; the position error does not go away).
Comparing the errors with and without it shows how much of the refraction error a
calibration on the particles would remove.
"""

import dataclasses

import numpy as np

from rimcl.core.errors import RimclError
from rimcl.lpt.calibration import SOLOFF_EXPONENTS, SoloffModel, _soloff_terms, triangulate

#: Fewest triangulated points in a sub-volume for its disparity to count.
MIN_POINTS = 5
_LINEAR = SOLOFF_EXPONENTS.sum(axis=1) <= 1


@dataclasses.dataclass
class SelfCalibration:
    """The corrected models and how the disparities fell.

    Attributes
    ----------
    models : list of SoloffModel
        Each camera's corrected mapping.
    rms_disparity_px : list of float
        rms over points and cameras of the disparity before each iteration, and after the
        last.
    cells_used : int
        Sub-volumes holding at least :data:`MIN_POINTS` points (last iteration).
    terms : int
        Terms of the correction polynomial.
    """

    models: list
    rms_disparity_px: list
    cells_used: int
    terms: int

    def describe(self):
        return {
            "rms_disparity_px": self.rms_disparity_px,
            "cells_used": self.cells_used,
            "correction_terms": self.terms,
            "min_points_per_cell": MIN_POINTS,
        }


def _cell_index(points, lo, hi, cells):
    """Flat sub-volume index of points (M, 3) in the box, -1 outside."""
    cells = np.asarray(cells)
    scaled = (points - lo) / (hi - lo) * cells
    finite = np.isfinite(scaled)
    index = np.floor(np.where(finite, scaled, -1.0)).astype(np.int64)  # NaN: a lost point
    inside = np.all((index >= 0) & (index < cells) & finite, axis=1)
    flat = np.ravel_multi_index(tuple(np.clip(index, 0, cells - 1).T), tuple(cells))
    return np.where(inside, flat, -1)


def _rms(disparity):
    finite = disparity[np.isfinite(disparity)]
    return float(np.sqrt(np.mean(finite**2))) if finite.size else None


def self_calibrate(models, pixels, cells=(3, 5, 5), iterations=3):
    """Correct Soloff models with the disparities of the measured particles.

    Parameters
    ----------
    models : list of SoloffModel
        One per camera, fitted on the target.
    pixels : ndarray, shape (C, M, 2)
        Located image points of ``M`` particle images (every frame) in each camera; NaN
        rows are left out.
    cells : tuple of 3 int
        Sub-volumes along ``x1`` (depth), ``x2``, ``x3`` of the models' target box.
    iterations : int
        Rounds of triangulation and correction.

    Returns
    -------
    SelfCalibration
    """
    if not all(isinstance(m, SoloffModel) for m in models):
        raise RimclError("the volume self-calibration corrects Soloff models (lpt.model)")
    pixels = np.asarray(pixels, dtype=np.float64)
    lo = models[0].centre - models[0].half
    hi = models[0].centre + models[0].half
    count = int(np.prod(cells))
    models = list(models)
    history, used, terms = [], 0, 0
    for _ in range(iterations):
        positions, _ = triangulate(models, pixels)
        residual = np.stack([pixels[c] - m.project(positions) for c, m in enumerate(models)])
        history.append(_rms(np.linalg.norm(residual, axis=-1)))
        index = _cell_index(positions, lo, hi, cells)
        keep = (index >= 0) & np.all(np.isfinite(residual), axis=(0, 2))
        members = np.bincount(index[keep], minlength=count)
        full = np.flatnonzero(members >= MIN_POINTS)
        used = int(full.size)
        if used < 4:
            raise RimclError(
                f"volume self-calibration: only {used} sub-volumes hold {MIN_POINTS} or more "
                "particles; use more tracers or frames, or fewer lpt.self_calibration_cells"
            )
        centres = np.stack([positions[keep][index[keep] == cell].mean(axis=0) for cell in full])
        chosen = np.ones(len(SOLOFF_EXPONENTS), bool) if used >= 2 * 19 else _LINEAR
        terms = int(chosen.sum())
        corrected = []
        for c, model in enumerate(models):
            shift = np.stack(
                [np.median(residual[c][keep][index[keep] == cell], axis=0) for cell in full]
            )
            design = _soloff_terms(model._normalise(centres))[:, chosen]
            fit, *_ = np.linalg.lstsq(design, shift, rcond=None)
            correction = np.zeros_like(model.coefficients)
            correction[chosen] = fit
            corrected.append(
                dataclasses.replace(model, coefficients=model.coefficients + correction)
            )
        models = corrected
    positions, _ = triangulate(models, pixels)
    residual = np.stack([pixels[c] - m.project(positions) for c, m in enumerate(models)])
    history.append(_rms(np.linalg.norm(residual, axis=-1)))
    return SelfCalibration(models, history, used, terms)
