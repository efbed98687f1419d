"""rimcl stats uses a render file only beside files of its own scene, and never writes into
a study directory (issue 20, item 2)."""

import json
from pathlib import Path
from types import SimpleNamespace

import pytest
from click.testing import CliRunner
from synthetic_render import write_render_file

from rimcl.cli.main import cli
from rimcl.core.errors import RimclError
from rimcl.stats.consistency import scene_mismatches
from rimcl.stats.document import run_stats


def _tables(name, config):
    return SimpleNamespace(path=Path(name), provenance={"config": config})


def test_what_differs_between_scenes_is_named_and_case_keys_are_not():
    base = {
        "case": "C1",
        "k_rho": 2.82e-4,
        "tracers": 100,
        "camera": {"camera": "plane", "fan": 16},
        "render": {"threshold": 100.0, "pixel_size": 7.7e-4},
        "frames": [0, 1, 2],
        "trace": {"device": {"device": "cpu"}, "precision": "f32c"},
        "rays_per_batch": 131072,
        "study_scene": {"cases": {"names": ["C1", "C4"]}},
    }
    other = json.loads(json.dumps(base))
    other.update(case="C4", k_rho=0.334, rays_per_batch=4096)
    other["trace"]["device"] = {"device": "gpu"}
    other["study_scene"] = {"cases": {"names": ["C4"]}}
    assert scene_mismatches([_tables("a.h5", base), _tables("b.h5", other)]) == []
    other["render"]["threshold"] = 500.0
    other["camera"]["fan"] = 8
    other["frames"] = [0, 1, 2, 3, 4]
    assert scene_mismatches([_tables("a.h5", base), _tables("b.h5", other)]) == [
        "camera.fan: 16 in a.h5, 8 in b.h5",
        "frames: [0, 1, 2] in a.h5, [0, 1, 2, 3, 4] in b.h5",
        "render.threshold: 100 in a.h5, 500 in b.h5",
    ]


def test_render_files_of_different_scenes_are_refused_unless_asked(tmp_path):
    air, water = str(tmp_path / "air.h5"), str(tmp_path / "water.h5")
    write_render_file(air, case="C1", k_rho=2.82e-4, n_tracers=30)
    write_render_file(water, case="C4", k_rho=0.334, n_tracers=40)
    out = tmp_path / "stats"
    with pytest.raises(RimclError, match=r"different scenes \(tracers: 30 in air.h5, 40 in "):
        run_stats([air, water], out, figures=False)
    assert not out.exists()
    result = CliRunner().invoke(cli, ["stats", air, water, "--out", str(out), "--no-figures"])
    assert result.exit_code == 1
    lines = result.output.strip().splitlines()
    assert len(lines) == 1 and "--mixed-scenes" in lines[0], result.output
    args = ["stats", air, water, "--out", str(out), "--no-figures", "--mixed-scenes"]
    result = CliRunner().invoke(cli, args)
    assert result.exit_code == 0, result.output
    cases = json.loads((out / "stats.json").read_text())["cases"]
    assert [case["name"] for case in cases] == ["C1", "C4"]


@pytest.mark.parametrize("layout", ["marker", "older study"])
def test_stats_never_replace_a_study_s_outputs(tmp_path, layout):
    path = str(tmp_path / "c1.h5")
    write_render_file(path)
    study = tmp_path / "study"
    (study / "cases").mkdir(parents=True)
    if layout == "marker":
        (study / ".rimcl-study").write_text("{}")
    else:
        (study / "scene.toml").write_text("[tracers]\ncount = 6\n")
    (study / "stats.json").write_text('{"the": "study\'s"}')
    with pytest.raises(RimclError, match="is a rimcl study directory"):
        run_stats([path], study, overwrite=True, figures=False)
    args = ["stats", path, "--out", str(study), "--overwrite", "--no-figures"]
    result = CliRunner().invoke(cli, args)
    assert result.exit_code == 1 and "another --out" in result.output
    assert (study / "stats.json").read_text() == '{"the": "study\'s"}'
