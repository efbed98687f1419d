"""The whole chain over refractive-index cases (``rimcl study``): resumable, atomic.

A study directory holds:

- ``scene.toml``: the scene actually used (written first; a rerun with another scene is
  refused unless ``force``);
- ``cases/<case>.h5``: one ``rimcl render`` file per case, written atomically when the
  case is finished; a rerun skips the cases whose file exists;
- ``shards/<case>/<first>-<stop>.h5``: with a Dask scheduler (``run.scheduler``), the
  finished shards of tracers, merged into the case files (:mod:`rimcl.distributed`);
- ``stats.json`` and ``figures/``: statistics and figures of all cases (:mod:`rimcl.stats`,
  :mod:`rimcl.figures`);
- ``summary.md``: the paper-style table, beside the paper's values for air and water.
  Written last, so its presence (newer than every case file) means the study is complete
  and a rerun only reads ``stats.json``.

Every case uses the same tracers, rays and random numbers (common random numbers), so
case-to-case differences are not noise; the reference images (through a uniform medium)
are computed once and reused.
"""

import dataclasses
import json
import time
from datetime import datetime, timezone
from pathlib import Path

from rimcl import __version__
from rimcl.config import MeasureConfig
from rimcl.errors import RimclError
from rimcl.provenance import atomic_path
from rimcl.scene import load_scene, scene_text

#: Scene keys that do not change the measurement: a study may resume with other values.
RUN_ONLY_KEYS = (
    ("run", "device"),
    ("run", "rays_per_batch"),
    ("run", "scheduler"),
    ("run", "shard_tracers"),
)

PAPER_SOURCE = (
    "H. Li, A. Fischer, M. Avila, D. Xu, *Measurement error of tracer-based velocimetry in "
    "single-phase turbulent flows with inhomogeneous refractive indices*"
)
#: The paper's values for air (C1) and water (C4), as its text states them, with where.
#: Relative errors in percent; the position error is an order of magnitude only.
PAPER_VALUES = {
    "C1": {
        "fluid": "air",
        "delta_n_max": "2.40e-5",
        "position_peak_over_L": "O(1e-4)",
        "velocity_systematic": "≈ 0.2 %",
        "velocity_random": "≈ 2 %",
        "acceleration_systematic": "≈ 1 %",
        "acceleration_random": "≈ 300 %",
    },
    "C4": {
        "fluid": "water",
        "delta_n_max": "2.85e-2",
        "position_peak_over_L": "O(1e-2)",
        "velocity_systematic": "≈ 10 %",
        "velocity_random": "≈ 2000 %",
        "acceleration_systematic": "≈ 500 %",
        "acceleration_random": "≈ 1e5 %",
    },
}
PAPER_CITATIONS = (
    "Δn_max: Table 2 (tab:cases). Position error: Sec. 4.2 (sec:position), 'for the air "
    "flow (C1), the magnitudes of position error are up to O(10^-4 L) ... for the water "
    "flow (C4) ... O(10^-2 L)'. Velocity: Sec. 4.3 (sec:velocity), mean and standard "
    "deviation of ε_u3/u3, 'approximately 0.2 % and about 2 %' (air), '10 %' and 'about "
    "2000 %' (water). Acceleration: Sec. 4.4 (sec:acceleration), 'about 1 % and 300 %' "
    "(air), 'about 500 % and 10^5 %' (water); also the Conclusions."
)


@dataclasses.dataclass
class StudyResult:
    """What :func:`run_study` did.

    Attributes
    ----------
    out_dir : Path
    stats : dict
        The ``stats.json`` document.
    ran, skipped : list of str
        Cases computed in this run, and cases found finished.
    case_seconds : dict of str to float
        Wall time of each case computed in this run (s).
    stats_redone : bool
        False when everything was up to date and only ``stats.json`` was read.
    wall_seconds : float
    """

    out_dir: Path
    stats: dict
    ran: list
    skipped: list
    case_seconds: dict
    stats_redone: bool
    wall_seconds: float


def _comparable(scene):
    trimmed = json.loads(json.dumps(scene))
    for section, name in RUN_ONLY_KEYS:
        trimmed[section].pop(name, None)
    return trimmed


