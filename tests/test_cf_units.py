"""Units of CF and .npz imports, read with cf-units: times in hours, days and ms, coordinates
in any length unit, velocities in UDUNITS spellings, ``positive = "down"``, and the refusals
(a density without units, several velocity candidates), each on a tiny synthetic file."""

import h5netcdf
import numpy as np
import pytest
from click.testing import CliRunner

from rimcl.cli.main import cli
from rimcl.core.errors import RimclError
from rimcl.fields.cf_import import import_dataset
from rimcl.fields.field_reader import FieldFile

# (depth, y, x) nodes: all different, so that a transposition shows
SHAPE = (3, 4, 5)


def _cf(path, *, time_units="seconds since 2000-01-01", times=(0.0, 1.0), length="mm",
        velocity_units="m s-1", density_units="kg m-3", positive=None, extra=None,
        w_standard=None, rho0=1000.0):  # fmt: skip
    """A CF file: density ``rho0`` + depth (kg m-3) on (time, depth, y, x) with coordinates
    0, 10, 20, ... in ``length``, velocity (1, 2, 3) × 1e-3 in ``velocity_units``; ``extra``
    maps more variable names to (value, attrs) on the same grid."""
    nz, ny, nx = SHAPE
    with h5netcdf.File(path, "w") as f:
        f.dimensions = {"time": len(times), "depth": nz, "y": ny, "x": nx}
        for name, n in (("depth", nz), ("y", ny), ("x", nx)):
            c = f.create_variable(name, (name,), "f8")
            c[:] = 10.0 * np.arange(n)
            c.attrs["units"] = length
        f.variables["depth"].attrs["axis"] = "Z"
        if positive:
            f.variables["depth"].attrs["positive"] = positive
        t = f.create_variable("time", ("time",), "f8")
        t[:] = times
        if time_units is not None:
            t.attrs["units"] = time_units
        dims = ("time", "depth", "y", "x")
        depth = 10.0 * np.arange(nz)[:, None, None]
        rho = f.create_variable("density", dims, "f8")
        rho[:] = np.broadcast_to(rho0 + depth, (len(times), *SHAPE))
        if density_units is not None:
            rho.attrs["units"] = density_units
        variables = {"u": (1e-3, {}), "v": (2e-3, {}), "w": (3e-3, {}), **(extra or {})}
        for name, (value, attrs) in variables.items():
            c = f.create_variable(name, dims, "f8")
            c[:] = value
            c.attrs.update({"units": velocity_units, **attrs} if velocity_units else attrs)
        if w_standard:
            f.variables["w"].attrs["standard_name"] = w_standard


def _import(tmp_path, name="f.nc", **options):
    out = tmp_path / f"{name}-{len(list(tmp_path.glob('*.h5')))}.h5"  # one per import
    import_dataset(tmp_path / name, out, depth_axis="y", **options)
    return FieldFile(out)


@pytest.mark.parametrize(
    ("time_units", "seconds"),
    [("hours since 2000-01-01", 3600.0), ("days since 2000-01-01 00:00:00", 86400.0),
     ("milliseconds since 1970-01-01", 1e-3), ("hours", 3600.0), ("s", 1.0)],
)  # fmt: skip
def test_cf_times_in_any_unit_give_the_time_scale(tmp_path, time_units, seconds):
    """Frames 1 unit apart stay 1 field unit apart, with time_s seconds each; the velocity
    (m s-1, coordinates in mm) is stored in mm per field time unit."""
    _cf(tmp_path / "f.nc", time_units=time_units)
    with _import(tmp_path) as ff:
        assert ff.attrs["time_s"] == seconds and ff.attrs["length_m"] == 1e-3
        np.testing.assert_array_equal(ff.times, [0.0, 1.0])
        # x1 = y (v), x2 = x (u), x3 = depth (w): 2, 1, 3 mm/s, times the seconds per unit
        expected = np.array([2.0, 1.0, 3.0]) * seconds
        np.testing.assert_allclose(ff.velocity(0)[1, 2, 3], expected, rtol=1e-6)
        assert ff.attrs["velocity_units"].startswith("converted from m s-1")


