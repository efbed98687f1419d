"""Outputs stay in their folder, replace an earlier run as a set, and belong to their inputs.

Each test fails on rimcl before output sets (issue 32, classes 1-3 and 7): a camera named
``../../x`` wrote outside the output folder, ``--overwrite`` left an earlier run's files
beside the new ones, a failed run left half a new set beside the old one, an output could
be an input, and a study kept its numbers after the field file changed.
"""

import json
import shutil

import h5py
import numpy as np
import pytest
from click.testing import CliRunner
from synthetic_render import write_render_file

from rimcl.cli.main import cli
from rimcl.core import memory
from rimcl.core.errors import RimclError
from rimcl.core.fingerprint import fingerprint
from rimcl.core.memory import check_sequence_memory
from rimcl.core.outputs import MANIFEST, OutputSet, check_file_name


def run(*args):
    return CliRunner().invoke(cli, [str(a) for a in args])


def one_error_line(result):
    assert result.exit_code == 1, result.output
    lines = result.output.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("Error: "), result.output
    return lines[0]


def files_of(folder):
    """Every file under ``folder`` (relative path to bytes)."""
    return {
        p.relative_to(folder).as_posix(): p.read_bytes()
        for p in sorted(folder.rglob("*"))
        if p.is_file()
    }


# ---------------------------------------------------------------- the mechanism


def _write(outputs, *parts, text):
    outputs.path(*parts).write_text(text)


def test_a_new_set_replaces_the_old_one_whole(tmp_path):
    out = tmp_path / "out"
    with OutputSet(out) as outputs:
        _write(outputs, "a.txt", text="old a")
        _write(outputs, "sub", "b.txt", text="old b")
    (out / "mine.txt").write_text("not rimcl's")  # never part of a set
    with pytest.raises(RimclError, match=r"a.txt exists \(use --overwrite"):
        OutputSet(out)
    with OutputSet(out, overwrite=True) as outputs:
        _write(outputs, "a.txt", text="new a")
    assert files_of(out) == {
        "a.txt": b"new a",
        "mine.txt": b"not rimcl's",
        MANIFEST: (out / MANIFEST).read_bytes(),
    }
    assert not (out / "sub").exists()  # emptied by the old set's file: removed
    assert json.loads((out / MANIFEST).read_text())["files"] == ["a.txt"]


def test_a_failed_run_leaves_the_old_set_and_no_staging(tmp_path):
    out = tmp_path / "out"
    with OutputSet(out) as outputs:
        _write(outputs, "a.txt", text="old a")
        _write(outputs, "b.txt", text="old b")
    before = files_of(out)
    with pytest.raises(ValueError), OutputSet(out, overwrite=True) as outputs:
        _write(outputs, "a.txt", text="new a")
        raise ValueError("the run failed half-way")
    assert files_of(out) == before
    assert [p.name for p in out.iterdir() if p.is_dir()] == []


@pytest.mark.parametrize(
    "name", ["../../victim/keep", "..", "a/b", "a\\b", "", " cam", "x\0y", "cam\n"]
)
def test_a_name_that_is_not_one_file_name_is_refused(tmp_path, name):
    with pytest.raises(RimclError, match="not a plain file name"):
        check_file_name(name, "camera name")
    outputs = OutputSet(tmp_path / "out")
    with pytest.raises(RimclError, match="not a plain file name"):
        outputs.path("dataset", name)
    outputs.discard()


def test_a_subfolder_linked_outside_is_refused_before_anything_moves(tmp_path):
    out, victim = tmp_path / "out", tmp_path / "victim"
    victim.mkdir()
    with OutputSet(out) as outputs:
        _write(outputs, "a.txt", text="old a")
    (out / "dataset").symlink_to(victim, target_is_directory=True)
    with (
        pytest.raises(RimclError, match="leads outside"),
        OutputSet(out, overwrite=True) as outputs,
    ):
        _write(outputs, "a.txt", text="new a")
        _write(outputs, "dataset", "keep", text="escaped")
    assert list(victim.iterdir()) == []
    assert (out / "a.txt").read_text() == "old a"


def test_a_second_run_into_a_set_being_written_is_refused_and_a_dead_ones_staging_removed(
    tmp_path,
):
    out = tmp_path / "out"
    running = OutputSet(out)
    _write(running, "a.txt", text="being written")
    with pytest.raises(RimclError, match="another rimcl run is writing"):
        OutputSet(out, overwrite=True)
    running._lock.close()  # as if its process had died: its staging is stale
    with OutputSet(out, overwrite=True) as outputs:
        _write(outputs, "b.txt", text="b")
    assert sorted(p.name for p in out.iterdir()) == [MANIFEST, "b.txt"]


