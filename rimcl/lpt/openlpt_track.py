"""OpenLPT's Shake-the-Box on a rimcl LPT dataset, and its tracks against the truth.

OpenLPT (``pip install openlpt``, MIT; module ``pyopenlpt``) is run on a dataset written by
``rimcl lpt render`` (:func:`rimcl.lpt.files.write_dataset`), once on the frames through the
field and once on the frames through the uniform fluid, each in a child process (its C++
core prints much and may abort; a crash must not take rimcl with it). Its inputs, written
into ``<dataset>/openlpt/<kind>/``:

- ``config.txt``: OpenLPT's positional main configuration (frame range, frame rate,
  threads, cameras, per camera the camera file and the sensor's full scale, per camera an
  image list, the view volume in mm, the voxel size in mm, the output folder, ``Tracer``
  and its configuration file, and no tracks to resume);
- ``tracerConfig.txt``: the 17 positional STB settings (search radii in voxels from the
  flow's largest displacement per frame and the mean tracer spacing, shake width, the
  predictive field's grid, IPR and shake loops, ghost threshold, 2-D and 3-D matching
  tolerances, reduced-camera loops, the 2-D detection threshold in counts — rimcl's own
  threshold of the camera — and the tracer image radius in px);
- ``<camera>_images.txt``: the TIFF paths, one per line, in frame order.

**Comparison.** OpenLPT writes its tracks at the last frame
(``Results/ConvergeTrack/{LongTrackActive,LongTrackInactive,ExitTrack}_<frame>.csv``, rows
``TrackID, FrameID, WorldX, WorldY, WorldZ, …`` in mm, track ids restarting per file). Each
track is assigned to the true tracer nearest to it in most of its frames; it is **true**
where at least :data:`MATCH_SHARE` of its points lie within :data:`MATCH_VOXELS` voxels of
that tracer (the LPT challenge counts a detection as true within one voxel; rimcl allows
two so that a refraction shift of a few tenths of a pixel is measured rather than counted
as a ghost), else a **ghost**. A true tracer is **found** where true tracks cover at least
:data:`FOUND_FRAMES` of its frames (OpenLPT drops tracks shorter than 7 frames). Position
errors are STB's positions minus the truth (mm, and px through the mean object-space pixel
of the cameras); velocity and acceleration come from the same sliding polynomial fit
(:func:`rimcl.ptv.track.sliding_fit`) applied to STB's positions and to the true positions
(the fit's own error, the baseline) and are compared with the true velocity and
acceleration. The **refraction error STB sees** is the field run's error minus the uniform
run's, per true tracer found by both.
"""

import json
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

from rimcl.core.errors import RimclError

#: Nearest-truth distance (voxels) within which an STB point belongs to that tracer.
MATCH_VOXELS = 2.0
#: Share of a track's points that must belong to one tracer for the track to be true.
MATCH_SHARE = 0.8
#: Frames a true tracer must be covered in to count as found.
FOUND_FRAMES = 7
#: The track files OpenLPT writes at the last frame.
TRACK_PREFIXES = ("LongTrackActive_", "LongTrackInactive_", "ExitTrack_")
#: The manifest rimcl writes beside a dataset for this module.
MANIFEST = "openlpt_dataset.json"


def openlpt_available():
    """True where ``pyopenlpt`` imports."""
    try:
        import pyopenlpt  # noqa: F401
    except ImportError:
        return False
    return True


def load_manifest(dataset):
    """The dataset's manifest (:func:`rimcl.lpt.files.write_dataset`), checked."""
    path = Path(dataset) / MANIFEST
    if not path.is_file():
        raise RimclError(
            f"{dataset} is not a rimcl LPT dataset (no {MANIFEST}); make one with "
            "'rimcl lpt render SCENE -o OUT' and pass OUT/dataset/<case>"
        )
    manifest = json.loads(path.read_text())
    if len(manifest["frames"]) < FOUND_FRAMES + 5:
        raise RimclError(
            f"OpenLPT's STB needs at least {FOUND_FRAMES + 5} frames (4 to start tracks, "
            f"tracks of 7 or more); the dataset has {len(manifest['frames'])}: render it with "
            "time.frames >= 12"
        )
    if len(manifest["cameras"]) < 2:
        raise RimclError("OpenLPT's STB needs at least two cameras")
    return manifest


