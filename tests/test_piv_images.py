"""PIV image pairs through a field (rimcl.piv.render), errors (rimcl.piv.study), figures."""

import dataclasses
import json

import h5py
import numpy as np
import pytest
import tifffile
from click.testing import CliRunner

from rimcl.cli.main import cli
from rimcl.core.errors import RimclError
from rimcl.fields.field import Field
from rimcl.fields.field_writer import write_field
from rimcl.optics.camera import PupilCamera, Scene
from rimcl.piv.analysis import PivSettings, WindowGrid, analyze_pair
from rimcl.piv.frame_pair import image_frames
from rimcl.piv.imaging_config import PivImaging, seed_particles, sheet_intensity
from rimcl.piv.render import PivConfig, run_piv_render
from rimcl.piv.study import load_piv_case, run_piv_case, write_piv_case
from rimcl.piv.tracer_motion import MOTION_3D, MOTION_SHEET
from rimcl.piv.truth import window_means
from rimcl.ptv.field_source import uniform_like
from rimcl.scene.config import CameraConfig, RunConfig

#: 96 px frames, 8 rays per tracer through a pupil, 16 px windows: a case in ~1 s
SMALL_PIV = PivConfig(imaging=PivImaging(pixels=96), settings=PivSettings(window=16))
PUPIL = CameraConfig(kind="pupil", pupil_rays=8)


def small(device, **changes):
    """Keyword arguments of run_piv_render / run_piv_case for a small run."""
    piv = dataclasses.replace(SMALL_PIV, **changes)
    return {"piv": piv, "camera": PUPIL, "run": RunConfig(device=device)}


def test_sheet_profile_and_seeding_density():
    assert sheet_intensity(0.3, 0.3, 0.1) == 1.0
    assert sheet_intensity(0.35, 0.3, 0.1) == pytest.approx(np.exp(-2))  # 1/e² at ±t/2
    scene = Scene(0.0, 1.0, np.zeros(2), np.ones(2), False)
    imaging = PivImaging(pixels=200, density=0.05, band=10.0, sheet_thickness=0.02)
    positions = seed_particles(scene, imaging, np.random.default_rng(1))
    # 220 x 220 px seeded; density counts tracers inside the 1/e² thickness
    inside = np.abs(positions[:, 0]) <= 0.01
    assert len(positions) == round(0.05 * 220**2 * 2)
    assert inside.sum() / 220**2 == pytest.approx(0.05, rel=0.05)
    assert np.all(np.abs(positions[:, 0]) <= 0.02)
    assert positions[:, 1].min() < 0 < 1 < positions[:, 2].max()


def test_window_means_know_which_tracers_each_window_holds():
    grid = WindowGrid.for_image((64, 64), 32, 0.5)  # corners 0, 16, 32
    col = np.array([5.0, 20.0, 40.0, 31.499])
    row = np.array([5.0, 5.0, 50.0, 5.0])
    values = np.array([[1.0], [3.0], [7.0], [5.0]])
    weights = np.array([1.0, 1.0, 2.0, 2.0])
    means, total = window_means(grid, col, row, values, weights)
    # window (0, 0) holds pixels 0..31, spanning [-0.5, 31.5)² (pixel centres at integers):
    # tracers 0, 1, 3
    assert total[0, 0] == 4.0 and means[0, 0, 0] == pytest.approx((1 + 3 + 10) / 4)
    # window (0, 1) spans columns [15.5, 47.5): tracers 1 and 3
    assert total[0, 1] == 3.0 and means[0, 1, 0] == pytest.approx((3 + 10) / 3)
    # tracer 2 (40, 50) lies in windows with corners (16 or 32, 32)
    assert total[2, 1] == total[2, 2] == 2.0 and means[2, 2, 0] == 7.0
    assert total[1, 0] == 0 and np.isnan(means[1, 0, 0])


def _slab(g, n0, counts, lo, spacing):
    """A clamped grid with δn = g (x2 - 0.5) and its exact gradient."""
    x2 = lo[1] + spacing[1] * np.arange(counts[1])
    delta_n = np.broadcast_to(g * (x2 - 0.5)[None, :, None], (counts[2], counts[1], counts[0]))
    gradient = np.zeros((*delta_n.shape, 3))
    gradient[..., 1] = g
    return Field.from_arrays(delta_n, spacing=spacing, origin=lo, n_ref=n0, gradient=gradient)


