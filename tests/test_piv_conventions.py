"""The image convention of every PIV output: row 0 at the top (highest x3), pixel centres at
integer coordinates; a known rotation comes out with the right signs and positions in the
frames, the truth, the vectors and every export. OpenPIV (GPL, never a dependency of rimcl)
is used by the last test only where it is installed."""

import h5netcdf
import numpy as np
import pytest
from scipy.io import loadmat
from skimage.measure import label, regionprops

from rimcl.fields.field import Field
from rimcl.optics.camera import PupilCamera, Scene
from rimcl.piv.analysis import PivSettings, WindowGrid, analyze_pair
from rimcl.piv.export import export_vectors
from rimcl.piv.frame_pair import image_frames
from rimcl.piv.imaging_config import PivImaging, frame_pixels, frame_points, seed_particles
from rimcl.piv.truth import true_displacement
from rimcl.ptv.field_source import uniform_like

SCENE = Scene(0.05, 1.05, np.zeros(2), np.ones(2), False)
IMAGING = PivImaging(pixels=128, sheet_thickness=2 / 128)
SETTINGS = PivSettings(window=32, overlap=0.5, passes=3)
THETA = 0.03  # rotation (rad) between the frames, counter-clockwise seen with x3 up


def _camera():
    return PupilCamera(SCENE, diameter=0.2, distance=20.0, rays=4)


def _medium():
    """A uniform medium (n = 1: straight rays) over the scene."""
    grid = Field.from_arrays(
        np.zeros((6, 6, 6)), spacing=(0.25, 0.3, 0.3), origin=(0.0, -0.25, -0.25), n_ref=1.0
    )
    return uniform_like(grid)


def test_frame_pixels_put_row_0_at_the_top_and_centres_on_integers():
    renderer = IMAGING.renderer(SCENE)
    shape = IMAGING.frame_shape(SCENE)
    pixel = renderer.pixel_size
    # the centre of the top-left pixel: lowest x2, highest x3
    corner = np.array([0.5 * pixel, 1.0 - 0.5 * pixel])
    np.testing.assert_allclose(frame_pixels(renderer, shape, corner), [0.0, 0.0], atol=1e-9)
    np.testing.assert_allclose(frame_points(renderer, shape, [0.0, 0.0]), corner, atol=1e-15)


def test_a_tracer_is_imaged_where_its_pixel_coordinates_say(device):
    # one bright tracer on the sheet at a known point: its image's centroid (scikit-image,
    # integer pixel centres) is its frame pixel position, in row 0 at the top
    point = np.array([0.3, 0.8])  # x3 = 0.8: the upper part of the view
    positions = np.array([[[SCENE.x_sheet, *point]]] * 2)
    made = image_frames(
        (_medium(), _medium()), positions, SCENE, _camera(), IMAGING, {"device": device}
    )
    image = made.images[0].astype(float)
    region = regionprops(label(image > 0), intensity_image=image)[0]
    expected = frame_pixels(IMAGING.renderer(SCENE), IMAGING.frame_shape(SCENE), point)
    row, col = region.centroid_weighted
    assert row < 64  # high x3 near the top
    assert col == pytest.approx(expected[0], abs=0.01) and row == pytest.approx(
        expected[1], abs=0.01
    )


@pytest.fixture(scope="module")
def rotation(device):
    """Frames of tracers turned by THETA about the view's centre, vectors and truth."""
    start = seed_particles(SCENE, IMAGING, np.random.default_rng(7))
    offset = start[:, 1:] - 0.5
    turned = 0.5 + offset @ np.array(
        [[np.cos(THETA), np.sin(THETA)], [-np.sin(THETA), np.cos(THETA)]]
    )
    positions = np.stack([start, np.column_stack([start[:, 0], turned])])
    made = image_frames(
        (_medium(), _medium()), positions, SCENE, _camera(), IMAGING, {"device": device}
    )
    vectors = analyze_pair(*made.images, SETTINGS)
    shape = IMAGING.frame_shape(SCENE)
    grid = WindowGrid.for_image(shape, SETTINGS.window, SETTINGS.overlap)
    weights = np.ones(start.shape[0])
    truth = true_displacement(positions, IMAGING.renderer(SCENE), shape, grid, weights)
    return vectors, truth, shape


