"""Rays through flat layers normal to ``x1`` (the fluid, a window, the outside medium).

Snell at each plane interface: :func:`aim_through_layers` finds the start direction that
reaches a given lateral offset (the lens camera's and the LPT rig's aiming through a
window), :func:`cross_window` carries exit rays through a window. Lengths in field length
units; directions are unit vectors, ``+x1`` towards the camera.
"""

import numpy as np


def _refract(directions, ratio):
    """Snell at a plane of normal ``x1``: unit directions into a medium with
    ``n_in / n_out = ratio`` (scalar or (K,)). Returns directions, NaN where reflected."""
    tangential = directions[:, 1:] * np.reshape(ratio, (-1, 1))
    with np.errstate(invalid="ignore"):
        normal = np.sqrt(1.0 - np.sum(tangential**2, axis=1))
    refracted = np.column_stack([normal, tangential])
    refracted[np.isnan(normal)] = np.nan
    return refracted


#: Newton steps of :func:`aim_through_layers` (``LENS_NEWTON_STEPS`` of ``cl/fan.cl``).
NEWTON_STEPS = 50
#: Longest cycle of a ray's last Newton iterates that :func:`aim_through_layers` detects.
NEWTON_CYCLE = 8


def _newton_step(sine, reach, depths, ratios):
    """One Newton step of :func:`aim_through_layers` for rays ``(K,)``."""
    s = sine[:, None] * ratios
    cosine = np.sqrt(1.0 - s**2)
    run = np.sum(depths * s / cosine, axis=-1)
    # c·c·c, not c**3: a pow whose last bit depends on the CPU (SIMD or libm)
    slope = np.sum(depths * ratios / (cosine * cosine * cosine), axis=-1)
    return sine - (run - reach) / slope


def aim_through_layers(lateral, depths, ratios):
    """Unit start directions of rays that cross flat layers normal to ``x1`` and reach a
    given lateral offset (Snell at every interface).

    :data:`NEWTON_STEPS` Newton steps from above (the run is convex and increasing in the
    sine, so they converge monotonically), as the device's fan kernel runs them. A ray
    whose iterate repeats one of its last :data:`NEWTON_CYCLE` (a fixed point, or a cycle
    in the last bits, which about a third of the rays fall into) repeats that cycle to the
    last step: its last iterate is read off the cycle and its steps end there, so the
    result has every bit of all the steps run.

    Parameters
    ----------
    lateral : ndarray, shape (..., 2)
        ``(x2, x3)`` offset from the start to the aim point (length units).
    depths : ndarray, shape (3,) or (..., 3)
        ``x1`` thickness of each layer, the start's first (length units, >= 0).
    ratios : ndarray, shape (3,)
        ``n_start / n_layer`` of each layer (1 for the first).

    Returns
    -------
    ndarray, float64, shape (..., 3)
        Directions in the first layer, towards ``+x1``.
    """
    reach = np.linalg.norm(lateral, axis=-1)
    # lateral run = Σ depth_i tan θ_i with sin θ_i = ratio_i sin θ (Snell at both faces)
    start = np.minimum(reach / np.sum(depths * ratios, axis=-1), 0.999 / ratios.max())
    reach_rays = reach.reshape(-1)
    depth_rays = np.broadcast_to(depths, (*reach.shape, 3)).reshape(-1, 3)
    sine = np.empty_like(reach_rays)
    active = np.arange(reach_rays.size)
    iterates = [np.broadcast_to(start, reach.shape).reshape(-1)]  # the last of each ray
    for step in range(1, NEWTON_STEPS + 1):
        following = _newton_step(iterates[-1], reach_rays[active], depth_rays[active], ratios)
        iterates = [*iterates[-NEWTON_CYCLE:], following]
        settled = np.zeros(active.size, dtype=bool)
        for period in range(1, len(iterates)):
            # iterate `step` equals iterate `step - period`: periodic from there on, so
            # the last step's is `(NEWTON_STEPS - step) % period` steps into the cycle
            repeats = ~settled & (following == iterates[-1 - period])
            if repeats.any():
                into = (NEWTON_STEPS - step) % period
                sine[active[repeats]] = iterates[-1 - period + into][repeats]
                settled |= repeats
        if settled.any():
            active = active[~settled]
            iterates = [values[~settled] for values in iterates]
    sine[active] = iterates[-1]
    sine = sine.reshape(reach.shape)
    unit = np.divide(
        lateral, reach[..., None], out=np.zeros_like(lateral), where=reach[..., None] > 0
    )
    return np.concatenate([np.sqrt(1.0 - sine**2)[..., None], sine[..., None] * unit], axis=-1)


def cross_window(end_pos, end_dir, thickness, fluid_index, window):
    """Rays leaving the fluid at ``x1 = x_end`` carried through a flat window.

    Parameters
    ----------
    end_pos, end_dir : ndarray, shape (K, 3)
        Exit points on the window's inner face and unit directions in the fluid.
    thickness : float
        The window's thickness (length units of ``end_pos``).
    fluid_index : float or ndarray, shape (K,)
        Index of the fluid at each exit point.
    window : FlatWindow

    Returns
    -------
    positions, directions : ndarray, shape (K, 3)
        On the outer face, and unit directions outside; NaN where reflected totally.
    """
    in_glass = _refract(end_dir, fluid_index / window.glass_index)
    positions = end_pos + (thickness / in_glass[:, :1]) * in_glass
    return positions, _refract(end_dir, fluid_index / window.outside_index)
