"""Matching from the images alone: epipolar candidates, ghosts and misses against the truth.

A real LPT code does not know which image belongs to which particle. It takes each image
point ``a`` of the first camera, follows its line of sight through the volume (the
calibrated model's points on ``DEPTHS`` planes ``x1 = const`` across the target's box), and
keeps the image points of the last camera (the widest pair of the presets) within a
tolerance of the projection of that line (the epipolar curve). Each pair is triangulated
and projected into the other cameras; a candidate whose projection has an image point
within the tolerance in every camera is a match. A match whose image points all belong to
one tracer is **true**, any other is a **ghost**; a tracer with no true match is
**missed** (its disparity exceeds the tolerance somewhere, or its image was not located).

Image points are the located centroids of :func:`rimcl.lpt.run.run_case` (one window per
tracer, so overlapping images are not merged here: the ghosts counted are those of the
geometry and the refraction, at the density ``ppp`` of the run).
"""

import numpy as np
from scipy.spatial import cKDTree

from rimcl.lpt.calibration import triangulate

#: Points along each line of sight (planes across the target's depth).
DEPTHS = 24


def _epipolar_curves(model_a, model_b, pixels, depths):
    """Camera b's pixels of camera a's lines of sight of ``pixels`` (A, 2) at ``depths``
    (D,): shape (A, D, 2), NaN where a line leaves the model's reach."""
    count, planes = len(pixels), len(depths)
    repeated = np.repeat(pixels, planes, axis=0)
    start = np.broadcast_to(model_a.centre, (count * planes, 3)).copy()
    points = model_a.on_plane(repeated, np.tile(depths, count), start)
    curves = model_b.project(np.nan_to_num(points))
    curves[~np.all(np.isfinite(points), axis=1)] = np.nan
    return curves.reshape(count, planes, 2)


def _segment_distance(points, starts, ends):
    """Distance of points (P, 2) to the nearest of the segments (S, 2)→(S, 2): (P,)."""
    along = ends - starts
    length2 = np.maximum(np.sum(along**2, axis=1), 1e-300)
    offset = points[:, None, :] - starts[None]
    share = np.clip(np.sum(offset * along[None], axis=2) / length2, 0.0, 1.0)
    nearest = starts[None] + share[..., None] * along[None]
    return np.min(np.linalg.norm(points[:, None, :] - nearest, axis=2), axis=1)


def match_frame(models, pixels, tolerance_px):
    """Match the image points of one frame without knowing the correspondence.

    Parameters
    ----------
    models : list of SoloffModel
        One per camera (at least 3).
    pixels : ndarray, shape (C, N, 2)
        Located image points; row ``i`` of every camera is tracer ``i`` (used only to
        score the matches); NaN rows are images not found.
    tolerance_px : float

    Returns
    -------
    dict
        ``tracers`` (with an image in every camera), ``matches``, ``true``, ``ghosts``,
        ``missed`` (tracers without a true match) and ``ghost_fraction`` (ghosts over
        matches), ``missed_fraction`` (missed over tracers).
    """
    pixels = np.asarray(pixels, dtype=np.float64)
    cameras, count = pixels.shape[:2]
    seen = [np.flatnonzero(np.all(np.isfinite(p), axis=1)) for p in pixels]
    trees = [cKDTree(p[s]) for p, s in zip(pixels, seen, strict=True)]
    lo = models[0].centre[0] - models[0].half[0]
    hi = models[0].centre[0] + models[0].half[0]
    depths = np.linspace(lo, hi, DEPTHS)
    # the first and the last camera: the widest pair of the presets, whose two-camera
    # point is best defined in depth (a narrow pair's depth error, projected into the
    # other cameras, would throw true matches out)
    last = cameras - 1
    curves = _epipolar_curves(models[0], models[last], pixels[0, seen[0]], depths)
    first, second = [], []
    for a, curve in zip(seen[0], curves, strict=True):
        curve = curve[np.all(np.isfinite(curve), axis=1)]
        if len(curve) < 2:
            continue
        reach = tolerance_px + 0.5 * np.max(np.linalg.norm(np.diff(curve, axis=0), axis=1))
        near = sorted({i for hits in trees[last].query_ball_point(curve, reach) for i in hits})
        if not near:
            continue
        candidates = seen[last][near]
        close = _segment_distance(pixels[last, candidates], curve[:-1], curve[1:])
        close = close <= tolerance_px
        first += [a] * int(close.sum())
        second += list(candidates[close])
    first, second = np.asarray(first, dtype=np.int64), np.asarray(second, dtype=np.int64)
    valid, same = np.zeros(first.size, dtype=bool), first == second
    # every candidate pair at once: triangulated on the first two cameras, then looked for
    # in the others (no pair at all, with few tracers: nothing matched)
    if first.size:
        pair = np.stack([pixels[0, first], pixels[last, second]])
        positions, _ = triangulate([models[0], models[last]], pair)
        valid = np.all(np.isfinite(positions), axis=1)
    for c in range(1, last):
        if not (first.size and seen[c].size):
            valid[:] = False
            break
        distance, index = trees[c].query(models[c].project(np.nan_to_num(positions)))
        valid &= distance <= tolerance_px
        same &= seen[c][np.asarray(index, dtype=np.int64)] == first
    true = int(np.sum(valid & same))
    ghosts = int(np.sum(valid & ~same))
    found = set(first[valid & same].tolist())
    complete = int(np.sum(np.all(np.isfinite(pixels), axis=(0, 2))))
    matches = true + ghosts
    return {
        "tolerance_px": float(tolerance_px),
        "tracers": complete,
        "matches": int(matches),
        "true": int(true),
        "ghosts": int(ghosts),
        "missed": int(count - len(found)),
        "ghost_fraction": ghosts / matches if matches else None,
        "missed_fraction": (count - len(found)) / count if count else None,
    }
