"""Calibration as an experiment does it, lines of sight and triangulation.

A target of points on several planes ``x1 = const`` across the measured volume is imaged
through the uniform fluid (at rest, window in place): the pinhole-plus-window projection
(:meth:`rimcl.lpt.rig.RigCamera.project`). Each camera is then fitted with

- a **pinhole** model: the direct linear transform (DLT, 11 parameters, Hartley-normalised
  linear least squares), which cannot represent the window's refraction exactly;
- a **Soloff polynomial**: each pixel coordinate a polynomial in ``(x, y, z) = (x2, x3, x1)``,
  cubic in ``x, y`` and quadratic in ``z`` (19 terms; Soloff, Adrian & Liu 1997).

The fit's rms residual over the target (px) is the calibration's own error, part of the
baseline. A camera maps an image point back to its **line of sight** (pinhole: the ray
through the centre; Soloff: the line through the points that map to the image point on two
planes ``x1 = const``). Triangulation is the least-squares intersection of the lines:
``X`` minimising ``Σ_k |(I - D_k D_kᵀ)(X - E_k)|²``; for Soloff the planes are then moved
to ``X ± δ`` and the intersection repeated, so each line is the local tangent of the
(slightly curved) polynomial line of sight. The **disparity** of a tracer is the largest
distance (px) between a camera's image point and the projection of the triangulated point.
"""

import dataclasses
import itertools

import numpy as np

from rimcl.core.errors import RimclError

#: Exponents of ``(x, y, z)`` of the Soloff terms: total degree <= 3, ``z`` at most squared.
SOLOFF_EXPONENTS = np.array(
    [e for e in itertools.product(range(4), repeat=3) if sum(e) <= 3 and e[2] <= 2]
)
_NEWTON_ITERATIONS = 30


def target_points(lo, hi, planes, grid):
    """Target points on ``planes`` planes ``x1 = const`` spanning ``[lo, hi]``.

    Parameters
    ----------
    lo, hi : sequence of 3 float
        Corners of the calibrated volume ``(x1, x2, x3)``.
    planes : int
    grid : tuple of 2 int
        Points along ``x2`` and ``x3`` per plane.

    Returns
    -------
    ndarray, float64, shape (planes · grid[0] · grid[1], 3)
    """
    x1 = np.linspace(lo[0], hi[0], planes)
    x2 = np.linspace(lo[1], hi[1], grid[0])
    x3 = np.linspace(lo[2], hi[2], grid[1])
    a, b, c = np.meshgrid(x1, x2, x3, indexing="ij")
    return np.column_stack([a.ravel(), b.ravel(), c.ravel()])


def _residual(model, points, pixels):
    return float(np.sqrt(np.mean(np.sum((model.project(points) - pixels) ** 2, axis=1))))


@dataclasses.dataclass(frozen=True)
class PinholeModel:
    """A DLT camera matrix ``P`` (3 x 4): ``[u w, v w, w] = P [X, 1]``.

    Attributes
    ----------
    matrix : ndarray, shape (3, 4)
    residual_px : float
        rms reprojection error over the target.
    """

    matrix: np.ndarray
    residual_px: float = float("nan")

    @classmethod
    def fit(cls, points, pixels):
        """Hartley-normalised DLT from points (M, 3) and their pixels (M, 2)."""
        points = np.asarray(points, dtype=np.float64)
        pixels = np.asarray(pixels, dtype=np.float64)
        if len(points) < 6:
            raise RimclError("a DLT fit needs at least 6 target points")
        t3, s3 = (
            points.mean(axis=0),
            np.sqrt(3) / np.mean(np.linalg.norm(points - points.mean(0), axis=1)),
        )
        t2, s2 = (
            pixels.mean(axis=0),
            np.sqrt(2) / np.mean(np.linalg.norm(pixels - pixels.mean(0), axis=1)),
        )
        xn = (points - t3) * s3
        un = (pixels - t2) * s2
        ones = np.ones((len(xn), 1))
        zeros = np.zeros((len(xn), 4))
        homog = np.hstack([xn, ones])
        rows_u = np.hstack([homog, zeros, -un[:, :1] * homog])
        rows_v = np.hstack([zeros, homog, -un[:, 1:] * homog])
        _, _, vt = np.linalg.svd(np.vstack([rows_u, rows_v]), full_matrices=False)
        normalised = vt[-1].reshape(3, 4)
        to_pixels = np.array([[1 / s2, 0, t2[0]], [0, 1 / s2, t2[1]], [0, 0, 1]])
        from_points = np.vstack([np.hstack([s3 * np.eye(3), (-s3 * t3)[:, None]]), [0, 0, 0, 1]])
        matrix = to_pixels @ normalised @ from_points
        matrix = matrix / np.linalg.norm(matrix[2, :3])
        model = cls(matrix)
        return dataclasses.replace(model, residual_px=_residual(model, points, pixels))

    def project(self, points):
        """Pixels (M, 2) of points (M, 3)."""
        homog = np.asarray(points, dtype=np.float64) @ self.matrix[:, :3].T + self.matrix[:, 3]
        return homog[:, :2] / homog[:, 2:]

    @property
    def centre(self):
        """The projection centre (3,)."""
        return -np.linalg.solve(self.matrix[:, :3], self.matrix[:, 3])

    def lines(self, pixels, near=None):
        """Lines of sight ``(E, D)`` (each (M, 3), ``D`` unit) of pixels (M, 2)."""
        pixels = np.asarray(pixels, dtype=np.float64)
        homog = np.column_stack([pixels, np.ones(len(pixels))])
        directions = np.linalg.solve(self.matrix[:, :3], homog.T).T
        directions /= np.linalg.norm(directions, axis=1, keepdims=True)
        return np.broadcast_to(self.centre, directions.shape), directions

    def describe(self):
        return {
            "model": "pinhole (DLT)",
            "matrix": self.matrix.tolist(),
            "residual_px": self.residual_px,
        }


