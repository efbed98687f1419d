"""Seeded random configurations through both engines (scenes no other test wrote down).

Each draws a case, camera (plane, pupil, lens with or without a window), renderer, bit
depth, PSF, threshold (fractional too), centroid weights, scaling, window cap, frames,
precision and interpolation, sometimes Mie weights
and sensor noise; the engines must agree as everywhere (``assert_engines_agree``). On the
development machine (2-core EPYC, PoCL) all 115 draws tried gave identical frame images.
"""

import dataclasses

import numpy as np
import pytest
from test_engine import assert_engines_agree

from rimcl.ptv.measure import run_render
from rimcl.scene.config import MeasureConfig, MieConfig


def _draw(rng):
    bits = int(rng.choice([8, 10, 12, 16]))
    sigma = float(rng.choice([0.8, 1.5, 3.0, 7.0]))
    options = {
        "tracers": int(rng.integers(3, 10)),
        "renderer": str(rng.choice(["exact", "paper"])),
        "bit_depth": bits,
        "pixels": int(rng.choice([256, 512, 1024, 2048])),
        "psf_sigma": sigma,
        "threshold": float(rng.uniform(5, 0.5 * (2**bits - 1))),
        "centroid_weights": str(rng.choice(["excess", "grey"])),
        "scaling": str(rng.choice(["reference", "per_image"])),
        "max_window": int(rng.choice([24, 64, 512] if sigma <= 1.5 else [64, 512])),
        "frames": int(rng.choice([1, 2, 3])),
        "seed": int(rng.integers(0, 1000)),
        "precision": str(rng.choice(["f32", "f32c", "f64"])),
        "interp": str(rng.choice(["trilinear", "bspline3"])),
        "frame_image": True,
    }
    camera = str(rng.choice(["plane", "pupil", "lens"]))
    lens = None
    if camera == "plane":
        options.update(camera="plane", fan=int(rng.choice([4, 8, 12])))
    elif camera == "pupil":
        options.update(
            camera="pupil",
            pupil_rays=int(rng.choice([16, 64, 200])),
            view_angle=float(rng.choice([0.0, 15.0, -30.0])),
            aperture_diameter=float(rng.choice([0.5, 2.0, 6.0])),
        )
    else:  # the sample's 2π box on a 1024-px sensor of 6.5 µm pixels at M = 0.2
        options.update(camera="lens", pupil_rays=int(rng.choice([16, 64, 200])))
        lens = {
            "length_m": 32.5e-6 * 1024 / (2 * np.pi),
            "magnification": 0.2,
            "f_number": float(rng.choice([2.0, 8.0])),
            "sensor_pixels": (1024, 1024),
            "window_thickness_mm": float(rng.choice([0.0, 5.0])),
            "fluid_index": float(rng.choice([1.0, 1.335])),
        }
    case = str(rng.choice(["C0", "C1", "C2", "C3", "C4", "G=0"]))
    mie = noise = None
    if rng.random() < 0.3:
        mie = MieConfig(
            enabled=True,
            diameter_um=float(rng.choice([1.0, 5.0])),
            polarisation=str(rng.choice(["unpolarised", "perpendicular", "linear"])),
        )
    if rng.random() < 0.3:
        noise = {
            "noise": True,
            "peak_electrons": float(rng.choice([200.0, 5000.0])),
            "background_e": float(rng.choice([0.0, 5.0])),
            "full_well_e": float(rng.choice([3000.0, 30000.0])),
        }
    return case, options, mie, noise, lens


@pytest.mark.parametrize("seed", range(10))
def test_random_configurations_agree_on_both_engines(device, seed):
    case, options, mie, noise, lens = _draw(np.random.default_rng(1000 + seed))
    results = []
    for engine in ("numpy", "device"):
        config = MeasureConfig.from_options(engine=engine, device=device, **options)
        if lens is not None:
            config = dataclasses.replace(config, camera=dataclasses.replace(config.camera, **lens))
        if mie is not None:
            config = dataclasses.replace(config, mie=mie)
        if noise is not None:
            config = dataclasses.replace(config, sensor=dataclasses.replace(config.sensor, **noise))
        results.append(run_render(None, case=case, config=config))
    assert_engines_agree(*results)  # centroids identical where the frame images are
