"""The rimcl field file: writer, reader, Gladstone–Dale conversion, time and sheet access."""

import h5py
import numpy as np
import pytest

import rimcl
from rimcl.core.errors import RimclError
from rimcl.fields.cases import CASES, PAPER_DELTA_N_MAX, resolve_k_rho
from rimcl.fields.field_loading import load_field
from rimcl.fields.field_reader import FieldFile
from rimcl.fields.field_writer import write_field
from rimcl.fields.sample import sample_path

SHAPE = (6, 5, 8)  # (n3, n2, n1)
ORIGIN = (0.5, -1.0, 2.0)
SPACING = (0.1, 0.2, 0.3)


def _indices():
    """Node indices i1, i2, i3 as (n3, n2, n1) arrays."""
    i3, i2, i1 = np.meshgrid(*(np.arange(n) for n in SHAPE), indexing="ij")
    return i1, i2, i3


def _linear_density(t):
    """ρ = 1 + (i1 + 2 i2 - i3 + 4 t)/1024: linear in space and time, exact in float32."""
    i1, i2, i3 = _indices()
    return 1.0 + (i1 + 2 * i2 - i3 + 4 * t) / 1024


#: ∇ρ of :func:`_linear_density` along x1, x2, x3
LINEAR_GRADIENT = np.array([1, 2, -1]) / 1024 / np.array(SPACING)


def _linear_frames(times):
    """Density and velocity (u = (i1 + t, 2 i2 - t, 3 i3 + i1)) per frame."""
    i1, i2, i3 = _indices()
    density = [_linear_density(t) for t in times]
    velocity = [np.stack([i1 + t, 2 * i2 - t, 3 * i3 + i1], axis=-1) for t in times]
    return density, velocity


def _write(path, times=(0.0, 0.5, 1.0), **extra):
    density, velocity = _linear_frames(times)
    options = dict(density=density, velocity=velocity, times=times, origin=ORIGIN,
                   spacing=SPACING)  # fmt: skip
    options.update(extra)
    return write_field(path, **options)


def test_cases_and_resolution():
    assert CASES == {"C0": 3.34e-5, "C1": 2.82e-4, "C2": 3.34e-3, "C3": 3.34e-2, "C4": 3.34e-1}
    assert set(PAPER_DELTA_N_MAX) == set(CASES)
    assert resolve_k_rho(case="c4") == ("C4", 0.334)
    assert resolve_k_rho(k_rho=1e-3) == ("G=0.001", 1e-3)
    assert resolve_k_rho(case="G=0.001") == ("G=0.001", 1e-3)
    for bad in ({}, {"case": "C1", "k_rho": 1e-3}, {"case": "C9"}, {"k_rho": -1.0},
                {"k_rho": float("nan")}):  # fmt: skip
        with pytest.raises(RimclError):
            resolve_k_rho(**bad)


def test_round_trip_keeps_layout_values_and_provenance(tmp_path):
    path = _write(tmp_path / "f.h5", attrs={"title": "linear", "extra": {"a": 1}})
    density, velocity = _linear_frames((0.0, 0.5, 1.0))
    with h5py.File(path) as h5:  # the documented layout, read with plain h5py
        assert h5.attrs["rimcl_schema"] == "field" and h5.attrs["schema_version"] == 1
        np.testing.assert_array_equal(h5["grid"].attrs["origin"], ORIGIN)
        np.testing.assert_array_equal(h5["grid"].attrs["spacing"], SPACING)
        assert h5["grid"].attrs["boundary"] == "clamp"
        assert sorted(h5["frames"]) == ["0000", "0001", "0002"]
        assert h5["frames/0001"].attrs["time"] == 0.5
        assert h5["frames/0001/density"].dtype == np.float32
        assert h5["frames/0001/density"].compression == "gzip"
        assert "versions" in h5.attrs and "config" in h5.attrs
    with FieldFile(path) as ff:
        assert ff.shape == SHAPE and ff.n_frames == 3 and ff.has_velocity
        np.testing.assert_array_equal(ff.times, [0.0, 0.5, 1.0])
        np.testing.assert_array_equal(ff.origin, ORIGIN)
        assert ff.boundary == "clamp" and ff.kind == "density"
        assert ff.attrs["title"] == "linear" and ff.attrs["extra"] == '{"a": 1}'
        np.testing.assert_array_equal(ff.density(2), density[2].astype(np.float32))
        np.testing.assert_array_equal(ff.velocity(1), velocity[1].astype(np.float32))


