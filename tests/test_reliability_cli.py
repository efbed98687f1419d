"""One error path, memory checked before it is spent, documented inputs, honest statuses."""

import errno
import json
import resource
import subprocess
import sys

import h5py
import numpy as np
import pytest
from click.testing import CliRunner

import rimcl.fields.info
import rimcl.optics.bench
from rimcl.cli.main import cli
from rimcl.core.errors import RimclError
from rimcl.core.memory import check_field_upload
from rimcl.fields.field import Field
from rimcl.fields.field_writer import write_field
from rimcl.optics.rays import read_rays
from rimcl.optics.trace import STATUS_NAMES, _finish
from rimcl.optics.tracing import trace_rays

# Address space a refusing process may use: the interpreter, NumPy, h5py and click.
ADDRESS_SPACE = 1536 * 2**20


def one_error_line(result):
    assert result.exit_code == 1, result.output
    assert isinstance(result.exception, SystemExit), repr(result.exception)
    lines = [line for line in result.output.splitlines() if line.strip()]
    assert len(lines) == 1 and lines[0].startswith("Error: "), result.output
    return lines[0]


def run(*args):
    return CliRunner().invoke(cli, [str(arg) for arg in args])


def declare_huge_field(path, chunks):
    """A few kB on disk declaring one 1024³ float32 frame (4 GiB) of fill values."""
    with h5py.File(path, "w") as h5:
        h5.attrs["rimcl_schema"] = "field"
        h5.attrs["schema_version"] = 1
        grid = h5.create_group("grid")
        grid.attrs["origin"] = np.zeros(3)
        grid.attrs["spacing"] = np.ones(3)
        frame = h5.create_group("frames/0000")
        frame.attrs["time"] = 0.0
        frame.create_dataset("density", shape=(1024,) * 3, dtype="f4", chunks=chunks,
                             fillvalue=1.0)  # fmt: skip
    assert path.stat().st_size < 64 * 1024
    return path


@pytest.fixture(scope="module")
def huge_declared(tmp_path_factory):
    return declare_huge_field(tmp_path_factory.mktemp("huge") / "huge.h5", (1, 1024, 1024))


def _limited(*args):
    """``rimcl ARGS`` in a process whose address space is limited to ADDRESS_SPACE."""

    def limit():
        resource.setrlimit(resource.RLIMIT_AS, (ADDRESS_SPACE, ADDRESS_SPACE))

    return subprocess.run(
        [sys.executable, "-c", "from rimcl.cli.main import cli; cli()", *map(str, args)],
        capture_output=True,
        text=True,
        preexec_fn=limit,
        timeout=120,
    )


@pytest.mark.skipif(sys.platform != "linux", reason="RLIMIT_AS as Linux counts it")
def test_a_tiny_file_declaring_a_huge_grid_is_refused_under_a_memory_limit(huge_declared, tmp_path):
    # trace reads the frame as a field (as render, study, field show do: FieldFile.field)
    output = tmp_path / "out.h5"
    done = _limited("trace", "--field", huge_declared, "-o", output)
    assert done.returncode == 1, done.stderr
    assert "Traceback" not in done.stderr and done.stdout == ""
    (line,) = done.stderr.strip().splitlines()
    assert "1024 x 1024 x 1024 nodes" in line and "needs about 96.0 GiB of memory" in line
    number, unit = line.split("only ")[1].split()[:2]
    available = float(number) * 1024 ** ["bytes", "KiB", "MiB", "GiB"].index(unit)
    assert 0 < available < ADDRESS_SPACE
    assert not output.exists() and not list(tmp_path.glob(".*.part"))
    # metadata alone answers at once, whatever the declared grid
    done = _limited("field", "info", "--json", huge_declared)
    assert done.returncode == 0, done.stderr
    info = json.loads(done.stdout)
    assert info["shape_n3_n2_n1"] == [1024] * 3 and "frames" not in info
    assert info["storage"]["density"]["declared_bytes"] == 4 * 1024**3
    assert info["storage"]["density"]["stored_bytes"] < 64 * 1024
    # streaming the values is bounded too: a chunk too large to decompress is refused
    chunky = declare_huge_field(tmp_path / "chunky.h5", (512, 1024, 1024))
    done = _limited("field", "info", "--values", chunky)
    assert done.returncode == 1 and "Traceback" not in done.stderr
    assert "one chunk of density of frame /frames/0000" in done.stderr
    assert "needs about 4.0 GiB of memory" in done.stderr


