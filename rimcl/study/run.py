"""The whole chain over refractive-index cases (``rimcl study``): resumable, atomic.

A study directory holds:

- ``.rimcl-study``: the marker that rimcl's study made this directory (a directory holding
  a ``summary.md`` or ``stats.json`` without it is refused, never overwritten); also the
  lock that keeps a second study from running in the same directory at once;
- ``scene.toml``: the scene of the case files, written once the scene has proven itself
  (its first case measured, or its finished cases checked), never by a run that failed
  before; a rerun with another scene is refused unless ``force``;
- ``cases/<case>.h5``: one ``rimcl render`` file per case, written atomically when the
  case is finished, recording the study's scene. A rerun keeps a case file only after
  :func:`check_case_file` found it readable, complete and made for this scene; anything
  else is measured again, with one line saying why;
- ``piv/<case>.h5`` with ``run.mode = "piv"`` or ``"both"``: the PIV errors of each case
  (:mod:`rimcl.piv.study`), kept on a rerun when complete and of the same scene;
- with ``run.mode = "lpt"`` instead: ``lpt/`` and ``figures/lpt_*`` (:mod:`rimcl.lpt.study`);
- ``shards/<case>/<first>-<stop>.h5``: with a Dask scheduler (``run.scheduler``), the
  finished shards of tracers, merged into the case files (:mod:`rimcl.study.distributed`);
- ``stats.json`` and ``figures/``: statistics and figures of all cases (:mod:`rimcl.stats.document`,
  :mod:`rimcl.stats.figures`; PIV: a ``piv`` entry per case and ``figures/piv_*``);
- ``summary.md``: the paper-style table, beside the paper's values for air and water.
  Written last, so its presence (newer than every case file) means the study is complete
  and a rerun only reads ``stats.json``.

``stats.json``, ``figures/`` and ``summary.md`` always come from case files of the scene
in ``scene.toml``: when a forced run changes the scene, they are removed before the new
``scene.toml`` is written. Partial files (``.<name>.<random>.part``) left by a killed run
are removed by the next one.

Every case uses the same tracers, rays and random numbers (common random numbers), so
case-to-case differences are not noise; the reference images (through a uniform medium)
are computed once and reused.
"""

import contextlib
import dataclasses
import json
import os
import re
import shutil
import time
from pathlib import Path

from rimcl import __version__
from rimcl.core.atomic import atomic_path
from rimcl.core.errors import RimclError
from rimcl.core.outputs import OutputSet
from rimcl.core.provenance import STUDY_MARKER
from rimcl.scene.config import DEFAULT_PSF_SIGMA
from rimcl.scene.load import load_scene
from rimcl.scene.study_config import StudyConfig
from rimcl.study.case_files import (
    SCENE_RECORD,
    case_path,
    check_case_file,
    comparable_scene,
    scene_differences,
)
from rimcl.study.summary import summary_markdown

#: File that marks a directory as a rimcl study (and is locked while a study runs in it).
MARKER = STUDY_MARKER
#: Name of the one case of a field file that stores δn (its own refractive index).
DELTA_N_CASE = "delta_n"
#: Frames every study case images (positions, velocity, acceleration).
# a partial file of rimcl.core.atomic.atomic_path: "." + name + "." + 8 random chars + ".part"
_PART_FILE = re.compile(r"^\..+\.[A-Za-z0-9_]{8}\.part$")


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


def _read_scene_file(scene_path):
    """The study recorded in a study directory; a damaged file is one line of error."""
    try:
        return StudyConfig.from_scene(load_scene(scene_path))
    except (RimclError, ValueError) as exc:  # ValueError: not text at all
        raise RimclError(
            f"{scene_path} is damaged ({exc}); use --force to redo the study, or another --out"
        ) from None


def _check_directory(out_dir, study, force):
    """Refuse to mix the results of two different scenes (the directory exists)."""
    scene_path = out_dir / "scene.toml"
    if force:
        return
    if scene_path.exists():
        previous = comparable_scene(_read_scene_file(scene_path))
        changes = scene_differences(previous, comparable_scene(study))
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


