"""Time-resolved PIV sequences (rimcl.piv.sequence): frames, dense truth, particle tables."""

import dataclasses
import json

import h5py
import numpy as np
import pytest
import tifffile
from test_piv_images import SMALL_PIV, _moving_box, small

from rimcl.core.errors import RimclError
from rimcl.piv.sequence import open_sequence_outputs, run_piv_sequence, write_piv_sequence


@pytest.fixture(scope="module")
def box(tmp_path_factory):
    return _moving_box(tmp_path_factory.mktemp("sequence") / "box.h5")


def test_sequence_of_a_uniform_flow_knows_its_truth(box, device, tmp_path):
    piv = dataclasses.replace(SMALL_PIV, dt=0.05)
    options = {**small(device), "piv": piv}
    made = run_piv_sequence(
        box, case="C2", frames=3, seeds=(1, 2), length_m=0.01, time_s=0.5, **options
    )
    assert [s.seed for s in made] == [1, 2]
    first, second = made
    pixel = first.config["imaging"]["pixel_size"]
    # every pixel of the dense truth moves by u dt per frame, in px and in m/s (the file
    # stores the velocity in float32: 0.3 and -0.2 to 4e-8 relative)
    assert first.truth_px.shape == (2, 96, 96, 2)
    np.testing.assert_allclose(first.truth_px[..., 0], 0.3 * 0.05 / pixel, rtol=1e-7)
    np.testing.assert_allclose(first.truth_px[..., 1], 0.2 * 0.05 / pixel, rtol=1e-7)
    np.testing.assert_allclose(first.truth_ms[..., 0], 0.3 * 0.01 / 0.5, rtol=1e-7)
    # the particle table: three exposures of the same tracers, moved by u dt each
    steps = np.diff(first.positions, axis=0)
    np.testing.assert_allclose(
        steps, np.broadcast_to([0.001, 0.015, -0.01], steps.shape), atol=1e-12
    )
    np.testing.assert_allclose(np.diff(first.pixels, axis=0)[..., 0], 0.015 / pixel, rtol=1e-7)
    assert first.frames.images.shape == (3, 96, 96)
    # the reference sequence: the same tracers through the uniform medium, imaged where
    # they are (straight rays, to rounding); through the field C2 bends them off by ~1e-3
    assert first.uniform.images.shape == (3, 96, 96)
    seen = np.isfinite(first.uniform.optics[..., 0])
    assert seen.mean() > 0.9
    np.testing.assert_allclose(
        first.uniform.optics[seen], first.positions[..., 1:][seen], atol=1e-12
    )
    assert np.nanmax(np.abs(first.frames.optics - first.positions[..., 1:])) > 1e-4
    assert not np.array_equal(first.frames.images, first.uniform.images)
    # independent realisations: other tracers, other frames
    count = first.positions.shape[1]
    assert second.positions.shape[1] == count
    assert not np.array_equal(first.positions, second.positions)
    assert not np.array_equal(first.frames.images, second.frames.images)
    with open_sequence_outputs(tmp_path / "seq") as outputs:
        paths = write_piv_sequence(outputs, first)
    assert [p.name for p in paths] == [
        "seq_seed1_000.tif",
        "seq_seed1_001.tif",
        "seq_seed1_002.tif",
        "seq_seed1_uniform_000.tif",
        "seq_seed1_uniform_001.tif",
        "seq_seed1_uniform_002.tif",
        "seq_seed1_truth.h5",
    ]
    np.testing.assert_array_equal(tifffile.imread(paths[1]), first.frames.images[1])
    np.testing.assert_array_equal(tifffile.imread(paths[4]), first.uniform.images[1])
    with h5py.File(paths[-1]) as h5:
        assert h5.attrs["rimcl_schema"] == "piv_sequence_truth"
        np.testing.assert_array_equal(h5["truth/dx"][...], first.truth_px[..., 0])
        assert h5["particles/position"].shape == (count, 3, 3)  # (id, frame, axis)
        assert "m/s" in h5.attrs["units"]
        np.testing.assert_array_equal(
            h5["particles/image_point_uniform"][...], np.swapaxes(first.uniform.optics, 0, 1)
        )
    import xarray as xr

    particles = xr.open_dataset(paths[-1], group="particles", engine="h5netcdf")
    assert particles["col"].dims == ("id", "frame") and particles["col"].attrs["units"] == "px"
    np.testing.assert_array_equal(particles["col"].values, first.pixels[..., 0].T)
    np.testing.assert_array_equal(particles["position"].sel(frame=2), first.positions[2])
    truth = xr.open_dataset(paths[-1], group="truth", engine="h5netcdf")
    assert truth["dx"].dims == ("step", "row", "column") and truth["dx"].attrs["units"] == "px"
    np.testing.assert_array_equal(truth["dy"].values, first.truth_px[..., 1])
    times = xr.open_dataset(paths[-1], engine="h5netcdf")["times"]
    assert times.dims == ("frame",) and times.attrs["units"] == "T0"


