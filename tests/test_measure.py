"""The synthetic PTV measurement end to end (``rimcl.ptv.measure.run_render``), on small fields."""

import dataclasses
import json
import tracemalloc

import h5py
import numpy as np
import pytest

from rimcl.core.errors import RimclError
from rimcl.core.tables_h5 import label_table, read_table
from rimcl.fields.field_writer import write_field
from rimcl.imaging.centroid import TracerFlag
from rimcl.optics.camera import PupilCamera, Scene
from rimcl.ptv.measure import run_render
from rimcl.ptv.render_file import merge_results, write_frame_image, write_render
from rimcl.scene.config import FluidConfig, MeasureConfig
from rimcl.stats.render_file import load_render

TIMES = (0.0, 0.01, 0.02)
OMEGA = 2.0  # solid-body rotation rate of the linear-medium file (rad per time unit)
GRADIENT, N0 = 5e-3, 1.33  # linear medium n = N0 + GRADIENT (x2 - 1/2)


def render(field, *, case=None, k_rho=None, reference=None, **options):
    """run_render with the flat option names of ``rimcl render``."""
    config = MeasureConfig.from_options(**options)
    return run_render(field, case=case, k_rho=k_rho, reference=reference, config=config)


SMALL = {"tracers": 6, "fan": 5, "pupil_rays": 25, "pixels": 1024}
#: the camera of the linear-medium tests, also where only the tracers' truth is checked (a
#: camera of its own costs a build of each kernel)
LINEAR_CAMERA = {
    "camera": "pupil",
    "camera_distance": 20.0,
    "aperture_diameter": 0.5,
    "pupil_rays": 64,
    "pixels": 2048,
}


def _grid(count, periodic):
    size = 2 * np.pi if periodic else 1.0
    h = size / count if periodic else size / (count - 1)
    x = np.arange(count) * h
    x3, x2, x1 = np.meshgrid(x, x, x, indexing="ij")
    return x1, x2, x3, h


@pytest.fixture(scope="module")
def blobs_file(tmp_path_factory):
    """A periodic 2π box of density blobs moving with a smooth periodic flow."""
    x1, x2, x3, h = _grid(16, periodic=True)
    density = [1 + 0.05 * np.sin(x1 + t) * np.cos(x2) * np.sin(x3 + 0.3) for t in (0, 0.1, 0.2)]
    velocity = [np.stack([np.zeros_like(x1), np.sin(x3), np.cos(x2)], axis=-1)] * 3
    path = tmp_path_factory.mktemp("fields") / "blobs.h5"
    write_field(
        path,
        density=density,
        times=TIMES,
        origin=(0, 0, 0),
        spacing=(h, h, h),
        velocity=velocity,
        boundary="periodic",
    )
    return path


@pytest.fixture(scope="module")
def linear_file(tmp_path_factory):
    """A clamped unit cube of constant ∇n along x2, the sheet rotating as a solid body."""
    x1, x2, x3, h = _grid(9, periodic=False)
    delta_n = [GRADIENT * (x2 - 0.5)] * 3
    velocity = [np.stack([0 * x1, -OMEGA * (x3 - 0.5), OMEGA * (x2 - 0.5)], axis=-1)] * 3
    path = tmp_path_factory.mktemp("fields") / "linear.h5"
    write_field(
        path,
        delta_n=delta_n,
        n_ref=N0,
        times=TIMES,
        origin=(0, 0, 0),
        spacing=(h, h, h),
        velocity=velocity,
    )
    return path


@pytest.mark.parametrize("camera", ["plane", "pupil"])
@pytest.mark.parametrize("renderer", ["exact", "paper"])
def test_zero_k_rho_measures_exactly_the_reference(blobs_file, device, renderer, camera):
    result = render(blobs_file, k_rho=0.0, renderer=renderer, camera=camera, device=device, **SMALL)
    rows = result.tracers
    assert np.all(np.isfinite(rows["x2_ref"])) and np.all(rows["flags"] == 0)
    for name in ("x2_opt", "x3_opt"):
        np.testing.assert_array_equal(rows[name], rows[f"{name}_ref"])
    for name in ("x2", "x3", "area", "perimeter", "circularity"):
        np.testing.assert_array_equal(rows[f"{name}_meas"], rows[f"{name}_ref"])
    velocity = result.kinematics["velocity"]
    np.testing.assert_array_equal(velocity["u2_meas"], velocity["u2_ref"])
    np.testing.assert_array_equal(velocity["u2_opt"], velocity["u2_opt_ref"])