@pytest.mark.parametrize(
    ("args", "needs"),
    [
        (
            ["trace", "--tracers", "1000000000000", "--fan", "32"],
            "tracing 1,024,000,000,000,000 rays needs",
        ),
        (["trace", "--fan", "30000", "--tracers", "10"], "tracing 9,000,000,000 rays needs"),
        (["render", "--tracers", "1000000000000"], "rendering 1,000,000,000,000 tracers"),
        (["render", "--fan", "30000"], "x 900,000,000 rays"),
        (["field", "synth", "--grid", "4096"], "the solver on a 4096³ grid"),
    ],
)
def test_options_implying_more_memory_than_there_is_are_refused(tmp_path, args, needs):
    output = tmp_path / "out.h5"
    line = one_error_line(run(*args, "-o", output))
    assert needs in line and "of memory, but only" in line and "available" in line
    assert not output.exists()


@pytest.mark.parametrize(
    ("args", "option"),
    [
        (["trace", "--max-steps", "0"], "--max-steps"),
        (["trace", "--max-steps", "4294967296"], "--max-steps"),
        (["trace", "--seed", "-1"], "--seed"),
        (["trace", "--fan", "0"], "--fan"),
        (["trace", "--step", "inf"], "--step"),
        (["trace", "--tolerance", "nan"], "--tolerance"),
        (["render", "--tracers", "0"], "--tracers"),
        (["render", "--psf-sigma", "-1"], "--psf-sigma"),
        (["render", "--margin", "0.7"], "--margin"),
        (["render", "--threshold", "inf"], "--threshold"),
        (["field", "synth", "--reynolds", "inf"], "--reynolds"),
        (["field", "synth", "--seed", "-3"], "--seed"),
        (["field", "synth", "--dt", "0"], "--dt"),
        (["field", "import", "x.h5", "--period", "-1"], "--period"),
        (["study", "--step", "nan"], "--step"),
        (["bench", "--pixels", "0"], "--pixels"),
    ],
)
def test_numbers_out_of_range_are_usage_errors(tmp_path, args, option):
    result = run(*args, "-o" if args[0] != "study" and args[0] != "bench" else "--out",
                 tmp_path / "out")  # fmt: skip
    assert result.exit_code == 2, result.output
    assert "Invalid value for" in result.output and option in result.output
    assert "Traceback" not in result.output


@pytest.mark.parametrize(
    ("failure", "words"),
    [
        (KeyError("n_ref"), "KeyError: 'n_ref' (rimcl -v shows where)"),
        (ZeroDivisionError("float division by zero"), "ZeroDivisionError: float division"),
        (OverflowError("int too large"), "OverflowError: int too large"),
        (MemoryError("Unable to allocate 32.0 GiB"), "out of memory (Unable to allocate 32.0"),
        (
            OSError(errno.ENOSPC, "No space left on device\nwhile writing chunk 7\n", "f.h5"),
            "the disk is full (no space left on device writing f.h5)",
        ),
        (RuntimeError("line one\nline two"), "RuntimeError: line one (rimcl -v shows where)"),
    ],
)
def test_any_failure_is_one_line_and_a_traceback_only_with_v(monkeypatch, failure, words):
    def broken(*args, **kwargs):
        raise failure

    monkeypatch.setattr(rimcl.fields.info, "describe_field_file", broken)
    line = one_error_line(run("field", "info"))
    assert words in line
    verbose = run("-v", "field", "info")
    assert verbose.exit_code == 1 and verbose.exception is failure


def test_a_binary_scene_file_is_named(tmp_path):
    scene = tmp_path / "scene.toml"
    scene.write_bytes(b"\x89PNG\r\n\x1a\n\x00\xff\xfe")
    line = one_error_line(run("study", scene, "--out", tmp_path / "out"))
    assert line == f"Error: scene file {scene} is not text (a TOML scene is UTF-8 text)"
    assert not (tmp_path / "out").exists()


