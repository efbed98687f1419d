"""Physical units end to end: scales, the study's units blocks, stats.csv and summary.md."""

import json

import numpy as np
import pandas as pd
import pytest

from rimcl.core.errors import RimclError
from rimcl.scene.load import load_scene
from rimcl.stats.render_file import load_render
from rimcl.stats.units import scales
from rimcl.study.answer import piv_units
from rimcl.study.run import run_study

LENGTH_M, TIME_S = 0.0106, 0.45
TINY = {
    "cases.names": ["C3"],
    "tracers.count": 8,
    "camera.fan": 4,
    "piv.pixels": 64,
    "piv.rays": 4,
    "piv.window": 16,
    "run.mode": "both",
    "time.frames": 3,
    "field.length_m": LENGTH_M,
    "field.time_s": TIME_S,
}


def test_scales_are_closed_forms():
    got = scales(length=2.0, pixel_size=0.004, dt=0.02, length_m=0.01, time_s=0.5)
    assert got["L_mm"] == pytest.approx(20.0)
    assert got["pixel_um"] == pytest.approx(40.0)
    assert got["dt_ms"] == pytest.approx(10.0)
    # a velocity error of 0.003 L0/T0 at Δt = 10 ms: 0.06 mm/s, 0.015 px per frame
    assert 0.003 * got["mm_s_per_velocity"] == pytest.approx(0.06)
    assert 0.003 * got["px_frame_per_velocity"] == pytest.approx(0.015)
    assert got["m_s2_per_acceleration"] == pytest.approx(0.04)
    bare = scales(length=2.0, pixel_size=0.004, dt=0.02)
    assert bare["in_field_units"] and bare["mm_s_per_velocity"] is None
    assert bare["px_per_length"] == pytest.approx(250.0)


def test_velocity_scale_gives_time_scale_and_conflicts_are_refused():
    scene = load_scene(None, {"field.length_m": 0.01, "field.velocity_m_s": 0.02})
    assert scene["field"]["time_s"] == pytest.approx(0.5)
    with pytest.raises(RimclError, match="disagree"):
        load_scene(None, {"field.length_m": 0.01, "field.velocity_m_s": 0.02, "field.time_s": 1.0})
    with pytest.raises(RimclError, match=r"needs field\.length_m"):
        load_scene(None, {"field.velocity_m_s": 0.02})


def test_piv_units_closed_form():
    piv = {
        "length_L": 2.0,
        "pixel_size_over_L": 0.002,
        "dt": 0.02,
        "displacement_px": {"truth_rms": 1.5, "refraction_rms": 0.01},
    }
    block = piv_units(piv, 0.01, 0.5)
    # 1.5 px of 4e-3 L0 in 0.02 T0: 0.3 L0/T0 = 6 mm/s at 1 cm and 0.5 s
    assert block["truth_rms"]["field"] == pytest.approx(0.3)
    assert block["truth_rms"]["mm_s"] == pytest.approx(6.0)
    assert piv_units(piv, None, None)["refraction_rms"]["mm_s"] is None


@pytest.fixture(scope="module")
def study(device, tmp_path_factory):
    out = tmp_path_factory.mktemp("units")
    scene = load_scene(None, {**TINY, "run.device": device.name})
    run_study(scene, out, figures=False)
    return out, json.loads((out / "stats.json").read_text())


