"""Field files open in xarray: every frame group has named dimensions (x3, x2, x1,
component), coordinates and units, the same values as rimcl's reader, which ignores them."""

import hashlib
import json
import warnings

import h5py
import numpy as np
import pytest

from rimcl.fields import field_writer
from rimcl.fields.field_reader import FieldFile
from rimcl.fields.field_writer import label_field_file, unit_texts, write_field
from rimcl.fields.sample import sample_path

xr = pytest.importorskip("xarray")

SHAPE = (4, 5, 6)  # (n3, n2, n1)
ORIGIN = (0.5, -1.0, 2.0)
SPACING = (0.1, 0.2, 0.3)
TIMES = (0.0, 0.25, 1.0)


def _frames(seed=0):
    rng = np.random.default_rng(seed)
    density = [1 + rng.random(SHAPE) for _ in TIMES]
    velocity = [rng.standard_normal((*SHAPE, 3)) for _ in TIMES]
    gradient = [rng.standard_normal((*SHAPE, 3)) for _ in TIMES]
    return density, velocity, gradient


def _open(path, frame):
    """One frame group in xarray, failing on any warning (phony dimensions warn)."""
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        return xr.open_dataset(path, group=f"frames/{frame:04d}", engine="h5netcdf").load()


def _nodes(axis, count, origin=ORIGIN, spacing=SPACING):
    return origin[axis] + spacing[axis] * np.arange(count)


def test_written_field_opens_in_xarray_with_dimensions_coordinates_and_units(tmp_path):
    density, velocity, gradient = _frames()
    path = write_field(tmp_path / "f.h5", density=density, velocity=velocity,
                       density_gradient=gradient, times=TIMES, origin=ORIGIN, spacing=SPACING,
                       attrs={"length_m": 0.3, "time_s": 0.5})  # fmt: skip
    with FieldFile(path) as ff:
        for k in range(len(TIMES)):
            data = _open(path, k)
            assert data["density"].dims == ("x3", "x2", "x1")
            assert data["velocity"].dims == ("x3", "x2", "x1", "component")
            assert data["density_gradient"].dims == ("x3", "x2", "x1", "component")
            assert list(data["component"].values) == ["x1", "x2", "x3"]
            for axis, name in enumerate(("x1", "x2", "x3")):
                np.testing.assert_array_equal(data[name], _nodes(axis, SHAPE[2 - axis]))
                assert data[name].attrs["units"] == "0.3 m"
            assert float(data["time"]) == TIMES[k] and data["time"].attrs["units"] == "0.5 s"
            np.testing.assert_array_equal(data["density"], ff.density(k))
            np.testing.assert_array_equal(data["velocity"], ff.velocity(k))
            np.testing.assert_array_equal(data["density_gradient"], ff.density_gradient(k))
            assert data["density"].attrs["units"] == "1"
            # physical = field value × the unit's factor: 0.3 m / 0.5 s, 1 / 0.3 m
            assert data["velocity"].attrs["units"] == f"{0.3 / 0.5!r} m/s"
            assert data["density_gradient"].attrs["units"] == f"{1 / 0.3!r} m^-1"
    # frames stack along time in one line
    frames = [_open(path, k) for k in range(len(TIMES))]
    stacked = xr.concat(frames, dim="time")
    assert stacked["density"].dims == ("time", "x3", "x2", "x1")
    np.testing.assert_array_equal(stacked["time"], TIMES)


