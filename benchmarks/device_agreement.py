"""Trace one fixed ray set on a device and save the results, or compare two saved runs.

Used to check that kernels agree between devices (PoCL against NVIDIA, say):

    python benchmarks/device_agreement.py trace --device pocl -o pocl.npz
    python benchmarks/device_agreement.py trace --device nvidia -o gpu.npz
    python benchmarks/device_agreement.py compare pocl.npz gpu.npz

The field is a seeded smooth random 64³ field with water-like index differences
(Δn = 1e-2) and the rays a seeded fan; every precision the device offers is traced.
"""

import argparse
import time

import numpy as np

import rimcl
from rimcl.core.device import has_fp64


def make_case(count=4096, seed=7):
    rng = np.random.default_rng(seed)
    size = 64
    h = 2 * np.pi / size
    x = h * np.arange(size)
    x3, x2, x1 = np.meshgrid(x, x, x, indexing="ij")
    values = np.zeros((size, size, size))
    for _ in range(8):
        k = rng.integers(-3, 4, size=3)
        values += np.cos(k[0] * x1 + k[1] * x2 + k[2] * x3 + rng.uniform(0, 2 * np.pi))
    values *= 1e-2 / np.ptp(values)
    field = rimcl.Field.from_arrays(values, spacing=(h, h, h), n_ref=1.333, boundary="periodic")
    origins = np.column_stack([np.zeros(count), rng.uniform(0, 2 * np.pi, (count, 2))])
    aims = np.column_stack([np.full(count, 2 * np.pi), rng.uniform(0, 2 * np.pi, (count, 2))])
    directions = aims - origins
    return field, origins, directions / np.linalg.norm(directions, axis=1, keepdims=True)


def trace(args):
    device = rimcl.select_device(args.device)
    field, origins, directions = make_case()
    saved = {"device": device.name.strip()}
    for precision in ("f32", "f32c", "f64"):
        if precision == "f64" and not has_fp64(device):
            continue
        for interp in args.interp:
            kwargs = dict(x_end=2 * np.pi, precision=precision, interp=interp, device=device)
            # warm up with the same ray count: PoCL specialises kernels per launch size
            rimcl.trace_rays(field, origins, directions, **kwargs)
            start = time.perf_counter()
            result = rimcl.trace_rays(field, origins, directions, **kwargs)
            elapsed = time.perf_counter() - start
            key = f"{interp}_{precision}"
            saved[f"{key}_image_pos"] = result.image_pos
            saved[f"{key}_status"] = result.status
            rate = result.steps.sum() / elapsed
            print(f"{device.name.strip()}: {key}: {rate:.3g} ray-steps/s, {result.counts}")
    np.savez(args.output, **saved)


def compare(args):
    first, second = np.load(args.first), np.load(args.second)
    print(f"{first['device']} against {second['device']}")
    for key in sorted(k for k in first.files if k.endswith("_image_pos") and k in second.files):
        ok = (first[key.replace("image_pos", "status")] == 0) & (
            second[key.replace("image_pos", "status")] == 0
        )
        diff = np.abs(first[key][ok] - second[key][ok]).max()
        print(
            f"{key.removesuffix('_image_pos'):>20}: max |r'_a - r'_b| = {diff:.2e} "
            f"over {ok.sum()} rays (L = 2π)"
        )


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(required=True)
    run = sub.add_parser("trace")
    run.add_argument("--device", default=None)
    run.add_argument("--interp", nargs="+", default=["trilinear"])
    run.add_argument("-o", "--output", required=True)
    run.set_defaults(func=trace)
    both = sub.add_parser("compare")
    both.add_argument("first")
    both.add_argument("second")
    both.set_defaults(func=compare)
    args = parser.parse_args()
    args.func(args)


if __name__ == "__main__":
    main()
