"""Camera files that OpenLPT reads, and the LPT challenge's calibration points.

**World frame** (shared with ``truth_tracks``): ``X, Y, Z = x2, x3, x1`` of the field, in
millimetres from the field's origin; ``Z`` is the depth, the axis every rig camera looks
along (towards ``-Z``). **Pixels**: ``(column, row)``, pixel ``(0, 0)`` centred on the
top-left pixel (OpenLPT's ``Pt2D(col, row)``, whose pixel ``(0, 0)`` is centred at 0.0).

OpenLPT (``pyopenlpt.loadCameraModel``) reads its camera files as a stream of tokens after
dropping the ``#`` comment lines, so every value line below is one token where OpenLPT
reads one (no spaces inside comma lists). Three models per camera:

- ``PINPLATE``: a pinhole at the entrance pupil's centre behind a flat refractive plate,
  the rig's exact chief-ray geometry (``x_cam = R X + T``; ``col = f x/z + c_x``,
  ``row = f y/z + c_y``; ``R``'s rows are the camera's column, row and viewing directions in
  the world frame; the plate's reference point on its fluid-side face, its normal from
  the camera towards the fluid; indices fluid → glass → outside; thickness in mm). Written
  for every camera with a window or a bare fluid surface between fluid and lens.
- ``PINHOLE``: the same camera without refraction, written only where nothing refracts
  (no window and the outside medium's index equal to the fluid's).
- ``POLYNOMIAL``: the Soloff fit of the calibration (cubic in ``X, Y``, quadratic in
  ``Z``), its coefficients expanded exactly from rimcl's normalised coordinates to powers of
  ``X, Y, Z`` in mm; its two reference planes ``Z = const`` (for OpenLPT's line of sight)
  bound the calibrated volume.

A camera with a Scheimpflug tilt has no pinhole model in OpenLPT (its camera matrix has no
term for a tilted sensor): only its ``POLYNOMIAL`` file is written, and
:func:`write_camera_files` says so in the models it returns.
"""

from math import comb

import numpy as np

from rimcl.core.atomic import atomic_path

#: Field axes of the world's X, Y, Z (X along x2, Y along x3, Z the depth x1).
XYZ_AXES = (1, 2, 0)
#: How many digits the camera files keep (OpenLPT parses them as doubles).
_DIGITS = 17


def _number(value):
    return f"{float(value):.{_DIGITS}g}"


def _row(values, separator=","):
    return separator.join(_number(v) for v in values)


def world_mm(points, length_m):
    """Field points ``(..., 3)`` in ``(x1, x2, x3)`` (field units) as world ``(X, Y, Z)`` mm."""
    return np.asarray(points, dtype=np.float64)[..., XYZ_AXES] * length_m * 1e3


def _world_vector(vector):
    return np.asarray(vector, dtype=np.float64)[..., XYZ_AXES]


def pinhole_parameters(camera):
    """The pinhole of a rig camera in the world frame.

    Parameters
    ----------
    camera : rimcl.lpt.rig.RigCamera

    Returns
    -------
    dict
        ``rotation`` (3, 3) (rows: column, row and viewing directions), ``translation`` (3,)
        (mm), ``focal_px`` (pupil-to-sensor distance in pixels), ``centre_px``
        ``(c_x, c_y)`` and ``image_size`` ``(n_row, n_col)``.
    """
    rotation = np.stack(
        [_world_vector(camera.right), _world_vector(camera.down), _world_vector(camera.forward)]
    )
    centre = world_mm(camera.position, camera.length_m)
    columns, rows = camera.pixels
    return {
        "rotation": rotation,
        "translation": -rotation @ centre,
        "focal_px": camera.principal_distance_mm * 1e3 / camera.pixel_pitch_um,
        "centre_px": (0.5 * (columns - 1), 0.5 * (rows - 1)),
        "image_size": (rows, columns),
    }