def test_physical_values_are_normalised_values_times_the_scales(study):
    _, stats = study
    case = stats["cases"][0]
    units = case["units"]
    factors = units["scales"]
    assert factors["length_m"] == LENGTH_M and factors["time_s"] == TIME_S
    assert factors["dt_ms"] == pytest.approx(case["dt"] * TIME_S * 1e3)
    pixel = case["pixel_size_over_L"] * case["length_L"]
    assert factors["pixel_um"] == pytest.approx(pixel * LENGTH_M * 1e6)
    median = units["position"]["median"]
    assert median["over_L"] == case["position_error_median_over_L"]
    assert median["um"] == pytest.approx(median["over_L"] * case["length_L"] * LENGTH_M * 1e6)
    assert median["px"] == pytest.approx(median["over_L"] / case["pixel_size_over_L"])
    for group, unit, factor in (
        ("velocity", "mm_s", LENGTH_M / TIME_S * 1e3),
        ("acceleration", "m_s2", LENGTH_M / TIME_S**2),
    ):
        for component in ("u3", "vector") if group == "velocity" else ("a3",):
            for entry in units[group][component].values():
                assert entry[unit] == pytest.approx(entry["field"] * factor)
    u3 = units["velocity"]["u3"]
    assert u3["rms_truth"]["px_frame"] == pytest.approx(
        u3["rms_truth"]["field"] * case["dt"] / pixel
    )
    # rms(ε)/rms(u3) of the statistics is the ratio of the two rms values
    ratio = u3["rms_refraction"]["field"] / u3["rms_truth"]["field"]
    assert ratio == pytest.approx(case["velocity"]["u3"]["rms_normalized"], rel=1e-9)
    piv = case["piv"]["units"]
    px = case["piv"]["displacement_px"]["refraction_rms"]
    piv_pixel = case["piv"]["pixel_size_over_L"] * case["piv"]["length_L"]
    assert piv["refraction_rms"]["mm_s"] == pytest.approx(
        px * piv_pixel / case["piv"]["dt"] * LENGTH_M / TIME_S * 1e3
    )


def test_physical_values_are_exactly_the_normalised_ones_times_the_scales(study):
    """PTV and PIV, in stats.json, stats.csv and summary.md: physical = normalised × scale,
    to the last bit (the tidy table read back exactly), with the scales the scene's."""
    out, stats = study
    case = stats["cases"][0]
    units, piv = case["units"], case["piv"]
    for factors in (units["scales"], piv["units"]["scales"]):
        assert factors["mm_s_per_velocity"] == LENGTH_M / TIME_S * 1e3
        assert factors["m_s2_per_acceleration"] == LENGTH_M / TIME_S**2
        assert factors["um_per_length"] == LENGTH_M * 1e6
    factors = units["scales"]
    assert factors["dt_ms"] == case["dt"] * TIME_S * 1e3
    expected = {}  # (quantity, component, statistic, unit) -> value
    for group in ("velocity", "velocity_fit", "acceleration", "acceleration_fit"):
        velocity = group.startswith("velocity")
        unit, factor = (
            ("mm_s", factors["mm_s_per_velocity"])
            if velocity
            else ("m_s2", factors["m_s2_per_acceleration"])
        )
        for component, entry in units[group].items():
            for statistic, values in entry.items():
                assert values[unit] == values["field"] * factor
                expected[group, component, statistic, unit.replace("_", "/")] = values[unit]
                if velocity:
                    per_frame = values["field"] * factors["px_frame_per_velocity"]
                    assert values["px_frame"] == per_frame
                    expected[group, component, statistic, "px/frame"] = per_frame
    for name, entry in units["position"].items():
        length = entry["over_L"] * case["length_L"]
        assert entry["um"] == length * factors["um_per_length"]
        assert entry["px"] == length * factors["px_per_length"]
        expected["position_error", "magnitude", name, "um"] = entry["um"]
        expected["position_error", "magnitude", name, "px"] = entry["px"]
    piv_pixel = piv["pixel_size_over_L"] * piv["length_L"]
    for key, px in piv["displacement_px"].items():
        if not key.endswith("_rms"):
            continue
        entry = piv["units"][key]
        assert entry["px_frame"] == px and entry["field"] == px * piv_pixel / piv["dt"]
        assert entry["mm_s"] == entry["field"] * piv["units"]["scales"]["mm_s_per_velocity"]
        expected["piv_displacement", key, "rms", "mm/s"] = entry["mm_s"]
        expected["piv_displacement", key, "rms", "px/frame"] = px
    assert len(expected) > 40
    table = pd.read_csv(out / "stats.csv", float_precision="round_trip")
    read = {
        (row.quantity, row.component, row.statistic, row.unit): row.value
        for row in table.itertuples()
        if row.unit in ("mm/s", "px/frame", "m/s2", "um", "px")
    }
    for key, value in expected.items():
        assert read[key] == value, key
    text = (out / "summary.md").read_text()
    truth = piv["units"]["truth_rms"]
    assert f"{truth['px_frame']:.3g} ({truth['mm_s']:.3g} mm/s)" in text
    scales_piv = piv["units"]["scales"]
    assert f"pixel = {piv['pixel_size_over_L']:.3g} L = {scales_piv['pixel_um']:.3g} µm" in text
    assert f"Δt = {piv['dt']:.3g} = {scales_piv['dt_ms']:.3g} ms" in text


