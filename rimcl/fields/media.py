"""Refractive index of real fluids in physical units.

Three formulations, each written from its publication:

- **water** (liquid, 0.1 MPa): the IAPWS 1997 formulation (IAPWS R9-97; Harvey, Gallagher &
  Levelt Sengers, J. Phys. Chem. Ref. Data 27, 761, 1998) gives ``n(T, ρ, λ)``; the density
  of air-free water at 0.1 MPa comes from Tanaka et al. (Metrologia 38, 301, 2001, the
  CIPM table, 0–40 °C) below :data:`DENSITY_SWITCH_C` and from Kell (J. Chem. Eng. Data 20,
  97, 1975, 0–150 °C) above it, where the two meet;
- **air**: Ciddor (Appl. Opt. 35, 1566, 1996), with the saturation vapour pressure of the
  IAPWS-IF97 equation and the enhancement factor of Ciddor's Appendix, as in the NIST
  Engineering Metrology Toolbox;
- **salt water**: Quan & Fry (Appl. Opt. 34, 3477, 1995), ``n(S, T, λ)`` at atmospheric
  pressure (0–30 °C, 0–35 g/kg, 400–700 nm).

A flow case maps onto a fluid with :class:`Fluid` and :func:`index_from_density`: the
field's dimensionless density (light fluid 1, heavy fluid 1.105 in the shipped sample and
the JHTDB mixing data) becomes a temperature difference ``ΔT`` (the heavy fluid is the
colder one) or a salinity difference ``ΔS`` (the heavy fluid is the saltier one), and the
nonlinear ``n(T)`` or ``n(S)`` gives ``δn = n - n_ref``. :func:`physical_equivalent` goes
the other way: the ``ΔT`` or ``ΔS`` that gives a case's largest index difference.

Units are in every name: temperatures in °C (``temperature_c``), wavelengths in vacuum in
nm (``wavelength_nm``), pressures in Pa, densities in kg/m³, salinities in g/kg. Every
function takes NumPy arrays (broadcast) and returns float64.
"""

import dataclasses
import math
import typing

import numpy as np
from scipy.optimize import brentq

from rimcl.core.errors import RimclError

ZERO_CELSIUS_K = 273.15
STANDARD_PRESSURE_PA = 101_325.0

# --- water: IAPWS R9-97 --------------------------------------------------------------------
# Lorentz–Lorenz form: (n² - 1)/(n² + 2) / ρ̄ = a0 + a1 ρ̄ + a2 T̄ + a3 λ̄² T̄ + a4/λ̄²
#                       + a5/(λ̄² - λ̄_UV²) + a6/(λ̄² - λ̄_IR²) + a7 ρ̄²
_IAPWS_A = (
    0.244257733,
    9.74634476e-3,
    -3.73234996e-3,
    2.68678472e-4,
    1.58920570e-3,
    2.45934259e-3,
    0.900704920,
    -1.66626219e-2,
)
_IAPWS_T_STAR_K = 273.15
_IAPWS_RHO_STAR = 1000.0  # kg/m³
_IAPWS_LAMBDA_STAR_NM = 589.0
_IAPWS_LAMBDA_UV = 0.229202  # reduced
_IAPWS_LAMBDA_IR = 5.432937  # reduced
IAPWS_RANGE = {
    "temperature_c": (-12.0, 500.0),
    "density_kg_m3": (0.0, 1060.0),
    "wavelength_nm": (200.0, 1100.0),
}

