"""The shipped sample: enough frames, spaced for accelerations, small enough to ship."""

import json
from pathlib import Path

import numpy as np

from rimcl.fields.field_reader import FieldFile
from rimcl.fields.sample import sample_path
from rimcl.optics.camera import Scene, seed_tracers
from rimcl.ptv.track import (
    SheetVelocity,
    fit_noise_std,
    integrate_tracks,
    sliding_fit,
    track_acceleration,
)


def test_sample_holds_density_and_the_sheet_velocity_of_21_frames():
    assert Path(sample_path()).stat().st_size <= 15e6
    with FieldFile(sample_path()) as ff:
        assert ff.shape == (64, 64, 64) and ff.boundary == "periodic" and ff.kind == "density"
        assert ff.n_frames == 13 and not ff.has_density_gradient
        np.testing.assert_allclose(np.diff(ff.times), 0.02, rtol=1e-9)
        # the sheet velocity lies on the sheet every scene puts there by default
        scene = Scene.from_grid(ff.origin, ff.spacing, ff.shape, ff.boundary)
        assert ff.has_velocity and not ff.has_full_velocity
        assert ff.velocity_sheet_x1 == scene.x_sheet
        history = json.loads(ff.attrs["history"])
        energy = np.interp(ff.times[0], history["time"], history["kinetic_energy"])
        # the first frame is the last spin-up step before the energy falls (to one step)
        assert ff.attrs["start"] == "kinetic-energy peak"
        assert energy >= (1 - 1e-6) * max(history["kinetic_energy"])


def test_sample_gives_accelerations_above_the_rounding_floor_at_frames_0_04_apart():
    dt, window, pixel = 0.04, 7, 2 * np.pi / 2048  # the default camera: 2048 px over 2π
    with FieldFile(sample_path()) as ff:
        scene = Scene.from_grid(ff.origin, ff.spacing, ff.shape, ff.boundary)
        times = ff.times[0] + dt * np.arange(window)
        assert times[-1] <= ff.times[-1] + 1e-9  # a whole window fits in the sample
        velocity = SheetVelocity.from_source(ff, scene.x_sheet, times[0], times[-1])
    assert velocity.times.size == 13  # every stored frame of the span, not only the sampled
    start = seed_tracers(200, scene, np.random.default_rng(0))
    tracks = integrate_tracks(velocity, start, times)
    truth = track_acceleration(velocity, tracks, times)[window // 2]
    rms = np.sqrt(np.mean(truth**2))
    # 10-bit rounding moves centroids by a few 1e-4 px per frame: with 5e-4 px
    # the fit's acceleration noise is 0.3 % of rms(a) (measured; rms(a) Δt² is 0.033 px),
    # where the three-frame difference at Δt = 0.005 gave 176 %
    assert fit_noise_std(window, 2, dt, 5e-4 * pixel)[2] < 0.02 * rms
    # the fit's own bias on the true track is small too (measured 0.7 %)
    fit = sliding_fit(tracks, dt, window, order=2)
    assert np.sqrt(np.mean((fit.acceleration[0] - truth) ** 2)) < 0.02 * rms