def test_a_rotation_has_the_right_signs_in_frames_truth_and_vectors(rotation):
    vectors, truth, shape = rotation
    centre = (shape[1] - 1) / 2
    # counter-clockwise with x3 up is counter-clockwise on the screen (y down):
    # dx = θ (y - c), dy = -θ (x - c): the top moves left, the right side moves up
    expected_dx = THETA * (vectors.y - centre)
    expected_dy = -THETA * (vectors.x - centre)
    np.testing.assert_array_equal(truth["x"], vectors.x)
    np.testing.assert_array_equal(truth["y"], vectors.y)
    inner = (slice(1, -1), slice(1, -1))
    # the truth averages the ~30 tracers of a window: their mean position lies ~1.7 px rms
    # off its centre, θ times that off the field at the centre
    assert np.abs(truth["dx"] - expected_dx)[inner].max() < 0.25
    assert np.abs(truth["dy"] - expected_dy)[inner].max() < 0.25
    # the deformed windows measure the rotation at their centres (same sign, same place)
    assert np.abs(vectors.dx - expected_dx)[inner].max() < 0.1
    assert np.abs(vectors.dy - expected_dy)[inner].max() < 0.1
    assert vectors.dx[0].mean() < -1 and vectors.dy[:, -1].mean() < -1


def test_the_exports_keep_the_signs_and_positions(rotation, tmp_path):
    vectors, _, _ = rotation
    for suffix in (".nc", ".txt", ".mat"):
        export_vectors(tmp_path / f"v{suffix}", vectors, orientation="y-down")
    with h5netcdf.File(tmp_path / "v.nc", "r") as nc:
        np.testing.assert_array_equal(nc.variables["y"][:], vectors.y[:, 0])
        np.testing.assert_array_equal(nc.variables["u"][:], vectors.dx)
        np.testing.assert_array_equal(nc.variables["v"][:], vectors.dy)
    # image orientation: OpenPIV's image coordinates (window 0..31 centred at 16)
    table = np.loadtxt(tmp_path / "v.txt")
    np.testing.assert_allclose(table[:, 1], vectors.y.ravel() + 0.5, rtol=1e-8)
    np.testing.assert_allclose(table[:, 3], vectors.dy.ravel(), rtol=1e-7)
    mat = loadmat(tmp_path / "v.mat")
    np.testing.assert_array_equal(mat["y"][0, 0], vectors.y + 1)
    np.testing.assert_array_equal(mat["v_original"][0, 0], vectors.dy)
    assert mat["calv"][0, 0] == 1.0 and mat["orientation"][0] == "y-down"


def test_openpiv_text_is_y_up_as_openpiv_writes_it(rotation, tmp_path):
    """The default .txt is OpenPIV's physical frame: read as OpenPIV's loader reads it
    (numpy.loadtxt, columns x y u v flags mask), the counter-clockwise rotation is
    u = -θ (y - c), v = +θ (x - c) about the frame's centre c = 64 (OpenPIV's coordinates)."""
    vectors, _, shape = rotation
    path = export_vectors(tmp_path / "v.txt", vectors)
    assert path.read_text().splitlines()[0] == "# x\ty\tu\tv\tflags\tmask"
    a = np.loadtxt(path)
    x, y, u, v, flags, mask = a[:, 0], a[:, 1], a[:, 2], a[:, 3], a[:, 4], a[:, 5]
    rows, cols = vectors.dx.shape
    assert a.shape == (rows * cols, 6)
    centre = shape[1] / 2
    # the top row of windows first, carrying the largest y: y up from the bottom edge
    np.testing.assert_allclose(y.reshape(rows, cols), shape[0] - 0.5 - vectors.y, atol=1e-9)
    np.testing.assert_allclose(x.reshape(rows, cols), vectors.x + 0.5, atol=1e-9)
    inner = np.zeros((rows, cols), bool)
    inner[1:-1, 1:-1] = True
    inner = inner.ravel()
    assert np.abs(u - (-THETA * (y - centre)))[inner].max() < 0.1
    assert np.abs(v - THETA * (x - centre))[inner].max() < 0.1
    assert np.all(flags == (~vectors.valid).ravel()) and np.all(mask == 0)