@pytest.mark.parametrize(
    ("length", "metres", "velocity_units", "speed"),
    [("millimeters", 1e-3, "m.s-1", 1.0), ("km", 1e3, "m/s", 1.0), ("cm", 1e-2, "mm s-1", 1e-3),
     ("m", 1.0, "cm s**-1", 1e-2)],
)  # fmt: skip
def test_cf_lengths_and_velocities_in_udunits_spellings(
    tmp_path, length, metres, velocity_units, speed
):
    _cf(tmp_path / "f.nc", length=length, velocity_units=velocity_units)
    with _import(tmp_path) as ff:
        assert ff.attrs["length_m"] == metres
        np.testing.assert_allclose(ff.spacing, [10.0, 10.0, 10.0])
        expected = np.array([2e-3, 1e-3, 3e-3]) * speed / metres  # field length per second
        np.testing.assert_allclose(ff.velocity(1)[0, 0, 0], expected, rtol=1e-6)
        note = ff.attrs["velocity_units"]
        assert note.startswith(f"converted from {velocity_units}") and "no units" not in note


def test_a_density_needs_its_units(tmp_path):
    _cf(tmp_path / "f.nc", density_units=None)
    with pytest.raises(RimclError, match=r"density without units .* --units \('kg m-3'"):
        _import(tmp_path)
    # named on the command line: converted, ρ / 1000 kg m-3
    with _import(tmp_path, units="g/l") as ff:
        np.testing.assert_allclose(ff.density(0)[:, 0, 0], [1.0, 1.01, 1.02], rtol=1e-7)
    # "1" (relative to 1000 kg m-3) on values of 1000 cannot be: refused, not n ≈ 335
    with pytest.raises(RimclError, match=r"density 1000 … 1020 × 1000 kg m-3 \(units '1'\) is no"):
        _import(tmp_path, units="1")
    # an anomaly ρ - ρ0 is no density either
    _cf(tmp_path / "anomaly.nc", rho0=-10.0)
    with pytest.raises(RimclError, match=r"density -0.01 … 0.01 × 1000 kg m-3"):
        _import(tmp_path, units="g/l", name="anomaly.nc")
    with pytest.raises(RimclError, match=r"units 'm s-1' are not those of a density"):
        _import(tmp_path, units="m s-1")


def test_cli_refuses_a_density_without_units_in_one_line(tmp_path):
    _cf(tmp_path / "f.nc", density_units=None)
    out = CliRunner().invoke(
        cli,
        ["field", "import", str(tmp_path / "f.nc"), "--depth-axis", "y", "-o",
         str(tmp_path / "o.h5")],
    )  # fmt: skip
    assert out.exit_code != 0 and "Traceback" not in out.output
    assert len(out.output.strip().splitlines()) == 1 and "--units" in out.output
    assert not (tmp_path / "o.h5").exists()


def test_positive_down_turns_the_axis_and_its_velocity_up(tmp_path):
    _cf(tmp_path / "f.nc", positive="down")
    with _import(tmp_path) as ff:
        # x3 = depth turned up: nodes -20, -10, 0 (mm); the densest water (depth 20) first
        assert ff.origin[2] == -20.0 and ff.spacing[2] == 10.0
        np.testing.assert_allclose(ff.density(0)[:, 0, 0], [1.02, 1.01, 1.0], rtol=1e-7)
        # w (positive down, no standard_name) changes sign; u and v do not
        np.testing.assert_allclose(ff.velocity(0)[0, 0, 0], [2.0, 1.0, -3.0], rtol=1e-6)
        assert ff.attrs["turned_up"] == "depth"
        assert "sign changed" in ff.attrs["velocity_units"]
    # an upward velocity (its standard_name says so) keeps its sign
    _cf(tmp_path / "g.nc", positive="down", w_standard="upward_sea_water_velocity")
    with _import(tmp_path, name="g.nc") as ff:
        np.testing.assert_allclose(ff.velocity(0)[0, 0, 0], [2.0, 1.0, 3.0], rtol=1e-6)
    # positive up changes nothing
    _cf(tmp_path / "h.nc", positive="up")
    with _import(tmp_path, name="h.nc") as ff:
        assert ff.origin[2] == 0.0
        np.testing.assert_allclose(ff.density(0)[:, 0, 0], [1.0, 1.01, 1.02], rtol=1e-7)