def test_tidy_table_reads_with_pandas_and_matches_stats_json(study):
    out, stats = study
    table = pd.read_csv(out / "stats.csv")
    assert list(table.columns) == [
        "case", "quantity", "component", "statistic", "value", "lo", "hi", "unit"
    ]  # fmt: skip
    case = stats["cases"][0]
    row = table[(table.quantity == "velocity_error") & (table.component == "u3")
                & (table.statistic == "rms_normalized")].iloc[0]  # fmt: skip
    assert row.value == pytest.approx(case["velocity"]["u3"]["rms_normalized"])
    assert [row.lo, row.hi] == pytest.approx(case["velocity"]["u3"]["ci95"]["rms_normalized"])

    def value(quantity, component, statistic, unit):
        picked = table[(table.quantity == quantity) & (table.component == component)
                       & (table.statistic == statistic) & (table.unit == unit)]  # fmt: skip
        assert len(picked) == 1
        return picked.value.iloc[0]

    field = value("velocity", "u3", "rms_refraction", "field")
    mm_s = value("velocity", "u3", "rms_refraction", "mm/s")
    assert mm_s == pytest.approx(field * LENGTH_M / TIME_S * 1e3)
    pixel = case["pixel_size_over_L"] * case["length_L"]
    px = value("velocity", "u3", "rms_refraction", "px/frame")
    assert px == pytest.approx(field * case["dt"] / pixel)
    acc = value("acceleration", "a3", "rms_total", "field")
    assert value("acceleration", "a3", "rms_total", "m/s2") == pytest.approx(
        acc * LENGTH_M / TIME_S**2
    )
    assert value("position_error", "magnitude", "median", "um") == pytest.approx(
        case["position_error_median_over_L"] * case["length_L"] * LENGTH_M * 1e6
    )
    piv_px = value("piv_displacement", "refraction_rms", "rms", "px/frame")
    piv_pixel = case["piv"]["pixel_size_over_L"] * case["piv"]["length_L"]
    assert value("piv_displacement", "refraction_rms", "rms", "mm/s") == pytest.approx(
        piv_px * piv_pixel / case["piv"]["dt"] * LENGTH_M / TIME_S * 1e3
    )


def test_summary_leads_with_the_answer_in_physical_units(study):
    out, stats = study
    text = (out / "summary.md").read_text()
    answer = text.index("## Your answer")
    assert answer < text.index("## Headline")
    units = stats["cases"][0]["units"]
    # the answer quotes the fitted tracks where there are any (what PTV codes report)
    group = "velocity_fit" if units.get("velocity_fit") else "velocity"
    total = units[group]["vector"]["rms_total"]
    assert f"your velocity error (the in-plane vector) is {total['mm_s']:.3g} mm/s" in text
    # and the headline tables' number beside it: refraction in u3 alone, the same group
    headline = 100 * stats["cases"][0][group]["u3"]["rms_normalized"]
    assert f"in u3 alone (the tables' headline) refraction is {headline:.3g} % of rms u3" in text
    assert f"Δt = {units['scales']['dt_ms']:.3g} ms" in text
    median = units["position"]["median"]
    assert f"median position error {median['um']:.3g} µm ({median['px']:.3g} px)" in text
    piv = stats["cases"][0]["piv"]["units"]["refraction_rms"]
    assert f"PIV: refraction error {piv['mm_s']:.3g} mm/s" in text
    assert np.isfinite(total["mm_s"])


