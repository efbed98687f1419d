"""The Appendix A check's refinement: Richardson's estimate from three resolutions."""

import pytest

from rimcl.ptv.numerics import GRID_RUNS, richardson


def test_richardson_recovers_a_second_order_limit():
    # m(h) = 3 + 5 h², at h = 1, 1/2, 1/4: the limit 3, order 2
    values = [3 + 5 * h**2 for h in (1.0, 0.5, 0.25)]
    step = richardson(values, own=0)  # the study's run is the coarsest step
    assert step["order"] == pytest.approx(2.0)
    assert step["extrapolated"] == pytest.approx(3.0)
    assert step["relative_change"] == pytest.approx(5 / 8)
    # the grid's own run is the finest: what a finer grid would still change
    grid = richardson(values, own=2)
    assert grid["relative_change"] == pytest.approx((5 / 16) / (3 + 5 / 16))


def test_richardson_says_nothing_outside_the_asymptotic_range():
    assert richardson([1.0, 1.2, 1.5], own=2) is None  # the changes grow
    assert richardson([1.0, 1.0, 1.0], own=0) is None  # nothing changes
    assert richardson([None, 1.0, 1.1], own=2) is None
    assert richardson([1.0, 2.0, 0.0], own=2) is None  # no value to compare with


def test_the_numerics_figure_draws_three_steps_and_grids_without_overlap(tmp_path, monkeypatch):
    import numpy as np
    from test_figures import layout_problems

    import rimcl.stats.figures_numerics as figures_numerics

    base = 10 ** np.random.default_rng(0).normal(-4.5, 0.3, 200)
    runs = {}
    for name, scale in (
        ("step h", 1.0),
        ("step h/2", 1.0),
        ("step h/4", 1.0),
        ("grid n/4", 0.8),
        ("grid n/2", 0.9),
    ):
        errors = scale * base
        runs[name] = {
            "step": 0.05,
            "grid_n3_n2_n1": [64, 64, 64],
            "errors_over_L": errors.tolist(),
            "median_over_L": float(np.median(errors)),
            "optics_errors_over_L": errors.tolist(),
            "optics_median_over_L": float(np.median(errors)),
        }
    runs["grid n"] = runs["step h"]
    numerics = {
        "case": "C1",
        "runs": runs,
        "step_richardson": None,
        "grid_richardson": richardson([runs[n]["median_over_L"] for n in GRID_RUNS], 2),
    }
    drawn = []
    monkeypatch.setattr(
        figures_numerics, "save_figure", lambda figure, *args: drawn.append(figure) or []
    )
    figures_numerics.write_numerics_figure(numerics, tmp_path, {})
    (figure,) = drawn
    titles = [ax.get_title(loc="left") for ax in figure.axes]
    assert "median unchanged" in titles[0]  # the three steps gave one median
    assert "a finer grid (Richardson) would move the" in titles[1]
    assert layout_problems(figure) == []