def test_density_becomes_delta_n_with_the_gladstone_dale_product(tmp_path):
    path = _write(tmp_path / "f.h5")
    stored = FieldFile(path).density(1).astype(np.float64)
    field = load_field(path, frame=1, case="C4")
    mean = stored.mean()
    np.testing.assert_allclose(field.delta_n, 0.334 * (stored - mean), rtol=2e-7)
    assert field.n_ref == pytest.approx(1 + 0.334 * mean, rel=1e-15)
    # 4th-order differences are exact on a linear field (up to float32 ∇n)
    np.testing.assert_allclose(field.gradient, np.broadcast_to(0.334 * LINEAR_GRADIENT,
                               (*SHAPE, 3)), rtol=2e-7)  # fmt: skip
    assert field.attrs["case"] == "C4" and field.attrs["time"] == 0.5
    custom = rimcl.load_field(path, frame=1, k_rho=1e-3)
    assert custom.attrs["case"] == "G=0.001"
    with pytest.raises(RimclError, match="Gladstone-Dale"):
        load_field(path)


def test_stored_density_gradient_is_used(tmp_path):
    density, _ = _linear_frames((0.0,))
    marker = np.full((*SHAPE, 3), 7.0)
    path = write_field(tmp_path / "g.h5", density=density, density_gradient=[marker],
                       times=[0.0], origin=ORIGIN, spacing=SPACING)  # fmt: skip
    field = load_field(path, k_rho=0.5)
    np.testing.assert_allclose(field.gradient, 3.5)


def test_delta_n_files_and_a_missing_boundary_attribute(tmp_path):
    path = tmp_path / "dn.h5"
    delta_n = np.linspace(-1e-4, 1e-4, np.prod(SHAPE)).reshape(SHAPE)
    # written with plain h5py, as a user would, without the optional boundary
    with h5py.File(path, "w") as h5:
        h5.attrs["rimcl_schema"] = "field"
        h5.attrs["schema_version"] = 1
        grid = h5.create_group("grid")
        grid.attrs["origin"] = ORIGIN
        grid.attrs["spacing"] = SPACING
        frame = h5.create_group("frames/0000")
        frame.attrs["time"] = 2.0
        frame.create_dataset("delta_n", data=delta_n.astype(np.float32)).attrs["n_ref"] = 1.33
    field = load_field(path)
    assert field.boundary == "clamp" and field.n_ref == 1.33
    np.testing.assert_allclose(field.delta_n, delta_n, rtol=1e-6)
    with pytest.raises(RimclError, match="delta_n directly"):
        load_field(path, case="C1")


def test_time_interpolation_linear_and_cubic(tmp_path):
    # linear in time: exact with two frames
    path = _write(tmp_path / "lin.h5", times=(0.0, 1.0))
    with FieldFile(path) as ff:
        assert ff.time_weights(0.25) == [(0, 0.75), (1, 0.25)]
        assert ff.time_weights(1.0) == [(1, 1.0)]
        field = ff.field_at(0.25, case="C2")
        expected = _linear_density(0.25)
        np.testing.assert_allclose(field.delta_n, 3.34e-3 * (expected - expected.mean()),
                                   rtol=2e-7)  # fmt: skip
        assert field.n_ref == pytest.approx(1 + 3.34e-3 * expected.mean(), rel=1e-15)
        np.testing.assert_allclose(field.gradient, np.broadcast_to(3.34e-3 * LINEAR_GRADIENT,
                                   (*SHAPE, 3)), rtol=2e-7)  # fmt: skip
        np.testing.assert_array_equal(ff.velocity_at(0.25)[..., 0], _indices()[0] + 0.25)
        with pytest.raises(RimclError, match="outside"):
            ff.field_at(1.5, case="C2")
    # cubic in time: exact with four or more (unevenly spaced) frames
    times = (0.0, 0.3, 1.0, 1.4, 2.0)
    x1 = ORIGIN[0] + SPACING[0] * _indices()[0]
    density = [1.0 + 0.05 * np.sin(x1) * (1 + t - t**2 + 0.5 * t**3) for t in times]
    path = write_field(tmp_path / "cubic.h5", density=density, times=times, origin=ORIGIN,
                       spacing=SPACING)  # fmt: skip
    with FieldFile(path) as ff:
        weights = ff.time_weights(1.2)
        assert [f for f, _ in weights] == [1, 2, 3, 4]
        assert sum(w for _, w in weights) == pytest.approx(1.0, abs=1e-14)
        t = 1.2
        truth = 1.0 + 0.05 * np.sin(x1) * (1 + t - t**2 + 0.5 * t**3)
        blended = sum(w * ff.density(f).astype(np.float64) for f, w in weights)
        np.testing.assert_allclose(blended, truth, atol=2e-7)
        linear = sum(w * ff.density(f).astype(np.float64) for f, w in ff.time_weights(t, "linear"))
        assert np.max(np.abs(linear - truth)) > 1e-3  # the cubic term is really there


