"""End-to-end speed of the measurement through both engines, on any device, in one run.

Two scenes, each through ``engine = "numpy"`` (trace on the device, images tracer by
tracer in NumPy) and ``engine = "device"`` (:mod:`rimcl.imaging.engine`: rays stay on the device
until per-tracer rows come back), each engine making a reference once per configuration
and reusing it for every case of that configuration, as ``rimcl study`` does (the default
lens is focused in each case's mean index, so its cases need references of their own):

- ``default study``: the built-in scene of ``rimcl study`` (shipped 64³ sample, 400
  tracers, the lens camera: 256 rays per tracer over its pupil, 2048² px sensor, its
  diffraction-limited point spread, a 10 mm window; Mie weights and sensor noise; cases
  C0-C4, 5 frames);
- ``paper density``: the same scene through the paper's plane camera with its 100 x 100
  = 1e4 rays per tracer (``camera.kind = "plane"``, ``camera.fan = 100``; 2048 px, σ 7 px;
  fewer tracers: ``--paper-tracers``).

Printed per scene and engine: wall time, stage times (``trace``: the trace kernel, or for
the device engine the fan kernel that also back-projects; ``render`` and ``centroid``: the
NumPy engine's stages, or the device engine's image kernel, which does both), host CPU
time per tracer image of the device engine (the main thread's CPU time in the engine's
frame loop: preparing batches, reading rows, forming columns; the run's fixed ray sample
excluded), rays per second end to end
(rays traced / wall time, reference included), and the ratio of the wall times
numpy / device. Machines drift by 30-40 % from minute to minute: only the
ratios of one run mean anything.

    python benchmarks/pipeline.py                      # default device
    python benchmarks/pipeline.py --device nvidia --paper-tracers 300 --json gpu.json
    python benchmarks/pipeline.py --profile            # + cProfile of the device engine's host
    python benchmarks/pipeline.py --device nvidia --scale-run 100000   # + the paper-scale run

``--scale-run N`` adds, on the device engine only, one case (C1) of ``N`` tracers x 1e4
rays x 3 frames plus its reference, end to end (the H100 target: 1e5 tracers in under
2 minutes).
"""

import argparse
import cProfile
import dataclasses
import io
import pstats
import time

from rimcl.core.device import describe_device, select_device
from rimcl.core.provenance import to_json, versions
from rimcl.ptv.measure import run_render
from rimcl.scene.config import MeasureConfig
from rimcl.scene.load import load_scene

ENGINES = ("numpy", "device")
TIMINGS = ("track", "trace", "render", "centroid", "engine_host", "ray_sample")


#: The paper-density scene: the default scene through the paper's plane camera and its
#: 100 x 100 fan (the default lens camera has its own ray count, which ``fan`` does not set).
PAPER_DENSITY = {"camera.kind": "plane", "camera.fan": 100}


def configs(scene, cases, engine, device, tracers=None):
    """The measurement configuration of each case of ``scene`` for ``engine``."""
    out = {}
    for case in cases:
        config = MeasureConfig.from_scene(scene, case)
        run = dataclasses.replace(config.run, engine=engine, device=device)
        count = (
            config.tracers
            if tracers is None
            else dataclasses.replace(config.tracers, count=tracers)
        )
        out[case] = dataclasses.replace(config, run=run, tracers=count)
    return out


def run_scene(per_engine):
    """Every case through every engine, interleaved case by case (so both engines see the
    same machine load), each engine making its reference once, as a study does."""
    rows = {
        engine: {"wall_s": 0.0, "rays": 0, "images": 0, **dict.fromkeys(TIMINGS, 0.0)}
        for engine in per_engine
    }
    # each engine's references so far: a case reuses the one made for its configuration (a
    # lens is focused in each case's mean index, so its cases need references of their own)
    references = {engine: [] for engine in per_engine}
    cases = next(iter(per_engine.values()))
    for case in cases:
        for engine, per_case in per_engine.items():
            start = time.perf_counter()
            result = run_render(
                None, case=case, config=per_case[case], reference=references[engine]
            )
            row = rows[engine]
            row["wall_s"] += time.perf_counter() - start
            made = all(r is not result.reference for r in references[engine])
            passes = 2 if made else 1  # a case that made its reference imaged twice
            if made:
                references[engine].append(result.reference)
            frames, count = result.attrs["n_frames"], result.attrs["n_tracers"]
            row.update(tracers=count, rays_per_tracer=result.attrs["rays_per_tracer"])
            row["camera"] = per_case[case].camera.kind
            row["rays"] += passes * frames * count * result.attrs["rays_per_tracer"]
            row["images"] += passes * frames * count
            for name in TIMINGS:
                row[name] += result.timings.get(name, 0.0)
    for row in rows.values():
        row["rays_per_s"] = row["rays"] / row["wall_s"]
    return rows