def test_sequence_beyond_the_stored_frames_is_refused(box, device):
    with pytest.raises(RimclError, match="beyond the last stored frame"):
        run_piv_sequence(box, case="C2", frames=4, **small(device))


def test_cli_writes_one_set_of_files_per_seed(box, tmp_path):
    from click.testing import CliRunner

    from rimcl.cli.main import cli

    base = ["piv", "sequence", "--field", box, "--case", "C2", "--pixels", "32", "--fan", "2"]
    runner = CliRunner()
    bad = runner.invoke(cli, [*base, "--seeds", "1,x", "-o", str(tmp_path / "bad")])
    assert bad.exit_code != 0 and "comma-separated integers" in bad.output
    ok = runner.invoke(
        cli, [*base, "--frames", "2", "--dt", "0.05", "--seeds", "0,1", "-o", str(tmp_path / "s")]
    )
    assert ok.exit_code == 0, ok.output
    for seed in (0, 1):
        assert (tmp_path / f"s_seed{seed}_001.tif").exists()
        assert (tmp_path / f"s_seed{seed}_uniform_001.tif").exists()
        assert (tmp_path / f"s_seed{seed}_truth.h5").exists()
    with h5py.File(tmp_path / "s_seed0_truth.h5") as h5:
        # no scales, no m/s: the units text names only what is written
        assert "u_ms" not in h5["truth"] and "u_ms" not in h5.attrs["units"]
    # a time scale without the field's size cannot give m/s: refused, not dropped
    lost = runner.invoke(
        cli, [*base, "--frames", "2", "--time-s", "0.5", "-o", str(tmp_path / "t")]
    )
    assert lost.exit_code == 1 and "give --length-m (field.length_m)" in lost.output
    assert not list(tmp_path.glob("t_*"))


def test_cli_takes_a_scene_file_as_piv_render_does(box, tmp_path):
    """The sequence's frames follow the scene's [piv] and camera sections, as piv render's."""
    from click.testing import CliRunner

    from rimcl.cli.main import cli

    scene = tmp_path / "scene.toml"
    scene.write_text(
        f'[field]\npath = "{box}"\nlength_m = 0.05\ntime_s = 2.0\n'
        '[camera]\nkind = "plane"\n[piv]\npixels = 24\nrays = 4\ndt = 0.05\nwindow = 8\n',
        encoding="utf-8",
    )
    out = tmp_path / "s"
    ok = CliRunner().invoke(
        cli, ["piv", "sequence", str(scene), "--case", "C2", "--frames", "2", "-o", str(out)]
    )
    assert ok.exit_code == 0, ok.output
    with h5py.File(f"{out}_seed0_truth.h5", "r") as h5:
        assert h5["truth/dx"].shape == (1, 24, 24)
        assert np.allclose(h5["times"][1] - h5["times"][0], 0.05)
        # the scene's scales give the truth in m/s: px/frame × (m per px) / (s per frame)
        config = json.loads(h5.attrs["config"])
        metres_per_px = 0.05 * config["imaging"]["pixel_size"]
        assert config["length_m"] == 0.05 and config["time_s"] == 2.0
        expected = h5["truth/dx"][...] * metres_per_px / (0.05 * 2.0)
        assert np.abs(expected).max() > 0
        np.testing.assert_allclose(h5["truth/u_ms"][...], expected, rtol=1e-12)
