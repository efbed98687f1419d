"""The Boussinesq solver behind ``rimcl field synth``: exact solutions and the run itself."""

import json

import h5py
import numpy as np
import pytest
from click.testing import CliRunner

from rimcl.cli.main import cli
from rimcl.fields.derivatives import gradient
from rimcl.fields.field_reader import FieldFile
from rimcl.fields.synth import BoussinesqSolver, default_reynolds, synthesize


def _coordinates(n):
    """x1, x2, x3 of an n³ periodic 2π grid as (n3, n2, n1) arrays."""
    axis = 2 * np.pi * np.arange(n) / n
    x3, x2, x1 = np.meshgrid(axis, axis, axis, indexing="ij")
    return x1, x2, x3


def _spectral_divergence(velocity, spacing):
    """∇·u of a periodic (n3, n2, n1, 3) velocity."""
    return sum(gradient(velocity[..., i], spacing, "spectral", True)[..., i] for i in range(3))


def test_taylor_green_vortex_decays_exactly():
    # u = (sin x1 cos x2, -cos x1 sin x2, 0) e^{-2νt}: the nonlinear term is a pure gradient
    n, reynolds, dt = 16, 50.0, 0.05
    solver = BoussinesqSolver(n, reynolds)
    x1, x2, _ = _coordinates(n)
    velocity = np.stack([np.sin(x1) * np.cos(x2), -np.cos(x1) * np.sin(x2), 0 * x1])
    u_hat = solver.forward(velocity)
    rho_hat = solver.forward(np.ones_like(x1))
    for _ in range(20):
        u_hat, rho_hat = solver.step(u_hat, rho_hat, dt)
    decay = np.exp(-2 * 20 * dt / reynolds)
    np.testing.assert_allclose(solver.inverse(u_hat), velocity * decay, atol=1e-10)
    # K = ½⟨|u|²⟩ = 1/4, ε = ν⟨|ω|²⟩ with ω3 = 2 sin x1 sin x2, so ⟨|ω|²⟩ = 1
    assert solver.kinetic_energy(u_hat) == pytest.approx(0.25 * decay**2, rel=1e-10)
    assert solver.dissipation(u_hat) == pytest.approx(decay**2 / reynolds, rel=1e-10)


def test_density_is_advected_and_diffused_exactly():
    # uniform flow U along x1 carries ρ = 1 + a sin(x1): ρ = 1 + a sin(x1 - U t) e^{-κ t};
    # with gravity along x1 the buoyancy of a density that varies along x1 only is a pure
    # gradient, which the projection removes, so U stays uniform
    n, reynolds, dt, speed, amplitude = 16, 20.0, 0.02, 0.3, 0.05
    solver = BoussinesqSolver(n, reynolds, schmidt=2.0, gravity_axis="x1")
    x1, _, _ = _coordinates(n)
    u_hat = solver.forward(np.stack([np.full_like(x1, speed), 0 * x1, 0 * x1]))
    rho_hat = solver.forward(1 + amplitude * np.sin(x1))
    steps = 25
    for _ in range(steps):
        u_hat, rho_hat = solver.step(u_hat, rho_hat, dt)
    time, diffusivity = steps * dt, 1 / (reynolds * 2.0)
    expected = 1 + amplitude * np.sin(x1 - speed * time) * np.exp(-diffusivity * time)
    np.testing.assert_allclose(solver.density(rho_hat), expected, atol=1e-10)
    np.testing.assert_allclose(solver.velocity(u_hat)[..., 0], speed, atol=1e-12)


def test_state_stays_solenoidal_and_dealiased():
    solver = BoussinesqSolver(32, default_reynolds(32))
    u_hat, rho_hat = solver.initial_state(seed=3)
    assert solver.kinetic_energy(u_hat) == 0.0  # from rest
    for _ in range(5):
        u_hat, rho_hat = solver.step(u_hat, rho_hat, 0.25)
    k_dot_u = sum(solver.k[i] * u_hat[i] for i in range(3))
    k_magnitude = np.sqrt(solver.k_squared)
    assert np.max(np.abs(k_dot_u)) < 1e-13 * np.max(k_magnitude * np.abs(u_hat).max(axis=0))
    assert np.all(u_hat[:, ~solver.dealias] == 0) and np.all(rho_hat[~solver.dealias] == 0)


def test_buoyancy_makes_heavy_fluid_sink_along_the_chosen_axis():
    for axis, component in (("x3", 2), ("x1", 0)):
        result = synthesize(grid=16, seed=2, t_start=2.0, frames=1, gravity_axis=axis)
        fluctuation = result.density[0] - result.density[0].mean()
        flux = np.mean(fluctuation[..., None] * result.velocity[0], axis=(0, 1, 2))
        assert flux[component] < 0
        others = np.delete(np.abs(flux), component)
        assert np.all(others < 0.05 * abs(flux[component]))


