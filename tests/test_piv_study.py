"""PIV in the study (run.mode, [piv]): case files, resuming, stats.json, summary, CLI."""

import json

import h5py
import numpy as np
import pytest
from click.testing import CliRunner

from rimcl.cli.main import cli
from rimcl.core.errors import RimclError
from rimcl.piv.study import STUDY_RECORD, configs_from_study, study_case_path
from rimcl.scene.load import load_scene
from rimcl.scene.study_config import StudyConfig
from rimcl.study.run import run_study

#: two cases on the sample: a handful of PTV tracers, 64 px PIV frames of 4 rays per tracer
TINY = {
    "cases.names": ["C0", "C4"],
    "tracers.count": 8,
    "camera.fan": 4,
    "piv.pixels": 64,
    "piv.rays": 4,
    "piv.window": 16,
    # noiseless frames: the refraction comparisons below would otherwise meet C0's noise floor
    "sensor.noise": False,
}


def tiny_scene(device, **overrides):
    return load_scene(None, {**TINY, "run.device": device.name, **overrides})


@pytest.fixture(scope="module")
def both(device, tmp_path_factory):
    out = tmp_path_factory.mktemp("study_both")
    lines = []
    result = run_study(
        tiny_scene(device, **{"run.mode": "both"}), out, figures=False, report=lines.append
    )
    return out, result, lines


def test_scene_keys_make_the_piv_configuration(device):
    scene = tiny_scene(device, **{"piv.dt": 0.06, "camera.kind": "pupil", "tracers.seed": 3})
    piv, configs = configs_from_study(StudyConfig.from_scene(scene))
    assert piv.imaging.pixels == 64 and piv.settings.window == 16 and piv.dt == 0.06
    assert piv.seed == 3 and piv.start_frame == 0
    assert configs["camera"].kind == "pupil" and configs["camera"].pupil_rays == 4
    plane = StudyConfig.from_scene(tiny_scene(device))
    assert configs_from_study(plane)[1]["camera"].fan == 2  # plane: √4 per side
    with pytest.raises(RimclError, match=r"run\.mode .* must be one of ptv, piv, both"):
        tiny_scene(device, **{"run.mode": "pvi"})
    with pytest.raises(RimclError, match=r"unknown key piv\.windows"):
        load_scene(None, {"piv.windows": 16})


def test_both_writes_piv_cases_beside_ptv(both):
    out, result, lines = both
    cases = {case["name"]: case for case in result.stats["cases"]}
    assert set(cases) == {"C0", "C4"}
    for name, case in cases.items():
        assert study_case_path(out, name).exists()
        # the PTV entry and the PIV one side by side, in the same summary shapes
        assert set(case["piv"]["velocity"]["u3"]) == set(case["velocity"]["u3"])
        compared = case["piv_vs_ptv"]["magnitude"]
        assert (
            compared["piv_rms_normalized"] == case["piv"]["velocity"]["magnitude"]["rms_normalized"]
        )
        assert compared["ptv_rms_normalized"] == case["velocity"]["magnitude"]["rms_normalized"]
        assert (
            compared["ptv_optics_rms_normalized"]
            == (case["optics"]["velocity"]["magnitude"]["rms_normalized"])
        )
    # refraction grows with G: C4 bends the vectors far more than C0
    c0, c4 = (cases[name]["piv"]["displacement_px"]["refraction_rms"] for name in ("C0", "C4"))
    assert c4 > 100 * c0 > 0
    assert "in-plane only" in cases["C0"]["piv"]["motion"]
    summary = (out / "summary.md").read_text()
    assert "## PIV beside PTV" in summary and "**Verdict:** PIV and PTV errors" in summary
    assert "out-of-plane motion and the loss of pairs it causes are NOT modelled" in summary
    stats = json.loads((out / "stats.json").read_text())
    assert stats["cases"][1]["piv"]["name"] == "C4"
    assert any("[PIV 2/2] C4: done" in line for line in lines)


def test_rerun_keeps_current_piv_cases_and_redoes_foreign_ones(both, device):
    out, _, _ = both
    kept = study_case_path(out, "C0")
    stamp = kept.stat().st_mtime_ns
    foreign = study_case_path(out, "C4")
    with h5py.File(foreign, "a") as h5:
        h5.attrs[STUDY_RECORD] = json.dumps({"another": "scene"})
    lines = []
    run_study(tiny_scene(device, **{"run.mode": "both"}), out, figures=False, report=lines.append)
    assert kept.stat().st_mtime_ns == stamp
    assert any("[PIV 1/2] C0: finished earlier, kept" in line for line in lines)
    assert "[PIV 2/2] C4: C4.h5 made for another scene; imaging and correlating again" in lines
    # PTV cases are kept too: switching the mode is not another scene
    assert any("C0: finished earlier, kept" in line and "PIV" not in line for line in lines)


