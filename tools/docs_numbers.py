"""Regenerate the numbers the documentation quotes from runs, and write them into the pages.

Every number in ``README.md`` and ``docs/**/*.md`` that comes from a run of rimcl is marked
in the page by an HTML comment right after it, naming its key::

    | C0 | 0.013<!--n:study.C0.u3.optics--> % | ...

and every program output quoted as a block is preceded by ``<!--block:KEY-->``. The
comments are invisible on GitHub and in the built site. This script

- ``run``: runs what the pages quote (the default study, the water-tank tutorial's study,
  the default lens's closed forms, …) at the sizes the pages state, and writes every number
  to ``docs/_static/numbers.json`` with the machine, the load, the versions and the hash of
  the configuration that made them (:func:`config_hash`);
- ``apply``: rewrites every marked number and block of the pages from that file;
- ``check``: exits 1 where a page differs from the file or the file from the current
  configuration (``tests/test_docs_numbers.py`` does the same, without running anything).

Usage, from the repository root::

    python tools/docs_numbers.py run            # full size: ~15 min on a quiet 2-core CPU
    python tools/docs_numbers.py run --small    # 12 tracers per study: a smoke test
    python tools/docs_numbers.py apply          # then read the diff (git diff): prose around
                                                # changed numbers may need a new verdict
    python tools/docs_numbers.py check

``run --only study,lens`` reruns some jobs and keeps the others' numbers. A job whose
output lacks a key records ``null`` (written "n/a" in the pages) and is listed at the end,
so that a renamed ``stats.json`` key is seen, not silently skipped.
"""

import argparse
import hashlib
import itertools
import json
import math
import os
import platform
import re
import resource
import shutil
import subprocess
import sys
import tempfile
import time
from datetime import datetime, timezone
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
NUMBERS = ROOT / "docs" / "_static" / "numbers.json"
SCHEMA = 1

#: ``0.62<!--n:key-->``: the number right before the comment (sign, digits, exponent).
NUMBER_MARK = re.compile(r"(n/a|[-−+]?\d[\d,]*(?:\.\d+)?(?:e[-−+]?\d+)?)<!--n:([\w.:=+\-]+)-->")
#: ``baseline<!--t:key-->``: a word a run decides (the dominant part of a budget).
WORD_MARK = re.compile(r"([A-Za-z_]+)<!--t:([\w.:=+\-]+)-->")
#: ``<!--block:key-->`` then a fenced block: the block's body is the program output ``key``.
BLOCK_MARK = re.compile(r"<!--block:([\w.:=+\-]+)-->\n(```[a-z]*\n)(.*?)(```)", re.DOTALL)

CASES = ("C0", "C1", "C2", "C3", "C4")


def pages():
    """The Markdown pages that may quote numbers: README.md and docs/**/*.md."""
    found = [ROOT / "README.md"]
    found += sorted(
        p
        for p in (ROOT / "docs").rglob("*.md")
        if "_build" not in p.parts and "_generated" not in p.parts
    )
    return found


# --- number formatting ------------------------------------------------------------------------


def fmt(value, digits=2, scale=1.0, decimals=None, sci=False):
    """A number as the pages write it.

    Parameters
    ----------
    value : float or None
        None or non-finite: ``n/a``.
    digits : int
        Significant digits (``decimals`` overrides: that many after the point).
    scale : float
        Multiplied in first (100 for a percentage).
    sci : bool
        Always ``mantissa e exponent`` (a column of small magnitudes).

    Returns
    -------
    str
        Plain decimals from 1e-4 to 1e5 (``0.00073``, ``370``), else ``3.8e-7``.
    """
    if value is None or not math.isfinite(float(value)):
        return "n/a"
    v = float(value) * scale
    if decimals is not None:
        return f"{v:.{decimals}f}"
    if v == 0:
        return "0"
    exponent = math.floor(math.log10(abs(v)))
    if sci or exponent < -4 or exponent >= 5:
        mantissa = f"{v / 10**exponent:.{digits - 1}f}"
        if float(mantissa) >= 10:  # 9.96 → 10 at 2 digits: one more power
            exponent += 1
            mantissa = f"{v / 10**exponent:.{digits - 1}f}"
        return f"{mantissa}e{exponent}"
    rounded = round(v, digits - 1 - exponent)
    places = max(0, digits - 1 - exponent)
    return f"{rounded:.{places}f}"


