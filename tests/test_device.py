"""Device selection: never interactive, explicit spec, then RIMCL_DEVICE, then GPU, then CPU."""

from types import SimpleNamespace

import pytest

import rimcl
from rimcl.core.device import describe_device, list_devices
from rimcl.core.errors import RimclError


def test_spec_forms_select_the_device(device):
    entry = next(e for e in list_devices() if e["usable"] and e["device"] == device.name.strip())
    by_index = rimcl.select_device(entry["index"])
    assert by_index.name == device.name
    assert rimcl.select_device(device) is device
    part = device.name.strip().split("-")[0]
    assert not rimcl.core.device.build_problem(rimcl.select_device(part))


def test_environment_variable_is_used(device, monkeypatch):
    entry = next(e for e in list_devices() if e["usable"] and e["device"] == device.name.strip())
    monkeypatch.setenv("RIMCL_DEVICE", entry["index"])
    assert rimcl.select_device().name == device.name


def test_unknown_spec_is_one_clear_error(device, monkeypatch):
    monkeypatch.delenv("RIMCL_DEVICE", raising=False)
    with pytest.raises(RimclError, match="no OpenCL device"):
        rimcl.select_device("no-such-device-anywhere")
    with pytest.raises(RimclError, match="no OpenCL device '9:9'"):
        rimcl.select_device("9:9")


def test_device_description_lists_what_users_need(device):
    info = describe_device(device)
    for key in (
        "platform",
        "device",
        "opencl_version",
        "compute_units",
        "fp64",
        "images",
        "usable",
    ):
        assert key in info
    # PoCL reports global memory as a share of the host's free memory: a record that held it
    # would differ between two processes on the same device (a Dask worker and the client)
    assert "global_memory_mib" not in info
    assert all(entry["global_memory_mib"] > 0 for entry in rimcl.list_devices())
    assert info["usable"] is True
    assert sum(entry["default"] for entry in list_devices()) == 1


class _FakeDevice:
    def __init__(self, name, kind, fp64):
        import pyopencl as cl

        self.name = name
        self.type = cl.device_type.GPU if kind == "gpu" else cl.device_type.CPU
        self.extensions = "cl_khr_fp64" if fp64 else "cl_khr_global_int32_base_atomics"
        self.platform = SimpleNamespace(name=name, version="OpenCL 3.0")


def test_the_device_engine_prefers_a_device_with_fp64(monkeypatch):
    """A laptop's integrated GPU without fp64 is the default device, but not the device
    engine's: it takes the first device with fp64 (here the CPU)."""
    import rimcl.core.device

    igpu, cpu = _FakeDevice("igpu", "gpu", False), _FakeDevice("pocl", "cpu", True)
    found = [(0, 0, igpu), (1, 0, cpu)]
    monkeypatch.delenv("RIMCL_DEVICE", raising=False)
    monkeypatch.setattr(rimcl.core.device, "_all_devices", lambda: found)
    monkeypatch.setattr(rimcl.core.device, "build_problem", lambda device: "")
    assert rimcl.core.device.select_device() is igpu
    assert rimcl.core.device.select_device(need_fp64=True) is cpu
    found[1] = (1, 0, _FakeDevice("old", "cpu", False))
    assert rimcl.core.device.select_device(need_fp64=True) is igpu  # none has it: the usual order
