"""Figures: every file written, labelled axes, nothing cut or overlapping, numbers = stats."""

import io
import json

import h5py
import numpy as np
import pytest
from matplotlib.backends.backend_agg import FigureCanvasAgg
from PIL import Image
from synthetic_budget import write_budget_file
from synthetic_render import write_render_file

from rimcl.stats.document import compute_stats
from rimcl.stats.figures import FIGURE_NAMES, draw_figure, write_figures
from rimcl.stats.figures_dt_sweep import draw_dt_sweep, write_dt_sweep_figure
from rimcl.stats.figures_rays import LITERATURE_STUDIES
from rimcl.stats.render_file import load_render

CASES = (
    ("G=0", 0.0, 0.0, 0.0, 0.0),
    ("C1", 2.82e-4, 1e-5, 1e-3, 0.05),
    ("C4", 0.334, 1e-2, 0.1, 20.0),
)


@pytest.fixture(scope="module")
def study(tmp_path_factory):
    folder = tmp_path_factory.mktemp("figures")
    tables = []
    for name, g, position, bias, spread in CASES:
        path = folder / f"{name}.h5"
        write_budget_file(
            path,
            optics_share=0.3,
            fit_frames=3 if g > 0 else None,
            case=name,
            k_rho=g,
            n_tracers=120,
            position_error_over_length=position,
            velocity_bias=bias,
            velocity_spread=spread,
            acceleration_bias=10 * bias,
            acceleration_spread=100 * spread,
            flagged={0: 2},
        )
        tables.append(load_render(path))
    return tables, compute_stats(tables), folder


def drawn_texts(figure, renderer):
    """``(what, window extent)`` of every text drawn: titles, labels, drawn tick labels,
    axes texts, legends, the suptitle and figure legends."""
    found = []

    def add(text, name):
        if text.get_visible() and text.get_text().strip():
            found.append((name, text.get_window_extent(renderer)))

    if figure._suptitle is not None:
        add(figure._suptitle, "suptitle")
    found += [("figure legend", legend.get_window_extent(renderer)) for legend in figure.legends]

    def add_axis(axis, where):
        add(axis.label, f"{where} {axis.axis_name}label")
        for tick in axis._update_ticks():
            for label in (tick.label1, tick.label2):
                add(label, f"{where} tick {label.get_text()!r}")

    for index, ax in enumerate(figure.axes):
        if not ax.axison:
            continue
        where = f"axes {index} {ax.get_title(loc='left')[:25]!r}"
        add(ax._left_title, f"{where} title")
        add(ax.title, f"{where} centre title")
        for axis in (ax.xaxis, ax.yaxis):
            add_axis(axis, where)
        # secondary axes (physical units) are children of their axes
        for child in ax.child_axes:
            for axis in (child.xaxis, child.yaxis):
                add_axis(axis, f"{where} second axis")
        if ax.get_legend() is not None:
            found.append((f"{where} legend", ax.get_legend().get_window_extent(renderer)))
        for text in ax.texts:
            add(text, f"{where} text")
    return found


def layout_problems(figure):
    """Text outside the figure, titles wider than their panel, text within 2 px of text."""
    canvas = FigureCanvasAgg(figure)
    canvas.draw()
    renderer = canvas.get_renderer()
    box = figure.bbox
    texts = drawn_texts(figure, renderer)
    problems = [
        f"cut: {name}"
        for name, e in texts
        if e.x0 < box.x0 - 1 or e.x1 > box.x1 + 1 or e.y0 < box.y0 - 1 or e.y1 > box.y1 + 1
    ]
    problems += [
        f"title wider than its panel: {ax.get_title(loc='left')[:30]!r}"
        for ax in figure.axes
        if ax.axison
        and ax.get_title(loc="left")
        and ax._left_title.get_window_extent(renderer).x1 > ax.bbox.x1 + 2
    ]
    for i, (name_a, a) in enumerate(texts):
        problems += [
            f"overlap: {name_a} / {name_b}"
            for name_b, b in texts[i + 1 :]
            if a.padded(2).overlaps(b)
        ]
    return problems


