"""Shared fixtures: one ``device`` per OpenCL device found (PoCL in CI).

Without any OpenCL device the kernel tests are skipped, unless
``RIMCL_REQUIRE_OPENCL=1`` (set by CI), which makes them fail instead.
"""

import os

import pytest

from rimcl.core.errors import RimclError

REQUIRE_OPENCL = os.environ.get("RIMCL_REQUIRE_OPENCL") == "1"
# the rule-based kernel shapes: no timed tuning of a device's shapes during the suite,
# nor a user's cached shapes (tests of the tuning set RIMCL_TUNE and RIMCL_SHAPE_CACHE)
os.environ["RIMCL_TUNE"] = "off"


def _devices():
    try:
        from rimcl.core.device import _all_devices, build_problem

        found = _all_devices()
    except (RimclError, ImportError) as exc:
        return [], str(exc)
    wanted = os.environ.get("RIMCL_TEST_DEVICE")
    devices = [d for _, _, d in found if not build_problem(d)]
    if not devices:
        return [], "no OpenCL device can compile kernels (see 'rimcl devices')"
    if wanted:
        from rimcl.core.device import select_device

        devices = [select_device(wanted)]
    return devices, ""


_DEVICES, _WHY_NONE = _devices()


def _device_id(device):
    return device.name.strip().split()[0].lower() if device is not None else "none"


@pytest.fixture(scope="session", params=_DEVICES or [None], ids=_device_id)
def device(request):
    """Every OpenCL device in turn (``RIMCL_TEST_DEVICE`` picks one)."""
    if request.param is None:
        if REQUIRE_OPENCL:
            pytest.fail(f"RIMCL_REQUIRE_OPENCL=1 but no OpenCL device: {_WHY_NONE}")
        pytest.skip(f"no OpenCL device: {_WHY_NONE}")
    return request.param


@pytest.fixture(scope="session")
def has_fp64(device):
    from rimcl.core.device import has_fp64

    return has_fp64(device)