def _soloff_terms(normalised, derivative=None):
    """Soloff terms (M, 19) at normalised ``(x, y, z)`` (M, 3), or their derivative along
    axis ``derivative`` (0, 1, 2 for x, y, z).

    Built from a table of powers ``x^0 … x^3`` per axis (products, no ``**``): the Newton
    loops of :meth:`SoloffModel.on_plane` evaluate it for every tracer and iteration.
    """
    exponents = SOLOFF_EXPONENTS
    powers = np.empty((3, 4, len(normalised)))  # axis, power, point: contiguous rows
    powers[:, 0] = 1.0
    for order in range(1, 4):
        powers[:, order] = powers[:, order - 1] * normalised.T
    factor = None
    if derivative is not None:
        factor = exponents[:, derivative].astype(np.float64)[:, None]
        exponents = np.maximum(exponents - np.eye(3, dtype=int)[derivative], 0)
    terms = powers[0, exponents[:, 0]] * powers[1, exponents[:, 1]]
    terms *= powers[2, exponents[:, 2]]
    return (terms if factor is None else terms * factor).T


@dataclasses.dataclass(frozen=True)
class SoloffModel:
    """Pixel ``(u, v) = Σ c_j x^a y^b z^c`` over the 19 Soloff terms.

    ``(x, y, z) = (x2, x3, x1)`` normalised to ``[-1, 1]`` over the target's box.

    Attributes
    ----------
    coefficients : ndarray, shape (19, 2)
    centre, half : ndarray, shape (3,)
        Normalisation ``(x1, x2, x3)``: ``(X - centre) / half``.
    residual_px : float
    """

    coefficients: np.ndarray
    centre: np.ndarray
    half: np.ndarray
    residual_px: float = float("nan")
    _order = (1, 2, 0)  # (x, y, z) = (x2, x3, x1)

    @classmethod
    def fit(cls, points, pixels):
        """Linear least squares of the 19 terms over target points (M, 3) and pixels (M, 2)."""
        points = np.asarray(points, dtype=np.float64)
        lo, hi = points.min(axis=0), points.max(axis=0)
        if np.any(hi <= lo) or len(np.unique(points[:, 0])) < 3:
            raise RimclError("a Soloff fit needs target points spread over at least 3 planes")
        centre, half = 0.5 * (lo + hi), 0.5 * (hi - lo)
        model = cls(np.zeros((len(SOLOFF_EXPONENTS), 2)), centre, half)
        terms = _soloff_terms(model._normalise(points))
        coefficients, *_ = np.linalg.lstsq(terms, np.asarray(pixels, dtype=np.float64), rcond=None)
        model = dataclasses.replace(model, coefficients=coefficients)
        return dataclasses.replace(model, residual_px=_residual(model, points, pixels))

    def _normalise(self, points):
        return ((points - self.centre) / self.half)[:, self._order]

    def project(self, points):
        """Pixels (M, 2) of points (M, 3)."""
        return (
            _soloff_terms(self._normalise(np.asarray(points, dtype=np.float64))) @ self.coefficients
        )

    def _jacobian_lateral(self, points):
        """d(u, v)/d(x2, x3) at points (M, 3): shape (M, 2, 2)."""
        normalised = self._normalise(points)
        columns = [
            _soloff_terms(normalised, axis) @ self.coefficients / self.half[self._order[axis]]
            for axis in (0, 1)
        ]
        return np.stack(columns, axis=-1)

    def on_plane(self, pixels, x1, start):
        """Points on planes ``x1`` (M,) that map to ``pixels`` (M, 2), by Newton from
        ``start`` (M, 3), all points at once (each stops when its step is below 1e-12 of
        the box). NaN where Newton does not converge."""
        pixels = np.asarray(pixels, dtype=np.float64)
        points = np.array(start, dtype=np.float64)
        points[:, 0] = x1
        good = np.all(np.isfinite(pixels), axis=1) & np.all(np.isfinite(points), axis=1)
        chosen, target = points[good], pixels[good]
        active = np.arange(len(chosen))
        tolerance = 1e-12 * self.half[1:]
        for _ in range(_NEWTON_ITERATIONS):
            if not active.size:
                break
            moving = chosen[active]
            residual = self.project(moving) - target[active]
            jacobian = self._jacobian_lateral(moving)
            # the 2 x 2 systems solved in closed form (Cramer), all at once
            a, b = jacobian[:, 0, 0], jacobian[:, 0, 1]
            c, d = jacobian[:, 1, 0], jacobian[:, 1, 1]
            with np.errstate(invalid="ignore", divide="ignore"):
                determinant = a * d - b * c
                step = np.column_stack(
                    [
                        (d * residual[:, 0] - b * residual[:, 1]) / determinant,
                        (a * residual[:, 1] - c * residual[:, 0]) / determinant,
                    ]
                )
            chosen[active, 1:] = moving[:, 1:] - step
            active = active[~np.all(np.abs(step) <= tolerance, axis=1)]
        chosen[~np.all(np.abs(self.project(chosen) - target) < 1e-6, axis=1)] = np.nan
        points[good] = chosen
        points[~good] = np.nan
        return points

    def lines(self, pixels, near):
        """Lines of sight ``(E, D)`` of pixels (M, 2) around the points ``near`` (M, 3)."""
        delta = 0.1 * self.half[0]
        first = self.on_plane(pixels, near[:, 0] - delta, near)
        second = self.on_plane(pixels, near[:, 0] + delta, near)
        direction = second - first
        return first, direction / np.linalg.norm(direction, axis=1, keepdims=True)

    def describe(self):
        return {
            "model": "soloff (cubic in x2, x3; quadratic in x1)",
            "exponents_x2_x3_x1": SOLOFF_EXPONENTS.tolist(),
            "coefficients_u_v": self.coefficients.tolist(),
            "centre": self.centre.tolist(),
            "half_width": self.half.tolist(),
            "residual_px": self.residual_px,
        }


