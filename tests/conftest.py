"""Shared fixtures: ``device``, the OpenCL device rimcl would choose (PoCL in CI).

``RIMCL_TEST_DEVICE`` picks another (a spec as for ``--device``), or ``all`` runs every
device test on every usable device. Devices that cannot build rimcl's kernels are never
used (:func:`rimcl.core.device.build_problem` probes them in a child process). Without any
usable OpenCL device the kernel tests are skipped, unless ``RIMCL_REQUIRE_OPENCL=1`` (set
by CI), which makes them fail instead.
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
        from rimcl.core.device import _all_devices, _preferred_first, build_problem, select_device

        wanted = os.environ.get("RIMCL_TEST_DEVICE") or None
        if wanted == "all":
            found = _preferred_first(_all_devices())
            devices = [d for _, _, d in found if not build_problem(d)]
            if not devices:
                return [], "no OpenCL device can build rimcl's kernels (see 'rimcl devices')"
            return devices, ""
        return [select_device(wanted)], ""
    except (RimclError, ImportError) as exc:
        return [], str(exc)


_DEVICES, _WHY_NONE = _devices()


def _device_id(device):
    return device.name.strip().split()[0].lower() if device is not None else "none"


@pytest.fixture(scope="session", params=_DEVICES or [None], ids=_device_id)
def device(request):
    """The device rimcl would choose (``RIMCL_TEST_DEVICE``: another, or ``all``)."""
    if request.param is None:
        if REQUIRE_OPENCL:
            pytest.fail(f"RIMCL_REQUIRE_OPENCL=1 but no OpenCL device: {_WHY_NONE}")
        pytest.skip(f"no OpenCL device: {_WHY_NONE}")
    return request.param


@pytest.fixture(scope="session")
def has_fp64(device):
    from rimcl.core.device import has_fp64

    return has_fp64(device)


@pytest.fixture(scope="session")
def lpt_flow(tmp_path_factory):
    """A tiny flow with full velocity for LPT runs (16³, 5 frames 0.04 apart), made once."""
    from rimcl.fields.synth import synthesize, write_synth

    result = synthesize(grid=16, seed=2, frames=5, frame_dt=0.04, t_start=0.5)
    return write_synth(result, tmp_path_factory.mktemp("flow") / "flow16.h5")
