"""The settings a study's PIV and PTV measured with, side by side.

A ratio of PIV's to PTV's relative refraction error compares like with like only where both
imaged the same tracers' light the same way: the same frame spacing Δt (a velocity error
from a position error scales as 1/Δt), the same camera and pixel on the sheet, the same
rays per tracer and the same bits. :func:`side_by_side` gives both sets and names those
that differ; the summary prints them beside the verdict, which holds only for like for like.
"""

import math

from rimcl.piv.study import configs_from_study

#: The settings compared: (key, name in the summary).
COMPARED = (
    ("dt", "Δt"),
    ("camera", "camera"),
    ("pixel_size_over_L", "pixel on the sheet / L"),
    ("rays_per_tracer", "rays per tracer"),
    ("bit_depth", "bits"),
    ("sensor_noise", "sensor noise"),
)


def _rays(camera):
    """Rays per tracer of a camera configuration (a plane camera: its fan squared)."""
    return int(camera.fan) ** 2 if camera.kind == "plane" else int(camera.pupil_rays)


def _same(first, second):
    if isinstance(first, float) and isinstance(second, float):
        return math.isclose(first, second, rel_tol=1e-9)
    return first == second


def side_by_side(study, ptv_case, piv_stats):
    """PTV's and PIV's measurement settings of one case, and those that differ.

    Parameters
    ----------
    study : rimcl.scene.study_config.StudyConfig
    ptv_case : dict
        The case's ``stats.json`` entry (its ``dt`` and ``pixel_size_over_L``).
    piv_stats : dict
        :func:`rimcl.piv.study.case_statistics` of the same case.

    Returns
    -------
    dict
        ``ptv`` and ``piv`` (``{key: value}`` of :data:`COMPARED`: Δt in field time
        units, the camera kind, the pixel over L, rays per tracer, bits, noise on or
        off), ``differ`` (the keys whose values differ) and ``like_for_like`` (none
        differs).
    """
    shared = study.shared
    _, piv_configs = configs_from_study(study)
    ptv = {
        "dt": float(ptv_case["dt"]),
        "camera": shared.camera.kind,
        "pixel_size_over_L": float(ptv_case["pixel_size_over_L"]),
        "rays_per_tracer": _rays(shared.camera),
        "bit_depth": int(shared.renderer.bit_depth),
        "sensor_noise": bool(shared.sensor.noise),
    }
    piv = {
        "dt": float(piv_stats["dt"]),
        "camera": piv_configs["camera"].kind,
        "pixel_size_over_L": float(piv_stats["pixel_size_over_L"]),
        "rays_per_tracer": _rays(piv_configs["camera"]),
        "bit_depth": int(study.piv.bit_depth),
        "sensor_noise": bool(piv_configs["sensor"].noise),
    }
    differ = [key for key, _ in COMPARED if not _same(ptv[key], piv[key])]
    return {"ptv": ptv, "piv": piv, "differ": differ, "like_for_like": not differ}