def test_a_fluid_without_a_temperature_difference_is_the_reference(blobs_file, device):
    config = MeasureConfig.from_options(device=device, **SMALL)
    # the blobs' two fluids are 0.95 and 1.05 (the fluid model must say so: see case_of)
    fluid = FluidConfig(kind="water", light_density=0.95, heavy_density=1.05)
    config = dataclasses.replace(config, fluid=fluid)
    rows = run_render(blobs_file, case="dT=0", config=config).tracers
    for name in ("x2", "x3", "x2_opt", "x3_opt"):
        reference = f"{name}_ref" if "opt" in name else f"{name.split('_')[0]}_ref"
        np.testing.assert_array_equal(
            rows[name if "opt" in name else f"{name}_meas"], rows[reference]
        )
    warm = run_render(blobs_file, case="dT=5", config=config).tracers
    assert np.nanmax(np.abs(warm["x2_opt"] - warm["x2_opt_ref"])) > 0


def test_reference_is_reused_across_cases_and_checked(blobs_file, device):
    fresh = render(blobs_file, case="C3", device=device, **SMALL)
    reused = render(blobs_file, case="C3", device=device, reference=fresh.reference, **SMALL)
    for name, values in fresh.tracers.items():
        np.testing.assert_array_equal(reused.tracers[name], values, err_msg=name)
    zero = render(blobs_file, k_rho=0.0, device=device, reference=fresh.reference, **SMALL)
    np.testing.assert_array_equal(zero.tracers["x2_meas"], zero.tracers["x2_ref"])
    with pytest.raises(RimclError, match="differs in: shard, tracers"):
        render(
            blobs_file,
            case="C3",
            device=device,
            reference=fresh.reference,
            **{**SMALL, "tracers": 7},
        )


def _linear_medium_image_shift(camera, tracers):
    """Mean float64 shift along x2 of the image points of a tracer's pupil rays.

    In ``t`` (dt = ds/n) the linear medium gives ``y'' = g² y`` for ``y = n(x2)``, so
    ``y = y0 cosh(g t) + T2 sinh(g t)`` and ``x2' = y0 sinh(g t) + T2 cosh(g t)``, while
    ``x1 = T1 t``; the exit at ``x1 = L`` is at ``t = L / T1``, and the image point is
    the straight backward extension of the exit ray to the sheet.
    """
    g, depth = GRADIENT, camera.scene.depth
    directions = camera.directions(tracers)
    y0 = N0 + g * (tracers[:, :1] - 0.5)
    t_in, t2_in = y0 * directions[..., 0], y0 * directions[..., 1]
    t_exit = depth / t_in
    y_exit = y0 * np.cosh(g * t_exit) + t2_in * np.sinh(g * t_exit)
    slope_exit = (y0 * np.sinh(g * t_exit) + t2_in * np.cosh(g * t_exit)) / t_in
    image = (y_exit - N0) / g + 0.5 - depth * slope_exit
    return (image - tracers[:, :1]).mean(axis=1)


def test_linear_medium_shift_matches_float64_rays(linear_file, device):
    settings = {"tracers": 4, "pupil_rays": 64, "pixels": 2048, "margin": 0.2}
    result = render(
        linear_file,
        camera="pupil",
        camera_distance=20.0,
        aperture_diameter=0.5,
        frames=1,
        device=device,
        **settings,
    )
    rows = result.tracers
    camera = PupilCamera(
        Scene.from_grid((0, 0, 0), (0.125,) * 3, (9, 9, 9), "clamp"), 0.5, 20.0, rays=64
    )
    tracers = np.stack([rows["x2_true"], rows["x3_true"]], axis=-1)
    expected = _linear_medium_image_shift(camera, tracers)
    pixel = result.attrs["pixel_size"]
    assert np.all(np.abs(expected) > 3 * pixel)  # a shift of several pixels
    np.testing.assert_allclose(rows["x2_meas"] - rows["x2_ref"], expected, rtol=0.02)
    # across the gradient nothing moves (each ray keeps its x3 image exactly)
    np.testing.assert_allclose(rows["x3_meas"], rows["x3_ref"], atol=0.01 * pixel)