def test_an_output_that_is_an_input_is_refused(tmp_path):
    out = tmp_path / "out"
    field = out / "field.h5"
    out.mkdir()
    field.write_text("input")
    outputs = OutputSet(out, inputs=[field])
    with pytest.raises(RimclError, match="is an input of this run"):
        outputs.path("field.h5")
    outputs.discard()
    assert field.read_text() == "input"


def test_a_prefix_set_finds_an_old_run_by_its_names(tmp_path):
    # files of a run without a manifest (rimcl before output sets): found by the patterns
    old = ["seq_seed0_000.tif", "seq_seed0_001.tif", "seq_seed0_002.tif", "seq_seed1_000.tif"]
    for name in (*old, "seq_seed0_truth.h5", "other_seed0_000.tif", "seq_notes.txt"):
        (tmp_path / name).write_text("old")
    owned = ("{prefix}_seed*_[0-9][0-9][0-9]*.tif", "{prefix}_seed*_truth.h5")
    with pytest.raises(RimclError, match=r"seq_seed0_000\.tif exists"):
        OutputSet(tmp_path / "seq", prefix=True, owned=owned)
    with OutputSet(tmp_path / "seq", overwrite=True, prefix=True, owned=owned) as outputs:
        for name in ("seq_seed0_000.tif", "seq_seed0_001.tif", "seq_seed0_truth.h5"):
            _write(outputs, name, text="new")
    left = sorted(p.name for p in tmp_path.iterdir() if not p.name.startswith("."))
    assert left == [
        "other_seed0_000.tif",
        "seq_notes.txt",
        "seq_seed0_000.tif",
        "seq_seed0_001.tif",
        "seq_seed0_truth.h5",
    ]


def test_a_fingerprint_follows_the_content(tmp_path):
    path = tmp_path / "f.bin"
    path.write_bytes(b"a" * 1000)
    first = fingerprint(path)
    copy = tmp_path / "g.bin"
    shutil.copy(path, copy)
    assert fingerprint(copy) == first  # same content, another file and time
    path.write_bytes(b"a" * 999 + b"b")
    assert fingerprint(path) != first


def test_a_sequence_that_cannot_fit_is_refused_naming_it(monkeypatch):
    monkeypatch.setattr(memory, "host_available", lambda: 4 * 1024**3)
    # 5000 frames of 512 x 512 px: 5.2 GB of frames alone
    with pytest.raises(RimclError, match=r"5000 frames of 512 x 512 px.*--frames or --seeds"):
        check_sequence_memory((32, 32, 32), 5000, 1, (512, 512))
    check_sequence_memory((32, 32, 32), 50, 1, (512, 512))  # 0.1 GB: fits


# ---------------------------------------------------------------- commands

CAMERA = """
[[rig.cameras]]
name = "{name}"
position_mm = [700.0, {x2}, 50.0]
look_at_mm = [50.0, 50.0, 50.0]
focal_length_mm = 16.0
f_number = 8.0
sensor_pixels = [320, 200]
"""


def lpt_scene(tmp_path, lpt_flow, left="left", frames=5, name="scene.toml"):
    scene = tmp_path / name
    scene.write_text(
        f'[field]\npath = "{lpt_flow}"\n[cases]\nnames = ["C3"]\n'
        f"[tracers]\ncount = 4\n[time]\nframes = {frames}\ndt = 0.03\n"
        "[lpt]\ncalibration_grid = [6, 5]\ncalibration_planes = 3\nimages = true\n"
        "self_calibration = false\nmax_rays = 4\nray_tolerance_px = 1.0\n"
        + CAMERA.format(name=left, x2=-300.0)
        + CAMERA.format(name="right", x2=400.0)
    )
    return scene


def test_a_camera_name_that_leaves_the_folder_writes_nothing_outside(tmp_path, lpt_flow):
    victim = tmp_path / "victim"
    victim.mkdir()
    (victim / "keep").write_text("precious")
    out = tmp_path / "a" / "b" / "c"
    scene = lpt_scene(tmp_path, lpt_flow, left="../../../victim/keep")
    line = one_error_line(run("lpt", "render", scene, "-o", out, "--overwrite"))
    assert "name" in line and "not a plain file name" in line
    assert files_of(victim) == {"keep": b"precious"}
    assert not out.exists()


def test_an_lpt_run_that_cannot_fit_is_refused_before_work(tmp_path, lpt_flow, monkeypatch):
    monkeypatch.setattr(memory, "host_available", lambda: 1024**2)
    out = tmp_path / "out"
    line = one_error_line(run("lpt", "run", lpt_scene(tmp_path, lpt_flow), "-o", out))
    assert "LPT of 4 tracers over 5 frames with 2 cameras needs about" in line
    assert "use fewer tracers" in line
    assert not out.exists()  # a run refused leaves no folder behind


