"""Scene files of ``rimcl study``: TOML, every key documented, with defaults and checks.

A scene says what to measure: the field, the refractive-index cases, the tracers, the
camera, the renderer and the integrator. Every key is optional; :data:`SCENE_KEYS` lists
them with their defaults, and ``rimcl study --print-default-scene`` prints them as a
commented TOML file. Unknown sections and keys are refused with the closest valid name
suggested, so a misspelt key never silently falls back to its default.

The defaults are sized so that ``rimcl study`` on the shipped 64³ sample finishes in a few
minutes on a 2-core CPU with PoCL; the paper's own settings are given in the comments.
"""

import copy
import dataclasses
import difflib
import json
import math
import sys
import textwrap
from pathlib import Path

from rimcl.core.errors import RimclError

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover - Python 3.10
    import tomli as tomllib


@dataclasses.dataclass(frozen=True)
class SceneKey:
    """One key of a scene file.

    Attributes
    ----------
    section, name : str
        ``[section]`` and key name.
    default : object
        Value when the key is absent; ``None`` for keys whose default is decided by the
        pipeline (the printed scene shows them commented out, with ``example``).
    kind : {"str", "int", "float", "bool", "names", "thresholds", "box", "ints", "vector"}
        ``names``: a list of strings; ``thresholds``: a table of case name to number;
        ``box``: three ``[lo, hi]`` pairs; ``ints``: a list of whole numbers >= 1;
        ``vector``: three numbers.
    doc : str
        What the key means, with units.
    choices : tuple of str
        Allowed values of a ``str`` key (empty: any).
    minimum : float, optional
        Smallest allowed value of a number.
    positive : bool
        A number that must be strictly positive.
    example : object
        Value shown for a key whose default is ``None``.
    """

    section: str
    name: str
    default: object
    kind: str
    doc: str
    choices: tuple = ()
    minimum: float | None = None
    positive: bool = False
    example: object = None

    @property
    def dotted(self):
        return f"{self.section}.{self.name}"


def _choices():
    from rimcl.imaging.centroid import CENTROID_WEIGHTS
    from rimcl.imaging.frames import SCALINGS
    from rimcl.imaging.render import RENDERERS
    from rimcl.optics.camera import CAMERAS
    from rimcl.optics.trace import INTERPOLATIONS, PRECISIONS
    from rimcl.scene.config import ENGINES

    return {
        "camera": CAMERAS,
        "weights": CENTROID_WEIGHTS,
        "renderer": RENDERERS,
        "interp": INTERPOLATIONS,
        "precision": PRECISIONS,
        "scale": SCALINGS,
        "engine": ENGINES,
    }