def test_growing_transverse_gradient_matches_the_closed_form(device):
    # a slab of depth L with uniform ∂n/∂x2 shifts every image point by
    # Δ = -L² (∂n/∂x2) / (2 n); a gradient changing between exposures shifts every PIV
    # vector by the change of Δ
    n0, depth, x_sheet = 1.33, 1.0, 0.05
    counts = np.array([6, 8, 8])
    lo, hi = np.array([0.0, -0.1, -0.1]), np.array([x_sheet + depth, 1.1, 1.1])
    spacing = (hi - lo) / (counts - 1)
    scene = Scene(x_sheet, x_sheet + depth, np.zeros(2), np.ones(2), False)
    imaging = PivImaging(pixels=256, sheet_thickness=2 / 256)
    pixel = imaging.pixel_size(scene)
    # a lens of NA 0.025 far away: near-normal rays, as the small-angle closed form assumes
    camera = PupilCamera(scene, diameter=1.0, distance=20.0, rays=16)
    change_px = 1.5
    g_change = -2 * n0 * change_px * pixel / depth**2
    g_a, g_b = -g_change / 2, g_change / 2
    start = seed_particles(scene, imaging, np.random.default_rng(3))
    positions = np.stack([start, start + np.array([0.0, 0.4, 0.25]) * pixel])
    fields = (_slab(g_a, n0, counts, lo, spacing), _slab(g_b, n0, counts, lo, spacing))
    options = {"device": device}
    through = image_frames(fields, positions, scene, camera, imaging, trace_options=options)
    uniform = uniform_like(fields[0])
    plain = image_frames(
        (uniform, uniform), positions, scene, camera, imaging, trace_options=options
    )
    measured = analyze_pair(*through.images)
    reference = analyze_pair(*plain.images)
    x2 = measured.x * pixel
    expected = (
        -(depth**2) / (2 * pixel) * (g_b / (n0 + g_b * (x2 - 0.5)) - g_a / (n0 + g_a * (x2 - 0.5)))
    )
    error_x = measured.dx - reference.dx
    error_y = measured.dy - reference.dy
    assert np.all(np.abs(error_x / expected - 1) < 0.02)
    assert np.all(np.abs(error_y) < 0.02 * change_px)
    assert error_x.mean() / expected.mean() == pytest.approx(1, abs=0.005)
    # the uniform-medium pair measures the true motion
    assert np.abs(reference.dx - 0.4).max() < 0.02 and np.abs(reference.dy + 0.25).max() < 0.02


def _moving_box(path, velocity=(0.02, 0.3, -0.2), sheet_only=False):
    """A periodic box with a density wave and a uniform velocity (u1, u2, u3): in full, or
    only (u2, u3) on the sheet x1 = 0."""
    count = 12
    h = 2 * np.pi / count
    x = np.arange(count) * h
    x3, x2, x1 = np.meshgrid(x, x, x, indexing="ij")
    density = [1 + 0.05 * np.sin(x1 + x2 + t) * np.cos(x3) for t in (0.0, 0.3, 0.6)]
    flow = np.broadcast_to(np.asarray(velocity, dtype=np.float32), (*x1.shape, 3))
    motion = {"velocity": [flow] * 3}
    if sheet_only:
        motion = {"velocity_sheet": [flow[:, :, 0, 1:]] * 3, "sheet_x1": 0.0}
    write_field(
        path,
        density=density,
        times=(0.0, 0.05, 0.1),
        origin=(0, 0, 0),
        spacing=(h, h, h),
        boundary="periodic",
        **motion,
    )
    return str(path)


@pytest.fixture(scope="module")
def box(tmp_path_factory):
    return _moving_box(tmp_path_factory.mktemp("piv") / "box.h5")


def test_uniform_flow_truth_and_out_of_plane_motion(box, device):
    result = run_piv_render(box, case="C2", **small(device))
    assert result.motion == MOTION_3D and result.dt == 0.1
    positions = result.reference.positions
    moved = positions[1] - positions[0]
    np.testing.assert_allclose(moved, np.tile([0.002, 0.03, -0.02], (len(moved), 1)), atol=1e-12)
    truth = result.reference.truth
    pixel = result.pixel_size
    assert np.allclose(truth["dx"], 0.03 / pixel) and np.allclose(truth["dy"], 0.02 / pixel)
    assert np.all(truth["tracers"] > 0)
    assert result.field.images.dtype == np.uint16 and result.field.images.shape == (2, 96, 96)
    assert result.field.ray_counts["ok"] == 2 * len(positions[0]) * 8