# --- reading outputs --------------------------------------------------------------------------


def dig(document, path):
    """The value at a dotted path; ``cases[C0]`` picks the case named C0. None if absent."""
    node = document
    for part in re.split(r"\.(?![^\[]*\])", path):  # no split inside [dT=0.3]
        match = re.fullmatch(r"(\w+)\[(.+)\]", part)
        try:
            if match:
                node = node[match[1]]
                node = next(
                    c for c in node if c.get("name") == match[2] or c.get("case") == match[2]
                )
            elif isinstance(node, list):
                node = node[int(part)]
            else:
                node = node[part]
        except (KeyError, IndexError, StopIteration, TypeError, ValueError):
            return None
    return node


class Collector:
    """The numbers of one run: ``put`` a value with its page format, keep what was missing."""

    def __init__(self):
        self.numbers = {}
        self.blocks = {}
        self.missing = []

    def put(self, key, value, digits=2, scale=1.0, unit="", source="", decimals=None, sci=False):
        if value is None:
            self.missing.append(f"{key} ({source})")
        self.numbers[key] = {
            "value": value,
            "text": fmt(value, digits, scale, decimals, sci),
            "unit": unit,
            "source": source,
        }

    def put_word(self, key, word, source=""):
        if word is None:
            self.missing.append(f"{key} ({source})")
        self.numbers[key] = {
            "value": word,
            "text": "n/a" if word is None else str(word),
            "source": source,
        }

    def put_from(self, key, document, path, where, **kw):
        self.put(key, dig(document, path), source=f"{where}: {path}", **kw)


# --- the jobs ---------------------------------------------------------------------------------


def _rimcl():
    here = Path(sys.executable).with_name("rimcl")
    return [str(here)] if here.exists() else [sys.executable, "-m", "rimcl"]


#: ``run --reuse``: read the outputs a kept folder holds instead of running again (timings n/a)
REUSE = False


def _run(argv, log, out, ok=(0,)):
    """Run one rimcl command into a fresh ``out`` (a folder, or the file its stdout goes to);
    its wall and CPU seconds (children's user + system). With :data:`REUSE` and a finished
    ``out``: nothing run, (None, None)."""
    out = Path(out)
    if REUSE and ((out / "stats.json").exists() or out.is_file()):
        return None, None
    shutil.rmtree(out, ignore_errors=True)  # a kept folder: never resume an older run
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    start = time.perf_counter()
    with open(log, "w", encoding="utf-8") as messages:
        stdout = open(out, "w", encoding="utf-8") if out.suffix == ".json" else messages
        with stdout:
            done = subprocess.run(_rimcl() + argv, stdout=stdout, stderr=messages, cwd=ROOT)
    wall = time.perf_counter() - start
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    if done.returncode not in ok:
        tail = Path(log).read_text(encoding="utf-8")[-2000:]
        raise RuntimeError(f"rimcl {' '.join(argv)} failed ({done.returncode}):\n{tail}")
    return wall, cpu


def _stats(directory):
    return json.loads((Path(directory) / "stats.json").read_text(encoding="utf-8"))