def test_sheet_velocity_is_linear_in_x1_and_wraps_when_periodic(tmp_path):
    path = _write(tmp_path / "f.h5")
    _, i2, i3 = _indices()
    with FieldFile(path) as ff:
        sheet = ff.sheet_velocity(0.75, ORIGIN[0] + 2.375 * SPACING[0])
        assert sheet.shape == (SHAPE[0], SHAPE[1], 2)
        # u2 = 2 i2 - t, u3 = 3 i3 + i1 (linear in x1 and t: exact)
        np.testing.assert_allclose(sheet[..., 0], 2 * i2[..., 0] - 0.75, rtol=1e-14)
        np.testing.assert_allclose(sheet[..., 1], 3 * i3[..., 0] + 2.375, rtol=1e-14)
        with pytest.raises(RimclError, match="outside the field"):
            ff.sheet_velocity(0.0, ORIGIN[0] - 1.0)
    n1 = SHAPE[2]
    wave = np.zeros((*SHAPE, 3))
    wave[..., 1] = np.arange(n1)[None, None, :] % 3  # u2 = i1 mod 3 on a periodic x1 axis
    density, _ = _linear_frames((0.0,))
    path = write_field(tmp_path / "p.h5", density=density, velocity=[wave], times=[0.0],
                       origin=ORIGIN, spacing=SPACING, boundary="periodic")  # fmt: skip
    with FieldFile(path) as ff:
        beyond = ORIGIN[0] + (n1 - 0.5) * SPACING[0]  # between the last node and node 0
        expected = 0.5 * ((n1 - 1) % 3) + 0.5 * 0
        np.testing.assert_allclose(ff.sheet_velocity(0.0, beyond)[..., 0], expected)
        np.testing.assert_allclose(
            ff.sheet_velocity(0.0, beyond - n1 * SPACING[0])[..., 0], expected
        )


@pytest.mark.parametrize(
    ("change", "message"),
    [
        ({"times": (0.0, 0.0, 1.0)}, "strictly increasing"),
        ({"spacing": (0.1, 0.0, 0.1)}, "spacing"),
        ({"boundary": "mirror"}, "boundary"),
        ({"velocity": [np.zeros((*SHAPE, 2))] * 3}, "velocity"),
        ({"density": [np.full(SHAPE, np.nan)] * 3}, "NaN"),
        ({"n_ref": 1.0}, "n_ref only"),
    ],
)
def test_bad_input_is_refused_and_nothing_is_written(tmp_path, change, message):
    with pytest.raises(RimclError, match=message):
        _write(tmp_path / "bad.h5", **change)
    assert list(tmp_path.iterdir()) == []


def test_existing_output_is_kept_without_overwrite(tmp_path):
    path = _write(tmp_path / "f.h5")
    before = path.read_bytes()
    with pytest.raises(RimclError, match="exists"):
        _write(path, times=(5.0, 6.0, 7.0))
    assert path.read_bytes() == before
    _write(path, times=(5.0, 6.0, 7.0), overwrite=True)
    assert FieldFile(path).times[0] == 5.0


def test_reader_errors_are_clear(tmp_path):
    with pytest.raises(RimclError, match="does not exist"):
        FieldFile(tmp_path / "none.h5")
    foreign = tmp_path / "foreign.h5"
    with h5py.File(foreign, "w") as h5:
        h5["Density_0001"] = np.zeros((2, 2, 2, 1), dtype=np.float32)
    with pytest.raises(RimclError, match=r"not a rimcl field file.*field import"):
        FieldFile(foreign)
    path = _write(tmp_path / "f.h5")
    with h5py.File(path, "a") as h5:
        h5["frames/0001/density"][0, 0, 0] = np.inf
    with FieldFile(path) as ff, pytest.raises(RimclError, match="NaN or inf"):
        ff.density(1)
    with FieldFile(path) as ff, pytest.raises(RimclError, match="frame 7 does not exist"):
        ff.field(7, case="C1")


def test_shipped_sample_is_a_periodic_64_cube_with_velocity():
    with FieldFile(sample_path()) as ff:
        assert ff.shape == (64, 64, 64) and ff.boundary == "periodic"
        assert ff.n_frames == 13 and ff.has_velocity and not ff.has_density_gradient
        np.testing.assert_allclose(np.diff(ff.times), 0.02, rtol=1e-9)
        np.testing.assert_allclose(ff.spacing, 2 * np.pi / 64)
        assert ff.sheet_velocity(ff.times[0] + 0.002, 0.0).shape == (64, 64, 2)
    field = rimcl.load_field(case="C1")
    assert field.boundary == "periodic" and field.shape == (64, 64, 64)
    assert 0.5 * PAPER_DELTA_N_MAX["C1"] < field.delta_n_range < 2 * PAPER_DELTA_N_MAX["C1"]