def test_slab_optics_error_is_the_closed_form_and_imaging_adds_little(linear_file, device):
    """A uniform transverse gradient shifts every image point by
    Δ = -L² (∂n/∂x2) / (2 n0); the optics mean carries it, the camera adds < 1 % at 16 bits."""
    result = render(
        linear_file,
        camera="pupil",
        camera_distance=20.0,
        aperture_diameter=0.5,
        frames=1,
        tracers=6,
        pupil_rays=64,
        pixels=2048,
        margin=0.2,
        psf_sigma=2.0,
        bit_depth=16,
        threshold=2562.0,
        device=device,
    )
    rows = result.tracers
    closed_form = -(1.0**2) * GRADIENT / (2 * N0)
    optics = rows["x2_opt"] - rows["x2_opt_ref"]
    np.testing.assert_allclose(optics, closed_form, rtol=0.01)
    np.testing.assert_allclose(rows["x2_opt_ref"], rows["x2_true"], rtol=0, atol=1e-12)
    imaging = (rows["x2_meas"] - rows["x2_ref"]) - optics
    assert np.all(np.abs(imaging) < 0.01 * abs(closed_form))


def test_solid_body_rotation_truth(linear_file, device):
    # the truth does not depend on the camera
    result = render(linear_file, tracers=40, margin=0.2, device=device, **LINEAR_CAMERA)
    rows = result.tracers
    start = np.stack([rows["x2_true"], rows["x3_true"]], axis=-1)[rows["frame"] == 0]
    offset = start - 0.5
    exact = []
    for frame, t in enumerate(TIMES):
        c, s = np.cos(OMEGA * t), np.sin(OMEGA * t)
        exact.append(
            0.5
            + np.stack(
                [c * offset[:, 0] - s * offset[:, 1], s * offset[:, 0] + c * offset[:, 1]], axis=-1
            )
        )
        pick = rows["frame"] == frame
        found = np.stack([rows["x2_true"][pick], rows["x3_true"][pick]], axis=-1)
        np.testing.assert_allclose(found, exact[-1], atol=1e-6 * result.attrs["length_L"])
    velocity = result.kinematics["velocity"]
    at_start = velocity["frame"] == 0
    np.testing.assert_allclose(velocity["u2_true"][at_start], -OMEGA * offset[:, 1], atol=1e-9)
    np.testing.assert_allclose(velocity["u3_true"][at_start], OMEGA * offset[:, 0], atol=1e-9)
    # the true acceleration is the second difference of the exact positions
    chord = (exact[2] - 2 * exact[1] + exact[0]) / TIMES[1] ** 2
    acceleration = result.kinematics["acceleration"]
    np.testing.assert_allclose(acceleration["a2_true"], chord[:, 0], atol=1e-3)
    np.testing.assert_allclose(acceleration["a3_true"], chord[:, 1], atol=1e-3)
    # and the Lagrangian acceleration along the track is the centripetal one, -ω² (x - c)
    for frame in range(3):
        pick = rows["frame"] == frame
        np.testing.assert_allclose(
            rows["a2_true"][pick], -(OMEGA**2) * (exact[frame][:, 0] - 0.5), atol=1e-6
        )


@pytest.fixture(scope="module")
def rotation_file(tmp_path_factory):
    """The linear medium of ``linear_file`` over 9 frames 0.01 apart."""
    x1, x2, x3, h = _grid(9, periodic=False)
    velocity = [np.stack([0 * x1, -OMEGA * (x3 - 0.5), OMEGA * (x2 - 0.5)], axis=-1)] * 9
    path = tmp_path_factory.mktemp("fields") / "rotation.h5"
    write_field(
        path,
        delta_n=[GRADIENT * (x2 - 0.5)] * 9,
        n_ref=N0,
        times=np.arange(9) * 0.01,
        origin=(0, 0, 0),
        spacing=(h, h, h),
        velocity=velocity,
    )
    return path