def test_every_figure_is_written_with_metadata_and_its_numbers(study):
    tables, stats, folder = study
    out = folder / "out"
    written = write_figures(tables, stats, out)
    assert len(written) == 3 * len(FIGURE_NAMES) >= 27
    for name in FIGURE_NAMES:
        with Image.open(out / f"{name}.png") as png:
            assert png.text["Software"].startswith("rimcl")
            assert png.size[0] > 400
        assert (out / f"{name}.pdf").read_bytes().startswith(b"%PDF")
        document = json.loads((out / f"{name}.json").read_text())
        assert document["figure"] == name
        assert document["config"] == stats["config"]
        assert "numpy" in document["versions"]


@pytest.mark.parametrize("name", FIGURE_NAMES)
def test_every_panel_is_labelled_and_nothing_is_cut_or_overlaps(study, name):
    tables, stats, _ = study
    figure, _ = draw_figure(name, tables, stats)
    shown = [ax for ax in figure.axes if ax.axison and ax.get_label() != "<colorbar>"]
    assert shown
    for ax in shown:
        assert ax.get_xlabel().strip()
        assert ax.get_ylabel().strip()
        title = ax.get_title(loc="left")
        # the panel letter opens the one title: it cannot sit over another title
        assert title.startswith("(") and not ax.get_title(loc="center"), title
    assert layout_problems(figure) == []


def test_the_layout_check_finds_a_title_over_a_title_and_a_cut_label(study):
    tables, stats, _ = study
    figure, _ = draw_figure("position_error", tables, stats)
    figure.axes[0].set_title("a centred title over the left one", loc="center")
    figure.axes[1].set_ylabel("y" * 400)
    problems = layout_problems(figure)
    assert any("overlap" in p and "centre title" in p for p in problems), problems
    assert any(p.startswith("cut") and "ylabel" in p for p in problems), problems


def test_position_figure_numbers_are_the_stats_numbers(study):
    tables, stats, _ = study
    _, data = draw_figure("position_error", tables, stats)
    peak, median = data["panels"]["b"]
    positive = [case for case in stats["cases"] if case["G"] > 0]
    assert peak["G"] == [case["G"] for case in positive]
    assert peak["value"] == [case["position_error_peak_over_L"] for case in positive]
    assert peak["ci95"] == [case["position_error_peak_over_L_ci95"] for case in positive]
    assert median["value"] == [case["position_error_median_over_L"] for case in positive]
    zero_case = data["panels"]["a"]["series"][0]
    assert zero_case["x_over_L"] == [] and zero_case["n_zero"] == zero_case["n"] == 357


def test_relative_error_histograms_are_normalised_pdfs(study):
    tables, stats, _ = study
    _, data = draw_figure("velocity_error", tables, stats)
    panel = data["panels"]["a"]
    # densities of log10 |ε/truth| on log bins: no gap at zero, each integrates to 1
    widths = np.diff(np.log10(panel["bin_edges"]))
    zero_case, air, water = panel["series"]
    assert zero_case["exactly_zero"] and zero_case["pdf"] == []
    assert zero_case["n_zero"] == zero_case["n"] > 0
    for series in (air, water):
        assert np.sum(np.asarray(series["pdf"]) * widths) == pytest.approx(1.0, rel=1e-12)
        assert series["n_zero"] == 0
    random_panel = data["panels"]["f"]
    u3 = next(s for s in random_panel if s["label"] == "u3: std(ε/u3)")
    assert u3["value"] == [case["velocity"]["u3"]["random"] for case in stats["cases"][1:]]
    assert u3["ci95"] == [case["velocity"]["u3"]["ci95"]["random"] for case in stats["cases"][1:]]


def test_angles_to_the_reference_and_to_the_truth(study):
    tables, stats, _ = study
    _, data = draw_figure("velocity_error", tables, stats)
    air = data["panels"]["d"]["series"][1]
    # the baseline adds 1 % of u along u: the angle to u equals the angle to u^ref
    assert air["ref"]["angle_deg"] and air["true"]["angle_deg"]
    np.testing.assert_allclose(air["ref"]["pdf_log10"], air["true"]["pdf_log10"], rtol=1e-6)


