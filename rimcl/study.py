"""The whole chain over refractive-index cases (``rimcl study``): resumable, atomic.

A study directory holds:

- ``scene.toml``: the scene actually used (written first; a rerun with another scene is
  refused unless ``force``);
- ``cases/<case>.h5``: one ``rimcl render`` file per case, written atomically when the
  case is finished; a rerun skips the cases whose file exists;
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
from pathlib import Path

from rimcl.errors import RimclError
from rimcl.provenance import atomic_path
from rimcl.scene import load_scene, render_arguments, scene_text
from rimcl.summary import summary_markdown

#: Scene keys that do not change the measurement: a study may resume with other values.
RUN_ONLY_KEYS = (("run", "device"), ("run", "rays_per_batch"))


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


def run_study(scene, out_dir, *, force=False, figures=True, progress=False, report=None):
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
    references = {}  # threshold -> reference images (they depend on it, not on the case)
    for index, name in enumerate(names, start=1):
        path = case_path(out_dir, name)
        if path.exists() and not force:
            skipped.append(name)
            say(f"[{index}/{len(names)}] {name}: finished earlier, kept ({path})")
            continue
        say(f"[{index}/{len(names)}] {name}: measuring")
        case_start = time.perf_counter()
        arguments = render_arguments(scene, name)
        result = run_render(
            **arguments, reference=references.get(arguments["threshold"]), progress=progress
        )
        references[arguments["threshold"]] = result.reference
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