def test_pivlab_mat_holds_calibrated_vectors_with_calu_and_calv(rotation, tmp_path):
    """The .mat as PIVlab's MAT export: calibrated x, y (m) and u, v (m/s) with calxy,
    calu, calv; y-up is PIVlab's "y increases to the top" (calv = -calu)."""
    vectors, _, shape = rotation
    pixel, dt = 2e-5, 1e-3
    export_vectors(tmp_path / "up.mat", vectors, pixel_size_m=pixel, dt_s=dt)
    export_vectors(
        tmp_path / "down.mat", vectors, pixel_size_m=pixel, dt_s=dt, orientation="y-down"
    )
    up, down = loadmat(tmp_path / "up.mat"), loadmat(tmp_path / "down.mat")
    speed = pixel / dt
    for mat in (up, down):
        assert mat["calxy"][0, 0] == pytest.approx(pixel)
        assert mat["calu"][0, 0] == pytest.approx(speed)
        assert mat["units"][0] == "[m] respectively [m/s]"
        np.testing.assert_allclose(mat["x"][0, 0], pixel * (vectors.x + 1))
        np.testing.assert_allclose(mat["u_original"][0, 0], speed * vectors.dx)
        assert mat["u_smoothed"][0, 0].size == 0
    assert up["calv"][0, 0] == pytest.approx(-speed) and up["orientation"][0] == "y-up"
    assert down["calv"][0, 0] == pytest.approx(speed)
    np.testing.assert_allclose(down["y"][0, 0], pixel * (vectors.y + 1))
    np.testing.assert_allclose(down["v_original"][0, 0], speed * vectors.dy)
    # y-up: PIVlab's calibrate.xy, y = calxy (rows - y_px) with 1-based y_px
    y_up = up["y"][0, 0]
    np.testing.assert_allclose(y_up, pixel * (shape[0] - 1 - vectors.y))
    # the rotation, counter-clockwise with y up, about the centre of the pixel centres
    centre = pixel * (shape[0] - 1) / 2
    x_m = up["x"][0, 0] - pixel
    inner = (slice(1, -1), slice(1, -1))
    tolerance = 0.1 * speed  # 0.1 px per pair
    assert np.abs(up["u_original"][0, 0] + THETA * (y_up - centre) / dt)[inner].max() < tolerance
    assert np.abs(up["v_original"][0, 0] - THETA * (x_m - centre) / dt)[inner].max() < tolerance
    assert any("rimcl" in str(line[0]) for line in up["information"].ravel())


def _pair_moved_right_and_down(device):
    """A uniform-medium pair whose tracers move 1 px along x2 and 2 px down (-x3)."""
    start = seed_particles(SCENE, IMAGING, np.random.default_rng(7))
    moved = np.column_stack([start[:, 0], start[:, 1:] + np.array([1.0, -2.0]) / 128])
    return image_frames(
        (_medium(), _medium()),
        np.stack([start, moved]),
        SCENE,
        _camera(),
        IMAGING,
        {"device": device},
    )


def test_openpiv_reads_the_pairs_with_the_right_signs(rotation, device):
    """The recipe of docs/reference/formats/piv.md: OpenPIV's standard pipeline on rimcl's
    frames (skipped where OpenPIV, GPL, is not installed; rimcl never imports it)."""
    pyprocess = pytest.importorskip("openpiv.pyprocess")
    tools = pytest.importorskip("openpiv.tools")
    made = _pair_moved_right_and_down(device)
    a, b = (image.astype(np.int32) for image in made.images)
    u, v, _ = pyprocess.extended_search_area_piv(a, b, 32, 16, search_area_size=32)
    x, y = pyprocess.get_coordinates(a.shape, 32, 16)
    # OpenPIV in image coordinates: u along columns (+x2), v down the rows (-x3)
    # (whole-pixel shifts: one pass without deformation has sub-pixel bias)
    assert np.median(u) == pytest.approx(1.0, abs=0.1)
    assert np.median(v) == pytest.approx(2.0, abs=0.1)
    # after its transform_coordinates, y points up and v = +x3 motion
    _, _, _, v_up = tools.transform_coordinates(x, y, u, v)
    assert np.median(v_up) == pytest.approx(-2.0, abs=0.1)