def test_bad_parameters_are_refused():
    from rimcl.core.errors import RimclError

    for bad in ({"grid": 8}, {"reynolds": -1.0}, {"frames": 0}, {"gravity_axis": "y"}):
        with pytest.raises(RimclError):
            synthesize(**bad)


@pytest.fixture(scope="module")
def peak_run(tmp_path_factory):
    """``rimcl field synth --grid 32 --seed 1 -o f.h5``: the issue's run, to the peak."""
    path = tmp_path_factory.mktemp("synth") / "f.h5"
    result = CliRunner().invoke(cli, ["field", "synth", "--grid", "32", "--seed", "1", "-o",
                                      str(path)])  # fmt: skip
    assert result.exit_code == 0, result.output
    return path, result.output


def test_synth_writes_evenly_spaced_finite_frames_at_the_energy_peak(peak_run):
    path, output = peak_run
    assert "kinetic-energy peak" in output and "frame 2" in output
    with FieldFile(path) as ff:
        assert ff.n_frames >= 3 and ff.boundary == "periodic" and ff.has_velocity
        assert ff.has_density_gradient and ff.shape == (32, 32, 32)
        np.testing.assert_allclose(np.diff(ff.times), 0.005, rtol=1e-9)
        np.testing.assert_allclose(ff.spacing, 2 * np.pi / 32)
        for frame in range(ff.n_frames):
            density, velocity = ff.density(frame), ff.velocity(frame)
            assert np.all(np.isfinite(density)) and np.all(np.isfinite(velocity))
            # two fluids 1 and 1.105 (Atwood 0.05), mixed: a spread of a few percent
            spread = (density.max() - density.min()) / density.mean()
            assert 0.02 < spread < 0.11 and 0.995 < density.min() and density.max() < 1.11
            assert np.sqrt(np.mean(velocity.astype(np.float64) ** 2)) > 0.01
        attrs = ff.attrs
        assert attrs["reynolds"] == default_reynolds(32) and attrs["gravity_axis"] == "x3"
        assert attrs["kmax_eta_last_frame"] >= 1.0  # the default Reynolds number is resolved
    with h5py.File(path) as h5:
        history = {k: np.asarray(v) for k, v in json.loads(h5.attrs["history"]).items()}
    energy, times = history["kinetic_energy"], history["time"]
    assert energy[0] == 0.0 and np.all(np.diff(energy[:20]) > 0)  # from rest, it grows
    first = times.searchsorted(attrs["t_first_frame"])
    assert energy[first] == energy[times <= times[first]].max()
    assert np.any(energy[times > times[first]] < energy[first])  # the peak was passed


def test_synth_velocity_is_solenoidal_and_gradient_spectral(peak_run):
    path, _ = peak_run
    with FieldFile(path) as ff:
        velocity = ff.velocity(1).astype(np.float64)
        divergence = _spectral_divergence(velocity, ff.spacing)
        velocity_gradient = gradient(velocity[..., 0], ff.spacing, "spectral", True)
        # float32 storage rounds u by ~6e-8 relative; the solver's state is exact
        assert np.sqrt(np.mean(divergence**2)) < 1e-6 * np.sqrt(np.mean(velocity_gradient**2))
        density = ff.density(1).astype(np.float64)
        recomputed = gradient(density, ff.spacing, "spectral", True)
        stored = ff.density_gradient(1)
        np.testing.assert_allclose(stored, recomputed, atol=1e-5 * np.abs(recomputed).max())


def test_same_seed_gives_the_same_file_and_another_seed_another(tmp_path):
    runner = CliRunner()
    paths = []
    for name, seed in (("a", 4), ("b", 4), ("c", 5)):
        path = tmp_path / f"{name}.h5"
        args = ["field", "synth", "--grid", "16", "--seed", str(seed), "--start-time", "0.5",
                "--frames", "3", "-o", str(path)]  # fmt: skip
        result = runner.invoke(cli, args)
        assert result.exit_code == 0, result.output
        paths.append(path)
    files = [FieldFile(p) for p in paths]
    try:
        for frame in range(3):
            for read in ("density", "velocity", "density_gradient"):
                a, b, c = (getattr(f, read)(frame) for f in files)
                np.testing.assert_array_equal(a, b)
                assert not np.array_equal(a, c)
        np.testing.assert_array_equal(files[0].times, [0.5, 0.505, 0.51])
    finally:
        for f in files:
            f.close()


def test_synth_refuses_an_existing_output_before_running(tmp_path):
    path = tmp_path / "f.h5"
    path.write_bytes(b"keep me")
    result = CliRunner().invoke(cli, ["field", "synth", "--grid", "16", "-o", str(path)])
    assert result.exit_code == 1
    assert result.output.strip().splitlines() == [
        f"Error: {path} exists (use --overwrite to replace it)"
    ]
    assert path.read_bytes() == b"keep me"