def _written_by_a_study(out_dir):
    """Whether an unmarked directory's stats.json is a study's (rimcl before the marker)."""
    try:
        stats = json.loads((out_dir / "stats.json").read_text())
        config = stats["config"]
        return "study_dir" in config and "scene" in config and (out_dir / "scene.toml").exists()
    except (OSError, ValueError, KeyError, TypeError):
        return False


#: The folders a study writes into and removes files from.
STUDY_FOLDERS = ("cases", "piv", "shards", "figures")


def _check_no_links(out_dir):
    """Refuse a study folder (or a case's shard folder) that is a symbolic link: what the
    study writes, replaces and removes there would land outside the study directory."""
    folders = [out_dir / name for name in STUDY_FOLDERS]
    shards = out_dir / "shards"
    if shards.is_dir() and not shards.is_symlink():
        folders += sorted(shards.iterdir())
    for folder in folders:
        if folder.is_symlink():
            raise RimclError(
                f"{folder} is a symbolic link (to {os.readlink(folder)}); a study writes only "
                "inside its directory: make it a real folder, or use another --out"
            )


@contextlib.contextmanager
def _claimed(out_dir):
    """Create (or adopt) a study directory and hold its lock while a study runs in it."""
    marker = out_dir / MARKER
    foreign = [name for name in ("summary.md", "stats.json") if (out_dir / name).exists()]
    if foreign and not marker.exists() and not _written_by_a_study(out_dir):
        raise RimclError(
            f"{out_dir} holds {' and '.join(foreign)} that rimcl study did not write "
            f"(no {MARKER} marker); choose another --out, or move them away"
        )
    try:
        (out_dir / "cases").mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise RimclError(f"cannot create study directory {out_dir}: {exc.strerror}") from None
    if not marker.exists():
        _write_text(marker, json.dumps({"rimcl_study": 1, "created_by": f"rimcl {__version__}"}))
    with open(marker, "rb") as handle:
        try:
            import fcntl
        except ImportError:  # pragma: no cover - not on POSIX: no lock
            fcntl = None
        if fcntl is not None:
            try:
                fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except OSError:
                raise RimclError(
                    f"another rimcl study is running in {out_dir}; wait for it or use another --out"
                ) from None
        yield


def _remove_stale_parts(out_dir):
    """Remove the partial files a killed run left; returns how many."""
    removed = 0
    for folder in (out_dir, out_dir / "cases", out_dir / "figures", out_dir / "piv"):
        if not folder.is_dir():
            continue
        for path in folder.iterdir():
            if _PART_FILE.match(path.name) and path.is_file():
                path.unlink()
                removed += 1
    return removed


def _write_text(path, text):
    with atomic_path(path, overwrite=True) as tmp:
        Path(tmp).write_text(text)


def study_cases(study):
    """The cases a :class:`~rimcl.scene.study_config.StudyConfig` measures: ``(name, case
    argument)`` pairs.

    A field file that stores ``delta_n`` carries its own refractive index: its study has
    one case, :data:`DELTA_N_CASE`, whatever ``cases.names`` says.

    Returns
    -------
    list of (str, str or None)
    """
    from rimcl.fields.field_reader import field_kind
    from rimcl.fields.sample import sample_path

    path = study.field_path or sample_path()
    if field_kind(path) == "delta_n":
        from rimcl.fields.cases import fluid_case

        fluid_cases = [name for name in study.names if fluid_case(name)]
        if fluid_cases:
            raise RimclError(
                f"{path} stores its refractive index (delta_n): it runs as is, case "
                f"{DELTA_N_CASE}; fluid case {', '.join(fluid_cases)} does not apply "
                f'(set cases.names = ["{DELTA_N_CASE}"])'
            )
        return [(DELTA_N_CASE, None)]
    if DELTA_N_CASE in study.names:
        raise RimclError(
            f"case {DELTA_N_CASE} runs a field file that stores its refractive index; {path} "
            "stores a density: name its cases (C0..C4, G=<value>, dT=<K>, dS=<g/kg>)"
        )
    return [(name, name) for name in study.names]


