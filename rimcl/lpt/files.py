"""LPT output files: the case file, and datasets for LPT codes (OpenLPT, MyPTV, DaVis).

**Case file** ``lpt_case_<case>.h5`` (``rimcl_schema = "lpt_case"``, ``schema_version = 2``),
with named dimensions (HDF5 dimension scales) and a ``units`` attribute on every dataset, so that
``xarray.open_dataset(path, group="tracks", engine="h5netcdf")`` gives ``(id, frame)`` arrays:

- root attributes: ``case``, ``n_ref``, ``length_m``, ``time_s`` (where the scene gives a
  time scale), ``units`` (JSON), ``config`` and ``versions`` (JSON);
- ``tracks/``: scales ``id (N,)`` and ``frame (F,)``; ``time (frame)``, ``flags (id)`` (1: a
  ray failed, 2: an image off a sensor, 4: an image not located), and per tracer and frame
  ``(id, frame)`` float64: ``x{1,2,3}_{true,meas,ref}``, ``x{1,2,3}_opt_{meas,ref}``,
  ``x{1,2,3}_floor`` (the reference exposed again with independent noise draws: the noise
  floor) (``L0``, field length units), ``u{1,2,3}_true`` (``L0/T0``), ``a{1,2,3}_true``
  (``L0/T0^2``); each with ``si_per_unit`` (metres, m/s, m/s², seconds per unit) where the
  scales are known (``L0`` always, the others with ``time_s``); at the threshold ×½ and ×2
  (``<s>`` = ``threshold_half``, ``threshold_double``: every image located again at that
  threshold, triangulated on the same models) ``x{1,2,3}_{meas,ref}_<s>``;
- ``cameras/<name>/``: scales ``id``, ``frame``, ``pixel_axis`` (``column``, ``row``);
  ``centroid_{meas,ref}``, ``optics_{meas,ref}`` ``(id, frame, pixel_axis)`` (px, pixel
  (0, 0) centred on the top-left pixel), ``disparity_*`` ``(id, frame)`` (px),
  ``image_flags_*``, ``peak_*``, ``failed_rays`` ``(id, frame)``; at the variant thresholds
  ``centroid_{meas,ref}_<s>`` and ``image_flags_{meas,ref}_<s>``; attributes ``parameters``
  (JSON: position, look-at, axes, optics), ``calibration`` (JSON: both fits and their
  residuals, px) and ``rays`` (JSON: the ray-count choice);
- ``calibration/``: scales ``point``, ``axis`` (``x1, x2, x3``), ``camera``, ``pixel_axis``;
  ``target (point, axis)`` (field units) and ``pixels (camera, point, pixel_axis)`` (px).

**Dataset** (``rimcl lpt render``), in ``<out>/dataset/<case>/``:

- ``images/field/cam<k>_frame<ffff>.tif`` and ``images/uniform/…``: TIFF per camera and
  frame through the field and through the uniform fluid: what the sensor records
  (:func:`rimcl.lpt.frames.recorded_frame`: every tracer's light added, background and
  noise on every pixel, digitised once);
- ``calibration_points.txt``: the first LPT challenge's layout, one target point a row,
  ``X Y Z x1 y1 … xC yC`` (mm, px), with ``X, Y, Z = x2, x3, x1`` from the field's origin,
  only the points every camera sees on its sensor (the header names the cameras);
- ``cam<k>_pinhole.json``: the fitted DLT matrix (maps ``[X, Y, Z, 1]`` in mm to pixels),
  its residual, and the true camera parameters;
- OpenLPT camera files (:mod:`rimcl.lpt.openlpt_files`): ``<cam>_openlpt_pinplate.txt``
  (or ``_pinhole.txt`` where nothing refracts) and ``<cam>_openlpt_polynomial.txt``;
- ``openlpt_dataset.json``: the manifest of :mod:`rimcl.lpt.openlpt_track` (frames, frame
  spacing, view volume and voxel in mm, per camera its frames, camera files, full scale,
  threshold, PSF σ, object-space pixel, calibration residuals; ``in_view``);
- ``truth_tracks.csv``: ``track_id, frame, time, X_mm, Y_mm, Z_mm, u, v, w, ax, ay, az``
  (time in field time units; with ``time_s`` velocity in m/s and acceleration in m/s²,
  without it in m per field time unit and m per field time unit squared; the header says
  which); ``truth_tracks.h5``: the same as ``(id, frame, axis)`` datasets ``position_mm``,
  ``velocity``, ``acceleration`` with named dimensions and ``units`` (``m/s``, ``m/s^2``;
  else ``m/T0``, ``m/T0^2``), and ``time (frame)`` (``T0``, with ``si_per_unit`` seconds
  where known); root attribute ``time_s``.
"""

