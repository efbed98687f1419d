"""A study directory is one scene: kills, changed scenes, damaged and foreign files.

The subprocess test kills ``rimcl study --force`` with a changed scene right after its
first case file landed, then checks that no later run ever mixes the two scenes.
"""

import fcntl
import json
import os
import shutil
import signal
import subprocess
import sys

import h5py
import pytest
from click.testing import CliRunner

from rimcl.cli.main import cli
from rimcl.core.errors import RimclError
from rimcl.scene.load import load_scene, scene_text
from rimcl.scene.study_config import StudyConfig
from rimcl.study.case_files import case_path, check_case_file
from rimcl.study.run import MARKER, run_study

CASES = ["C0", "C1", "C2"]


def tiny(device, **overrides):
    """A scene that runs in about a second on 2 cores."""
    values = {
        "cases.names": CASES,
        "tracers.count": 6,
        "camera.fan": 6,
        "renderer.pixels": 256,
        "run.device": device.name,
        **overrides,
    }
    return load_scene(None, values)


@pytest.fixture(scope="module")
def finished(device, tmp_path_factory):
    """A finished study (no figures) and its scene."""
    out = tmp_path_factory.mktemp("finished")
    scene = tiny(device)
    run_study(scene, out, figures=False)
    return scene, out


def _rimcl(*args):
    """``rimcl ARGS`` as a process whose output lines can be read as they come."""
    return subprocess.Popen(
        [sys.executable, "-c", "from rimcl.cli.main import cli; cli()", *args],
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
        env={**os.environ, "PYTHONUNBUFFERED": "1"},
    )


def _n_tracers(out):
    stats = json.loads((out / "stats.json").read_text())
    return {case["name"]: case["n_tracers"] for case in stats["cases"]}


@pytest.mark.skipif(sys.platform == "win32", reason="POSIX signals")
def test_killed_forced_study_of_another_scene_never_mixes_scenes(device, tmp_path):
    out = tmp_path / "study"
    common = ["--out", str(out), "--cases", ",".join(CASES), "--device", device.name]
    common += ["--fan", "6", "--pixels", "256", "--no-figures", "--no-progress"]
    first = _rimcl("study", *common, "--tracers", "6")
    output, _ = first.communicate(timeout=300)
    assert first.returncode == 0, output
    assert _n_tracers(out) == dict.fromkeys(CASES, 6)

    forced = _rimcl("study", *common, "--tracers", "7", "--force")
    lines = []
    for line in forced.stdout:
        lines.append(line)
        if "C0: done" in line:
            forced.send_signal(signal.SIGKILL)
            break
    forced.wait(timeout=60)
    forced.stdout.close()
    assert forced.returncode == -signal.SIGKILL, "".join(lines)
    # killed between cases: the new scene is recorded, the old statistics are gone
    assert "count = 7" in (out / "scene.toml").read_text()
    assert not (out / "stats.json").exists() and not (out / "summary.md").exists()

    plain = CliRunner().invoke(cli, ["study", *common, "--tracers", "7"])
    assert plain.exit_code == 0, plain.output
    assert "C0: finished earlier, kept" in plain.output
    for case in ("C1", "C2"):
        assert f"{case}.h5 made for another scene (tracers.count: 6 -> 7)" in plain.output
    assert "2 cases measured, 1 kept" in plain.output
    assert _n_tracers(out) == dict.fromkeys(CASES, 7)
    assert (out / "summary.md").exists()

    old = CliRunner().invoke(cli, ["study", *common, "--tracers", "6"])
    assert old.exit_code == 1 and "another scene (tracers.count: 7 -> 6)" in old.output
    assert _n_tracers(out) == dict.fromkeys(CASES, 7)


