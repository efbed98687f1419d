"""Figures: every file written, labelled axes, and the numbers beside them match stats."""

import io
import json

import numpy as np
import pytest
from PIL import Image
from synthetic_render import write_render_file

from rimcl.figures import FIGURE_NAMES, draw_figure, write_figures
from rimcl.stats import compute_stats, load_render

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
        write_render_file(
            path,
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


def test_every_figure_is_written_with_metadata_and_its_numbers(study):
    tables, stats, folder = study
    out = folder / "out"
    written = write_figures(tables, stats, out)
    assert len(written) == 3 * len(FIGURE_NAMES) >= 18
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
def test_every_panel_has_labelled_axes(study, name):
    tables, stats, _ = study
    figure, _ = draw_figure(name, tables, stats)
    shown = [ax for ax in figure.axes if ax.axison and ax.get_label() != "<colorbar>"]
    assert shown
    for ax in shown:
        assert ax.get_xlabel().strip()
        assert ax.get_ylabel().strip()


def test_position_figure_numbers_are_the_stats_numbers(study):
    tables, stats, _ = study
    _, data = draw_figure("position_error", tables, stats)
    peaks = data["panels"]["b"]
    positive = [case for case in stats["cases"] if case["G"] > 0]
    assert peaks["G"] == [case["G"] for case in positive]
    assert peaks["peak_over_L"] == [case["position_error_peak_over_L"] for case in positive]
    zero_case = data["panels"]["a"]["series"][0]
    assert zero_case["x_over_L"] == [] and zero_case["n_zero"] == zero_case["n"] == 357


def test_relative_error_histograms_are_normalised_pdfs(study):
    tables, stats, _ = study
    _, data = draw_figure("velocity_error", tables, stats)
    panel = data["panels"]["a"]
    widths = np.diff(panel["bin_edges"])
    zero_case, air, water = panel["series"]
    assert zero_case["exactly_zero"] and zero_case["pdf"] == []
    for series in (air, water):
        assert np.sum(np.asarray(series["pdf"]) * widths) == pytest.approx(1.0, rel=1e-12)
    random_panel = data["panels"]["e"]
    u3 = next(s for s in random_panel if s["label"] == "u3")
    assert u3["abs_value"] == [case["velocity"]["u3"]["random"] for case in stats["cases"][1:]]


def test_a_uniform_medium_alone_draws_every_figure(study):
    tables, _, _ = study
    uniform = [tables[0]]
    stats = compute_stats(uniform)
    for name in FIGURE_NAMES:
        figure, _ = draw_figure(name, uniform, stats)
        figure.savefig(io.BytesIO(), format="png", dpi=30)
        notes = [text.get_text() for ax in figure.axes for text in ax.texts]
        if name in ("position_error", "velocity_error", "error_budget"):
            assert "nothing to show: every value is zero" in notes