# --- water density at 0.1 MPa --------------------------------------------------------------
# Tanaka et al. 2001: ρ = a5 [1 - (t + a1)² (t + a2) / (a3 (t + a4))], t in °C (ITS-90)
_TANAKA = (-3.983035, 301.797, 522528.9, 69.34881, 999.974950)
# Kell 1975: ρ = (c0 + c1 t + … + c5 t⁵) / (1 + b t). Its t is IPTS-68; used with ITS-90 as
# it is: t68 - t90 ≤ 0.026 K below 100 °C changes ρ by ≤ 0.02 kg/m³ (n by ≤ 1e-5 at 99 °C)
_KELL_NUM = (999.83952, 16.945176, -7.9870401e-3, -46.170461e-6, 105.56302e-9, -280.54253e-12)
_KELL_DEN = 16.879850e-3
#: Temperature (°C) where Tanaka's and Kell's densities agree (to 1e-9 kg/m³); water below it
#: uses Tanaka (it reproduces IAPWS-95 to ~1e-3 kg/m³ in 0–40 °C, Kell is ~3e-3 low), above it
#: Kell (Tanaka is fitted only up to 40 °C).
DENSITY_SWITCH_C = 38.156366789
WATER_RANGE_C = (0.0, 99.0)  # liquid at 0.1 MPa (boils at 99.6 °C)

# --- air: Ciddor 1996 ----------------------------------------------------------------------
_CIDDOR_K = (238.0185, 5792105.0, 57.362, 167917.0)  # µm⁻², 1, µm⁻², 1 (×1e-8 refractivity)
_CIDDOR_W = (295.235, 2.6422, -0.032380, 0.004028)  # water vapour, µm⁻²ⁿ
_CIDDOR_CF = 1.022
_CIDDOR_Z = {  # compressibility (BIPM-1981/91), SI units
    "a0": 1.58123e-6,
    "a1": -2.9331e-8,
    "a2": 1.1043e-10,
    "b0": 5.707e-6,
    "b1": -2.051e-8,
    "c0": 1.9898e-4,
    "c1": -2.376e-6,
    "d": 1.83e-11,
    "e": -0.765e-8,
}
_GAS_CONSTANT = 8.314510  # J/(mol K), Ciddor's value (it cancels in the density ratios)
_WATER_MOLAR_MASS = 0.018015  # kg/mol
_ENHANCEMENT = (1.00062, 3.14e-8, 5.6e-7)  # α, β (1/Pa), γ (1/°C²)
# IAPWS-IF97 saturation pressure of water (region 4), n1 … n10
_IF97_SAT = (
    0.11670521452767e4,
    -0.72421316703206e6,
    -0.17073846940092e2,
    0.12020824702470e5,
    -0.32325550322333e7,
    0.14915108613530e2,
    -0.48232657361591e4,
    0.40511340542057e6,
    -0.23855557567849,
    0.65017534844798e3,
)
CIDDOR_RANGE = {"temperature_c": (-40.0, 100.0), "wavelength_nm": (300.0, 1690.0)}

# --- salt water: Quan & Fry 1995 -----------------------------------------------------------
_QUAN_FRY = (
    1.31405,
    1.779e-4,
    -1.05e-6,
    1.6e-8,
    -2.02e-6,
    15.868,
    0.01155,
    -0.00423,
    -4382.0,
    1.1455e6,
)
# Quan & Fry fit Austin & Halikas's indices, measured relative to the laboratory air: made
# absolute with dry air at 20 °C, 101.325 kPa (the air's own variation, ±1e-5 over ±10 K,
# is below the fit's accuracy)
_QUAN_FRY_AIR_C = 20.0
QUAN_FRY_RANGE = {
    "temperature_c": (0.0, 30.0),
    "salinity_g_kg": (0.0, 35.0),
    "wavelength_nm": (400.0, 700.0),
}

FLUIDS = ("water", "air", "saltwater")
#: Density of the light and the heavy fluid of the mixing data (JHTDB "mixing", the sample).
MIXING_DENSITIES = (1.0, 1.105)


def _check_range(name, values, bounds, what):
    values = np.asarray(values, dtype=np.float64)
    lo, hi = bounds
    if not np.all(np.isfinite(values)):
        raise RimclError(f"{what}: {name} holds NaN or infinite values")
    if values.size and (values.min() < lo or values.max() > hi):
        raise RimclError(
            f"{what}: {name} spans {values.min():g} … {values.max():g}, outside the "
            f"formulation's range {lo:g} … {hi:g}"
        )
    return values


