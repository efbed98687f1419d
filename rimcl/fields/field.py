"""Refractive-index fields: gridded (:class:`Field`) and closed-form (:class:`AnalyticField`).

A gridded field stores ``δn = n - n_ref`` in float32 with ``n_ref`` a float64 scalar
(storing ``n`` itself in float32 ruins small gradients), plus ``∇n`` in float32.
Arrays are C-ordered ``(n3, n2, n1)`` so that ``x1``, the marching direction of the
rays, is contiguous; gradients are ``(n3, n2, n1, 3)`` with components along
``x1, x2, x3``. Grids are node-centred: node ``i`` along ``x_k`` sits at
``origin_k + i * spacing_k``.
"""

import dataclasses
import functools

import numpy as np

from rimcl.core.errors import RimclError
from rimcl.fields.derivatives import gradient as compute_gradient

BOUNDARIES = ("clamp", "periodic")


def _triple(values, name):
    array = np.asarray(values, dtype=np.float64).reshape(-1)
    if array.size != 3 or not np.all(np.isfinite(array)):
        raise RimclError(f"{name} must be 3 finite numbers (x1, x2, x3), got {values!r}")
    return array


@dataclasses.dataclass(eq=False)
class Field:
    """A gridded refractive-index field.

    Build it with :meth:`from_arrays`; the attributes are not meant to be set directly.

    Attributes
    ----------
    delta_n : ndarray, float32, shape (n3, n2, n1)
        ``n - n_ref``.
    gradient : ndarray, float32, shape (n3, n2, n1, 3)
        ``∇n`` (1/length), components along ``x1, x2, x3``.
    spacing, origin : ndarray, float64, shape (3,)
        Along ``x1, x2, x3`` (length units).
    n_ref : float
        Reference refractive index (float64).
    boundary : {"clamp", "periodic"}
        ``clamp`` samples the nearest edge value outside the grid; ``periodic`` wraps
        (the grid then holds one full period, endpoint excluded).
    attrs : dict
        Provenance (source file, frame, time, Gladstone–Dale product...).
    """

    delta_n: np.ndarray
    gradient: np.ndarray
    spacing: np.ndarray
    origin: np.ndarray
    n_ref: float
    boundary: str = "clamp"
    attrs: dict = dataclasses.field(default_factory=dict)
    _device_cache: dict = dataclasses.field(default_factory=dict, repr=False)

    @classmethod
    def from_arrays(
        cls,
        delta_n,
        spacing,
        origin=(0.0, 0.0, 0.0),
        n_ref=1.0,
        gradient=None,
        boundary="clamp",
        gradient_method=None,
        attrs=None,
    ):
        """Build a field from arrays, computing ``∇n`` if it is not given.

        Parameters
        ----------
        delta_n : array_like, shape (n3, n2, n1)
            ``n - n_ref``; stored as float32.
        spacing : sequence of 3 float
            ``(h1, h2, h3)``, positive (length units).
        origin : sequence of 3 float
            Position of node ``(0, 0, 0)`` as ``(x1, x2, x3)``.
        n_ref : float
            Reference index, kept in float64.
        gradient : array_like, shape (n3, n2, n1, 3), optional
            ``∇n`` along ``x1, x2, x3``. Computed from ``delta_n`` in float64 when omitted.
        boundary : {"clamp", "periodic"}
        gradient_method : {"fd2", "fd4", "fd6", "spectral"}, optional
            Default ``spectral`` for periodic fields, ``fd4`` otherwise.
        attrs : dict, optional
            Provenance to carry along.

        Returns
        -------
        Field
        """
        if boundary not in BOUNDARIES:
            raise RimclError(f"boundary must be one of {BOUNDARIES}, got {boundary!r}")
        values = np.asarray(delta_n)
        if values.ndim != 3:
            raise RimclError(f"delta_n must have shape (n3, n2, n1), got {values.shape}")
        if min(values.shape) < 1 or (boundary == "clamp" and values.shape[2] < 2):
            raise RimclError(f"delta_n shape {values.shape} is too small to trace through")
        if not np.all(np.isfinite(values)):
            raise RimclError("delta_n holds NaN or infinite values")
        spacing = _triple(spacing, "spacing")
        if np.any(spacing <= 0):
            raise RimclError(f"spacing must be positive, got {spacing.tolist()}")
        origin = _triple(origin, "origin")
        n_ref = float(n_ref)
        if not np.isfinite(n_ref) or n_ref <= 0:
            raise RimclError(f"n_ref must be a positive number, got {n_ref}")
        if gradient is None:
            method = gradient_method or ("spectral" if boundary == "periodic" else "fd4")
            grad = compute_gradient(values, spacing, method=method, periodic=boundary == "periodic")
        else:
            grad = np.asarray(gradient)
            if grad.shape != (*values.shape, 3):
                raise RimclError(f"gradient must have shape {(*values.shape, 3)}, got {grad.shape}")
            if not np.all(np.isfinite(grad)):
                raise RimclError("gradient holds NaN or infinite values")
        if np.min(values) + n_ref <= 0:
            raise RimclError("n_ref + delta_n must be positive everywhere")
        return cls(
            delta_n=np.ascontiguousarray(values, dtype=np.float32),
            gradient=np.ascontiguousarray(grad, dtype=np.float32),
            spacing=spacing,
            origin=origin,
            n_ref=n_ref,
            boundary=boundary,
            attrs=dict(attrs or {}),
        )

    @property
    def shape(self):
        """Array shape ``(n3, n2, n1)``."""
        return self.delta_n.shape

    @property
    def counts(self):
        """Node counts along ``x1, x2, x3``."""
        n3, n2, n1 = self.delta_n.shape
        return np.array([n1, n2, n3])

    @property
    def periodic(self):
        return self.boundary == "periodic"

    @property
    def grid_lo(self):
        """Lowest node position along ``x1, x2, x3``."""
        return self.origin.copy()

    @property
    def grid_hi(self):
        """Highest node position along ``x1, x2, x3`` (for periodic fields, the period end)."""
        last = self.counts if self.periodic else self.counts - 1
        return self.origin + last * self.spacing

    @property
    def box_lo(self):
        """Lower corner of the region rays may move in (``-inf`` where periodic)."""
        return np.full(3, -np.inf) if self.periodic else self.grid_lo

    @property
    def box_hi(self):
        """Upper corner of the region rays may move in (``+inf`` where periodic)."""
        return np.full(3, np.inf) if self.periodic else self.grid_hi

    @functools.cached_property
    def is_uniform(self):
        """δn and ∇n are zero everywhere: rays go straight.

        (:func:`rimcl.optics.straight.straight_rays` then skips the integrator.)
        """
        return not (np.any(self.delta_n) or np.any(self.gradient))

    @property
    def delta_n_range(self):
        """``max(δn) - min(δn)``, the field's Δn_max."""
        return float(np.max(self.delta_n)) - float(np.min(self.delta_n))

    @property
    def n_min(self):
        return self.n_ref + float(np.min(self.delta_n))

    @property
    def packed(self):
        """``(n3, n2, n1, 4)`` float32: ``δn, ∂n/∂x1, ∂n/∂x2, ∂n/∂x3`` per node."""
        if "packed" not in self._device_cache:
            packed = np.empty((*self.shape, 4), dtype=np.float32)
            packed[..., 0] = self.delta_n
            packed[..., 1:] = self.gradient
            self._device_cache["packed"] = packed
        return self._device_cache["packed"]

    def cached(self, key, make):
        """Per-field cache of derived data and device buffers (uploaded once)."""
        if key not in self._device_cache:
            self._device_cache[key] = make()
        return self._device_cache[key]

    def describe(self):
        """Plain-data summary for output files."""
        return {
            "kind": "grid",
            "shape_n3_n2_n1": list(self.shape),
            "spacing": self.spacing.tolist(),
            "origin": self.origin.tolist(),
            "n_ref": self.n_ref,
            "boundary": self.boundary,
            "delta_n_range": self.delta_n_range,
            "attrs": {k: v for k, v in self.attrs.items() if _plain(v)},
        }


