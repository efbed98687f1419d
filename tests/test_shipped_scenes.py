"""The example scenes shipped in data_samples/scenes load and run end to end."""

import json
from pathlib import Path

import pytest

from rimcl.scene.load import load_scene
from rimcl.study.run import run_study

SCENES = sorted((Path(__file__).parents[1] / "data_samples" / "scenes").glob("*.toml"))


@pytest.mark.parametrize("path", SCENES, ids=[p.stem for p in SCENES])
def test_shipped_scene_runs(path, device, tmp_path):
    small = {
        "tracers.count": 8,
        "camera.pupil_rays": 64,
        "piv.rays": 64,  # as the camera's: PIV like for like where a scene runs both
        "time.frames": 3,
        "time.fit_window": 3,
        "run.device": device.name,
    }
    if path.stem == "piv_vs_ptv":
        # PIV frames are the sensor: a sixteenth of its pixels, four times their size on the
        # sheet, and a third of its seeding (every PIV tracer is aimed through the field)
        small.update(
            {
                "camera.sensor_pixels": [128, 128],
                "camera.magnification": 0.025,
                "piv.density": 0.01,
            }
        )
    scene = load_scene(path, small)
    assert scene["camera"]["kind"] == "lens"
    result = run_study(scene, tmp_path / "study", figures=False)
    stats = json.loads((tmp_path / "study" / "stats.json").read_text())
    fluid_cases = [c for c in stats["cases"] if c["name"].startswith("dT=")]
    assert fluid_cases and all(c["G"] is None for c in fluid_cases)
    # a larger temperature difference bends light more
    medians = [c["optics"]["position_error_median_over_L"] for c in fluid_cases]
    assert medians == sorted(medians)
    assert all("water" in c["physical_equivalent"] for c in stats["cases"])
    assert result.ran[: len(scene["cases"]["names"])] == scene["cases"]["names"]
    if scene["run"]["mode"] == "both":
        # the same Δt, camera, pixel, rays, bits and noise: the summary compares like for like
        for case in stats["cases"]:
            settings = case["piv_vs_ptv"]["settings"]
            assert settings["like_for_like"], settings
        assert "measured **like for like**" in (tmp_path / "study" / "summary.md").read_text()
