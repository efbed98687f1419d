"""Your own flow: CF netCDF and .npz imports of temperature, salinity, density, index or δn,
and the guard that no case applies a fluid model to a scalar it does not fit."""

import h5netcdf
import h5py
import numpy as np
import pytest
from click.testing import CliRunner

from rimcl.cli.main import cli
from rimcl.core.errors import RimclError
from rimcl.fields.cf_import import import_dataset
from rimcl.fields.field_loading import load_field
from rimcl.fields.field_reader import FieldFile
from rimcl.fields.field_writer import write_field
from rimcl.fields.media import Fluid, water_index
from rimcl.ptv.field_source import case_of
from rimcl.ptv.measure import run_render
from rimcl.scene.config import FluidConfig, MeasureConfig

N = 9  # nodes per axis of the tank
SIDE_MM = 80.0  # its side


def _tank(path, *, kelvin=True, frames=2):
    """A CF file: temperature rising linearly with height z (20 → 50 °C), dims
    (time, z, y, x) with x fastest; coordinates in mm; velocity in m/s."""
    axis = np.linspace(0.0, SIDE_MM, N)
    z, _, x = np.meshgrid(axis, axis, axis, indexing="ij")
    temperature_c = 20.0 + 30.0 * z / SIDE_MM + 0.5 * x / SIDE_MM
    with h5netcdf.File(path, "w") as f:
        f.dimensions = {"time": frames, "z": N, "y": N, "x": N}
        for name, axis_letter in (("x", "X"), ("y", "Y"), ("z", "Z")):
            v = f.create_variable(name, (name,), "f8")
            v[:] = axis
            v.attrs.update(units="mm", axis=axis_letter)
        t = f.create_variable("time", ("time",), "f8")
        t[:] = 0.005 * np.arange(frames)
        t.attrs["units"] = "seconds since 2024-01-01"
        v = f.create_variable("temp", ("time", "z", "y", "x"), "f8")
        v[:] = np.stack([temperature_c] * frames) + (273.15 if kelvin else 0.0)
        v.attrs.update(units="K" if kelvin else "degC", standard_name="sea_water_temperature")
        for name, value in (("u", 0.001), ("v", 0.002), ("w", 0.003)):
            c = f.create_variable(name, ("time", "z", "y", "x"), "f4")
            c[:] = value
            c.attrs["units"] = "m s-1"
    return temperature_c


@pytest.fixture(scope="module")
def tank(tmp_path_factory):
    folder = tmp_path_factory.mktemp("tank")
    temperature_c = _tank(folder / "tank.nc")
    imported = import_dataset(folder / "tank.nc", folder / "tank.h5", depth_axis="y")
    # the same field written by hand: x1 = y (depth), x2 = x, x3 = z; (n3, n2, n1) = (z, x, y)
    n = water_index(np.transpose(temperature_c, (0, 2, 1)), 532.0)
    by_hand = folder / "by_hand.h5"
    write_field(
        by_hand,
        delta_n=[n - 1.335] * 2,
        n_ref=1.335,
        times=(0.0, 0.005),
        origin=(0, 0, 0),
        spacing=(SIDE_MM / (N - 1),) * 3,
        velocity=[np.broadcast_to(np.array([2.0, 1.0, 3.0]), (N, N, N, 3))] * 2,
    )
    return imported, by_hand