def test_lpt_overwrite_replaces_the_set_and_a_failed_run_keeps_the_old(
    tmp_path, lpt_flow, monkeypatch
):
    out = tmp_path / "out"
    first = run("lpt", "render", lpt_scene(tmp_path, lpt_flow, frames=6), "-o", out)
    assert first.exit_code == 0, first.output
    old = files_of(out)
    assert "dataset/C3/images/field/left_frame0005.tif" in old
    assert "dataset/C3/left_pinhole.json" in old
    refused = one_error_line(run("lpt", "render", lpt_scene(tmp_path, lpt_flow), "-o", out))
    assert "exists (use --overwrite" in refused
    # a run that fails after writing some of its frames leaves the earlier set whole
    import rimcl.lpt.files

    writer = rimcl.lpt.files.frame_writer

    def failing_writer(outputs, scene):
        write, written = writer(outputs, scene), []

        def sink(*args):
            write(*args)
            written.append(args)
            if len(written) == 3:
                raise RimclError("disk full")

        return sink

    renamed = lpt_scene(tmp_path, lpt_flow, left="west", frames=5, name="renamed.toml")
    with monkeypatch.context() as patched:
        patched.setattr(rimcl.lpt.files, "frame_writer", failing_writer)
        failed = run("lpt", "render", renamed, "-o", out, "--overwrite")
    assert failed.exit_code == 1 and failed.output.endswith("Error: disk full\n")
    assert files_of(out) == old
    # 5 frames and a renamed camera: frame 5 and the old camera's files are gone
    second = run("lpt", "render", renamed, "-o", out, "--overwrite")
    assert second.exit_code == 0, second.output
    new = files_of(out)
    assert "dataset/C3/images/field/west_frame0004.tif" in new
    assert not [name for name in new if "left" in name or "frame0005" in name]
    listed = json.loads((out / MANIFEST).read_text())["files"]
    assert sorted(listed) == sorted(name for name in new if name != MANIFEST)
    with h5py.File(out / "lpt_case_C3.h5") as h5:
        assert set(h5["cameras"]) == {"west", "right"}


def test_stats_overwrite_without_figures_removes_the_old_figures(tmp_path, monkeypatch):
    import rimcl.stats.figures

    def draw(all_tables, stats, folder, overwrite=True):  # the figures' files, not drawn
        for name in ("errors.png", "errors.json"):
            (folder / name).write_text(name)

    monkeypatch.setattr(rimcl.stats.figures, "write_figures", draw)
    files = []
    for name, g in (("C1", 2.82e-4), ("C4", 0.334)):
        files.append(tmp_path / f"{name}.h5")
        write_render_file(files[-1], case=name, k_rho=g, n_tracers=30)
    out = tmp_path / "stats"
    assert run("stats", *files, "--out", out).exit_code == 0
    assert sorted(p.name for p in (out / "figures").iterdir()) == ["errors.json", "errors.png"]
    result = run("stats", *files, "--out", out, "--no-figures", "--overwrite")
    assert result.exit_code == 0, result.output
    assert not (out / "figures").exists()
    assert sorted(files_of(out)) == [MANIFEST, "stats.csv", "stats.json"]


def test_an_output_that_is_an_input_is_refused_by_the_commands(tmp_path):
    frame = tmp_path / "a.tif"
    import tifffile

    tifffile.imwrite(frame, np.zeros((64, 64), np.uint16))
    before = frame.read_bytes()
    line = one_error_line(run("piv", "analyze", frame, frame, "-o", frame, "--overwrite"))
    assert "is an input of this run" in line
    assert frame.read_bytes() == before
    scene = tmp_path / "scene.toml"
    field = tmp_path / "field.h5"
    from rimcl.fields.sample import sample_path

    shutil.copy(sample_path(), field)
    scene.write_text(f'[field]\npath = "{field}"\n')
    before = field.read_bytes()
    for command in (["render"], ["trace"]):
        line = one_error_line(run(*command, scene, "-o", field, "--overwrite"))
        assert "is an input of this run" in line
    line = one_error_line(run("field", "show", field, "-o", field, "--overwrite"))
    assert "is an input of this run" in line
    assert field.read_bytes() == before


def test_piv_sequence_overwrite_leaves_no_frame_of_the_earlier_run(tmp_path):
    small = ["--camera", "plane", "--fan", "1", "--pixels", "32", "--density", "0.01"]
    prefix = tmp_path / "s"
    first = run("piv", "sequence", *small, "--frames", "3", "--seeds", "0,1", "-o", prefix)
    assert first.exit_code == 0, first.output
    # per seed: 3 frames, 3 frames through the uniform fluid, the truth file
    assert len(list(tmp_path.glob("s_*"))) == 14
    line = one_error_line(run("piv", "sequence", *small, "--frames", "2", "-o", prefix))
    assert "s_seed0_000.tif exists (use --overwrite" in line
    args = ("--frames", "2", "--seeds", "1", "-o", prefix, "--overwrite")
    second = run("piv", "sequence", *small, *args)
    assert second.exit_code == 0, second.output
    left = sorted(p.name for p in tmp_path.iterdir())
    assert left == [
        ".s" + MANIFEST,
        "s_seed1_000.tif",
        "s_seed1_001.tif",
        "s_seed1_truth.h5",
        "s_seed1_uniform_000.tif",
        "s_seed1_uniform_001.tif",
    ]


