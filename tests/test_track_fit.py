"""Tracks of many frames: finite differences, the sliding polynomial fit, the true motion."""

import numpy as np
import pytest

from rimcl.core.errors import RimclError
from rimcl.fields.field_reader import FieldFile
from rimcl.fields.field_writer import write_field
from rimcl.ptv.track import (
    SheetVelocity,
    first_difference,
    fit_filters,
    fit_noise_std,
    forward_differences,
    integrate_tracks,
    second_difference,
    second_differences,
    sliding_fit,
    track_acceleration,
    track_velocity,
)


def _polynomial_track(coefficients, times):
    """``x(t) = Σ_p c_p t^p`` per tracer and component: coefficients (P, N, 2) -> (F, N, 2)."""
    powers = times[:, None] ** np.arange(len(coefficients))
    return np.einsum("fp,pnc->fnc", powers, coefficients)


def _derivative(coefficients, times, order):
    """The ``order``-th time derivative of :func:`_polynomial_track`."""
    derived = np.polynomial.polynomial.polyder(coefficients, m=order, axis=0)
    return _polynomial_track(derived, times)


@pytest.mark.parametrize(("window", "order"), [(3, 2), (5, 2), (7, 2), (5, 3), (7, 3), (9, 4)])
def test_fit_recovers_a_polynomial_track_of_its_order_exactly(window, order):
    rng = np.random.default_rng(window * 10 + order)
    dt, frames = 0.05, 12
    times = 0.3 + dt * np.arange(frames)
    coefficients = rng.uniform(-1, 1, (order + 1, 50, 2))
    fit = sliding_fit(_polynomial_track(coefficients, times), dt, window, order)
    half = window // 2
    np.testing.assert_array_equal(fit.centres, np.arange(half, frames - half))
    at = times[fit.centres]
    # measured: 4e-13 at worst (round-off of positions of order 1 over Δt² = 2.5e-3)
    for estimate, derivative in zip(
        (fit.position, fit.velocity, fit.acceleration), range(3), strict=True
    ):
        np.testing.assert_allclose(
            estimate, _derivative(coefficients, at, derivative), rtol=0, atol=1e-12
        )


def test_fit_bias_of_a_quartic_is_the_closed_form():
    # x = (t - t_c)^4 about the centre: a(t_c) = 0, while a quadratic fit over k = -3..3
    # returns 2 Δt² Σ(k² - 4) k⁴ / Σ(k² - 4)² = 2 Δt² 804/84 (bias ∝ Δt² d⁴x/dt⁴)
    dt = 0.04
    offsets = dt * (np.arange(7) - 3.0)
    positions = np.broadcast_to((offsets**4)[:, None, None], (7, 1, 2))
    fit = sliding_fit(positions, dt, window=7, order=2)
    np.testing.assert_allclose(fit.acceleration, 2 * dt**2 * 804 / 84, rtol=1e-12)
    np.testing.assert_allclose(fit.velocity, 0.0, atol=1e-15)


def test_three_frame_quadratic_fit_is_the_papers_second_difference():
    rng = np.random.default_rng(3)
    positions, dt = rng.normal(size=(6, 20, 2)), 0.02
    fit = sliding_fit(positions, dt, window=3, order=2)
    np.testing.assert_allclose(fit.acceleration, second_differences(positions, dt), rtol=1e-12)
    central = (positions[2:] - positions[:-2]) / (2 * dt)
    np.testing.assert_allclose(fit.velocity, central, rtol=1e-12)
    np.testing.assert_allclose(fit.position, positions[1:-1], rtol=1e-12)