def test_cf_temperature_gives_the_index_of_rimcl_media_on_the_right_axes(tank):
    imported, by_hand = tank
    mine, theirs = load_field(imported), load_field(by_hand)
    n_mine = mine.delta_n.astype(np.float64) + mine.n_ref
    n_theirs = theirs.delta_n.astype(np.float64) + theirs.n_ref
    np.testing.assert_allclose(n_mine, n_theirs, rtol=0, atol=1e-9)
    with FieldFile(imported) as ff:
        assert ff.kind == "delta_n"
        assert ff.attrs["scalar"] == "temperature" and ff.attrs["scalar_units"] == "K"
        assert ff.attrs["axes"] == "x1=y,x2=x,x3=z"
        assert ff.attrs["length_m"] == pytest.approx(1e-3) and ff.attrs["time_s"] == 1.0
        np.testing.assert_allclose(ff.attrs["scalar_range"], [20.0, 50.5])
        # m/s → mm/s, components permuted to (x1, x2, x3) = (v, u, w)
        np.testing.assert_allclose(ff.velocity(0)[3, 4, 5], [2.0, 1.0, 3.0], rtol=1e-6)
        np.testing.assert_allclose(ff.times, [0.0, 0.005])


def test_an_imported_field_opens_in_xarray_in_the_inputs_units(tank):
    """The import records length_m = 1e-3 (mm coordinates) and time_s = 1: xarray gives the
    depth axis y as x1 in units of 0.001 m, holding the input's millimetres."""
    xr = pytest.importorskip("xarray")
    imported, _ = tank
    with xr.open_dataset(imported, group="frames/0001", engine="h5netcdf") as frame:
        assert frame["delta_n"].dims == ("x3", "x2", "x1")
        assert frame["x1"].attrs["units"] == "0.001 m" and frame["time"].attrs["units"] == "1.0 s"
        np.testing.assert_allclose(frame["x1"], np.linspace(0.0, SIDE_MM, N), rtol=1e-12)
        assert frame["velocity"].attrs["units"] == "0.001 m/s"
        # (x1, x2, x3) = (v, u, w) of the input: 0.002, 0.001, 0.003 m/s
        u = frame["velocity"].isel(x3=0, x2=0, x1=0).values * 1e-3
        np.testing.assert_allclose(u, [0.002, 0.001, 0.003], rtol=1e-6)
        with FieldFile(imported) as ff:
            np.testing.assert_array_equal(frame["delta_n"], ff.delta_n(1)[0])


def test_tracer_images_move_the_way_the_gradient_says(tank, device):
    """n falls with height x3 (warmer water above): light bends down, towards higher n, so
    the image of a tracer seen through the depth x1 lies above it (Δx3 > 0), by the slab
    closed form Δ = -L² (∂n/∂x3) / (2 n0), and the same as through the hand-written field."""
    imported, by_hand = tank
    config = MeasureConfig.from_options(
        camera="pupil", camera_distance=2000.0, aperture_diameter=20.0, frames=1, tracers=4,
        pupil_rays=64, pixels=2048, margin=0.3, device=device,
    )  # fmt: skip
    rows = [run_render(p, config=config).tracers for p in (imported, by_hand)]
    shift = [r["x3_opt"] - r["x3_opt_ref"] for r in rows]
    np.testing.assert_allclose(shift[0], shift[1], rtol=1e-6, atol=1e-9)
    dn_dx3 = (water_index(50.0) - water_index(20.0)) / SIDE_MM  # mean slope, 1/mm
    closed_form = -(SIDE_MM**2) * dn_dx3 / (2 * water_index(35.0))
    assert np.all(shift[0] > 0)
    np.testing.assert_allclose(shift[0], closed_form, rtol=0.1)  # n(T) is not linear
    side = [r["x2_opt"] - r["x2_opt_ref"] for r in rows]
    assert np.all(np.abs(side[0]) < 0.05 * closed_form)  # the weak x gradient: small


