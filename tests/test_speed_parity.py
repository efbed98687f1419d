"""The numba float64 speed baseline traces the same rays as the kernel (speed itself is
measured by benchmarks/speed.py, never here)."""

import numpy as np
import pytest
from tracing_fields import independent_module, oblique_rays, smooth_field

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


@pytest.mark.parametrize("periodic", [False, True])
def test_both_numba_baselines_trace_the_float64_reference(periodic):
    """The package's numba baseline and the benchmark's independent numba code (which
    checks the baseline's speed) trace what the float64 NumPy reference traces: the
    same statuses and step counts, exit points and directions to float64 rounding."""
    from rimcl.optics.reference import trace_rays_reference
    from rimcl.optics.trace import default_step, join_pairs, split_pairs

    independent = independent_module()
    field = smooth_field(3e-2, counts=(16, 14, 12), periodic=periodic, seed=21)
    length = 2 * np.pi if periodic else 1.0
    origins, directions = oblique_rays(24, 0.2 * length, 0.8 * length, 0.3, seed=22)
    # the inputs the reference rounds to (float32 pairs, as the kernel receives them)
    origins = join_pairs(*split_pairs(origins))
    directions = directions / np.linalg.norm(directions, axis=1, keepdims=True)
    directions = join_pairs(*split_pairs(directions))
    x_end = float(join_pairs(*split_pairs([0.95 * length]))[0])
    step = float(join_pairs(*split_pairs([default_step(field)]))[0])
    reference = trace_rays_reference(field, origins, directions, x_end=x_end, step=step)
    limit = 4000
    package = trace_rays_numba(
        field, origins, directions, x_end=x_end, step=step, max_steps=limit, parallel=False
    )
    end, steps, status = independent.trace_field(
        field, origins, directions, x_end=x_end, step=step, max_steps=limit, parallel=False
    )
    assert reference.counts["ok"] >= 20 and reference.counts["exit_side"] + reference.counts[
        "ok"
    ] == len(origins)
    for name, got_status, got_steps, got_pos, got_dir in (
        ("package", package.status, package.steps, package.end_pos, package.end_dir),
        ("independent", status, steps, end[:, :3], end[:, 3:]),
    ):
        np.testing.assert_array_equal(got_status, reference.status, err_msg=name)
        np.testing.assert_array_equal(got_steps, reference.steps, err_msg=name)
        np.testing.assert_allclose(got_pos, reference.end_pos, rtol=0, atol=1e-13 * length)
        unit = got_dir / np.linalg.norm(got_dir, axis=1, keepdims=True)
        np.testing.assert_allclose(unit, reference.end_dir, rtol=0, atol=1e-13)
