"""Studies on Dask (rimcl.study.distributed): the same numbers as one process, on loopback
LocalClusters, with a worker killed while writing, and after a rerun.

One tiny study (2 cases, 20 tracers in shards of 7, a 6x6 fan, 256 pixels) is measured
once in this process as the answer every distributed run must give bit for bit.
"""

import dataclasses
import json
import os
import sys
from pathlib import Path
from types import SimpleNamespace

import h5py
import numpy as np
import pytest
from click.testing import CliRunner

from rimcl.cli.main import cli
from rimcl.core.errors import RimclError
from rimcl.fields.field_reader import FieldFile
from rimcl.fields.sample import sample_path
from rimcl.ptv.measure import run_render
from rimcl.scene.config import MeasureConfig
from rimcl.scene.load import load_scene, scene_text
from rimcl.scene.study_config import StudyConfig
from rimcl.study.distributed import (
    KINEMATIC_TABLES,
    _reference_for,
    connect,
    parse_scheduler,
    read_shard,
    scene_stamp,
    shard_path,
    shard_ranges,
    worker_device,
    worker_index,
    write_shard,
)
from rimcl.study.run import case_path, run_study

distributed = pytest.importorskip("distributed")

CASES = ["C1", "C4"]
TINY = {
    "cases.names": CASES,
    "tracers.count": 20,
    "camera.fan": 6,
    "renderer.pixels": 256,
    "run.shard_tracers": 7,
}
SHARDS = [(0, 7), (7, 14), (14, 20)]


def tiny_scene(device, **overrides):
    return load_scene(None, {**TINY, "run.device": device.name, **overrides})


@pytest.fixture(scope="module")
def single(device, tmp_path_factory):
    """The study in this process: the numbers every distributed run must reproduce."""
    out = tmp_path_factory.mktemp("single")
    return out, run_study(tiny_scene(device), out, figures=False)


@pytest.fixture(scope="module")
def cluster():
    """Two single-threaded worker processes on loopback, whose client a test can use."""
    with (
        distributed.LocalCluster(
            n_workers=2,
            threads_per_worker=1,
            processes=True,
            host="127.0.0.1",
            dashboard_address=None,
        ) as cluster,
        distributed.Client(cluster) as client,
    ):
        yield cluster, client


def assert_same_case_files(expected, actual):
    """Every table of two render files equal array by array, and the same configuration."""
    with h5py.File(expected, "r") as want, h5py.File(actual, "r") as got:
        groups = [g for g in ("tracers", *KINEMATIC_TABLES, "rays") if g in want]
        assert groups == [g for g in ("tracers", *KINEMATIC_TABLES, "rays") if g in got]
        for group in groups:
            assert sorted(got[group]) == sorted(want[group])
            for name in want[group]:
                np.testing.assert_array_equal(
                    got[group][name][()], want[group][name][()], err_msg=f"{group}/{name}"
                )
        assert dict(got["rays"].attrs) == dict(want["rays"].attrs)
        for key in ("config", "device", "n_tracers", "delta_n_max", "case"):
            assert got.attrs[key] == want.attrs[key], key


def assert_same_study(single, out):
    single_dir, single_result = single
    stats = json.loads((out / "stats.json").read_text())
    assert stats["cases"] == single_result.stats["cases"]
    for case in CASES:
        assert_same_case_files(case_path(single_dir, case), case_path(out, case))
    assert not list(out.rglob("*.part"))


def test_scheduler_specs():
    assert parse_scheduler("local:3") == ("local", 3)
    assert parse_scheduler(" tcp://10.0.0.5:8786 ") == ("address", "tcp://10.0.0.5:8786")
    for bad in ("local:0", "local", "8786", "local:two"):
        with pytest.raises(RimclError, match="must be local:N with N >= 1 or a Dask"):
            parse_scheduler(bad)


def test_shards_tile_the_tracers():
    assert shard_ranges(20, 7) == SHARDS
    assert shard_ranges(400, 100) == [(0, 100), (100, 200), (200, 300), (300, 400)]
    assert shard_ranges(5, 100) == [(0, 5)]
    assert shard_path("d", "C1", (7, 14)) == Path("d/shards/C1/7-14.h5")


