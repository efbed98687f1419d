"""The sheet where the experiment has it: a sheet moved inside the shipped sample runs on
its built-in flow with full velocity, generated once into the cache and reused."""

import h5py
import numpy as np
import pytest
from click.testing import CliRunner

import rimcl.fields.full_sample as full_sample
from rimcl.cli.main import cli
from rimcl.fields.field_reader import FieldFile
from rimcl.scene.command import place_sheet
from rimcl.scene.load import load_scene

# the solver at 16³: a few seconds (the sample's own 64³ takes a minute, once)
TINY = {
    "grid": 16,
    "seed": 1,
    "reynolds": 60.0,
    "schmidt": 1.0,
    "frames": 3,
    "frame_dt": 0.02,
    "gravity_axis": "x3",
}


@pytest.fixture
def cache(tmp_path, monkeypatch):
    monkeypatch.setenv(full_sample.CACHE_ENV, str(tmp_path / "cache"))
    monkeypatch.setattr(full_sample, "sample_settings", lambda: dict(TINY))
    return tmp_path / "cache"


def test_the_sample_settings_are_its_recorded_ones():
    settings = full_sample.sample_settings()
    assert settings["grid"] == 64 and settings["frames"] == 13 and settings["frame_dt"] == 0.02


def test_the_full_flow_is_generated_once_then_reused(cache):
    said = []
    path = full_sample.full_velocity_sample(report=said.append)
    assert path.parent == cache and len(said) == 1 and "generating it once" in said[0]
    stamp = path.stat().st_mtime_ns
    assert full_sample.full_velocity_sample(report=said.append) == path
    assert len(said) == 1 and path.stat().st_mtime_ns == stamp  # reused, not redone
    with FieldFile(path) as flow:
        assert flow.has_full_velocity and flow.shape == (16, 16, 16)
    # another setting is another flow: never a file made for different settings
    other = full_sample.full_velocity_sample({**TINY, "seed": 2}, report=said.append)
    assert other != path and len(said) == 2
    # a damaged cached file is made again
    path.write_bytes(b"not hdf5")
    assert full_sample.full_velocity_sample(report=said.append) == path and len(said) == 3
    assert h5py.is_hdf5(path)


def test_only_a_moved_sheet_on_the_sample_changes_the_field(cache):
    assert place_sheet(load_scene())["field"]["path"] == ""
    at_stored_plane = load_scene(overrides={"field.x_sheet": 0.0})
    assert place_sheet(at_stored_plane)["field"]["path"] == ""
    moved = place_sheet(load_scene(overrides={"field.x_sheet": 1.5}))
    assert moved["field"]["path"] == str(full_sample.full_velocity_sample())
    assert not list(cache.glob("*.tmp*"))


def test_render_moves_the_sheet_inside_the_built_in_flow(cache, device, tmp_path):
    scene = tmp_path / "deep.toml"
    scene.write_text(
        '[field]\nx_sheet = 1.5\n[camera]\nkind = "plane"\nfan = 4\n'
        "[tracers]\ncount = 3\n[time]\nframes = 3\n[renderer]\npixels = 512\n"
    )
    out = tmp_path / "deep.h5"
    result = CliRunner().invoke(cli, ["render", str(scene), "-o", str(out)])
    assert result.exit_code == 0, result.output
    assert "generating it once" in result.output
    with h5py.File(out) as h5:
        assert h5.attrs["x_sheet"] == 1.5
        assert h5.attrs["field"] == str(full_sample.full_velocity_sample())
        assert np.all(np.isfinite(h5["tracers/x2_meas"][()]))