import json

import h5py
import numpy as np

from rimcl.core.atomic import atomic_path
from rimcl.core.fingerprint import fingerprint
from rimcl.core.outputs import OutputSet
from rimcl.core.provenance import stamp_h5, to_json
from rimcl.core.tables_h5 import (
    TRACER_DIMENSIONS,
    add_scale,
    mark_si,
    si_per_unit,
    write_variable,
)
from rimcl.lpt.openlpt_track import MANIFEST
from rimcl.stats.render_file import THRESHOLD_SUFFIXES
from rimcl.stats.tables import write_json

SCHEMA = "lpt_case"
#: 2: named (id, frame) dimensions, tracks stored (N, F) (1: (F, N) without dimensions)
SCHEMA_VERSION = 2
#: The two axes of a pixel position.
PIXEL_AXES = ["column", "row"]
#: Field axes of the LPT challenge's X, Y, Z (X along x2, Y along x3, Z = depth x1).
XYZ_AXES = (1, 2, 0)


def _units(run):
    names = {"L0": "m", "T0": "s", "L0/T0": "m/s", "L0/T0^2": "m/s^2"}
    each = {
        unit: f" ({value:g} {names[unit]} each)"
        for unit, value in si_per_unit(run.length_m, run.time_s).items()
    }
    return {
        "positions": "field length units" + each["L0"],
        "velocity": "field length / field time units" + each.get("L0/T0", ""),
        "acceleration": "field length / field time units squared" + each.get("L0/T0^2", ""),
        "centroids": "pixels (column, row); pixel (0, 0) centred on the top-left pixel",
        "disparity": "pixels",
        "time": "field time units" + each.get("T0", ""),
    }


#: The files ``rimcl lpt run`` and ``rimcl lpt render`` write in their output folder (an
#: earlier run's are replaced as a set, :class:`rimcl.core.outputs.OutputSet`).
OWNED = ("lpt_stats.json", "lpt_case_*.h5", "dataset/**/*")


def open_outputs(out_dir, scene, overwrite=False):
    """The output set of an LPT run in ``out_dir``: an earlier run's files are refused
    before any work (unless ``overwrite``) and replaced, as a set, only when the whole run
    succeeded; the field file may not be an output."""
    return OutputSet(
        out_dir, overwrite=overwrite, owned=OWNED, inputs=[scene.study.field_path or None]
    )


def lpt_inputs(field_path):
    """The fingerprints of the files an LPT run reads (``{"field file": ...}``; the built-in
    flow, made by rimcl itself: ``"built-in"``), recorded in ``lpt_stats.json``."""
    return {"field file": fingerprint(field_path) if field_path else "built-in"}


