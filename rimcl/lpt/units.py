"""An LPT case's errors in physical units: µm and px, mm/s and px/frame, m/s².

LPT positions are in field length units with ``length_m`` metres each (the scene's
``field.length_m``, else the field scaled to a 100 mm ``x2`` width); velocities and
accelerations need a time scale too, ``field.time_s`` (seconds per field time unit, or
``field.length_m / field.velocity_m_s``). :func:`case_units` states every rms of a case
both ways, ``physical = normalised × scale`` with the factors of
:func:`rimcl.stats.units.scales`, as the PTV statistics do; without ``time_s`` the
velocities and accelerations stay in field units (their physical values ``None``) and the
block's ``note`` says so.
"""

from rimcl.stats.units import scale_note, scales

COMPONENTS = ("x1", "x2", "x3")
#: Errors of each component (``meas − ref``, its optics and imaging parts, the noise floor
#: ``floor − ref``, ``ref − true``, self-calibrated ``meas − ref``; :mod:`rimcl.lpt.budget`).
ERRORS = (
    "refraction",
    "optics",
    "imaging",
    "noise_floor",
    "baseline",
    "refraction_self_calibrated",
)
#: Per kinematic group: the physical unit's key and the factor of :func:`scales` for it.
_GROUPS = {
    "velocity": ("mm_s", "mm_s_per_velocity"),
    "acceleration": ("m_s2", "m_s2_per_acceleration"),
}


def _times(value, factor):
    return None if value is None or factor is None else value * factor


def _rms(summary):
    return None if summary is None else summary["rms"]


def case_units(stats, depth, length_m, time_s=None):
    """The ``units`` block of one case of ``lpt_stats.json``.

    Parameters
    ----------
    stats : dict
        The case's statistics (:func:`rimcl.lpt.run.case_statistics`): ``pixel_size``,
        ``fit.dt``, ``position`` and ``velocity``/``acceleration`` with their ``absolute``
        rms errors and ``truth_rms`` (field units).
    depth : float
        The field's extent along ``x1`` (field length units; ``L_mm`` of the scales).
    length_m : float
        Metres per field length unit.
    time_s : float, optional
        Seconds per field time unit.

    Returns
    -------
    dict
        ``scales`` (:func:`rimcl.stats.units.scales`), ``note``, ``position`` per component
        and error: ``{"field", "um", "px"}``; ``velocity`` and ``acceleration`` per
        component: ``rms_truth`` and ``rms_<error>`` (:data:`ERRORS`) as ``{"field",
        "mm_s", "px_frame"}`` and ``{"field", "m_s2"}`` (None where nothing was measured
        or the scale is unknown).
    """
    factors = scales(depth, stats["pixel_size"], stats["fit"]["dt"], length_m, time_s)
    block = {"scales": factors, "note": scale_note(factors), "position": {}}
    for name in COMPONENTS:
        block["position"][name] = {
            f"rms_{kind}": {
                "field": _rms(stats["position"][name][kind]),
                "um": _times(_rms(stats["position"][name][kind]), factors["um_per_length"]),
                "px": _times(_rms(stats["position"][name][kind]), factors["px_per_length"]),
            }
            for kind in ERRORS
        }
    for group, (physical, factor) in _GROUPS.items():

        def both(value, physical=physical, factor=factor, group=group):
            entry = {"field": value, physical: _times(value, factors[factor])}
            if group == "velocity":
                entry["px_frame"] = _times(value, factors["px_frame_per_velocity"])
            return entry

        block[group] = {}
        for name in COMPONENTS:
            entry = stats[group][name]
            values = {"rms_truth": both(entry["truth_rms"])}
            for kind in ERRORS:
                values[f"rms_{kind}"] = both(_rms(entry["absolute"][kind]))
            block[group][name] = values
    return block
