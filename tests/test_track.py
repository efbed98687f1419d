"""True tracer motion (RK4, cubic in space, linear in time) and finite differences."""

import numpy as np
import pytest

from rimcl.core.errors import RimclError
from rimcl.ptv.track import SheetVelocity, first_difference, integrate_tracks, second_difference


def _nodes(count, lo, hi, periodic):
    if periodic:
        spacing = (hi - lo) / count
        return lo + spacing * np.arange(count), spacing
    return np.linspace(lo, hi, count), (hi - lo) / (count - 1)


def _rotate(points, centre, angle):
    d = points - centre
    c, s = np.cos(angle), np.sin(angle)
    return centre + np.stack([c * d[:, 0] - s * d[:, 1], s * d[:, 0] + c * d[:, 1]], axis=-1)


def test_solid_body_rotation_matches_the_exact_rotation():
    size, omega, centre = 1.0, 2 * np.pi, np.array([0.5, 0.5])
    x, h = _nodes(33, 0.0, size, periodic=False)
    x3, x2 = np.meshgrid(x, x, indexing="ij")
    plane = np.stack([-omega * (x3 - centre[1]), omega * (x2 - centre[0])], axis=-1)
    times = np.array([0.0, 0.05, 0.1])  # a fifth of a turn: a stringent test of RK4
    velocity = SheetVelocity([plane] * 3, times, (0.0, 0.0), (h, h), periodic=False)
    rng = np.random.default_rng(1)
    radius = 0.499 * np.sqrt(rng.random(400))  # up to the grid edge, never beyond
    azimuth = 2 * np.pi * rng.random(400)
    start = centre + np.stack([radius * np.cos(azimuth), radius * np.sin(azimuth)], axis=-1)
    tracks = integrate_tracks(velocity, start, times)
    for k, t in enumerate(times):
        np.testing.assert_allclose(tracks[k], _rotate(start, centre, omega * t), atol=1e-6 * size)
    assert velocity.inside(tracks[-1]).all()


def test_periodic_shear_flow_wraps_and_matches_the_closed_form():
    period, amplitude, drift = 2 * np.pi, 0.7, 1.3
    x, h = _nodes(48, 0.0, period, periodic=True)
    x3, _ = np.meshgrid(x, x, indexing="ij")
    # u2 = A sin(x3), u3 = V: x3 = x3_0 + V t, x2 = x2_0 - A/V (cos(x3) - cos(x3_0))
    plane = np.stack([amplitude * np.sin(x3), np.full_like(x3, drift)], axis=-1)
    times = np.array([0.0, 0.5, 1.0])
    velocity = SheetVelocity([plane] * 3, times, (0.0, 0.0), (h, h), periodic=True)
    start = np.array([[0.3, 6.0], [5.9, 0.1], [3.0, 3.0]])  # two cross the periodic edge
    tracks = integrate_tracks(velocity, start, times, substeps=32)
    x3_end = start[:, 1] + drift * times[-1]
    x2_end = start[:, 0] - amplitude / drift * (np.cos(x3_end) - np.cos(start[:, 1]))
    # measured: 2e-7 (the periodic cubic spline of sin on 48 nodes); clamped: 0.3
    np.testing.assert_allclose(tracks[-1], np.stack([x2_end, x3_end], axis=-1), atol=1e-6)


def test_velocity_is_linear_in_time_between_frames():
    _, h = _nodes(6, 0.0, 1.0, periodic=False)
    u0, u1 = np.array([1.0, -2.0]), np.array([3.0, 0.5])
    planes = [np.broadcast_to(u, (6, 6, 2)) for u in (u0, u1)]
    velocity = SheetVelocity(planes, [0.0, 0.1], (0.0, 0.0), (h, h), periodic=False)
    start = np.array([[0.5, 0.5]])
    np.testing.assert_allclose(velocity(start, 0.025), [0.75 * u0 + 0.25 * u1])
    tracks = integrate_tracks(velocity, start, [0.0, 0.1], substeps=1)
    # x = x0 + u0 t + (u1 - u0) t² / (2 Δt): a quadratic, exact for RK4
    np.testing.assert_allclose(tracks[1, 0], start[0] + 0.1 * u0 + (u1 - u0) * 0.1 / 2)


def test_clamped_velocity_holds_the_edge_value_and_marks_outside():
    x, h = _nodes(8, 0.0, 1.0, periodic=False)
    x3, x2 = np.meshgrid(x, x, indexing="ij")
    plane = np.stack([x2, x3], axis=-1)
    velocity = SheetVelocity([plane], [0.0], (0.0, 0.0), (h, h), periodic=False)
    points = np.array([[1.5, 0.25], [0.5, -0.5]])
    np.testing.assert_allclose(velocity(points, 0.0), [[1.0, 0.25], [0.5, 0.0]], atol=1e-12)
    np.testing.assert_array_equal(velocity.inside(points), [False, False])
    assert velocity.inside(np.array([[0.0, 1.0]])).all()


def test_finite_differences_of_a_parabola_are_exact():
    dt = 0.005
    t = np.arange(3)[:, None, None] * dt
    u0, a = np.array([0.4, -1.1]), np.array([3.0, 0.2])
    positions = np.array([1.0, 2.0]) + u0 * t + 0.5 * a * t**2
    np.testing.assert_allclose(second_difference(positions, dt)[0], a, rtol=1e-8)
    np.testing.assert_allclose(first_difference(positions, dt)[0], u0 + 0.5 * a * dt)


@pytest.mark.parametrize(
    ("planes", "times", "match"),
    [
        (np.zeros((2, 8, 8, 3)), [0.0, 1.0], "shape"),
        (np.zeros((2, 8, 8, 2)), [1.0, 0.0], "increase"),
        (np.full((1, 8, 8, 2), np.nan), [0.0], "NaN"),
        (np.zeros((1, 3, 8, 2)), [0.0], "4 x 4"),
    ],
)
def test_bad_velocity_rejected(planes, times, match):
    with pytest.raises(RimclError, match=match):
        SheetVelocity(planes, times, (0, 0), (1, 1), periodic=False)


def test_time_outside_the_frames_rejected():
    velocity = SheetVelocity(np.zeros((2, 5, 5, 2)), [0.0, 1.0], (0, 0), (1, 1), periodic=True)
    with pytest.raises(RimclError, match="outside the velocity frames"):
        velocity(np.zeros((1, 2)), 1.5)