def write_case(path, run, result, scene, overwrite=True):
    """Write one case's per-tracer results (layout in the module docstring)."""
    from rimcl.lpt.config import describe

    with atomic_path(path, overwrite) as tmp, h5py.File(tmp, "w") as h5:
        h5.attrs["rimcl_schema"] = SCHEMA
        h5.attrs["schema_version"] = SCHEMA_VERSION
        h5.attrs["case"] = result["case"]
        h5.attrs["n_ref"] = result["n_ref"]
        h5.attrs["length_m"] = run.length_m
        if run.time_s is not None:
            h5.attrs["time_s"] = run.time_s
        h5.attrs["units"] = json.dumps(_units(run))
        stamp_h5(h5, {**describe(scene), "study_scene": scene.study.scene_record()})
        frames, count = run.true.shape[:2]

        def tracer_group(name, pixel_axis=False):
            group = h5.require_group(name)
            add_scale(group, "id", np.arange(count))
            add_scale(group, "frame", np.arange(frames))
            if pixel_axis:
                add_scale(group, "pixel_axis", PIXEL_AXES)
            return group

        def per_tracer(group, name, values, units):
            """Per frame and tracer ``(F, N, ...)`` values written as ``(id, frame, ...)``."""
            values = np.swapaxes(np.asarray(values), 0, 1)
            dimensions = (*TRACER_DIMENSIONS, "pixel_axis")[: values.ndim]
            write_variable(group, name, values, dimensions, units)

        tracks = tracer_group("tracks")
        write_variable(tracks, "time", run.times, ("frame",), "T0")
        write_variable(tracks, "flags", result["flags"], ("id",), "1")
        for axis in range(3):
            columns = {
                f"x{axis + 1}_true": (run.true, "L0"),
                f"x{axis + 1}_meas": (result["x_meas"], "L0"),
                f"x{axis + 1}_ref": (result["x_ref"], "L0"),
                f"x{axis + 1}_opt_meas": (result["x_opt_meas"], "L0"),
                f"x{axis + 1}_opt_ref": (result["x_opt_ref"], "L0"),
                f"x{axis + 1}_floor": (result.get("x_floor"), "L0"),
                f"x{axis + 1}_vsc": (result.get("x_vsc"), "L0"),
                **{
                    f"x{axis + 1}_{kind}_{suffix}": (result[f"x_{kind}_{suffix}"], "L0")
                    for kind in ("meas", "ref")
                    for suffix in THRESHOLD_SUFFIXES
                },
                f"u{axis + 1}_true": (run.u_true, "L0/T0"),
                f"a{axis + 1}_true": (run.a_true, "L0/T0^2"),
            }
            for name, (values, units) in columns.items():
                if values is not None:
                    per_tracer(tracks, name, values[..., axis], units)
        for c, camera in enumerate(result["cameras"]):
            group = tracer_group(f"cameras/{camera.name}", pixel_axis=True)
            for kind in ("meas", "ref"):
                per_tracer(group, f"centroid_{kind}", result[f"centroid_{kind}"][:, c], "px")
                per_tracer(group, f"optics_{kind}", result[f"optics_{kind}"][:, c], "px")
                per_tracer(group, f"image_flags_{kind}", result[f"image_flags_{kind}"][:, c], "1")
                for suffix in THRESHOLD_SUFFIXES:
                    name = f"{kind}_{suffix}"
                    per_tracer(group, f"centroid_{name}", result[f"centroid_{name}"][:, c], "px")
                    per_tracer(
                        group, f"image_flags_{name}", result[f"image_flags_{name}"][:, c], "1"
                    )
                per_tracer(group, f"peak_{kind}", result[f"peak_{kind}"][:, c], "1")
                per_tracer(group, f"disparity_{kind}", result[f"disparity_{kind}"][..., c], "px")
                disparity = result[f"disparity_opt_{kind}"][..., c]
                per_tracer(group, f"disparity_opt_{kind}", disparity, "px")
            if "disparity_vsc" in result:
                per_tracer(group, "disparity_vsc", result["disparity_vsc"][..., c], "px")
            per_tracer(group, "failed_rays", result["failed_rays"][:, c], "1")
            group.attrs["parameters"] = to_json(camera.describe())
            group.attrs["calibration"] = to_json(result["calibration"][c])
            group.attrs["rays"] = to_json(result["rays"][c])
        calibration = h5.create_group("calibration")
        add_scale(calibration, "point", np.arange(len(result["target"])))
        add_scale(calibration, "axis", ["x1", "x2", "x3"])
        add_scale(calibration, "camera", [camera.name for camera in result["cameras"]])
        add_scale(calibration, "pixel_axis", PIXEL_AXES)
        write_variable(calibration, "target", result["target"], ("point", "axis"), "L0")
        pixels = result["target_pixels"]
        write_variable(calibration, "pixels", pixels, ("camera", "point", "pixel_axis"), "px")
        for group in (tracks, calibration):
            mark_si(group, si_per_unit(run.length_m, run.time_s))
        h5.attrs["exposure"] = to_json(result["exposure"])
        h5.attrs["sensor"] = to_json(result["sensor"])
        h5.attrs["mie"] = to_json(result["mie"])
        h5.attrs["self_calibration"] = to_json(result["self_calibration"])
        h5.attrs["matching"] = to_json(result["matching"])
    return path


def _to_mm(points, length_m):
    return np.asarray(points)[..., XYZ_AXES] * length_m * 1e3