def _differences(old, new):
    return [
        f"{section}.{name}: {old[section].get(name)!r} -> {value!r}"
        for section, table in new.items()
        for name, value in table.items()
        if old.get(section, {}).get(name) != value
    ]


def _check_directory(out_dir, scene, force):
    """Create the directory; refuse to mix the results of two different scenes."""
    try:
        (out_dir / "cases").mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise RimclError(f"cannot create study directory {out_dir}: {exc.strerror}") from None
    scene_path = out_dir / "scene.toml"
    if force:
        return
    if scene_path.exists():
        previous = _comparable(load_scene(scene_path))
        changes = _differences(previous, _comparable(scene))
        if changes:
            raise RimclError(
                f"{out_dir} holds a study of another scene ({'; '.join(changes)}); "
                "use --force to redo it, or another --out"
            )
    elif any((out_dir / "cases").glob("*.h5")):
        raise RimclError(
            f"{out_dir / 'cases'} holds render files but {scene_path} is missing; "
            "use --force to redo them, or another --out"
        )


def _write_text(path, text):
    with atomic_path(path, overwrite=True) as tmp:
        Path(tmp).write_text(text)


def case_path(out_dir, case):
    """Render file of one case in a study directory."""
    return Path(out_dir) / "cases" / f"{case}.h5"


def _up_to_date(out_dir, case_files, figures):
    from rimcl.figures import FIGURE_NAMES

    summary, stats = out_dir / "summary.md", out_dir / "stats.json"
    needed = [summary, stats]
    if figures:
        needed += [out_dir / "figures" / f"{name}.png" for name in FIGURE_NAMES]
    if not all(path.exists() for path in needed):
        return False
    inputs = [out_dir / "scene.toml", *case_files]
    return summary.stat().st_mtime >= max(path.stat().st_mtime for path in inputs)


def run_study(
    scene, out_dir, *, force=False, figures=True, progress=False, report=None, scheduler=None
):
    """Run every case of a scene, then the statistics, figures and summary.

    Parameters
    ----------
    scene : dict
        A complete scene (:func:`rimcl.scene.load_scene`).
    out_dir : str or Path
        Study directory (created if missing).
    force : bool
        Redo every case and the statistics even if finished.
    figures : bool
        Also draw the figures (the statistics and summary are always written).
    progress : bool
        Show progress bars.
    report : callable, optional
        Called with one line of text per step (the CLI echoes them).
    scheduler : str, optional
        Measure the cases on Dask (``"local:N"`` or a scheduler address; default: the
        scene's ``run.scheduler``, "" = this process): see :mod:`rimcl.distributed`.
        ``case_seconds`` are then worker seconds.

    Returns
    -------
    StudyResult

    Raises
    ------
    RimclError
        For a directory holding another scene's study, an unusable field or device, and
        every error of the measurement.
    """
    from rimcl.measure import run_render, write_render

    started = time.perf_counter()
    say = report or (lambda line: None)
    out_dir = Path(out_dir)
    _check_directory(out_dir, scene, force)
    scene_path, text = out_dir / "scene.toml", scene_text(scene)
    if not scene_path.exists() or scene_path.read_text() != text:
        _write_text(scene_path, text)
    names = scene["cases"]["names"]
    ran, skipped, seconds = [], [], {}
    todo = names
    scheduler = scheduler or scene["run"]["scheduler"]
    if scheduler:
        from rimcl.distributed import measure_cases

        ran, skipped, seconds = measure_cases(
            scene, out_dir, scheduler, force=force, progress=progress, report=say
        )
        todo = []  # the cluster measured every case
    references = {}  # threshold -> reference images (they depend on it, not on the case)
    for index, name in enumerate(todo, start=1):
        path = case_path(out_dir, name)
        if path.exists() and not force:
            skipped.append(name)
            say(f"[{index}/{len(names)}] {name}: finished earlier, kept ({path})")
            continue
        say(f"[{index}/{len(names)}] {name}: measuring")
        case_start = time.perf_counter()
        config = MeasureConfig.from_scene(scene, name)
        threshold = config.renderer.threshold
        result = run_render(
            scene["field"]["path"] or None,
            case=name,
            config=config,
            reference=references.get(threshold),
            progress=progress,
        )
        references[threshold] = result.reference
        write_render(path, result, overwrite=True)
        seconds[name] = time.perf_counter() - case_start
        ran.append(name)
        say(f"[{index}/{len(names)}] {name}: done in {seconds[name]:.1f} s")
    case_files = [case_path(out_dir, name) for name in names]
    if not force and not ran and _up_to_date(out_dir, case_files, figures):
        say("statistics, figures and summary are up to date")
        stats = json.loads((out_dir / "stats.json").read_text())
        return StudyResult(
            out_dir, stats, ran, skipped, seconds, False, time.perf_counter() - started
        )
    say("statistics and figures" if figures else "statistics")
    stats = write_study_outputs(out_dir, scene, case_files, figures)
    return StudyResult(out_dir, stats, ran, skipped, seconds, True, time.perf_counter() - started)