def iapws_water_index(temperature_c, density_kg_m3, wavelength_nm):
    """Refractive index of water and steam by the IAPWS 1997 formulation (R9-97).

    Parameters
    ----------
    temperature_c : array_like
        Temperature (°C, ITS-90), -12 … 500.
    density_kg_m3 : array_like
        Density (kg/m³), 0 … 1060.
    wavelength_nm : array_like
        Vacuum wavelength (nm), 200 … 1100.

    Returns
    -------
    ndarray, float64
        ``n``, broadcast over the inputs.
    """
    what = "IAPWS R9-97 water index"
    t = _check_range("temperature_c", temperature_c, IAPWS_RANGE["temperature_c"], what)
    rho = _check_range("density_kg_m3", density_kg_m3, IAPWS_RANGE["density_kg_m3"], what)
    lam = _check_range("wavelength_nm", wavelength_nm, IAPWS_RANGE["wavelength_nm"], what)
    a0, a1, a2, a3, a4, a5, a6, a7 = _IAPWS_A
    rho_r = rho / _IAPWS_RHO_STAR
    t_r = (t + ZERO_CELSIUS_K) / _IAPWS_T_STAR_K
    lam2 = (lam / _IAPWS_LAMBDA_STAR_NM) ** 2
    molar = (
        a0
        + a1 * rho_r
        + a2 * t_r
        + a3 * lam2 * t_r
        + a4 / lam2
        + a5 / (lam2 - _IAPWS_LAMBDA_UV**2)
        + a6 / (lam2 - _IAPWS_LAMBDA_IR**2)
        + a7 * rho_r**2
    )
    lorentz_lorenz = rho_r * molar  # (n² - 1)/(n² + 2)
    return np.sqrt((1.0 + 2.0 * lorentz_lorenz) / (1.0 - lorentz_lorenz))


def _tanaka_density(t):
    a1, a2, a3, a4, a5 = _TANAKA
    return a5 * (1.0 - (t + a1) ** 2 * (t + a2) / (a3 * (t + a4)))


def _kell_density(t):
    return np.polynomial.polynomial.polyval(t, _KELL_NUM) / (1.0 + _KELL_DEN * t)


def water_density(temperature_c):
    """Density of air-free liquid water at 0.1 MPa (kg/m³), 0 … 99 °C.

    Tanaka et al. (2001) below :data:`DENSITY_SWITCH_C`, Kell (1975) above; the two agree
    at the switch, so ``ρ(T)`` is continuous. Tanaka's table is for 101.325 kPa: the
    1.3 kPa to 0.1 MPa changes ``ρ`` by 6e-4 kg/m³ (``n`` by 3e-7), below both
    formulations' uncertainty, and is not applied.

    Parameters
    ----------
    temperature_c : array_like
        Temperature (°C, ITS-90).

    Returns
    -------
    ndarray, float64
    """
    t = _check_range("temperature_c", temperature_c, WATER_RANGE_C, "water density at 0.1 MPa")
    return np.where(t <= DENSITY_SWITCH_C, _tanaka_density(t), _kell_density(t))


def water_index(temperature_c, wavelength_nm=532.0):
    """Refractive index of liquid water at 0.1 MPa: IAPWS R9-97 at :func:`water_density`.

    Parameters
    ----------
    temperature_c : array_like
        0 … 99 °C.
    wavelength_nm : array_like
        Vacuum wavelength (nm), 200 … 1100.

    Returns
    -------
    ndarray, float64
    """
    return iapws_water_index(temperature_c, water_density(temperature_c), wavelength_nm)


