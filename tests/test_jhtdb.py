"""Import of JHTDB cut-outs (HDF5 / netCDF-4 layouts) and .npz files, built here."""

import h5netcdf
import h5py
import numpy as np
import pytest
from click.testing import CliRunner

from rimcl.cli.main import cli
from rimcl.fields.derivatives import gradient
from rimcl.fields.field_reader import FieldFile
from rimcl.fields.jhtdb import parse_crop, parse_frames, read_cutouts

NX, NY, NZ = 8, 6, 10  # a full periodic box: x, y, z have 8, 6, 10 nodes over 2π
INDICES = (285, 286)


def _coordinates():
    return {a: (2 * np.pi * np.arange(n) / n).astype(np.float32) for a, n in
            (("x", NX), ("y", NY), ("z", NZ))}  # fmt: skip


def _flow(index):
    """Density (nz, ny, nx) and velocity (nz, ny, nx, 3) at a time index, float32."""
    c = _coordinates()
    z, y, x = np.meshgrid(c["z"], c["y"], c["x"], indexing="ij")
    phase = 0.1 * index
    density = 1.05 + 0.05 * np.sin(x + phase) * np.cos(2 * y) + 0.01 * np.cos(z)
    velocity = np.stack([np.sin(z + phase), np.cos(x), np.sin(y) * np.cos(x)], axis=-1)
    return density.astype(np.float32), velocity.astype(np.float32)


def _web_service_file(path, indices=INDICES, coordinates=None, **overrides):
    """Several times in one HDF5 file, as the JHTDB web cut-out service writes them."""
    coordinates = coordinates or _coordinates()
    with h5py.File(path, "w") as h5:
        for index in indices:
            density, velocity = _flow(index)
            h5[f"Density_{index:04d}"] = overrides.get("density", density[..., None])
            h5[f"Velocity_{index:04d}"] = overrides.get("velocity", velocity)
        for axis, values in coordinates.items():
            h5[f"{axis}coor"] = values
        h5["_start"] = np.array([0, 0, 0, indices[0]], dtype=np.int32)  # service bookkeeping
    return path


def _netcdf_files(directory):
    """One netCDF-4 file per variable and time (giverny 3.x spelling), via h5netcdf."""
    paths = []
    for index in INDICES:
        density, velocity = _flow(index)
        for variable, values in (("density", density[..., None]), ("velocity", velocity)):
            path = directory / f"{variable}_{index}.nc"
            with h5netcdf.File(path, "w") as nc:
                nc.dimensions = {"zcoor": NZ, "ycoor": NY, "xcoor": NX,
                                 "values": values.shape[-1]}  # fmt: skip
                for axis, coordinate in _coordinates().items():
                    nc.create_variable(f"{axis}coor", (f"{axis}coor",), np.float32)[:] = coordinate
                dims = ("zcoor", "ycoor", "xcoor", "values")
                nc.create_variable(f"{variable}_{index:04d}", dims, np.float32)[:] = values
            paths.append(path)
    return paths


def _import(*args):
    return CliRunner().invoke(cli, ["field", "import", *map(str, args)])


def test_web_service_layout_imports_with_values_shapes_spacing_and_times(tmp_path):
    source = _web_service_file(tmp_path / "cutout.h5")
    out = tmp_path / "field.h5"
    result = _import(source, "-o", out)
    assert result.exit_code == 0, result.output
    with FieldFile(out) as ff:
        assert ff.shape == (NZ, NY, NX) and ff.n_frames == 2
        np.testing.assert_allclose(ff.spacing, 2 * np.pi / np.array([NX, NY, NZ]), rtol=1e-6)
        np.testing.assert_array_equal(ff.origin, 0.0)
        # JHTDB mixing: index i is t = (i - 1) * 0.04, so index 286 is t = 11.4
        np.testing.assert_allclose(ff.times, [11.36, 11.4], rtol=1e-12)
        assert ff.boundary == "periodic"  # a full 2π box
        for frame, index in enumerate(INDICES):
            density, velocity = _flow(index)
            np.testing.assert_array_equal(ff.density(frame), density)
            np.testing.assert_array_equal(ff.velocity(frame), velocity)
            spectral = gradient(density.astype(np.float64), ff.spacing, "spectral", True)
            np.testing.assert_allclose(ff.density_gradient(frame), spectral, atol=1e-6)
        assert ff.attrs["axes"] == "x1=x,x2=y,x3=z"
        assert ff.attrs["time_indices"] == list(INDICES)
    info = CliRunner().invoke(cli, ["field", "info", "--values", str(out)])
    assert info.exit_code == 0 and "8 x 6 x 10" in info.output and "C4" in info.output
    picture = tmp_path / "imported.png"
    shown = CliRunner().invoke(cli, ["field", "show", str(out), "--case", "C1", "-o", str(picture)])
    assert shown.exit_code == 0, shown.output
    assert picture.read_bytes().startswith(b"\x89PNG")