def _budget(c, stats, prefix, where, cases):
    """The error-budget table of a study: rms(ε_u3)/rms(u3) of the differences, in %."""
    for case in cases:
        base = f"cases[{case}]"
        for part, path in (
            ("optics", "optics.velocity.u3"),
            ("imaging", "imaging.velocity.u3"),
            ("total", "velocity.u3"),
            ("noise_floor", "noise_floor.velocity.u3"),
            ("baseline", "baseline.velocity.u3"),
        ):
            key = f"{prefix}.{case}.u3.{part}"
            c.put_from(
                key, stats, f"{base}.{path}.rms_normalized", where, digits=2, scale=100, unit="%"
            )
            for end, index in (("lo", 0), ("hi", 1)):
                c.put_from(
                    f"{key}.{end}",
                    stats,
                    f"{base}.{path}.ci95.rms_normalized.{index}",
                    where,
                    digits=2,
                    scale=100,
                    unit="%",
                )
        c.put_from(f"{prefix}.{case}.used", stats, f"{base}.n_used", where, decimals=0)
        c.put_from(f"{prefix}.{case}.tracers", stats, f"{base}.n_tracers", where, decimals=0)
        for flag in ("below_threshold", "split", "no_rays"):
            key, path = f"{prefix}.{case}.excluded.{flag}", f"{base}.n_excluded.{flag}"
            c.put_from(key, stats, path, where, decimals=0)
        key, path = (
            f"{prefix}.{case}.position_median_over_L",
            f"{base}.position_error_median_over_L",
        )
        c.put_from(key, stats, path, where, digits=3, sci=True)
        for name, group in (("u3_fit", "velocity_fit.u3"), ("a3_fit", "acceleration_fit.a3")):
            path = f"{base}.baseline.{group}.rms_normalized"
            c.put_from(f"{prefix}.{case}.{name}.baseline", stats, path, where, scale=100, unit="%")
    # the growth of the optics part from case to case (G grows ×8.4, ×11.8)
    for a, b in itertools.pairwise(cases):
        x = dig(stats, f"cases[{a}].optics.velocity.u3.rms_normalized")
        y = dig(stats, f"cases[{b}].optics.velocity.u3.rms_normalized")
        ratio = y / x if x and y is not None else None
        c.put(
            f"{prefix}.optics_ratio.{a}-{b}", ratio, digits=3, source=f"{where}: optics u3 {b}/{a}"
        )
    dts = dig(stats, "dt_sweep.dt") or [None]
    for end, index in (("first", 0), ("last", -1)):
        c.put(f"{prefix}.dt_sweep.dt.{end}", dts[index], digits=2, source=f"{where}: dt_sweep.dt")
    for case in cases:
        x = dig(stats, f"cases[{case}].optics.velocity.u3.rms_normalized")
        y = dig(stats, f"cases[{case}].imaging.velocity.u3.rms_normalized")
        ratio = y / x if x and y is not None else None
        c.put(
            f"{prefix}.{case}.imaging_over_optics",
            ratio,
            digits=2,
            source=f"{where}: u3 imaging/optics",
        )
        # the Δt sweep: the baseline of u3 at the first and the last frame spacing
        sweep = dig(stats, f"dt_sweep.cases.{case}") or {}
        baseline = (sweep.get("velocity.u3") or {}).get("baseline") or [None]
        for end, index in (("first", 0), ("last", -1)):
            c.put(
                f"{prefix}.{case}.dt_sweep.u3_baseline.{end}",
                baseline[index],
                digits=3,
                scale=100,
                unit="%",
                source=f"{where}: dt_sweep.cases.{case}['velocity.u3'].baseline[{index}]",
            )


def _lens(c, scale, work):
    """The default lens camera's closed forms (no run): what every page says of the camera."""
    from rimcl.optics.camera import Scene
    from rimcl.scene.config import MeasureConfig
    from rimcl.scene.load import load_scene

    scene = load_scene()
    box = Scene(0.0, 2 * math.pi, (0.0, 0.0), (2 * math.pi, 2 * math.pi), True)
    camera = MeasureConfig.from_scene(scene, "C1").camera.build(box, 1.0)
    where = "default scene, LensCamera"
    c.put("lens.f_number", camera.f_number, decimals=0, source=where)
    c.put("lens.na", camera.numerical_aperture, digits=2, source=where)
    c.put("lens.aperture_mm", camera.aperture_mm, digits=3, unit="mm", source=where)
    c.put("lens.dof_mm", camera.depth_of_field_mm, digits=2, unit="mm", source=where)
    c.put("lens.diffraction_um", camera.diffraction_diameter_um, digits=3, unit="µm", source=where)
    c.put("lens.image_um", camera.image_diameter_um, digits=3, unit="µm", source=where)
    c.put("lens.image_px", 4 * camera.psf_sigma_px, digits=3, unit="px", source=where)
    c.put("lens.image_px2", 4 * camera.psf_sigma_px, digits=2, unit="px", source=where)
    c.put("lens.sigma_px", camera.psf_sigma_px, digits=2, unit="px", source=where)
    c.put("sample.time_s", scene["field"]["time_s"], digits=2, unit="s", source="shipped sample")
    dt = scene["time"]["dt"] or 0.02
    c.put(
        "sample.dt_ms",
        dt * scene["field"]["time_s"] * 1e3,
        digits=2,
        unit="ms",
        source="shipped sample",
    )
    return {"wall_s": 0.0, "cpu_s": 0.0}