def _pinhole_lines(camera, model, error_lines):
    pinhole = pinhole_parameters(camera)
    rotation, translation = pinhole["rotation"], pinhole["translation"]
    focal, (c_x, c_y) = pinhole["focal_px"], pinhole["centre_px"]
    n_row, n_col = pinhole["image_size"]
    angle = np.arccos(np.clip(0.5 * (np.trace(rotation) - 1.0), -1.0, 1.0))
    axis = np.array(
        [
            rotation[2, 1] - rotation[1, 2],
            rotation[0, 2] - rotation[2, 0],
            rotation[1, 0] - rotation[0, 1],
        ]
    )
    norm = np.linalg.norm(axis)
    # Rodrigues vector (OpenLPT reads and ignores it; written for OpenCV users)
    rotation_vector = axis / norm * angle if norm > 1e-12 else np.zeros(3)
    lines = [
        "# Camera Model: (PINHOLE/POLYNOMIAL/PINPLATE)",
        model,
        *error_lines,
        "# Image Size: (n_row,n_col)",
        f"{n_row},{n_col}",
        "# Camera Matrix: (px; col = f x/z + c_x, row = f y/z + c_y, pixel (0, 0) centred at 0)",
        _row([focal, 0.0, c_x]),
        _row([0.0, focal, c_y]),
        "0,0,1",
        "# Distortion Coefficients: (none: an ideal lens)",
        "0,0,0,0,0",
        "# Rotation Vector:",
        _row(rotation_vector),
        "# Rotation Matrix: (x_cam = R X + T; X, Y, Z = field x2, x3, x1 in mm)",
        *(_row(r) for r in rotation),
        "# Inverse of Rotation Matrix:",
        *(_row(r) for r in rotation.T),
        "# Translation Vector: (mm)",
        _row(translation),
        "# Inverse of Translation Vector: (mm; the pupil centre)",
        _row(-rotation.T @ translation),
    ]
    return lines


def _error_lines(residual_px):
    text = "None" if residual_px is None else f"{_number(residual_px)},0"
    return [
        "# Camera Calibration Error: (rms reprojection of the target, px; None: exact model)",
        text,
        "# Pose Calibration Error:",
        "None",
    ]


def refracts(camera):
    """True where light refracts between the fluid and the lens (a window or a bare
    surface between different indices)."""
    return camera.window_thickness_mm > 0 or camera.window.outside_index != camera.fluid_index


def pinplate_text(camera):
    """The ``PINPLATE`` camera file of a rig camera (text)."""
    face_field = np.array([camera.x_end, camera.look_at[1], camera.look_at[2]])
    plane_point = world_mm(face_field, camera.length_m)
    normal = _world_vector([-1.0, 0.0, 0.0])
    window = camera.window
    glass_index = window.glass_index if camera.window_thickness_mm > 0 else window.outside_index
    lines = _pinhole_lines(camera, "PINPLATE", _error_lines(None))
    lines += [
        "# Reference Point of Refractive Plate: (mm; on its fluid-side face)",
        _row(plane_point),
        "# Normal Vector of Refractive Plate: (unit; from the camera towards the fluid)",
        _row(normal),
        "# Refractive Index Array: (fluid,glass,outside)",
        _row([camera.fluid_index, glass_index, window.outside_index]),
        "# Width of the Refractive Plate: (mm)",
        _number(camera.window_thickness_mm),
        "# Projection Tolerance:",
        "1e-10",
        "# Maximum Number of Iterations for Projection:",
        "1000",
        "# Optimization Rate:",
        "0.5",
    ]
    return "\n".join(lines) + "\n"


def pinhole_text(camera):
    """The ``PINHOLE`` camera file of a rig camera without refraction (text)."""
    return "\n".join(_pinhole_lines(camera, "PINHOLE", _error_lines(None))) + "\n"


def polynomial_coefficients(model, length_m):
    """A Soloff model's terms as powers of the world's ``X, Y, Z`` in mm.

    Parameters
    ----------
    model : dict
        :meth:`rimcl.lpt.calibration.SoloffModel.describe` (``exponents_x2_x3_x1``,
        ``coefficients_u_v``, ``centre`` and ``half_width`` in field ``(x1, x2, x3)``).
    length_m : float

    Returns
    -------
    dict
        ``(a, b, c) -> (coefficient_u, coefficient_v)`` of ``X^a Y^b Z^c`` (X, Y, Z in mm).
    """
    scale = length_m * 1e3
    centre = np.asarray(model["centre"], dtype=np.float64)[list(XYZ_AXES)] * scale
    half = np.asarray(model["half_width"], dtype=np.float64)[list(XYZ_AXES)] * scale
    exponents = np.asarray(model["exponents_x2_x3_x1"], dtype=int)
    coefficients = np.asarray(model["coefficients_u_v"], dtype=np.float64)
    expanded = {}
    for powers, coefficient in zip(exponents, coefficients, strict=True):
        # ((X - c) / h)^p = Σ_i C(p, i) X^i (-c)^(p - i) / h^p, per axis
        per_axis = [
            [(i, comb(p, i) * (-centre[k]) ** (p - i) / half[k] ** p) for i in range(p + 1)]
            for k, p in enumerate(powers)
        ]
        for (i, fx), (j, fy), (k, fz) in (
            (x, y, z) for x in per_axis[0] for y in per_axis[1] for z in per_axis[2]
        ):
            key = (i, j, k)
            expanded[key] = expanded.get(key, 0.0) + coefficient * fx * fy * fz
    return expanded