def test_delta_n_and_sheet_files_without_scales_say_field_units(tmp_path):
    density, velocity, _ = _frames(1)
    sheet = [v[:, :, 2, 1:] for v in velocity]
    path = write_field(tmp_path / "s.h5", delta_n=density, n_ref=1.33, velocity_sheet=sheet,
                       sheet_x1=ORIGIN[0] + 2 * SPACING[0], times=TIMES, origin=ORIGIN,
                       spacing=SPACING)  # fmt: skip
    data = _open(path, 2)
    assert data["delta_n"].dims == ("x3", "x2", "x1")
    assert data["velocity_sheet"].dims == ("x3", "x2", "sheet_component")
    assert list(data["sheet_component"].values) == ["x2", "x3"]
    assert data["x2"].attrs["units"] == "field length units"
    assert data["time"].attrs["units"] == "field time units"
    assert data["velocity_sheet"].attrs["units"] == "(field length units)/(field time units)"
    assert data["delta_n"].attrs["n_ref"] == 1.33
    with FieldFile(path) as ff:
        values, n_ref = ff.delta_n(2)
        np.testing.assert_array_equal(data["delta_n"], values)
        assert n_ref == 1.33
        np.testing.assert_array_equal(
            data["velocity_sheet"], ff.sheet_velocity(TIMES[2], x1=ORIGIN[0] + 2 * SPACING[0])
        )


def test_unit_texts_with_one_scale_and_with_both():
    assert unit_texts(length_m=2.0)["velocity"] == "(2.0 m)/(field time units)"
    assert unit_texts(time_s=4.0)["velocity"] == "(field length units)/(4.0 s)"
    assert unit_texts(1.0, 1.0)["velocity"] == "1.0 m/s"
    assert unit_texts()["gradient"] == "1/(field length units)"


def _stored(path):
    """Every stored byte and value of the frames' arrays, and what the reader returns."""
    found = {}
    with h5py.File(path) as h5:
        for name, group in h5["frames"].items():
            found[f"{name} attrs"] = dict(group.attrs)
            for array in ("density", "velocity"):
                dataset = group[array]
                raw = hashlib.sha256()
                for k in range(dataset.id.get_num_chunks()):
                    offset = dataset.id.get_chunk_info(k).chunk_offset
                    raw.update(dataset.id.read_direct_chunk(offset)[1])
                found[f"{name}/{array} chunks"] = raw.hexdigest()
                found[f"{name}/{array}"] = dataset[()].tobytes()
    with FieldFile(path) as ff:
        found["times"] = ff.times.tobytes()
        for k in range(ff.n_frames):
            field = ff.field(k, case="C3")
            found[f"field {k}"] = field.delta_n.tobytes() + field.gradient.tobytes()
            found[f"velocity {k}"] = ff.velocity(k).tobytes()
    return found


def test_an_old_file_reads_the_same_and_is_labelled_in_place(tmp_path, monkeypatch):
    density, velocity, _ = _frames(2)
    with monkeypatch.context() as patch:  # a file of the layout before dimension scales
        patch.setattr(field_writer, "attach_scales", lambda h5: None)
        path = write_field(tmp_path / "old.h5", density=density, velocity=velocity,
                           times=TIMES, origin=ORIGIN, spacing=SPACING)  # fmt: skip
    with h5py.File(path) as h5:
        assert "x1" not in h5["frames/0000"]
    before = _stored(path)
    assert label_field_file(path) is True
    assert _stored(path) == before
    assert label_field_file(path) is False  # already labelled: left as it is
    data = _open(path, 1)
    assert data["velocity"].dims == ("x3", "x2", "x1", "component")
    np.testing.assert_array_equal(data["density"], np.float32(density[1]))
    with h5py.File(path) as h5:
        assert json.loads(h5.attrs["dimension_scales"])["versions"]["h5py"] == h5py.__version__


def test_the_shipped_sample_opens_in_xarray_with_the_readers_values():
    path = sample_path()
    with FieldFile(path) as ff:
        for k in (0, ff.n_frames - 1):
            data = _open(path, k)
            assert data["density"].dims == ("x3", "x2", "x1")
            assert data["velocity_sheet"].dims == ("x3", "x2", "sheet_component")
            np.testing.assert_array_equal(data["density"], ff.density(k))
            np.testing.assert_array_equal(
                data["velocity_sheet"], ff.sheet_velocity(ff.times[k], x1=0.0)
            )
            assert float(data["time"]) == ff.times[k]
            np.testing.assert_allclose(
                data["x3"], _nodes(2, 64, ff.origin, ff.spacing), rtol=0, atol=0
            )
            assert data["x1"].attrs["units"] == "field length units"