def _study(c, scale, work):
    """``rimcl study --out study-out``: the default study (400 tracers at full size)."""
    out = work / "study-out"
    argv = ["study", "--out", str(out), "--no-progress"]
    if scale == "small":
        argv += ["--tracers", "12", "--no-figures"]
    wall, cpu = _run(argv, work / "study.log", out)
    stats = _stats(out)
    where = "rimcl study --out study-out, stats.json"
    _budget(c, stats, "study", where, CASES)
    if wall is not None:  # a reused run keeps the timing of the run that made it
        c.put(
            "time.study.wall_s", wall, digits=2, unit="s", source="wall clock of the whole command"
        )
        c.put("time.study.cpu_s", cpu, digits=2, unit="s", source="CPU seconds of the command")
    return {
        "wall_s": wall,
        "cpu_s": cpu,
        "argv": argv,
        "device": dig(stats, "config.inputs.0.device"),
    }


def _tank(c, scale, work):
    """The water-tank tutorial: ``rimcl study data_samples/scenes/water_tank.toml --tracers 30``."""
    out = work / "tank"
    tracers = "30" if scale == "full" else "8"
    argv = [
        "study",
        "data_samples/scenes/water_tank.toml",
        "--out",
        str(out),
        "--tracers",
        tracers,
        "--no-progress",
    ]
    wall, cpu = _run(argv, work / "tank.log", out)
    stats = _stats(out)
    where = "water-tank tutorial, stats.json"
    for case in ("dT=0.3", "dT=3", "dT=30"):
        base = f"cases[{case}].units"
        for unit, digits in (("um", 3), ("px", 3)):
            path = f"{base}.position.median.{unit}"
            c.put_from(f"tank.{case}.position_{unit}", stats, path, where, digits=digits)
        for part in ("rms_total", "rms_refraction", "rms_baseline", "rms_truth"):
            path = f"{base}.velocity_fit.vector.{part}.mm_s"
            c.put_from(f"tank.{case}.u_fit.{part}", stats, path, where, digits=3, unit="mm/s")
        total = dig(stats, f"{base}.velocity_fit.vector.rms_total.mm_s")
        truth = dig(stats, f"{base}.velocity_fit.vector.rms_truth.mm_s")
        share = total / truth if total is not None and truth else None
        c.put(f"tank.{case}.u_fit.total_pct", share, digits=2, scale=100, unit="%", source=where)
    if wall is not None:  # a reused run keeps the timing of the run that made it
        c.put(
            "time.tank.wall_s",
            wall,
            digits=2,
            unit="s",
            source="wall clock of the tutorial's command",
        )
    _scene_table(c, stats, "water", where)
    summary = (out / "summary.md").read_text(encoding="utf-8")
    # what the tutorial's `sed -n '/^## Your answer/,/^## Headline/p'` prints
    c.blocks["tank.answer"] = _section(summary, "## Your answer", "## Headline")
    csv = out / "stats.csv"
    if csv.exists():
        c.blocks["tank.csv"] = _fit_table(csv)
    return {"wall_s": wall, "cpu_s": cpu, "argv": argv}