def tracer_settings(manifest):
    """The 17 positional values of ``tracerConfig.txt`` (with their comments)."""
    voxel = manifest["voxel_mm"]
    spacing = (np.prod(np.diff(np.reshape(manifest["volume_mm"], (3, 2)), axis=1)) /
               max(manifest["tracers"], 1)) ** (1.0 / 3.0)  # fmt: skip
    search = max(3.0, 1.5 * manifest["max_displacement_mm"] / voxel + 2.0)
    cameras = manifest["cameras"]
    threshold = int(max(1, round(min(c["threshold_counts"] for c in cameras))))
    radius = max(2.0, min(6.0, 2.0 * max(c["psf_sigma_px"] for c in cameras)))
    return [
        (f"{search:.6g}", "search radius connecting tracks to objects (voxels)"),
        ("4", "frames of the initial phase"),
        (f"{max(spacing / voxel, 2.0 * search):.6g}", "mean tracer spacing (voxels)"),
        ("0.25", "shake width (voxels)"),
        ("21", "predictive field grid x"),
        ("21", "predictive field grid y"),
        ("21", "predictive field grid z"),
        (f"{search:.6g}", "predictive field search radius (voxels)"),
        ("4", "IPR loops"),
        ("4", "shake loops"),
        ("0.1", "ghost threshold"),
        ("1.0", "2-D tolerance (px)"),
        ("2.0", "3-D tolerance (voxels)"),
        ("1", "cameras that may be missing"),
        ("2", "IPR loops per reduced camera combination"),
        (str(threshold), "2-D particle finder threshold (counts: rimcl's camera threshold)"),
        (f"{radius:.6g}", "tracer image radius (px)"),
    ]


def write_inputs(dataset, manifest, kind, folder):
    """OpenLPT's configuration for one kind of frames (``field`` or ``uniform``).

    Returns the path of ``config.txt``.
    """
    folder = Path(folder).resolve()
    folder.mkdir(parents=True, exist_ok=True)
    dataset = Path(dataset).resolve()
    frames = manifest["frames"]
    camera_lines, list_lines = [], []
    for camera in manifest["cameras"]:
        images = folder / f"{camera['name']}_images.txt"
        paths = [str(dataset / "images" / kind / camera["images"][f]) for f in range(len(frames))]
        images.write_text("\n".join(paths) + "\n")
        camera_file = dataset / camera["openlpt_file"]
        camera_lines.append(f"{camera_file},{int(camera['full_scale'])}")
        list_lines.append(str(images))
    tracer = folder / "tracerConfig.txt"
    tracer.write_text(
        "# rimcl: STB settings for a rimcl LPT dataset (OpenLPT's positional order)\n"
        + "".join(f"{value} # {comment}\n" for value, comment in tracer_settings(manifest))
    )
    volume = manifest["volume_mm"]
    fps = 1.0 / manifest["dt_s"] if manifest.get("dt_s") else 1.0
    lines = [
        "# Frame Range: [startID,endID]",
        f"0,{len(frames) - 1}",
        "# Frame Rate: [Hz]",
        str(max(1, round(fps))),
        "# Number of Threads: (0: use as many as possible)",
        str(os.cpu_count() or 1),
        "# Number of Cameras:",
        str(len(camera_lines)),
        "# Camera File Path, Max Intensity",
        *camera_lines,
        "# Image File Path",
        *list_lines,
        "# View Volume: (xmin,xmax,ymin,ymax,zmin,zmax) mm; X, Y, Z = field x2, x3, x1",
        ",".join(f"{v:.9g}" for v in volume),
        "# Voxel to MM:",
        f"{manifest['voxel_mm']:.9g}",
        "# Output Folder Path:",
        str(folder / "Results"),
        "# Object Types:",
        "Tracer",
        "# STB Config Files:",
        str(tracer),
        "# Flag to load previous track files, previous frameID",
        "0,-1",
    ]
    config = folder / "config.txt"
    config.write_text("\n".join(lines) + "\n")
    return config


