"""Sheet-only velocity: the field file's ``velocity_sheet``, ``field synth --sheet-velocity``."""

import h5py
import numpy as np
import pytest
from click.testing import CliRunner

from rimcl.cli.main import cli
from rimcl.core.errors import RimclError
from rimcl.fields.field_reader import FieldFile
from rimcl.fields.field_writer import write_field
from rimcl.fields.info import describe_field_file
from rimcl.fields.synth import BoussinesqSolver

SHAPE = (6, 5, 8)  # (n3, n2, n1)
SPACING = (0.25, 0.5, 0.75)


def _plane(t):
    """``(u2, u3) = (i2 + 10 t, i3 - t)`` on the (n3, n2) nodes: exact in float32."""
    i3, i2 = np.meshgrid(np.arange(SHAPE[0]), np.arange(SHAPE[1]), indexing="ij")
    return np.stack([i2 + 10 * t, i3 - t], axis=-1)


def _write(path, times=(0.0, 0.5, 1.0), x1=0.5, boundary="periodic", **extra):
    options = dict(
        density=[np.ones(SHAPE)] * len(times),
        velocity_sheet=[_plane(t) for t in times],
        sheet_x1=x1,
        times=times,
        origin=(0.0, 0.0, 0.0),
        spacing=SPACING,
        boundary=boundary,
    )
    options.update(extra)
    return write_field(path, **options)


def test_sheet_velocity_round_trip_layout_and_time_interpolation(tmp_path):
    path = _write(tmp_path / "f.h5")
    with h5py.File(path) as h5:  # the documented layout, read with plain h5py
        dataset = h5["frames/0001/velocity_sheet"]
        assert dataset.shape == (6, 5, 2) and dataset.dtype == np.float32
        assert dataset.attrs["x1"] == 0.5 and "velocity" not in h5["frames/0001"]
    with FieldFile(path) as ff:
        assert ff.has_velocity and not ff.has_full_velocity and ff.velocity_sheet_x1 == 0.5
        np.testing.assert_array_equal(ff.sheet_velocity(0.5, 0.5), _plane(0.5))
        np.testing.assert_allclose(ff.sheet_velocity(0.25, 0.5, method="linear"), _plane(0.25))
        # periodic along x1 (period 8 × 0.75 = 6): the same plane one period on
        np.testing.assert_array_equal(ff.sheet_velocity(1.0, 6.5), _plane(1.0))
        with pytest.raises(RimclError, match=r"only on x1 = 0.5, not on x1 = 0.75"):
            ff.sheet_velocity(0.0, 0.75)
        with pytest.raises(RimclError, match="not the full velocity"):
            ff.velocity(0)


def test_full_velocity_file_is_not_a_sheet_file(tmp_path):
    path = write_field(
        tmp_path / "full.h5",
        density=[np.ones(SHAPE)],
        velocity=[np.zeros((*SHAPE, 3))],
        times=[0.0],
        origin=(0, 0, 0),
        spacing=SPACING,
    )
    with FieldFile(path) as ff:
        assert ff.has_velocity and ff.has_full_velocity and ff.velocity_sheet_x1 is None


@pytest.mark.parametrize(
    ("extra", "match"),
    [
        ({"velocity": [np.zeros((*SHAPE, 3))] * 3}, "either velocity or velocity_sheet"),
        ({"sheet_x1": None}, "needs sheet_x1"),
        ({"velocity_sheet": None}, "only goes with velocity_sheet"),
        ({"velocity_sheet": [np.zeros((5, 6, 2))] * 3}, r"must have shape \(6, 5, 2\)"),
        ({"velocity_sheet": [np.full((6, 5, 2), np.nan)] * 3}, "NaN"),
        ({"velocity_sheet": [np.zeros((6, 5, 2))] * 2}, "2 frames, expected 3"),
        ({"boundary": "clamp", "x1": 6.0}, r"sheet_x1 = 6 must lie in the field along x1"),
        ({"x1": float("inf")}, "must lie in the field"),
    ],
)
def test_bad_sheet_velocity_is_refused_on_writing(tmp_path, extra, match):
    with pytest.raises(RimclError, match=match):
        _write(tmp_path / "bad.h5", **extra)
    assert not (tmp_path / "bad.h5").exists()


def test_inconsistent_sheet_velocity_is_refused_on_reading(tmp_path):
    path = _write(tmp_path / "f.h5")
    with h5py.File(path, "a") as h5:
        h5["frames/0002/velocity_sheet"].attrs["x1"] = 1.5
    with FieldFile(path) as ff, pytest.raises(RimclError, match="different planes"):
        _ = ff.has_velocity
    path = _write(tmp_path / "g.h5")
    with h5py.File(path, "a") as h5:
        del h5["frames/0001/velocity_sheet"]
    with FieldFile(path) as ff, pytest.raises(RimclError, match="missing from /frames/0001"):
        ff.sheet_velocity(0.0, 0.5)


def test_info_describes_the_sheet_velocity(tmp_path):
    info = describe_field_file(_write(tmp_path / "f.h5"), values=True)
    assert info["has_velocity"] and info["velocity_sheet_x1"] == 0.5
    expected = np.sqrt(np.mean(_plane(0.0).reshape(-1, 2) ** 2, axis=0))
    np.testing.assert_allclose(info["frames"][0]["velocity_rms"], expected)


def test_spectral_sheet_plane_is_exact_between_nodes():
    solver = BoussinesqSolver(16, 400.0)
    x = 2 * np.pi * np.arange(16) / 16
    x3, x2, x1 = np.meshgrid(x, x, x, indexing="ij")
    # band-limited in x1 (modes 1 and 3), not solenoidal: the evaluation needs neither
    velocity = np.stack(
        [np.zeros_like(x1), np.sin(x1 + 0.3) * np.cos(x3), np.cos(3 * x1) + np.sin(2 * x2)]
    )
    plane = solver.sheet_velocity(solver.forward(velocity), 0.77)
    expected = np.stack(
        [np.sin(0.77 + 0.3) * np.cos(x3[..., 0]), np.cos(3 * 0.77) + np.sin(2 * x2[..., 0])],
        axis=-1,
    )
    np.testing.assert_allclose(plane, expected, rtol=0, atol=1e-14)


def test_synth_sheet_velocity_matches_the_full_run_on_its_plane(tmp_path):
    node_x1 = 3 * 2 * np.pi / 16
    files = {}
    for name, extra in (("full", []), ("sheet", ["--sheet-velocity", repr(node_x1)])):
        files[name] = tmp_path / f"{name}.h5"
        options = "--grid 16 --seed 4 --start-time 0.5 --frames 4 --frame-dt 0.1 --no-gradient"
        args = ["field", "synth", *options.split(), "-o", str(files[name])]
        result = CliRunner().invoke(cli, args + extra)
        assert result.exit_code == 0, result.output
    with FieldFile(files["full"]) as full, FieldFile(files["sheet"]) as sheet:
        np.testing.assert_allclose(sheet.times, 0.5 + 0.1 * np.arange(4), rtol=1e-12)
        assert not sheet.has_full_velocity and sheet.velocity_sheet_x1 == node_x1
        np.testing.assert_array_equal(sheet.density(3), full.density(3))
        for t in sheet.times:
            # the same float64 plane, rounded to float32 in both files
            np.testing.assert_array_equal(
                sheet.sheet_velocity(t, node_x1), full.sheet_velocity(t, node_x1)
            )
    assert files["sheet"].stat().st_size < 0.6 * files["full"].stat().st_size
