"""Where methods fail: steps longer than the field's features, strong gradients that
turn rays back or out through the side, plain float32 losing small deflections."""

import numpy as np

import rimcl
from rimcl.optics.trace import LONG_STEP_CELLS, default_step
from rimcl.optics.verify import exact_linear


def _bump_field(nodes=48, width_cells=1.5, amplitude=1e-3):
    """A Gaussian bump of δn, ``width_cells`` cells wide (σ), in the middle of [0, 1]³."""
    x = np.linspace(0.0, 1.0, nodes)
    x3, x2, x1 = np.meshgrid(x, x, x, indexing="ij")
    sigma = width_cells * x[1]
    values = amplitude * np.exp(-((x1 - 0.5) ** 2 + (x2 - 0.5) ** 2 + (x3 - 0.5) ** 2) / sigma**2)
    return rimcl.Field.from_arrays(values, spacing=(x[1],) * 3, n_ref=1.33)


def test_a_step_longer_than_the_features_is_flagged_and_halving_it_converges(device):
    field = _bump_field()
    rng = np.random.default_rng(11)
    # rays aimed through the bump
    origins = np.column_stack([np.zeros(16), 0.5 + rng.uniform(-0.04, 0.04, (16, 2))])
    directions = np.tile([1.0, 0.0, 0.0], (16, 1))
    cell = default_step(field) * 2  # one cell of arc
    fine = rimcl.trace_rays(field, origins, directions, x_end=1.0, step=cell / 16, device=device)
    displacement = np.max(np.abs(fine.image_pos - origins))
    errors = []
    for cells in (6.0, 3.0, 1.5, 0.75, 0.375):
        result = rimcl.trace_rays(
            field, origins, directions, x_end=1.0, step=cells * cell, device=device
        )
        flagged = "warnings" in result.config
        assert flagged == (cells > LONG_STEP_CELLS)
        errors.append(np.max(np.abs(result.image_pos - fine.image_pos)))
    # the long step misses much of the deflection; shorter steps converge to the fine one
    assert errors[0] > 0.1 * displacement
    assert all(errors[i + 1] < errors[i] / 2 for i in range(len(errors) - 1))
    assert errors[-1] < 1e-3 * displacement


def _ramp_field(n0, g, x2_high):
    """n = n0 - g x1 (strong, water-like) on [0, 1] x [-1, x2_high] x [-0.5, 0.5]."""
    counts = (9, 33, 3)
    lo, hi = np.array([0.0, -1.0, -0.5]), np.array([1.0, x2_high, 0.5])
    spacing = (hi - lo) / (np.array(counts) - 1)
    x1 = lo[0] + spacing[0] * np.arange(counts[0])
    values = np.broadcast_to(-g * x1, counts[::-1]).copy()
    gradient = np.zeros((*counts[::-1], 3))
    gradient[..., 0] = -g
    return rimcl.Field.from_arrays(values, spacing=spacing, origin=lo, n_ref=n0, gradient=gradient)


def _ramp_outcome(n0, g, theta, x_end, x2_high):
    """Exact fate of rays from (0, 0, 0) at angle theta to x1 (towards +x2) in
    n = n0 - g x1: with y = n0 - g x1, y'' = g² y in t, T2 = n0 sin(theta) is constant.
    Returns the status and the x2 of the event (exit plane, turning point)."""
    t1, t2 = n0 * np.cos(theta), n0 * np.sin(theta)
    y_end = n0 - g * x_end
    turns = t2 >= y_end  # Snell: n(x1) = n0 sin(theta) before the exit plane
    # turning point: tanh(g t) = T1/y0; exit plane: y0 cosh(g t) - T1 sinh(g t) = y_end
    t_turn = np.arctanh(np.minimum(t1 / n0, 1 - 1e-15)) / g
    root = np.sqrt(np.maximum(y_end**2 - n0**2 + t1**2, 0.0))
    t_exit = np.log((y_end - root) / (n0 - t1)) / g
    t_event = np.where(turns, t_turn, t_exit)
    x2_event = t2 * t_event
    status = np.where(x2_event > x2_high, 1, np.where(turns, 2, 0))
    return status, x2_event


def test_strong_gradients_turn_rays_back_or_out_as_the_closed_form_says(device):
    """Water-like index drop 0.05 over the depth: grazing rays turn back (n0 sin θ0 >
    n(x_end)), wide ones leave through the side x2 = 3; the others reach the exit plane
    where the closed form puts them."""
    n0, g, x2_high = 1.35, 0.05, 3.0
    field = _ramp_field(n0, g, x2_high)
    theta = np.deg2rad(np.linspace(60.0, 88.0, 57))
    status, x2_event = _ramp_outcome(n0, g, theta, 1.0, x2_high)
    # leave out rays whose fate is decided within a cell of a border
    clear = np.abs(x2_event - x2_high) > 0.2
    theta, status, x2_event = theta[clear], status[clear], x2_event[clear]
    origins = np.zeros((len(theta), 3))
    directions = np.column_stack([np.cos(theta), np.sin(theta), np.zeros(len(theta))])
    result = rimcl.trace_rays(field, origins, directions, x_end=1.0, device=device)
    np.testing.assert_array_equal(result.status, status)
    counts = result.counts
    assert counts["ok"] > 0 and counts["turned_back"] > 0 and counts["exit_side"] > 0
    assert counts["ok"] + counts["turned_back"] + counts["exit_side"] == len(theta)
    ok = status == 0
    np.testing.assert_allclose(result.end_pos[ok, 1], x2_event[ok], rtol=0, atol=1e-6)
    assert np.all(np.isnan(result.image_pos[~ok]))


def test_plain_float32_loses_small_deflections_that_f32c_keeps(device):
    """Δn = 1e-6 across the field, the paper's step 1e-4 (3e4 steps per ray)."""
    n0, g = 1.0003, 5e-7
    lo, hi = np.array([0.0, -1.0, -1.0]), np.array([np.pi, 1.0, 1.0])
    counts = (9, 9, 9)
    spacing = (hi - lo) / (np.array(counts) - 1)
    x2 = lo[1] + spacing[1] * np.arange(counts[1])
    values = np.broadcast_to((g * x2)[None, :, None], counts[::-1]).copy()
    gradient = np.zeros((*counts[::-1], 3))
    gradient[..., 1] = g
    field = rimcl.Field.from_arrays(values, spacing=spacing, origin=lo, n_ref=n0, gradient=gradient)
    rng = np.random.default_rng(12)
    origins = np.column_stack([np.zeros(6), rng.uniform(-0.3, 0.3, (6, 2))])
    directions = np.column_stack([np.ones(6), rng.uniform(-0.1, 0.1, (6, 2))])
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    exact = exact_linear(rimcl.analytic_field("linear", n0=n0, g=g), origins, directions, np.pi)
    straight = origins + (np.pi / directions[:, 0])[:, None] * directions
    bend = exact[:, 1] - straight[:, 1]
    assert np.min(np.abs(bend)) > 1e-6  # the deflection to keep: a few 1e-6
    relative = {}
    for precision in ("f32", "f32c"):
        result = rimcl.trace_rays(
            field, origins, directions, x_end=np.pi, step=1e-4, precision=precision, device=device
        )
        assert result.steps.min() > 3e4
        relative[precision] = np.max(
            np.abs(result.end_pos[:, 1] - straight[:, 1] - bend) / np.abs(bend)
        )
    assert relative["f32c"] < 1e-3
    assert relative["f32"] > 0.5