def write_study_outputs(out_dir, scene, case_files, figures=True):
    """``stats.json``, the figures and ``summary.md`` (last) of finished case files.

    Returns
    -------
    dict
        The ``stats.json`` document.
    """
    from rimcl.figures import write_figures
    from rimcl.stats import check_cases, compute_stats, load_render, write_json

    all_tables = []
    for path in case_files:
        tables = load_render(path)
        if tables.case != path.stem:
            raise RimclError(f"{path} holds case {tables.case!r}, not {path.stem!r}")
        all_tables.append(tables)
    all_tables = check_cases(all_tables)
    stats = compute_stats(all_tables, config={"scene": scene, "study_dir": str(out_dir)})
    if figures:
        write_figures(all_tables, stats, out_dir / "figures", overwrite=True)
    write_json(out_dir / "stats.json", stats, overwrite=True)
    _write_text(out_dir / "summary.md", summary_markdown(stats, scene))
    return stats


def _percent(value):
    return "n/a" if value is None else f"{100 * value:.3g} %"


def _number(value):
    return "n/a" if value is None else f"{value:.3g}"


def _case_row(case):
    velocity, acceleration = case["velocity"]["u3"], case["acceleration"]["a3"]
    return [
        case["name"],
        _number(case["G"]),
        _number(case["delta_n_max"]),
        f"{case['n_used']}/{case['n_tracers']}",
        _number(case["position_error_peak_over_L"]),
        _percent(velocity["systematic"]),
        _percent(velocity["random"]),
        _percent(acceleration["systematic"]),
        _percent(acceleration["random"]),
    ]


def _table(header, rows):
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    lines += ["| " + " | ".join(row) + " |" for row in rows]
    return lines