def _keys():
    choice = _choices()
    return (
        SceneKey(
            "field",
            "path",
            "",
            "str",
            'rimcl field file with density and velocity; "" = the shipped 64³ sample',
        ),
        SceneKey(
            "field",
            "start_frame",
            0,
            "int",
            "stored frame of the first imaged frame (time t0)",
            minimum=0,
        ),
        SceneKey(
            "field",
            "x_sheet",
            None,
            "float",
            "light-sheet plane x1 (field length units); default: the grid's first x1",
            example=0.0,
        ),
        SceneKey(
            "field",
            "depth",
            None,
            "float",
            "traced depth L (field length units); default: the whole grid along x1",
            positive=True,
            example=3.0,
        ),
        SceneKey(
            "field",
            "box",
            None,
            "box",
            "measure in this box cut out of the field, [[x1lo, x1hi], [x2lo, x2hi], "
            "[x3lo, x3hi]] (field length units), clamped outside (the paper: a 512³ eighth)",
            example=[[0.0, 3.141592653589793]] * 3,
        ),
        SceneKey(
            "time",
            "frames",
            5,
            "int",
            "frames imaged, time.dt apart (3: the paper; more for fitted tracks)",
            positive=True,
        ),
        SceneKey(
            "time",
            "dt",
            None,
            "float",
            "time between imaged frames; default: the field's frame spacing (0.02 on the "
            "sample; the paper: 0.005); times between stored frames are interpolated",
            positive=True,
            example=0.04,
        ),
        SceneKey(
            "time",
            "fit_window",
            5,
            "int",
            "frames of the sliding polynomial fit of each track (odd; the fitted velocity "
            "and acceleration need at least as many frames)",
            minimum=3,
        ),
        SceneKey("time", "fit_order", 2, "int", "order of the fitted polynomial", minimum=2),
        SceneKey(
            "time",
            "dt_multiples",
            [1, 2],
            "ints",
            "the Δt sweep: the paper's differences also over every m-th imaged frame, for "
            "each m listed (Δt = m time.dt)",
        ),
        SceneKey(
            "cases",
            "names",
            ["C0", "C1", "C2", "C3", "C4"],
            "names",
            'Gladstone–Dale cases: C0..C4 (the paper; C1 air, C4 water) or "G=<value>"',
        ),
        SceneKey(
            "cases",
            "thresholds",
            {},
            "thresholds",
            "grey threshold per case (counts), overriding renderer.threshold "
            "(the paper: 100 for air, 500 for water)",
            example={"C4": 50.0},
        ),
        SceneKey(
            "tracers",
            "count",
            400,
            "int",
            "tracers in the sheet, uniform random (paper: 1e5)",
            positive=True,
        ),
        SceneKey(
            "tracers",
            "seed",
            0,
            "int",
            "seed of tracers and ray samples; the same for every case (common random numbers)",
            minimum=0,
        ),
        SceneKey(
            "tracers",
            "margin",
            0.05,
            "float",
            "edge band of the field of view kept free of tracers (fraction of its width)",
            minimum=0.0,
        ),
        SceneKey(
            "camera",
            "kind",
            "plane",
            "str",
            "plane: rays aimed at a fan x fan grid on the exit plane (the paper); "
            "pupil: rays over a circular aperture (field units); lens: a real camera in "
            "physical units (focal_length_mm, f_number, magnification, sensor, window; "
            "pupil_rays rays per tracer; needs field.length_m)",
            choices=choice["camera"],
        ),
        SceneKey(
            "camera",
            "fan",
            24,
            "int",
            "plane camera: aim points per side (paper: 100)",
            positive=True,
        ),
        SceneKey(
            "camera", "pupil_rays", 1024, "int", "pupil camera: rays per tracer", positive=True
        ),
        SceneKey(
            "camera",
            "aperture_diameter",
            None,
            "float",
            "pupil diameter (field length units); default: distance / 4",
            positive=True,
            example=3.0,
        ),
        SceneKey(
            "camera",
            "focal_length",
            None,
            "float",
            "with f_number instead of aperture_diameter: D = focal_length / f_number",
            positive=True,
            example=2.0,
        ),
        SceneKey(
            "camera", "f_number", None, "float", "see focal_length", positive=True, example=2.8
        ),
        SceneKey(
            "camera",
            "distance",
            None,
            "float",
            "sheet to pupil centre along the viewing axis (field length units); default: 4 L",
            positive=True,
            example=25.0,
        ),
        SceneKey(
            "camera", "view_angle", 0.0, "float", "viewing axis angle to x1, towards +x2 (degrees)"
        ),
        SceneKey(
            "renderer",
            "kind",
            "exact",
            "str",
            "exact: pixel-integrated Gaussian per ray; paper: nearest-pixel binning, "
            "then a Gaussian filter",
            choices=choice["renderer"],
        ),
        SceneKey(
            "renderer",
            "pixels",
            2048,
            "int",
            "pixels across the field of view (paper: 8192); finer pixels lower the "
            "rounding noise of the centroids, which dominates the errors of the weakest cases",
            positive=True,
        ),
        SceneKey(
            "renderer",
            "psf_sigma",
            None,
            "float",
            "Gaussian point-spread sigma (pixels); default 7 px (2.3 px gives the paper's "
            "~10 px tracer image; 7 px keeps water-like cases, whose rays spread over "
            "~1e-2 L, one blob above threshold), or a lens camera's own tracer image",
            positive=True,
            example=7.0,
        ),
        SceneKey(
            "renderer",
            "threshold",
            40.0,
            "float",
            "grey threshold in camera counts (10 bits: of 1023; the paper: 100 for air); "
            "the peak of a C4 tracer image falls to a few percent of the reference peak",
            minimum=0.0,
        ),
        SceneKey(
            "renderer",
            "centroid_weights",
            "excess",
            "str",
            "excess: grey value minus threshold (smooth); grey: the paper's grey value",
            choices=choice["weights"],
        ),
        SceneKey(
            "renderer",
            "bit_depth",
            10,
            "int",
            "bits per pixel of the camera, 8 to 16 (paper: 10); the rounding to counts moves "
            "centroids by a few 1e-4 pixel at 10 bits, a floor under the weakest cases' "
            "velocity errors (scale the threshold with the full scale 2**bits - 1)",
            positive=True,
        ),
        SceneKey(
            "renderer",
            "scale",
            "reference",
            "str",
            "reference: each measured image uses the scale of its tracer's reference image "
            "(comparable images); per_image: every image scaled to its own peak, as the "
            'paper "rescaled to a 10-bit dynamic range"',
            choices=choice["scale"],
        ),
        SceneKey(
            "renderer",
            "max_window",
            512,
            "int",
            "largest per-tracer image window side (pixels)",
            positive=True,
        ),
        SceneKey(
            "integrator",
            "interp",
            "trilinear",
            "str",
            "interpolation of the gridded field",
            choices=choice["interp"],
        ),
        SceneKey(
            "integrator",
            "precision",
            "f32c",
            "str",
            "accumulation: plain float32, compensated float32, float64",
            choices=choice["precision"],
        ),
        SceneKey(
            "integrator",
            "step",
            None,
            "float",
            "integration step in t = s/n (field length units); default: half a cell",
            positive=True,
            example=0.05,
        ),
        SceneKey(
            "field",
            "length_m",
            None,
            "float",
            "metres per field length unit (the field's physical size; the lens camera needs it)",
            positive=True,
            example=0.0106,
        ),
        SceneKey(
            "camera",
            "focal_length_mm",
            50.0,
            "float",
            "lens camera: focal length (mm); camera.f_number is its f-number (default 8)",
            positive=True,
        ),
        SceneKey(
            "camera",
            "magnification",
            None,
            "float",
            "lens camera: magnification M (or working_distance_mm)",
            positive=True,
            example=0.2,
        ),
        SceneKey(
            "camera",
            "working_distance_mm",
            None,
            "float",
            "lens camera: object distance from the lens to the (apparent) sheet (mm)",
            positive=True,
            example=300.0,
        ),
        SceneKey(
            "camera",
            "pixel_pitch_um",
            6.5,
            "float",
            "lens camera: sensor pixel pitch (µm)",
            positive=True,
        ),
        SceneKey(
            "camera",
            "sensor_pixels",
            [2048, 2048],
            "ints",
            "lens camera: sensor pixels along x2 and x3 (sets the image; renderer.pixels unused)",
        ),
        SceneKey(
            "camera",
            "wavelength_nm",
            532.0,
            "float",
            "lens camera: vacuum wavelength (nm)",
            positive=True,
        ),
        SceneKey(
            "camera",
            "particle_diameter_um",
            10.0,
            "float",
            "lens camera: tracer diameter (µm), for its geometric image",
            positive=True,
        ),
        SceneKey(
            "camera",
            "window_thickness_mm",
            0.0,
            "float",
            "lens camera: a flat window between fluid and lens (mm; 0: none)",
            minimum=0.0,
        ),
        SceneKey("camera", "window_index", 1.52, "float", "window glass index", positive=True),
        SceneKey(
            "camera", "outside_index", 1.0, "float", "index between window and lens", positive=True
        ),
        SceneKey(
            "sensor",
            "noise",
            False,
            "bool",
            "photon shot noise, read noise and background (false: the deterministic camera)",
        ),
        SceneKey(
            "sensor",
            "peak_electrons",
            10000.0,
            "float",
            "mean photoelectrons at the peak of a tracer's reference image",
            positive=True,
        ),
        SceneKey("sensor", "read_noise_e", 2.0, "float", "read noise (e- rms)", minimum=0.0),
        SceneKey("sensor", "background_e", 0.0, "float", "background per pixel (e-)", minimum=0.0),
        SceneKey("sensor", "full_well_e", 30000.0, "float", "full well (e-)", positive=True),
        SceneKey(
            "sensor",
            "gain_e_per_count",
            None,
            "float",
            "e- per count; default: full well / (2**bit_depth - 1)",
            positive=True,
            example=7.3,
        ),
        SceneKey(
            "sensor",
            "seed",
            None,
            "int",
            "seed of the noise draws; default tracers.seed",
            minimum=0,
            example=0,
        ),
        SceneKey(
            "mie", "enabled", False, "bool", "weight each ray by its Mie scattering intensity"
        ),
        SceneKey("mie", "diameter_um", 10.0, "float", "particle diameter (µm)", positive=True),
        SceneKey(
            "mie",
            "particle_index",
            1.59,
            "float",
            "particle index (1.59 polystyrene, 1.45 DEHS)",
            positive=True,
        ),
        SceneKey("mie", "particle_absorption", 0.0, "float", "imaginary part of it", minimum=0.0),
        SceneKey(
            "mie",
            "fluid_index",
            None,
            "float",
            "index around the particle; default: the [fluid]'s, else 1",
            positive=True,
            example=1.335,
        ),
        SceneKey("mie", "wavelength_nm", 532.0, "float", "vacuum wavelength (nm)", positive=True),
        SceneKey(
            "mie",
            "sheet_direction",
            [0.0, 1.0, 0.0],
            "vector",
            "propagation direction of the light sheet (x1, x2, x3)",
        ),
        SceneKey(
            "mie",
            "polarisation",
            "unpolarised",
            "str",
            "relative to each ray's scattering plane, or linear along polarisation_direction",
            choices=("unpolarised", "perpendicular", "parallel", "linear"),
        ),
        SceneKey(
            "mie",
            "polarisation_direction",
            [0.0, 0.0, 1.0],
            "vector",
            "the linear polarisation (perpendicular to the sheet direction)",
        ),
        SceneKey(
            "fluid",
            "kind",
            "",
            "str",
            'the fluid of dT=/dS= cases: water, air or saltwater ("": none)',
            choices=("", "water", "air", "saltwater"),
        ),
        SceneKey("fluid", "temperature_c", 20.0, "float", "base temperature (°C)"),
        SceneKey(
            "fluid", "salinity_g_kg", 0.0, "float", "base salinity (g/kg; saltwater)", minimum=0.0
        ),
        SceneKey("fluid", "pressure_pa", 101325.0, "float", "pressure (Pa; air)", positive=True),
        SceneKey(
            "fluid", "relative_humidity", 0.0, "float", "relative humidity 0..1 (air)", minimum=0.0
        ),
        SceneKey("fluid", "wavelength_nm", 532.0, "float", "vacuum wavelength (nm)", positive=True),
        SceneKey(
            "fluid",
            "light_density",
            1.0,
            "float",
            "the field's light fluid (dimensionless density): the warm or fresh one",
            positive=True,
        ),
        SceneKey(
            "fluid",
            "heavy_density",
            1.105,
            "float",
            "the field's heavy fluid: the cold or salty one",
            positive=True,
        ),
        SceneKey(
            "run",
            "device",
            "",
            "str",
            'OpenCL device (see "rimcl devices"); "" = $RIMCL_DEVICE, then a GPU, then a CPU',
        ),
        SceneKey(
            "run",
            "engine",
            "device",
            "str",
            "where tracer images are rendered and located: device (rays, images and "
            "centroids on the OpenCL device; needs fp64) or numpy (the readable reference "
            "engine, tracer by tracer)",
            choices=choice["engine"],
        ),
        SceneKey(
            "run",
            "numerics",
            True,
            "bool",
            "with the figures, the paper's Appendix A check: one case (C1) at half the step "
            "and on every second grid node, its |ε_x| PDFs in figures/numerics.png",
        ),
        SceneKey(
            "run",
            "ray_sample",
            20000,
            "int",
            "first-frame rays kept per case for the ray diagnostics",
            minimum=0,
        ),
        SceneKey(
            "run",
            "rays_per_batch",
            131072,
            "int",
            "rays traced per batch (bounds the memory)",
            positive=True,
        ),
        SceneKey(
            "run",
            "mode",
            "ptv",
            "str",
            "ptv: tracer tracks; piv: cross-correlation of full frames ([piv]); both: each "
            "case both ways, compared in summary.md",
            choices=("ptv", "piv", "both"),
        ),
        SceneKey(
            "run",
            "scheduler",
            "",
            "str",
            'Dask scheduler measuring the cases: "" = this process; "local:N" = N worker '
            'processes here; "tcp://HOST:PORT" = a running scheduler (rimcl[distributed])',
        ),
        SceneKey(
            "run",
            "shard_tracers",
            100,
            "int",
            "tracers per Dask task (one case, one shard of tracers) with run.scheduler; "
            "the results do not depend on it",
            positive=True,
        ),
        *_piv_keys(),
    )


