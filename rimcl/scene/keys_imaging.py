"""Scene keys of the measurement geometry and imaging.

The sections ``[field]``, ``[time]``, ``[cases]``, ``[tracers]``, ``[camera]`` (pinhole and
lens cameras), ``[renderer]`` and ``[integrator]``, in the order of the printed default
scene.
"""

from rimcl.scene.key import SceneKey, choices


def imaging_keys():
    """The keys of the field, time, cases, tracers, camera, renderer and integrator."""
    choice = choices()
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
            "frames imaged, time.dt apart (3: the paper, the fewest an acceleration needs; "
            "more for fitted tracks)",
            minimum=3,
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
            "frames of the sliding polynomial fit of each track (odd, at most time.frames; "
            "unset and more than the frames: the largest odd number of frames there are)",
            minimum=3,
        ),
        SceneKey("time", "fit_order", 2, "int", "order of the fitted polynomial", minimum=2),
        SceneKey(
            "time",
            "dt_multiples",
            None,
            "ints",
            "the Δt sweep: the paper's differences also over every m-th imaged frame, for "
            "each m listed (Δt = m time.dt); default: every m from 1 to time.frames - 1 "
            "(5 frames: Δt, 2Δt, 3Δt, 4Δt; accelerations where 2m + 1 frames fit)",
            example=[1, 2],
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
            "lens",
            "str",
            "lens (the default): a real PTV camera in physical units (50 mm f/11 at M = 0.2: "
            "NA 0.0076, tracer images 2.65 px) behind the tank's wall (focal_length_mm, "
            "f_number, magnification, sensor, window; pupil_rays rays per tracer; needs "
            "field.length_m); plane: rays aimed at a fan x fan grid on the exit plane (the "
            "paper's, NA ~0.8: --preset paper); pupil: rays over a circular aperture (field units)",
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
            "camera",
            "pupil_rays",
            256,
            "int",
            "pupil and lens camera: rays per tracer (a narrow lens cone needs few; the "
            "sensitivity check repeats the study with 4 times as many)",
            positive=True,
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
            "camera",
            "f_number",
            None,
            "float",
            "see focal_length (>= 0.5: the limit of a lens in air)",
            minimum=0.5,
            example=2.8,
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
            20.0,
            "float",
            "grey threshold in camera counts (12 bits: of 4095). 20 sits just above the default "
            "sensor's noise floor (background 20 e- = 2.7 counts, noise 0.7 counts: 25 sigma "
            "above) and keeps whole tracer images: 1.5 % of the reference peak of 10000 e- = "
            "1365 counts (the paper: 100 of 1023 for air, 500 for water)",
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
            12,
            "int",
            "bits per pixel of the camera, 8 to 16 (a 12-bit sCMOS; paper: 10); the rounding "
            "to counts moves centroids by a few 1e-4 pixel at 10 bits, a floor under the "
            "weakest cases' velocity errors (scale the threshold with the full scale 2**bits - 1)",
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
            "split",
            "exclude",
            "str",
            "a tracer image split in several components, or whose rays spread past "
            "max_window: exclude it from the statistics (flagged), or brightest: locate its "
            "brightest component as a detection over the whole frame does (the paper's; "
            "noted, counted)",
            choices=choice["split"],
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
            "metres per field length unit (the field's physical size; the lens camera needs "
            "it); default: the field file's length_m, 0.0106 for the shipped sample (a 66.6 mm "
            "cube: 2048 px of 6.5 µm at M = 0.2 across its 2π)",
            positive=True,
            example=0.0106,
        ),
        SceneKey(
            "field",
            "time_s",
            None,
            "float",
            "seconds per field time unit (outputs in ms, mm/s, m/s²); default: the field "
            "file's time_s, or field.length_m / field.velocity_m_s",
            positive=True,
            example=0.3,
        ),
        SceneKey(
            "field",
            "velocity_m_s",
            None,
            "float",
            "metres per second of one field velocity unit: another way to give field.time_s",
            positive=True,
            example=0.035,
        ),
        SceneKey(
            "camera",
            "focal_length_mm",
            50.0,
            "float",
            "lens camera: focal length (mm); camera.f_number is its f-number (default 11)",
            positive=True,
        ),
        SceneKey(
            "camera",
            "magnification",
            None,
            "float",
            "lens camera: magnification M (or working_distance_mm); default 0.2",
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
            10.0,
            "float",
            "lens camera: the flat wall between fluid and lens (mm; 0: the bare fluid/air "
            "interface, which refracts as well)",
            minimum=0.0,
        ),
        SceneKey("camera", "window_index", 1.52, "float", "window glass index", minimum=1.0),
        SceneKey(
            "camera", "outside_index", 1.0, "float", "index between window and lens", minimum=1.0
        ),
    )