@pytest.mark.parametrize("dt", [0.02, 0.015])
def test_fitted_tracks_of_many_frames(rotation_file, device, dt):
    """5 frames dt apart (stored, or interpolated between stored frames): the fit of the
    uniform-medium optics means (the tracers themselves) recovers -ω² r to its own bias."""
    frames = 5
    result = render(
        rotation_file, tracers=8, margin=0.2, frames=frames, dt=dt, device=device, **LINEAR_CAMERA
    )
    kinematics = result.kinematics
    assert result.attrs["dt"] == pytest.approx(dt)
    assert len(kinematics["velocity"]["id"]) == 8 * (frames - 1)
    assert len(kinematics["acceleration"]["id"]) == 8 * (frames - 2)
    fit = kinematics["acceleration_fit"]
    assert set(fit["frame"]) == {2}
    rows = result.tracers
    centre = rows["frame"] == 2
    radius = np.stack([rows["x2_true"][centre], rows["x3_true"][centre]], axis=-1) - 0.5
    np.testing.assert_allclose(fit["a2_true"], -(OMEGA**2) * radius[:, 0], atol=1e-6)
    bias = np.hypot(fit["a2_opt_ref"] - fit["a2_true"], fit["a3_opt_ref"] - fit["a3_true"])
    assert np.all(bias < 2e-3 * OMEGA**2 * np.linalg.norm(radius, axis=1))
    u_fit = kinematics["velocity_fit"]
    np.testing.assert_allclose(u_fit["u2_true"], -OMEGA * radius[:, 1], atol=1e-9)
    # an order-2 fit misses the rotation's third derivative: O(Δt² ω³ r), here < 2e-3 ω r
    u_bias = np.hypot(
        u_fit["u2_opt_ref"] - u_fit["u2_true"], u_fit["u3_opt_ref"] - u_fit["u3_true"]
    )
    assert np.all(u_bias < 2e-3 * OMEGA * np.linalg.norm(radius, axis=1))


def test_batches_do_not_change_the_result(blobs_file, device):
    whole = render(blobs_file, case="C2", device=device, **SMALL)
    pieces = render(blobs_file, case="C2", device=device, rays_per_batch=40, **SMALL)
    for name, values in whole.tracers.items():
        np.testing.assert_array_equal(pieces.tracers[name], values, err_msg=name)
    for name, values in whole.rays.items():
        np.testing.assert_array_equal(pieces.rays[name], values, err_msg=name)


def test_shards_merge_into_the_whole_run(blobs_file, device):
    config = MeasureConfig.from_options(device=device, frame_image=True, ray_sample=30, **SMALL)
    whole = run_render(blobs_file, case="C3", config=config)
    parts = [run_render(blobs_file, case="C3", config=config, shard=s) for s in ((0, 2), (2, 6))]
    merged = merge_results(parts)
    for name, values in whole.tracers.items():
        np.testing.assert_array_equal(merged.tracers[name], values, err_msg=name)
    for name, values in whole.rays.items():
        np.testing.assert_array_equal(merged.rays[name], values, err_msg=name)
    for group, table in whole.kinematics.items():
        if table is None:
            assert merged.kinematics[group] is None
            continue
        for name, values in table.items():
            np.testing.assert_array_equal(merged.kinematics[group][name], values, err_msg=name)
    assert merged.ray_attrs == whole.ray_attrs
    np.testing.assert_array_equal(merged.frame_image, whole.frame_image)
    np.testing.assert_array_equal(merged.reference.images["scale"], whole.reference.images["scale"])
    again = run_render(blobs_file, case="C1", config=config, reference=merged.reference)
    assert again.attrs["n_tracers"] == SMALL["tracers"]
    with pytest.raises(RimclError, match="do not tile"):
        merge_results(parts[1:])


def test_memory_is_flat_in_the_number_of_tracers(blobs_file, device):
    def peak(tracers):
        tracemalloc.start()
        render(
            blobs_file,
            case="C1",
            frames=1,
            tracers=tracers,
            fan=8,
            pixels=512,
            rays_per_batch=256,
            ray_sample=100,
            device=device,
        )
        peak_bytes = tracemalloc.get_traced_memory()[1]
        tracemalloc.stop()
        return peak_bytes

    peak(4)  # builds and caches the kernels
    small, large = peak(8), peak(64)
    # per-tracer tables cost ~200 bytes a tracer; a batch of rays ~100 kB
    assert large - small < 100_000


