"""Mie ray weights (rimcl.imaging.mie) against miepython and closed forms."""

import miepython
import numpy as np
import pytest

from rimcl.core.errors import RimclError
from rimcl.imaging.mie import MieWeights, ray_weights
from rimcl.optics.camera import PlaneCamera, Scene


def _fan_directions(count=400):
    """Initial directions of the paper's fan from two tracers (incidence up to ~0.95 rad)."""
    scene = Scene(0.0, 1.0, np.zeros(2), np.ones(2), False)
    camera = PlaneCamera(scene, 20)
    tracers = np.array([[0.2, 0.3], [0.7, 0.6]])
    return camera.directions(tracers).reshape(-1, 3)[:count]


def _miepython(mie, directions):
    cosines = directions @ np.asarray(mie.sheet_direction)
    parallel, perpendicular = miepython.intensities(
        complex(mie.particle_index, -mie.particle_absorption),
        mie.diameter_um,
        1e-3 * mie.wavelength_nm,
        cosines,
        n_env=mie.fluid_index,
        norm="wiscombe",
    )
    return perpendicular, parallel


@pytest.mark.parametrize("polarisation", ["perpendicular", "parallel", "unpolarised"])
def test_weights_equal_miepython_at_the_rays_angles(polarisation):
    # the paper's tracers: 10 µm, 532 nm; polystyrene in water, sheet along x2
    mie = MieWeights(10.0, 1.59, 1.335, 532.0, (0.0, 1.0, 0.0), polarisation)
    directions = _fan_directions()
    perpendicular, parallel = _miepython(mie, directions)
    expected = {
        "perpendicular": perpendicular,
        "parallel": parallel,
        "unpolarised": 0.5 * (perpendicular + parallel),
    }[polarisation]
    np.testing.assert_allclose(mie.weights(directions), expected, rtol=1e-6, atol=0)


def test_absorbing_particle_matches_miepython():
    mie = MieWeights(2.0, 1.5, 1.0, 633.0, (0.0, 0.0, 1.0), "unpolarised", 0.05)
    directions = _fan_directions(200)
    perpendicular, parallel = _miepython(mie, directions)
    np.testing.assert_allclose(
        mie.weights(directions), 0.5 * (perpendicular + parallel), rtol=1e-6, atol=0
    )


def test_linear_polarisation_splits_per_scattering_plane():
    sheet = (0.0, 1.0, 0.0)
    vertical = MieWeights(5.0, 1.45, 1.0, 532.0, sheet, (0.0, 0.0, 1.0))
    horizontal = MieWeights(5.0, 1.45, 1.0, 532.0, sheet, (1.0, 0.0, 0.0))
    directions = _fan_directions()
    perpendicular, parallel = vertical.intensities(vertical.scattering_cosines(directions))
    # two crossed polarisations add up to unpolarised light, ray by ray
    total = vertical.weights(directions) + horizontal.weights(directions)
    np.testing.assert_allclose(total, perpendicular + parallel, rtol=1e-12)
    # rays in the x1-x2 plane: the field along x3 is perpendicular to their scattering plane
    angle = np.linspace(0.1, 3.0, 7)
    in_plane = np.stack([np.sin(angle), np.cos(angle), np.zeros_like(angle)], axis=1)
    s1, s2 = vertical.intensities(vertical.scattering_cosines(in_plane))
    np.testing.assert_allclose(vertical.weights(in_plane), s1, rtol=1e-12)
    np.testing.assert_allclose(horizontal.weights(in_plane), s2, rtol=1e-12)


def test_rayleigh_limit_closed_form():
    # a particle far below the wavelength: |S1|² flat, |S2|² ∝ cos²θ, corrections O(x²)
    mie = MieWeights(0.001, 1.5, 1.0, 532.0, (0.0, 1.0, 0.0), "parallel")  # x = 0.006
    angle = np.linspace(0.2, 3.0, 9)
    directions = np.stack([np.sin(angle), np.cos(angle), np.zeros_like(angle)], axis=1)
    perpendicular, parallel = mie.intensities(np.cos(angle))
    np.testing.assert_allclose(perpendicular / perpendicular[0], 1.0, rtol=1e-4)
    np.testing.assert_allclose(parallel / perpendicular, np.cos(angle) ** 2, rtol=1e-4, atol=1e-6)
    np.testing.assert_allclose(mie.weights(directions), parallel, rtol=1e-12)


def test_camera_on_the_sheet_normal_sees_side_scatter():
    mie = MieWeights(sheet_direction=(0.0, 2.0, 0.0))  # normalised
    assert mie.scattering_cosines(np.array([1.0, 0.0, 0.0])) == 0.0  # θ = 90°
    assert mie.sheet_direction == (0.0, 1.0, 0.0)


def test_uniform_weights_when_off():
    directions = _fan_directions().reshape(4, 100, 3)
    weights = ray_weights(directions)
    assert weights.shape == (4, 100) and np.all(weights == 1.0)
    mie = MieWeights(fluid_index=1.335)
    np.testing.assert_array_equal(ray_weights(directions, mie), mie.weights(directions))


@pytest.mark.parametrize(
    ("options", "message"),
    [
        ({"polarisation": "circular"}, "unknown mie polarisation"),
        ({"polarisation": (0.0, 1.0, 0.0)}, "perpendicular to the sheet"),
        ({"sheet_direction": (0.0, 0.0, 0.0)}, "nonzero 3-vector"),
        ({"particle_index": 1.335, "fluid_index": 1.335}, "scatters no light"),
        ({"diameter_um": -1.0}, "diameter_um"),
    ],
)
def test_bad_input_is_one_clear_error(options, message):
    with pytest.raises(RimclError, match=message):
        MieWeights(**options)


def test_amplitudes_summed_in_parts_have_the_bits_of_the_complex_sums():
    """The series is summed on real and imaginary parts apart; every bit equals the complex
    sums' (the plain loop below), absorbing particle included."""
    from rimcl.imaging.mie import _amplitudes

    mu = np.concatenate([np.random.default_rng(2).uniform(-1, 1, 5000), [-1.0, 0.0, 1.0]])
    for absorption in (0.0, 0.05):
        weights = MieWeights(
            10.0, 1.59, 1.333, 532.0, (0.0, 1.0, 0.0), particle_absorption=absorption
        )
        scaled_a, scaled_b = weights._scaled_coefficients()
        s1 = np.zeros(mu.shape, dtype=np.complex128)
        s2 = np.zeros(mu.shape, dtype=np.complex128)
        pi_previous, pi_current = np.zeros(mu.shape), np.ones(mu.shape)
        for n in range(1, len(scaled_a) + 1):
            tau = n * mu * pi_current - (n + 1) * pi_previous
            s1 += scaled_a[n - 1] * pi_current + scaled_b[n - 1] * tau
            s2 += scaled_a[n - 1] * tau + scaled_b[n - 1] * pi_current
            pi_previous, pi_current = (
                pi_current,
                ((2 * n + 1) * mu * pi_current - (n + 1) * pi_previous) / n,
            )
        got = _amplitudes(mu, scaled_a, scaled_b)
        np.testing.assert_array_equal(got[0], s1)
        np.testing.assert_array_equal(got[1], s2)