def frame_writer(outputs, scene):
    """A ``frame_sink`` for :func:`rimcl.lpt.run.run_case` that writes each camera frame as
    a 16-bit TIFF: ``dataset/<case>/images/{field,uniform}/<cam>_frame<ffff>.tif`` of the
    output set ``outputs`` (:class:`rimcl.core.outputs.OutputSet`)."""
    import tifffile

    from rimcl.lpt.config import describe

    labels = {"meas": "field", "ref": "uniform"}

    def write(case, kind, camera, frame, counts):
        config = to_json({**describe(scene), "case": case, "camera": camera.name})
        name = outputs.path(
            "dataset", case, "images", labels[kind], f"{camera.name}_frame{frame:04d}.tif"
        )
        with atomic_path(name) as tmp:
            tifffile.imwrite(tmp, counts, description=config, photometric="minisblack")

    return write


def write_dataset(outputs, run, result, scene, overwrite=True):
    """Files for LPT codes (layout in the module docstring) in the output set ``outputs``
    (:class:`rimcl.core.outputs.OutputSet`). Returns the (staging) directory."""
    from rimcl.lpt.openlpt_files import write_camera_files

    folder = outputs.folder_path("dataset", result["case"])
    cameras = result["cameras"]
    # the target holds only points every camera sees (rimcl.lpt.run.calibrate_rig)
    target_mm = _to_mm(result["target"], run.length_m)
    pixels = np.asarray(result["target_pixels"])
    columns = [target_mm] + [pixels[c] for c in range(len(pixels))]
    header = "X Y Z " + " ".join(f"x{c + 1} y{c + 1}" for c in range(len(pixels)))
    names = ", ".join(f"x{c + 1} y{c + 1} = {camera.name}" for c, camera in enumerate(cameras))
    with atomic_path(folder / "calibration_points.txt", overwrite) as tmp:
        np.savetxt(
            tmp,
            np.hstack(columns),
            fmt="%.6f",
            header=f"{header}\nX, Y, Z in mm from the field origin (X, Y, Z = field x2, x3, "
            f"x1); x = column, y = row in px, pixel (0, 0) centred at (0, 0); {names}; "
            f"{len(target_mm)} target points (only those every camera sees)",
        )
    to_field = np.zeros((4, 4))
    scale = 1e-3 / run.length_m
    for xyz, axis in enumerate(XYZ_AXES):
        to_field[axis, xyz] = scale
    to_field[3, 3] = 1.0
    for c, camera in enumerate(cameras):
        pinhole = result["calibration"][c]["pinhole"]
        matrix_mm = np.asarray(pinhole["matrix"]) @ to_field
        write_json(
            outputs.path("dataset", result["case"], f"{camera.name}_pinhole.json"),
            {
                "dlt_matrix_mm_to_px": matrix_mm.tolist(),
                "dlt_matrix_note": "[u w, v w, w] = P [X, Y, Z, 1], X Y Z in mm",
                "residual_px": pinhole["residual_px"],
                "camera": camera.describe(),
            },
            overwrite,
        )
    openlpt = write_camera_files(
        folder, cameras, result["calibration"], result["target"], overwrite
    )
    write_truth_tracks(folder, run, overwrite)
    write_json(folder / MANIFEST, _manifest(run, result, openlpt), overwrite)
    return folder


def _manifest(run, result, openlpt):
    """What :mod:`rimcl.lpt.openlpt_track` needs to run a tracker on the dataset."""
    true_mm = _to_mm(run.true, run.length_m)
    steps = np.linalg.norm(np.diff(true_mm, axis=0), axis=-1)
    pixel_mm = [camera.pixel_size * run.length_m * 1e3 for camera in result["cameras"]]
    # the view volume: where the tracers are in any frame, and a few pixels around
    lo = np.nanmin(true_mm.reshape(-1, 3), axis=0)
    hi = np.nanmax(true_mm.reshape(-1, 3), axis=0)
    margin = 5.0 * max(pixel_mm)
    frames = list(range(run.true.shape[0]))
    dt = float(run.times[1] - run.times[0]) if len(frames) > 1 else None
    cameras = []
    for c, camera in enumerate(result["cameras"]):
        files = openlpt[camera.name]
        cameras.append(
            {
                "name": camera.name,
                "images": [f"{camera.name}_frame{f:04d}.tif" for f in frames],
                "openlpt_file": files.get("PINPLATE")
                or files.get("PINHOLE")
                or files["POLYNOMIAL"],
                "openlpt_files": files,
                "full_scale": int(result["sensor"]["full_scale"]),
                "threshold_counts": float(result["exposure"]["thresholds"][c]),
                "psf_sigma_px": float(camera.psf_sigma_px),
                "pixel_mm": float(pixel_mm[c]),
                "calibration_residual_px": {
                    model: result["calibration"][c][model]["residual_px"]
                    for model in ("pinhole", "soloff")
                },
            }
        )
    return {
        "rimcl_schema": "lpt_dataset",
        "case": result["case"],
        "frames": frames,
        "tracers": int(run.true.shape[1]),
        "in_view": (np.asarray(result["flags"]) == 0).tolist(),
        "dt": dt,
        "dt_s": None if run.time_s is None or dt is None else dt * run.time_s,
        "length_m": run.length_m,
        "axes": "X, Y, Z = field x2, x3, x1 (mm from the field origin)",
        "volume_mm": [
            float(v) for pair in zip(lo - margin, hi + margin, strict=True) for v in pair
        ],
        "voxel_mm": float(np.mean(pixel_mm)),
        "max_displacement_mm": float(np.nanmax(steps)) if steps.size else 0.0,
        "cameras": cameras,
    }