def run_stb(config, log_path, timeout_s):
    """Run OpenLPT's STB on ``config`` in a child process; its output goes to ``log_path``.

    Returns the wall time (s).
    """
    started = time.perf_counter()
    code = "import sys, pyopenlpt; pyopenlpt.run(sys.argv[1])"
    with open(log_path, "w") as log:
        try:
            done = subprocess.run(
                [sys.executable, "-c", code, str(config)],
                cwd=str(Path(config).parent),
                stdout=log,
                stderr=subprocess.STDOUT,
                stdin=subprocess.DEVNULL,
                timeout=timeout_s,
                check=False,
            )
        except subprocess.TimeoutExpired:
            raise RimclError(
                f"OpenLPT ran past {timeout_s:g} s on {config} (log: {log_path}); "
                "give it longer with --timeout"
            ) from None
    if done.returncode != 0:
        raise RimclError(f"OpenLPT failed (exit {done.returncode}); its log: {log_path}")
    return time.perf_counter() - started


def read_tracks(results, last_frame):
    """OpenLPT's tracks at ``last_frame``: a list of ``(frames (K,), positions (K, 3) mm)``."""
    tracks = []
    folder = Path(results) / "ConvergeTrack"
    for prefix in TRACK_PREFIXES:
        path = folder / f"{prefix}{last_frame}.csv"
        lines = path.read_text().splitlines()[1:] if path.is_file() else []
        lines = [line for line in lines if line.strip()]
        if not lines:
            continue
        rows = np.array([[float(v) for v in line.split(",")[:5]] for line in lines])
        for track_id in np.unique(rows[:, 0]):
            mine = rows[rows[:, 0] == track_id]
            order = np.argsort(mine[:, 1])
            tracks.append((mine[order, 1].astype(int), mine[order, 2:5]))
    if not folder.is_dir():
        raise RimclError(f"OpenLPT wrote no tracks under {results}")
    return tracks


def assign(tracks, truth, voxel_mm):
    """STB tracks on the true tracers.

    Parameters
    ----------
    tracks : list of (ndarray, ndarray)
        :func:`read_tracks`.
    truth : ndarray, shape (F, N, 3)
        True positions (mm).
    voxel_mm : float

    Returns
    -------
    positions : ndarray, shape (F, N, 3)
        STB's position of each true tracer (NaN where no true track holds it).
    ghosts : int
        Tracks not on one tracer.
    """
    frames, count = truth.shape[:2]
    positions = np.full_like(truth, np.nan)
    ghosts = 0
    for track_frames, points in tracks:
        inside = (track_frames >= 0) & (track_frames < frames)
        track_frames, points = track_frames[inside], points[inside]
        if not len(track_frames):
            continue
        distance = np.linalg.norm(truth[track_frames] - points[:, None, :], axis=-1)
        nearest = np.argmin(distance, axis=1)
        tracer = np.bincount(nearest, minlength=count).argmax()
        close = distance[:, tracer] <= MATCH_VOXELS * voxel_mm
        if close.mean() < MATCH_SHARE:
            ghosts += 1
            continue
        positions[track_frames[close], tracer] = points[close]
    return positions, ghosts


def _rms(values):
    values = np.asarray(values)
    values = values[np.isfinite(values)]
    return float(np.sqrt(np.mean(values**2))) if values.size else None


