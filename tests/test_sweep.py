"""The Δt sweep: every m-th frame of a study equals a study imaged m Δt apart."""

import numpy as np
import pytest

from rimcl.fields.field_writer import write_field
from rimcl.ptv.measure import run_render
from rimcl.ptv.render_file import write_render
from rimcl.ptv.sweep import every_mth_frame
from rimcl.scene.config import MeasureConfig, TimeConfig
from rimcl.stats.render_file import load_render


@pytest.fixture(scope="module")
def rotating_blobs(tmp_path_factory):
    count = 12
    h = 2 * np.pi / count
    x = np.arange(count) * h
    x3, x2, x1 = np.meshgrid(x, x, x, indexing="ij")
    times = np.arange(9) * 0.01
    density = [1 + 0.05 * np.sin(x1 + t) * np.cos(x2) * np.sin(x3 + 0.3) for t in times]
    velocity = [np.stack([0 * x1, np.sin(x3), np.cos(x2)], axis=-1)] * len(times)
    path = tmp_path_factory.mktemp("sweep") / "blobs.h5"
    write_field(
        path,
        density=density,
        times=times,
        origin=(0, 0, 0),
        spacing=(h, h, h),
        velocity=velocity,
        boundary="periodic",
    )
    return path


def _tables(path, out, device, frames, dt):
    options = {"tracers": 5, "fan": 4, "pixels": 512, "device": device, "fit_window": 3}
    config = MeasureConfig.from_options(frames=frames, dt=dt, **options)
    return load_render(write_render(out, run_render(path, case="C3", config=config)))


def test_every_other_frame_is_the_run_twice_as_far_apart(rotating_blobs, device, tmp_path):
    dense = _tables(rotating_blobs, tmp_path / "dense.h5", device, frames=5, dt=0.01)
    sparse = _tables(rotating_blobs, tmp_path / "sparse.h5", device, frames=3, dt=0.02)
    strided = every_mth_frame(dense, 2, TimeConfig(frames=1, fit_window=3))
    assert strided.dt == pytest.approx(sparse.dt)
    for group in ("velocity", "acceleration", "velocity_fit", "acceleration_fit"):
        expected, found = getattr(sparse, group), getattr(strided, group)
        assert set(found) >= {"u2_meas", "u3_ref"} or set(found) >= {"a2_meas", "a3_ref"}
        for name, values in expected.items():
            if name == "frame":
                continue
            # the same positions differenced: equal to rounding
            np.testing.assert_allclose(found[name], values, rtol=1e-9, atol=1e-12, err_msg=name)
    same = every_mth_frame(dense, 1, TimeConfig(frames=1, fit_window=3))
    np.testing.assert_array_equal(same.velocity["u3_meas"], dense.velocity["u3_meas"])
    assert every_mth_frame(dense, 5, TimeConfig(frames=1)) is None