def _up_to_date(out_dir, case_files, figures, mode="ptv"):
    from rimcl.piv.figures import FIGURE_NAMES as PIV_FIGURE_NAMES
    from rimcl.stats.figures import FIGURE_NAMES

    summary, stats = out_dir / "summary.md", out_dir / "stats.json"
    needed = [summary, stats]
    names = {"ptv": FIGURE_NAMES, "piv": PIV_FIGURE_NAMES}.get(
        mode, FIGURE_NAMES + PIV_FIGURE_NAMES
    )
    if figures:
        needed += [out_dir / "figures" / f"{name}.png" for name in names]
    if not all(path.exists() for path in needed):
        return False
    inputs = [out_dir / "scene.toml", *case_files]
    return summary.stat().st_mtime >= max(path.stat().st_mtime for path in inputs)


def _check_resources(study):
    """Refuse, before anything is written, a scene whose geometry does not fit its field
    or whose sizes do not fit in memory."""
    from rimcl.core.device import select_device
    from rimcl.core.memory import check_render_request
    from rimcl.fields.field_reader import FieldFile
    from rimcl.fields.sample import sample_path
    from rimcl.optics.camera import Scene

    config = study.shared
    path = study.field_path or sample_path()
    with FieldFile(path) as source:
        Scene.from_grid(
            source.origin,
            source.spacing,
            source.shape,
            source.boundary,
            config.x_sheet,
            config.depth,
        )
    camera, renderer = config.camera, config.renderer
    check_render_request(
        source.shape,
        path,
        tracers=config.tracers.count,
        camera=camera.kind,
        fan=camera.fan,
        pupil_rays=camera.pupil_rays,
        rays_per_batch=config.run.rays_per_batch,
        frames=config.time.frames,
        max_window=renderer.max_window,
        pixels=renderer.pixels,
        psf_sigma=renderer.psf_sigma or DEFAULT_PSF_SIGMA,
        interp=config.integrator.interp,
        device=select_device(config.run.device, need_fp64=config.run.engine == "device"),
    )


class _SceneFile:
    """Writes ``scene.toml`` once the scene has proven itself, retiring the statistics of
    another scene first."""

    def __init__(self, out_dir, study):
        self.path, self.study = out_dir / "scene.toml", study
        self.text = study.text

    def settle(self):
        """Make ``scene.toml`` this scene's (before a case file or statistics of it land)."""
        if self.path.exists() and self.path.read_text() == self.text:
            return
        previous = None
        if self.path.exists():
            with contextlib.suppress(RimclError):
                previous = comparable_scene(_read_scene_file(self.path))
        if previous != comparable_scene(self.study):
            # statistics and figures of another scene's case files: never beside this one
            for name in ("summary.md", "stats.json"):
                (self.path.parent / name).unlink(missing_ok=True)
            shutil.rmtree(self.path.parent / "figures", ignore_errors=True)
        _write_text(self.path, self.text)