def track_errors(positions, truth, velocity, acceleration, dt, px_mm, in_view, window=7):
    """Errors of STB's tracks (found tracers) against the truth.

    Parameters
    ----------
    positions, truth : ndarray, shape (F, N, 3)
        STB's and the true positions (mm).
    velocity, acceleration : ndarray, shape (F, N, 3)
        True velocity and acceleration (mm per time unit and its square).
    dt : float
        Frame spacing (time units).
    px_mm : float
        Object-space pixel (mm), for errors in px.
    in_view : ndarray, bool, shape (N,)
        Tracers imaged by every camera in every frame (rimcl's own measurement kept them):
        the true tracks a tracker can find.
    window : int
        Frames of the sliding fit.

    Returns
    -------
    dict
        ``found``, ``position_rms_mm``/``_px`` (per axis X, Y, Z and all),
        ``velocity_rms``, ``acceleration_rms`` (per axis) and the fit's baselines.
    """
    from rimcl.ptv.track import sliding_fit

    covered = np.isfinite(positions).all(axis=-1).sum(axis=0)
    found = covered >= FOUND_FRAMES
    error = positions - truth
    result = {
        "tracers": int(truth.shape[1]),
        "true_tracers": int(in_view.sum()),
        "found": int(found[in_view].sum()),
        "found_share": float(found[in_view].mean()) if in_view.any() else None,
        "found_elsewhere": int(found[~in_view].sum()),
        "points_covered_share": float(covered.sum() / truth[..., 0].size),
        "position_rms_mm": {a: _rms(error[..., k]) for k, a in enumerate("XYZ")},
    }
    result["position_rms_mm"]["all"] = _rms(np.linalg.norm(error, axis=-1))
    result["position_rms_px"] = {
        a: None if v is None else v / px_mm for a, v in result["position_rms_mm"].items()
    }
    if truth.shape[0] >= window:
        measured = sliding_fit(positions, dt, window=window)
        exact = sliding_fit(truth, dt, window=window)
        rows = measured.centres
        for name, fitted, baseline, true in (
            ("velocity", measured.velocity, exact.velocity, velocity[rows]),
            ("acceleration", measured.acceleration, exact.acceleration, acceleration[rows]),
        ):
            result[f"{name}_rms"] = {a: _rms((fitted - true)[..., k]) for k, a in enumerate("XYZ")}
            result[f"{name}_baseline_rms"] = {
                a: _rms(np.where(np.isfinite(fitted[..., k]), (baseline - true)[..., k], np.nan))
                for k, a in enumerate("XYZ")
            }
            result[f"{name}_truth_rms"] = {a: _rms(true[..., k]) for k, a in enumerate("XYZ")}
    return result


def _truth(dataset):
    import h5py

    with h5py.File(Path(dataset) / "truth_tracks.h5", "r") as h5:
        # stored (id, frame, axis): (F, N, 3) here; velocity in m/s (or m/T0) -> mm
        swap = [
            np.swapaxes(h5[name][()], 0, 1) for name in ("position_mm", "velocity", "acceleration")
        ]
        return swap[0], 1e3 * swap[1], 1e3 * swap[2]