def test_truth_file_opens_in_xarray_and_gives_the_truth_in_m_s(box, device, tmp_path):
    import xarray as xr

    from rimcl.piv.truth import write_piv_render

    # 1 cm per field length unit, 0.5 s per field time unit: (u2, u3) = (0.3, -0.2) L0/T0
    # is 6 mm/s along the columns and 4 mm/s down the rows
    camera = dataclasses.replace(PUPIL, length_m=0.01)
    kwargs = {**small(device, time_s=0.5), "camera": camera}
    result = run_piv_render(box, case="C2", **kwargs)
    paths = write_piv_render(tmp_path / "run", result)
    truth = xr.open_dataset(paths["truth"], group="truth", engine="h5netcdf")
    assert truth["u_ms"].dims == ("row", "column") and truth["u_ms"].attrs["units"] == "m/s"
    # the field stores the velocity in float32 (0.3 to 4e-8)
    np.testing.assert_allclose(truth["u_ms"], 0.006, rtol=1e-7)
    np.testing.assert_allclose(truth["v_ms"], 0.004, rtol=1e-7)
    factor = result.pixel_size * 0.01 / (result.dt * 0.5)
    np.testing.assert_array_equal(truth["u_ms"], result.reference.truth["dx"] * factor)
    assert truth["dx"].attrs["units"] == "px"
    np.testing.assert_array_equal(truth["column"], result.reference.truth["x"][0])
    particles = xr.open_dataset(paths["truth"], group="particles", engine="h5netcdf")
    assert particles["position"].dims == ("id", "frame", "axis")
    assert list(particles["frame"].values) == ["A", "B"]
    assert particles["position"].attrs["units"] == "L0"
    np.testing.assert_array_equal(
        particles["position"].sel(frame="B").values, result.reference.positions[1]
    )
    assert particles["image_point_field"].dims == ("id", "frame", "image_axis")
    np.testing.assert_array_equal(
        particles["rays_collected_uniform"].sel(frame="A"), result.uniform.collected[0]
    )
    root = xr.open_dataset(paths["truth"], engine="h5netcdf")
    assert root.attrs["length_m"] == 0.01 and root.attrs["time_s"] == 0.5
    assert root.attrs["m_s_per_px"] == pytest.approx(factor, rel=1e-15)


def test_sheet_velocity_moves_tracers_in_plane_only(tmp_path, device):
    # a file with the sheet velocity only: every tracer keeps its depth and moves with the
    # sheet's (u2, u3), whatever its x1; the out-of-plane u1 is not there to use
    box = _moving_box(tmp_path / "sheet.h5", sheet_only=True)
    result = run_piv_render(box, case="C2", **small(device))
    assert result.motion == MOTION_SHEET
    positions = result.reference.positions
    np.testing.assert_array_equal(positions[1, :, 0], positions[0, :, 0])
    assert np.ptp(positions[0, :, 0]) > 0.5 * result.imaging.thickness(result.scene)
    moved = positions[1, :, 1:] - positions[0, :, 1:]
    np.testing.assert_allclose(moved, np.tile([0.03, -0.02], (len(moved), 1)), atol=1e-9)
    prefix = tmp_path / "sheet"
    from rimcl.piv.truth import write_piv_render

    write_piv_render(prefix, result)
    with h5py.File(tmp_path / "sheet_truth.h5") as h5:
        assert "NOT modelled" in h5.attrs["motion"]
    # a sheet elsewhere than the stored plane has no velocity to move its tracers
    with pytest.raises(RimclError, match="stores the sheet velocity only on x1 = 0"):
        run_piv_render(box, case="C2", **small(device, x_sheet=1.0))


def test_zero_k_rho_gives_exactly_zero_refraction_error(device):
    first = run_piv_case(case="C3", **small(device))
    zero = run_piv_case(k_rho=0.0, reference=first.reference, **small(device))
    # the shipped sample stores the sheet velocity only, 0.02 apart; dt = 0.1 spans 5
    assert first.render.motion == MOTION_SHEET
    assert first.render.config["velocity_frames"] == [0, 1, 2, 3, 4, 5]
    vectors = zero.vectors
    assert np.array_equal(zero.render.field.images, zero.render.uniform.images)
    assert np.all(vectors["dx_field"] - vectors["dx_uniform"] == 0)
    assert np.all(vectors["dy_field"] - vectors["dy_uniform"] == 0)
    assert np.all(vectors["dx_optics"][vectors["used"]] == 0)
    assert zero.stats["displacement_px"]["refraction_max"] == 0.0
    assert zero.stats["velocity"]["u3"]["rms_normalized"] == 0.0
    # the case that bends light does move the vectors
    assert first.stats["displacement_px"]["refraction_rms"] > 0
    assert {"systematic", "random", "median", "iqr", "rms_normalized", "n"} <= set(
        first.stats["velocity"]["u2"]
    )