def summary_markdown(stats, scene):
    """The study's summary table as Markdown, beside the paper's values for air and water.

    Parameters
    ----------
    stats : dict
        The ``stats.json`` document.
    scene : dict
        The scene of the study.

    Returns
    -------
    str
    """
    cases = stats["cases"]
    first = cases[0]
    camera = scene["camera"]
    rays = (
        f"plane camera, {camera['fan']}×{camera['fan']} rays per tracer"
        if camera["kind"] == "plane"
        else f"pupil camera, {camera['pupil_rays']} rays per tracer"
    )
    field = scene["field"]["path"] or "the shipped 64³ sample (buoyancy-driven mixing)"
    stamp = datetime.now(timezone.utc).strftime("%Y-%m-%d %H:%M UTC")
    devices = ", ".join(
        sorted({str(entry.get("device", {}).get("device")) for entry in stats["config"]["inputs"]})
    )
    lines = [
        f"# rimcl study: {len(cases)} cases",
        "",
        f"rimcl {__version__}, {stamp}. Field: {field}. {scene['tracers']['count']} tracers, "
        f"{rays}, {scene['renderer']['kind']} renderer, {scene['renderer']['pixels']} pixels "
        f"across the field of view (pixel = {first['pixel_size_over_L']:.3g} L), "
        f"L = {first['length_L']:.4g}, Δt = {first['dt']:.3g}.",
        f"Device: {devices}. Configuration: `scene.toml`; every number and the software "
        "versions: `stats.json`; figures with their data: `figures/`.",
        "",
        "## Results",
        "",
        "Errors from refraction only: position `ε_x = x' − x^ref`, velocity "
        "`ε_u = u' − u^ref`, acceleration `ε_a = a' − a^ref` (measured through the field "
        "minus measured through a uniform medium). *Systematic* = mean of `ε/truth`, "
        "*random* = its standard deviation (the paper's definitions), for the `x3` "
        "components, in percent (`stats.json` holds fractions).",
        "",
    ]
    header = [
        "case",
        "G = Kρ",
        "Δn_max",
        "tracers used",
        "position-error peak / L",
        "u3 systematic",
        "u3 random",
        "a3 systematic",
        "a3 random",
    ]
    lines += _table(header, [_case_row(case) for case in cases])
    lines += [
        "",
        "The random errors are standard deviations of ratios whose denominators come "
        "close to zero for some tracers: they are dominated by the few slowest tracers. "
        "The robust companions below do not have that weakness. Where `rms(ε_u)/rms(u)` "
        "grows more slowly than G, the velocity error is mostly the rounding noise of the "
        "10-bit images (a few 1e-4 px per frame), not refraction. *Baseline* is the error "
        "of finite differences and rendering without refraction (`u^ref − u`, "
        "`a^ref − a`), which every PTV measurement has.",
        "",
    ]
    header = [
        "case",
        "u3: median, IQR",
        "rms(ε_u)/rms(u)",
        "baseline rms(ε_u)/rms(u)",
        "a3: median, IQR",
        "rms(ε_a)/rms(a)",
        "baseline rms(ε_a)/rms(a)",
    ]
    rows = []
    for case in cases:
        u3, a3 = case["velocity"]["u3"], case["acceleration"]["a3"]
        rows.append(
            [
                case["name"],
                f"{_percent(u3['median'])}, {_percent(u3['iqr'])}",
                _percent(u3["rms_normalized"]),
                _percent(case["baseline"]["velocity"]["u3"]["rms_normalized"]),
                f"{_percent(a3['median'])}, {_percent(a3['iqr'])}",
                _percent(a3["rms_normalized"]),
                _percent(case["baseline"]["acceleration"]["a3"]["rms_normalized"]),
            ]
        )
    lines += _table(header, rows)
    excluded = [
        f"{case['name']}: "
        + (", ".join(f"{n} {name}" for name, n in case["n_excluded"].items() if n) or "none")
        for case in cases
    ]
    lines += ["", "Tracers left out (a tracer may carry several flags): " + "; ".join(excluded)]
    lines += [
        "",
        "## Against the paper (air C1, water C4)",
        "",
        "**The flows differ.** The paper traced a 1024³ JHTDB direct numerical simulation "
        "of homogeneous buoyancy-driven turbulence (Re = 12500) over its own depth L, with "
        "1e5 tracers, 100×100 rays each and 8192² pixels; this study uses the field, depth "
        "and sizes above. Only orders of magnitude and trends with G can agree; no "
        "agreement of the numbers themselves is expected.",
        "",
    ]
    by_name = {case["name"]: case for case in cases}
    header = [
        "",
        "Δn_max",
        "position-error peak / L",
        "velocity systematic",
        "velocity random",
        "acceleration systematic",
        "acceleration random",
    ]
    rows = []
    for name, paper in PAPER_VALUES.items():
        rows.append(
            [
                f"paper, {paper['fluid']} ({name})",
                paper["delta_n_max"],
                paper["position_peak_over_L"],
                paper["velocity_systematic"],
                paper["velocity_random"],
                paper["acceleration_systematic"],
                paper["acceleration_random"],
            ]
        )
        case = by_name.get(name)
        if case is None:
            rows.append([f"rimcl, {name}", *["not run"] * 6])
        else:
            row = _case_row(case)
            rows.append([f"rimcl, {name}", row[2], row[4], *row[5:]])
    lines += _table(header, rows)
    lines += ["", f"Paper: {PAPER_SOURCE}. Where: {PAPER_CITATIONS}", ""]
    return "\n".join(lines)
