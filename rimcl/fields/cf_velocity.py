"""Velocity of an imported CF dataset (:mod:`rimcl.fields.cf_import`): which variables are
the flow's components, and their frames in field units along ``x1, x2, x3``.

Components are found by name (``u, v, w``, ...) or CF ``standard_name`` (``*_x_velocity``,
``eastward_*``, ``upward_*``) among the variables on the scalar's grid, or as one
``velocity`` array with a trailing component axis; two candidates for one component (a flow
and a Stokes drift) are refused, naming ``--velocity``. Units are read with cf-units
(:func:`rimcl.fields.cf_units.velocity_factor`).
"""

from types import SimpleNamespace

import numpy as np

from rimcl.core.errors import RimclError
from rimcl.fields.cf_units import velocity_factor

_VELOCITY_NAMES = {
    "x": ("u", "ux", "u_x", "u1", "velocity_x", "vx", "x_velocity"),
    "y": ("v", "uy", "u_y", "u2", "velocity_y", "vy", "y_velocity"),
    "z": ("w", "uz", "u_z", "u3", "velocity_z", "vz", "z_velocity"),
}
_VELOCITY_STANDARD = {"x": ("_x_velocity", "eastward_", "x_wind"),
                      "y": ("_y_velocity", "northward_", "y_wind"),
                      "z": ("_z_velocity", "upward_")}  # fmt: skip


def velocity_variables(variables, velocity, path):
    """The velocity variables along ``x, y, z`` (or one with a component axis), or None.

    Without ``velocity`` the candidates are found by name and ``standard_name`` among the
    variables (on any grid: one off the scalar's is refused when read); two candidates for
    one component (a flow and a Stokes drift, say) are refused rather than one taken by its
    place in the file.
    """
    if velocity is not None:
        names = [n.strip() for n in str(velocity).split(",")]
        if len(names) == 1 and names[0] in variables:
            return names[0]
        if len(names) != 3 or any(n not in variables for n in names):
            raise RimclError(
                f"--velocity names the x, y, z components ('u,v,w'), got {velocity!r} "
                f"(variables: {', '.join(sorted(variables))})"
            )
        return dict(zip(("x", "y", "z"), names, strict=True))
    stacked = variables.get("velocity")
    stacked = stacked if stacked is not None and stacked.dims[-1:] == ("component",) else None
    found = {}
    for letter in ("x", "y", "z"):
        for var in variables.values():
            standard = str(var.attrs.get("standard_name", "")).lower()
            if var.name.lower() in _VELOCITY_NAMES[letter] or (
                standard and any(part in standard for part in _VELOCITY_STANDARD[letter])
            ):
                found.setdefault(letter, []).append(var.name)
    several = {a: names for a, names in found.items() if len(names) > 1}
    if several or (stacked is not None and found):
        options = "; ".join(f"{a}: {', '.join(n)}" for a, n in several.items()) or (
            f"'velocity' and {', '.join(n for names in found.values() for n in names)}"
        )
        raise RimclError(
            f"{path} holds several velocity candidates ({options}); name the flow's "
            "components with --velocity u,v,w"
        )
    if stacked is not None:
        return "velocity"
    if not found:
        return None
    if len(found) != 3:
        raise RimclError(
            f"{path} has velocity along {', '.join(sorted(found))} only; rimcl needs all "
            "three components (or none): name them with --velocity u,v,w"
        )
    return {letter: names[0] for letter, names in found.items()}


def read_velocity(variables, vel, wanted, frame_of, layout, length_m, time_s, up, timed):
    """Velocity frames in field length per field time, along ``x1, x2, x3``.

    ``up``: the axis letters turned up (``positive = "down"`` in the input), whose
    component changes sign unless its ``standard_name`` says it is upward already;
    ``timed``: whether the input's times are in a unit it does not name (then a velocity in
    m s-1 cannot be put in field units, and is refused).
    """
    if isinstance(vel, str):
        var = variables[vel]
        parts = {}
        for letter, component in zip(("x", "y", "z"), range(3), strict=True):
            parts[letter] = SimpleNamespace(
                name=var.name,
                attrs=var.attrs,
                read=lambda sel=(), c=component: var.read(sel)[..., c],
            )
        unit = var.attrs.get("units")
    else:
        parts = {letter: variables[name] for letter, name in vel.items()}
        units = {str(v.attrs.get("units", "")) for v in parts.values()}
        if len(units) > 1:
            raise RimclError(f"the velocity components have different units: {sorted(units)}")
        unit = units.pop()
    names = "/".join(dict.fromkeys(v.name for v in parts.values()))
    factor, note = 1.0, "field length per field time (the file gives no units)"
    speed = velocity_factor(unit, names)
    if speed is not None:
        if length_m is None:
            note = f"{unit} (the coordinates give no length unit)"
        elif timed:
            raise RimclError(
                f"the velocity {names} is in {unit}, but the time coordinate has no units: "
                "give it units (e.g. 'seconds since 2000-01-01') to convert the velocity"
            )
        else:
            if time_s is None:
                time_s = 1.0  # times from --t0/--dt: the velocity's own unit, seconds
            factor = speed / (length_m / time_s)
            note = f"converted from {unit} to field units (x {factor:g})"
    signs = np.array(
        [
            -1.0
            if a in up and "upward" not in str(parts[a].attrs.get("standard_name", "")).lower()
            else 1.0
            for a in ("x", "y", "z")
        ]
    )
    if np.any(signs < 0):
        note += "; the downward component's sign changed (positive = down)"
    frames = []
    for k in wanted:
        stacked = np.stack([frame_of(parts[a], k) for a in ("x", "y", "z")], axis=-1)
        frames.append(layout.vector(stacked * (factor * signs)))
    return frames, note, time_s
