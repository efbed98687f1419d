"""Scene keys of 3-D particle tracking (``run.mode = "lpt"``, ``rimcl lpt``).

The sections ``[rig]`` (the cameras and their window), ``[illumination]`` (the seeded
volume) and ``[lpt]`` (rays, images, calibration, self-calibration, matching), and the keys
of each ``[[rig.cameras]]`` table: the one table of their names, defaults, meanings and
limits. :mod:`rimcl.scene.lpt_config` parses them (the camera tables and the combinations
that no single key can check).
"""

from rimcl.scene.key import SceneKey

#: The preset a scene without ``[[rig.cameras]]`` tables runs.
DEFAULT_PRESET = "lpt-challenge"
#: Section name of the camera tables' keys (``[[rig.cameras]]``).
CAMERA_SECTION = "rig.cameras"


def camera_keys():
    """The keys of each ``[[rig.cameras]]`` table (mm, µm; the field's frame)."""
    return (
        SceneKey(CAMERA_SECTION, "name", "", "str", 'camera name ("": cam1, cam2, ...)'),
        SceneKey(
            CAMERA_SECTION,
            "position_mm",
            None,
            "vector",
            "pupil centre (mm in the field's frame, from its origin; required)",
            example=[640.0, 50.0, 50.0],
        ),
        SceneKey(
            CAMERA_SECTION,
            "look_at_mm",
            None,
            "vector",
            "the point imaged to the sensor centre (mm; required)",
            example=[50.0, 50.0, 50.0],
        ),
        SceneKey(CAMERA_SECTION, "focal_length_mm", 100.0, "float", "mm", positive=True),
        SceneKey(CAMERA_SECTION, "f_number", 16.0, "float", "f-number", positive=True),
        SceneKey(CAMERA_SECTION, "pixel_pitch_um", 10.0, "float", "µm", positive=True),
        SceneKey(CAMERA_SECTION, "sensor_pixels", [1920, 1200], "ints", "columns, rows"),
        SceneKey(CAMERA_SECTION, "scheimpflug_deg", 0.0, "float", "sensor tilt (degrees)"),
    )


def _camera_table_doc():
    described = ", ".join(
        f"{key.name} ({'required' if key.default is None else repr(key.default)})"
        for key in camera_keys()
    )
    return f"[[rig.cameras]] tables, mm in the field's frame: {described}"


def lpt_keys():
    """The keys of the ``[rig]``, ``[illumination]`` and ``[lpt]`` sections."""
    return (
        SceneKey(
            "rig",
            "preset",
            None,
            "str",
            "lpt-challenge: four cameras at -30, -10, +10, +30 degrees from x1 in the x1-x2 "
            "plane (1920 x 1200 px of 10 µm, f = 100 mm, f/16), placed so the field's x2 width "
            'fills 96 % of the sensor; stereo: the +-30 degree pair; "": the [[rig.cameras]] '
            f"tables; default {DEFAULT_PRESET}, or the tables where there are some",
            choices=(DEFAULT_PRESET, "stereo", ""),
            example=DEFAULT_PRESET,
        ),
        SceneKey("rig", "cameras", [], "tables", _camera_table_doc()),
        SceneKey(
            "rig",
            "window_thickness_mm",
            10.0,
            "float",
            "the window on the exit face every camera looks through (mm; 0: a bare surface)",
            minimum=0.0,
        ),
        SceneKey("rig", "window_index", 1.52, "float", "window glass index", positive=True),
        SceneKey(
            "rig", "outside_index", 1.0, "float", "index between window and lenses", positive=True
        ),
        SceneKey(
            "rig",
            "wavelength_nm",
            532.0,
            "float",
            "light wavelength (nm), for the images",
            positive=True,
        ),
        SceneKey(
            "rig",
            "particle_diameter_um",
            10.0,
            "float",
            "tracer diameter (µm), for the geometric image",
            minimum=0.0,
        ),
        SceneKey(
            "illumination",
            "thickness",
            None,
            "float",
            "seeded slab along x1 (field length units); default 0.3 of the field's x2 width",
            positive=True,
            example=0.3,
        ),
        SceneKey(
            "illumination",
            "centre",
            None,
            "float",
            "slab centre along x1 (field length units); default the field's middle",
            example=0.5,
        ),
        SceneKey(
            "illumination",
            "extent",
            [0.8, 0.5],
            "floats",
            "seeded fractions of the field's x2 and x3 widths, centred",
        ),
        SceneKey(
            "illumination",
            "ppp",
            None,
            "float",
            "tracers per pixel of the first camera (instead of tracers.count)",
            positive=True,
            example=0.01,
        ),
        SceneKey(
            "lpt",
            "ray_tolerance_px",
            0.01,
            "float",
            "rays per tracer: the fewest whose located centroid moves less than this (px)",
            positive=True,
        ),
        SceneKey("lpt", "max_rays", 128, "int", "most rays per tracer", positive=True),
        SceneKey("lpt", "calibration_planes", 5, "int", "target planes (x1 = const)", minimum=3),
        SceneKey(
            "lpt", "calibration_grid", [13, 9], "ints", "target points per plane along x2, x3"
        ),
        SceneKey(
            "lpt",
            "model",
            "soloff",
            "str",
            "camera model of the triangulation: Soloff polynomial or pinhole (DLT)",
            choices=("soloff", "pinhole"),
        ),
        SceneKey(
            "lpt",
            "engine",
            "device",
            "str",
            "ray tracing: device (OpenCL) or numpy (float64 reference; slow)",
            choices=("device", "numpy"),
        ),
        SceneKey(
            "lpt",
            "match_tolerances_px",
            [0.5, 1.0, 2.0],
            "floats",
            "disparities (px) above which an LPT code loses the match",
        ),
        SceneKey("lpt", "images", True, "bool", "rimcl lpt render: write the TIFF frames"),
        SceneKey("lpt", "bit_depth", 16, "int", "the cameras' ADC bits (8 to 16)", minimum=8),
        SceneKey(
            "lpt",
            "exposure",
            0.5,
            "float",
            "peak of the brightest camera's median tracer, fraction of the sensor's level",
            positive=True,
        ),
        SceneKey(
            "lpt",
            "threshold",
            0.05,
            "float",
            "each camera's grey threshold, fraction of its median tracer's peak",
            positive=True,
        ),
        SceneKey(
            "lpt",
            "self_calibration",
            True,
            "bool",
            "volume self-calibration on the measured images (Soloff model)",
        ),
        SceneKey(
            "lpt",
            "self_calibration_cells",
            [3, 5, 5],
            "ints",
            "its sub-volumes along x1, x2, x3",
        ),
        SceneKey(
            "lpt",
            "self_calibration_iterations",
            3,
            "int",
            "its rounds of triangulation and correction",
            positive=True,
        ),
    )
