"""Sensitivity bands: headline numbers under other settings, and their verdicts."""

import h5py
import numpy as np
import pytest
from synthetic_render import write_render_file

from rimcl.stats.document import case_statistics
from rimcl.stats.render_file import load_render
from rimcl.stats.sensitivity import (
    EXCLUDED_BY_OPTICS,
    FILE_VARIANTS,
    MEASURED_VARIANTS,
    THRESHOLD_NAMES,
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


def test_excluded_tracers_without_an_optics_image_are_not_counted_as_used(tmp_path):
    """A tracer with no ray in any frame has no optics position (NaN): the variant that
    counts the excluded tracers by their optics error uses the others only."""
    path = tmp_path / "c4.h5"
    write_render_file(path, case="C4", k_rho=0.334, n_tracers=40, flagged={3: 1, 7: 1, 9: 1})
    with h5py.File(path, "a") as h5:
        ids = h5["tracers/id"][...]
        for c in ("2", "3"):
            h5[f"tracers/x{c}_opt_ref"] = h5[f"tracers/x{c}_ref"][...]
            optics = h5[f"tracers/x{c}_meas"][...].copy()
            optics[ids == 7] = np.nan  # no ray in any frame
            h5[f"tracers/x{c}_opt"] = optics
    tables = load_render(path)
    assert headline_values(tables)["n_used"] == 37
    assert headline_values(tables, excluded_by_optics=True)["n_used"] == 39


def test_a_band_reads_stable_inside_the_interval_and_names_the_largest_move():
    case = {"velocity": {"u3": {"rms_normalized": 0.32, "ci95": {"rms_normalized": [0.28, 0.36]}}}}
    path = "velocity.u3.rms_normalized"
    inside = bands(case, {"threshold ×½": {path: 0.30}, "rays ×4": {path: 0.35}})[path]
    # stable against what ran; the measured variants that did not run are named in the
    # verdict: inside the interval, stable, with the largest move beside it
    assert inside["stable"]
    assert inside["text"] == "stable (rays ×4: +9 %); not run: the other interpolation"
    assert inside["not_run"] == ["the other interpolation"]
    every = {name: {path: 0.32} for name in (*FILE_VARIANTS, *MEASURED_VARIANTS)}
    assert bands(case, every)[path]["text"] == "stable"
    assert bands(case, every)[path]["not_run"] == []
    # C4's threshold dependence (14.7 / 32.0 / 37.7 %) shows
    moved = bands(case, {"threshold ×½": {path: 0.147}, "threshold ×2": {path: 0.377}})[path]
    assert not moved["stable"]
    assert moved["text"] == "depends on threshold ×½ by -54 %"
    assert bands(case, {})[path]["text"] == "n/a"


def test_a_variant_that_keeps_no_tracer_is_never_stable():
    """A threshold that loses every tracer has no number: the band says so instead of
    reading stable over the variants that kept some."""
    case = {"velocity": {"u3": {"rms_normalized": 0.32, "ci95": {"rms_normalized": [0.1, 0.9]}}}}
    path = "velocity.u3.rms_normalized"
    variants = {
        "threshold ×½": {path: 0.31, "n_used": 40},
        "threshold ×2": {path: None, "n_used": 0},
    }
    band = bands(case, variants, measured=())[path]
    assert band["stable"] is False
    assert band["text"] == "depends on threshold ×2: it keeps no tracer"


def test_variant_scenes_change_one_setting():
    from rimcl.scene.load import load_scene

    scene = load_scene(overrides={"cases.thresholds": {"C4": 80.0}})
    changed = {directory: variant_scene(scene, directory) for _, directory in VARIANTS}
    assert set(changed) == {"interpolation", "rays_x4"}  # the thresholds need no measurement
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
    assert set(case["sensitivity"]["variants"]) == {*FILE_VARIANTS, *(n for n, _ in VARIANTS)}
    band = case["sensitivity"]["bands"]["velocity.u3.rms_normalized"]
    assert set(band["relative"]) == set(case["sensitivity"]["variants"])
    assert "Sensitivity to settings" in (tmp_path / "summary.md").read_text()
    # a rerun keeps every variant's file
    again = run_study(load_scene(None, overrides), tmp_path, figures=False)
    assert again.ran == []


def _with_threshold_columns(path, moved_ids, factor):
    """Add the threshold variants' columns to a synthetic render file: at ×½ the same
    positions as at ×1; at ×2 the tracers ``moved_ids`` have ``factor`` times their
    measured velocity error and tracer 0 is lost (below the threshold)."""
    with h5py.File(path, "a") as h5:
        for group, symbol in (("tracers", "x"), ("velocity", "u"), ("acceleration", "a")):
            table = h5[group]
            ids = table["id"][...]
            for suffix in THRESHOLD_NAMES.values():
                for c in (2, 3):
                    ref, meas = table[f"{symbol}{c}_ref"][...], table[f"{symbol}{c}_meas"][...]
                    if suffix == "threshold_double" and symbol == "u":
                        moved = np.isin(ids, moved_ids)
                        meas = np.where(moved, ref + factor * (meas - ref), meas)
                    table[f"{symbol}{c}_ref_{suffix}"] = ref
                    table[f"{symbol}{c}_meas_{suffix}"] = meas
                lost = (ids == 0) * (1 if suffix == "threshold_double" else 0)
                table[f"flags_{suffix}"] = table["flags"][...] | lost


def test_every_case_carries_its_threshold_band_from_its_own_file(tmp_path):
    """The threshold ×½ and ×2 come from the file's own columns: the same numbers where the
    positions are the same, 'depends on threshold ×2' where its errors grow, and the
    tracers each threshold keeps."""
    path = tmp_path / "c4.h5"
    write_render_file(path, case="C4", k_rho=0.334, n_tracers=60)
    _with_threshold_columns(path, moved_ids=np.arange(30), factor=3.0)
    tables = load_render(path)
    case = case_statistics(tables)
    variants = case["sensitivity"]["variants"]
    assert set(variants) == set(FILE_VARIANTS)
    assert variants["threshold ×½"]["n_used"] == 60 and variants["threshold ×2"]["n_used"] == 59
    u3 = "velocity.u3.rms_normalized"
    # ×½: the positions of ×1, the same numbers
    for path_, value in headline_values(tables).items():
        assert variants["threshold ×½"][path_] == pytest.approx(value)
    # ×2: tracers 1..29 carry 3 times their error (tracer 0 left out): the known ratio
    velocity = tables.velocity
    keep = velocity["id"] != 0
    error = velocity["u3_meas"][keep] - velocity["u3_ref"][keep]
    error = np.where(velocity["id"][keep] < 30, 3.0 * error, error)
    expected = np.sqrt(np.sum(error**2) / np.sum(velocity["u3_true"][keep] ** 2))
    assert variants["threshold ×2"][u3] == pytest.approx(expected)
    band = case["sensitivity"]["bands"][u3]
    assert band["text"].startswith("depends on threshold ×2 by +")
    # positions did not move at either threshold: stable, over what ran
    assert (
        case["sensitivity"]["bands"]["position_error_median_over_L"]["text"]
        == "stable; not run: the other interpolation, rays ×4"
    )
    assert band["not_run"] == list(MEASURED_VARIANTS)


def test_a_default_study_shows_the_threshold_band_of_every_headline_number(device, tmp_path):
    """A default-style study (the lens camera, noise, Mie) on a tiny scene: every headline
    number of every case has its band from the threshold ×½ and ×2 without --sensitivity,
    and the summary says which variants the band includes."""
    from rimcl.scene.load import load_scene
    from rimcl.study.run import run_study

    overrides = {
        "cases.names": ["C2", "C3"],
        "tracers.count": 12,
        "camera.pupil_rays": 32,
        "time.frames": 5,
        # 400 counts (10 % of the 12-bit full scale): high enough that the doubled
        # threshold loses C3's dim, spread images (through the default f/11 lens)
        "renderer.threshold": 400.0,
        "run.device": device.name,
    }
    result = run_study(load_scene(None, overrides), tmp_path, figures=False)
    assert not (tmp_path / "sensitivity").exists()  # nothing measured again
    for case in result.stats["cases"]:
        assert set(case["sensitivity"]["variants"]) == set(FILE_VARIANTS)
        for band in case["sensitivity"]["bands"].values():
            assert set(band["variants"]) >= set(THRESHOLD_NAMES)
            assert band["text"].startswith(("stable", "depends on "))
    # C3's images are dim and spread: the doubled threshold loses tracers
    c3 = result.stats["cases"][-1]
    assert c3["sensitivity"]["variants"]["threshold ×2"]["n_used"] < c3["n_used"]
    summary = (tmp_path / "summary.md").read_text()
    assert "*threshold ×½*, *threshold ×2*" in summary
    assert "does not include *the other interpolation* and *rays ×4*" in summary