def saturation_vapour_pressure(temperature_c):
    """Saturation pressure of water vapour over liquid water (Pa), IAPWS-IF97 region 4.

    Parameters
    ----------
    temperature_c : array_like
        0 … 100 °C.

    Returns
    -------
    ndarray, float64
    """
    t = _check_range("temperature_c", temperature_c, (0.0, 100.0), "saturation vapour pressure")
    n1, n2, n3, n4, n5, n6, n7, n8, n9, n10 = _IF97_SAT
    kelvin = t + ZERO_CELSIUS_K
    theta = kelvin + n9 / (kelvin - n10)
    a = theta**2 + n1 * theta + n2
    b = n3 * theta**2 + n4 * theta + n5
    c = n6 * theta**2 + n7 * theta + n8
    return 1e6 * (2.0 * c / (-b + np.sqrt(b**2 - 4.0 * a * c))) ** 4


def _ciddor_compressibility(pressure_pa, kelvin, water_fraction):
    z = _CIDDOR_Z
    t = kelvin - ZERO_CELSIUS_K
    ratio = pressure_pa / kelvin
    return (
        1.0
        - ratio
        * (
            z["a0"]
            + z["a1"] * t
            + z["a2"] * t**2
            + (z["b0"] + z["b1"] * t) * water_fraction
            + (z["c0"] + z["c1"] * t) * water_fraction**2
        )
        + ratio**2 * (z["d"] + z["e"] * water_fraction**2)
    )


def air_index(
    temperature_c,
    pressure_pa=STANDARD_PRESSURE_PA,
    wavelength_nm=532.0,
    relative_humidity=0.0,
    co2_ppm=450.0,
):
    """Refractive index of moist air by Ciddor (1996).

    Parameters
    ----------
    temperature_c : array_like
        -40 … 100 °C (humid air: 0 … 100 °C).
    pressure_pa : array_like
        Total pressure (Pa).
    wavelength_nm : array_like
        Vacuum wavelength (nm), 300 … 1690.
    relative_humidity : array_like
        0 … 1 (fraction, not %).
    co2_ppm : array_like
        CO₂ mole fraction (µmol/mol).

    Returns
    -------
    ndarray, float64
    """
    what = "Ciddor air index"
    t = _check_range("temperature_c", temperature_c, CIDDOR_RANGE["temperature_c"], what)
    lam = _check_range("wavelength_nm", wavelength_nm, CIDDOR_RANGE["wavelength_nm"], what)
    p = _check_range("pressure_pa", pressure_pa, (1.0, 1e7), what)
    h = _check_range("relative_humidity", relative_humidity, (0.0, 1.0), what)
    co2 = _check_range("co2_ppm", co2_ppm, (0.0, 1e4), what)
    kelvin = t + ZERO_CELSIUS_K
    sigma2 = (1e3 / lam) ** 2  # µm⁻²
    k0, k1, k2, k3 = _CIDDOR_K
    standard_air = 1e-8 * (k1 / (k0 - sigma2) + k3 / (k2 - sigma2))
    standard_air = standard_air * (1.0 + 0.534e-6 * (co2 - 450.0))
    w0, w1, w2, w3 = _CIDDOR_W
    standard_vapour = 1e-8 * _CIDDOR_CF * (w0 + w1 * sigma2 + w2 * sigma2**2 + w3 * sigma2**3)
    air_molar_mass = 1e-3 * (28.9635 + 12.011e-6 * (co2 - 400.0))
    if np.any(h > 0):
        if np.any((h > 0) & (t < 0)):
            raise RimclError(f"{what}: humid air needs temperatures of 0 °C or more")
        alpha, beta, gamma = _ENHANCEMENT
        enhancement = alpha + beta * p + gamma * t**2
        water_fraction = np.where(
            h > 0, enhancement * h * saturation_vapour_pressure(np.maximum(t, 0.0)) / p, 0.0
        )
    else:
        water_fraction = np.zeros(np.broadcast(t, p, h).shape)
    # densities of standard dry air (15 °C, 101325 Pa) and pure vapour (20 °C, 1333 Pa)
    standard_kelvin, vapour_kelvin = 288.15, 293.15
    rho_axs = (
        STANDARD_PRESSURE_PA
        * air_molar_mass
        / (
            _ciddor_compressibility(STANDARD_PRESSURE_PA, standard_kelvin, 0.0)
            * _GAS_CONSTANT
            * standard_kelvin
        )
    )
    rho_ws = (
        1333.0
        * _WATER_MOLAR_MASS
        / (_ciddor_compressibility(1333.0, vapour_kelvin, 1.0) * _GAS_CONSTANT * vapour_kelvin)
    )
    molar_density = p / (
        _ciddor_compressibility(p, kelvin, water_fraction) * _GAS_CONSTANT * kelvin
    )
    rho_a = molar_density * air_molar_mass * (1.0 - water_fraction)
    rho_w = molar_density * _WATER_MOLAR_MASS * water_fraction
    return 1.0 + (rho_a / rho_axs) * standard_air + (rho_w / rho_ws) * standard_vapour