def test_openpiv_saves_the_file_rimcl_writes(device, tmp_path):
    """OpenPIV's standard pipeline (extended_search_area_piv, get_coordinates,
    scaling.uniform, transform_coordinates, tools.save) on a rimcl pair writes, column by
    column, the file rimcl's export writes for its own vectors of the pair (skipped where
    OpenPIV, GPL, is not installed)."""
    pyprocess = pytest.importorskip("openpiv.pyprocess")
    tools = pytest.importorskip("openpiv.tools")
    scaling = pytest.importorskip("openpiv.scaling")
    made = _pair_moved_right_and_down(device)
    pixel, dt = 1e-5, 1e-3
    a, b = (image.astype(np.int32) for image in made.images)
    u, v, _ = pyprocess.extended_search_area_piv(a, b, 32, 16, dt=dt, search_area_size=32)
    x, y = pyprocess.get_coordinates(a.shape, 32, 16)
    x, y, u, v = scaling.uniform(x, y, u, v, scaling_factor=1 / pixel)
    x, y, u, v = tools.transform_coordinates(x, y, u, v)
    tools.save(tmp_path / "openpiv.txt", x, y, u, v)
    ours = analyze_pair(*made.images, PivSettings(window=32, overlap=0.5, passes=3))
    export_vectors(tmp_path / "rimcl.txt", ours, pixel_size_m=pixel, dt_s=dt)
    theirs, mine = np.loadtxt(tmp_path / "openpiv.txt"), np.loadtxt(tmp_path / "rimcl.txt")
    first = [(tmp_path / n).read_text().splitlines()[0] for n in ("openpiv.txt", "rimcl.txt")]
    assert first[0] == first[1]
    assert theirs.shape == mine.shape == (49, 6)
    # x, y: the same window centres (OpenPIV prints 5 digits)
    np.testing.assert_allclose(mine[:, :2], theirs[:, :2], rtol=1e-4)
    # u, v: the same signs and values; OpenPIV's one pass without deformation loses pairs
    # at the window edges (up to 0.22 px off, median 0.04 px), rimcl's three passes do not
    speed = pixel / dt
    difference = np.abs(mine[:, 2:4] - theirs[:, 2:4]) / speed
    assert difference.max() < 0.3 and np.median(difference) < 0.1
    # moved +1 px along x2 and 2 px down x3: u = +1 px, v = -2 px (v up)
    assert np.median(mine[:, 2:4], axis=0) == pytest.approx([speed, -2 * speed], rel=0.01)
    np.testing.assert_array_equal(mine[:, 4:], theirs[:, 4:])  # no flags, no mask


def _wavy_pair():
    """A pair in a curved flow with gradients of 0.05 px/px, as the sample's at 256 px."""
    from piv_particles import particle_pair

    def wave(x, y):
        return np.sin(2 * np.pi * y / 128), 0.8 * np.cos(2 * np.pi * x / 128)

    return particle_pair(wave, (256, 256), seed=11), wave


def test_curved_flow_keeps_its_valid_vectors():
    # eps 0.2 px: the normalized median test leaves a smooth curved flow alone
    (a, b), wave = _wavy_pair()
    result = analyze_pair(a, b)
    truth_x, truth_y = wave(result.x, result.y)
    assert result.replaced.sum() <= 2
    assert np.sqrt(np.mean((result.dx - truth_x) ** 2)) < 0.06
    assert np.sqrt(np.mean((result.dy - truth_y) ** 2)) < 0.06


def test_as_accurate_as_openpiv_window_deformation():
    """rimcl piv analyze (defaults) against OpenPIV's windef, two passes of 32 px with
    symmetric deformation, on the same curved-flow pair (skipped without OpenPIV)."""
    windef = pytest.importorskip("openpiv.windef")
    validation = pytest.importorskip("openpiv.validation")
    filters = pytest.importorskip("openpiv.filters")
    (a, b), wave = _wavy_pair()
    settings = windef.PIVSettings()
    settings.windowsizes, settings.overlap, settings.num_iterations = (32, 32), (16, 16), 2
    frame_a, frame_b = a.astype(np.float64), b.astype(np.float64)
    x, y, u, v, s2n = windef.first_pass(frame_a, frame_b, settings)
    none = np.zeros_like(u, dtype=bool)
    u, v = np.ma.masked_array(u, mask=none), np.ma.masked_array(v, mask=none)
    flags = validation.typical_validation(u, v, s2n, settings)
    u, v = filters.replace_outliers(u, v, flags, method="localmean", max_iter=4, kernel_size=2)
    u, v = np.ma.masked_array(u, mask=none), np.ma.masked_array(v, mask=none)
    x, y, u, v, _, flags = windef.multipass_img_deform(frame_a, frame_b, 1, x, y, u, v, settings)
    u, v = filters.replace_outliers(u, v, flags, method="localmean", max_iter=4, kernel_size=2)
    # OpenPIV's centres: a window of pixels 0..31 at 16, their centroid at 15.5
    theirs = wave(x - 0.5, y - 0.5)
    ours = analyze_pair(a, b)
    truth = wave(ours.x, ours.y)
    for mine, other, true_mine, true_other in zip(
        (ours.dx, ours.dy), (u, v), truth, theirs, strict=True
    ):
        rms_ours = np.sqrt(np.mean((mine - true_mine) ** 2))
        rms_theirs = np.sqrt(np.mean((np.ma.filled(other, np.nan) - true_other) ** 2))
        assert rms_ours <= rms_theirs