def test_acceleration_figure_uses_the_estimator_of_the_papers_table(study):
    tables, stats, _ = study
    figure, data = draw_figure("acceleration_error", tables, stats)
    assert "three-point differences" in figure._suptitle.get_text()
    for letter, key in (("e", "systematic"), ("f", "random"), ("g", "rms_normalized")):
        series = next(s for s in data["panels"][letter] if s["label"].startswith("a3"))
        assert series["value"] == [c["acceleration"]["a3"][key] for c in stats["cases"][1:]]


def test_maps_draw_each_value_at_its_own_frame(tmp_path):
    path = tmp_path / "c1.h5"
    write_render_file(path, n_tracers=30)
    with h5py.File(path, "a") as h5:
        h5["acceleration/frame"] = np.ones(30, dtype=np.int64)  # the three-point middle frame
        ids, frames = h5["tracers/id"][()], h5["tracers/frame"][()]
        x2 = h5["tracers/x2_true"][()]
    tables = [load_render(path)]
    _, data = draw_figure("maps", tables, compute_stats(tables))
    acceleration = data["panels"]["a3 truth"]
    expected = {int(i): x for i, f, x in zip(ids, frames, x2, strict=True) if f == 1}
    assert acceleration["x2"] == [expected[i] for i in acceleration["id"]]
    velocity = data["panels"]["u3 truth"]
    first = {int(i): x for i, f, x in zip(ids, frames, x2, strict=True) if f == 0}
    assert velocity["x2"] == [first[i] for i in velocity["id"]]


def test_budget_figure_draws_the_four_parts_and_the_verdicts(study):
    tables, stats, _ = study
    _, data = draw_figure("error_budget", tables, stats)
    velocity = data["panels"]["b"]
    assert [series["label"] for series in velocity] == [
        "optics",
        "imaging",
        "total refraction",
        "baseline (no refraction)",
    ]
    optics, imaging, total, _ = velocity
    np.testing.assert_allclose(optics["value"], 0.3 * np.asarray(total["value"]), rtol=1e-9)
    np.testing.assert_allclose(imaging["value"], 0.7 * np.asarray(total["value"]), rtol=1e-9)
    verdicts = data["panels"]["verdicts"]
    assert len(verdicts) == 3 and all("dominates" in line for line in verdicts)


def test_convergence_figure_draws_each_subsample(study):
    tables, stats, _ = study
    _, data = draw_figure("convergence", tables, stats)
    first = data["panels"]["a"]
    assert first["group"] == "velocity" and len(data["panels"]) == 4  # one per quantity
    air = next(e for e in first["series"] if e["statistic"] == "random")
    convergence = stats["cases"][1]["convergence"]
    values = convergence["velocity"]["u3"]["random"]["value"]
    assert air["n_tracers"] == convergence["n_tracers"]
    np.testing.assert_allclose(air["value"], values, rtol=1e-12)
    np.testing.assert_allclose(air["relative_to_n"], np.asarray(values) / values[-1], rtol=1e-12)


def test_deflection_figure_marks_the_literature_and_the_incidence_split(study):
    tables, stats, _ = study
    figure, data = draw_figure("ray_deflection", tables, stats)
    literature = data["panels"]["a"]["literature"]
    assert len(literature) == len(LITERATURE_STUDIES) == 10
    water = next(entry for entry in literature if "water" in entry["flow"])
    # the studies sit at their Δn_max, the axis of the cases: no path length is invented
    assert water["delta_n_max"] == 3.4e-4 and "NL" not in water
    labels = [text.get_text() for text in figure.axes[0].get_legend().get_texts()]
    assert "0 ≤ |θ0| ≤ 0.6" in labels and "0.6 < |θ0|" in labels
    # (a) each case's deflections at its own Δn_max, with their median (not |N| L, which
    # is the same path integral as |Δθ|)
    positive = [case for case in stats["cases"] if case["delta_n_max"] > 0]
    series = data["panels"]["a"]["series"]
    assert [entry["delta_n_max"] for entry in series] == [c["delta_n_max"] for c in positive]
    for entry in series:
        if entry["deflection"]:
            assert entry["median"] == pytest.approx(np.median(entry["deflection"]))
    assert "Δn_max" in figure.axes[1].get_xlabel()