def test_fit_filters_have_the_closed_form_noise_gains():
    # quadratic over k = -3..3: the value's gain² is (VᵀV)⁻¹[0, 0] = 196/(7·196 - 28²) = 1/3,
    # the slope's 1/Σk² = 1/28, twice the curvature's 4/Σ(k² - 4)² = 4/84
    gains = np.linalg.norm(fit_filters(7, 2), axis=1)
    np.testing.assert_allclose(gains, [np.sqrt(1 / 3), 1 / np.sqrt(28), 2 / np.sqrt(84)])
    # five points: (VᵀV)⁻¹[0, 0] = 34/(5·34 - 10²) = 17/35, Σk² = 10, Σ(k² - 2)² = 14
    gains = np.linalg.norm(fit_filters(5, 2), axis=1)
    np.testing.assert_allclose(gains, [np.sqrt(17 / 35), 1 / np.sqrt(10), 2 / np.sqrt(14)])
    np.testing.assert_allclose(fit_noise_std(5, 2, 0.02, 3e-3), 3e-3 * gains / [1, 0.02, 4e-4])


@pytest.mark.parametrize(("window", "order"), [(5, 2), (7, 3)])
def test_noise_on_positions_gives_the_predicted_scatter(window, order):
    rng = np.random.default_rng(11)
    dt, frames, tracers, noise = 0.02, window + 2, 50000, 4e-4
    times = dt * np.arange(frames)
    coefficients = rng.uniform(-1, 1, (3, tracers, 2))
    clean = _polynomial_track(coefficients, times)
    fit = sliding_fit(clean + rng.normal(0, noise, clean.shape), dt, window, order)
    exact = sliding_fit(clean, dt, window, order)
    expected = fit_noise_std(window, order, dt, noise)
    for k, name in enumerate(("position", "velocity", "acceleration")):
        scatter = getattr(fit, name) - getattr(exact, name)
        measured = scatter.reshape(scatter.shape[0], -1).std(axis=1)
        # 1e5 samples per centre frame: a standard error of 1/sqrt(2e5) = 0.22 %
        np.testing.assert_allclose(measured, expected[k], rtol=0.01)


def test_papers_differences_over_many_frames():
    dt, frames = 0.02, 6
    times = dt * np.arange(frames)
    u0, a = np.array([0.4, -1.1]), np.array([3.0, 0.2])
    positions = (
        np.array([1.0, 2.0]) + u0 * times[:, None, None] + 0.5 * a * times[:, None, None] ** 2
    )
    velocity = forward_differences(positions, dt)
    acceleration = second_differences(positions, dt)
    assert velocity.shape == (frames - 1, 1, 2) and acceleration.shape == (frames - 2, 1, 2)
    # forward difference at frame k: u(t_k) + a Δt/2; second difference: a at every centre
    np.testing.assert_allclose(velocity[:, 0], u0 + a * (times[:-1, None] + dt / 2), rtol=1e-10)
    np.testing.assert_allclose(acceleration[:, 0], np.broadcast_to(a, (4, 2)), rtol=1e-8)
    np.testing.assert_array_equal(velocity[0], first_difference(positions, dt))
    np.testing.assert_array_equal(acceleration[0], second_difference(positions, dt))


def _rotation_planes(omegas, nodes, centre):
    x3, x2 = np.meshgrid(nodes, nodes, indexing="ij")
    return [np.stack([-w * (x3 - centre[1]), w * (x2 - centre[0])], axis=-1) for w in omegas]


def test_true_acceleration_of_solid_body_rotation_is_centripetal():
    omega, centre = 2 * np.pi, np.array([0.5, 0.5])
    nodes = np.linspace(0.0, 1.0, 33)
    times = np.linspace(0.0, 0.1, 6)
    velocity = SheetVelocity(
        _rotation_planes([omega] * 6, nodes, centre), times, (0, 0), (1 / 32, 1 / 32), False
    )
    rng = np.random.default_rng(5)
    radius, azimuth = 0.3 * np.sqrt(rng.random(200)), 2 * np.pi * rng.random(200)
    start = centre + np.stack([radius * np.cos(azimuth), radius * np.sin(azimuth)], axis=-1)
    tracks = integrate_tracks(velocity, start, times)
    r = tracks - centre
    u = track_velocity(velocity, tracks, times)
    a = track_acceleration(velocity, tracks, times)  # one-sided at the ends, central inside
    np.testing.assert_allclose(u, omega * np.stack([-r[..., 1], r[..., 0]], axis=-1), atol=1e-12)
    # measured: 5e-9 of |a| = ω² r: the spline's round-off in u (1e-13) over the step h = 2e-5
    np.testing.assert_allclose(a, -(omega**2) * r, rtol=0, atol=1e-6 * omega**2 * 0.3)