def _scene_table(c, stats, prefix, where):
    """A shipped scene's row per case: Δn_max, position-error peak, rms(ε_u3)/rms(u3) and the
    budget's dominant part (the physical-scenes page)."""
    for case in stats.get("cases", []):
        name, base = case.get("name"), f"cases[{case.get('name')}]"
        c.put_from(f"{prefix}.{name}.delta_n_max", stats, f"{base}.delta_n_max", where, sci=True)
        c.put_from(
            f"{prefix}.{name}.peak_over_L",
            stats,
            f"{base}.position_error_peak_over_L",
            where,
            sci=True,
        )
        c.put_from(f"{prefix}.{name}.peak_px", stats, f"{base}.position_error_peak_px", where)
        c.put_from(
            f"{prefix}.{name}.u3",
            stats,
            f"{base}.velocity.u3.rms_normalized",
            where,
            scale=100,
            unit="%",
        )
        c.put_word(
            f"{prefix}.{name}.dominant", dig(stats, f"{base}.budget_verdict.dominant"), where
        )


def _air(c, scale, work):
    """The air scene of the physical-scenes page: ``rimcl study data_samples/scenes/air.toml
    --tracers 30``."""
    out = work / "air"
    tracers = "30" if scale == "full" else "8"
    argv = ["study", "data_samples/scenes/air.toml", "--out", str(out), "--tracers", tracers]
    wall, cpu = _run([*argv, "--no-progress", "--no-figures"], work / "air.log", out)
    _scene_table(c, _stats(out), "air", "air scene, stats.json")
    return {"wall_s": wall, "cpu_s": cpu, "argv": argv}


#: The default study of earlier versions: the paper's kind of fan on a noiseless 10-bit camera.
FAN_SCENE = """[camera]
kind = "plane"
fan = 24
[renderer]
pixels = 2048
psf_sigma = 7.0
threshold = 40.0
bit_depth = 10
[sensor]
noise = false
[mie]
enabled = false
"""


def _fan(c, scale, work):
    """The noiseless fan (plane camera, 24² rays, 2048 px, σ = 7 px, threshold 40 of 10 bits,
    no Mie weights), 400 tracers: the rounding floor and the fan-to-lens comparison."""
    scene = work / "fan.toml"
    scene.write_text(FAN_SCENE, encoding="utf-8")
    out = work / "fan"
    argv = ["study", str(scene), "--out", str(out), "--no-progress", "--no-figures"]
    if scale == "small":
        argv += ["--tracers", "12"]
    wall, cpu = _run(argv, work / "fan.log", out)
    stats = _stats(out)
    _budget(c, stats, "fan", "the noiseless fan, stats.json", CASES)
    # the lens (the default study) against the fan, where both were run
    lens = Path(work / "study-out" / "stats.json")
    if lens.exists():
        lens = json.loads(lens.read_text(encoding="utf-8"))
        for case in CASES:
            for name, path in (
                ("position_median_over_L", "position_error_median_over_L"),
                ("u3.optics", "optics.velocity.u3.rms_normalized"),
            ):
                x = dig(stats, f"cases[{case}].{path}")
                y = dig(lens, f"cases[{case}].{path}")
                ratio = y / x if x and y is not None else None
                c.put(f"fan.{case}.lens_over_fan.{name}", ratio, source="study-out / fan")
    return {"wall_s": wall, "cpu_s": cpu, "argv": argv}


def _verify(c, scale, work):
    """``rimcl verify --json``: the integrator against closed forms (the accuracy page)."""
    out = work / "verify.json"
    # status 1: a case missed its tolerance, still a result to quote
    wall, cpu = _run(["verify", "--json"], work / "verify.log", out, ok=(0, 1))
    result = json.loads(out.read_text(encoding="utf-8"))
    where = "rimcl verify --json"
    for row in result.get("rows", []):
        case = row["case"].replace(" ", "_")
        interp = "analytic" if row["interpolation"] == "analytic" else "grid"
        key = f"verify.{case}.{interp}.{row['precision']}"
        c.put(key, row.get("max_error"), source=f"{where}: {row['case']}, {row['interpolation']}")
    ratios = dig(result, "convergence.ratios") or []
    for index, ratio in enumerate(ratios):
        c.put(f"verify.convergence.{index}", ratio, digits=3, source=f"{where}: convergence")
    c.put("verify.f32_drift", dig(result, "f32_drift.f32"), source=f"{where}: f32_drift")
    return {"wall_s": wall, "cpu_s": cpu, "passed": result.get("passed")}


