"""Kernel shapes measured per device (rimcl.optics.shapes): the cache, its use by
trace_rays, and a tiny tuning run. The suite runs with RIMCL_TUNE=off (conftest); these
tests point RIMCL_SHAPE_CACHE at a temporary file."""

import json

import numpy as np
import pytest
from tracing_fields import oblique_rays, smooth_field

import rimcl
from rimcl.core.errors import RimclError
from rimcl.optics import shapes, tuning
from rimcl.optics.shapes import KernelShape


@pytest.fixture
def cache(tmp_path, monkeypatch):
    """A private shape cache, read but never tuned into (RIMCL_TUNE=cache)."""
    path = tmp_path / "cache" / "kernel_shapes.json"
    monkeypatch.setenv("RIMCL_SHAPE_CACHE", str(path))
    monkeypatch.setenv("RIMCL_TUNE", "cache")
    monkeypatch.setattr(shapes, "_memo", {})
    return path


def _trace(device, **options):
    field = smooth_field(2e-2, counts=(14, 12, 10), seed=31)
    origins, directions = oblique_rays(37, 0.2, 0.8, 0.25, seed=32)
    return rimcl.trace_rays(field, origins, directions, x_end=0.95, device=device, **options)


def test_trace_rays_uses_the_cached_shape_and_traces_the_same_bits(device, cache):
    """A cached shape (an unusual one: 4 lanes, work-groups of 2) is what trace_rays and
    `rimcl devices` use; the results are those of the rule-based shape, bit for bit."""
    rule = _trace(device, kernel_shape=shapes.rule_shape(device))
    assert tuning.tuned_entry(device) is None  # nothing cached: the rule
    assert shapes.default_kernel_shape(device) == shapes.rule_shape(device)
    wanted = KernelShape(lanes=4, pocl_fast=False, group=2)
    shapes._write_cache(cache, shapes.device_key(device), {"shape": wanted.describe()})
    shapes._memo.clear()
    assert shapes.default_kernel_shape(device) == wanted
    # f64 and the other interpolations take at most CPU_LANES lanes of the measured shape
    assert shapes.default_kernel_shape(device, "f64").lanes == 4
    tuned = _trace(device)
    assert tuned.config["kernel_shape"] == wanted.describe()
    for name in ("end_pos", "end_dir", "image_pos", "path_length", "n_metric", "steps"):
        np.testing.assert_array_equal(getattr(tuned, name), getattr(rule, name), err_msg=name)
    # another device's entry in the same file is kept when this one is rewritten
    shapes._write_cache(cache, "other | 1.0 | cpu | v1", {"shape": KernelShape().describe()})
    entries = json.loads(cache.read_text())["entries"]
    assert set(entries) == {shapes.device_key(device), "other | 1.0 | cpu | v1"}


def test_a_broken_cache_or_mode_falls_back_or_fails_clearly(device, cache, monkeypatch):
    cache.parent.mkdir(parents=True)
    cache.write_text("{not json")
    assert shapes.default_kernel_shape(device) == shapes.rule_shape(device)
    cache.write_text(json.dumps({"entries": {shapes.device_key(device): {"shape": {"lanes": 3}}}}))
    shapes._memo.clear()
    assert shapes.default_kernel_shape(device) == shapes.rule_shape(device)
    monkeypatch.setenv("RIMCL_TUNE", "sometimes")
    with pytest.raises(RimclError, match="RIMCL_TUNE must be one of"):
        shapes.default_kernel_shape(device)
    with pytest.raises(RimclError, match="work-group size"):
        KernelShape(8, False, group=0)


def test_a_tiny_tuning_run_keeps_the_fastest_shape(device, cache):
    """tune() times the shapes on a tiny field, keeps the fastest with its measurements
    in the cache (atomically written JSON), and the device then uses it."""
    rule = shapes.rule_shape(device)
    other = KernelShape(lanes=1 if rule.lanes > 1 else 8, pocl_fast=rule.pocl_fast)
    entry = tuning.tune(device, nodes=10, rays=256, repeats=2, shapes=[rule, other], groups=[4])
    measured = {
        KernelShape(m["lanes"], m["pocl_fast"], m["group"]): m for m in entry["measurements"]
    }
    assert set(measured) == {rule, other, KernelShape(rule.lanes, rule.pocl_fast, 4)} or set(
        measured
    ) == {rule, other, KernelShape(other.lanes, other.pocl_fast, 4)}
    fastest = max(measured, key=lambda shape: measured[shape]["ray_steps_per_s"])
    assert KernelShape(**entry["shape"]) == fastest
    for m in measured.values():
        assert len(m["kernel_seconds"]) >= 2 and m["ray_steps_per_s"] > 0
    stored = json.loads(cache.read_text())["entries"][shapes.device_key(device)]
    assert stored["shape"] == entry["shape"] and stored["workload"]["field_nodes"] == 10
    assert not list(cache.parent.glob("*.part"))
    assert shapes.default_kernel_shape(device) == fastest