def test_true_acceleration_holds_the_local_change_of_a_spinning_up_rotation():
    # u = ω(t) J r with ω linear in time (exactly what linear interpolation between frames
    # gives): Du/Dt = ω' J r - ω² r
    omega0, spin, centre = 3.0, 20.0, np.array([0.5, 0.5])
    nodes = np.linspace(0.0, 1.0, 33)
    times = np.linspace(0.0, 0.08, 5)
    omegas = omega0 + spin * times
    velocity = SheetVelocity(
        _rotation_planes(omegas, nodes, centre), times, (0, 0), (1 / 32, 1 / 32), False
    )
    start = centre + np.array([[0.2, 0.0], [0.0, -0.25], [0.1, 0.1]])
    tracks = integrate_tracks(velocity, start, times, substeps=16)
    r = tracks - centre
    expected = spin * np.stack([-r[..., 1], r[..., 0]], axis=-1) - omegas[:, None, None] ** 2 * r
    a = track_acceleration(velocity, tracks, times)
    np.testing.assert_allclose(a, expected, rtol=0, atol=1e-7)


def test_true_acceleration_refuses_a_span_too_short_for_its_step():
    velocity = SheetVelocity(np.zeros((2, 5, 5, 2)), [0.0, 1.0], (0, 0), (1, 1), periodic=True)
    with pytest.raises(RimclError, match="smaller step"):
        track_acceleration(velocity, np.zeros((1, 1, 2)), [0.5], step=0.6)
    with pytest.raises(RimclError, match="positive time"):
        track_acceleration(velocity, np.zeros((1, 1, 2)), [0.5], step=-1.0)


@pytest.mark.parametrize(
    ("window", "order", "frames", "match"),
    [
        (6, 2, 9, "odd number"),
        (3, 3, 9, "more than the order"),
        (7, 1, 9, "at least 2"),
        (7, 2, 5, "7 frames or more"),
    ],
)
def test_bad_fit_settings_are_refused(window, order, frames, match):
    with pytest.raises(RimclError, match=match):
        sliding_fit(np.zeros((frames, 3, 2)), 0.02, window, order)


def test_bad_frame_spacing_and_too_few_frames_are_refused():
    with pytest.raises(RimclError, match="positive time"):
        sliding_fit(np.zeros((7, 3, 2)), 0.0)
    with pytest.raises(RimclError, match="3 frames or more"):
        second_differences(np.zeros((2, 3, 2)), 0.02)


def test_sheet_velocity_from_a_file_takes_every_frame_the_span_needs(tmp_path):
    n, times = 8, 0.1 * np.arange(6)
    planes = [np.full((n, n, 2), k, dtype=np.float32) for k in range(6)]
    path = write_field(
        tmp_path / "f.h5",
        density=[np.ones((n, n, n))] * 6,
        velocity_sheet=planes,
        sheet_x1=0.0,
        times=times,
        origin=(0, 0, 0),
        spacing=(1, 1, 1),
        boundary="periodic",
    )
    with FieldFile(path) as ff:
        velocity = SheetVelocity.from_source(ff, 0.0, 0.15, 0.3)
        np.testing.assert_allclose(velocity.times, times[1:4])
        # linear in time between the stored frames: u = 10 t
        np.testing.assert_allclose(velocity(np.zeros((1, 2)), 0.25), [[2.5, 2.5]])
        np.testing.assert_allclose(SheetVelocity.from_source(ff, 0, 0.2, 0.2).times, [0.2])
        with pytest.raises(RimclError, match="need velocity frames there"):
            SheetVelocity.from_source(ff, 0.0, 0.1, 0.7)