def polynomial_text(model, length_m, image_size, z_planes_mm):
    """The ``POLYNOMIAL`` camera file of a Soloff fit (text).

    Parameters
    ----------
    model : dict
        The fit's :meth:`~rimcl.lpt.calibration.SoloffModel.describe`.
    length_m : float
    image_size : tuple of 2 int
        ``(n_row, n_col)``.
    z_planes_mm : tuple of 2 float
        The reference planes ``Z = const`` for OpenLPT's lines of sight (mm).
    """
    terms = sorted(polynomial_coefficients(model, length_m).items())
    lines = [
        "# Camera Model: (PINHOLE/POLYNOMIAL/PINPLATE)",
        "POLYNOMIAL",
        "# Camera Calibration Error: (rms reprojection of the target, px)",
        f"{_number(model['residual_px'])},0",
        "# Image Size: (n_row,n_col)",
        f"{image_size[0]},{image_size[1]}",
        "# Reference Plane: (REF_Z: lines of sight between Z = the two values, mm)",
        f"REF_Z,{_number(z_planes_mm[0])},{_number(z_planes_mm[1])}",
        "# Number of Coefficients:",
        str(len(terms)),
        "# U_Coeff,X_Power,Y_Power,Z_Power (column px; X, Y, Z = field x2, x3, x1 in mm)",
        *(f"{_number(c[0])},{a},{b},{e}" for (a, b, e), c in terms),
        "# V_Coeff,X_Power,Y_Power,Z_Power (row px)",
        *(f"{_number(c[1])},{a},{b},{e}" for (a, b, e), c in terms),
    ]
    return "\n".join(lines) + "\n"


def _write_text(path, text, overwrite):
    with atomic_path(path, overwrite) as tmp:
        tmp.write_text(text)


def write_camera_files(folder, cameras, calibrations, target, overwrite=True):
    """Every camera's OpenLPT files in ``folder``: ``<name>_openlpt_pinplate.txt`` (or
    ``<name>_openlpt_pinhole.txt`` without refraction) and ``<name>_openlpt_polynomial.txt``.

    Parameters
    ----------
    folder : pathlib.Path
    cameras : list of rimcl.lpt.rig.RigCamera
    calibrations : list of dict
        Per camera ``{"soloff": SoloffModel.describe(), ...}``.
    target : ndarray, shape (M, 3)
        The calibration target (field units): its depth range gives the polynomial's
        reference planes.
    overwrite : bool

    Returns
    -------
    dict
        Per camera name, ``{model name: file name}``, and ``"pinhole_model": None`` with a
        reason where the camera has none.
    """
    written = {}
    target_z = world_mm(target, cameras[0].length_m)[:, 2]
    planes = (float(target_z.min()), float(target_z.max()))
    for camera, calibration in zip(cameras, calibrations, strict=True):
        files = {}
        size = (camera.pixels[1], camera.pixels[0])
        name = f"{camera.name}_openlpt_polynomial.txt"
        _write_text(
            folder / name,
            polynomial_text(calibration["soloff"], camera.length_m, size, planes),
            overwrite,
        )
        files["POLYNOMIAL"] = name
        if camera.scheimpflug_deg != 0.0:
            files["pinhole_model"] = None
            files["note"] = "a Scheimpflug sensor has no OpenLPT pinhole model"
        elif refracts(camera):
            files["PINPLATE"] = f"{camera.name}_openlpt_pinplate.txt"
            _write_text(folder / files["PINPLATE"], pinplate_text(camera), overwrite)
        else:
            files["PINHOLE"] = f"{camera.name}_openlpt_pinhole.txt"
            _write_text(folder / files["PINHOLE"], pinhole_text(camera), overwrite)
        written[camera.name] = files
    return written