def test_cli_piv_mode_only(device, tmp_path):
    scene_file = tmp_path / "scene.toml"
    # the plane camera: piv.pixels sets its frame (the default lens would image 2048² px)
    scene_file.write_text(
        '[camera]\nkind = "plane"\n'
        "[piv]\npixels = 64\nrays = 4\nwindow = 16\n[tracers]\ncount = 8\n"
    )
    out = tmp_path / "study"
    args = ["study", str(scene_file), "--mode", "piv", "--cases", "C1", "-o", str(out)]
    result = CliRunner().invoke(cli, [*args, "--no-figures", "--device", device.name])
    assert result.exit_code == 0, result.output
    assert "PIV C1" in result.output and "refraction" in result.output
    assert not (out / "cases" / "C1.h5").exists() and study_case_path(out, "C1").exists()
    stats = json.loads((out / "stats.json").read_text())
    assert set(stats["cases"][0]) == {"name", "G", "delta_n_max", "piv"}
    assert "No PTV case to compare with" in (out / "summary.md").read_text()


def test_verdict_names_the_cases_that_agree_and_those_that_differ():
    from rimcl.study.summary_piv import piv_verdict

    def case(name, ratio, optics):
        both = {"ratio_rms_normalized": ratio, "optics_ratio_rms_normalized": optics}
        return {"name": name, "piv_vs_ptv": {"magnitude": both}}

    stats = {"cases": [case("C1", 1.5, 1.2), case("C3", 3.0, 0.6), case("C4", 0.25, 0.5)]}
    line = piv_verdict(stats)
    assert "errors (PIV/PTV of rms(ε_|u|)/rms(|u|)) **agree** within a factor 2 in C1 (1.5)" in line
    assert "**differ** in C3 (3.0), C4 (0.25)" in line
    assert "optics parts (rays only) **agree** within a factor 2 in every case" in line
    assert piv_verdict({"cases": [{"name": "C1"}]}).startswith("No PTV case")


def test_window_blocks_group_the_vectors_one_window_spans():
    from rimcl.piv.study import window_blocks

    ids, k = window_blocks((5, 7), 0.5)
    assert k == 2 and ids.shape == (5, 7)
    assert ids[0, 0] == ids[1, 1] == ids[0, 1] and ids[0, 0] != ids[0, 2] != ids[2, 2]
    assert len(np.unique(ids)) == 3 * 4
    assert (
        window_blocks((4, 4), 0.0)[1] == 1 and len(np.unique(window_blocks((4, 4), 0.0)[0])) == 16
    )
    assert window_blocks((4, 4), 0.75)[1] == 4


def test_vectors_of_overlapping_windows_are_resampled_together():
    """Errors shared by the 2 x 2 vectors of each block (as overlapping windows share
    pixels): resampling vectors one by one would make the interval half as wide."""
    from rimcl.piv.study import vector_errors, window_blocks

    rng = np.random.default_rng(3)
    ids, _ = window_blocks((40, 40), 0.5)
    block_error = rng.normal(size=ids.max() + 1)
    error = block_error[ids].ravel() + 1e-3 * rng.normal(size=ids.size)
    table = {
        "u2_true": np.ones(ids.size),
        "u3_true": np.ones(ids.size),
        "u2_meas": 1 + error,
        "u3_meas": 1 + error,
        "u2_ref": np.ones(ids.size),
        "u3_ref": np.ones(ids.size),
    }
    width = {}
    for name, groups in (("blocks", ids.ravel()), ("vectors", None)):
        low, high = vector_errors(table, "meas", "ref", groups)["u2"]["ci95"]["systematic"]
        width[name] = high - low
    assert 1.7 < width["blocks"] / width["vectors"] < 2.4


def test_a_kept_piv_file_of_another_case_is_measured_again(both, device):
    out, _, _ = both
    misplaced = study_case_path(out, "C4")
    misplaced.write_bytes(study_case_path(out, "C0").read_bytes())  # C0's numbers under C4
    lines = []
    run_study(tiny_scene(device, **{"run.mode": "both"}), out, figures=False, report=lines.append)
    assert "[PIV 2/2] C4: C4.h5 holds case 'C0', not 'C4'; imaging and correlating again" in lines
    with h5py.File(misplaced) as h5:
        assert h5.attrs["case"] == "C4"


@pytest.mark.parametrize(
    "keys, message",
    [
        ({"piv.window": 31}, "even number of pixels"),
        ({"piv.pixels": 24, "piv.window": 32}, "does not fit"),
        ({"run.scheduler": "local:0"}, "local:N with N >= 1"),
    ],
)
def test_a_failed_piv_study_leaves_nothing_that_refuses_the_corrected_rerun(
    device, tmp_path, keys, message
):
    out = tmp_path / "study"
    with pytest.raises(RimclError, match=message):
        run_study(tiny_scene(device, **{"run.mode": "piv", **keys}), out, figures=False)
    assert not (out / "scene.toml").exists()


