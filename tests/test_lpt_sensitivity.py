"""LPT threshold band: every headline number again with the images located at each camera's
threshold ×½ and ×2 (same digitised images, same models, same fits), with PTV's verdicts.

- The numbers of the case's own positions equal its statistics (×1 is the main number).
- Variant positions equal to the main ones give the main numbers and "stable".
- Where a variant threshold moves a located image, its numbers move; where it moves none,
  they stay.
- The verdict rule is PTV's: a variant outside the interval "depends on threshold ×2 by Y %".
"""

import numpy as np
import pytest

from rimcl.lpt.sensitivity import HEADLINES, band_lines, headline_values, threshold_sensitivity
from rimcl.stats.sensitivity import THRESHOLD_NAMES, bands


def _lookup(case, path):
    node = case
    for name in path.split("."):
        node = node[name]
    return node


@pytest.fixture(scope="module")
def measured(lpt_flow, tmp_path_factory):
    """C3 through the tiny flow (stereo rig, noiseless sensor, NumPy engine): the run, the
    scene, the case's arrays and its statistics."""
    from rimcl.lpt.config import parse_lpt_scene
    from rimcl.lpt.run import FLAG_IMAGE_LOST, case_statistics, prepare, run_case

    scene = parse_lpt_scene(
        {
            "field": {"path": str(lpt_flow)},
            "tracers": {"count": 30},
            "time": {"frames": 5},
            "sensor": {"noise": False},
            "rig": {"preset": "stereo"},
            "run": {"engine": "numpy"},
            "lpt": {"max_rays": 4, "calibration_grid": [6, 5], "self_calibration": False},
        }
    )
    run = prepare(scene, tmp_path_factory.mktemp("lptband"), {})
    try:
        result = run_case(run, scene, "C3")
    finally:
        run.source.close()
    stats = case_statistics(run, result, scene)
    kept = (result["flags"] & ~FLAG_IMAGE_LOST) == 0
    stats["sensitivity"] = threshold_sensitivity(run, result, stats, kept, scene)
    return run, scene, result, stats, kept


def test_own_positions_give_the_case_statistics(measured):
    run, scene, result, stats, _ = measured
    times = scene.measure.time
    values = headline_values(
        run,
        result["x_meas"],
        result["x_ref"],
        result["flags"] == 0,
        times.fit_window,
        times.fit_order,
    )
    assert values["n_used"] == stats["tracers_kept"] > 0
    for path in HEADLINES:
        assert values[path] == pytest.approx(_lookup(stats, path), rel=1e-12, abs=0), path


def test_every_headline_has_a_band_with_both_thresholds(measured):
    *_, stats, _ = measured
    block = stats["sensitivity"]
    assert set(block["variants"]) == set(THRESHOLD_NAMES)
    assert set(block["bands"]) == set(HEADLINES)
    for path, band in block["bands"].items():
        assert band["value"] == _lookup(stats, path)
        assert set(band["variants"]) == set(THRESHOLD_NAMES), path
        assert band["not_run"] == []
        assert band["text"].startswith(("stable", "depends on threshold")), band["text"]
    lines = band_lines(stats)
    assert len(lines) == 3  # too few tracers to tell a tail: no line of rms ratios it carries
    assert all(line.count("x1 ") == 1 and "n/a" not in line for line in lines)


def test_variants_equal_to_the_main_images_give_the_main_numbers(measured):
    run, scene, result, stats, kept = measured
    same = dict(result)
    for suffix in THRESHOLD_NAMES.values():
        for kind in ("meas", "ref"):
            same[f"x_{kind}_{suffix}"] = result[f"x_{kind}"]
            same[f"image_flags_{kind}_{suffix}"] = result[f"image_flags_{kind}"]
    block = threshold_sensitivity(run, same, stats, kept, scene)
    for path, band in block["bands"].items():
        for value in band["variants"].values():
            assert value == pytest.approx(band["value"], rel=1e-12, abs=0), path
        assert band["text"] == "stable", path