def _piv_keys():
    """The ``[piv]`` section (:mod:`rimcl.piv.render`, :mod:`rimcl.piv.analysis`).

    Frames, light sheet and correlation.
    """
    return (
        SceneKey(
            "piv",
            "pixels",
            512,
            "int",
            "pixels across the field of view of the PIV frames (a lens camera: its sensor)",
            positive=True,
        ),
        SceneKey(
            "piv",
            "density",
            0.03,
            "float",
            "particle image density: tracers per pixel inside the sheet's 1/e² thickness",
            positive=True,
        ),
        SceneKey(
            "piv",
            "diameter",
            3.0,
            "float",
            "particle image diameter d = 4 σ (pixels; a lens camera: its own tracer image)",
            positive=True,
        ),
        SceneKey(
            "piv",
            "sheet_thickness",
            None,
            "float",
            "light-sheet thickness between the 1/e² points of its Gaussian profile along x1 "
            "(field length units); default 8 pixels",
            positive=True,
            example=0.1,
        ),
        SceneKey("piv", "bit_depth", 16, "int", "bits per pixel of the PIV frames", positive=True),
        SceneKey(
            "piv",
            "rays",
            64,
            "int",
            "rays per tracer of the PIV frames, with the camera's kind and optics (a plane "
            "camera: a fan of round(sqrt(rays)) per side)",
            positive=True,
        ),
        SceneKey(
            "piv",
            "dt",
            0.1,
            "float",
            "time between exposures A and B; 0.1 on the sample moves tracers 1.5 px rms, "
            "up to 4.5 px, at 512 px",
            positive=True,
        ),
        SceneKey(
            "piv",
            "window",
            32,
            "int",
            "interrogation window of the last pass (px, even)",
            positive=True,
        ),
        SceneKey("piv", "overlap", 0.5, "float", "overlap of neighbouring windows", minimum=0.0),
        SceneKey(
            "piv",
            "passes",
            3,
            "int",
            "correlation passes (2 and more deform the windows)",
            positive=True,
        ),
    )