def run_study(
    scene, out_dir, *, force=False, figures=True, progress=False, report=None, scheduler=None
):
    """Run every case of a scene, then the statistics, figures and summary.

    Parameters
    ----------
    scene : StudyConfig, dict, str or Path
        The study (:class:`rimcl.scene.study_config.StudyConfig`), or a complete scene
        (:func:`rimcl.scene.load.load_scene`) or scene file, parsed into one here.
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
        scene's ``run.scheduler``, "" = this process): see :mod:`rimcl.study.distributed`.
        ``case_seconds`` are then worker seconds. Checked in every mode before anything
        is written (:func:`rimcl.study.scheduler.check_scheduler`).

    Returns
    -------
    StudyResult

    Raises
    ------
    RimclError
        For a directory holding another scene's study or files rimcl did not write, a
        study already running there, an unusable field or device, a scene that cannot fit
        in memory, and every error of the measurement.
    """
    from rimcl.ptv.measure import run_render
    from rimcl.ptv.render_file import write_render

    started = time.perf_counter()
    say = report or (lambda line: None)
    out_dir = Path(out_dir)
    if isinstance(scene, (str, Path)):
        scene = load_scene(scene)
    study = scene if isinstance(scene, StudyConfig) else StudyConfig.from_scene(scene)
    mode = study.run.mode
    all_cases = study_cases(study)
    cases = all_cases if mode in ("ptv", "both") else []
    if study.run.sensitivity and mode in ("piv", "lpt"):
        # the variants re-measure PTV cases: asked for where none run, say so, not nothing
        raise RimclError(
            f'run.sensitivity measures the PTV cases again; run.mode = "{mode}" has none '
            '(use run.mode = "ptv" or "both", or drop run.sensitivity)'
        )
    if mode != "lpt":  # the LPT stage checks its own rig and flow
        _check_resources(study)
    _check_no_links(out_dir)
    if mode != "ptv":
        from rimcl.piv.render import check_piv_scene
        from rimcl.piv.study import configs_from_study

        # bad [piv] keys, a sheet the field cannot hold: refused before anything is written
        check_piv_scene(study.field_path or None, configs_from_study(study)[0])
    scheduler = scheduler or study.run.scheduler
    if scheduler:
        from rimcl.study.distributed import check_scheduler

        # every mode: a scheduler that cannot serve is refused before anything is written
        answered = check_scheduler(scheduler)
        if not cases:
            say(f"Dask: {answered}, not used: PIV cases are measured in this process")
    with _claimed(out_dir):
        _check_no_links(out_dir)  # again under the lock: nothing changes it from here on
        removed = _remove_stale_parts(out_dir)
        if removed:
            say(f"removed {removed} partial file(s) left by an interrupted run")
        _check_directory(out_dir, study, force)
        if all_cases[0][0] == DELTA_N_CASE:
            say(f"{study.field_path} stores delta_n: one case, its own index")
        scene_file = _SceneFile(out_dir, study)
        if mode == "lpt":
            from rimcl.lpt.study import run_lpt_study

            scene_file.settle()
            stats, ran = run_lpt_study(study, out_dir, force=force, figures=figures, report=say)
            kept = [] if ran else [f"lpt/{name}" for name in stats["lpt"]["cases"]]
            elapsed = time.perf_counter() - started
            return StudyResult(out_dir, stats, ran, kept, {}, True, elapsed)
        ran, skipped, seconds = [], [], {}
        todo = cases
        if scheduler and cases:
            from rimcl.study.distributed import measure_cases

            ran, skipped, seconds = measure_cases(
                study,
                out_dir,
                scheduler,
                force=force,
                progress=progress,
                report=say,
                connected=scene_file.settle,
            )
            todo = []  # the cluster measured every case
        # reference images: they depend on the threshold, not on the case (a lens camera's
        # and Mie weights' also on the case's mean index); the one that fits is reused
        references = []
        for index, (name, case) in enumerate(todo, start=1):
            path = case_path(out_dir, name)
            step = f"[{index}/{len(cases)}] {name}"
            reason = None if force or not path.exists() else check_case_file(path, study, name)
            if path.exists() and not force and reason is None:
                skipped.append(name)
                say(f"{step}: finished earlier, kept ({path})")
                continue
            what = f"{path.name} {reason}; measuring again" if reason else "measuring"
            if not ran:  # the longest silence of a study without progress bars
                what += " (the first case also builds the kernels and reference images)"
            say(f"{step}: {what}")
            case_start = time.perf_counter()
            config = study.measure(name)
            result = run_render(
                study.field_path or None,
                case=case,
                config=config,
                reference=references,
                progress=progress,
            )
            if all(r is not result.reference for r in references):
                references.append(result.reference)
            result.config[SCENE_RECORD] = comparable_scene(study)
            scene_file.settle()
            write_render(path, result, overwrite=True)
            seconds[name] = time.perf_counter() - case_start
            ran.append(name)
            say(f"{step}: done in {seconds[name]:.1f} s")
        if cases:
            scene_file.settle()  # every case file checked, or measured
        variant_files = {}
        if study.run.sensitivity and cases:
            from rimcl.study.sensitivity import measure_variants

            variant_files, measured = measure_variants(
                study, out_dir, cases, force=force, progress=progress, say=say
            )
            ran += [f"sensitivity/{name}" for name in measured]
        piv_files = []
        if mode != "ptv":
            from rimcl.piv.study import run_study_cases

            piv_files, piv_ran = run_study_cases(
                study,
                out_dir,
                comparable_scene(study),
                all_cases,
                force=force,
                report=say,
                before_write=scene_file.settle,
                progress=progress,
            )
            scene_file.settle()
            ran += [f"piv/{name}" for name in piv_ran]
            skipped += [f"piv/{name}" for name, _ in all_cases if name not in piv_ran]
        case_files = [case_path(out_dir, name) for name, _ in cases]
        if not force and not ran and _up_to_date(out_dir, case_files + piv_files, figures, mode):
            with contextlib.suppress(OSError, ValueError):
                stats = json.loads((out_dir / "stats.json").read_text())
                say("statistics, figures and summary are up to date")
                return StudyResult(
                    out_dir, stats, ran, skipped, seconds, False, time.perf_counter() - started
                )
        stats = write_study_outputs(
            out_dir, study, case_files, figures, piv_files, progress, variant_files, report=say
        )
    return StudyResult(out_dir, stats, ran, skipped, seconds, True, time.perf_counter() - started)