def seawater_index(salinity_g_kg, temperature_c, wavelength_nm=532.0):
    """Refractive index of salt water at atmospheric pressure by Quan & Fry (1995).

    Quan & Fry's fit gives the index relative to air; it is returned absolute (relative to
    vacuum, like the other formulations) by multiplying with the index of dry air at
    20 °C and 101.325 kPa.

    Parameters
    ----------
    salinity_g_kg : array_like
        0 … 35 g/kg (‰).
    temperature_c : array_like
        0 … 30 °C.
    wavelength_nm : array_like
        Vacuum wavelength (nm), 400 … 700.

    Returns
    -------
    ndarray, float64
    """
    what = "Quan & Fry salt-water index"
    s = _check_range("salinity_g_kg", salinity_g_kg, QUAN_FRY_RANGE["salinity_g_kg"], what)
    t = _check_range("temperature_c", temperature_c, QUAN_FRY_RANGE["temperature_c"], what)
    lam = _check_range("wavelength_nm", wavelength_nm, QUAN_FRY_RANGE["wavelength_nm"], what)
    n0, n1, n2, n3, n4, n5, n6, n7, n8, n9 = _QUAN_FRY
    relative_to_air = (
        n0
        + (n1 + n2 * t + n3 * t**2) * s
        + n4 * t**2
        + (n5 + n6 * s + n7 * t) / lam
        + n8 / lam**2
        + n9 / lam**3
    )
    return relative_to_air * air_index(_QUAN_FRY_AIR_C, wavelength_nm=lam)