def test_worker_index_and_device(device, monkeypatch):
    assert [worker_index(n) for n in (0, 3, "gpu-1", "SLURMCluster-2", "tcp://h:8786")] == [
        0,
        3,
        1,
        2,
        None,
    ]
    monkeypatch.delenv("RIMCL_DEVICE", raising=False)
    assert worker_device(1, device.name) == device
    monkeypatch.setenv("RIMCL_DEVICE", "no-such-device")
    with pytest.raises(RimclError, match="no OpenCL device matches 'no-such-device'"):
        worker_device(1, device.name)


def test_a_shard_file_holds_its_tables_and_reference(device, tmp_path):
    config = MeasureConfig.from_scene(tiny_scene(device), "C1")
    config = dataclasses.replace(config, run=dataclasses.replace(config.run, device=device))
    result = run_render(None, case="C1", config=config, shard=(7, 14))
    path = tmp_path / "7-14.h5"
    write_shard(path, result)
    back = read_shard(path)
    tables = {"tracers": result.tracers, "rays": result.rays, **result.kinematics}
    read = {"tracers": back.tracers, "rays": back.rays, **back.kinematics}
    for group, table in tables.items():
        for name, values in (table or {}).items():
            np.testing.assert_array_equal(read[group][name], values, err_msg=name)
    assert back.ray_attrs == result.ray_attrs and back.config["shard"] == [7, 14]
    stored, made = back.reference, result.reference
    assert stored.key == made.key and stored.ray_counts == made.ray_counts
    for name in ("tracks", "true_velocity", "true_acceleration", "outside"):
        np.testing.assert_array_equal(getattr(stored, name), getattr(made, name))
    for name, values in made.images.items():
        np.testing.assert_array_equal(stored.images[name], values, err_msg=name)
    worker = SimpleNamespace(device=device)
    assert _reference_for(path, worker).key == made.key
    with h5py.File(path, "a") as h5:  # as if another kind of device had measured it
        key = json.loads(h5["reference"].attrs["key"])
        key["trace"]["device"]["device"] = "another GPU"
        h5["reference"].attrs["key"] = json.dumps(key)
    assert _reference_for(path, worker) is None


def test_a_worker_keeps_the_frames_of_the_latest_case():
    from rimcl.study.distributed import _CachedFrames

    with FieldFile(sample_path()) as file:
        frames = _CachedFrames(file, budget=1 << 30)
        assert frames.shape == file.shape and frames.path == file.path
        first = frames.field(0, 0.01)
        assert frames.field(0, 0.01) is first  # the next shard of the case: no reload
        assert frames.field(1, 0.01) is not first
        other = frames.field(0, 0.02)  # another case: the first one's frames are dropped
        np.testing.assert_array_equal(other.delta_n, 2 * first.delta_n)
        assert frames.field(0, 0.01) is not first
        tight = _CachedFrames(file, budget=first.delta_n.nbytes)  # too small for a frame
        assert tight.field(0, 0.01) is not tight.field(0, 0.01)


def test_without_dask_a_scheduler_is_one_clear_error(device, tmp_path, monkeypatch):
    monkeypatch.setitem(sys.modules, "distributed", None)  # import distributed fails
    with pytest.raises(RimclError, match=r"needs Dask distributed.*rimcl\[distributed\]"):
        run_study(tiny_scene(device), tmp_path, figures=False, scheduler="local:2")
    result = CliRunner().invoke(
        cli, ["study", "--out", str(tmp_path / "cli"), "--scheduler", "local:2"]
    )
    assert result.exit_code == 1
    assert result.output.strip().splitlines() == [
        "Error: scheduler 'local:2' needs Dask distributed, which is not installed: "
        'pip install "rimcl[distributed]"'
    ]


