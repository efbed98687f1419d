"""Box cuts of field files, per-image scaling and the paper preset."""

import math

import numpy as np
import pytest

from rimcl.core.errors import RimclError
from rimcl.fields.crop import CroppedSource
from rimcl.fields.field_reader import FieldFile
from rimcl.fields.field_writer import write_field
from rimcl.imaging.frames import Imaging, image_batch
from rimcl.imaging.render import Renderer
from rimcl.scene.load import load_scene


@pytest.fixture(scope="module")
def periodic_file(tmp_path_factory):
    count = 16
    h = 2 * np.pi / count
    x = np.arange(count) * h
    x3, x2, x1 = np.meshgrid(x, x, x, indexing="ij")
    density = [1 + 0.05 * np.sin(x1) * np.cos(x2 + t) * np.sin(x3) for t in (0.0, 0.1)]
    velocity = [np.stack([0 * x1, np.sin(x3), np.cos(x2)], axis=-1)] * 2
    path = tmp_path_factory.mktemp("crop") / "box.h5"
    write_field(
        path,
        density=density,
        times=(0.0, 0.01),
        origin=(0, 0, 0),
        spacing=(h, h, h),
        velocity=velocity,
        boundary="periodic",
    )
    return path


def test_a_box_is_the_whole_field_cut(periodic_file):
    with FieldFile(periodic_file) as source:
        cut = CroppedSource(source, [[0, math.pi], [math.pi / 2, math.pi], [0, math.pi]])
        whole, part = source.field(1, 0.3), cut.field(1, 0.3)
        assert cut.shape == (9, 5, 9) and cut.boundary == "clamp"
        np.testing.assert_allclose(cut.origin, [0, math.pi / 2, 0], atol=1e-12)
        np.testing.assert_array_equal(part.delta_n, whole.delta_n[0:9, 4:9, 0:9])
        np.testing.assert_array_equal(part.gradient, whole.gradient[0:9, 4:9, 0:9])
        assert part.n_ref == whole.n_ref and part.boundary == "clamp"
        plane = source.sheet_velocity(0.005, 0.0)
        np.testing.assert_array_equal(cut.sheet_velocity(0.005, 0.0), plane[0:9, 4:9])
        with pytest.raises(RimclError, match="along x2"):
            CroppedSource(source, [[0, 1], [7, 8], [0, 1]])
        with pytest.raises(RimclError, match="lo < hi"):
            CroppedSource(source, [[1, 0], [0, 1], [0, 1]])


def _tracer_rays(offset, count=400, seed=1):
    rng = np.random.default_rng(seed)
    return offset + 0.002 * rng.standard_normal((1, count, 2))


@pytest.mark.parametrize("scaling", ["reference", "per_image"])
def test_per_image_scaling_keeps_a_dimmed_image_at_full_scale(scaling):
    imaging = Imaging(Renderer("exact", 1e-3, (0.0, 0.0), 2.0), 100.0, scaling=scaling)
    points = _tracer_rays(0.05)
    usable = np.ones(points.shape[:2], dtype=bool)
    reference = image_batch(imaging, points, usable, 1.0, np.zeros(1, dtype=int))
    dimmed = image_batch(
        imaging, points, usable, 0.5, np.zeros(1, dtype=int), scales=reference["scale"]
    )
    assert reference["peak"][0] == pytest.approx(1023)
    expected_peak = 1023 if scaling == "per_image" else 511.5
    assert dimmed["peak"][0] == pytest.approx(expected_peak)
    assert (dimmed["area"][0] > reference["area"][0] * 0.9) == (scaling == "per_image")


def test_paper_preset_and_a_file_on_top(tmp_path):
    scene = load_scene(preset="paper")
    assert scene["camera"]["fan"] == 100 and scene["renderer"]["kind"] == "paper"
    assert scene["renderer"]["scale"] == "per_image"
    assert scene["cases"]["thresholds"]["C4"] == 500.0
    assert scene["field"]["box"][0] == [0.0, math.pi]
    path = tmp_path / "scene.toml"
    path.write_text("[camera]\nfan = 10\n")
    mixed = load_scene(path, {"tracers.count": 5}, preset="paper")
    assert (mixed["camera"]["fan"], mixed["camera"]["kind"]) == (10, "plane")
    assert mixed["renderer"]["pixels"] == 8192 and mixed["tracers"]["count"] == 5
    with pytest.raises(RimclError, match="unknown preset"):
        load_scene(preset="papr")