@dataclasses.dataclass(frozen=True)
class Fluid:
    """A fluid at a base state, whose index varies with temperature (or salinity).

    The base state is where a flow case is centred: for ``water`` and ``air`` a case varies
    the temperature around ``temperature_c`` (:meth:`index` of a temperature field); for
    ``saltwater`` it varies the salinity upwards from ``salinity_g_kg`` at the fixed
    ``temperature_c`` (:meth:`index` of a salinity field).

    Attributes
    ----------
    kind : {"water", "air", "saltwater"}
    temperature_c : float
        Base temperature (°C).
    wavelength_nm : float
        Vacuum wavelength of the light (nm).
    salinity_g_kg : float
        Base salinity (g/kg); ``saltwater`` only.
    pressure_pa : float
        Pressure (Pa); ``air`` only (water and salt water are at 0.1 MPa).
    relative_humidity : float
        0 … 1; ``air`` only.
    """

    kind: str
    temperature_c: float = 20.0
    wavelength_nm: float = 532.0
    salinity_g_kg: float = 0.0
    pressure_pa: float = STANDARD_PRESSURE_PA
    relative_humidity: float = 0.0

    def __post_init__(self):
        if self.kind not in FLUIDS:
            raise RimclError(f"unknown fluid {self.kind!r}; choose from {', '.join(FLUIDS)}")
        if self.kind != "air" and self.pressure_pa != STANDARD_PRESSURE_PA:
            raise RimclError(f"{self.kind} is modelled at 0.1 MPa only; pressure_pa applies to air")
        if self.kind != "air" and self.relative_humidity != 0.0:
            raise RimclError(f"relative_humidity applies to air, not {self.kind}")
        if self.kind != "saltwater" and self.salinity_g_kg != 0.0:
            raise RimclError(f"salinity applies to saltwater, not {self.kind}")
        self.index()  # validates the base state against the formulation's range

    @property
    def varies(self):
        """What a case varies: ``"temperature"`` (water, air) or ``"salinity"``."""
        return "salinity" if self.kind == "saltwater" else "temperature"

    @property
    def base(self):
        """The base value of :attr:`varies` (°C or g/kg)."""
        return self.salinity_g_kg if self.kind == "saltwater" else self.temperature_c

    @property
    def unit(self):
        """Unit of :attr:`varies`: ``"K"`` (a temperature difference) or ``"g/kg"``."""
        return "g/kg" if self.kind == "saltwater" else "K"

    @property
    def range(self):
        """Valid ``(low, high)`` of :attr:`varies` for this fluid's formulation."""
        if self.kind == "water":
            return WATER_RANGE_C
        if self.kind == "air":
            return (0.0, 100.0) if self.relative_humidity > 0 else CIDDOR_RANGE["temperature_c"]
        return QUAN_FRY_RANGE["salinity_g_kg"]

    def index(self, temperature_c=None, salinity_g_kg=None):
        """Refractive index at the given temperatures (or salinities), the rest at base.

        Parameters
        ----------
        temperature_c : array_like, optional
            Temperature field (°C); default the base temperature.
        salinity_g_kg : array_like, optional
            Salinity field (g/kg), ``saltwater`` only; default the base salinity.

        Returns
        -------
        ndarray, float64
            ``n``, broadcast over the inputs (0-d for the base state).
        """
        t = self.temperature_c if temperature_c is None else temperature_c
        if self.kind == "water":
            if salinity_g_kg is not None:
                raise RimclError("water has no salinity; use the saltwater fluid")
            return water_index(t, self.wavelength_nm)
        if self.kind == "air":
            if salinity_g_kg is not None:
                raise RimclError("air has no salinity")
            return air_index(t, self.pressure_pa, self.wavelength_nm, self.relative_humidity)
        s = self.salinity_g_kg if salinity_g_kg is None else salinity_g_kg
        return seawater_index(s, t, self.wavelength_nm)

    def index_of(self, values):
        """Index at values of :attr:`varies` (°C or g/kg), the other variable at base."""
        if self.kind == "saltwater":
            return self.index(salinity_g_kg=values)
        return self.index(temperature_c=values)

    def span(self, delta):
        """The ``(low, high)`` values of :attr:`varies` that a difference ``delta`` spans.

        Temperature differences are centred on the base temperature; salinity differences
        run upwards from the base salinity.
        """
        delta = float(delta)
        if self.kind == "saltwater":
            return self.base, self.base + delta
        return self.base - 0.5 * delta, self.base + 0.5 * delta

    def describe(self):
        """Plain-value description for output files."""
        record = {"fluid": self.kind, "temperature_c": self.temperature_c}
        record["wavelength_nm"] = self.wavelength_nm
        if self.kind == "saltwater":
            record["salinity_g_kg"] = self.salinity_g_kg
        if self.kind == "air":
            record["pressure_pa"] = self.pressure_pa
            record["relative_humidity"] = self.relative_humidity
        record["n_base"] = float(self.index())
        record["formulation"] = {
            "water": "IAPWS R9-97; density Tanaka 2001 / Kell 1975",
            "air": "Ciddor 1996",
            "saltwater": "Quan & Fry 1995",
        }[self.kind]
        return record

    def label(self):
        """Short text of the base state, e.g. ``"water at 20 °C"``."""
        if self.kind == "saltwater":
            return f"salt water at {self.temperature_c:g} °C from {self.salinity_g_kg:g} g/kg"
        name = "water" if self.kind == "water" else "air"
        return f"{name} at {self.temperature_c:g} °C"