def _locking(c, scale, work):
    """Why the default lens is f/11: the noiseless baseline of the sliding fit's a3 at C0
    through f/8 (1.94 px images) and f/11 (2.65 px), 100 tracers each."""
    wall = cpu = 0.0
    for f_number in (8, 11):
        scene = work / f"locking-f{f_number}.toml"
        tracers = 100 if scale == "full" else 12
        scene.write_text(
            f'[cases]\nnames = ["C0"]\n[tracers]\ncount = {tracers}\n'
            f"[sensor]\nnoise = false\n[camera]\nf_number = {f_number}.0\n",
            encoding="utf-8",
        )
        out = work / f"locking-f{f_number}"
        argv = ["study", str(scene), "--out", str(out), "--no-progress", "--no-figures"]
        w, u = _run(argv, work / f"locking-f{f_number}.log", out)
        wall, cpu = (None, None) if w is None else (wall + w, cpu + u)
        stats = _stats(out)
        where = f"C0, noiseless camera, f/{f_number}, stats.json"
        camera = dig(stats, "config.inputs.0.config.camera") or {}
        sigma = camera.get("psf_sigma_px")
        c.put(
            f"locking.f{f_number}.image_px",
            None if sigma is None else 4 * sigma,
            digits=3,
            source=where,
        )
        for group, q in (("acceleration_fit", "a3"), ("acceleration_fit", "a2")):
            path = f"cases[C0].baseline.{group}.{q}.rms_normalized"
            key = f"locking.f{f_number}.{q}_fit"
            c.put_from(key, stats, path, where, scale=100, unit="%")
            for end, index in (("lo", 0), ("hi", 1)):
                path = f"cases[C0].baseline.{group}.{q}.ci95.rms_normalized.{index}"
                c.put_from(f"{key}.{end}", stats, path, where, scale=100, unit="%")
    return {"wall_s": wall, "cpu_s": cpu}


def _section(text, first, last):
    """The lines of a summary.md from the heading ``first`` up to the heading that starts with
    ``last`` (not included); a note where ``first`` is missing."""
    lines = text.splitlines()
    try:
        start = next(i for i, line in enumerate(lines) if line.strip() == first)
    except StopIteration:
        return f"(summary.md has no section {first!r})\n"
    end = next((i for i in range(start + 1, len(lines)) if lines[i].startswith(last)), len(lines))
    return "\n".join(lines[start:end]).rstrip() + "\n"


def _fit_table(csv):
    """The tutorial's pandas table: velocity_fit, vector, mm/s, one row per case."""
    try:
        import pandas as pd
    except ImportError:
        return "(pandas not installed)\n"
    table = pd.read_csv(csv)
    rows = table[(table.quantity == "velocity_fit") & (table.component == "vector")]
    return (
        rows[rows.unit == "mm/s"]
        .pivot(index="case", columns="statistic", values="value")
        .to_string()
        + "\n"
    )


#: name: (function, what it runs); ``run`` runs them in this order.
JOBS = {
    "lens": (_lens, "the default lens's closed forms (no run)"),
    "study": (_study, "rimcl study --out study-out (the default study)"),
    "tank": (_tank, "rimcl study data_samples/scenes/water_tank.toml --tracers 30"),
    "air": (_air, "rimcl study data_samples/scenes/air.toml --tracers 30"),
    "verify": (_verify, "rimcl verify --json"),
    "fan": (_fan, "the noiseless fan of earlier versions (24² rays), 400 tracers"),
    "locking": (_locking, "C0 on a noiseless camera through f/8 and f/11, 100 tracers each"),
}


# --- provenance -------------------------------------------------------------------------------