def test_several_velocity_candidates_are_refused(tmp_path):
    """A Stokes drift beside the flow: not taken by its place in the file."""
    stokes = {"standard_name": "sea_surface_stokes_drift_x_velocity"}
    _cf(tmp_path / "f.nc", extra={"ustokes": (5e-3, stokes)})
    with pytest.raises(RimclError, match=r"several velocity candidates \(x: u, ustokes\).*--velo"):
        _import(tmp_path)
    with _import(tmp_path, velocity="ustokes,v,w") as ff:
        np.testing.assert_allclose(ff.velocity(0)[0, 0, 0], [2.0, 5.0, 3.0], rtol=1e-6)


def test_velocity_units_that_are_no_velocity_and_untimed_frames_are_refused(tmp_path):
    _cf(tmp_path / "f.nc", velocity_units="m")
    with pytest.raises(RimclError, match=r"units 'm' are not a velocity"):
        _import(tmp_path)
    _cf(tmp_path / "g.nc", time_units=None)
    with pytest.raises(RimclError, match=r"time coordinate has no units"):
        _import(tmp_path, name="g.nc")
    # without velocity units nothing is converted, and the note says so
    _cf(tmp_path / "h.nc", time_units=None, velocity_units=None)
    with _import(tmp_path, name="h.nc") as ff:
        assert "the file gives no units" in ff.attrs["velocity_units"]
        np.testing.assert_allclose(ff.velocity(0)[0, 0, 0], [2e-3, 1e-3, 3e-3], rtol=1e-6)


def test_npz_and_zarr_read_units_alike(tmp_path):
    """An .npz with times in hours and coordinates in km, and a Zarr store of a
    positive-down file, convert as their netCDF files do."""
    nz, ny, nx = SHAPE
    depth = 10.0 * np.arange(nz)[:, None, None]
    np.savez(
        tmp_path / "f.npz", density=np.broadcast_to(1000.0 + depth, (2, *SHAPE)),
        density_units=np.array("kg m-3"), times=np.array([0.0, 1.0]),
        times_units=np.array("hours since 2000-01-01"), x=10.0 * np.arange(nx),
        y=10.0 * np.arange(ny), z=10.0 * np.arange(nz), x_units=np.array("km"),
        y_units=np.array("km"), z_units=np.array("km"),
        velocity=np.broadcast_to(np.array([1.0, 2.0, 3.0]), (2, *SHAPE, 3)),
        velocity_units=np.array("m.s-1"),
    )  # fmt: skip
    with _import(tmp_path, name="f.npz") as ff:
        assert ff.attrs["time_s"] == 3600.0 and ff.attrs["length_m"] == 1e3
        # 1, 2, 3 m/s: 3.6 km per hour each
        np.testing.assert_allclose(ff.velocity(0)[0, 0, 0], [7.2, 3.6, 10.8], rtol=1e-6)
    xr = pytest.importorskip("xarray")
    pytest.importorskip("zarr")
    _cf(tmp_path / "d.nc", positive="down", time_units="hours since 2000-01-01")
    with xr.open_dataset(tmp_path / "d.nc", engine="h5netcdf", decode_cf=False) as nc:
        nc.to_zarr(tmp_path / "d.zarr", consolidated=False)
    with _import(tmp_path, name="d.nc") as ours, _import(tmp_path, name="d.zarr") as theirs:
        for key in ("time_s", "length_m", "turned_up", "velocity_units"):
            assert theirs.attrs[key] == ours.attrs[key], key
        np.testing.assert_array_equal(theirs.velocity(0), ours.velocity(0))
        np.testing.assert_array_equal(theirs.density(0), ours.density(0))
        assert ours.origin[2] == -20.0