def _index_difference(fluid, delta):
    """Largest index difference over the span of ``delta`` (n(T) need not be monotonic)."""
    lo, hi = fluid.span(delta)
    values = fluid.index_of(np.linspace(lo, hi, 129))
    return float(values.max() - values.min())


@dataclasses.dataclass(frozen=True)
class Equivalent:
    """The temperature or salinity difference that gives an index difference.

    Attributes
    ----------
    fluid : Fluid
    delta_n_max : float
        The index difference asked for.
    delta : float
        ``ΔT`` (K) or ``ΔS`` (g/kg) giving it; NaN when it is out of reach.
    reachable : bool
        False when even the largest difference the formulation covers gives less.
    delta_limit : float
        The largest difference within the formulation's range from the base state.
    delta_n_limit : float
        The index difference at ``delta_limit``.
    """

    fluid: Fluid
    delta_n_max: float
    delta: float
    reachable: bool
    delta_limit: float
    delta_n_limit: float

    @property
    def text(self):
        """One line, e.g. ``"air at 20 °C, ΔT ≈ 25 K"``."""
        symbol = "ΔS" if self.fluid.kind == "saltwater" else "ΔT"
        if self.reachable:
            return f"{self.fluid.label()}, {symbol} ≈ {_round2(self.delta)} {self.fluid.unit}"
        return (
            f"{self.fluid.label()}: out of reach ({symbol} = {_round2(self.delta_limit)} "
            f"{self.fluid.unit}, the formulation's limit, gives Δn = {self.delta_n_limit:.2g})"
        )

    def __str__(self):
        return self.text


def _round2(value):
    """Two significant digits, without an exponent for everyday magnitudes."""
    if value == 0 or not math.isfinite(value):
        return f"{value:g}"
    digits = max(0, 1 - math.floor(math.log10(abs(value))))
    return f"{round(value, digits):.{digits}f}"


def physical_equivalent(delta_n_max, fluid):
    """The ``ΔT`` (or ``ΔS``) of a fluid that gives an index difference ``delta_n_max``.

    Temperature differences are centred on the fluid's base temperature, salinity
    differences run up from its base salinity (as :func:`index_from_density` maps them).

    Parameters
    ----------
    delta_n_max : float
        Largest index difference of a case (``≥ 0``).
    fluid : Fluid

    Returns
    -------
    Equivalent
        ``str()`` of it reads e.g. ``"air at 20 °C, ΔT ≈ 25 K"``.
    """
    delta_n_max = float(delta_n_max)
    if not (math.isfinite(delta_n_max) and delta_n_max >= 0):
        raise RimclError(f"the index difference must be finite and >= 0, got {delta_n_max}")
    lo, hi = fluid.range
    if fluid.kind == "saltwater":
        limit = hi - fluid.base
    else:
        limit = 2.0 * min(fluid.base - lo, hi - fluid.base)
    reach = _index_difference(fluid, limit) if limit > 0 else 0.0
    if delta_n_max == 0:
        return Equivalent(fluid, 0.0, 0.0, True, limit, reach)
    if delta_n_max > reach:
        return Equivalent(fluid, delta_n_max, float("nan"), False, limit, reach)
    delta = brentq(
        lambda d: _index_difference(fluid, d) - delta_n_max, 0.0, limit, xtol=1e-12, rtol=1e-10
    )
    return Equivalent(fluid, delta_n_max, float(delta), True, limit, reach)


