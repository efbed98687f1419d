"""summary.md: headline statistics with intervals, the paper's labelled, marks, budget, n/a."""

import pytest
from synthetic_budget import write_budget_file
from synthetic_render import write_render_file

from rimcl.scene.load import load_scene
from rimcl.scene.study_config import StudyConfig
from rimcl.stats.document import compute_stats
from rimcl.stats.render_file import load_render
from rimcl.study.summary import summary_markdown
from rimcl.study.summary_format import significant, with_interval


@pytest.fixture(scope="module")
def scene():
    return StudyConfig.from_scene(load_scene(None))


def table_rows(text, first_cell):
    """Cells of the Markdown table rows whose first cell is ``first_cell``."""
    rows = []
    for line in text.splitlines():
        cells = [cell.strip() for cell in line.strip("|").split(" | ")]
        if line.startswith("|") and cells[0] == first_cell:
            rows.append(cells)
    return rows


def test_values_come_with_their_intervals_and_the_paper_statistics_are_labelled(tmp_path, scene):
    paths = []
    for name, g, seed in (("C1", 2.82e-4, 0), ("C4", 0.334, 1)):
        paths.append(tmp_path / f"{name}.h5")
        write_budget_file(paths[-1], fit_frames=3, case=name, k_rho=g, n_tracers=80, seed=seed)
    stats = compute_stats([load_render(path) for path in paths])
    text = summary_markdown(stats, scene)
    air = stats["cases"][0]
    u3 = air["velocity"]["u3"]
    low, high = u3["ci95"]["rms_normalized"]
    expected = (
        f"{significant(100 * u3['rms_normalized'])} "
        f"[{significant(100 * low, 2)}, {significant(100 * high, 2)}] %"
    )
    assert expected in table_rows(text, "C1")[1]  # position table first, then u3
    assert (
        "## The paper's statistics" in text
        and "**Acceleration a3, sliding polynomial fit**" in text
    )
    # |ε_x| in a header must not split the table
    header = next(line for line in text.splitlines() if "peak \\|ε_x\\| / L" in line)
    assert header.count(" | ") == 5
    assert "## Error budget: optics, imaging, total, noise floor, baseline" in text
    # files without the floor's columns: the floor is n/a, said so, not a number
    budget = [row for row in table_rows(text, "C1") if len(row) == 10]
    assert len(budget) == 1 and budget[0][4] == "n/a (no floor in the render file)"
    assert "no noise floor in these render files" in air["budget_verdict"]["text"]
    assert air["budget_verdict"]["text"] in text


def test_a_growing_statistic_is_marked(tmp_path, scene):
    path = tmp_path / "c1.h5"
    write_render_file(path, n_tracers=40)
    stats = compute_stats([load_render(path)])
    case = stats["cases"][0]
    case["convergence"]["not_converged"] = ["velocity.u3.random", "position_error_median_over_L"]
    text = summary_markdown(stats, scene)
    position = table_rows(text, "C1")[0]
    assert position[-1].endswith(" †") and not position[-2].endswith(" †")
    paper_row = table_rows(text, "C1")[-1]  # the paper's statistics come last
    random = with_interval(
        case["velocity"]["u3"]["random"], case["velocity"]["u3"]["ci95"]["random"], 100, " %"
    )
    assert any(cell.startswith(f"{random} †") for cell in paper_row)
    assert "- C1: not converged: `velocity.u3.random`, `position_error_median_over_L`" in text
    # beside it: its influence and its conditioned value
    share = significant(case["velocity"]["u3"]["influence"], 2)
    conditioned = case["velocity"]["u3"]["conditioned"]
    assert (
        f"{random} † (top-3 share {share}; conditioned "
        f"{with_interval(conditioned['random'], conditioned['ci95']['random'], 100, ' %')})"
    ) in paper_row


