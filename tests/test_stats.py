"""Error statistics against render files with injected errors of known statistics."""

import json

import h5py
import numpy as np
import pytest
from synthetic_render import write_render_file

from rimcl.core.errors import RimclError
from rimcl.stats.document import case_statistics, compute_stats, run_stats
from rimcl.stats.peaks import pdf_peak
from rimcl.stats.render_file import load_render
from rimcl.stats.summaries import error_summary
from rimcl.stats.tables import angle_deg


@pytest.fixture
def render_file(tmp_path):
    path = tmp_path / "c1.h5"
    injected = write_render_file(path)
    return path, injected


def test_relative_errors_have_the_injected_moments(render_file):
    path, injected = render_file
    case = case_statistics(load_render(path))
    for block, symbol, bias, spread in (
        ("velocity", "u", 0.01, 0.05),
        ("acceleration", "a", 0.5, 3.0),
    ):
        for component in ("2", "3"):
            summary = case[block][f"{symbol}{component}"]
            relative = injected[f"{symbol}{component}"]
            assert summary["systematic"] == pytest.approx(bias, rel=1e-12, abs=1e-14)
            assert summary["random"] == pytest.approx(spread, rel=1e-12)
            assert summary["median"] == pytest.approx(np.median(relative), rel=1e-12)
            q25, q75 = np.percentile(relative, [25, 75])
            assert summary["iqr"] == pytest.approx(q75 - q25, rel=1e-12)
            assert summary["n"] == 400
        baseline = case["baseline"][block][f"{symbol}3"]
        assert baseline["systematic"] == pytest.approx(0.01, rel=1e-12)
        assert baseline["random"] < 1e-13
        assert baseline["rms_normalized"] == pytest.approx(0.01, rel=1e-12)


def test_rms_normalized_is_rms_error_over_rms_truth(render_file):
    path, injected = render_file
    tables = load_render(path)
    truth = tables.velocity["u3_true"]
    error = injected["u3"] * truth
    expected = np.sqrt(np.mean(error**2) / np.mean(truth**2))
    case = case_statistics(tables)
    assert case["velocity"]["u3"]["rms_normalized"] == pytest.approx(expected, rel=1e-12)


def test_position_error_peak_near_the_injected_mode_and_scales_exactly(tmp_path):
    peaks = []
    for scale in (1e-4, 1e-3):
        path = tmp_path / f"{scale}.h5"
        write_render_file(path, position_error_over_length=scale)
        peaks.append(case_statistics(load_render(path))["position_error_peak_over_L"])
    # log10(|ε|/L) is normal about log10(1e-4) with std 0.3 and 1200 samples
    assert abs(np.log10(peaks[0]) + 4.0) < 0.1
    # same random draws scaled by 10: the estimator is scale-equivariant
    assert peaks[1] / peaks[0] == pytest.approx(10.0, rel=1e-9)


def test_pdf_peak_of_a_normal_sample_and_of_a_constant():
    rng = np.random.default_rng(5)
    assert abs(pdf_peak(3.0 + rng.standard_normal(20000)) - 3.0) < 0.05
    assert pdf_peak(np.full(7, 0.25)) == 0.25
    assert pdf_peak(np.zeros(5), log=True) == 0.0


def test_flagged_tracers_are_counted_per_flag_and_left_out(tmp_path):
    path = tmp_path / "flagged.h5"
    write_render_file(path, flagged={3: 1, 7: 2 | 4, 11: 4})
    case = case_statistics(load_render(path))
    assert case["n_tracers"] == 400
    assert case["n_used"] == 397
    assert case["n_excluded"] == {
        "below_threshold": 1,
        "split": 1,
        "window_edge": 2,
        "rays_failed": 0,
        "saturated": 0,
    }
    assert case["velocity"]["u2"]["n"] == 397
    # the flagged rows hold NaN: any leak would make these non-finite
    assert np.isfinite(case["velocity"]["u2"]["random"])
    assert np.isfinite(case["position_error_peak_over_L"])