def test_reference_must_match(box, device):
    first = run_piv_render(box, case="C1", **small(device))
    with pytest.raises(RimclError, match="differs in: seed"):
        run_piv_render(box, case="C2", reference=first.reference, **small(device, seed=5))


def test_exposure_beyond_the_stored_frames_is_refused(box):
    with pytest.raises(RimclError, match="beyond the last stored frame"):
        run_piv_render(box, case="C1", **small(None, start_frame=1, dt=0.2))


def test_lens_camera_sets_the_frame(box, device):
    lens = CameraConfig(
        kind="lens", length_m=0.01, magnification=0.5, sensor_pixels=(80, 64), pupil_rays=8
    )
    result = run_piv_render(
        box, case="C1", piv=SMALL_PIV, camera=lens, run=RunConfig(device=device)
    )
    camera = result.camera
    assert result.pixel_size == camera.pixel_size
    assert result.field.images.shape == (2, 64, 80)
    assert result.renderer.psf_sigma == camera.psf_sigma_px
    # uniform flow: the truth is the motion in this lens's pixels
    assert np.allclose(result.reference.truth["dx"], 0.03 / camera.pixel_size)


def test_cli_render_writes_frames_and_truth(box, device, tmp_path):
    prefix = tmp_path / "run"
    args = ["piv", "render", "--field", box, "--case", "C2", "--pixels", "96"]
    args += ["--camera", "pupil", "--pupil-rays", "8", "--window", "16", "-o", str(prefix)]
    result = CliRunner().invoke(cli, args)
    assert result.exit_code == 0, result.output
    for name in ("field_A", "field_B", "uniform_A", "uniform_B"):
        image = tifffile.imread(tmp_path / f"run_{name}.tif")
        assert image.dtype == np.uint16 and image.shape == (96, 96) and image.max() > 0
    with h5py.File(tmp_path / "run_truth.h5") as h5:
        assert h5.attrs["rimcl_schema"] == "piv_truth" and "versions" in h5.attrs
        assert h5["truth/dx"].shape == (11, 11)
        assert h5["particles/position"].shape[1:] == (2, 3)  # (id, frame, axis)
        assert "m_s_per_px" not in h5.attrs or h5.attrs["m_s_per_px"] > 0
    again = CliRunner().invoke(cli, args)
    assert again.exit_code == 1 and "exists" in again.output


def test_render_overwrite_writes_the_five_files_as_one_set(box, device, tmp_path, monkeypatch):
    import rimcl.piv.truth

    prefix = tmp_path / "run"
    args = ["piv", "render", "--field", box, "--case", "C2", "--pixels", "96"]
    args += ["--camera", "pupil", "--pupil-rays", "8", "--window", "16", "-o", str(prefix)]
    assert CliRunner().invoke(cli, args).exit_code == 0
    before = {path.name: path.read_bytes() for path in tmp_path.iterdir()}
    assert len(before) == 5

    real_file = h5py.File

    def full_disk(path, mode="r", **kwargs):
        if mode != "w":
            return real_file(path, mode, **kwargs)
        raise OSError(f"Unable to create file (name = '{path}', errno = 28, No space left)")

    monkeypatch.setattr(rimcl.piv.truth.h5py, "File", full_disk)
    result = CliRunner().invoke(cli, [*args, "--case", "C4", "--overwrite"])
    assert result.exit_code == 1
    lines = result.output.strip().splitlines()
    assert len(lines) == 1 and "run_truth.h5'" in lines[0] and ".part" not in lines[0], lines
    assert "failed, the old ones are unchanged" in lines[0]
    assert {path.name: path.read_bytes() for path in tmp_path.iterdir()} == before


def test_case_file_round_trip(box, device, tmp_path):
    case = run_piv_case(box, case="C4", **small(device))
    path = tmp_path / "case.h5"
    write_piv_case(path, case)
    vectors, stats = load_piv_case(path)
    assert stats["name"] == "C4" and stats["n_vectors"] == vectors["x"].size
    np.testing.assert_array_equal(vectors["dx_field"], case.vectors["dx_field"])


