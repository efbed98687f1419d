"""Every kernel file builds for every define set it documents."""

import itertools

import pytest

from rimcl.core.device import context_for, is_pocl
from rimcl.core.program import build_program, get_kernel, kernel_files


def _product(**choices):
    names = sorted(choices)
    for values in itertools.product(*(choices[name] for name in names)):
        yield dict(zip(names, values, strict=True))


# file -> (kernel names, list of define sets)
DEFINE_SETS = {
    "trace.cl": (
        ("trace_rays",),
        [
            *_product(RIMCL_PRECISION=(0, 1, 2), RIMCL_FIELD=(1, 2, 3, 4), RIMCL_PERIODIC=(0,)),
            *_product(RIMCL_PRECISION=(0, 1, 2), RIMCL_FIELD=(0,), RIMCL_PERIODIC=(0, 1)),
            # interpolations in the CPU shape (8 rays per work-item, PoCL switch) ...
            *_product(
                RIMCL_PRECISION=(0, 1, 2),
                RIMCL_FIELD=(0,),
                RIMCL_INTERP=(0, 1, 2),
                RIMCL_PERIODIC=(0, 1),
                RIMCL_LANES=(8,),
                RIMCL_POCL_FAST=(1,),
            ),
            # ... and in the GPU shape (one ray per work-item, standard functions)
            *_product(
                RIMCL_PRECISION=(0, 1, 2),
                RIMCL_FIELD=(0,),
                RIMCL_INTERP=(1, 2),
                RIMCL_PERIODIC=(0, 1),
            ),
            # adaptive steps, other lane widths, closed forms in lanes
            *_product(
                RIMCL_PRECISION=(0, 1, 2),
                RIMCL_FIELD=(0,),
                RIMCL_INTERP=(0, 2),
                RIMCL_ADAPTIVE=(1,),
                RIMCL_LANES=(1, 8),
            ),
            *_product(RIMCL_PRECISION=(1,), RIMCL_FIELD=(0,), RIMCL_LANES=(2, 4, 16)),
            *_product(
                RIMCL_PRECISION=(1, 2),
                RIMCL_FIELD=(1, 2, 3, 4),
                RIMCL_LANES=(8,),
                RIMCL_POCL_FAST=(1,),
                RIMCL_ADAPTIVE=(0, 1),
            ),
        ],
    ),
    # the device engine: camera fans (plane, pupil, lens behind a window) in both kernel
    # shapes; image kernels
    "fan.cl": (
        ("trace_fan", "fan_directions"),
        [
            *_product(RIMCL_PRECISION=(0, 1, 2), RIMCL_FIELD=(0,), RIMCL_CAMERA=(0, 1, 2)),
            *_product(
                RIMCL_PRECISION=(1,),
                RIMCL_FIELD=(0,),
                RIMCL_INTERP=(0, 1, 2),
                RIMCL_PERIODIC=(0, 1),
                RIMCL_CAMERA=(0, 1, 2),
                RIMCL_LANES=(16,),
                RIMCL_POCL_FAST=(1,),
            ),
            *_product(
                RIMCL_PRECISION=(1,), RIMCL_FIELD=(2,), RIMCL_CAMERA=(1,), RIMCL_ADAPTIVE=(1,)
            ),
        ],
    ),
    "image.cl": (
        ("image_tracers",),
        [
            *_product(RIMCL_RENDERER=(0, 1), RIMCL_CENTROID=(0, 1)),
            *_product(RIMCL_RENDERER=(0, 1), RIMCL_CENTROID=(0,), RIMCL_POCL_FAST=(1,)),
            *_product(RIMCL_RENDERER=(0, 1), RIMCL_CENTROID=(0,), RIMCL_NOISE=(1,)),
            *_product(
                RIMCL_RENDERER=(0,), RIMCL_CENTROID=(1,), RIMCL_NOISE=(1,), RIMCL_POCL_FAST=(1,)
            ),
        ],
    ),
    "frame.cl": (
        (
            "tracer_rows",
            "splat_tiles",
        ),
        [*_product(RIMCL_MIE=(0, 1), RIMCL_TILE=(16, 32, 64), RIMCL_POCL_FAST=(0, 1))],
    ),
}


def _cases():
    for filename, (kernels, define_sets) in DEFINE_SETS.items():
        for defines in define_sets:
            label = "-".join(f"{k.removeprefix('RIMCL_')}={v}" for k, v in defines.items())
            yield pytest.param(filename, kernels, defines, id=f"{filename}-{label}")


def test_every_kernel_file_is_covered():
    assert set(kernel_files()) == set(DEFINE_SETS)


@pytest.mark.parametrize(("filename", "kernels", "defines"), list(_cases()))
def test_kernel_builds(device, has_fp64, filename, kernels, defines):
    if defines.get("RIMCL_PRECISION") == 2 and not has_fp64:
        pytest.skip("f64 needs cl_khr_fp64")
    if defines.get("RIMCL_POCL_FAST") and not is_pocl(device):
        pytest.skip("the PoCL switch uses clang builtins that only PoCL is asked to build")
    program = build_program(context_for(device), filename, defines)
    for name in kernels:
        assert get_kernel(program, name).function_name == name
