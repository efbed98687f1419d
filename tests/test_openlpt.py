"""OpenLPT reads rimcl's LPT datasets: its camera files, the calibration points, and its
Shake-the-Box tracks through the uniform fluid and the field (the optional extra
``rimcl[openlpt]``; CI installs it through the test extra)."""

import json
from pathlib import Path

import h5py
import numpy as np
import pytest
from click.testing import CliRunner
from doc_pages import code_blocks

from rimcl.cli.main import cli
from rimcl.lpt.openlpt_files import polynomial_coefficients

pyopenlpt = pytest.importorskip("pyopenlpt")

#: The how-to page whose scene this test runs.
HOWTO = Path(__file__).resolve().parents[1] / "docs" / "howto" / "openlpt.md"
NAMES = ("minus30", "minus10", "plus10", "plus30")
#: Frames: STB starts tracks on 4 and keeps those of 7 or more.
FRAMES = 12


@pytest.fixture(scope="module")
def dataset(tmp_path_factory):
    """The how-to's scene (a C1 dataset at 0.005 tracers per pixel, 12 frames), rendered once."""
    from rimcl.fields.synth import synthesize, write_synth

    folder = tmp_path_factory.mktemp("openlpt")
    flow = synthesize(grid=16, seed=2, frames=FRAMES, frame_dt=0.01, t_start=0.5)
    field = write_synth(flow, folder / "flow.h5")
    scene = folder / "scene.toml"
    (text,) = [b.text for b in code_blocks(HOWTO) if b.lang == "toml"]
    scene.write_text(text.replace('"FLOW.h5"', f'"{field}"'))
    out = folder / "out"
    result = CliRunner().invoke(cli, ["lpt", "render", str(scene), "-o", str(out)])
    assert result.exit_code == 0, result.output
    return out


def _project(model, points):
    return np.array([[p[0], p[1]] for p in (model.project(pyopenlpt.Pt3D(*x)) for x in points)])


def test_camera_files_project_onto_the_particle_images(dataset):
    """Every camera file loads in OpenLPT; the true positions project within 0.1 px (median)
    of the located particle images through the uniform fluid, and the calibration points'
    pixels are the camera files' projections to 0.05 px."""
    folder = dataset / "dataset" / "C1"
    manifest = json.loads((folder / "openlpt_dataset.json").read_text())
    with h5py.File(folder / "truth_tracks.h5", "r") as h5:
        truth = h5["position_mm"][()].reshape(-1, 3)  # (id, frame, axis) in mm
    points = np.loadtxt(folder / "calibration_points.txt")
    assert points.shape[1] == 3 + 2 * len(NAMES)
    with h5py.File(dataset / "lpt_case_C1.h5", "r") as case:
        for c, camera in enumerate(manifest["cameras"]):
            assert set(camera["openlpt_files"]) == {"PINPLATE", "POLYNOMIAL"}
            located = case[f"cameras/{camera['name']}/centroid_ref"][()].reshape(-1, 2)
            for model_name, file_name in camera["openlpt_files"].items():
                model = pyopenlpt.loadCameraModel(str(folder / file_name))
                miss = np.hypot(*(_project(model, truth) - located).T)
                assert np.nanmedian(miss) < 0.1, (camera["name"], model_name)
            # every calibration point is on every sensor, at the camera file's projection
            pixels = points[:, 3 + 2 * c : 5 + 2 * c]
            assert np.all(pixels >= -0.5) and np.all(pixels[:, 0] <= 255.5)
            assert np.all(pixels[:, 1] <= 159.5)
            model = pyopenlpt.loadCameraModel(str(folder / camera["openlpt_file"]))
            np.testing.assert_allclose(_project(model, points[:, :3]), pixels, atol=0.05)


def test_polynomial_expansion_is_exact():
    """The Soloff terms in normalised coordinates, expanded to powers of X, Y, Z in mm,
    give the same pixels (a random cubic, the exponents of rimcl's Soloff model)."""
    from rimcl.lpt.calibration import SOLOFF_EXPONENTS, SoloffModel

    rng = np.random.default_rng(4)
    model = SoloffModel(
        rng.normal(size=(len(SOLOFF_EXPONENTS), 2)),
        centre=np.array([3.0, 2.0, 1.0]),
        half=np.array([0.5, 1.5, 2.5]),
    )
    points = rng.uniform(0.0, 4.0, size=(50, 3))
    length_m = 0.02
    expanded = polynomial_coefficients(model.describe(), length_m)
    world = points[:, (1, 2, 0)] * length_m * 1e3
    pixels = np.zeros((50, 2))
    for (a, b, c), coefficient in expanded.items():
        pixels += np.outer(world[:, 0] ** a * world[:, 1] ** b * world[:, 2] ** c, coefficient)
    np.testing.assert_allclose(pixels, model.project(points), rtol=0, atol=1e-9)


def test_stb_tracks_rimcl_frames(dataset):
    """OpenLPT's STB on the uniform frames finds at least 95 % of the true tracks at an rms
    position error of at most 0.15 px, with few ghosts; through the field it reports the
    refraction error it sees."""
    folder = dataset / "dataset" / "C1"
    result = CliRunner().invoke(cli, ["lpt", "track", str(folder), "--with", "openlpt"])
    assert result.exit_code == 0, result.output
    stats = json.loads((folder / "openlpt" / "track_stats.json").read_text())
    uniform, field = stats["uniform"], stats["field"]
    assert uniform["true_tracers"] >= 0.9 * uniform["tracers"]
    assert uniform["found_share"] >= 0.95
    assert uniform["position_rms_px"]["all"] <= 0.15
    assert uniform["ghosts"] <= 0.05 * uniform["tracks"]
    # the frame spacing is 2.5 ms: velocities in mm/s, compared over the found tracks
    assert stats["units"]["velocity"] == "mm/s"
    for name in ("velocity_rms", "acceleration_rms"):
        assert all(np.isfinite(uniform[name][a]) for a in "XYZ")
    assert field["found_share"] >= 0.9
    refraction = stats["refraction"]
    assert refraction["points"] > 0 and refraction["position_rms_px"]["all"] > 0
    assert "true tracks found" in result.output and "refraction STB sees" in result.output


def test_track_refuses_a_folder_that_is_no_dataset(tmp_path):
    result = CliRunner().invoke(cli, ["lpt", "track", str(tmp_path)])
    assert result.exit_code != 0
    assert "not a rimcl LPT dataset" in result.output
    assert "Traceback" not in result.output
