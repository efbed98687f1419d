"""Gladstone–Dale cases: how strongly density fluctuations bend light.

The refractive index follows ``n = 1 + G ρ`` with ``G = K ρ_fluid`` (the paper's ``K ρ``,
dimensionless) and ``ρ`` the dimensionless density of the flow data. The five cases of the
paper span air to water; any other ``G`` can be given directly.
"""

import math

from rimcl.core.errors import RimclError

#: Gladstone–Dale product ``G = K ρ`` of the paper's cases (dimensionless).
CASES = {"C0": 3.34e-5, "C1": 2.82e-4, "C2": 3.34e-3, "C3": 3.34e-2, "C4": 3.34e-1}

#: The paper's largest index difference Δn_max in its JHTDB cut-out, per case.
PAPER_DELTA_N_MAX = {"C0": 2.85e-6, "C1": 2.40e-5, "C2": 2.85e-4, "C3": 2.85e-3, "C4": 2.85e-2}

#: Fluid each case stands for, where the paper names one.
CASE_FLUIDS = {"C1": "air", "C4": "water"}


def custom_case_name(k_rho):
    """Name of a case given by its ``G`` alone, e.g. ``"G=0.001"``."""
    return f"G={k_rho:g}"


def resolve_k_rho(case=None, k_rho=None):
    """Name and Gladstone–Dale product of a case given by name or by value.

    Parameters
    ----------
    case : str, optional
        ``"C0"`` … ``"C4"`` (case-insensitive), or a custom name ``"G=<value>"`` as
        returned by this function.
    k_rho : float, optional
        A custom ``G = K ρ`` (dimensionless, finite, ``>= 0``; 0 is a uniform medium).

    Returns
    -------
    name : str
        The case name (``"C1"``, or ``"G=0.001"`` for a custom value).
    k_rho : float

    Raises
    ------
    RimclError
        If neither or both are given, or the case or value is not valid.
    """
    if case is not None and k_rho is not None:
        raise RimclError(f"give either a case ({case!r}) or a K*rho value ({k_rho!r}), not both")
    if case is None and k_rho is None:
        raise RimclError(
            f"a density field needs a Gladstone-Dale product: a case ({', '.join(CASES)}) "
            "or a custom K*rho"
        )
    if case is not None:
        name = str(case).strip()
        if name.upper() in CASES:
            return name.upper(), CASES[name.upper()]
        if not name.lower().startswith("g="):
            raise RimclError(
                f"unknown case {case!r}; choose from {', '.join(CASES)} or give 'G=<value>'"
            )
        k_rho = name[2:]
    try:
        value = float(k_rho)
    except (TypeError, ValueError):
        raise RimclError(f"K*rho must be a number, got {k_rho!r}") from None
    if not math.isfinite(value) or value < 0:
        raise RimclError(f"K*rho must be finite and >= 0, got {value!r}")
    return custom_case_name(value), value


#: Prefixes of fluid cases: a temperature (K) or salinity (g/kg) difference of a fluid.
FLUID_CASES = {"dT=": "temperature", "dS=": "salinity"}


def fluid_case(name):
    """The fluid difference a case name asks for, or None for a Gladstone–Dale case.

    Parameters
    ----------
    name : str
        ``"dT=<kelvin>"`` or ``"dS=<g/kg>"`` (between the light and the heavy fluid).

    Returns
    -------
    (str, float) or None
        ``("temperature" | "salinity", difference)``.
    """
    text = str(name).strip()
    for prefix, quantity in FLUID_CASES.items():
        if text.lower().startswith(prefix.lower()):
            try:
                value = float(text[len(prefix) :])
            except ValueError:
                raise RimclError(f"{name!r}: {prefix}<value> needs a number") from None
            if not math.isfinite(value) or value < 0:
                raise RimclError(f"{name!r}: the difference must be finite and >= 0")
            return quantity, value
    return None