#: Every key of a scene file, in the order of the printed default scene.
SCENE_KEYS = _keys()
SECTIONS = tuple(dict.fromkeys(key.section for key in SCENE_KEYS))
_BY_NAME = {key.dotted: key for key in SCENE_KEYS}


def default_scene():
    """The scene with every key at its default.

    Returns
    -------
    dict of str to dict
        ``{section: {key: value}}``; ``None`` where the pipeline decides.
    """
    scene = {section: {} for section in SECTIONS}
    for key in SCENE_KEYS:
        scene[key.section][key.name] = copy.deepcopy(key.default)
    return scene


def _toml_value(value):
    """TOML text of a scene value, inline (arrays and tables on one line)."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, str):
        return json.dumps(value, ensure_ascii=False)  # a valid TOML basic string
    if isinstance(value, float):
        return repr(value) if math.isfinite(value) else str(value)
    if isinstance(value, int):
        return str(value)
    if isinstance(value, list):
        return "[" + ", ".join(_toml_value(item) for item in value) + "]"
    if isinstance(value, dict):
        items = ", ".join(f"{json.dumps(k)} = {_toml_value(v)}" for k, v in value.items())
        return "{ " + items + " }" if items else "{}"
    raise TypeError(f"no TOML form for {value!r}")


def default_scene_text():
    """The default scene as a commented TOML file: every key, its meaning and default.

    Returns
    -------
    str
    """
    lines = [
        "# rimcl study scene. Every key is optional: a missing key takes the value shown.",
        "# Lengths are in field length units (the field file's grid), angles in degrees.",
        "# Keys commented out default to what the pipeline decides (see their comment).",
    ]
    for section in SECTIONS:
        lines += ["", f"[{section}]"]
        for key in (k for k in SCENE_KEYS if k.section == section):
            note = f" (one of: {', '.join(key.choices)})" if key.choices else ""
            lines += textwrap.wrap(
                key.doc + note, width=88, initial_indent="# ", subsequent_indent="#   "
            )
            if key.default is None or key.default == {}:
                lines.append(f"# {key.name} = {_toml_value(key.example)}")
            else:
                lines.append(f"{key.name} = {_toml_value(key.default)}")
    return "\n".join(lines) + "\n"


def _suggest(word, candidates):
    close = difflib.get_close_matches(word, list(candidates), n=1, cutoff=0.5)
    return f"; did you mean {close[0]!r}?" if close else ""


def _check_value(key, value, where):
    """The value of ``key`` converted and checked; raises RimclError naming ``where``."""
    name = f"{key.dotted} in {where}"
    if key.kind == "names":
        if not isinstance(value, list) or not all(isinstance(v, str) for v in value):
            raise RimclError(f"{name} must be a list of case names, got {value!r}")
        if not value:
            raise RimclError(f"{name} must name at least one case")
        return _check_cases(value, name)
    if key.kind == "thresholds":
        if not isinstance(value, dict):
            raise RimclError(f"{name} must be a table of case name = threshold, got {value!r}")
        return {
            _check_cases([case], name)[0]: _check_number(
                dataclasses.replace(key, kind="float", minimum=0.0), count, name
            )
            for case, count in value.items()
        }
    if key.kind == "str":
        if not isinstance(value, str):
            raise RimclError(f"{name} must be a string, got {value!r}")
        if key.choices and value not in key.choices:
            raise RimclError(
                f"{name} must be one of {', '.join(key.choices)}, got {value!r}"
                + _suggest(value, key.choices)
            )
        return value
    if key.kind == "ints":
        if (
            not isinstance(value, list)
            or not value
            or not all(isinstance(v, int) and not isinstance(v, bool) and v >= 1 for v in value)
        ):
            raise RimclError(f"{name} must be a list of whole numbers >= 1, got {value!r}")
        return [int(v) for v in value]
    if key.kind == "vector":
        if not (
            isinstance(value, list)
            and len(value) == 3
            and all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in value)
        ):
            raise RimclError(f"{name} must be three numbers [x1, x2, x3], got {value!r}")
        return [float(v) for v in value]
    if key.kind == "box":
        pairs_ok = isinstance(value, list) and len(value) == 3
        pairs_ok = pairs_ok and all(isinstance(p, list) and len(p) == 2 for p in value)
        if not pairs_ok or not all(
            isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)
            for pair in value
            for v in pair
        ):
            raise RimclError(
                f"{name} must be three [lo, hi] pairs of numbers (x1, x2, x3), got {value!r}"
            )
        if any(lo >= hi for lo, hi in value):
            raise RimclError(f"{name} needs lo < hi along every axis, got {value!r}")
        return [[float(lo), float(hi)] for lo, hi in value]
    if key.kind == "bool":
        if not isinstance(value, bool):
            raise RimclError(f"{name} must be true or false, got {value!r}")
        return value
    return _check_number(key, value, name)


def _check_number(key, value, name):
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise RimclError(f"{name} must be a number, got {value!r}")
    if key.kind == "int":
        if isinstance(value, float) and not value.is_integer():
            raise RimclError(f"{name} must be a whole number, got {value!r}")
        value = int(value)
    else:
        value = float(value)
        if not math.isfinite(value):
            raise RimclError(f"{name} must be finite, got {value!r}")
    if key.positive and not value > 0:
        raise RimclError(f"{name} must be positive, got {value!r}")
    if key.minimum is not None and value < key.minimum:
        raise RimclError(f"{name} must be at least {key.minimum}, got {value!r}")
    return value


def _check_cases(names, where):
    from rimcl.fields.cases import CASES, fluid_case, resolve_k_rho

    resolved = []
    for case in names:
        try:
            if fluid_case(case) is not None:
                resolved.append(case.strip())
                continue
            resolved.append(resolve_k_rho(case=case)[0])
        except RimclError as exc:
            raise RimclError(f"{where}: {exc}{_suggest(case.upper(), CASES)}") from None
    duplicates = sorted({name for name in resolved if resolved.count(name) > 1})
    if duplicates:
        raise RimclError(f"{where} names case {', '.join(duplicates)} more than once")
    return resolved


def validate_scene(raw, where="the scene"):
    """Check a scene mapping and fill in the defaults.

    Parameters
    ----------
    raw : dict
        ``{section: {key: value}}`` as read from TOML (missing keys allowed).
    where : str
        Named in error messages (a file name).

    Returns
    -------
    dict
        The complete scene, every key present (``None`` for pipeline defaults).

    Raises
    ------
    RimclError
        For an unknown section or key (with the closest valid name), a value of the wrong
        type, out of range, or not among the choices.
    """
    scene = default_scene()
    for section, table in raw.items():
        if section not in scene:
            raise RimclError(
                f"unknown section [{section}] in {where}" + _suggest(section, SECTIONS)
            )
        if not isinstance(table, dict):
            raise RimclError(f"[{section}] in {where} must be a table of keys")
        for name, value in table.items():
            key = _BY_NAME.get(f"{section}.{name}")
            if key is None:
                elsewhere = [k.dotted for k in SCENE_KEYS if k.name == name]
                hint = (
                    f"; did you mean {elsewhere[0]!r}?"
                    if elsewhere
                    else _suggest(name, [k.name for k in SCENE_KEYS if k.section == section])
                )
                raise RimclError(f"unknown key {section}.{name} in {where}{hint}")
            scene[section][name] = _check_value(key, value, where)
    from rimcl.fields.cases import fluid_case

    fluid_cases = [c for c in scene["cases"]["names"] if fluid_case(c) is not None]
    if fluid_cases and not scene["fluid"]["kind"]:
        raise RimclError(
            f"cases {', '.join(fluid_cases)} in {where} need a fluid: set [fluid] kind "
            "(water, air or saltwater)"
        )
    unknown = set(scene["cases"]["thresholds"]) - set(scene["cases"]["names"])
    if unknown:
        raise RimclError(
            f"cases.thresholds in {where} names {', '.join(sorted(unknown))}, "
            "which cases.names does not run"
        )
    return scene


#: Named scenes (``rimcl study --preset NAME``): keys that differ from the defaults.
PRESETS = {
    # The paper's own setting (its §3.2): the 100 x 100 fan, nearest-pixel binning then a
    # Gaussian filter, 8192 px over the traced box, a ~10 px tracer image (σ 2.3 px at a
    # threshold of 100 of 1023), thresholds 100 (air-like) and 500 (water-like), every
    # image rescaled to its own 10-bit range, on a π³ clamped eighth of the 2π sample
    # (the paper traced a 512³ eighth of the 1024³ box).
    "paper": {
        "field": {"box": [[0.0, math.pi], [0.0, math.pi], [0.0, math.pi]]},
        "cases": {"thresholds": {"C0": 100.0, "C1": 100.0, "C2": 100.0, "C3": 500.0, "C4": 500.0}},
        "camera": {"kind": "plane", "fan": 100},
        "renderer": {
            "kind": "paper",
            "pixels": 8192,
            "psf_sigma": 2.3,
            "threshold": 100.0,
            "centroid_weights": "grey",
            "scale": "per_image",
        },
    },
}


def load_scene(path=None, overrides=None, preset=None):
    """Read a scene file (or the defaults), apply overrides, check everything.

    Parameters
    ----------
    path : str or Path, optional
        A TOML scene file; the default scene when omitted.
    overrides : dict, optional
        ``{"section.key": value}`` applied on top (command-line options); ``None`` values
        are ignored.
    preset : str, optional
        A name of :data:`PRESETS`, applied under the file's keys.

    Returns
    -------
    dict
        The complete, checked scene (see :func:`validate_scene`).
    """
    raw = {}
    where = "the default scene"
    if preset is not None:
        if preset not in PRESETS:
            raise RimclError(f"unknown preset {preset!r}; choose from {', '.join(PRESETS)}")
        raw = copy.deepcopy(PRESETS[preset])
        where = f"the {preset} preset"
    if path is not None:
        path = Path(path)
        where = str(path)
        try:
            text = path.read_text(encoding="utf-8")
        except OSError as exc:
            raise RimclError(f"cannot read scene file {path}: {exc.strerror}") from None
        except UnicodeDecodeError:
            raise RimclError(
                f"scene file {path} is not text (a TOML scene is UTF-8 text)"
            ) from None
        try:
            from_file = tomllib.loads(text)
        except tomllib.TOMLDecodeError as exc:
            raise RimclError(f"{path} is not valid TOML: {exc}") from None
        for section, table in from_file.items():
            if isinstance(table, dict) and isinstance(raw.get(section), dict):
                raw[section] = {**raw[section], **table}
            else:
                raw[section] = table
        field_path = (
            raw.get("field", {}).get("path") if isinstance(raw.get("field"), dict) else None
        )
        if isinstance(field_path, str) and field_path and not Path(field_path).is_absolute():
            # a scene names its field relative to itself, wherever it is run from
            raw["field"]["path"] = str((path.parent / field_path).resolve())
    for dotted, value in (overrides or {}).items():
        if value is None:
            continue
        section, name = dotted.split(".", 1)
        raw.setdefault(section, {})[name] = value
    if preset is not None:
        # the preset's thresholds cover every paper case; keep those of the cases run
        names = raw.get("cases", {}).get("names", default_scene()["cases"]["names"])
        preset_thresholds = PRESETS[preset].get("cases", {}).get("thresholds", {})
        thresholds = raw.get("cases", {}).get("thresholds", {})
        for case in set(preset_thresholds) - set(names):
            if thresholds.get(case) == preset_thresholds[case]:
                del thresholds[case]
    return validate_scene(raw, where)


def scene_text(scene):
    """A complete scene as TOML (keys left to the pipeline are omitted).

    Parameters
    ----------
    scene : dict
        As returned by :func:`load_scene`.

    Returns
    -------
    str
        Readable again by :func:`load_scene`.
    """
    lines = ["# the scene of this study; run it again with: rimcl study scene.toml --out DIR"]
    for section, table in scene.items():
        lines += ["", f"[{section}]"]
        lines += [f"{name} = {_toml_value(v)}" for name, v in table.items() if v is not None]
    return "\n".join(lines) + "\n"