def test_cli_imports_degc_netcdf_and_npz_temperature(tmp_path):
    temperature_c = _tank(tmp_path / "c.nc", kelvin=False, frames=1)
    runner = CliRunner()
    arguments = ["field", "import", str(tmp_path / "c.nc"), "--depth-axis", "x"]
    out = runner.invoke(cli, [*arguments, "-o", str(tmp_path / "c.h5")])
    assert out.exit_code == 0, out.output
    axis = np.linspace(0.0, SIDE_MM, N)
    np.savez(
        tmp_path / "t.npz", temperature=temperature_c, temperature_units=np.array("degC"),
        x=axis, y=axis, z=axis, x_units=np.array("mm"),
    )  # fmt: skip
    arguments = ["field", "import", str(tmp_path / "t.npz"), "--depth-axis", "x"]
    out = runner.invoke(cli, [*arguments, "-o", str(tmp_path / "t.h5")])
    assert out.exit_code == 0, out.output
    a, b = load_field(tmp_path / "c.h5"), load_field(tmp_path / "t.h5")
    np.testing.assert_allclose(a.delta_n + a.n_ref, b.delta_n + b.n_ref, atol=1e-9)
    # depth x: x1 = x, x2 = y, x3 = z
    expected = water_index(np.transpose(temperature_c, (0, 1, 2)), 532.0)
    np.testing.assert_allclose(a.delta_n + a.n_ref, expected, atol=1e-9)


def test_a_zarr_store_imports_the_same_field_as_its_netcdf(tank, tmp_path):
    """The CF tank written to Zarr by xarray (undecoded, as the file is) imports through
    ``rimcl field import`` to the very field of the netCDF file."""
    xr = pytest.importorskip("xarray")
    pytest.importorskip("zarr")
    imported, _ = tank
    with xr.open_dataset(imported.parent / "tank.nc", engine="h5netcdf", decode_cf=False) as nc:
        nc.to_zarr(tmp_path / "tank.zarr", consolidated=False)
    out = CliRunner().invoke(
        cli,
        ["field", "import", str(tmp_path / "tank.zarr"), "--depth-axis", "y",
         "-o", str(tmp_path / "zarr.h5")],
    )  # fmt: skip
    assert out.exit_code == 0, out.output
    with FieldFile(imported) as ours, FieldFile(tmp_path / "zarr.h5") as theirs:
        for key in ("scalar", "scalar_units", "axes", "length_m", "time_s"):
            assert theirs.attrs[key] == ours.attrs[key], key
        np.testing.assert_array_equal(theirs.attrs["scalar_range"], ours.attrs["scalar_range"])
        np.testing.assert_array_equal(theirs.times, ours.times)
        for k in range(len(ours.times)):
            np.testing.assert_array_equal(theirs.velocity(k), ours.velocity(k))
    mine, theirs = load_field(imported), load_field(tmp_path / "zarr.h5")
    np.testing.assert_array_equal(theirs.delta_n, mine.delta_n)
    assert theirs.n_ref == mine.n_ref
    np.testing.assert_array_equal(theirs.origin, mine.origin)
    np.testing.assert_array_equal(theirs.spacing, mine.spacing)


def test_a_zarr_store_without_zarr_installed_is_one_line(tmp_path, monkeypatch):
    import sys

    (tmp_path / "s.zarr").mkdir()
    monkeypatch.setitem(sys.modules, "zarr", None)  # import zarr raises ImportError
    out = CliRunner().invoke(
        cli, ["field", "import", str(tmp_path / "s.zarr"), "--depth-axis", "y",
              "-o", str(tmp_path / "s.h5")],
    )  # fmt: skip
    assert out.exit_code != 0
    assert "needs xarray and zarr (pip install xarray zarr)" in out.output
    assert len(out.output.strip().splitlines()) == 1 and "Traceback" not in out.output