class IndexField(typing.NamedTuple):
    """A density field mapped onto a fluid (:func:`index_from_density`).

    ``Field.from_arrays(f.delta_n, spacing, origin, n_ref=f.n_ref, gradient=f.gradient)``
    builds the traced field.
    """

    delta_n: np.ndarray  # float32 (n3, n2, n1): n - n_ref
    n_ref: float  # the mean index
    gradient: np.ndarray  # float32 (n3, n2, n1, 3): ∇n (1/length), or None
    scalar: np.ndarray  # float64 (n3, n2, n1): temperature (°C) or salinity (g/kg)


def index_from_density(
    density,
    fluid,
    delta,
    density_gradient=None,
    light=MIXING_DENSITIES[0],
    heavy=MIXING_DENSITIES[1],
):
    """Map a dimensionless density field onto a fluid's temperature or salinity and index.

    The fraction of heavy fluid ``c = (ρ - light) / (heavy - light)`` becomes a temperature
    ``T = T0 + (1/2 - c) ΔT`` (the heavy fluid is the colder, the field is centred on the
    base temperature ``T0``) or a salinity ``S = S0 + c ΔS`` (the heavy fluid is the
    saltier). The index follows the fluid's nonlinear ``n(T)`` or ``n(S)``.

    Parameters
    ----------
    density : array_like, shape (n3, n2, n1)
        Dimensionless density (the field file's ``density``).
    fluid : Fluid
    delta : float
        ``ΔT`` (K) or ``ΔS`` (g/kg) between the light and the heavy fluid (``≥ 0``).
    density_gradient : array_like, shape (n3, n2, n1, 3), optional
        ``∇ρ`` (1/length); gives ``∇n = (dn/dc) ∇ρ / (heavy - light)`` by the chain rule.
    light, heavy : float
        Dimensionless densities of the light and the heavy fluid.

    Returns
    -------
    IndexField
        ``delta_n`` float32 ``(n3, n2, n1)``; ``n_ref`` float, the mean index; ``gradient``
        float32 ``(n3, n2, n1, 3)`` or None; ``scalar`` float64, the temperature (°C) or
        salinity (g/kg) field. ``delta = 0`` gives ``δn`` exactly 0.
    """
    delta = float(delta)
    if not (math.isfinite(delta) and delta >= 0):
        raise RimclError(f"the {fluid.varies} difference must be finite and >= 0, got {delta}")
    if not heavy > light:
        raise RimclError(f"the heavy density ({heavy}) must exceed the light one ({light})")
    rho = np.asarray(density, dtype=np.float64)
    fraction = (rho - light) / (heavy - light)
    if fluid.kind == "saltwater":
        slope = delta  # dS/dc
        scalar = fluid.base + fraction * delta
    else:
        slope = -delta  # dT/dc
        scalar = fluid.base + (0.5 - fraction) * delta
    n = fluid.index_of(scalar)
    first = n.flat[0]
    # mean of the differences to one sample: exactly that sample when the field is uniform,
    # so a zero difference gives δn = 0 exactly (no rounding of a mean of equal numbers)
    n_ref = float(first + np.mean(n - first))
    gradient = None
    if density_gradient is not None:
        grad_rho = np.asarray(density_gradient, dtype=np.float64)
        if grad_rho.shape != (*rho.shape, 3):
            raise RimclError(
                f"density_gradient must have shape {(*rho.shape, 3)}, got {grad_rho.shape}"
            )
        step = 1e-3 * max(abs(delta), 1.0)  # central difference: relative error ~1e-7
        lo, hi = fluid.range
        ahead = np.minimum(scalar + step, hi)
        behind = np.maximum(scalar - step, lo)
        dn_dscalar = (fluid.index_of(ahead) - fluid.index_of(behind)) / (ahead - behind)
        dn_drho = dn_dscalar * slope / (heavy - light)
        gradient = (dn_drho[..., None] * grad_rho).astype(np.float32)
    return IndexField(
        delta_n=(n - n_ref).astype(np.float32), n_ref=n_ref, gradient=gradient, scalar=scalar
    )
