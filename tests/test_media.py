"""Refractive index of water, air and salt water against published values (rimcl.fields.media)."""

import numpy as np
import pytest

from rimcl.core.errors import RimclError
from rimcl.fields import media
from rimcl.fields.media import Fluid


def _dn_dt(index, temperature_c, step=1e-3):
    return (index(temperature_c + step) - index(temperature_c - step)) / (2 * step)


@pytest.mark.parametrize(
    ("wavelength_nm", "expected"),
    # IAPWS R9-97, Table 3: liquid water at 273.15 K and 0.1 MPa (n to the digits given)
    [(226.5, 1.394527), (589.0, 1.334344), (1013.98, 1.326135)],
)
def test_iapws_check_values_at_0_1_mpa(wavelength_nm, expected):
    assert round(float(media.water_index(0.0, wavelength_nm)), 6) == expected


def test_water_density_reference_points():
    # CIPM table (Tanaka et al. 2001): 999.9750 at the maximum (3.983 °C), 998.2067 at 20 °C
    np.testing.assert_allclose(
        media.water_density([3.983035, 20.0]), [999.975, 998.2067], atol=1e-4
    )
    # above the switch (Kell 1975): IAPWS-95 gives 988.03 at 50 °C and 1 atm
    assert media.water_density(50.0) == pytest.approx(988.03, abs=0.01)
    temperatures = np.linspace(0.0, 10.0, 100_001)
    assert abs(temperatures[np.argmax(media.water_density(temperatures))] - 3.983) < 1e-3


def test_water_density_continuous_at_the_switch():
    below = media.water_density(media.DENSITY_SWITCH_C - 1e-9)
    above = media.water_density(media.DENSITY_SWITCH_C + 1e-9)
    assert abs(above - below) < 1e-8
    slope = (media.water_density(media.DENSITY_SWITCH_C + 0.5) - below) / 0.5
    assert -0.4 < slope < -0.3  # kg/m³/K near 38 °C: no step, no kink worth the name


def test_water_dn_dt_at_20c_532nm():
    # -9.1e-5 /K
    slope = _dn_dt(lambda t: media.water_index(t, 532.0), 20.0)
    assert round(float(slope), 6) == -9.1e-5


def test_water_is_absolute_index():
    # Tilton & Taylor's 1.33299 at 20 °C and 589.3 nm is relative to air; IAPWS is absolute
    n_air = media.air_index(20.0, wavelength_nm=589.3)
    assert abs(media.water_index(20.0, 589.3) / n_air - 1.33299) < 2e-5


def test_ciddor_standard_value():
    # NIST Engineering Metrology Toolbox (Stone & Zimmerman), Ciddor: 633 nm, 20 °C,
    # 101.325 kPa, dry, 450 ppm CO2 -> 1.000271800
    assert round(float(media.air_index(20.0, 101_325.0, 633.0, 0.0, 450.0)), 9) == 1.000271800


@pytest.mark.parametrize(
    ("temperature_c", "humidity", "expected"),
    # the NIST procedure (IAPWS saturation pressure), as computed by the ref_index package
    [(20.0, 0.2, 1.0002716285340578), (20.0, 0.8, 1.0002711183472626), (60.0, 0.8, 1.000234024)],
)
def test_ciddor_humid_air(temperature_c, humidity, expected):
    n = media.air_index(temperature_c, 101_325.0, 633.0, humidity)
    assert abs(n - expected) < 3e-10


def test_saturation_vapour_pressure_if97_check_value():
    # IAPWS-IF97, Table 35: p_s(300 K) = 0.353658941e-2 MPa
    assert media.saturation_vapour_pressure(300.0 - 273.15) == pytest.approx(3536.58941, abs=1e-5)


def test_air_dn_dt_is_the_ideal_gas_value():
    # n - 1 ∝ density ∝ 1/T: dn/dT = -(n - 1)/T, about -9e-7 /K at 20 °C
    slope = float(_dn_dt(lambda t: media.air_index(t, wavelength_nm=532.0), 20.0))
    ideal = -(float(media.air_index(20.0, wavelength_nm=532.0)) - 1.0) / 293.15
    assert slope == pytest.approx(ideal, rel=5e-3)
    assert round(slope, 7) == -9e-7


def test_quan_fry_fresh_water_matches_iapws():
    temperatures = np.linspace(0.0, 30.0, 7)[:, None]
    wavelengths = np.linspace(400.0, 700.0, 7)[None, :]
    fresh = media.seawater_index(0.0, temperatures, wavelengths)
    # Quan & Fry's fit of Austin & Halikas agrees with IAPWS R9-97 to a few 1e-5
    assert np.max(np.abs(fresh - media.water_index(temperatures, wavelengths))) < 4e-5