def test_netcdf_files_one_per_time_import_the_same(tmp_path):
    paths = _netcdf_files(tmp_path)
    with h5py.File(paths[0]) as h5:
        assert "values" in h5  # the dummy dimension dataset netCDF-4 writes, to be skipped
    out = tmp_path / "field.h5"
    result = _import(*paths, "-o", out, "--frames", "286")
    assert result.exit_code == 0, result.output
    density, velocity = _flow(286)
    with FieldFile(out) as ff:
        assert ff.n_frames == 1 and ff.times[0] == pytest.approx(11.4)
        np.testing.assert_array_equal(ff.density(0), density)
        np.testing.assert_array_equal(ff.velocity(0), velocity)


def test_axes_mapping_transposes_arrays_and_permutes_components(tmp_path):
    source = _web_service_file(tmp_path / "cutout.h5")
    flow = read_cutouts([source], axes="z,y,x")
    density, velocity = _flow(285)
    # x1 = z, x2 = y, x3 = x: rimcl arrays are (n3, n2, n1) = (nx, ny, nz)
    np.testing.assert_array_equal(flow.density[0], density.transpose(2, 1, 0))
    np.testing.assert_array_equal(flow.velocity[0], velocity.transpose(2, 1, 0, 3)[..., ::-1])
    np.testing.assert_allclose(flow.spacing, 2 * np.pi / np.array([NZ, NY, NX]), rtol=1e-6)
    flow = read_cutouts([source], axes="y,z,x")
    np.testing.assert_array_equal(flow.density[0], density.transpose(2, 0, 1))
    np.testing.assert_array_equal(flow.velocity[0], velocity.transpose(2, 0, 1, 3)[..., [1, 2, 0]])


def test_crop_and_stride_select_nodes_and_make_a_clamped_field(tmp_path):
    source = _web_service_file(tmp_path / "cutout.h5")
    out = tmp_path / "crop.h5"
    result = _import(source, "-o", out, "--crop", "1:7,:,2:9", "--stride", "2,1,3",
                     "--gradient", "fd6", "--frames", "285-285")  # fmt: skip
    assert result.exit_code == 0, result.output
    density, velocity = _flow(285)
    with FieldFile(out) as ff:
        np.testing.assert_array_equal(ff.density(0), density[2:9:3, :, 1:7:2])
        np.testing.assert_array_equal(ff.velocity(0), velocity[2:9:3, :, 1:7:2])
        h = 2 * np.pi / np.array([NX, NY, NZ])
        np.testing.assert_allclose(ff.origin, [h[0], 0, 2 * h[2]], rtol=1e-6)
        np.testing.assert_allclose(ff.spacing, h * [2, 1, 3], rtol=1e-6)
        assert ff.boundary == "clamp" and ff.attrs["density_gradient"] == "fd6"
        cropped = density[2:9:3, :, 1:7:2].astype(np.float64)
        expected = gradient(cropped, ff.spacing, "fd6", False)
        np.testing.assert_allclose(ff.density_gradient(0), expected, rtol=1e-5, atol=1e-6)


def test_stored_times_win_and_t0_dt_apply_otherwise(tmp_path):
    source = _web_service_file(tmp_path / "cutout.h5")
    flow = read_cutouts([source], t0=1.0, dt=0.005)
    np.testing.assert_allclose(flow.times, [1.0 + 284 * 0.005, 1.0 + 285 * 0.005])
    with h5py.File(source, "a") as h5:
        h5["Density_0286"].attrs["time"] = 42.0
    assert read_cutouts([source]).times[1] == 42.0


