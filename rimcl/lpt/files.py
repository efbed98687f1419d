"""LPT output files: the case file, and datasets for LPT codes (OpenLPT, MyPTV, DaVis).

**Case file** ``lpt_case_<case>.h5`` (``rimcl_schema = "lpt_case"``, ``schema_version = 1``):

- root attributes: ``case``, ``n_ref``, ``length_m``, ``units`` (JSON), ``config`` and
  ``versions`` (JSON);
- ``tracks/``: ``time (F,)``, ``tracer_id (N,)``, ``flags (N,)`` (1: a ray failed,
  2: an image off a sensor), and per tracer and frame ``(F, N)`` float64:
  ``x{1,2,3}_{true,meas,ref}`` (field length units), ``u{1,2,3}_true``, ``a{1,2,3}_true``;
- ``cameras/<name>/``: ``centroid_meas``, ``centroid_ref`` ``(F, N, 2)`` (px, column/row,
  pixel (0, 0) centred on the top-left pixel), ``disparity_meas``, ``disparity_ref``
  ``(F, N)`` (px), ``failed_rays (F, N)``; attributes ``parameters`` (JSON: position,
  look-at, axes, optics), ``calibration`` (JSON: both fits and their residuals, px) and
  ``rays`` (JSON: the ray-count choice);
- ``calibration/``: ``target (M, 3)`` (field units) and ``pixels (C, M, 2)``.

**Dataset** (``rimcl lpt render``), in ``<out>/dataset/<case>/``:

- ``images/field/cam<k>_frame<ffff>.tif`` and ``images/uniform/…``: 16-bit TIFF per camera
  and frame through the field and through the uniform fluid; each tracer a pixel-integrated
  Gaussian (σ of the camera's diffraction-limited image) at its image centroid;
- ``calibration_points.txt``: the first LPT challenge's layout, one target point a row,
  ``X Y Z x1 y1 … xC yC`` (mm, px), with ``X, Y, Z = x2, x3, x1`` from the field's origin;
- ``cam<k>_pinhole.json``: the fitted DLT matrix (maps ``[X, Y, Z, 1]`` in mm to pixels),
  its residual, and the true camera parameters;
- ``truth_tracks.h5`` and ``truth_tracks.csv``: ``track_id, frame, time_s, X_mm, Y_mm,
  Z_mm, u_m_s, v_m_s, w_m_s, ax_m_s2, ay_m_s2, az_m_s2``.
"""

import json

import h5py
import numpy as np

from rimcl.core.provenance import atomic_path, stamp_h5, to_json
from rimcl.stats.tables import write_json

SCHEMA = "lpt_case"
SCHEMA_VERSION = 1
#: Field axes of the LPT challenge's X, Y, Z (X along x2, Y along x3, Z = depth x1).
XYZ_AXES = (1, 2, 0)


def _units(run):
    return {
        "positions": f"field length units ({run.length_m:g} m each)",
        "velocity": "field length / field time units",
        "acceleration": "field length / field time units squared",
        "centroids": "pixels (column, row); pixel (0, 0) centred on the top-left pixel",
        "disparity": "pixels",
        "time": "field time units",
    }


def write_case(path, run, result, scene, overwrite=True):
    """Write one case's per-tracer results (layout in the module docstring)."""
    from rimcl.lpt.config import describe

    with atomic_path(path, overwrite) as tmp, h5py.File(tmp, "w") as h5:
        h5.attrs["rimcl_schema"] = SCHEMA
        h5.attrs["schema_version"] = SCHEMA_VERSION
        h5.attrs["case"] = result["case"]
        h5.attrs["n_ref"] = result["n_ref"]
        h5.attrs["length_m"] = run.length_m
        h5.attrs["units"] = json.dumps(_units(run))
        stamp_h5(h5, {**describe(scene), "study_scene": scene.study})
        tracks = h5.create_group("tracks")
        tracks["time"] = run.times
        tracks["tracer_id"] = np.arange(run.true.shape[1])
        tracks["flags"] = result["flags"]
        for axis in range(3):
            tracks[f"x{axis + 1}_true"] = run.true[..., axis]
            tracks[f"x{axis + 1}_meas"] = result["x_meas"][..., axis]
            tracks[f"x{axis + 1}_ref"] = result["x_ref"][..., axis]
            tracks[f"u{axis + 1}_true"] = run.u_true[..., axis]
            tracks[f"a{axis + 1}_true"] = run.a_true[..., axis]
        cameras = h5.create_group("cameras")
        for c, camera in enumerate(result["cameras"]):
            group = cameras.create_group(camera.name)
            group["centroid_meas"] = result["centroid_meas"][:, c]
            group["centroid_ref"] = result["centroid_ref"][:, c]
            group["disparity_meas"] = result["disparity_meas"][..., c]
            group["disparity_ref"] = result["disparity_ref"][..., c]
            group["failed_rays"] = result["failed_rays"][:, c]
            group.attrs["parameters"] = to_json(camera.describe())
            group.attrs["calibration"] = to_json(result["calibration"][c])
            group.attrs["rays"] = to_json(result["rays"][c])
        calibration = h5.create_group("calibration")
        calibration["target"] = result["target"]
        calibration["pixels"] = result["target_pixels"]
    return path