def test_notes_are_counted_and_the_tracers_kept(tmp_path):
    path = tmp_path / "noted.h5"
    write_render_file(path, flagged={4: 2}, noted={4: 128, 5: 128, 6: 16 | 128})
    case = case_statistics(load_render(path))
    assert case["n_noted"] == {"saturated": 3, "rays_failed": 1}
    assert case["n_used_noted"] == 2
    assert case["n_used"] == 399
    assert case["velocity"]["u3"]["n"] == 399


def test_unknown_flag_bits_are_named_not_dropped(tmp_path):
    path = tmp_path / "odd.h5"
    write_render_file(path, flagged={2: 8})
    case = case_statistics(load_render(path))
    assert case["n_excluded"]["bit8"] == 1
    assert case["n_used"] == 399


def test_uniform_medium_gives_exactly_zero_errors(tmp_path):
    path = tmp_path / "uniform.h5"
    write_render_file(
        path,
        case="G=0",
        k_rho=0.0,
        position_error_over_length=0.0,
        velocity_bias=0.0,
        velocity_spread=0.0,
        acceleration_bias=0.0,
        acceleration_spread=0.0,
    )
    case = case_statistics(load_render(path))
    assert case["position_error_peak_over_L"] == 0.0
    assert case["position_error_median_over_L"] == 0.0
    for block in ("velocity", "acceleration"):
        for summary in (case[block][k] for k in case[block] if k != "angle_deg_median"):
            assert summary["systematic"] == 0.0
            assert summary["random"] == 0.0
            assert summary["rms_normalized"] == 0.0
        assert case[block]["angle_deg_median"] == 0.0
    assert case["area_change_peak"] == 0.0
    assert case["not_resolved"] is None  # a uniform medium really gives 0


def test_unresolved_refraction_is_n_a_not_zero(tmp_path):
    """An index that varies but moves no measured image (every image equals its reference)
    was not resolved: the case says so, and the command line prints n/a, not 0."""
    from click.testing import CliRunner

    from rimcl.cli.main import cli

    path = tmp_path / "locked.h5"
    write_render_file(path, position_error_over_length=0.0)
    case = case_statistics(load_render(path))
    assert case["delta_n_max"] > 0 and case["position_error_peak_over_L"] == 0.0
    assert "below what this camera and renderer resolve" in case["not_resolved"]
    moved = tmp_path / "moved.h5"
    write_render_file(moved)
    assert case_statistics(load_render(moved))["not_resolved"] is None
    result = CliRunner().invoke(
        cli, ["stats", str(path), "-o", str(tmp_path / "s"), "--no-figures"]
    )
    assert result.exit_code == 0, result.output
    line = next(line for line in result.output.splitlines() if "C1" in line and "tracers" in line)
    assert "errors n/a" in line and "peak 0" not in line


def test_angle_between_vectors():
    first = (np.array([1.0, 1.0, 1.0, 0.3, 2.0]), np.array([0.0, 0.0, 0.0, 0.7, -1.0]))
    second = (np.array([0.0, 1.0, -1.0, 0.3, 2.0]), np.array([1.0, 1.0, 0.0, 0.7, -1.0]))
    np.testing.assert_allclose(angle_deg(first, second)[:3], [90.0, 45.0, 180.0], rtol=1e-14)
    assert np.all(angle_deg(first, second)[3:] == 0.0)


def test_error_summary_leaves_out_zero_truth_and_small_samples():
    summary = error_summary([1.0, 2.0, 5.0], [2.0, 0.0, 10.0])
    assert summary["n"] == 2
    assert summary["systematic"] == pytest.approx(0.5)
    assert summary["random"] == 0.0
    single = error_summary([1.0], [4.0])
    assert single["systematic"] == 0.25
    assert single["random"] is None