def test_without_scales_outputs_say_field_units(device, tmp_path):
    """A field file without length_m and time_s: the shipped sample's copy, its scales removed."""
    import shutil

    import h5py

    from rimcl.fields.sample import sample_path

    bare = tmp_path / "bare.h5"
    shutil.copyfile(sample_path(), bare)
    with h5py.File(bare, "a") as h5:
        for key in ("length_m", "time_s"):
            h5.attrs.pop(key, None)
    scene = load_scene(
        None, {**TINY, "run.mode": "ptv", "field.path": str(bare), "field.length_m": None,
               "field.time_s": None, "run.device": device.name},
    )  # fmt: skip
    assert scene["field"]["time_s"] is None
    out = tmp_path / "study"
    run_study(scene, out, figures=False)
    stats = json.loads((out / "stats.json").read_text())
    units = stats["cases"][0]["units"]
    assert (
        units["scales"]["in_field_units"] and units["velocity"]["u3"]["rms_truth"]["mm_s"] is None
    )
    assert "*In field units*" in (out / "summary.md").read_text()


def test_case_and_piv_files_open_with_xarray_as_named_dimensions_with_units(study):
    import xarray as xr

    out, stats = study
    case_file = out / "cases" / "C3.h5"
    tracers = xr.open_dataset(case_file, group="tracers", engine="h5netcdf")
    assert set(tracers.coords) >= {"id", "frame", "time"}
    assert tracers["x3_meas"].attrs["units"] == "L0"
    assert tracers["x3_meas"].attrs["si_per_unit"] == pytest.approx(LENGTH_M)
    assert tracers["x3_meas"].dims == ("id", "frame")
    assert tracers["x3_meas"].shape == (TINY["tracers.count"], TINY["time.frames"])
    assert tracers["time"].dims == ("frame",)
    velocity = xr.open_dataset(case_file, group="velocity", engine="h5netcdf")
    assert velocity["u3_meas"].dims == ("id", "frame")
    assert velocity["u3_meas"].attrs["units"] == "L0/T0"
    assert velocity["u3_meas"].attrs["si_per_unit"] == pytest.approx(LENGTH_M / TIME_S)
    # the same numbers as rimcl's reader, frame-major
    tables = load_render(case_file)
    for data, table in ((tracers, tables.tracers), (velocity, tables.velocity)):
        for name in ("x3_meas", "u3_meas", "flags"):
            if name in data:
                flat = data[name].transpose("frame", "id").values.reshape(-1)
                np.testing.assert_array_equal(flat, table[name])
    rays = xr.open_dataset(case_file, group="rays", engine="h5netcdf")
    assert "ray" in rays.dims
    piv = xr.open_dataset(out / "piv" / "C3.h5", engine="h5netcdf")
    assert piv["dx_field"].dims == ("row", "column") and piv["dx_field"].attrs["units"] == "px"
    np.testing.assert_array_equal(piv["row"].values, piv["y"].values[:, 0])
    # the truth in m/s: one pixel of displacement in Δt is pixel · length_m / (Δt · time_s)
    block = stats["cases"][0]["piv"]
    assert piv.attrs["length_m"] == LENGTH_M and piv.attrs["time_s"] == TIME_S
    per_px = block["pixel_size_over_L"] * block["length_L"] * LENGTH_M / (block["dt"] * TIME_S)
    assert piv.attrs["m_s_per_px"] == pytest.approx(per_px, rel=1e-12)
    assert piv["u_true_ms"].dims == ("row", "column") and piv["u_true_ms"].attrs["units"] == "m/s"
    np.testing.assert_array_equal(piv["u_true_ms"], piv["dx_true"] * piv.attrs["m_s_per_px"])
    np.testing.assert_array_equal(piv["v_true_ms"], piv["dy_true"] * piv.attrs["m_s_per_px"])
    # the tables' numbers are the file's columns
    assert stats["cases"][0]["n_tracers"] == tracers.sizes["id"]