def test_npz_with_documented_names(tmp_path):
    densities, velocities = zip(*(_flow(i) for i in INDICES), strict=True)
    path = tmp_path / "flow.npz"
    np.savez(path, density=np.stack(densities), velocity=np.stack(velocities),
             times=np.array([0.0, 0.005]), spacing=np.array([0.1, 0.2, 0.3]),
             origin=np.array([1.0, 2.0, 3.0]))  # fmt: skip
    out = tmp_path / "npz.h5"
    result = _import(path, "-o", out)
    assert result.exit_code == 0, result.output
    with FieldFile(out) as ff:
        np.testing.assert_array_equal(ff.times, [0.0, 0.005])
        np.testing.assert_array_equal(ff.spacing, [0.1, 0.2, 0.3])
        np.testing.assert_array_equal(ff.origin, [1.0, 2.0, 3.0])
        np.testing.assert_array_equal(ff.density(1), densities[1])
        np.testing.assert_array_equal(ff.velocity(0), velocities[0])
        assert ff.boundary == "clamp"
    single = tmp_path / "one.npz"
    np.savez(single, density=densities[0], **{f"{a}coor": c for a, c in _coordinates().items()})
    result = _import(single, "-o", tmp_path / "one.h5", "--t0", "11.4")
    assert result.exit_code == 0, result.output
    with FieldFile(tmp_path / "one.h5") as ff:
        assert ff.times.tolist() == [11.4] and ff.boundary == "periodic" and not ff.has_velocity


def _bad_coordinates():
    coordinates = _coordinates()
    coordinates["y"] = coordinates["y"] ** 1.5  # stretched
    return coordinates


def _missing_coordinates():
    coordinates = _coordinates()
    del coordinates["z"]
    return coordinates


@pytest.mark.parametrize(
    ("make", "message"),
    [
        (lambda p: _web_service_file(p, density=np.full((NZ, NY, NX, 1), np.nan, np.float32)),
         "NaN or infinite"),
        (lambda p: _web_service_file(p, velocity=np.full((NZ, NY, NX, 3), np.inf, np.float32)),
         "NaN or infinite"),
        (lambda p: _web_service_file(p, coordinates=_missing_coordinates()), "no zcoor"),
        (lambda p: _web_service_file(p, coordinates=_bad_coordinates()), "not uniformly spaced"),
        (lambda p: _web_service_file(p, density=np.ones((NZ, NY, NX + 1, 1), np.float32)),
         "has shape"),
        (lambda p: _web_service_file(p, velocity=np.ones((NZ, NY, NX, 2), np.float32)),
         "has shape"),
    ],
)  # fmt: skip
def test_bad_cutouts_give_one_error_line_and_no_output(tmp_path, make, message):
    source = make(tmp_path / "bad.h5")
    out = tmp_path / "out.h5"
    result = _import(source, "-o", out)
    assert result.exit_code == 1
    lines = result.output.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("Error: ") and message in lines[0], lines
    assert not out.exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["bad.h5"]


def test_inconsistent_files_and_selections_are_refused(tmp_path):
    first = _web_service_file(tmp_path / "a.h5", indices=(285,))
    other_grid = {**_coordinates(), "x": _coordinates()["x"] + np.float32(0.5)}
    shifted = _web_service_file(tmp_path / "b.h5", indices=(286,), coordinates=other_grid)
    same_time = _web_service_file(tmp_path / "c.h5", indices=(285,))
    velocity_only = tmp_path / "v.h5"
    with h5py.File(velocity_only, "w") as h5:
        h5["Velocity_0001"] = _flow(1)[1]
        for axis, values in _coordinates().items():
            h5[f"{axis}coor"] = values
    out = tmp_path / "out.h5"
    for args, message in [
        ((first, shifted), "differs from the other files' grid"),
        ((first, same_time), "appears twice"),
        ((velocity_only,), "no density"),
        ((first, "--frames", "300"), "no density for time index [300]"),
        ((first, "--crop", "0:1,:,:"), "at least 2"),
        ((first, "--axes", "x,x,z"), "permutation"),
        ((first, "--boundary", "periodic", "--crop", "0:4,:,:"), "full period"),
        ((tmp_path / "missing.h5",), "does not exist"),
    ]:
        result = _import(*args, "-o", out)
        assert result.exit_code == 1, (args, result.output)
        assert message in result.output and len(result.output.strip().splitlines()) == 1
        assert not out.exists()


def test_existing_output_is_kept(tmp_path):
    source = _web_service_file(tmp_path / "cutout.h5")
    out = tmp_path / "out.h5"
    out.write_bytes(b"old")
    result = _import(source, "-o", out)
    assert result.exit_code == 1 and "exists" in result.output
    assert out.read_bytes() == b"old"
    assert _import(source, "-o", out, "--overwrite").exit_code == 0


def test_spec_parsers():
    assert parse_frames("285-287,290") == [285, 286, 287, 290]
    assert parse_crop(":,2:,:-1") == (slice(None), slice(2, None), slice(None, -1))