def warm_up(scene, device, tracers):
    """Build every kernel both engines use, for every batch size of the runs (PoCL compiles
    a kernel once per work size; builds are cached and are not part of the runs)."""
    for engine in ("device", "numpy"):
        for config in configs(scene, ["C1"], engine, device, tracers).values():
            one_frame = dataclasses.replace(config, time=dataclasses.replace(config.time, frames=1))
            run_render(None, case="C1", config=one_frame)


def scale_run(scene, device, tracers):
    """One case at paper density (``tracers`` x 1e4 rays x 3 frames, its reference
    included) through the device engine, end to end; prints and returns its times."""
    config = configs(scene, ["C1"], "device", device, tracers=tracers)["C1"]
    config = dataclasses.replace(config, time=dataclasses.replace(config.time, frames=3))
    start = time.perf_counter()
    result = run_render(None, case="C1", config=config)
    wall = time.perf_counter() - start
    rays = 2 * 3 * tracers * result.attrs["rays_per_tracer"]
    row = {"tracers": tracers, "wall_s": wall, "rays_per_s": rays / wall, **result.timings}
    print(
        f"\nscale run: C1, {tracers} tracers x 1e4 rays x 3 frames + reference: {wall:.1f} s "
        f"wall ({row['rays_per_s']:.3g} rays/s; trace {row['trace']:.1f} s, render "
        f"{row['render']:.1f} s, host {row.get('engine_host', 0.0):.1f} s)"
    )
    return row


def profile_device(per_case):
    """cProfile of one case through the device engine: where the host time goes."""
    case, config = next(iter(per_case.items()))
    profiler = cProfile.Profile()
    profiler.enable()
    run_render(None, case=case, config=config)
    profiler.disable()
    text = io.StringIO()
    pstats.Stats(profiler, stream=text).sort_stats("tottime").print_stats(12)
    return text.getvalue()


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--device", default=None, help="OpenCL device spec (rimcl devices).")
    parser.add_argument(
        "--cases", default="C0,C1,C2,C3,C4", help="Cases of both scenes ('' for none)."
    )
    parser.add_argument("--tracers", type=int, default=None, help="Default study tracers.")
    parser.add_argument("--paper-tracers", type=int, default=24)
    parser.add_argument("--profile", action="store_true", help="Profile the device host.")
    parser.add_argument("--json", default=None, help="Also write the results to this file.")
    parser.add_argument(
        "--scale-run", type=int, default=None, metavar="N", help="One case, N tracers x 1e4 rays."
    )
    args = parser.parse_args()

    device = select_device(args.device)
    cases = [c.strip() for c in args.cases.split(",") if c.strip()]
    scenes = {
        "default study": (load_scene(None), args.tracers),
        "paper density": (load_scene(None, PAPER_DENSITY), args.paper_tracers),
    }
    for scene, tracers in scenes.values() if cases else ():
        warm_up(scene, device, tracers)
    report = {"device": describe_device(device), "cases": cases, "scenes": {}}
    print(f"device: {report['device']['device']} ({report['device']['platform']})")
    for name, (scene, tracers) in scenes.items() if cases else ():
        rows = run_scene(
            {engine: configs(scene, cases, engine, device, tracers) for engine in ENGINES}
        )
        ratio = rows["numpy"]["wall_s"] / rows["device"]["wall_s"]
        report["scenes"][name] = {**rows, "ratio_numpy_over_device": ratio}
        row = rows["device"]
        print(
            f"\n{name}: {row['tracers']} tracers x {row['rays_per_tracer']} rays "
            f"({row['camera']} camera), cases {','.join(cases)}, a reference per configuration"
        )
        print(
            f"{'engine':7s} {'wall s':>8s} {'trace':>7s} {'render':>7s} {'centroid':>8s} "
            f"{'track':>6s} {'host us/img':>11s} {'rays/s':>9s}"
        )
        for engine, row in rows.items():
            host = None
            if engine == "device":  # per image: without the run's fixed ray sample
                host = (row["engine_host"] - row["ray_sample"]) / row["images"] * 1e6
            print(
                f"{engine:7s} {row['wall_s']:8.2f} {row['trace']:7.2f} {row['render']:7.2f} "
                f"{row['centroid']:8.2f} {row['track']:6.2f} "
                f"{'-' if host is None else f'{host:.0f}':>11s} {row['rays_per_s']:9.3g}"
            )
        print(f"device engine / numpy engine: {ratio:.2f}x faster")
    if args.scale_run:
        report["scale_run"] = scale_run(scenes["paper density"][0], device, args.scale_run)
    if args.profile:
        per_case = configs(scenes["default study"][0], ["C1"], "device", device, args.tracers)
        report["profile"] = profile_device(per_case)
        print("\ncProfile of the device engine (one case, reference included):")
        print(report["profile"])
    report["versions"] = versions()
    if args.json:
        with open(args.json, "w", encoding="utf-8") as out:
            out.write(to_json(report))
    return report


if __name__ == "__main__":
    main()