def test_a_threshold_that_moves_images_moves_the_numbers(measured):
    """×½ and ×2 of the threshold take more or less of the images' wings: located centroids
    move, and with them every one of the variant's numbers."""
    _, _, result, stats, _ = measured
    moved = 0
    for name, suffix in THRESHOLD_NAMES.items():
        main, other = result["centroid_meas"], result[f"centroid_meas_{suffix}"]
        both = np.isfinite(main) & np.isfinite(other)
        if not np.any(main[both] != other[both]):
            continue
        moved += 1
        values = stats["sensitivity"]["variants"][name]
        changed = [p for p in HEADLINES if values[p] != _lookup(stats, p)]
        assert len(changed) == len(HEADLINES), (name, changed)
    assert moved == len(THRESHOLD_NAMES)


def test_a_variant_that_loses_every_image_is_left_out_of_the_band(measured):
    """A noisy camera's threshold ×½ can lie below its background (every window one blob):
    that variant counts no tracer and its numbers are n/a, the band holds the other."""
    from rimcl.imaging.centroid import TracerFlag

    run, scene, result, stats, kept = measured
    lost = dict(result)
    lost["image_flags_meas_threshold_half"] = np.full_like(
        result["image_flags_meas"], int(TracerFlag.TOUCHES_EDGE)
    )
    block = threshold_sensitivity(run, lost, stats, kept, scene)
    assert block["variants"]["threshold ×½"] == {**dict.fromkeys(HEADLINES), "n_used": 0}
    for path, band in block["bands"].items():
        assert set(band["variants"]) == {"threshold ×2"}, path
        assert (
            band["variants"]["threshold ×2"]
            == stats["sensitivity"]["bands"][path]["variants"]["threshold ×2"]
        )
        # a variant without a tracer leaves no number stable
        if band["value"]:
            assert band["stable"] is False
            assert band["text"] == "depends on threshold ×½: it keeps no tracer"


def test_verdict_is_the_ptv_rule_on_lpt_paths():
    case = {
        "position": {"x1": {"refraction": {"rms": 2.0, "ci95": [1.8, 2.2]}}},
        "velocity": {
            "x1": {"refraction": {"rms_normalized": 0.1, "ci95": {"rms_normalized": [0.09, 0.11]}}}
        },
    }
    paths = ("position.x1.refraction.rms", "velocity.x1.refraction.rms_normalized")
    variants = {
        "threshold ×½": {paths[0]: 2.1, paths[1]: 0.1},
        "threshold ×2": {paths[0]: 3.0, paths[1]: 0.1},
    }
    result = bands(case, variants, paths, measured=())
    assert result[paths[0]]["ci95"] == [1.8, 2.2]
    assert result[paths[0]]["text"] == "depends on threshold ×2 by +50 %"
    assert result[paths[0]]["stable"] is False
    assert result[paths[1]]["ci95"] == [0.09, 0.11]
    assert result[paths[1]]["text"] == "stable"


def test_rms_ratios_a_tail_carries_are_named():
    """PTV's rule on LPT: an rms ratio whose largest tracers carry Σε² or whose tail is
    heavy is named as no headline; a normal one is not."""
    from rimcl.lpt.sensitivity import tail_lines

    heavy = {"top_share": 0.6, "tail_index": 1.5}
    normal = {"top_share": 0.05, "tail_index": 8.0}
    case = {
        "velocity": {"x1": {"refraction": heavy}, "x2": {"refraction": normal}},
        "acceleration": {"x3": {"refraction": {"top_share": 0.1, "tail_index": 2.0}}},
    }
    (line,) = tail_lines(case)
    assert line.endswith("velocity x1 (few tracers, heavy tail); acceleration x3 (heavy tail)")
    assert tail_lines({"velocity": {"x1": {"refraction": normal}}}) == []
