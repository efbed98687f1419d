"""The optics / imaging split of the error, fit tracks of many frames, and partial columns."""

import h5py
import numpy as np
import pytest
from synthetic_budget import write_budget_file
from synthetic_render import write_render_file

from rimcl.core.errors import RimclError
from rimcl.stats.document import budget_verdict, case_statistics
from rimcl.stats.render_file import load_render
from rimcl.stats.summaries import SUMMARY_KEYS


@pytest.fixture(scope="module")
def budget_case(tmp_path_factory):
    path = tmp_path_factory.mktemp("budget") / "c3.h5"
    injected = write_budget_file(path, optics_share=0.25, fit_frames=4, flagged={5: 2})
    return case_statistics(load_render(path)), injected


def scaled(summary, factor):
    return {key: None if summary[key] is None else factor * summary[key] for key in SUMMARY_KEYS}


def test_optics_and_imaging_split_the_total_by_the_injected_shares(budget_case):
    case, _ = budget_case
    for part, share in (("optics", 0.25), ("imaging", 0.75)):
        block = case[part]
        for key in ("position_error_peak_over_L", "position_error_median_over_L"):
            assert block[key] == pytest.approx(share * case[key], rel=1e-9)
            np.testing.assert_allclose(
                block[f"{key}_ci95"], np.multiply(share, case[f"{key}_ci95"]), rtol=1e-9
            )
        for group, components in (("velocity", ("u2", "u3")), ("acceleration", ("a2", "a3"))):
            for component in components:
                total, found = case[group][component], block[group][component]
                for key, value in scaled(total, share).items():
                    assert found[key] == pytest.approx(value, rel=1e-9, abs=1e-15), (part, key)
                for key in SUMMARY_KEYS:
                    np.testing.assert_allclose(
                        found["ci95"][key], np.multiply(share, total["ci95"][key]), rtol=1e-5
                    )
                assert found["n"] == total["n"] == 399


def test_budget_blocks_have_the_keys_of_the_total(budget_case):
    case, _ = budget_case
    position_keys = {key for key in case if key.startswith("position_error_")}
    for part in ("optics", "imaging"):
        # no optics columns in the fit groups of this file: only the kinematic groups that have them
        assert set(case[part]) == position_keys | {"velocity", "acceleration"}
        for group in ("velocity", "acceleration"):
            assert set(case[part][group]) == set(case[group])


def test_verdict_names_the_dominant_part(budget_case):
    case, _ = budget_case
    verdict = case["budget_verdict"]
    assert verdict["dominant"] == "imaging"
    assert verdict["imaging"] == pytest.approx(3 * verdict["optics"], rel=1e-9)
    assert "imaging 3× optics" in verdict["text"] and verdict["text"].startswith("C1:")
    quiet = {**case, "imaging": {"velocity": {"u3": {"rms_normalized": 1e-9}}}}
    quiet["optics"] = {"velocity": {"u3": {"rms_normalized": 2e-9}}}
    quiet["velocity"] = {"u3": {"rms_normalized": 2.2e-9}}
    verdict = budget_verdict(quiet)
    assert verdict["dominant"] == "baseline" and verdict["refraction_over_baseline"] < 1e-3
    assert "below the baseline" in verdict["text"]
    # refraction above the baseline is never said to be dominated by it
    loud = {**quiet, "velocity": {"u3": {"rms_normalized": 2 * verdict["baseline"]}}}
    assert budget_verdict(loud)["dominant"] == "optics"
    assert "above the baseline" in budget_verdict(loud)["text"]


def test_verdict_says_whether_images_change_size(budget_case):
    """The typical image keeping its size (ΔA/A peak 0) does not hide a tenth that grows."""
    case, _ = budget_case
    reshaped = {**case, "area_change_peak": 0.0, "area_change_p90": 0.84}
    assert "images change size (|ΔA/A| 90th percentile 0.84)" in (budget_verdict(reshaped)["text"])
    kept = {**case, "area_change_peak": 0.0, "area_change_p90": 0.001}
    assert "keep their size" in budget_verdict(kept)["text"]
    assert case["area_change_p90"] is not None


def test_fit_groups_have_the_shape_of_the_differences_and_their_errors(budget_case):
    case, injected = budget_case
    for group, symbol in (("velocity_fit", "u"), ("acceleration_fit", "a")):
        assert set(case[group]) == set(case[group.removesuffix("_fit")])
        assert set(case["baseline"][group]) == set(case["baseline"][group.removesuffix("_fit")])
        for component in ("2", "3"):
            summary = case[group][f"{symbol}{component}"]
            assert summary["n"] == 4 * 399  # four frames per tracer, tracer 5 flagged
            kept = np.delete(injected["fit"][f"{symbol}{component}"], np.arange(20, 24))
            assert summary["systematic"] == pytest.approx(np.mean(kept), rel=1e-9)
            assert summary["random"] == pytest.approx(np.std(kept, ddof=1), rel=1e-9)
            baseline = case["baseline"][group][f"{symbol}{component}"]
            assert baseline["rms_normalized"] == pytest.approx(1e-3, rel=1e-9)
    series = case["convergence"]["acceleration_fit"]["a3"]["rms_normalized"]["value"]
    assert series[-1] == case["acceleration_fit"]["a3"]["rms_normalized"]


def test_files_without_the_new_columns_have_no_new_blocks(tmp_path):
    path = tmp_path / "plain.h5"
    write_render_file(path, n_tracers=30)
    case = case_statistics(load_render(path))
    for key in ("optics", "imaging", "velocity_fit", "acceleration_fit"):
        assert key not in case
    assert case["budget_verdict"] is None
    assert set(case["baseline"]) == {"velocity", "acceleration"}


def test_half_a_set_of_optics_columns_is_refused(tmp_path):
    path = tmp_path / "half.h5"
    write_render_file(path, n_tracers=10)
    with h5py.File(path, "a") as h5:
        h5["tracers/x2_opt"] = h5["tracers/x2_meas"][()]
    with pytest.raises(RimclError, match="has x2_opt but lacks x3_opt, x2_opt_ref, x3_opt_ref"):
        load_render(path)