def test_maps_show_the_uniform_medium_beside_truth_and_measurements(study):
    tables, stats, _ = study
    _, data = draw_figure("maps", tables, stats)
    uniform = data["panels"]["u3 uniform medium (no refraction)"]
    air = next(t for t in tables if t.case == "C1")
    kept = air.velocity["id"] != 0
    np.testing.assert_array_equal(uniform["value"], air.velocity["u3_ref"][kept])


def test_tracer_shape_splits_small_and_large_area_changes(study, tmp_path):
    tables, _, _ = study
    path = tmp_path / "big.h5"
    write_render_file(path, case="C9", k_rho=0.5, n_tracers=60)
    with h5py.File(path, "a") as h5:
        area = h5["tracers/area_ref"][()]
        h5["tracers/area_meas"][...] = area * 40
    both = [*tables, load_render(path)]
    figure, data = draw_figure("tracer_shape", both, compute_stats(both))
    titles = [ax.get_title(loc="left") for ax in figure.axes]
    assert any("small changes" in t for t in titles) and any("large changes" in t for t in titles)
    small = data["panels"]["a"]
    # whole pixels of an 80 px² image, bins centred on whole-pixel changes
    steps = np.diff(small["bin_edges"]) * 80
    assert np.allclose(steps, np.round(steps)) and np.all(steps >= 1)
    centres = (np.asarray(small["bin_edges"][:-1]) + steps / 160) * 80
    assert np.allclose(centres / steps, np.round(centres / steps))


def test_a_uniform_medium_alone_draws_every_figure(study):
    tables, _, _ = study
    uniform = [tables[0]]
    stats = compute_stats(uniform)
    for name in FIGURE_NAMES:
        figure, _ = draw_figure(name, uniform, stats)
        figure.savefig(io.BytesIO(), format="png", dpi=30)
        notes = [text.get_text() for ax in figure.axes for text in ax.texts]
        if name in ("position_error", "velocity_error"):
            assert "nothing to show: every value is zero" in notes


def test_dt_sweep_finds_where_refraction_dominates(study, tmp_path):
    _, stats, _ = study

    def at(dt, factor):
        document = json.loads(json.dumps(stats))
        for case in document["cases"]:
            baseline = case["baseline"]["velocity"]["u3"]
            baseline["rms_normalized"] *= factor
            baseline["ci95"]["rms_normalized"] = [
                factor * v for v in baseline["ci95"]["rms_normalized"]
            ]
        return document

    # the baseline falls as 1/Δt; refraction stays: it dominates from some Δt on
    sweep = {dt: at(dt, 1e-3 / dt) for dt in (0.005, 0.02, 0.08)}
    figure, data = draw_dt_sweep(sweep)
    entry = data["panels"]["cases"]["C1"]["velocity.u3"]
    assert entry["baseline"][0] / entry["baseline"][2] == pytest.approx(16.0)
    expected = [r > b for r, b in zip(entry["refraction"], entry["baseline"], strict=True)]
    assert entry["dominates"] == expected
    assert layout_problems(figure) == []
    written = write_dt_sweep_figure(sweep, tmp_path / "sweep")
    assert (tmp_path / "sweep" / "dt_sweep.png").exists()
    assert written["dt"] == [0.005, 0.02, 0.08]


def test_position_error_axes_carry_micrometres_where_the_scene_gives_the_size(study):
    import dataclasses

    tables, stats, _ = study

    def micrometre_axes(all_tables):
        figure, _ = draw_figure("position_error", all_tables, stats)
        assert layout_problems(figure) == []
        return [
            child
            for ax in figure.axes
            for child in ax.child_axes
            if "µm" in (child.get_xlabel() + child.get_ylabel())
        ]

    assert micrometre_axes(tables) == []  # field units only: no physical axis
    scaled = [dataclasses.replace(t, length_m=0.01) for t in tables]
    pdf_axis, peak_axis = micrometre_axes(scaled)
    # |ε_x| / L = 1e-3 is 1e-3 of L field units of 1 cm each, in µm, on both axes
    for axis in (pdf_axis, peak_axis):
        forward, inverse = axis._functions
        assert forward(1e-3) == pytest.approx(1e-3 * tables[0].length * 0.01 * 1e6)
        assert inverse(forward(2e-4)) == pytest.approx(2e-4)