def physical_equivalents(delta_n_max, fluid):
    """What a case's index difference means physically: the temperature
    difference of air and of water (and the salinity difference of salt water) that gives
    it, at the scene's fluid state (``fluid``, a :class:`rimcl.scene.config.FluidConfig`;
    default 20 °C, 532 nm).

    Returns
    -------
    dict of str to str
        ``{"air": "air at 20 °C, ΔT ≈ 26 K", "water": ..., "saltwater": ...}``.
    """
    from rimcl.fields.media import Fluid, physical_equivalent

    state = {"temperature_c": fluid.temperature_c, "wavelength_nm": fluid.wavelength_nm}
    fluids = {
        "air": Fluid("air", pressure_pa=fluid.pressure_pa, **state),
        "water": Fluid("water", **state),
        "saltwater": Fluid("saltwater", salinity_g_kg=fluid.salinity_g_kg, **state),
    }
    return {name: physical_equivalent(delta_n_max, f).text for name, f in fluids.items()}


def _numerics(study, case, figures_dir, versions):
    """Run the Appendix A check, draw its figure, and return its numbers for stats.json."""
    from rimcl.ptv.numerics import numerical_convergence
    from rimcl.stats.figures_numerics import write_numerics_figure

    numerics = numerical_convergence(study, case)
    write_numerics_figure(numerics, figures_dir, versions)
    runs = numerics["runs"]
    return {
        "case": numerics["case"],
        "median_over_L": {name: run["median_over_L"] for name, run in runs.items()},
        "optics_median_over_L": {name: run["optics_median_over_L"] for name, run in runs.items()},
        **{key: value for key, value in numerics.items() if key.endswith("ratio")},
    }


def _numerics_case(study, names):
    """The case of the Appendix A check (C1, else the first Gladstone–Dale case), or None
    when the scene asks for none or has no such case."""
    from rimcl.fields.cases import CASES

    if not study.run.numerics:
        return None
    if "C1" in names:
        return "C1"
    return next((name for name in names if name in CASES or name.startswith("G=")), None)


def write_study_outputs(
    out_dir,
    study,
    case_files,
    figures=True,
    piv_files=(),
    progress=False,
    variant_files=None,
    report=None,
):
    """``stats.json``, the figures and ``summary.md`` (last) of finished case files
    (PTV render files, PIV case files; ``variant_files``: the sensitivity variants' render
    files, :func:`rimcl.study.sensitivity.measure_variants`); ``progress``: a progress bar
    over the steps (on a terminal); ``report``: told one line as each stage starts.

    The figures are one set (:class:`rimcl.core.outputs.OutputSet`): drawn into staging,
    they replace the earlier ones whole (a figure this run does not draw is removed); with
    ``figures`` False the earlier figures are removed.

    Returns
    -------
    dict
        The ``stats.json`` document.
    """
    # the figures are one set: drawn into staging, they replace the earlier ones whole
    figure_set = OutputSet(out_dir / "figures", overwrite=True, owned=("*",)) if figures else None
    try:
        return _study_outputs(
            out_dir, study, case_files, figure_set, piv_files, progress, variant_files, report
        )
    finally:
        if figure_set is not None:
            figure_set.discard()  # a failed run: the earlier figures stay whole