def _plain(value):
    return isinstance(value, (str, int, float, bool, list, tuple)) or np.isscalar(value)


ANALYTIC_KINDS = ("uniform", "grin", "fisheye", "linear")

# parameter names and defaults of each closed-form field
_ANALYTIC_PARAMS = {
    "uniform": {"n0": 1.0},
    "grin": {"n0": 1.5, "alpha": 0.01},
    "fisheye": {"n_max": 2.0},
    "linear": {"n0": 1.33, "g": 1e-3},
}


@dataclasses.dataclass(eq=False)
class AnalyticField:
    """A closed-form refractive-index field evaluated inside the kernel.

    Kinds (coordinates ``x1, x2, x3``):

    - ``uniform``: ``n = n0``.
    - ``grin``: GRIN rod, ``n² = n0² (1 - alpha² x2²)``.
    - ``fisheye``: Maxwell fish-eye (cylindrical), ``n = n_max / (1 + x1² + x2²)``.
    - ``linear``: ``n = n0 + g x2``.

    Attributes
    ----------
    kind : str
    params : dict of str to float
    box_lo, box_hi : ndarray, shape (3,)
        Region the rays may move in; leaving it gives status ``exit_side``.
    """

    kind: str
    params: dict
    box_lo: np.ndarray
    box_hi: np.ndarray

    periodic = False

    @property
    def n_ref(self):
        return float(self.params.get("n0", self.params.get("n_max", 1.0)))

    def refractive_index(self, points):
        """``n`` at ``points`` (``(..., 3)``, float64)."""
        x = np.asarray(points, dtype=np.float64)
        p = self.params
        if self.kind == "uniform":
            return np.full(x.shape[:-1], p["n0"])
        if self.kind == "grin":
            return p["n0"] * np.sqrt(1.0 - (p["alpha"] * x[..., 1]) ** 2)
        if self.kind == "fisheye":
            return p["n_max"] / (1.0 + x[..., 0] ** 2 + x[..., 1] ** 2)
        return p["n0"] + p["g"] * x[..., 1]

    def index_gradient(self, points):
        """``∇n`` at ``points`` (``(..., 3)``, float64)."""
        x = np.asarray(points, dtype=np.float64)
        p = self.params
        grad = np.zeros(x.shape)
        if self.kind == "grin":
            grad[..., 1] = -(p["n0"] ** 2) * p["alpha"] ** 2 * x[..., 1] / self.refractive_index(x)
        elif self.kind == "fisheye":
            scale = -2.0 * p["n_max"] / (1.0 + x[..., 0] ** 2 + x[..., 1] ** 2) ** 2
            grad[..., 0] = scale * x[..., 0]
            grad[..., 1] = scale * x[..., 1]
        elif self.kind == "linear":
            grad[..., 1] = p["g"]
        return grad

    def on_grid(self, counts, lo, hi, n_ref=None):
        """Sample this field onto a node grid (δn and exact ∇n), as a :class:`Field`.

        Parameters
        ----------
        counts : sequence of 3 int
            Nodes along ``x1, x2, x3``.
        lo, hi : sequence of 3 float
            First and last node positions along ``x1, x2, x3``.
        n_ref : float, optional
            Reference index (default: this field's ``n_ref``).
        """
        counts = np.asarray(counts, dtype=int)
        lo = np.asarray(lo, dtype=np.float64)
        hi = np.asarray(hi, dtype=np.float64)
        spacing = np.where(counts > 1, (hi - lo) / np.maximum(counts - 1, 1), 1.0)
        axes = [lo[k] + spacing[k] * np.arange(counts[k]) for k in range(3)]
        x3, x2, x1 = np.meshgrid(axes[2], axes[1], axes[0], indexing="ij")
        points = np.stack([x1, x2, x3], axis=-1)
        n_ref = self.n_ref if n_ref is None else float(n_ref)
        return Field.from_arrays(
            self.refractive_index(points) - n_ref,
            spacing=spacing,
            origin=lo,
            n_ref=n_ref,
            gradient=self.index_gradient(points),
            attrs={"analytic": self.kind, **{k: float(v) for k, v in self.params.items()}},
        )

    def describe(self):
        return {
            "kind": "analytic",
            "analytic": self.kind,
            "params": dict(self.params),
            "box_lo": self.box_lo.tolist(),
            "box_hi": self.box_hi.tolist(),
        }


def analytic_field(kind, box_lo=None, box_hi=None, **params):
    """Make a closed-form field.

    Parameters
    ----------
    kind : {"uniform", "grin", "fisheye", "linear"}
    box_lo, box_hi : sequence of 3 float, optional
        Region the rays may move in (default: unbounded).
    **params
        ``n0``, ``alpha``, ``n_max``, ``g`` as the kind needs (defaults in
        ``_ANALYTIC_PARAMS``).

    Returns
    -------
    AnalyticField
    """
    if kind not in ANALYTIC_KINDS:
        raise RimclError(f"unknown analytic field {kind!r}; choose from {ANALYTIC_KINDS}")
    merged = dict(_ANALYTIC_PARAMS[kind])
    unknown = set(params) - set(merged)
    if unknown:
        raise RimclError(f"analytic field {kind!r} takes {sorted(merged)}, not {sorted(unknown)}")
    merged.update({k: float(v) for k, v in params.items()})
    lo = np.full(3, -np.inf) if box_lo is None else np.asarray(box_lo, dtype=np.float64)
    hi = np.full(3, np.inf) if box_hi is None else np.asarray(box_hi, dtype=np.float64)
    return AnalyticField(kind=kind, params=merged, box_lo=lo, box_hi=hi)
