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
        # never "stable": the band lacks a variant, and says which and why
        assert band["stable"] is None and band["text"] == "n/a: threshold ×½ lost every tracer"
        assert band["tracers_lost"] == ["threshold ×½"]


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


# ---------------------------------------------------------------- n/a, never an accident


def _statistics(run, scene, result):
    """A case's statistics as ``lpt run`` writes them (units, band), checked JSON-able."""
    import json

    from rimcl.lpt.run import FLAG_IMAGE_LOST, case_statistics
    from rimcl.lpt.units import case_units

    stats = case_statistics(run, result, scene)
    stats["units"] = case_units(stats, 1.0, run.length_m, run.time_s)
    kept = (result["flags"] & ~FLAG_IMAGE_LOST) == 0
    stats["sensitivity"] = threshold_sensitivity(run, result, stats, kept, scene)
    json.dumps(stats, allow_nan=False)  # no NaN anywhere
    return stats


def test_a_case_that_kept_no_tracer_is_n_a_with_its_reason(measured):
    """Every image lost (dim cameras, a tiny sensor): every number n/a, the reason named,
    and the statistics still JSON (they were NaN, and writing them crashed)."""
    from rimcl.lpt.run import FLAG_IMAGE_LOST, summary_lines

    run, scene, result, _, _ = measured
    lost = {**result, "flags": np.full_like(result["flags"], FLAG_IMAGE_LOST)}
    stats = _statistics(run, scene, lost)
    assert stats["tracers_kept"] == 0 and stats["excluded"]["image_lost"] == 30
    assert stats["no_tracer"].startswith("no tracer kept of 30 (30 an image was not found")
    for path in HEADLINES:
        assert _lookup(stats, path) is None, path
    document = {"tracers": 30, "times": run.times.tolist(), "length_m": run.length_m,
                "cases": {"C3": {**stats, "rays": result["rays"], "n_ref": 1.33,
                                 "calibration_residual_px": {"a": {"soloff": 0.0}}}}}  # fmt: skip
    text = "\n".join(summary_lines(document))
    assert "n/a: no tracer kept of 30" in text and "nan" not in text.lower()


def test_an_unresolved_shift_is_not_resolved_not_a_measured_zero(measured):
    """Rays that moved but located images that did not: the refraction is not resolved."""
    run, scene, result, _, _ = measured
    same = {**result, "centroid_meas": result["centroid_ref"].copy()}
    assert np.any(result["optics_meas"] != result["optics_ref"])
    stats = _statistics(run, scene, same)
    assert "below what these cameras resolve" in stats["not_resolved"]
    # the case's own images moved: resolved
    assert _statistics(run, scene, result)["not_resolved"] is None


def test_pixels_are_per_camera_and_do_not_depend_on_camera_order(measured):
    """Two cameras of different pixels (at the object): "px" is on their mean, whichever
    camera comes first (it was the first camera's), and per camera beside it."""
    from types import SimpleNamespace

    run, scene, result, _, _ = measured
    pixel = result["cameras"][0].pixel_size
    cameras = [SimpleNamespace(name="a", pixel_size=pixel),
               SimpleNamespace(name="b", pixel_size=2 * pixel)]  # fmt: skip
    stats, other = (
        _statistics(run, scene, {**result, "cameras": order}) for order in (cameras, cameras[::-1])
    )
    assert stats["pixel_size_per_camera"] == {"a": pixel, "b": 2 * pixel}
    assert stats["pixel_size"] == other["pixel_size"] == 1.5 * pixel
    for axis in ("x1", "x2", "x3"):
        block = stats["position"][axis]
        rms = block["refraction"]["rms"]
        assert block["refraction_rms_px"] == other["position"][axis]["refraction_rms_px"]
        assert block["refraction_rms_px"] == rms / (1.5 * pixel)
        assert block["refraction_rms_px_per_camera"] == {"a": rms / pixel, "b": rms / (2 * pixel)}


def test_a_round_off_truth_gives_no_ratio(measured):
    """A uniform flow's true acceleration is 0 up to round-off: no rms(ε)/rms(truth) of it
    (it printed a baseline of 9.5e9), the absolute errors kept."""
    import dataclasses

    run, scene, result, stats, _ = measured
    still = dataclasses.replace(run, a_true=np.full_like(run.a_true, 3e-17))
    guarded = _statistics(still, scene, result)
    for axis in ("x1", "x2", "x3"):
        block = guarded["acceleration"][axis]
        assert block["refraction"]["rms_normalized"] is None
        assert block["baseline"]["rms_normalized"] is None
        assert "0 up to round-off" in block["ratio_na"]
        assert (
            block["absolute"]["refraction"] == stats["acceleration"][axis]["absolute"]["refraction"]
        )
        # the velocity's truth is no round-off: its ratios stand
        assert guarded["velocity"][axis]["refraction"]["rms_normalized"] is not None
        assert "ratio_na" not in guarded["velocity"][axis]


def test_a_variant_that_kept_few_tracers_is_named_with_its_count(measured):
    """A variant that keeps 2 of the case's tracers may still land in the interval: the
    verdict names it with its count (it read "stable (−94 %)" without a word)."""
    from rimcl.imaging.centroid import TracerFlag

    run, scene, result, stats, kept = measured
    few = dict(result)
    flags = np.zeros_like(result["image_flags_meas"])
    flags[..., 2:] = int(TracerFlag.TOUCHES_EDGE)  # every tracer but the first two lost
    few["image_flags_meas_threshold_half"] = flags
    block = threshold_sensitivity(run, few, stats, kept, scene)
    n_used = block["variants"]["threshold ×½"]["n_used"]
    assert 0 < n_used <= 2 < 0.5 * stats["tracers_kept"]
    note = f"threshold ×½ kept {n_used} of {stats['tracers_kept']} tracers"
    for path, band in block["bands"].items():
        assert band["text"].endswith(f"({note})"), path
        assert band["tracers_lost"] == [note]


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
