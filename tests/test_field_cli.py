"""``rimcl field info`` and ``rimcl field show`` on the shipped sample and on other files."""

import json

import numpy as np
import pytest
from click.testing import CliRunner
from PIL import Image

from rimcl.cli.main import cli
from rimcl.fields.cases import CASES, PAPER_DELTA_N_MAX
from rimcl.fields.field_reader import FieldFile
from rimcl.fields.field_writer import write_field
from rimcl.fields.sample import sample_path


def _run(*args):
    return CliRunner().invoke(cli, ["field", *map(str, args)])


@pytest.fixture
def small_file(tmp_path):
    """A clamped 12 x 10 x 8 density file without velocity (as an import might give)."""
    i3, i2, i1 = np.meshgrid(np.arange(8), np.arange(10), np.arange(12), indexing="ij")
    density = [1.0 + 0.01 * np.sin(i1 / 3 + t) * np.cos(i2 / 4) + 0.001 * i3 for t in (0, 1)]
    return write_field(tmp_path / "small.h5", density=density, times=[2.0, 2.5],
                       origin=(-1, 0, 1), spacing=(0.5, 0.25, 0.125),
                       attrs={"title": "small test field"})  # fmt: skip


def test_group_lists_its_subcommands():
    result = CliRunner().invoke(cli, ["field", "--help"])
    assert result.exit_code == 0
    for name in ("synth", "import", "info", "show"):
        assert name in result.output


def test_info_on_the_sample_reports_grid_frames_and_delta_n_per_case():
    result = _run("info", "--json", "--values")
    assert result.exit_code == 0, result.output
    info = json.loads(result.output)
    with FieldFile(sample_path()) as ff:
        spread = max(ff.density(k).max() for k in range(ff.n_frames)) - min(
            ff.density(k).min() for k in range(ff.n_frames)
        )
        times = ff.times.tolist()
    assert info["shape_n3_n2_n1"] == [64, 64, 64] and info["boundary"] == "periodic"
    assert info["times"] == times and info["has_velocity"]
    assert info["memory_bytes_per_frame"]["field_trilinear"] == 64**3 * 16
    for name, g in CASES.items():
        entry = info["delta_n_max"][name]
        assert entry["delta_n_max"] == pytest.approx(g * float(spread), rel=1e-6)
        assert entry["paper"] == PAPER_DELTA_N_MAX[name]
    text = _run("info", "--values").output
    assert "64 x 64 x 64" in text and "C4" in text and "water" in text


def test_info_on_another_file(small_file):
    result = _run("info", small_file)
    assert result.exit_code == 0, result.output
    assert "12 x 10 x 8" in result.output and "clamp" in result.output
    assert "small test field" in result.output and "velocity rms" not in result.output


def _png(path):
    with Image.open(path) as image:
        return np.asarray(image.convert("L"), dtype=float), dict(image.info)


def test_show_writes_a_readable_png_of_the_sample(tmp_path):
    out = tmp_path / "sample.png"
    result = _run("show", "-o", out)
    assert result.exit_code == 0, result.output
    pixels, info = _png(out)
    assert pixels.shape[1] > 2 * pixels.shape[0]  # three panels side by side
    assert pixels.std() > 20  # not blank
    config = json.loads(info["Description"])
    assert config["field"] == sample_path() and config["quantity"] == "all"
    assert info["Software"].startswith("rimcl ")


def test_show_variants_and_errors(tmp_path, small_file):
    out = tmp_path / "f.png"
    result = _run("show", small_file, "--case", "C1", "--plane", "x1x2", "--time", "2.25",
                  "-o", out)  # fmt: skip
    assert result.exit_code == 0, result.output
    pixels, info = _png(out)
    assert json.loads(info["Description"])["case"] == "C1" and pixels.std() > 10
    pdf = tmp_path / "f.pdf"
    assert _run("show", small_file, "--quantity", "gradient", "-o", pdf).exit_code == 0
    assert pdf.read_bytes().startswith(b"%PDF")
    for args, message in [
        (("--quantity", "velocity"), "holds no velocity"),
        (("--plane", "x2x3", "--at", "100"), "outside the field"),
        (("--time", "9"), "outside the stored frames"),
        (("--frame", "5"), "frame 5 does not exist"),
        (("-o", tmp_path / "f.jpg"), ".png or .pdf"),
        ((), "exists"),
    ]:
        options = args if "-o" in args else (*args, "-o", out)
        result = _run("show", small_file, *options)
        assert result.exit_code == 1, (args, result.output)
        lines = result.output.strip().splitlines()
        assert len(lines) == 1 and message in lines[0], (args, lines)
    assert not (tmp_path / "f.jpg").exists()