def test_devices_shows_the_shape_in_use_and_bench_needs_out_or_tune(device, cache):
    """`rimcl devices` shows the rule until a shape is measured, then the measured one;
    `rimcl bench` without --out or --tune is one clear line."""
    from click.testing import CliRunner

    from rimcl.cli.main import cli

    def listed():
        result = CliRunner().invoke(cli, ["devices", "--json"])
        assert result.exit_code == 0, result.output
        mine = [e for e in json.loads(result.output) if e["device"] == device.name.strip()]
        return mine[0]["kernel_shape"]

    shown = listed()
    assert shown["source"] == "rule"
    assert KernelShape(shown["lanes"], shown["pocl_fast"], shown["group"]) == shapes.rule_shape(
        device
    )
    measured = KernelShape(lanes=2, pocl_fast=False, group=8)
    entry = {"shape": measured.describe(), "measurements": [{"ray_steps_per_s": 1.5e7}]}
    shapes._write_cache(cache, shapes.device_key(device), entry)
    shown = listed()
    assert shown["source"] == "measured" and shown["ray_steps_per_s"] == 1.5e7
    assert (shown["lanes"], shown["group"]) == (2, 8)
    table = CliRunner().invoke(cli, ["devices"])
    assert "2 lanes, group 8 (measured)" in table.output
    refused = CliRunner().invoke(cli, ["bench"])
    assert refused.exit_code != 0
    assert (
        refused.output.strip()
        .splitlines()[-1]
        .endswith("give --out DIR for the sweep, or --tune to measure kernel shapes")
    )


def test_image_kernel_work_group_sizes_give_the_same_rows(device):
    """The image kernel's work-group size changes speed only: each tracer's row is made by
    one work-item whatever the group, so the columns (and the summed frame) are the same."""
    from rimcl.imaging.device import (
        CPU_IMAGE_GROUPS,
        GPU_IMAGE_GROUPS,
        image_points,
        rule_image_group,
    )
    from rimcl.imaging.frames import Imaging
    from rimcl.imaging.render import FrameImage, Renderer

    rng = np.random.default_rng(21)
    pixel = 1 / 256
    count, rays = 40, 24
    points = rng.uniform(0.1, 0.9, size=(count, 1, 2)) + 1.5 * pixel * rng.normal(
        size=(count, rays, 2)
    )
    usable = rng.uniform(size=(count, rays)) > 0.1
    weights = rng.uniform(0.5, 1.5, size=(count, rays))
    imaging = Imaging(Renderer("exact", pixel, (0.0, 0.0), 1.2, 32, 12), 300.0)
    flags = np.zeros(count, dtype=np.int64)
    # the sizes tune_image() chooses from (each is another build of the kernel on PoCL)
    candidates = CPU_IMAGE_GROUPS if rule_image_group(device) == 1 else GPU_IMAGE_GROUPS
    groups = [g for g in candidates if g <= device.max_work_group_size]
    columns, frames = {}, {}
    for group in groups:
        canvas = FrameImage(256, 256, imaging.renderer.full_scale)
        columns[group] = image_points(
            imaging, points, usable, weights, flags, device=device, canvas=canvas, group=group
        )
        frames[group] = canvas.counts
    first = groups[0]
    assert np.count_nonzero(np.isfinite(columns[first]["x2"])) > count // 2
    assert frames[first].max() > 0
    for group in groups[1:]:
        for name, values in columns[first].items():
            np.testing.assert_array_equal(columns[group][name], values, err_msg=f"{group} {name}")
        np.testing.assert_array_equal(frames[group], frames[first])
    with pytest.raises(RimclError, match="work-group size must be 1 to"):
        image_points(imaging, points, usable, weights, flags, device=device, group=1 << 20)


def test_a_tiny_image_tuning_run_keeps_the_fastest_group(device, cache):
    """tune_image() times the image kernel's work-group sizes and keeps the fastest in the
    device's cache entry, beside the trace shape, where image_group() and `rimcl devices`
    find it; before the device has an entry nothing is stored and the rule applies."""
    from rimcl.imaging.device import image_group, rule_image_group, tune_image

    groups = [1, 2] if rule_image_group(device) == 1 else [32, 64]
    alone = tune_image(device, rays=8, repeats=1, groups=groups)
    assert not alone["stored"] and not cache.exists()
    assert image_group(device) == rule_image_group(device)
    shapes._write_cache(cache, shapes.device_key(device), {"shape": KernelShape().describe()})
    shapes._memo.clear()
    result = tune_image(device, rays=8, repeats=2, groups=groups)
    assert result["stored"]
    measured = {m["group"]: m for m in result["measurements"]}
    assert set(measured) == set(groups)
    fastest = max(measured, key=lambda group: measured[group]["tracers_per_s"])
    assert result["group"] == fastest
    assert all(len(m["kernel_seconds"]) == 2 for m in measured.values())
    stored = json.loads(cache.read_text())["entries"][shapes.device_key(device)]
    assert stored["image"]["group"] == fastest and stored["shape"] == KernelShape().describe()
    assert image_group(device) == fastest
    assert shapes.shape_in_use(device)["image_group"] == fastest
    assert f"image group {fastest}" in shapes.describe_shape(shapes.shape_in_use(device))