def test_the_headline_leads_with_the_median_and_marks_an_rms_a_tail_carries(tmp_path, scene):
    """The median and IQR of ε/truth come first; an rms ratio whose largest tracers carry
    Σε² or whose tail is heavy reads † with why, beside the same number unmarked."""
    path = tmp_path / "c4.h5"
    write_render_file(path, case="C4", k_rho=0.334, n_tracers=40)
    stats = compute_stats([load_render(path)])
    case = stats["cases"][0]
    u3 = case["velocity"]["u3"]
    u3["top_share"], u3["top_tracers"], u3["tail_index"] = 0.83, 3, 1.2
    case["convergence"]["not_converged"] = ["velocity.u3.rms_normalized"]
    case["convergence"]["reasons"] = {"velocity.u3.rms_normalized": ["few tracers", "heavy tail"]}
    text = summary_markdown(stats, scene)
    row = table_rows(text, "C4")[1]  # position table first, then u3
    median = with_interval(u3["median"], u3["ci95"]["median"], 100, " %")
    rms = with_interval(u3["rms_normalized"], u3["ci95"]["rms_normalized"], 100, " %")
    assert row[1] == median
    assert row[3] == f"{rms} † (3 tracers carry 83 % of Σε²; tail index 1.2)"
    # a3 is not marked: its rms reads plain
    a3 = case["acceleration"]["a3"]
    a3_row = table_rows(text, "C4")[2]
    assert a3_row[3] == with_interval(a3["rms_normalized"], a3["ci95"]["rms_normalized"], 100, " %")


def test_the_paper_table_gives_both_error_definitions(tmp_path, scene):
    path = tmp_path / "c1.h5"
    write_render_file(path, n_tracers=40)
    stats = compute_stats([load_render(path)])
    case = stats["cases"][0]
    definitions = stats["config"]["error_definitions"]
    assert set(definitions) == {"refraction", "against_truth", "baseline", "noise_floor"}
    truth = case["against_truth"]["velocity"]["u3"]
    refraction = case["velocity"]["u3"]
    assert truth["rms_normalized"] != refraction["rms_normalized"]
    text = summary_markdown(stats, scene)
    (vs_truth,) = table_rows(text, "rimcl, C1, vs truth (the paper's ε)")
    assert vs_truth[3].startswith(
        with_interval(truth["systematic"], truth["ci95"]["systematic"], 100, " %")
    )
    (vs_reference,) = table_rows(text, "rimcl, C1, vs reference (refraction)")
    assert vs_reference[3].startswith(
        with_interval(refraction["systematic"], refraction["ci95"]["systematic"], 100, " %")
    )


def test_empty_samples_read_n_a(tmp_path, scene):
    path = tmp_path / "lost.h5"
    write_render_file(path, n_tracers=5, flagged={i: 1 for i in range(5)})
    text = summary_markdown(compute_stats([load_render(path)]), scene)
    position = table_rows(text, "C1")[0]
    assert position[3:] == ["0/5", "n/a", "n/a"]
    assert " 0 " not in " ".join(position[4:])


def test_significant_digits_without_exponents_in_the_readable_range():
    assert significant(2134.0) == "2130"
    assert significant(2134.0, 2) == "2100"
    assert significant(0.012345) == "0.0123"
    assert significant(-0.094, 2) == "-0.094"
    assert significant(3.2e-6) == "3.2e-06"
    assert with_interval(None, [1, 2]) == "n/a"
    assert with_interval(0.5, None, 100, " %") == "50.0 %"


def test_tracers_with_several_images_are_counted_per_case(tmp_path, scene):
    """The note multiple_images (several aims reach the lens's pupil) is counted per case in
    stats.json (n_noted) and in summary.md."""
    import json

    import h5py

    from rimcl.imaging.centroid import TracerFlag, flag_names

    path = tmp_path / "C4.h5"
    several = {tracer: int(TracerFlag.MULTIPLE_IMAGES) for tracer in (2, 5, 11)}
    write_render_file(path, case="C4", k_rho=0.334, n_tracers=20, noted=several)
    with h5py.File(path, "a") as h5:
        h5.attrs["flag_names"] = json.dumps(flag_names())  # the real bits' names
    stats = compute_stats([load_render(path)])
    assert stats["cases"][0]["n_noted"]["multiple_images"] == 3
    assert "pupil; physics, noted and kept): C4: 3" in summary_markdown(stats, scene)