def test_a_damaged_case_file_is_measured_again(finished, device, tmp_path):
    scene, source = finished
    out = tmp_path / "study"
    shutil.copytree(source, out)
    damaged = case_path(out, "C1")
    size = damaged.stat().st_size
    os.truncate(damaged, size // 2)
    lines = []
    result = run_study(scene, out, figures=False, report=lines.append)
    assert result.ran == ["C1"] and result.skipped == ["C0", "C2"]
    assert any("C1.h5 unreadable or incomplete" in line for line in lines)
    assert check_case_file(damaged, StudyConfig.from_scene(scene), "C1") is None


def _copy(source, target):
    target.write_bytes(source.read_bytes())
    return target


def test_check_case_file_names_why_a_file_cannot_be_kept(finished, device, tmp_path):
    scene, out = finished
    study = StudyConfig.from_scene(scene)
    c0 = case_path(out, "C0")
    assert check_case_file(c0, study, "C0") is None
    assert check_case_file(c0, study, "C1") == "holds case 'C0', not 'C1'"
    other = StudyConfig.from_scene(tiny(device, **{"tracers.count": 9}))
    assert check_case_file(c0, other, "C0") == ("made for another scene (tracers.count: 6 -> 9)")
    # the device and batch size may differ
    assert (
        check_case_file(
            c0, StudyConfig.from_scene(tiny(device, **{"run.rays_per_batch": 999})), "C0"
        )
        is None
    )
    no_velocity = _copy(c0, tmp_path / "C0.h5")
    with h5py.File(no_velocity, "a") as h5:
        del h5["velocity"]
    assert "group 'velocity' is missing" in check_case_file(no_velocity, study, "C0")
    short = _copy(c0, tmp_path / "short.h5")
    with h5py.File(short, "a") as h5:  # the first 4 tracers of the (id, frame) table
        for name in list(h5["acceleration"]):
            values = h5["acceleration"][name][()]
            del h5["acceleration"][name]
            h5["acceleration"][name] = values if name == "frame" else values[:4]
    reason = check_case_file(short, study, "C0")
    evaluated = scene["time"]["frames"] - 2
    wanted = scene["tracers"]["count"] * evaluated
    assert reason == f"incomplete (acceleration has {4 * evaluated} rows, the scene needs {wanted})"
    unrecorded = _copy(c0, tmp_path / "unrecorded.h5")
    with h5py.File(unrecorded, "a") as h5:
        config = json.loads(h5.attrs["config"])
        del config["study_scene"]
        h5.attrs["config"] = json.dumps(config)
    assert "records no study scene" in check_case_file(unrecorded, study, "C0")
    garbage = tmp_path / "garbage.h5"
    garbage.write_bytes(b"\x89HDF\r\n\x1a\n" + os.urandom(2000))
    assert check_case_file(garbage, study, "C0").startswith("unreadable or incomplete")


def test_outputs_rimcl_did_not_write_are_refused_never_overwritten(device, tmp_path):
    (tmp_path / "summary.md").write_text("my own notes\n")
    with pytest.raises(RimclError, match=r"summary.md that rimcl study did not write"):
        run_study(tiny(device), tmp_path, figures=False)
    assert (tmp_path / "summary.md").read_text() == "my own notes\n"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["summary.md"]


def test_stale_partial_files_are_removed_and_others_kept(finished, device, tmp_path):
    scene, source = finished
    out = tmp_path / "study"
    shutil.copytree(source, out)
    stale = [out / ".stats.json.k2j4_8zq.part", out / "cases" / ".C1.h5.abcdefgh.part"]
    for path in stale:
        path.write_bytes(b"half")
    mine = out / ".notes.part"
    mine.write_text("not rimcl's")
    lines = []
    run_study(scene, out, figures=False, report=lines.append)
    assert not any(path.exists() for path in stale) and mine.exists()
    assert "removed 2 partial file(s) left by an interrupted run" in lines


def test_a_second_study_in_a_running_study_directory_is_refused(finished, device):
    scene, out = finished
    with open(out / MARKER, "rb") as held:
        fcntl.flock(held, fcntl.LOCK_EX | fcntl.LOCK_NB)
        with pytest.raises(RimclError, match="another rimcl study is running in"):
            run_study(scene, out, figures=False)


def test_a_failed_scene_does_not_lock_the_directory(device, tmp_path):
    out = tmp_path / "study"
    outside = tiny(device, **{"field.x_sheet": 1000.0})
    with pytest.raises(RimclError, match=r"the sheet|depth"):
        run_study(outside, out, figures=False)
    assert not out.exists()  # refused before anything was written
    late = tiny(device, **{"field.start_frame": 11, "cases.names": ["C1"]})
    with pytest.raises(RimclError, match="need the field up to"):
        run_study(late, out, figures=False)
    assert not (out / "scene.toml").exists()
    good = tiny(device, **{"cases.names": ["C1"]})
    result = run_study(good, out, figures=False)  # no --force needed
    assert result.ran == ["C1"]
    assert (out / "scene.toml").read_text() == scene_text(good)


@pytest.mark.parametrize("folder", ["cases", "piv", "shards", "figures", "shards/C1"])
def test_a_study_folder_that_is_a_symbolic_link_is_refused(device, tmp_path, folder):
    out, outside = tmp_path / "study", tmp_path / "elsewhere"
    outside.mkdir()
    stale = outside / ".C1.h5.abcdefgh.part"  # would be removed as a study's partial file
    stale.write_bytes(b"not the study's")
    (out / folder).parent.mkdir(parents=True)
    (out / folder).symlink_to(outside, target_is_directory=True)
    with pytest.raises(RimclError, match=rf"{folder} is a symbolic link \(to .*elsewhere\)"):
        run_study(tiny(device, **{"run.mode": "both"}), out, figures=False)
    assert stale.read_bytes() == b"not the study's" and sorted(outside.iterdir()) == [stale]
    assert not (out / "scene.toml").exists() and not (out / MARKER).exists()


def test_every_statistics_stage_says_when_it_starts(finished, tmp_path):
    """No silent stage: the statistics and the Δt sweep each start with a line (a user saw
    nothing for 86 s)."""
    from rimcl.study.run import write_study_outputs

    scene, out = finished
    copy = tmp_path / "copy"
    shutil.copytree(out, copy)
    lines = []
    files = sorted((copy / "cases").glob("*.h5"))
    study = StudyConfig.from_scene(scene)
    write_study_outputs(copy, study, files, figures=False, report=lines.append)
    assert lines[0] == "statistics of 3 case file(s), with bootstrap intervals"
    assert lines[1] == "Δt sweep: statistics at 2 Δt, 3 Δt, 4 Δt"