def test_maps_and_dt_sweep_speak_physical_units_where_the_scales_are_known(study):
    import dataclasses

    tables, stats, _ = study
    _, plain = draw_figure("maps", tables, stats)
    truth = plain["panels"]["u3 truth"]
    assert truth["units"] == {"x2": "field length units", "x3": "field length units",
                              "value": "field units"}  # fmt: skip
    # 1 cm and 0.5 s per field unit: 10 mm per length unit, 20 mm/s per velocity unit,
    # 0.04 m/s² per acceleration unit
    scaled = [dataclasses.replace(t, length_m=0.01, time_s=0.5) for t in tables]
    figure, data = draw_figure("maps", scaled, stats)
    for key, unit, factor in (("u3 truth", "mm/s", 20.0), ("a3 truth", "m/s²", 0.04)):
        panel, before = data["panels"][key], plain["panels"][key]
        assert panel["units"] == {"x2": "mm", "x3": "mm", "value": unit}
        np.testing.assert_allclose(panel["x2"], np.asarray(before["x2"]) * 10.0, rtol=1e-12)
        np.testing.assert_allclose(panel["value"], np.asarray(before["value"]) * factor, rtol=1e-12)
    labels = {ax.get_xlabel() for ax in figure.axes} | {ax.get_ylabel() for ax in figure.axes}
    assert {"x2 (mm)", "x3 (mm)", "u3 (mm/s)", "a3 (m/s²)"} <= labels
    assert layout_problems(figure) == []

    def sweep(time_s):
        documents = {}
        for dt in (0.005, 0.02, 0.08):
            document = json.loads(json.dumps(stats))
            for case in document["cases"]:
                case["units"]["scales"]["time_s"] = time_s
            documents[dt] = document
        return documents

    figure, data = draw_dt_sweep(sweep(None))
    assert data["panels"]["ms_per_time_unit"] is None
    assert not [child for ax in figure.axes for child in ax.child_axes]
    figure, data = draw_dt_sweep(sweep(0.5))
    assert data["panels"]["ms_per_time_unit"] == 500.0
    tops = [child for ax in figure.axes for child in ax.child_axes]
    assert tops and all(child.get_xlabel() == "Δt (ms)" for child in tops)
    assert tops[0]._functions[0](0.02) == pytest.approx(10.0)  # 0.02 × 0.5 s = 10 ms
    assert layout_problems(figure) == []


def test_circularity_of_images_of_a_few_pixels_is_not_drawn(tmp_path):
    path = tmp_path / "c1.h5"
    write_render_file(path, n_tracers=30)
    with h5py.File(path, "a") as h5:
        h5["tracers/area_ref"][...] = 4.0
        h5["tracers/area_meas"][...] = 4.0 + (np.arange(h5["tracers/area_meas"].size) % 2)
    tables = [load_render(path)]
    figure, data = draw_figure("tracer_shape", tables, compute_stats(tables))
    assert data["panels"]["b"] == {"not_drawn": True, "median_area_px": 4.0}
    titles = [" ".join(ax.get_title(loc="left").split()) for ax in figure.axes]
    assert any("whole pixels, ΔA/A moves in steps of 0.25" in t for t in titles)
    assert layout_problems(figure) == []