def test_stats_document_sorted_by_g_with_provenance(tmp_path):
    water, air = tmp_path / "w.h5", tmp_path / "a.h5"
    write_render_file(water, case="C4", k_rho=0.334)
    write_render_file(air, case="C1", k_rho=2.82e-4)
    stats = compute_stats([load_render(water), load_render(air)])
    assert [c["name"] for c in stats["cases"]] == ["C1", "C4"]
    assert stats["cases"][1]["delta_n_max"] == pytest.approx(0.085 * 0.334)
    assert [i["case"] for i in stats["config"]["inputs"]] == ["C1", "C4"]
    assert stats["config"]["inputs"][0]["config"]["case"] == "C1"
    assert "numpy" in stats["versions"]
    rays = stats["cases"][0]["rays"]
    assert rays["status_counts"] == {"ok": 1200 * 1024, "exit_side": 0}
    assert rays["reference_status_counts"] == {"ok": 1200 * 1024}


def test_run_stats_without_figures_writes_strict_json(tmp_path):
    path = tmp_path / "c1.h5"
    write_render_file(path)
    out = tmp_path / "out"
    run_stats([path], out, figures=False)
    stats = json.loads((out / "stats.json").read_text())
    assert stats["cases"][0]["name"] == "C1"
    with pytest.raises(RimclError, match="exists"):
        run_stats([path], out, figures=False)
    assert json.loads((out / "stats.json").read_text()) == stats


def test_two_files_of_one_case_are_refused(tmp_path):
    first, second = tmp_path / "1.h5", tmp_path / "2.h5"
    write_render_file(first)
    write_render_file(second, seed=1)
    with pytest.raises(RimclError, match="more than one render file for case C1"):
        compute_stats([load_render(first), load_render(second)])


@pytest.mark.parametrize(
    ("damage", "message"),
    [
        (lambda h5: h5.attrs.__setitem__("rimcl_schema", "field"), "not a rimcl render file"),
        (lambda h5: h5.attrs.__setitem__("schema_version", 7), "schema version 7"),
        (lambda h5: h5.__delitem__("velocity/u3_meas"), "lacks datasets u3_meas"),
        (lambda h5: h5.__delitem__("acceleration"), "group 'acceleration' is missing"),
        (lambda h5: h5.attrs.__delitem__("length_L"), "length_L"),
        (lambda h5: h5.attrs.__setitem__("flag_names", "{"), "not JSON"),
    ],
)
def test_damaged_render_files_get_one_clear_error(tmp_path, damage, message):
    path = tmp_path / "bad.h5"
    write_render_file(path, n_tracers=10)
    with h5py.File(path, "a") as h5:
        damage(h5)
    with pytest.raises(RimclError, match=message):
        load_render(path)


def test_missing_and_non_hdf5_inputs(tmp_path):
    with pytest.raises(RimclError, match="no such file"):
        load_render(tmp_path / "absent.h5")
    text = tmp_path / "text.h5"
    text.write_text("not hdf5")
    with pytest.raises(RimclError, match="not a readable HDF5 file"):
        load_render(text)


def test_the_command_line_marks_an_rms_that_has_not_converged(tmp_path, capsys):
    """The printed rms of a case whose tail carries it reads † with why, and the median and
    IQR of ε/truth beside it; an rms that converged reads plain."""
    from rimcl.cli.stats import echo_case_lines
    from rimcl.study.summary_format import percent

    path = tmp_path / "c4.h5"
    write_render_file(path, case="C4", k_rho=0.334, n_tracers=40)
    case = case_statistics(load_render(path))
    case["convergence"]["not_converged"] = ["velocity.u3.rms_normalized"]
    case["convergence"]["reasons"] = {"velocity.u3.rms_normalized": ["few tracers", "heavy tail"]}
    u3 = case["velocity"]["u3"]
    echo_case_lines({"cases": [case]})
    line = capsys.readouterr().out
    assert (
        f"† not converged (few tracers, heavy tail); median ε/u3 {percent(u3['median'])}, "
        f"IQR {percent(u3['iqr'])}"
    ) in line
    case["convergence"]["not_converged"] = []
    echo_case_lines({"cases": [case]})
    assert "†" not in capsys.readouterr().out
