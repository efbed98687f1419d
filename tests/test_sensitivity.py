"""Sensitivity bands: headline numbers under other settings, and their verdicts."""

import h5py
import numpy as np
import pytest
from synthetic_render import write_render_file

from rimcl.stats.document import case_statistics
from rimcl.stats.render_file import load_render
from rimcl.stats.sensitivity import (
    EXCLUDED_BY_OPTICS,
    MEASURED_VARIANTS,
    bands,
    headline_values,
)
from rimcl.study.sensitivity import VARIANTS, variant_scene


def test_excluded_tracers_count_with_their_optics_error(tmp_path):
    path = tmp_path / "c4.h5"
    flagged = {3: 1, 7: 1}
    write_render_file(path, case="C4", k_rho=0.334, n_tracers=40, flagged=flagged)
    with h5py.File(path, "a") as h5:
        truth = h5["velocity/u3_true"][...]
        error = h5["velocity/u3_meas"][...] - h5["velocity/u3_ref"][...]
        optics = 0.5 * truth  # the excluded tracers' optics error: half their velocity
        for component in ("u2", "u3"):
            h5[f"velocity/{component}_opt_ref"] = np.zeros_like(truth)
            h5[f"velocity/{component}_opt"] = optics
    tables = load_render(path)
    kept = np.setdiff1d(np.arange(40), list(flagged))
    plain = headline_values(tables)["velocity.u3.rms_normalized"]
    assert plain == pytest.approx(np.sqrt(np.sum(error[kept] ** 2) / np.sum(truth[kept] ** 2)))
    counted = headline_values(tables, excluded_by_optics=True)["velocity.u3.rms_normalized"]
    squares = np.sum(error[kept] ** 2) + np.sum(optics[list(flagged)] ** 2)
    assert counted == pytest.approx(np.sqrt(squares / np.sum(truth**2)))
    # no optics columns for the accelerations: nothing to count them by
    assert (
        headline_values(tables, excluded_by_optics=True)["acceleration.a3.rms_normalized"] is None
    )
    case = case_statistics(tables)
    band = case["sensitivity"]["bands"]["velocity.u3.rms_normalized"]
    assert band["value"] == pytest.approx(plain)
    assert band["variants"][EXCLUDED_BY_OPTICS] == pytest.approx(counted)
    assert band["text"].startswith(f"depends on {EXCLUDED_BY_OPTICS} by +")


def test_a_band_reads_stable_inside_the_interval_and_names_the_largest_move():
    case = {"velocity": {"u3": {"rms_normalized": 0.32, "ci95": {"rms_normalized": [0.28, 0.36]}}}}
    path = "velocity.u3.rms_normalized"
    inside = bands(case, {"threshold ×½": {path: 0.30}, "rays ×4": {path: 0.35}})[path]
    # stable only against what ran
    assert inside["stable"] and inside["text"] == "stable against threshold ×½, rays ×4"
    every = {name: {path: 0.33} for name in (EXCLUDED_BY_OPTICS, *MEASURED_VARIANTS)}
    assert bands(case, every)[path]["text"] == "stable"
    # C4's threshold dependence (14.7 / 32.0 / 37.7 %) shows
    moved = bands(case, {"threshold ×½": {path: 0.147}, "threshold ×2": {path: 0.377}})[path]
    assert not moved["stable"]
    assert moved["text"] == "depends on threshold ×½ by -54 %"
    assert bands(case, {})[path]["text"] == "n/a"


def test_variant_scenes_change_one_setting():
    from rimcl.scene.load import load_scene

    scene = load_scene(overrides={"cases.thresholds": {"C4": 80.0}})
    changed = {directory: variant_scene(scene, directory) for _, directory in VARIANTS}
    assert changed["threshold_half"]["renderer"]["threshold"] == scene["renderer"]["threshold"] / 2
    assert changed["threshold_double"]["cases"]["thresholds"] == {"C4": 160.0}
    assert changed["interpolation"]["integrator"]["interp"] == "bspline3"
    assert changed["rays_x4"]["camera"]["pupil_rays"] == 4 * scene["camera"]["pupil_rays"]
    paper = load_scene(preset="paper")
    assert variant_scene(paper, "rays_x4")["camera"]["fan"] == 200


def test_a_study_with_sensitivity_measures_every_variant(device, tmp_path):
    from rimcl.scene.load import load_scene
    from rimcl.study.run import run_study

    overrides = {
        "cases.names": ["C1"],
        "tracers.count": 4,
        "camera.fan": 3,
        "renderer.pixels": 256,
        "time.frames": 3,
        "time.fit_window": 3,
        "run.sensitivity": True,
        "run.device": device.name,
    }
    result = run_study(load_scene(None, overrides), tmp_path, figures=False)
    for _, directory in VARIANTS:
        assert (tmp_path / "sensitivity" / directory / "cases" / "C1.h5").is_file()
    (case,) = result.stats["cases"]
    assert set(case["sensitivity"]["variants"]) == {EXCLUDED_BY_OPTICS, *(n for n, _ in VARIANTS)}
    band = case["sensitivity"]["bands"]["velocity.u3.rms_normalized"]
    assert set(band["relative"]) == set(case["sensitivity"]["variants"])
    assert "Sensitivity to settings" in (tmp_path / "summary.md").read_text()
    # a rerun keeps every variant's file
    again = run_study(load_scene(None, overrides), tmp_path, figures=False)
    assert again.ran == []