def _study_outputs(
    out_dir, study, case_files, figure_set, piv_files, progress, variant_files, report
):
    """:func:`write_study_outputs`, the figures drawn into ``figure_set`` (None: none)."""
    from rimcl.ptv.sweep import sweep_stats
    from rimcl.stats.document import check_cases, compute_stats
    from rimcl.stats.figures import write_figures
    from rimcl.stats.figures_dt_sweep import dt_sweep_data, write_dt_sweep_figure
    from rimcl.stats.render_file import load_render
    from rimcl.stats.tables import write_json
    from rimcl.stats.units import write_tidy

    config = {"scene": study.scene_record(), "study_dir": str(out_dir)}
    stats = {"cases": [], "config": config}
    figures = figure_set is not None
    figures_dir = figure_set.staging if figures else None
    # steps: each case file read, PTV statistics, PTV figures, PIV results, PIV figures,
    # the files written
    total = len(case_files) + 2 * bool(case_files) + 2 * bool(piv_files) + 1
    bar = _steps_bar(progress, total)
    say = report or (lambda line: None)
    if case_files:
        say(f"statistics of {len(case_files)} case file(s), with bootstrap intervals")
        all_tables = []
        for path in case_files:
            tables = load_render(path)
            if tables.case != path.stem:
                raise RimclError(f"{path} holds case {tables.case!r}, not {path.stem!r}")
            all_tables.append(tables)
            bar.update()
        all_tables = check_cases(all_tables)
        stats = compute_stats(all_tables, config=config)
        if variant_files:
            from rimcl.study.sensitivity import add_variants

            add_variants(stats, variant_files)
        for case in stats["cases"]:
            case["physical_equivalent"] = physical_equivalents(
                case["delta_n_max"], study.shared.fluid
            )
        bar.update()
        if figures:
            say("figures")
            write_figures(all_tables, stats, figures_dir, overwrite=True)
        bar.update()
        numerics_case = _numerics_case(study, [t.case for t in all_tables])
        if figures and numerics_case is not None:
            say(f"numerics check on {numerics_case}")
            stats["numerics"] = _numerics(study, numerics_case, figures_dir, stats["versions"])
        multiples = sorted(set(study.dt_multiples) - {1})
        if multiples:
            say(f"Δt sweep: statistics at {', '.join(f'{m} Δt' for m in multiples)}")
            by_dt = sweep_stats(
                all_tables, multiples, study.shared.time, lambda t: compute_stats(t, config=config)
            )
            if by_dt:
                by_dt[float(all_tables[0].dt)] = stats
                if figures:
                    stats["dt_sweep"] = write_dt_sweep_figure(by_dt, figures_dir)
                else:
                    stats["dt_sweep"] = dt_sweep_data(by_dt)
    if piv_files:
        from rimcl.piv.comparison import side_by_side
        from rimcl.piv.figures import write_piv_figures
        from rimcl.piv.study import add_study_results
        from rimcl.study.answer import piv_units

        say(f"PIV statistics of {len(piv_files)} case file(s)" + (", figures" if figures else ""))
        piv_cases = add_study_results(stats, piv_files)
        for case in stats["cases"]:
            if "piv_vs_ptv" in case:  # what each measured with: like for like or not
                case["piv_vs_ptv"]["settings"] = side_by_side(study, case, case["piv"])
            if "piv" in case:
                case["piv"]["units"] = piv_units(
                    case["piv"], study.shared.camera.length_m, study.shared.time.time_s
                )
        bar.update()
        if figures:
            write_piv_figures(piv_cases, figures_dir, config=config, overwrite=True)
        bar.update()
    write_json(out_dir / "stats.json", stats, overwrite=True)
    write_tidy(out_dir / "stats.csv", stats)
    if figure_set is not None:
        figure_set.commit()
    else:  # figures of earlier numbers: never beside these statistics
        shutil.rmtree(out_dir / "figures", ignore_errors=True)
    _write_text(out_dir / "summary.md", summary_markdown(stats, study))
    bar.update()
    bar.close()
    return stats


def _steps_bar(enabled, total):
    """A progress bar over the statistics-and-figures steps (disabled: does nothing)."""
    from tqdm.auto import tqdm

    return tqdm(
        total=total, unit="step", desc="statistics and figures", disable=None if enabled else True
    )