def track_dataset(dataset, kinds=("uniform", "field"), timeout_s=3600.0, progress=None):
    """Run STB on a dataset's frames of each kind and compare with the truth.

    Parameters
    ----------
    dataset : path
        ``<out>/dataset/<case>`` of ``rimcl lpt render``.
    kinds : tuple of str
        ``uniform`` and/or ``field``.
    timeout_s : float
        Longest STB run (s).
    progress : callable, optional
        Receives one line per stage.

    Returns
    -------
    dict
        Per kind the STB tracks' statistics (:func:`track_errors` plus ``tracks``,
        ``ghosts``, ``ghost_share``, ``wall_s``), and ``refraction`` (field minus uniform,
        per tracer found by both) where both ran; also written to
        ``<dataset>/openlpt/track_stats.json``.
    """
    if not openlpt_available():
        raise RimclError(
            "OpenLPT is not installed: pip install 'rimcl[openlpt]' (or pip install openlpt)"
        )
    dataset = Path(dataset)
    manifest = load_manifest(dataset)
    truth, velocity, acceleration = _truth(dataset)
    dt = manifest["dt_s"] or manifest["dt"]
    px_mm = float(np.mean([c["pixel_mm"] for c in manifest["cameras"]]))
    stats = {
        "dataset": str(dataset),
        "case": manifest["case"],
        "settings": {
            "match_voxels": MATCH_VOXELS,
            "match_share": MATCH_SHARE,
            "found_frames": FOUND_FRAMES,
            "voxel_mm": manifest["voxel_mm"],
            "pixel_mm": px_mm,
            "tracer_config": [v for v, _ in tracer_settings(manifest)],
        },
        "units": {
            "position": "mm (and px of the cameras' mean object-space pixel)",
            "velocity": "mm/s" if manifest["dt_s"] else "mm per field time unit",
            "acceleration": "mm/s^2" if manifest["dt_s"] else "mm per field time unit squared",
        },
    }
    positions = {}
    for kind in kinds:
        folder = dataset / "openlpt" / kind
        config = write_inputs(dataset, manifest, kind, folder)
        if progress:
            progress(f"OpenLPT STB on the {kind} frames ({len(manifest['frames'])} frames)")
        wall = run_stb(config, folder / "openlpt.log", timeout_s)
        tracks = read_tracks(folder / "Results", len(manifest["frames"]) - 1)
        placed, ghosts = assign(tracks, truth, manifest["voxel_mm"])
        in_view = np.asarray(manifest["in_view"], dtype=bool)
        entry = track_errors(placed, truth, velocity, acceleration, dt, px_mm, in_view)
        entry.update(
            tracks=len(tracks),
            ghosts=ghosts,
            ghost_share=ghosts / len(tracks) if tracks else None,
            wall_s=wall,
        )
        stats[kind] = entry
        positions[kind] = placed
    if {"uniform", "field"} <= set(positions):
        shift = positions["field"] - positions["uniform"]
        both = np.isfinite(shift).all(axis=-1)
        stats["refraction"] = {
            "points": int(both.sum()),
            "position_rms_mm": {a: _rms(shift[..., k]) for k, a in enumerate("XYZ")},
        }
        stats["refraction"]["position_rms_mm"]["all"] = _rms(np.linalg.norm(shift, axis=-1))
        stats["refraction"]["position_rms_px"] = {
            a: None if v is None else v / px_mm
            for a, v in stats["refraction"]["position_rms_mm"].items()
        }
    out = dataset / "openlpt" / "track_stats.json"
    out.write_text(json.dumps(stats, indent=1, default=float))
    return stats


def _fmt(value, digits=3):
    return "n/a" if value is None else f"{value:.{digits}g}"


def _percent(share):
    return "n/a" if share is None else f"{100 * share:.1f} %"


def summary_lines(stats):
    """Lines for the terminal: per kind tracks found, ghosts and errors; refraction."""
    units = stats["units"]
    lines = [f"OpenLPT STB on {stats['dataset']} (case {stats['case']})"]
    for kind in ("uniform", "field"):
        if kind not in stats:
            continue
        s = stats[kind]
        lines.append(
            f"  {kind}: {s['found']}/{s['true_tracers']} true tracks found "
            f"({_percent(s['found_share'])}), {s['tracks']} tracks, {s['ghosts']} ghosts; "
            f"position rms {_fmt(s['position_rms_mm']['all'])} mm "
            f"({_fmt(s['position_rms_px']['all'])} px); {s['wall_s']:.0f} s"
        )
        if "velocity_rms" in s:
            for name, unit in (("velocity", units["velocity"]),
                               ("acceleration", units["acceleration"])):  # fmt: skip
                rms = "/".join(_fmt(s[f"{name}_rms"][a]) for a in "XYZ")
                base = "/".join(_fmt(s[f"{name}_baseline_rms"][a]) for a in "XYZ")
                lines.append(f"    {name} rms X/Y/Z {rms} {unit} (fit baseline {base})")
    if "refraction" in stats:
        r = stats["refraction"]
        lines.append(
            "  refraction STB sees (field - uniform), position rms X/Y/Z "
            + "/".join(_fmt(r["position_rms_mm"][a]) for a in "XYZ")
            + f" mm ({_fmt(r['position_rms_px']['all'])} px over {r['points']} points)"
        )
    return lines