def intersect(starts, directions):
    """Least-squares intersection of lines, per point.

    Parameters
    ----------
    starts, directions : ndarray, shape (C, M, 3)
        ``C`` lines (one per camera) for each of ``M`` points; ``directions`` unit.

    Returns
    -------
    ndarray, shape (M, 3)
        ``X`` minimising ``Σ_k |(I - D_k D_kᵀ)(X - E_k)|²``; NaN where a line is missing.
    """
    eye = np.eye(3)
    projector = eye - directions[..., :, None] * directions[..., None, :]  # (C, M, 3, 3)
    matrix = projector.sum(axis=0)
    vector = np.einsum("cmij,cmj->mi", projector, starts)
    bad = ~np.all(np.isfinite(matrix.reshape(len(matrix), -1)), axis=1)
    matrix[bad], vector[bad] = eye, np.nan
    return np.linalg.solve(matrix, vector[..., None])[..., 0]


def triangulate(models, pixels, refinements=2):
    """3-D positions from each camera's image points on calibrated models.

    Parameters
    ----------
    models : list of PinholeModel or SoloffModel
        One per camera.
    pixels : ndarray, shape (C, M, 2)
        Image points of ``M`` tracers in each of ``C`` cameras.
    refinements : int
        For Soloff models: intersections repeated with lines re-built at the last estimate
        (the first estimate is the pinhole-free intersection at the target's centre depth).

    Returns
    -------
    positions : ndarray, shape (M, 3)
    disparity : ndarray, shape (M, C)
        Distance (px) between each camera's image point and the projection of the position.
    """
    pixels = np.asarray(pixels, dtype=np.float64)
    count = pixels.shape[1]
    guess = None
    if isinstance(models[0], SoloffModel):
        guess = np.broadcast_to(models[0].centre, (count, 3)).copy()
    rounds = 1 + (refinements if guess is not None else 0)
    for _ in range(rounds):
        lines = [model.lines(p, guess) for model, p in zip(models, pixels, strict=True)]
        starts = np.stack([np.asarray(e, dtype=np.float64) for e, _ in lines])
        directions = np.stack([d for _, d in lines])
        guess = intersect(starts, directions)
    disparity = np.stack(
        [
            np.linalg.norm(model.project(np.nan_to_num(guess)) - p, axis=1)
            for model, p in zip(models, pixels, strict=True)
        ],
        axis=1,
    )
    disparity[~np.all(np.isfinite(guess), axis=1)] = np.nan
    return guess, disparity


def calibrate(camera, points, model):
    """Fit one camera's model to the target imaged through the uniform fluid.

    Parameters
    ----------
    camera : rimcl.lpt.rig.RigCamera
    points : ndarray, shape (M, 3)
        Target points.
    model : {"soloff", "pinhole"}

    Returns
    -------
    PinholeModel or SoloffModel
    """
    pixels = camera.project(points)
    if not np.all(np.isfinite(pixels)):
        raise RimclError(f"camera {camera.name} cannot see every calibration point")
    return (SoloffModel if model == "soloff" else PinholeModel).fit(points, pixels)
