"""Fields with known rays, shared by the interpolation, step, auto and failure tests."""

import numpy as np

import rimcl

#: Where the Luneburg-type lens index n² = 2 - r² is continued outside, r > LENS_KNEE,
#: by + LENS_CURL (r - LENS_KNEE)⁴: smooth (C³) and positive on the whole grid, and
#: more than 3 cells away from every ray, which stays inside the unit sphere.
LENS_KNEE, LENS_CURL = 1.1, 20.0


def luneburg_field(nodes=64, half_width=1.1):
    """A Luneburg lens of radius 1 at the origin, sampled on ``nodes³`` over the cube
    ``[-half_width, half_width]³`` (δn and the exact ∇n at the nodes, n_ref = 1).

    Inside the unit sphere ``n = sqrt(2 - r²)``: rays entering parallel to ``x1`` meet at
    the focus ``(1, 0, 0)`` on the far side of the sphere.
    """
    x = np.linspace(-half_width, half_width, nodes)
    x3, x2, x1 = np.meshgrid(x, x, x, indexing="ij")
    r = np.sqrt(x1**2 + x2**2 + x3**2)
    outside = r > LENS_KNEE
    n_squared = 2 - r**2 + np.where(outside, LENS_CURL * (r - LENS_KNEE) ** 4, 0.0)
    n = np.sqrt(n_squared)
    dn2_dr = -2 * r + np.where(outside, 4 * LENS_CURL * (r - LENS_KNEE) ** 3, 0.0)
    dn_dr_over_r = dn2_dr / (2 * n * np.where(r > 0, r, 1.0))
    gradient = np.stack([dn_dr_over_r * x1, dn_dr_over_r * x2, dn_dr_over_r * x3], axis=-1)
    return rimcl.Field.from_arrays(
        n - 1.0, spacing=(x[1] - x[0],) * 3, origin=(-half_width,) * 3, gradient=gradient
    )


def luneburg_rays(count, aperture=0.7, seed=0):
    """Rays parallel to ``+x1`` starting where they enter the unit sphere, at distances
    up to ``aperture`` from the axis (n = 1 there, so they enter unbent)."""
    rng = np.random.default_rng(seed)
    radius = aperture * np.sqrt(rng.uniform(0, 1, count))
    angle = rng.uniform(0, 2 * np.pi, count)
    x2, x3 = radius * np.cos(angle), radius * np.sin(angle)
    origins = np.column_stack([-np.sqrt(1 - x2**2 - x3**2), x2, x3])
    directions = np.tile([1.0, 0.0, 0.0], (count, 1))
    return origins, directions


def smooth_field(delta_n, counts=(20, 18, 16), periodic=False, n_ref=1.33, seed=0):
    """A few random Fourier modes of peak-to-peak amplitude ``delta_n`` on a grid of
    ``counts`` nodes along ``x1, x2, x3``: the box ``[0, 1]³`` (clamped) or one period
    ``2π`` (periodic)."""
    rng = np.random.default_rng(seed)
    counts = np.asarray(counts)
    spacing = 2 * np.pi / counts if periodic else 1.0 / (counts - 1)
    axes = [spacing[k] * np.arange(counts[k]) for k in range(3)]
    x3, x2, x1 = np.meshgrid(axes[2], axes[1], axes[0], indexing="ij")
    values = np.zeros(x1.shape)
    for _ in range(5):
        k = rng.integers(1, 3, size=3) * rng.choice([-1, 1], size=3)
        scale = 1.0 if periodic else np.pi
        values += np.cos(scale * (k[0] * x1 + k[1] * x2 + k[2] * x3) + rng.uniform(0, 2 * np.pi))
    values *= delta_n / np.ptp(values)
    return rimcl.Field.from_arrays(
        values, spacing=spacing, n_ref=n_ref, boundary="periodic" if periodic else "clamp"
    )


def oblique_rays(count, lo, hi, spread, seed=0):
    """Rays from the plane x1 = 0 with (x2, x3) uniform in [lo, hi]², within ``spread``
    rad of +x1 in x2 and x3."""
    rng = np.random.default_rng(seed)
    origins = np.column_stack([np.zeros(count), rng.uniform(lo, hi, (count, 2))])
    slopes = np.tan(rng.uniform(-spread, spread, (count, 2)))
    directions = np.column_stack([np.ones(count), slopes])
    return origins, directions / np.linalg.norm(directions, axis=1, keepdims=True)


def independent_module():
    """benchmarks/numba_independent.py: float64 tracing code written apart from the package
    (the speed benchmark's check of its baseline; the exit index's independent check)."""
    import importlib.util
    import sys
    from pathlib import Path

    if "numba_independent" in sys.modules:
        return sys.modules["numba_independent"]

    path = Path(__file__).resolve().parents[1] / "benchmarks" / "numba_independent.py"
    spec = importlib.util.spec_from_file_location("numba_independent", path)
    module = importlib.util.module_from_spec(spec)
    # registered before it runs: numba's disk cache finds its functions' module by name
    sys.modules["numba_independent"] = module
    spec.loader.exec_module(module)
    return module