def test_cli_local_cluster_gives_the_single_process_numbers(single, device, tmp_path):
    scene_file = tmp_path / "scene.toml"
    scene_file.write_text(scene_text(tiny_scene(device)))
    out = tmp_path / "study"
    args = ["study", str(scene_file), "--out", str(out), "--scheduler", "local:2"]
    result = CliRunner().invoke(cli, [*args, "--no-progress", "--no-figures"])
    assert result.exit_code == 0, result.output
    assert "Dask: 2 local worker processes; dashboard http://127.0.0.1:" in result.output
    assert "[2/2] C4: 3 shard files merged (3 measured now" in result.output
    assert_same_study(single, out)
    for case in CASES:
        for shard in SHARDS:
            assert read_shard(shard_path(out, case, shard)).config["shard"] == list(shard)


class DieWhileWriting(distributed.WorkerPlugin):
    """The first worker to write shard file ``target`` of a case dies half-way through
    (``os._exit``, as a killed process), once: ``marker`` records that it happened."""

    name = "die-while-writing"

    def __init__(self, case, target, marker):
        self.case, self.target, self.marker = case, target, marker

    def setup(self, worker):
        import rimcl.ptv.render_file

        stamp = rimcl.ptv.render_file.stamp_h5

        def stamp_then_die(h5obj, *args, **kwargs):
            stamp(h5obj, *args, **kwargs)  # the file now holds attributes but no tables
            name = h5obj.file.filename
            if f"{os.sep}{self.case}{os.sep}" in name and self.target in name:
                if not os.path.exists(self.marker):
                    Path(self.marker).write_text(name)
                    os._exit(1)

        rimcl.ptv.render_file.stamp_h5 = stamp_then_die


def test_a_killed_worker_loses_nothing_and_a_rerun_redoes_only_missing_shards(
    single, device, cluster, tmp_path
):
    local, client = cluster
    marker = tmp_path / "killed"
    client.register_plugin(DieWhileWriting("C4", "7-14.h5", str(marker)))
    out = tmp_path / "study"
    scene = tiny_scene(device)
    try:
        result = run_study(scene, out, figures=False, scheduler=local.scheduler_address)
    finally:
        client.unregister_worker_plugin(DieWhileWriting.name)
    assert marker.exists(), "no worker died"
    assert ".7-14.h5." in marker.read_text()  # it died writing the temporary file
    assert result.ran == CASES
    assert_same_study(single, out)

    # a killed client: shard files but no case file; a lost shard file, and one of
    # another scene (as a forced single-process run of another scene leaves them)
    case_path(out, "C4").unlink()
    shard_path(out, "C4", (7, 14)).unlink()
    with h5py.File(shard_path(out, "C4", (14, 20)), "a") as h5:
        h5.attrs["study_scene"] = scene_stamp(
            StudyConfig.from_scene(tiny_scene(device, **{"tracers.seed": 1}))
        )
    kept = shard_path(out, "C4", (0, 7)).stat().st_mtime_ns
    lines = []
    # the rerun on the same cluster (a fresh one costs its processes' start and kernels)
    again = run_study(
        scene, out, figures=False, scheduler=local.scheduler_address, report=lines.append
    )
    assert again.skipped == ["C1"] and again.ran == ["C4"]
    assert "[2/2] C4: 3 shard files merged (2 measured now" in "\n".join(lines)
    assert shard_path(out, "C4", (0, 7)).stat().st_mtime_ns == kept
    assert_same_study(single, out)


def test_one_worker_gives_the_same_numbers(single, device, tmp_path, monkeypatch):
    # the default nannies of the cluster fixture put it into this process's environment
    monkeypatch.delenv("MALLOC_TRIM_THRESHOLD_", raising=False)
    lines = []
    with connect("local:1", "", device.name, report=lines.append) as (client, _):
        assert lines[-1] == f"1 workers: 1 x {device.name.strip()}"
        # glibc keeps its dynamic mmap threshold in the workers (see connect)
        assert client.run(os.environ.get, "MALLOC_TRIM_THRESHOLD_") == {
            address: None for address in client.scheduler_info()["workers"]
        }
        out = tmp_path / "study"
        run_study(tiny_scene(device), out, figures=False, scheduler=client.scheduler.address)
    assert_same_study(single, out)