def test_a_ray_csv_with_the_documented_header_is_read(tmp_path):
    rays = np.array([[0.0, 1.0, 2.0, 1.0, 0.0, 0.0], [0.5, 1.5, 2.5, 0.8, 0.6, 0.0]])
    header = tmp_path / "header.csv"
    header.write_text("x1,x2,x3,d1,d2,d3\n" + "\n".join(",".join(map(str, r)) for r in rays))
    origins, directions = read_rays(header)
    np.testing.assert_array_equal(origins, rays[:, :3])
    np.testing.assert_array_equal(directions, rays[:, 3:])
    empty = tmp_path / "empty.csv"
    empty.write_text("x1,x2,x3,d1,d2,d3\n")
    line = one_error_line(run("trace", "--rays", empty, "-o", tmp_path / "t.h5"))
    assert line == f"Error: {empty} holds no rays"


G = 2.82e-4  # C1


@pytest.fixture(scope="module")
def twin_files(tmp_path_factory):
    """The same flow as a density file and as the delta_n file C1 makes of it."""
    folder = tmp_path_factory.mktemp("twins")
    rng = np.random.default_rng(3)
    x = np.linspace(0, 2 * np.pi, 12, endpoint=False)
    density = [
        (1.05 + 0.05 * np.sin(x[None, None, :] + k) * np.cos(x[:, None, None])).repeat(1, 1)
        * np.ones((12, 12, 12))
        for k in range(3)
    ]
    velocity = [0.1 * rng.standard_normal((12, 12, 12, 3)) for _ in range(3)]
    common = dict(times=[0.0, 0.01, 0.02], origin=(0, 0, 0), spacing=(0.5,) * 3,
                  velocity=velocity)  # fmt: skip
    density_path = write_field(folder / "density.h5", density=density, **common)
    means = [float(np.mean(d.astype(np.float32), dtype=np.float64)) for d in density]
    delta_n = [
        G * (d.astype(np.float32).astype(np.float64) - m)
        for d, m in zip(density, means, strict=True)
    ]
    delta_path = write_field(
        folder / "delta_n.h5", delta_n=delta_n, n_ref=[1 + G * m for m in means], **common
    )
    return density_path, delta_path


def test_a_delta_n_file_traces_as_its_density_twin(device, twin_files, tmp_path):
    density_path, delta_path = twin_files
    results = []
    for path, case in ((density_path, ["--case", "C1"]), (delta_path, [])):
        output = tmp_path / f"{path.stem}-trace.h5"
        result = run("trace", "--field", path, *case, "--tracers", 3, "--fan", 4,
                     "--device", device.name, "-o", output)  # fmt: skip
        assert result.exit_code == 0, result.output
        with h5py.File(output, "r") as h5:
            results.append(h5["rays/image_pos"][()])
    # the same refractive index up to float32 rounding of the stored δn (1e-7 of G Δρ)
    np.testing.assert_allclose(results[0], results[1], rtol=0, atol=1e-9)
    line = one_error_line(run("trace", "--field", delta_path, "--case", "C4",
                              "-o", tmp_path / "no.h5"))  # fmt: skip
    assert "stores delta_n (its own refractive index); a case or K*rho does not apply" in line


def test_a_delta_n_file_renders_and_benchmarks(device, twin_files, tmp_path):
    _, delta_path = twin_files
    output = tmp_path / "render.h5"
    result = run("render", "--field", delta_path, "--tracers", 4, "--fan", 4, "--pixels", 128,
                 "--frames", 3, "--device", device.name, "-o", output)  # fmt: skip
    assert result.exit_code == 0, result.output
    with h5py.File(output, "r") as h5:
        assert h5.attrs["case"] == "delta_n" and np.isnan(h5.attrs["k_rho"])
    (case,) = rimcl.optics.bench.bench_cases(delta_path, ["C1", "C4"], quick=True)
    assert case.name == "delta_n" and case.k_rho is None
    with h5py.File(delta_path, "r") as h5:
        stored = h5["frames/0000/delta_n"][()]
    np.testing.assert_array_equal(case.field.delta_n, stored)