def test_quan_fry_salinity_slope():
    # about 1.9e-4 per g/kg (sea water S = 35 is 0.0064 above fresh water at 20 °C)
    n35 = media.seawater_index(35.0, 20.0, 589.3) / media.air_index(20.0, wavelength_nm=589.3)
    n0 = media.seawater_index(0.0, 20.0, 589.3) / media.air_index(20.0, wavelength_nm=589.3)
    assert n35 - n0 == pytest.approx(0.00640, abs=5e-5)


@pytest.mark.parametrize(
    ("kind", "delta_n", "expected"),
    [
        ("air", 2.85e-6, "air at 20 °C, ΔT ≈ 3.0 K"),  # the paper's C0
        ("air", 2.40e-5, "air at 20 °C, ΔT ≈ 26 K"),  # C1
        ("water", 2.85e-4, "water at 20 °C, ΔT ≈ 3.1 K"),  # C2
        ("water", 2.85e-3, "water at 20 °C, ΔT ≈ 33 K"),  # C3
        ("saltwater", 2.85e-3, "salt water at 20 °C from 0 g/kg, ΔS ≈ 15 g/kg"),  # C3
    ],
)
def test_physical_equivalents_of_the_paper_cases(kind, delta_n, expected):
    fluid = Fluid(kind)
    equivalent = media.physical_equivalent(delta_n, fluid)
    assert str(equivalent) == expected
    lo, hi = fluid.span(equivalent.delta)
    values = fluid.index_of(np.array([lo, hi]))
    assert abs(values[0] - values[1]) == pytest.approx(delta_n, rel=1e-7)


def test_c4_is_out_of_reach_of_water():
    equivalent = media.physical_equivalent(2.85e-2, Fluid("water"))
    assert not equivalent.reachable and np.isnan(equivalent.delta)
    assert equivalent.delta_limit == 40.0  # centred on 20 °C, the liquid range starts at 0
    assert "out of reach" in str(equivalent)


def test_zero_difference_maps_to_exactly_zero():
    density = 1.0 + 0.105 * np.random.default_rng(1).random((4, 5, 6))
    gradient = np.ones((4, 5, 6, 3))
    mapped = media.index_from_density(density, Fluid("water"), 0.0, gradient)
    assert not np.any(mapped.delta_n) and not np.any(mapped.gradient)
    assert mapped.n_ref == float(media.water_index(20.0))


def test_density_maps_onto_temperature_and_index():
    fluid = Fluid("water", temperature_c=20.0)
    x = np.linspace(0.0, 1.0, 11)
    density = np.broadcast_to(1.0 + 0.105 * x, (3, 2, 11))  # light at x = 0, heavy at x = 1
    mapped = media.index_from_density(density, fluid, 30.0)
    np.testing.assert_allclose(mapped.scalar[0, 0, [0, -1]], [35.0, 5.0])  # heavy is colder
    n = mapped.delta_n.astype(np.float64) + mapped.n_ref
    np.testing.assert_allclose(n, fluid.index(mapped.scalar), atol=2e-7)  # float32 δn
    assert mapped.delta_n.dtype == np.float32 and isinstance(mapped.n_ref, float)
    assert mapped.n_ref == pytest.approx(np.mean(fluid.index(mapped.scalar)), abs=1e-12)


def test_chain_rule_gradient_matches_differences():
    fluid = Fluid("saltwater", temperature_c=15.0)
    h = 1e-4
    x = np.array([0.5 - h, 0.5, 0.5 + h])
    density = np.broadcast_to(1.0 + 0.105 * x**2, (1, 1, 3))
    grad_rho = np.zeros((1, 1, 3, 3))
    grad_rho[..., 0] = 2 * 0.105 * x
    mapped = media.index_from_density(density, fluid, 20.0, grad_rho)
    n = fluid.index_of(mapped.scalar)[0, 0]
    assert mapped.gradient[0, 0, 1, 0] == pytest.approx((n[2] - n[0]) / (2 * h), rel=1e-5)
    assert not np.any(mapped.gradient[..., 1:])


@pytest.mark.parametrize(
    ("call", "message"),
    [
        (lambda: Fluid("glycerol"), "unknown fluid"),
        (lambda: Fluid("water", temperature_c=120.0), "outside the formulation's range"),
        (lambda: Fluid("water", pressure_pa=2e5), "0.1 MPa"),
        (lambda: media.index_from_density(np.ones(2), Fluid("water"), -1.0), ">= 0"),
        (lambda: media.index_from_density([1.0, 1.105], Fluid("water"), 60.0), "range"),
        (lambda: media.air_index(-5.0, relative_humidity=0.5), "0 °C or more"),
        (lambda: media.water_index(20.0, 150.0), "wavelength_nm"),
    ],
)
def test_bad_input_is_one_clear_error(call, message):
    with pytest.raises(RimclError, match=message):
        call()
