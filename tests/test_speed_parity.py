"""The numba float64 speed baseline traces the same rays as the kernel (speed itself is
measured by benchmarks/speed.py, never here)."""

import numpy as np
import pytest
from tracing_fields import oblique_rays, smooth_field

import rimcl

pytest.importorskip("numba")

from rimcl.optics.baseline import trace_rays_numba


@pytest.mark.slow
@pytest.mark.parametrize("periodic", [False, True])
def test_default_trace_agrees_with_the_numba_baseline(device, periodic):
    """Must hold (issue 6): the default trace (trilinear, f32c) agrees with the float64
    numba implementation to 2e-6 L, with the same status and step counts."""
    field = smooth_field(3e-2, counts=(32, 30, 28), periodic=periodic, seed=13)
    length = 2 * np.pi if periodic else 1.0
    origins, directions = oblique_rays(200, 0.2 * length, 0.8 * length, 0.25, seed=14)
    x_end = 0.95 * length
    kernel = rimcl.trace_rays(field, origins, directions, x_end=x_end, device=device)
    # the serial build of the same code: it compiles in a third of the time
    baseline = trace_rays_numba(field, origins, directions, x_end=x_end, parallel=False)
    np.testing.assert_array_equal(kernel.status, baseline.status)
    np.testing.assert_array_equal(kernel.steps, baseline.steps)
    assert kernel.counts["ok"] >= 190
    ok = kernel.ok
    assert np.max(np.abs(kernel.image_pos[ok] - baseline.image_pos[ok])) <= 2e-6 * length
    np.testing.assert_allclose(kernel.end_dir[ok], baseline.end_dir[ok], rtol=0, atol=1e-7)