def test_figures_of_two_cases(box, device, tmp_path):
    from rimcl.piv.figures import FIGURE_NAMES, write_piv_figures

    strong = run_piv_case(box, case="C4", **small(device))
    zero = run_piv_case(box, k_rho=0.0, reference=strong.reference, **small(device))
    # a window without tracers: no truth there, and the vector is not used
    strong.vectors["dx_true"][0, 0] = np.nan
    strong.vectors["used"][0, 0] = False
    cases = [(strong.vectors, strong.stats), (zero.vectors, zero.stats)]
    written = write_piv_figures(cases, tmp_path, config={"test": True})
    assert len(written) == 3 * len(FIGURE_NAMES)
    for name in FIGURE_NAMES:
        assert (tmp_path / f"{name}.png").stat().st_size > 10_000
        document = json.loads((tmp_path / f"{name}.json").read_text())
        assert document["config"] == {"test": True} and document["panels"]
    pdfs = json.loads((tmp_path / "piv_error_pdfs.json").read_text())["panels"]
    # sorted by Δn_max: the uniform medium first, with every refraction error exactly zero
    assert pdfs["a"]["series"][0]["exactly_zero"]
    assert pdfs["f"]["G"] == [strong.stats["G"]]
    maps = json.loads((tmp_path / "piv_error_maps.json").read_text())["panels"]
    assert maps["baseline C4"]["magnitude_px"][0][0] is None
    # in your units where the field's scales are known: without them, pixels alone
    from test_figures import layout_problems

    from rimcl.piv.figures import draw_piv_figure

    assert strong.stats["length_m"] is None  # the library's default plane camera
    figure, _ = draw_piv_figure("piv_error_pdfs", cases[::-1])
    assert not [child for ax in figure.axes for child in ax.child_axes]
    scaled = [(v, {**s, "length_m": 0.01, "time_s": 0.5}) for v, s in cases[::-1]]
    figure, _ = draw_piv_figure("piv_error_pdfs", scaled)
    (second,) = [child for ax in figure.axes for child in ax.child_axes]
    assert second.get_ylabel() == "rms per-vector error (mm/s)"
    pixel = strong.stats["pixel_size_over_L"] * strong.stats["length_L"]
    # one pixel in Δt: pixel · 1 cm / (Δt · 0.5 s), in mm/s
    assert second._functions[0](1.0) == pytest.approx(pixel * 10.0 / (strong.stats["dt"] * 0.5))
    # what the scales add stays clear of the rest (the PDF panels' corner ticks '0.0' and
    # '10^-2' sit within 2 px of each other with or without scales: not checked here)
    assert [p for p in layout_problems(figure) if "second axis" in p or "cut" in p] == []
    figure, _ = draw_piv_figure("piv_vectors", scaled)
    assert f"1 px = {pixel * 1e4:.3g} µm on the sheet" in figure._suptitle.get_text()
    assert layout_problems(figure) == []


def test_ray_deposit_is_the_exact_renderer():
    from scipy.special import ndtr

    from rimcl.imaging.render import Renderer
    from rimcl.piv.frame_pair import deposit_rays

    renderer = Renderer("exact", 1.0, (0.0, 0.0), 0.75, 64, 16)
    points = np.array([[10.3, 20.7], [30.5, 12.25], [0.2, 5.0]])  # (column, row)
    weights = np.array([1.0, 0.5, 2.0])
    frame = np.zeros((40, 50))
    assert deposit_rays(frame, points, weights, renderer) == 0
    # each ray alone through the exact renderer, on a canvas 10 px wider on every side
    canvas = np.zeros((60, 70))
    for point, weight in zip(points, weights, strict=True):
        window = renderer.window_for(point[None])
        image, _ = renderer.render(point[None], np.array([weight]), window)
        rows, cols = window.row0 + 10, window.col0 + 10
        canvas[rows : rows + window.height, cols : cols + window.width] += image
    np.testing.assert_allclose(frame, canvas[10:50, 10:60], rtol=0, atol=1e-15)
    # the third ray loses the light left of column 0
    lost = weights[2] * ndtr(-0.2 / 0.75)
    assert frame.sum() == pytest.approx(weights.sum() - lost, abs=1e-4)
    assert deposit_rays(frame, np.array([[-3.0, 4.0]]), np.ones(1), renderer) == 1