def _to_mm(points, length_m):
    return np.asarray(points)[..., XYZ_AXES] * length_m * 1e3


def tracer_image(camera, centroids, full_scale=65535, fill=0.6):
    """A 16-bit frame of Gaussian tracer images at ``centroids`` (N, 2) px.

    Each tracer is a pixel-integrated Gaussian of the camera's ``σ``
    (:class:`rimcl.imaging.render.Renderer`, ``exact``), scaled so that a tracer centred on
    a pixel peaks at ``fill`` of full scale; overlapping tracers add and clip.
    """
    from rimcl.imaging.render import FrameImage, Renderer, quantize, scale_for

    renderer = Renderer("exact", 1.0, (-0.5, -0.5), psf_sigma=camera.psf_sigma_px, bit_depth=16)
    centred = np.zeros((1, 2))
    reference, _ = renderer.render(
        renderer.to_pixels(centred), np.ones(1), renderer.window_for(renderer.to_pixels(centred))
    )
    scale = fill * scale_for(reference, full_scale)
    frame = FrameImage(camera.pixels[0], camera.pixels[1], full_scale)
    for point in centroids[np.all(np.isfinite(centroids), axis=1)]:
        local = renderer.to_pixels(point[None])
        window = renderer.window_for(local)
        image, _ = renderer.render(local, np.ones(1), window)
        frame.add(window, quantize(image, scale, full_scale)[0])
    return frame.counts


def write_dataset(out_dir, run, result, scene, overwrite=True):
    """Files for LPT codes (layout in the module docstring). Returns the directory."""
    import tifffile

    from rimcl.lpt.config import describe

    folder = out_dir / "dataset" / result["case"]
    config = to_json({**describe(scene), "case": result["case"]})
    if scene.lpt.images:
        for kind, label in (("meas", "field"), ("ref", "uniform")):
            images = folder / "images" / label
            images.mkdir(parents=True, exist_ok=True)
            for c, camera in enumerate(result["cameras"]):
                for k in range(run.times.size):
                    counts = tracer_image(camera, result[f"centroid_{kind}"][k, c])
                    name = images / f"{camera.name}_frame{k:04d}.tif"
                    with atomic_path(name, overwrite) as tmp:
                        tifffile.imwrite(tmp, counts, description=config, photometric="minisblack")
    folder.mkdir(parents=True, exist_ok=True)
    target_mm = _to_mm(result["target"], run.length_m)
    pixels = result["target_pixels"]
    columns = [target_mm] + [pixels[c] for c in range(len(pixels))]
    header = "X Y Z " + " ".join(f"x{c + 1} y{c + 1}" for c in range(len(pixels)))
    with atomic_path(folder / "calibration_points.txt", overwrite) as tmp:
        np.savetxt(
            tmp,
            np.hstack(columns),
            fmt="%.6f",
            header=f"{header}\nX, Y, Z in mm (x2, x3, x1 of the field); x, y in px",
        )
    to_field = np.zeros((4, 4))
    scale = 1e-3 / run.length_m
    for xyz, axis in enumerate(XYZ_AXES):
        to_field[axis, xyz] = scale
    to_field[3, 3] = 1.0
    for c, camera in enumerate(result["cameras"]):
        pinhole = result["calibration"][c]["pinhole"]
        matrix_mm = np.asarray(pinhole["matrix"]) @ to_field
        write_json(
            folder / f"{camera.name}_pinhole.json",
            {
                "dlt_matrix_mm_to_px": matrix_mm.tolist(),
                "dlt_matrix_note": "[u w, v w, w] = P [X, Y, Z, 1], X Y Z in mm",
                "residual_px": pinhole["residual_px"],
                "camera": camera.describe(),
            },
            overwrite,
        )
    write_truth_tracks(folder, run, overwrite)
    return folder


def write_truth_tracks(folder, run, overwrite=True):
    """``truth_tracks.h5`` and ``.csv``: true positions (mm), velocity (m/s), acceleration
    (m/s²); ``time_s`` is in field time units unless the field gives seconds."""
    frames, count = run.true.shape[:2]
    ids = np.broadcast_to(np.arange(count), (frames, count))
    frame = np.broadcast_to(np.arange(frames)[:, None], (frames, count))
    times = np.broadcast_to(run.times[:, None], (frames, count))
    position = _to_mm(run.true, run.length_m)
    velocity = run.u_true[..., XYZ_AXES] * run.length_m
    acceleration = run.a_true[..., XYZ_AXES] * run.length_m
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
            header=names
            + "\nvelocity in m per field time unit, acceleration in m per field time unit^2",
            comments="# ",
        )
    with atomic_path(folder / "truth_tracks.h5", overwrite) as tmp, h5py.File(tmp, "w") as h5:
        h5.attrs["rimcl_schema"] = "lpt_truth_tracks"
        h5.attrs["axes"] = "X, Y, Z = field x2, x3, x1 (mm from the field origin)"
        h5.attrs["units"] = json.dumps(
            {
                "position": "mm",
                "velocity": "m per field time unit",
                "acceleration": "m per field time unit squared",
                "time": "field time units",
            }
        )
        h5["time"] = run.times
        h5["position_mm"] = position
        h5["velocity"] = velocity
        h5["acceleration"] = acceleration
