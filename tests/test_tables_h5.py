"""Per-tracer tables as (id, frame) datasets: xarray's named dimensions, rimcl's 1-D columns."""

import h5py
import numpy as np
import pytest
import xarray as xr

from rimcl.core.tables_h5 import label_table, read_table, write_tracer_table


def _table(count=5, frames=(0, 1, 2)):
    """A frame-major table: all tracers of the first frame first."""
    rng = np.random.default_rng(1)
    ids = np.arange(10, 10 + count)
    rows = count * len(frames)
    return {
        "id": np.tile(ids, len(frames)),
        "frame": np.repeat(frames, count),
        "time": np.repeat(0.25 * np.asarray(frames), count),
        "x2_meas": rng.standard_normal(rows),
        "u3_meas": rng.standard_normal(rows),
        "flags": rng.integers(0, 4, rows),
    }


def test_a_frame_major_table_opens_as_id_frame_and_reads_back_exactly(tmp_path):
    table = _table()
    path = tmp_path / "t.h5"
    with h5py.File(path, "w") as h5:
        write_tracer_table(h5.create_group("tracers"), table)
    data = xr.open_dataset(path, group="tracers", engine="h5netcdf")
    assert data["x2_meas"].dims == ("id", "frame") and data["x2_meas"].shape == (5, 3)
    np.testing.assert_array_equal(data["id"], np.arange(10, 15))
    np.testing.assert_array_equal(data["frame"], [0, 1, 2])
    assert data["time"].dims == ("frame",) and "time" in data.coords
    # tracer 12 at frame 1 is row 1 * 5 + 2 of the frame-major table
    assert data["x2_meas"].sel(id=12, frame=1).item() == table["x2_meas"][7]
    assert data["flags"].sel(id=14, frame=2).item() == table["flags"][14]
    assert data["x2_meas"].attrs["units"] == "L0" and data["u3_meas"].attrs["units"] == "L0/T0"
    assert data["time"].attrs["units"] == "T0"
    with h5py.File(path, "r") as h5:
        read = read_table(h5["tracers"])
    assert set(read) == set(table)
    for name, values in table.items():
        np.testing.assert_array_equal(read[name], values, err_msg=name)
        assert read[name].dtype == values.dtype


def test_evaluation_frames_and_a_single_frame_keep_their_numbers(tmp_path):
    path = tmp_path / "t.h5"
    tables = {"velocity": _table(frames=(1, 2, 3, 4)), "one": _table(count=3, frames=(2,))}
    with h5py.File(path, "w") as h5:
        for name, table in tables.items():
            write_tracer_table(h5.create_group(name), table)
    for name, table in tables.items():
        data = xr.open_dataset(path, group=name, engine="h5netcdf")
        np.testing.assert_array_equal(data["frame"], np.unique(table["frame"]))
        with h5py.File(path, "r") as h5:
            read = read_table(h5[name])
        for column, values in table.items():
            np.testing.assert_array_equal(read[column], values, err_msg=column)


@pytest.mark.parametrize(
    "change",
    [
        lambda t: {k: v[1:] for k, v in t.items()},  # a tracer missing at one frame
        lambda t: (
            {k: v.reshape(3, 5)[:, ::-1].reshape(-1) for k, v in t.items()}
            | {"id": np.tile([10, 10, 11, 12, 13], 3)}
        ),  # a repeated id
        lambda t: {k: v.reshape(3, 5).T.reshape(-1) for k, v in t.items()},  # tracer-major
    ],
)
def test_a_table_that_is_no_rectangle_stays_rows_and_reads_back(tmp_path, change):
    table = change(_table())
    path = tmp_path / "t.h5"
    with h5py.File(path, "w") as h5:
        write_tracer_table(h5.create_group("t"), table)
    data = xr.open_dataset(path, group="t", engine="h5netcdf")
    assert data["x2_meas"].dims == ("row",)
    with h5py.File(path, "r") as h5:
        read = read_table(h5["t"])
    assert set(read) == set(table)
    for name, values in table.items():
        np.testing.assert_array_equal(read[name], values, err_msg=name)


def test_row_tables_of_older_files_read_without_their_row_scale(tmp_path):
    table = _table()
    path = tmp_path / "old.h5"
    with h5py.File(path, "w") as h5:
        group = h5.create_group("tracers")
        for name, values in table.items():
            group[name] = values
        label_table(group)  # the layout of schema version 1
        assert "row" in group
        read = read_table(group)
    assert set(read) == set(table)
    for name, values in table.items():
        np.testing.assert_array_equal(read[name], values, err_msg=name)
