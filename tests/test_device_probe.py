"""An OpenCL device that cannot build rimcl's kernels is never a crash (issue 20, item 6):
the probe builds what the engines build in a child process, such devices are skipped,
and the choice among several PoCLs is the newest, whatever order the loader lists them."""

import sys
from types import SimpleNamespace

import pytest
from click.testing import CliRunner

import rimcl.core.device as dev
from rimcl.cli.main import cli
from rimcl.core.errors import RimclError
from rimcl.core.program import build_program, get_kernel

DEBIAN = "OpenCL 3.0 PoCL 3.1+debian  Linux, None+Asserts, RELOC, SPIR, LLVM 15.0.6, SLEEF"
WHEEL = "OpenCL 3.0 PoCL 3.0-rc2  Linux, Release, RELOC, LLVM 14.0.6, SLEEF, DISTRO"


def _fake(name, version, kind="cpu", platform="Portable Computing Language"):
    import pyopencl as cl

    return SimpleNamespace(
        name=name,
        type=cl.device_type.GPU if kind == "gpu" else cl.device_type.CPU,
        extensions="cl_khr_fp64",
        version=version.split("  ")[0],
        platform=SimpleNamespace(name=platform, version=version, vendor="vendor"),
    )


def test_pocl_versions_order_releases():
    assert dev.pocl_versions(_fake("a", DEBIAN)) == ((3, 1, 0, 1), (15, 0, 6, 1))
    assert dev.pocl_versions(_fake("b", WHEEL)) == ((3, 0, 0, 0), (14, 0, 6, 1))
    assert dev.pocl_versions(_fake("c", "OpenCL 3.0 CUDA 12.4", platform="NVIDIA CUDA")) is None


@pytest.mark.parametrize("wheel_first", [True, False])
def test_the_newest_pocl_is_chosen_whatever_the_loader_order(monkeypatch, wheel_first):
    debian, wheel = _fake("debian", DEBIAN), _fake("wheel", WHEEL)
    found = [(0, 0, wheel), (1, 0, debian)] if wheel_first else [(0, 0, debian), (1, 0, wheel)]
    monkeypatch.delenv("RIMCL_DEVICE", raising=False)
    monkeypatch.setattr(dev, "_all_devices", lambda: found)
    monkeypatch.setattr(dev, "build_problem", lambda device: "")
    assert dev.select_device() is debian
    assert dev.select_device("pocl") is debian
    gpu = _fake("gpu", "OpenCL 3.0 CUDA 12.4", "gpu", "NVIDIA CUDA")
    found.append((2, 0, gpu))
    assert dev.select_device() is gpu


def test_a_device_that_cannot_build_is_skipped_and_none_is_one_line(monkeypatch, tmp_path):
    debian, wheel = _fake("debian", DEBIAN), _fake("wheel", WHEEL)
    problems = {"debian": "image.cl: error: fma on double8", "wheel": ""}
    monkeypatch.delenv("RIMCL_DEVICE", raising=False)
    monkeypatch.setattr(dev, "_all_devices", lambda: [(0, 0, debian), (1, 0, wheel)])
    monkeypatch.setattr(dev, "build_problem", lambda device: problems[device.name])
    assert dev.select_device() is wheel
    with pytest.raises(RimclError, match=r"debian \(debian\) cannot build .*fma on double8"):
        dev.select_device("debian")
    assert dev.select_device("pocl") is wheel  # a spec matching both: the one that builds
    problems["wheel"] = "trace.cl: clCreateKernel failed: INVALID_KERNEL_NAME"
    with pytest.raises(
        RimclError,
        match=r"no OpenCL device can build rimcl's kernels .*"
        r"fma on double8.*INVALID_KERNEL_NAME.*pocl-opencl-icd",
    ):
        dev.select_device()
    out = str(tmp_path / "render.h5")
    result = CliRunner().invoke(cli, ["render", "--tracers", "2", "--fan", "2", "-o", out])
    assert result.exit_code == 1
    lines = result.output.strip().splitlines()
    assert len(lines) == 1 and "no OpenCL device can build" in lines[0], result.output


@pytest.fixture
def fresh_probe(tmp_path, monkeypatch):
    monkeypatch.setenv("RIMCL_CACHE_DIR", str(tmp_path))
    dev.build_problem.cache_clear()
    yield tmp_path
    dev.build_problem.cache_clear()


def test_the_probe_builds_in_a_child_and_keeps_the_answer(device, fresh_probe, monkeypatch):
    defines = {"RIMCL_RENDERER": 0, "RIMCL_CENTROID": 0}
    monkeypatch.setattr(dev, "probe_builds", lambda d: [("image.cl", ["no_such_kernel"], defines)])
    problem = dev.build_problem(device)
    assert problem.startswith("image.cl: ") and "INVALID_KERNEL_NAME" in problem
    assert len(list(fresh_probe.glob("device-probe-*.json"))) == 1
    dev.build_problem.cache_clear()
    monkeypatch.setattr(dev, "_probe_command", lambda: ["false"])  # the cache answers
    assert dev.build_problem(device) == problem


def test_a_failed_compile_names_the_compiler_error(device, fresh_probe, monkeypatch):
    monkeypatch.setattr(dev, "probe_builds", lambda d: [("image.cl", ["image_tracers"], {})])
    problem = dev.build_problem(device)
    assert problem.startswith("image.cl: ") and "RIMCL_RENDERER must be defined" in problem


def test_a_probe_that_crashes_is_a_problem_not_a_crash(device, fresh_probe, monkeypatch):
    code = "import sys; sys.stderr.write('LLVM ERROR: fma double8\\n'); import os; os.abort()"
    monkeypatch.setattr(dev, "_probe_command", lambda: [sys.executable, "-c", code])
    problem = dev.build_problem(device)
    assert problem == "building rimcl's kernels crashed (SIGABRT): LLVM ERROR: fma double8"


def test_the_default_probe_passes_on_the_chosen_device(device, fresh_probe):
    assert dev.build_problem(device) == ""


def test_engines_turn_build_and_kernel_failures_into_one_line(device):
    context = dev.context_for(device)
    with pytest.raises(RimclError, match=r"build of image.cl failed on .*RIMCL_RENDERER"):
        build_program(context, "image.cl", {"RIMCL_CENTROID": 0})
    program = build_program(context, "image.cl", {"RIMCL_RENDERER": 0, "RIMCL_CENTROID": 0})
    with pytest.raises(RimclError, match="kernel no_such_kernel cannot be created"):
        get_kernel(program, "no_such_kernel")
