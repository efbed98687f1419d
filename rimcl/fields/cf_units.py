"""Units of an imported dataset, read with cf-units (UDUNITS-2, the units library the CF
conventions name): a scalar's units to the unit rimcl stores, and the metres, seconds and
metres per second of one coordinate, time or velocity unit.

Every function refuses, in one line that names the option to give, units it cannot read or
that are not of the right kind, and a missing ``units`` attribute where a quantity needs
one (a temperature in K or °C, a salinity, a density in kg m-3 or relative to
1000 kg m-3): no unit is guessed.
"""

from rimcl.core.errors import RimclError

#: The unit each quantity is stored in (cf-units spelling; a density is stored relative to
#: 1000 kg m-3, converted through kg m-3).
_TARGET = {"temperature": "degC", "salinity": "g/kg", "density": "kg m-3", "index": "1",
           "delta_n": "1"}  # fmt: skip
#: Quantities whose values mean nothing without units (a density of 1000 read as relative
#: to 1000 kg m-3 gives n ≈ 335).
NEEDS_UNITS = ("temperature", "salinity", "density")
#: Practical salinity (PSS-78) is a ratio UDUNITS does not name; its values are within
#: 0.5 % of g/kg, which is how rimcl's n(S) reads them.
_PRACTICAL_SALINITY = ("psu", "pss-78", "pss78", "practical_salinity_unit")
#: Relative densities beyond this are not ρ / 1000 kg m-3 of any fluid (osmium: 22.6).
_MAX_RELATIVE_DENSITY = 25.0
_HINT = {"temperature": "'K' or 'degC'", "salinity": "'g/kg', 'psu' or '1' (kg/kg)",
         "density": "'kg m-3', or '1' for ρ / 1000 kg m-3", "index": "'1'",
         "delta_n": "'1'"}  # fmt: skip


def _unit(text, what):
    from cf_units import Unit

    try:
        return Unit(str(text).strip())
    except (ValueError, TypeError):
        raise RimclError(f"{what}: units {text!r} are not UDUNITS units") from None


def has_units(text):
    """Whether a ``units`` attribute is given (not missing, not blank)."""
    return text is not None and str(text).strip() != ""


def scalar_conversion(quantity, units, name, standard_name=""):
    """Factor and offset taking the scalar from ``units`` to its stored unit.

    Parameters
    ----------
    quantity : str
        One of ``temperature`` (stored in °C), ``salinity`` (g/kg), ``density``
        (ρ / 1000 kg m-3), ``index`` or ``delta_n`` (dimensionless).
    units : str or None
        The ``units`` attribute (or ``--units``).
    name : str
        The variable's name, for the error lines.
    standard_name : str
        Its CF ``standard_name``: practical salinity in ``1`` is PSS-78.

    Returns
    -------
    factor, offset : float
        ``stored = values * factor + offset``.
    """
    hint = f"give them with --units ({_HINT[quantity]})"
    if not has_units(units):
        if quantity in NEEDS_UNITS:
            raise RimclError(f"{name}: a {quantity} without units is ambiguous; {hint}")
        return 1.0, 0.0
    text = str(units).strip()
    if quantity == "salinity" and (
        text.lower() in _PRACTICAL_SALINITY
        or (text == "1" and "practical_salinity" in str(standard_name).lower())
    ):
        return 1.0, 0.0
    unit = _unit(text, name)
    if quantity == "density" and unit.is_dimensionless():
        factor = unit.convert(1.0, "1")  # relative to 1000 kg m-3 already
        return float(factor), 0.0
    target = _TARGET[quantity]
    if not unit.is_convertible(target):
        article = "an" if quantity == "index" else "a"
        raise RimclError(f"{name}: units {text!r} are not those of {article} {quantity}; {hint}")
    offset = float(unit.convert(0.0, target))
    factor = float(unit.convert(1.0, target)) - offset
    if quantity == "density":
        factor, offset = factor * 1e-3, offset * 1e-3
    return factor, offset


def check_relative_density(values_range, units, name):
    """Refuse a density whose stored values (ρ / 1000 kg m-3) are no fluid's: 1000 read in
    units of 1, or an anomaly ρ - ρ0."""
    lo, hi = values_range
    if not (0.0 < lo and hi < _MAX_RELATIVE_DENSITY):
        raise RimclError(
            f"{name}: density {lo:g} … {hi:g} × 1000 kg m-3 (units {units!r}) is no fluid's "
            "density (the wrong units, or an anomaly?); give its units with --units (e.g. "
            "'kg m-3')"
        )


def length_factor(units, name):
    """Metres per unit of a coordinate, or None where it has no units or is not a length
    (degrees of latitude, grid indices)."""
    if not has_units(units):
        return None
    try:
        unit = _unit(units, name)
    except RimclError:
        return None  # not a UDUNITS unit at all: an index or a label, not a length
    return float(unit.convert(1.0, "m")) if unit.is_convertible("m") else None


def time_factor(units, name):
    """Seconds per unit of a time coordinate (``hours``, ``ms``, ``days since 2000-01-01``),
    or None where it has no units.

    Raises
    ------
    RimclError
        For units that are not a time.
    """
    if not has_units(units):
        return None
    period = str(units).split(" since ")[0].strip()
    unit = _unit(period, name)
    if not unit.is_convertible("s"):
        raise RimclError(f"{name}: units {units!r} are not a time (e.g. 'seconds since …')")
    return float(unit.convert(1.0, "s"))


def velocity_factor(units, name):
    """Metres per second of one velocity unit (``m s-1``, ``m.s-1``, ``cm/s``), or None
    where it has no units.

    Raises
    ------
    RimclError
        For units that are not a velocity.
    """
    if not has_units(units):
        return None
    unit = _unit(units, name)
    if not unit.is_convertible("m s-1"):
        raise RimclError(f"{name}: units {units!r} are not a velocity (e.g. 'm s-1')")
    return float(unit.convert(1.0, "m s-1"))
