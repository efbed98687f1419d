"""Seconds per PIV frame: the device engine against the NumPy engine, in one run.

Frame pairs of the shipped sample (plane camera, ``--rays`` rays per tracer as a fan of
round(sqrt(rays))², ``--pixels`` across, ``--density`` particles per pixel; defaults: 1024
px, 0.03 ppp, 256 rays), made by each engine from the same seed: the pair through a
uniform medium (straight rays: the cost of making, imaging and splatting the rays) and
the pair through case ``--case`` (default C2: the trace through the field adds its cost to
both engines alike). A small warm-up run builds every kernel first. Prints the wall time
per frame of each engine and pair, their stage times, the same-run ratios and how many
pixels' counts differ:

    python benchmarks/piv_frames.py                       # 1024² px, 256 rays, C2
    python benchmarks/piv_frames.py --pixels 512 --case G=0   # straight rays: imaging only
    python benchmarks/piv_frames.py --pixels 256 --rays 64 --device nvidia

Machines shared with other jobs drift by tens of per cent from minute to minute; only the
ratios of one run mean much. Say which CPU or GPU and what else ran beside the numbers.
"""

import argparse
import dataclasses

import numpy as np

from rimcl.core.device import describe_device, select_device
from rimcl.piv.imaging_config import PivImaging
from rimcl.piv.render import PivConfig, run_piv_render
from rimcl.scene.config import CameraConfig, RunConfig


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--pixels", type=int, default=1024)
    parser.add_argument("--density", type=float, default=0.03)
    parser.add_argument("--rays", type=int, default=256)
    parser.add_argument("--case", default="C2")
    parser.add_argument("--device", default=None)
    args = parser.parse_args()
    device = describe_device(select_device(args.device))
    print(f"device: {device['device'].strip()} ({device['platform']})")
    fan = round(args.rays**0.5)
    imaging = PivImaging(pixels=args.pixels, density=args.density)
    common = {"case": args.case, "camera": CameraConfig(kind="plane", fan=fan)}
    results = {}
    for engine in ("device", "numpy"):
        run = RunConfig(device=args.device, engine=engine)
        warm = PivConfig(imaging=dataclasses.replace(imaging, pixels=64))
        run_piv_render(**common, piv=warm, run=run)
        results[engine] = run_piv_render(**common, piv=PivConfig(imaging=imaging), run=run)
    tracers = results["device"].reference.positions.shape[1]
    print(f"{args.pixels}² px, {tracers} tracers, {fan * fan} rays each, case {args.case}")
    for medium in ("uniform", "field"):
        wall = {}
        for engine, result in results.items():
            frames = getattr(result, medium)
            wall[engine] = frames.seconds["wall"] / 2
            stages = ", ".join(
                f"{k} {v / 2:.2f} s" for k, v in frames.seconds.items() if k != "wall"
            )
            print(f"{medium:>7} {engine:>6}: {wall[engine]:.2f} s per frame ({stages})")
        counts = [getattr(r, medium).images.astype(np.int64) for r in results.values()]
        differ = np.count_nonzero(counts[0] != counts[1])
        print(
            f"{medium:>7} speed-up device / numpy (same run): "
            f"{wall['numpy'] / wall['device']:.1f}x; pixels whose counts differ: {differ} "
            f"of {counts[0].size} (at most {np.abs(counts[0] - counts[1]).max()} count)"
        )


if __name__ == "__main__":
    main()