def test_salinity_and_density_units(tmp_path):
    axis = np.linspace(0.0, 0.1, 5)
    salt = np.full((5, 5, 5), 10.0) + np.arange(5)[:, None, None]
    np.savez(tmp_path / "s.npz", salinity=salt, salinity_units=np.array("g/kg"), x=axis, y=axis,
             z=axis)  # fmt: skip
    import_dataset(tmp_path / "s.npz", tmp_path / "s.h5", depth_axis="x", fluid="saltwater")
    field = load_field(tmp_path / "s.h5")
    expected = Fluid("saltwater").index(salinity_g_kg=salt)
    np.testing.assert_allclose(field.delta_n + field.n_ref, expected, atol=1e-9)
    rho = 998.0 + salt / 10
    np.savez(tmp_path / "d.npz", rho=rho, rho_units=np.array("kg m-3"), x=axis, y=axis, z=axis)
    import_dataset(tmp_path / "d.npz", tmp_path / "d.h5", depth_axis="x")
    with FieldFile(tmp_path / "d.h5") as ff:
        assert ff.kind == "density" and ff.attrs["scalar"] == "density"
        np.testing.assert_allclose(ff.density(0), rho / 1000.0, rtol=1e-7)
    with pytest.raises(RimclError, match="units 'furlongs'"):
        import_dataset(tmp_path / "d.npz", tmp_path / "x.h5", depth_axis="x", units="furlongs")
    with pytest.raises(RimclError, match="--depth-axis"):
        import_dataset(tmp_path / "d.npz", tmp_path / "x.h5")


def _density_file(path, lo, hi, **attrs):
    x = np.linspace(0, 1, 5)
    density = lo + (hi - lo) * np.broadcast_to(x, (5, 5, 5))
    write_field(path, density=[density], times=[0.0], origin=(0, 0, 0), spacing=(0.25,) * 3,
                attrs=attrs)  # fmt: skip
    return FieldFile(path)


def test_a_fluid_case_on_densities_that_do_not_fit_is_refused(tmp_path):
    water = FluidConfig(kind="water")
    with _density_file(tmp_path / "narrow.h5", 1.0, 1.00048) as source:
        with pytest.raises(RimclError, match=r"1 … 1\.00048.*1 and 1\.105"):
            case_of(source, "dT=2", None, water)
        # the field's own two fluids named: accepted
        fitted = FluidConfig(kind="water", light_density=1.0, heavy_density=1.00048)
        assert case_of(source, "dT=2", None, fitted).heavy == 1.00048
        # a Gladstone–Dale case needs no fluid model
        assert case_of(source, "C1", None, water).g == pytest.approx(2.82e-4)
    with _density_file(tmp_path / "own.h5", 0.99, 1.01, rho_light=0.99, rho_heavy=1.01) as src:
        index = case_of(src, "dT=2", None, water)  # the file's recorded fluids
        assert (index.light, index.heavy) == (0.99, 1.01)


def test_delta_n_files_run_as_is_and_refuse_fluid_cases(tank):
    imported, _ = tank
    with FieldFile(imported) as source:
        assert case_of(source, "delta_n", None, FluidConfig()).name == "delta_n"
        with pytest.raises(RimclError, match=r"temperature field .* runs as is .* dT=2"):
            case_of(source, "dT=2", None, FluidConfig(kind="water"))
    with _density_file(imported.parent / "rho.h5", 1.0, 1.105) as source:
        with pytest.raises(RimclError, match="stores a density"):
            case_of(source, "delta_n", None, FluidConfig())


def test_study_scene_names_delta_n(tank):
    from rimcl.scene.load import load_scene
    from rimcl.scene.study_config import StudyConfig
    from rimcl.study.run import study_cases

    imported, _ = tank
    scene = load_scene(None, {"field.path": str(imported), "cases.names": ["delta_n"]})
    assert study_cases(StudyConfig.from_scene(scene)) == [("delta_n", None)]
    scene = load_scene(
        None, {"field.path": str(imported), "cases.names": ["dT=2"], "fluid.kind": "water"}
    )
    with pytest.raises(RimclError, match="does not apply"):
        study_cases(StudyConfig.from_scene(scene))


def test_netcdf_dimension_without_coordinates_is_one_line(tmp_path):
    with h5py.File(tmp_path / "bad.nc", "w") as h5:
        h5["temperature"] = np.zeros((3, 3, 3))
    with pytest.raises(RimclError, match="has no coordinate values"):
        import_dataset(tmp_path / "bad.nc", tmp_path / "o.h5", depth_axis="x")