def write_truth_tracks(folder, run, overwrite=True):
    """``truth_tracks.h5`` and ``.csv``: true positions (mm), velocity and acceleration (m/s
    and m/s² with the run's ``time_s``, else metres per field time unit and its square);
    times in field time units."""
    frames, count = run.true.shape[:2]
    si = si_per_unit(run.length_m, run.time_s)
    ids = np.broadcast_to(np.arange(count), (frames, count))
    frame = np.broadcast_to(np.arange(frames)[:, None], (frames, count))
    times = np.broadcast_to(run.times[:, None], (frames, count))
    position = _to_mm(run.true, run.length_m)
    # physical = normalised × the one factor per unit (metres per L0, or m/s per L0/T0, ...)
    if run.time_s is None:
        kinematic_units = {"velocity": ("m/T0", "L0"), "acceleration": ("m/T0^2", "L0")}
        texts = ("m per field time unit", "m per field time unit squared")
    else:
        kinematic_units = {"velocity": ("m/s", "L0/T0"), "acceleration": ("m/s^2", "L0/T0^2")}
        texts = ("m/s", "m/s^2")
    velocity = run.u_true[..., XYZ_AXES] * si[kinematic_units["velocity"][1]]
    acceleration = run.a_true[..., XYZ_AXES] * si[kinematic_units["acceleration"][1]]
    time_text = "field time units" + ("" if run.time_s is None else f" ({run.time_s:g} s each)")
    table = np.column_stack(
        [
            ids.ravel(),
            frame.ravel(),
            times.ravel(),
            position.reshape(-1, 3),
            velocity.reshape(-1, 3),
            acceleration.reshape(-1, 3),
        ]
    )
    names = "track_id,frame,time,X_mm,Y_mm,Z_mm,u,v,w,ax,ay,az"
    with atomic_path(folder / "truth_tracks.csv", overwrite) as tmp:
        np.savetxt(
            tmp,
            table,
            delimiter=",",
            fmt=["%d", "%d", "%.9g"] + ["%.9g"] * 9,
            header=f"{names}\ntime in {time_text}, velocity in {texts[0]}, acceleration in "
            f"{texts[1]}",
            comments="# ",
        )
    with atomic_path(folder / "truth_tracks.h5", overwrite) as tmp, h5py.File(tmp, "w") as h5:
        h5.attrs["rimcl_schema"] = "lpt_truth_tracks"
        h5.attrs["axes"] = "X, Y, Z = field x2, x3, x1 (mm from the field origin)"
        if run.time_s is not None:
            h5.attrs["time_s"] = run.time_s
        h5.attrs["units"] = json.dumps(
            {"position": "mm", "velocity": texts[0], "acceleration": texts[1], "time": time_text}
        )
        # named dimensions (id, frame, axis), for xarray.open_dataset(path)
        add_scale(h5, "id", np.arange(count))
        add_scale(h5, "frame", np.arange(frames))
        add_scale(h5, "axis", ["X", "Y", "Z"])
        write_variable(h5, "time", run.times, ("frame",), "T0")
        dimensions = (*TRACER_DIMENSIONS, "axis")
        for name, values, units in (
            ("position_mm", position, "mm"),
            ("velocity", velocity, kinematic_units["velocity"][0]),
            ("acceleration", acceleration, kinematic_units["acceleration"][0]),
        ):
            write_variable(h5, name, np.swapaxes(values, 0, 1), dimensions, units)
        mark_si(h5, si)