@pytest.mark.parametrize("seeds", ["-1", "0,0", ","])
def test_piv_sequence_seeds_are_checked_in_one_line(tmp_path, seeds):
    line = one_error_line(run("piv", "sequence", f"--seeds={seeds}", "-o", tmp_path / "s"))
    assert "--seeds takes distinct comma-separated integers >= 0" in line


def test_piv_analyze_help_states_the_pixel_convention_of_its_output():
    from rimcl.piv.analysis import COORDINATES

    text = " ".join(run("piv", "analyze", "--help").output.split())
    assert "[j - 1/2, j + 1/2) x [i - 1/2, i + 1/2)" in text
    assert "[j - 1/2, j + 1/2) x [i - 1/2, i + 1/2)" in COORDINATES


# ---------------------------------------------------------------- results and their inputs


def _steepen(path):
    """Rewrite a field file in place, at the same path: every density gradient 1.5 times."""
    with h5py.File(path, "r+") as h5:
        for frame in h5["frames"].values():
            density = frame["density"]
            values = density[()]
            density[...] = values + 0.5 * (values - values.mean())


def test_a_study_rerun_after_its_field_file_changed_measures_again(device, tmp_path):
    from rimcl.fields.sample import sample_path

    field = tmp_path / "field.h5"
    shutil.copy(sample_path(), field)
    scene = tmp_path / "scene.toml"
    scene.write_text(
        f'[field]\npath = "{field}"\n[sensor]\nnoise = false\n[renderer]\npixels = 256\n'
    )
    out = tmp_path / "study"
    args = ["study", scene, "--out", out, "--cases", "C1", "--device", device.name]
    args += ["--tracers", "6", "--fan", "6", "--no-progress", "--no-figures"]
    first = run(*args)
    assert first.exit_code == 0, first.output
    old = json.loads((out / "stats.json").read_text())["cases"][0]["delta_n_max"]
    _steepen(field)
    (out / "figures").mkdir()
    (out / "figures" / "errors.png").write_text("a figure of the old numbers")
    again = run(*args)
    assert again.exit_code == 0, again.output
    assert "field file changed since" in again.output and "measuring again" in again.output
    assert "1 cases measured, 0 kept" in again.output and "up to date" not in again.output
    assert not (out / "figures").exists()  # never beside statistics of other numbers
    new = json.loads((out / "stats.json").read_text())["cases"][0]["delta_n_max"]
    assert new == pytest.approx(1.5 * old, rel=1e-3)
    third = run(*args)  # and now it is up to date
    assert "0 cases measured, 1 kept" in third.output and "up to date" in third.output


def test_an_lpt_study_rerun_after_its_field_file_changed_measures_again(tmp_path, lpt_flow):
    field = tmp_path / "flow.h5"
    shutil.copy(lpt_flow, field)
    scene = lpt_scene(tmp_path, field)
    scene.write_text(scene.read_text() + '[run]\nmode = "lpt"\n')
    out = tmp_path / "study"
    first = run("study", scene, "--out", out, "--no-figures")
    assert first.exit_code == 0, first.output
    old = json.loads((out / "lpt" / "lpt_stats.json").read_text())
    _steepen(field)
    again = run("study", scene, "--out", out, "--no-figures")
    assert again.exit_code == 0, again.output
    assert "field file changed since" in again.output and "measuring again" in again.output
    assert "finished earlier, kept" not in again.output
    new = json.loads((out / "lpt" / "lpt_stats.json").read_text())
    assert new["inputs"] != old["inputs"]
    assert new["inputs"]["field file"] == fingerprint(field)


def test_a_netcdf_dimension_without_values_is_named_as_the_file_names_it(tmp_path):
    import xarray as xr

    from rimcl.fields.cf_import import import_dataset

    path = tmp_path / "nocoord.nc"
    density = xr.DataArray(np.full((4, 5, 6), 1000.0), dims=("z", "y", "x"))
    xr.Dataset({"density": density.assign_attrs(units="kg m-3")}).to_netcdf(path, engine="h5netcdf")
    with pytest.raises(RimclError) as error:
        import_dataset(path, tmp_path / "o.h5", depth_axis="x")
    text = str(error.value)
    assert "(dimension 'z') has no coordinate values" in text
    assert "netCDF dimension but not" not in text