def config_hash():
    """Hash of what decides the numbers besides the code: the default scene (every key and
    default, as ``rimcl study --print-default-scene`` prints it), the shipped scenes, the
    shipped sample and the job definitions of this script.

    Returns
    -------
    str
        sha256, hex.
    """
    from rimcl.fields.sample import sample_path
    from rimcl.scene.load import default_scene_text

    digest = hashlib.sha256(default_scene_text().encode())
    for scene in sorted((ROOT / "data_samples" / "scenes").glob("*.toml")):
        digest.update(scene.name.encode() + scene.read_bytes())
    digest.update(Path(sample_path()).read_bytes())
    for name, (function, what) in JOBS.items():
        digest.update(f"{name}:{what}:{function.__doc__}".encode())
    return digest.hexdigest()


def _machine():
    cpu = platform.processor()
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    return {"cpu": cpu, "cores": os.cpu_count(), "platform": platform.platform()}


def _versions():
    from rimcl.core.provenance import versions

    return versions()


def _git():
    try:
        return subprocess.run(
            ["git", "describe", "--always", "--dirty"],
            cwd=ROOT,
            capture_output=True,
            text=True,
            check=True,
        ).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return None


# --- commands ---------------------------------------------------------------------------------


def load_numbers(path=NUMBERS):
    return json.loads(Path(path).read_text(encoding="utf-8"))


def run(scale, only=None, keep=None, target=NUMBERS):
    target = Path(target)
    previous = (
        load_numbers(target) if target.exists() else {"numbers": {}, "blocks": {}, "jobs": {}}
    )
    names = list(JOBS) if not only else only
    unknown = set(names) - set(JOBS)
    if unknown:
        sys.exit(f"unknown job(s) {sorted(unknown)}; choose from {', '.join(JOBS)}")
    work = Path(keep) if keep else Path(tempfile.mkdtemp(prefix="rimcl-docs-numbers-"))
    work.mkdir(parents=True, exist_ok=True)
    collector = Collector()
    jobs = {k: v for k, v in previous.get("jobs", {}).items() if k not in names}
    numbers = {k: v for k, v in previous.get("numbers", {}).items() if k.split(".")[0] not in names}
    started = time.perf_counter()
    for name in names:
        function, what = JOBS[name]
        load = os.getloadavg()[0]
        print(f"[{name}] {what} ...", flush=True)
        info = function(collector, scale, work)
        info.update(
            scale=scale, load_before=round(load, 1), load_after=round(os.getloadavg()[0], 1)
        )
        info["finished"] = datetime.now(timezone.utc).isoformat(timespec="seconds")
        if info["wall_s"] is None:
            # the timing (if recorded) of the run that made the outputs
            before = previous.get("jobs", {}).get(name, {})
            info.update(reused=True, wall_s=before.get("wall_s"), cpu_s=before.get("cpu_s"))
            print(f"[{name}] reused the kept outputs", flush=True)
        else:
            print(f"[{name}] {info['wall_s']:.0f} s wall, {info['cpu_s']:.0f} s CPU", flush=True)
        jobs[name] = info
    numbers.update(collector.numbers)
    blocks = {**previous.get("blocks", {}), **collector.blocks}
    document = {
        "schema": SCHEMA,
        "made_by": "tools/docs_numbers.py run" + (" --small" if scale == "small" else ""),
        "config_hash": config_hash(),
        "git": _git(),
        "machine": _machine(),
        "versions": _versions(),
        "jobs": jobs,
        "missing": collector.missing,
        "numbers": dict(sorted(numbers.items())),
        "blocks": dict(sorted(blocks.items())),
    }
    target.parent.mkdir(parents=True, exist_ok=True)
    tmp = target.with_suffix(".tmp")
    tmp.write_text(json.dumps(document, indent=1, ensure_ascii=False) + "\n", encoding="utf-8")
    tmp.replace(target)
    if not keep:
        shutil.rmtree(work, ignore_errors=True)
    print(
        f"wrote {target}: {len(numbers)} numbers, {len(blocks)} blocks, "
        f"{time.perf_counter() - started:.0f} s"
    )
    for item in collector.missing:
        print(f"  missing: {item}")