def test_dt_sweep_draws_a_quantity_that_some_time_steps_lack(study):
    """At 3Δt five frames hold no acceleration (it needs 7): the acceleration panel stays,
    with n/a there; a quantity at one time step only is not drawn."""
    _, stats, _ = study
    lacking = json.loads(json.dumps(stats))
    for case in lacking["cases"]:
        for group in ("acceleration", "velocity_fit", "acceleration_fit"):
            case.pop(group, None)
            case["baseline"].pop(group, None)
    only_first = json.loads(json.dumps(stats))
    for case in only_first["cases"]:
        case.pop("velocity_fit", None)
    sweep = {0.02: stats, 0.04: only_first, 0.06: lacking}
    figure, data = draw_dt_sweep(sweep)
    panels = data["panels"]
    assert "acceleration.a3" in panels["quantities"]
    assert "velocity_fit.u3" not in panels["quantities"]  # at 0.02 only
    entry = panels["cases"]["C1"]["acceleration.a3"]
    assert entry["refraction"][2] is None and entry["refraction"][0] is not None
    assert layout_problems(figure) == []


def test_position_pdf_counts_the_exact_zeros_it_cannot_draw(tmp_path):
    """Tracers whose image did not move (|ε_x| = 0, as the paper preset's whole-pixel
    images give) are counted in the label and the curve carries the others' share."""
    path = tmp_path / "c1.h5"
    write_render_file(path, n_tracers=40)
    with h5py.File(path, "a") as h5:
        unmoved = h5["tracers/id"][()] < 10
        for c in ("2", "3"):
            meas = h5[f"tracers/x{c}_meas"][()]
            meas[unmoved] = h5[f"tracers/x{c}_ref"][()][unmoved]
            h5[f"tracers/x{c}_meas"][...] = meas
    tables = [load_render(path)]
    figure, data = draw_figure("position_error", tables, compute_stats(tables))
    entry = data["panels"]["a"]["series"][0]
    assert entry["n_zero"] == int(np.count_nonzero(unmoved)) > 0
    assert entry["nonzero_share"] == pytest.approx(1 - entry["n_zero"] / entry["n"])
    widths = np.diff(np.log10(entry["x_over_L"]))
    area = np.sum(0.5 * (np.asarray(entry["pdf_log10"][1:]) + entry["pdf_log10"][:-1]) * widths)
    assert area == pytest.approx(entry["nonzero_share"], rel=0.02)
    labels = [text.get_text() for text in figure.axes[0].get_legend().get_texts()]
    assert any(f"{entry['n_zero']} of {entry['n']} exactly 0" in label for label in labels)


def test_unconverged_statistics_are_drawn_open_without_bars(study):
    """The paper's random error of a case marked not converged is an open point without
    its bar in panel (f); the others keep their bars."""
    tables, stats, _ = study
    stats = json.loads(json.dumps(stats))
    stats["cases"][1]["convergence"]["not_converged"] = []
    stats["cases"][-1]["convergence"]["not_converged"] = ["velocity.u3.random"]
    figure, data = draw_figure("velocity_error", tables, stats)
    u3 = next(s for s in data["panels"]["f"] if s["label"] == "u3: std(ε/u3)")
    assert u3["not_converged"] == [False, True]  # C1, C4
    ax = figure.axes[5]  # panel (f)
    open_points = [
        line
        for line in ax.get_lines()
        if line.get_markerfacecolor() == "white" and len(line.get_xdata()) == 1
    ]
    assert [list(line.get_ydata()) for line in open_points] == [[abs(u3["value"][1])]]
    labels = [text.get_text() for text in ax.get_legend().get_texts()]
    assert "not converged (no interval)" in labels


def test_convergence_titles_name_jumps_apart_from_tails(study):
    """A flat curve that a tail carries is not titled as jumping with N."""
    tables, stats, _ = study
    stats = json.loads(json.dumps(stats))
    air, water = stats["cases"][1], stats["cases"][2]
    air["convergence"]["not_converged"] = ["velocity.u3.random"]
    air["convergence"]["reasons"] = {"velocity.u3.random": ["few rows"]}
    water["convergence"]["not_converged"] = ["velocity.u3.rms_normalized"]
    water["convergence"]["reasons"] = {"velocity.u3.rms_normalized": ["jump", "heavy tail"]}
    figure, _ = draw_figure("convergence", tables, stats)
    title = " ".join(figure.axes[0].get_title("left").split())
    jumps = title.split("jumps with N:")[1].split(";")[0]
    assert "rms C4" in jumps and "C1" not in jumps
    assert "a tail carries: rms C4 / std C1" in title