def test_a_lens_is_focused_in_each_cases_index_with_a_reference_of_its_own(device):
    """PIV through the lens camera: each case's lens is focused (and its uniform pair
    traced) in that case's mean index, as PTV's; a reference made for another index is
    not reused, the case's own is."""
    from rimcl.piv.study import run_piv_case

    scene = tiny_scene(
        device,
        **{
            "camera.kind": "lens",
            # a small sensor and few tracers: each is aimed through the field (many traces),
            # and which reference a case takes does not depend on how many there are
            "camera.sensor_pixels": [64, 64],
            "camera.magnification": 0.01,
            "piv.density": 0.01,
        },
    )
    piv, configs = configs_from_study(StudyConfig.from_scene(scene))
    c0 = run_piv_case(case="C0", piv=piv, reference=[], **configs)
    c4 = run_piv_case(case="C4", piv=piv, reference=[c0.reference], **configs)
    index = {
        name: case.render.reference.key["camera"]["fluid_index"]
        for name, case in (("C0", c0), ("C4", c4))
    }
    # the shipped sample's n = 1 + G ρ: C0 is air-like, C4 water-like
    assert index["C0"] == pytest.approx(1.0, abs=1e-4)
    assert index["C4"] == pytest.approx(1.35, abs=0.01)
    assert c4.reference is not c0.reference
    again = run_piv_case(case="C4", piv=piv, reference=[c0.reference, c4.reference], **configs)
    assert again.reference is c4.reference
    np.testing.assert_array_equal(again.vectors["dx_field"], c4.vectors["dx_field"])


def test_the_summary_sets_ptv_and_piv_settings_side_by_side(both):
    """The tiny study's PIV frames differ from its PTV images in Δt, pixel and rays: the
    summary says so beside the verdict, with both values of each."""
    out, result, _ = both
    settings = result.stats["cases"][0]["piv_vs_ptv"]["settings"]
    assert settings["ptv"]["dt"] == result.stats["cases"][0]["dt"]
    assert settings["piv"]["dt"] == pytest.approx(0.1)
    assert settings["ptv"]["rays_per_tracer"] == 16 and settings["piv"]["rays_per_tracer"] == 4
    assert settings["ptv"]["bit_depth"] == 12 and settings["piv"]["bit_depth"] == 16
    assert settings["differ"] == ["dt", "pixel_size_over_L", "rays_per_tracer", "bit_depth"]
    assert not settings["like_for_like"]
    summary = (out / "summary.md").read_text()
    assert "| rays per tracer | 16 | 4 |" in summary
    assert "**Not like for like**: PTV and PIV differ in Δt, pixel on the sheet / L, rays" in (
        summary
    )


def test_like_for_like_settings_are_named_so(device):
    """The same Δt, camera, pixel, rays and bits: like for like."""
    from rimcl.piv.comparison import side_by_side

    scene = tiny_scene(
        device,
        **{"piv.dt": 0.02, "piv.rays": 16, "piv.bit_depth": 12, "renderer.pixels": 64},
    )
    study = StudyConfig.from_scene(scene)
    pixel = 1 / 64
    ptv_case = {"dt": 0.02, "pixel_size_over_L": pixel}
    settings = side_by_side(study, ptv_case, {"dt": 0.02, "pixel_size_over_L": pixel})
    assert settings["like_for_like"] and settings["differ"] == []
    assert settings["ptv"] == settings["piv"]
    longer = side_by_side(study, ptv_case, {"dt": 0.1, "pixel_size_over_L": pixel})
    assert longer["differ"] == ["dt"]


def test_piv_uniform_medium_has_no_refraction_and_a_noise_floor(device):
    """A noisy camera through a uniform medium: the pair through the "field" shares its noise
    draws with the uniform pair (common random numbers), so every refraction vector is
    exactly 0; the noise floor, a second uniform pair with other draws, is not."""
    from rimcl.piv.study import run_piv_case

    scene = tiny_scene(device, **{"sensor.noise": True, "cases.names": ["G=0"]})
    piv, configs = configs_from_study(StudyConfig.from_scene(scene))
    case = run_piv_case(case="G=0", piv=piv, reference=[], **configs)
    vectors, stats = case.vectors, case.stats
    used = vectors["used"]
    assert used.any()
    np.testing.assert_array_equal(vectors["dx_field"][used], vectors["dx_uniform"][used])
    assert stats["velocity"]["u3"]["rms_normalized"] == 0
    assert stats["displacement_px"]["refraction_rms"] == 0
    both = used & vectors["valid_floor"]
    floor = np.hypot(
        vectors["dx_floor"] - vectors["dx_uniform"], vectors["dy_floor"] - vectors["dy_uniform"]
    )[both]
    assert stats["displacement_px"]["noise_floor_rms"] == pytest.approx(
        np.sqrt(np.mean(floor**2)), rel=1e-12
    )
    assert stats["displacement_px"]["noise_floor_rms"] > 0
    assert stats["noise_floor"]["velocity"]["u3"]["rms_normalized"] > 0