def test_ray_sample_and_status_counts(blobs_file, device):
    result = render(blobs_file, case="C4", device=device, ray_sample=50, **SMALL)
    rays = result.rays
    assert len(rays["theta0"]) == 50
    assert set(rays) >= {"theta0", "deflection", "n_metric", "path_length", "displacement"}
    assert np.all((rays["tracer_id"] >= 0) & (rays["tracer_id"] < SMALL["tracers"]))
    counts = result.ray_attrs
    traced = sum(
        counts[f"count_{name}"]
        for name in ("ok", "exit_side", "turned_back", "max_steps", "non_finite")
    )
    assert traced == 3 * SMALL["tracers"] * SMALL["fan"] ** 2
    # a periodic box straight on: all paths are longer than the depth, |Δθ| ≈ |N| S
    ok = rays["status"] == 0
    assert np.all(rays["path_length"][ok] >= result.attrs["length_L"] * (1 - 1e-9))
    np.testing.assert_allclose(
        rays["deflection"][ok], rays["n_metric"][ok] * rays["path_length"][ok], rtol=0.3
    )


def test_write_render_file_layout(blobs_file, device, tmp_path):
    result = render(blobs_file, case="C1", device=device, frame_image=True, **SMALL)
    path = tmp_path / "render.h5"
    write_render(path, result)
    with h5py.File(path, "r") as h5:
        assert h5.attrs["rimcl_schema"] == "render" and h5.attrs["schema_version"] == 2
        assert h5.attrs["case"] == "C1" and h5.attrs["k_rho"] == pytest.approx(2.82e-4)
        assert h5.attrs["length_L"] == pytest.approx(2 * np.pi)
        assert h5.attrs["pixel_size"] == pytest.approx(2 * np.pi / SMALL["pixels"])
        assert h5.attrs["dt"] == pytest.approx(0.01)
        assert json.loads(h5.attrs["flag_names"])[str(int(TracerFlag.SPLIT))] == "split"
        assert json.loads(h5.attrs["config"])["tracers"] == SMALL["tracers"]
        assert "versions" in h5.attrs and "device" in h5.attrs
        assert h5["tracers/x2_meas"].shape == (SMALL["tracers"], 3)  # (id, frame)
        # the paper's differences: velocity at frames 0, 1; acceleration at frame 1
        np.testing.assert_array_equal(h5["velocity/frame"][()], [0, 1])
        assert h5["velocity/u2_true"].shape == (6, 2) and h5["acceleration/a3_meas"].shape == (6, 1)
        assert "velocity_fit" not in h5  # 3 frames: fewer than the fit window
        assert h5["rays"].attrs["count_ok"] > 0
    with pytest.raises(RimclError, match="exists"):
        write_render(path, result)
    # one line in xarray: every per-tracer table is (id, frame) arrays with units, and
    # rimcl's reader gives back the run's frame-major columns exactly
    import xarray as xr

    tables = load_render(path)
    for group in ("tracers", "velocity", "acceleration"):
        table = result.tracers if group == "tracers" else result.kinematics[group]
        read = getattr(tables, group)
        frames = len(np.unique(table["frame"]))
        with xr.open_dataset(path, group=group, engine="h5netcdf") as data:
            assert data["flags"].dims == ("id", "frame")
            np.testing.assert_array_equal(data["id"], np.arange(SMALL["tracers"]))
            for name, values in table.items():
                if name in read:
                    np.testing.assert_array_equal(read[name], values, err_msg=name)
                if name not in ("id", "frame", "time"):
                    grid = values.reshape(frames, SMALL["tracers"]).T
                    np.testing.assert_array_equal(data[name].values, grid, err_msg=name)
            symbol, unit = {"tracers": ("x", "L0"), "velocity": ("u", "L0/T0"),
                            "acceleration": ("a", "L0/T0^2")}[group]  # fmt: skip
            assert data[f"{symbol}2_meas"].attrs["units"] == unit
    with xr.open_dataset(path, group="tracers", engine="h5netcdf") as data:
        assert data["time"].dims == ("frame",) and data["time"].attrs["units"] == "T0"
        np.testing.assert_array_equal(data["time"], result.tracers["time"][:: SMALL["tracers"]])
    # a file of schema version 1 (1-D rows with a row dimension) still reads the same
    old = tmp_path / "version1.h5"
    old.write_bytes(path.read_bytes())
    with h5py.File(old, "a") as h5:
        h5.attrs["schema_version"] = 1
        for group in ("tracers", "velocity", "acceleration"):
            columns = read_table(h5[group])
            del h5[group]
            table = h5.create_group(group)
            for name, values in columns.items():
                table[name] = values
            label_table(table, None if group == "tracers" else "id")
    again = load_render(old)
    for group in ("tracers", "velocity", "acceleration"):
        assert getattr(again, group).keys() == getattr(tables, group).keys()
        for name, values in getattr(tables, group).items():
            np.testing.assert_array_equal(getattr(again, group)[name], values, err_msg=name)
    image_path = tmp_path / "frame.png"
    write_frame_image(image_path, result)
    from PIL import Image

    with Image.open(image_path) as image:
        pixels = np.asarray(image)
        assert "rimcl" in image.info
    np.testing.assert_array_equal(pixels[::-1], result.frame_image)
    # six tracers far apart: the frame's brightest pixel is the brightest measured image's
    first = result.tracers["frame"] == 0
    assert result.frame_image.max() == min(round(result.tracers["peak_meas"][first].max()), 1023)