def test_bench_never_replaces_earlier_results_on_a_failing_run(tmp_path, monkeypatch):
    earlier = {name: f"earlier {name}\n" for name in ("bench.csv", "bench.json", "bench.png")}
    for name, text in earlier.items():
        (tmp_path / name).write_text(text)
    line = one_error_line(run("bench", "--out", tmp_path, "--cases", ""))
    assert "name at least one case" in line
    row = dict.fromkeys(rimcl.optics.bench.CSV_COLUMNS, 0.0)
    meta = {"device": {"device": "none"}, "references": {}, "cases": []}
    monkeypatch.setattr(rimcl.optics.bench, "bench_cases", lambda *a, **k: [])
    monkeypatch.setattr(rimcl.optics.bench, "run_bench", lambda *a, **k: ([row], dict(meta)))

    def disk_full(*args):
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(rimcl.optics.bench, "plot_pareto", disk_full)
    line = one_error_line(run("bench", "--out", tmp_path, "--cases", "C1"))
    assert "the disk is full" in line
    for name, text in earlier.items():
        assert (tmp_path / name).read_text() == text
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(earlier)


def test_rays_with_non_finite_outputs_are_non_finite_never_ok():
    count = 4
    raw_out = np.zeros((count, 17), dtype=np.float32)
    raw_out[:, 0] = 1.0  # end x1 = 1
    raw_out[:, 6] = 1.0  # end direction along x1
    raw_out[:, 12] = raw_out[:, 13] = 1.0  # path lengths
    raw_out[1, 7] = np.nan  # ok by the kernel, NaN direction
    raw_out[2, 13] = np.inf  # ok by the kernel, infinite optical path
    info = np.zeros((count, 4), dtype=np.int32)
    info[3, 1] = STATUS_NAMES.index("exit_side")
    origins = np.zeros((count, 3))
    directions = np.tile([1.0, 0.0, 0.0], (count, 1))
    result = _finish(origins, directions, raw_out, info, 0.1, {})
    assert result.status.tolist() == [0, 4, 4, 1]
    assert sum(result.counts.values()) == count
    assert np.all(np.isfinite(result.image_pos[result.ok]))
    assert np.all(np.isnan(result.image_pos[~result.ok]))
    np.testing.assert_array_equal(result.image_pos[0], [0.0, 0.0, 0.0])


def test_an_absurd_grid_spacing_gives_non_finite_rays_not_ok_ones(device):
    rng = np.random.default_rng(0)
    field = Field.from_arrays(1e-4 * rng.standard_normal((8, 8, 8)), spacing=(1e25,) * 3)
    x_end = 7e25
    origins = np.column_stack([np.zeros(16), rng.uniform(1e25, 6e25, (16, 2))])
    directions = np.column_stack([np.ones(16), rng.uniform(-0.2, 0.2, (16, 2))])
    result = trace_rays(field, origins, directions, x_end=x_end, device=device)
    assert sum(result.counts.values()) == 16
    assert result.counts["non_finite"] > 0
    finite = np.isfinite(result.image_pos).all(axis=1) & np.isfinite(result.path_length)
    assert np.all(finite[result.ok])


def test_field_info_reads_metadata_only_and_streams_values_on_request(huge_declared, monkeypatch):
    def no_reading(*args, **kwargs):
        raise AssertionError("field info read frame data")

    monkeypatch.setattr(rimcl.fields.field_reader.FieldFile, "_read", no_reading)
    info = rimcl.fields.info.describe_field_file(huge_declared)
    assert info["memory_bytes_per_frame"]["field_trilinear"] == 16 * 1024**3
    assert "frames" not in info and "delta_n_max" not in info


class _SmallDevice:
    """The memory figures of an OpenCL device with 8 GiB, at most 2 GiB per buffer."""

    name = "small device "
    global_mem_size = 8 * 2**30
    max_mem_alloc_size = 2 * 2**30


def test_field_uploads_are_checked_against_the_device():
    check_field_upload((512, 512, 512), _SmallDevice(), "trilinear")  # 2.0 GiB: fits
    with pytest.raises(RimclError, match=r"needs one buffer of 3\.2 GiB.* allows is 2\.0 GiB"):
        check_field_upload((600, 600, 600), _SmallDevice(), "trilinear")
    check_field_upload((1024, 1024, 512), _SmallDevice(), "bspline3")  # 4 bytes a node
    with pytest.raises(RimclError, match=r"16\.0 GiB of device memory, but small device has 8"):
        check_field_upload((1024, 1024, 1024), _SmallDevice(), "texture")
