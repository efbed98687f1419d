"""``rimcl stats`` and ``rimcl study`` through click's test runner, and a real kill."""

import json
import os
import signal
import subprocess
import sys
import time

import pytest
from click.testing import CliRunner
from synthetic_render import write_render_file

from rimcl.cli.main import cli
from rimcl.scene.keys import default_scene
from rimcl.scene.load import load_scene
from rimcl.stats.render_file import load_render

QUICK = ["--tracers", "6", "--fan", "6", "--no-progress", "--no-figures"]


def run(*args):
    return CliRunner().invoke(cli, list(args))


def one_error_line(result):
    assert result.exit_code == 1, result.output
    lines = result.output.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("Error: "), result.output
    return lines[0]


def test_print_default_scene_is_the_default(tmp_path):
    result = run("study", "--print-default-scene")
    assert result.exit_code == 0
    path = tmp_path / "scene.toml"
    path.write_text(result.output)
    # the defaults, and the shipped sample's own time scale (filled where the scene has none)
    loaded, defaults = load_scene(path), default_scene()
    assert loaded == load_scene()
    assert defaults["field"]["time_s"] is None and loaded["field"]["time_s"] > 0
    loaded["field"]["time_s"] = None
    assert loaded == defaults


def test_study_needs_an_output_directory():
    result = run("study")
    assert result.exit_code == 2
    assert "--out DIR" in result.output


def test_bad_scene_is_one_line_and_writes_nothing(tmp_path):
    scene = tmp_path / "scene.toml"
    scene.write_text("[renderer]\npixel = 512\n")
    out = tmp_path / "out"
    line = one_error_line(run("study", str(scene), "--out", str(out)))
    assert "unknown key renderer.pixel" in line and "did you mean 'pixels'?" in line
    assert not out.exists()
    line = one_error_line(run("study", "--out", str(out), "--cases", "C1,C9"))
    assert "unknown case 'C9'" in line
    assert not out.exists()


def test_study_runs_then_resumes_from_the_command_line(device, tmp_path):
    out = tmp_path / "study"
    # the default noisy camera: the measured and reference images share their noise draws,
    # so a uniform medium's refraction error is exactly 0, and the noise floor is apart
    args = ("study", "--out", str(out), "--cases", "G=0,C2", "--device", device.name)
    args += tuple(QUICK)
    first = run(*args)
    assert first.exit_code == 0, first.output
    assert "2 cases measured, 0 kept" in first.output and "written" in first.output
    stats = json.loads((out / "stats.json").read_text())
    assert [case["name"] for case in stats["cases"]] == ["G=0", "C2"]
    uniform = stats["cases"][0]
    assert uniform["position_error_peak_over_L"] == 0.0
    assert uniform["velocity"]["u3"]["rms_normalized"] == 0.0
    assert uniform["noise_floor"]["velocity"]["u3"]["rms_normalized"] > 0
    line = next(row for row in first.output.splitlines() if row.strip().startswith("G=0  "))
    assert "u3 0 %" in line and "noise floor (camera alone): u3" in line
    assert "refraction not resolved" in uniform["budget_verdict"]["text"]
    again = run(*args)
    assert again.exit_code == 0, again.output
    assert "0 cases measured, 2 kept" in again.output and "up to date" in again.output
    changed = one_error_line(run(*args[: -len(QUICK)], *QUICK[2:], "--tracers", "7"))
    assert "another scene (tracers.count: 6 -> 7)" in changed


def test_stats_command_writes_json_and_refuses_to_overwrite(tmp_path):
    files = []
    for name, g in (("C1", 2.82e-4), ("C4", 0.334)):
        files.append(str(tmp_path / f"{name}.h5"))
        write_render_file(files[-1], case=name, k_rho=g, n_tracers=30)
    out = tmp_path / "stats"
    result = run("stats", *files, "--out", str(out), "--no-figures")
    assert result.exit_code == 0, result.output
    assert "C1" in result.output and "C4" in result.output
    before = (out / "stats.json").read_text()
    assert [case["name"] for case in json.loads(before)["cases"]] == ["C1", "C4"]
    line = one_error_line(run("stats", *files, "--out", str(out), "--no-figures"))
    assert "stats.json exists" in line
    assert (out / "stats.json").read_text() == before
    result = run("stats", *files, "--out", str(out), "--no-figures", "--overwrite")
    assert result.exit_code == 0, result.output
    line = one_error_line(run("stats", str(tmp_path / "missing.h5"), "--out", str(out)))
    assert "no such file" in line


@pytest.mark.skipif(sys.platform == "win32", reason="POSIX signals")
def test_killed_study_process_leaves_whole_files_and_resumes(device, tmp_path):
    out = tmp_path / "killed"
    cases = "C0,C1,C2,C3,C4"
    args = ["study", "--out", str(out), "--cases", cases, "--device", device.name]
    args += QUICK  # the configuration of the test above: its kernels are built already
    process = subprocess.Popen(
        [sys.executable, "-c", "from rimcl.cli.main import cli; cli()", *args],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
    )
    first_case = out / "cases" / "C0.h5"
    deadline = time.monotonic() + 120
    while not first_case.exists() and process.poll() is None and time.monotonic() < deadline:
        time.sleep(0.01)
    if process.poll() is not None:
        pytest.fail(f"the study ended before it could be killed: {process.stderr.read()!r}")
    os.kill(process.pid, signal.SIGKILL)
    process.wait()
    process.stderr.close()
    assert first_case.exists(), "the study never finished its first case"
    assert not (out / "stats.json").exists()
    finished = sorted((out / "cases").glob("*.h5"))
    for path in finished:
        assert load_render(path).case == path.stem
    kept = first_case.stat().st_mtime_ns
    result = run(*args)
    assert result.exit_code == 0, result.output
    assert f"{len(finished)} kept" in result.output
    assert first_case.stat().st_mtime_ns == kept
    stats = json.loads((out / "stats.json").read_text())
    assert [case["name"] for case in stats["cases"]] == cases.split(",")