def render(text, document):
    """The page ``text`` with every marked number and block taken from ``document``."""
    numbers, blocks = document["numbers"], document["blocks"]

    def number(match):
        key = match[2]
        return (numbers[key]["text"] if key in numbers else match[1]) + f"<!--n:{key}-->"

    def block(match):
        key = match[1]
        body = blocks.get(key, match[3])
        return f"<!--block:{key}-->\n{match[2]}{body}{match[4]}"

    def word(match):
        key = match[2]
        return (numbers[key]["text"] if key in numbers else match[1]) + f"<!--t:{key}-->"

    return BLOCK_MARK.sub(block, WORD_MARK.sub(word, NUMBER_MARK.sub(number, text)))


def differences(document):
    """Every marked number or block that differs from ``document``, and unknown keys."""
    problems = []
    for page in pages():
        text = page.read_text(encoding="utf-8")
        name = page.relative_to(ROOT)
        for match in NUMBER_MARK.finditer(text):
            entry = document["numbers"].get(match[2])
            if entry is None:
                problems.append(f"{name}: unknown number key {match[2]}")
            elif entry["text"] != match[1].replace("−", "-"):
                problems.append(f"{name}: {match[2]} is {match[1]}, the run gave {entry['text']}")
        for match in WORD_MARK.finditer(text):
            entry = document["numbers"].get(match[2])
            if entry is None:
                problems.append(f"{name}: unknown word key {match[2]}")
            elif entry["text"] != match[1]:
                problems.append(f"{name}: {match[2]} is {match[1]}, the run gave {entry['text']}")
        for match in BLOCK_MARK.finditer(text):
            body = document["blocks"].get(match[1])
            if body is None:
                problems.append(f"{name}: unknown block key {match[1]}")
            elif body != match[3]:
                problems.append(f"{name}: block {match[1]} differs from the run's output")
        if "<!--n:" in NUMBER_MARK.sub("", text) or "<!--t:" in WORD_MARK.sub("", text):
            problems.append(f"{name}: a mark without a number or word right before it")
    return problems


def apply(path=NUMBERS):
    document = load_numbers(path)
    for page in pages():
        text = page.read_text(encoding="utf-8")
        new = render(text, document)
        if new != text:
            page.write_text(new, encoding="utf-8")
            print(f"updated {page.relative_to(ROOT)}")


def check(path=NUMBERS):
    document = load_numbers(path)
    problems = differences(document)
    if document["config_hash"] != config_hash():
        problems.append(
            "docs/_static/numbers.json was made from another configuration: run it again"
        )
    for problem in problems:
        print(problem)
    return 1 if problems else 0


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    sub = parser.add_subparsers(dest="command", required=True)
    runner = sub.add_parser("run", help="run the jobs and write docs/_static/numbers.json")
    runner.add_argument(
        "--small", action="store_true", help="12 tracers: a smoke test, not for the pages"
    )
    runner.add_argument("--only", help="comma-separated jobs: " + ", ".join(JOBS))
    runner.add_argument("--keep", help="keep the runs' outputs in this folder")
    runner.add_argument(
        "--out", default=str(NUMBERS), help="the numbers file (default: %(default)s)"
    )
    runner.add_argument(
        "--reuse",
        action="store_true",
        help="with --keep: read the outputs already there instead of running (timings n/a)",
    )
    applier = sub.add_parser("apply", help="write the numbers of the file into the pages")
    checker = sub.add_parser("check", help="exit 1 where a page or the file is out of date")
    for command in (applier, checker):
        command.add_argument("--numbers", default=str(NUMBERS), help="default: %(default)s")
    args = parser.parse_args(argv)
    if args.command == "run":
        global REUSE
        REUSE = bool(args.reuse and args.keep)
        run(
            "small" if args.small else "full",
            args.only.split(",") if args.only else None,
            args.keep,
            args.out,
        )
        return 0
    if args.command == "apply":
        apply(args.numbers)
        return 0
    return check(args.numbers)


if __name__ == "__main__":
    sys.exit(main())
