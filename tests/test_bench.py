"""``rimcl bench``: the sweep, its failure marks and its output files (no timing asserted)."""

import csv
import json

import numpy as np
import pytest
from click.testing import CliRunner

import rimcl
from rimcl.cli.main import cli
from rimcl.optics.bench import (
    CSV_COLUMNS,
    FAIL_F32_DRIFT,
    FAIL_STEP,
    QUICK_STEP_FACTORS,
    TOLERANCE_PIXELS,
    _load,
    mark_failures,
    synthetic_density,
)


@pytest.fixture(scope="module")
def small_field_file(tmp_path_factory):
    """A 16³ periodic density (box 2π) in a rimcl field file."""
    path = tmp_path_factory.mktemp("bench") / "small.h5"
    density = synthetic_density(16, seed=1)
    rimcl.write_field(
        path,
        density=[density],
        times=[0.0],
        origin=(0.0, 0.0, 0.0),
        spacing=(2 * np.pi / 16,) * 3,
        boundary="periodic",
    )
    return path


def _read_csv(path):
    lines = path.read_text(encoding="utf-8").splitlines()
    comments = [line for line in lines if line.startswith("#")]
    rows = list(csv.DictReader(line for line in lines if not line.startswith("#")))
    return comments, rows


def test_bench_quick_writes_csv_json_and_png(small_field_file, tmp_path, device):
    out = tmp_path / "bench"
    result = CliRunner().invoke(
        cli,
        [
            "bench",
            "--quick",
            "--out",
            str(out),
            "--field",
            str(small_field_file),
            "--interp",
            "trilinear",
            "--precision",
            "f32,f32c",
            "--device",
            device.name.strip(),
        ],
    )
    assert result.exit_code == 0, result.output
    assert "wrote" in result.output and "bench.png" in result.output
    comments, rows = _read_csv(out / "bench.csv")
    assert [c.split(":")[0] for c in comments[1:]] == ["# config", "# device", "# versions"]
    assert json.loads(comments[2].split(":", 1)[1])["device"] == device.name.strip()
    assert list(rows[0]) == list(CSV_COLUMNS)
    # 2 cases x (3 steps x 2 precisions + 1 adaptive)
    assert len(rows) == 2 * (len(QUICK_STEP_FACTORS) * 2 + 1)
    assert {r["case"] for r in rows} == {"C1", "C4"}
    for row in rows:
        assert float(row["ray_steps_per_s"]) > 0
        assert int(row["rays_ok"]) + int(row["rays_exit_side"]) + int(
            row["rays_turned_back"]
        ) + int(row["rays_max_steps"]) + int(row["rays_non_finite"]) == int(row["rays"])
        marked = FAIL_STEP in row["notes"]
        fixed = row["step_control"] == "fixed"
        assert marked == (fixed and float(row["err_fine_max_px"]) > TOLERANCE_PIXELS)
    # the step error shrinks with the step (the reference's is 4 times smaller still)
    for case in ("C1", "C4"):
        fixed = [
            r
            for r in rows
            if r["case"] == case and r["precision"] == "f32c" and r["step_control"] == "fixed"
        ]
        errors = [
            float(r["err_fine_max_px"]) for r in sorted(fixed, key=lambda r: -float(r["step"]))
        ]
        assert len(errors) == 3 and errors[0] > 4 * errors[1] > 16 * errors[2] > 0
    document = json.loads((out / "bench.json").read_text(encoding="utf-8"))
    assert len(document["rows"]) == len(rows) and document["meta"]["quick"] is True
    assert (out / "bench.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def _row(precision, err_fine_px, step=0.1):
    return {
        "case": "C1",
        "interp": "trilinear",
        "precision": precision,
        "step_control": "fixed",
        "step": step,
        "err_fine_max_px": err_fine_px,
        "rays_lost": 0,
        **{f"rays_{name}": 0 for name in rimcl.STATUS_NAMES},
    }


def test_failure_marks():
    rows = [
        _row("f32c", 1e-5),
        _row("f32", 5e-3),  # 500 times f32c, below the tolerance: drift only
        _row("f32c", 2e-2, step=0.4),
        _row("f32", 2.1e-2, step=0.4),  # the step dominates: no drift
    ]
    rows[1]["rays_turned_back"] = 3
    rows[2]["rays_lost"] = 2
    mark_failures(rows)
    assert rows[0]["notes"] == ""
    assert rows[1]["notes"] == f"{FAIL_F32_DRIFT}; 3 turned back"
    assert rows[2]["notes"] == f"{FAIL_STEP}; 2 rays lost"
    assert rows[3]["notes"] == FAIL_STEP


def test_bench_refuses_unknown_settings(small_field_file, tmp_path, device):
    result = CliRunner().invoke(
        cli,
        ["bench", "--quick", "--out", str(tmp_path), "--field", str(small_field_file),
         "--interp", "cubic", "--device", device.name.strip()],
    )  # fmt: skip
    assert result.exit_code == 1
    assert "interp must be among" in result.output


def test_without_the_sample_a_synthetic_field_with_its_density_range_stands_in(monkeypatch):
    import rimcl.fields.sample

    def missing():
        raise rimcl.RimclError("the shipped sample is missing")

    monkeypatch.setattr(rimcl.fields.sample, "sample_path", missing)
    field = _load(None, 0.334)
    assert "synthetic" in field.attrs["source"] and field.periodic
    # the mixing flow's densities span 1 to 1.105 (Atwood number 0.05)
    assert field.delta_n_range == pytest.approx(0.334 * 0.105, rel=1e-6)