def test_field_without_velocity_cannot_track(tmp_path, device):
    x1, _, _, h = _grid(8, periodic=True)
    path = tmp_path / "still.h5"
    write_field(
        path,
        density=[1 + 0 * x1] * 3,
        times=TIMES,
        origin=(0, 0, 0),
        spacing=(h, h, h),
        boundary="periodic",
    )
    with pytest.raises(RimclError, match="holds no velocity"):
        render(path, case="C1", device=device, **SMALL)
    single = render(path, case="C1", frames=1, device=device, **SMALL)
    assert set(single.kinematics.values()) == {None}


@pytest.mark.parametrize(
    ("kw", "match"),
    [
        ({"tracers": 0}, "at least 1"),
        ({"frames": 0}, "frames must be"),
        ({"frames": 4}, "need the field up to t = 0.03"),
        ({"start_frame": 1}, "need the field up to t = 0.03"),
        ({"fit_window": 4}, "odd number of frames"),
        ({"camera": "pinhole"}, "unknown camera"),
        ({"threshold": 2000}, "threshold"),
        ({"k_rho": -1.0, "case": None}, "K\\*rho"),
    ],
)
def test_bad_requests_rejected(blobs_file, kw, match):
    settings = {**SMALL, "case": "C1", **kw}
    with pytest.raises(RimclError, match=match):
        render(blobs_file, **settings)


def test_pupil_that_collects_no_ray_is_an_error(linear_file, device):
    # seen from 80° off axis, every ray leaves the clamped field through its side
    with pytest.raises(RimclError, match="no ray"):
        render(
            linear_file,
            camera="pupil",
            view_angle=80.0,
            camera_distance=10.0,
            aperture_diameter=0.5,
            frames=1,
            device=device,
            **{**SMALL, "pixels": 256},
        )


def test_split_images_are_located_by_their_brightest_component_when_asked(device):
    """renderer.split = "brightest" (the paper preset): a split image, or one whose rays
    spread past the window, keeps its brightest component's centroid and is only noted;
    the images, positions and flag bits are those of "exclude", which leaves it out."""
    import dataclasses

    from rimcl.imaging.centroid import TracerFlag

    options = {"tracers": 4, "fan": 12, "renderer": "paper", "pixels": 2048, "psf_sigma": 1.5}
    config = MeasureConfig.from_options(
        device=device, max_window=24, threshold=500.0, bit_depth=10, frames=1, **options
    )
    runs = {
        split: run_render(
            None,
            case="C4",
            config=dataclasses.replace(
                config, renderer=dataclasses.replace(config.renderer, split=split)
            ),
        )
        for split in ("exclude", "brightest")
    }
    excluded, kept = runs["exclude"].tracers, runs["brightest"].tracers
    located = int(TracerFlag.SPLIT | TracerFlag.RAYS_OUTSIDE_WINDOW)
    assert np.any(excluded["flags"] & located)  # the strong case splits or spreads them
    np.testing.assert_array_equal(excluded["x2_meas"], kept["x2_meas"])
    np.testing.assert_array_equal(
        excluded["flags"] | excluded["notes"], kept["flags"] | kept["notes"]
    )
    assert not np.any(kept["flags"] & located)
    np.testing.assert_array_equal(kept["notes"] & located, excluded["flags"] & located)
    assert np.isfinite(kept["x2_meas"][kept["flags"] == 0]).all()
