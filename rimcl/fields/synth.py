"""Synthetic buoyancy-driven turbulence: a compact pseudo-spectral Boussinesq solver.

Two miscible fluids (densities 1 and 1.105, Atwood number 0.05, as in the JHTDB "mixing"
data set) start at rest as random blobs in a periodic box ``[0, 2π)³``; buoyancy sets them
moving and the flow becomes turbulent. In the Boussinesq approximation, with the density
scale ``ρ̄`` (the mean density), unit gravity (Froude number 1), length ``L0`` (box
``2π``) and velocity ``U0``:

    ∂u/∂t = u × ω - ∇Π + (1/Re) ∇²u - g (ρ - ρ̄)/ρ̄ e_g,     ∇·u = 0,
    ∂ρ/∂t = -u·∇ρ + 1/(Re Sc) ∇²ρ,

with ``ω = ∇ × u`` and gravity ``-g e_g`` along one axis (default ``x3``, so that the light
sheet ``x2``–``x3`` contains it). Fields are Fourier series on an ``N³`` grid, dealiased by
the 2/3 rule (every wavenumber component ``|k_i| <= (N - 1) // 3``), advanced with classical
RK4 at a step limited by advection (CFL) and diffusion; the pressure ``Π`` is removed by
projecting the velocity onto divergence-free fields at every stage, so ``∇·u = 0`` to
round-off. FFTs use :mod:`scipy.fft` with all cores.

The run goes from rest to the peak of turbulent kinetic energy (the state of the JHTDB
frames the paper used) and then records frames ``Δt`` apart: the density, and either the
full velocity or only the in-plane velocity ``(u2, u3)`` on one light-sheet plane
``x1 = const`` (evaluated spectrally, so exact at any ``x1``), which keeps a file of many
frames small.

The initial blobs are drawn on a fixed set of low wavenumbers (``|k_i| <= 10``), so one
seed gives the same initial condition on every grid of 32³ or more: a finer grid resolves
the same flow better.
"""

import dataclasses
import math

import numpy as np
import scipy.fft

from rimcl.core.atomic import check_output
from rimcl.core.errors import RimclError
from rimcl.core.memory import check_synth_memory
from rimcl.fields.field_writer import write_field

RHO_LIGHT = 1.0
RHO_HEAVY = 1.105
ATWOOD = (RHO_HEAVY - RHO_LIGHT) / (RHO_HEAVY + RHO_LIGHT)
GRAVITY = 1.0
GRAVITY_AXES = ("x1", "x2", "x3")

#: Peak wavenumber of the initial blob spectrum (blobs about 2π/3 across).
BLOB_WAVENUMBER = 3.0
#: Width of the tanh interface between the fluids, in units of the blob field's rms.
INTERFACE_WIDTH = 0.5
# blob modes are drawn on |k_i| <= _SEED_MODES, a cube every grid >= 32 resolves
_SEED_MODES = 10
_SEED_GRID = 32

#: Reynolds number resolved at 64³ (k_max η ≳ 1 at the kinetic-energy peak); other grids
#: scale it as (N / 64)^(4/3), since η ∝ Re^(-3/4) at fixed dissipation.
REYNOLDS_64 = 400.0

#: Advective CFL number of the RK4 step (RK4 is stable to about 2.8/2.1 = 1.3 here).
CFL = 0.8
#: Largest time step (time units), for the start from rest and slow phases.
DT_MAX = 0.25
# RK4 stability on the negative real axis, with a safety factor of 2
_DIFFUSIVE_LIMIT = 2.78 / 2


def default_reynolds(grid):
    """Default Reynolds number for an ``grid³`` run: ``1000 (grid/64)^(4/3)``, rounded."""
    return float(round(REYNOLDS_64 * (grid / 64.0) ** (4.0 / 3.0)))


@dataclasses.dataclass
class SynthResult:
    """Frames and history of a :func:`synthesize` run.

    Attributes
    ----------
    times : ndarray, float64, shape (n_frames,)
        Frame times (time units ``L0/U0``).
    density : list of ndarray, float64, each (N, N, N)
        Density per frame (light fluid 1, heavy 1.105), array order ``(n3, n2, n1)``.
    velocity : list of ndarray, float64, each (N, N, N, 3), or None
        Velocity per frame, components along ``x1, x2, x3``; None when only the sheet
        velocity was kept.
    density_gradient : list of ndarray or None
        Spectral ``∇ρ`` per frame (exact for the band-limited field), if requested.
    history : dict of str to ndarray
        Per step: ``time``, ``kinetic_energy`` (``½⟨|u|²⟩``), ``density_variance``
        (``⟨(ρ - ρ̄)²⟩``), ``dissipation`` (``ν⟨|ω|²⟩``).
    params : dict
        Everything that defines the run (grid, seed, Reynolds number, ...) and its
        outcome (peak time, ``k_max η``).
    velocity_sheet : list of ndarray, float64, each (N, N, 2), or None
        In-plane velocity ``(u2, u3)`` per frame on the plane ``x1 = sheet_x1``, at the
        nodes ``(x3, x2)``; None when the full velocity was kept.
    sheet_x1 : float or None
        The plane of ``velocity_sheet`` (length units).
    """

    times: np.ndarray
    density: list
    velocity: list | None
    density_gradient: list | None
    history: dict
    params: dict
    velocity_sheet: list | None = None
    sheet_x1: float | None = None

    @property
    def spacing(self):
        """Grid spacing ``2π/N`` along ``x1, x2, x3``."""
        return np.full(3, 2 * np.pi / self.params["grid"])


class BoussinesqSolver:
    """Spectral state and right-hand side of the Boussinesq equations on an ``N³`` box.

    The state is ``(u_hat, rho_hat)``: real-FFT coefficients of the velocity, shape
    ``(3, N, N, N//2 + 1)`` (components along ``x1, x2, x3``), and of the density,
    ``(N, N, N//2 + 1)``, for physical arrays ordered ``(n3, n2, n1)``.

    Parameters
    ----------
    grid : int
        Points per side ``N`` (the box is ``2π``).
    reynolds : float
        ``Re = 1/ν``.
    schmidt : float
        ``Sc = ν/κ``.
    gravity_axis : {"x1", "x2", "x3"}
        Gravity points along ``-gravity_axis``.
    """

    def __init__(self, grid, reynolds, schmidt=1.0, gravity_axis="x3"):
        if gravity_axis not in GRAVITY_AXES:
            raise RimclError(f"gravity axis must be one of {GRAVITY_AXES}, got {gravity_axis!r}")
        self.grid = grid
        self.viscosity = 1.0 / reynolds
        self.diffusivity = 1.0 / (reynolds * schmidt)
        self.gravity_component = GRAVITY_AXES.index(gravity_axis)
        n = grid
        k_full = scipy.fft.fftfreq(n, 1.0 / n)
        k_half = scipy.fft.rfftfreq(n, 1.0 / n)
        # wavenumbers along x1 (rfft axis, last), x2, x3, broadcast to (n3, n2, n1//2+1)
        self.k = (
            k_half[None, None, :],
            k_full[None, :, None],
            k_full[:, None, None],
        )
        self.k_max = (n - 1) // 3
        self.dealias = (
            (np.abs(self.k[0]) <= self.k_max)
            & (np.abs(self.k[1]) <= self.k_max)
            & (np.abs(self.k[2]) <= self.k_max)
        )
        self.k_squared = self.k[0] ** 2 + self.k[1] ** 2 + self.k[2] ** 2
        self._inverse_k_squared = np.where(
            self.k_squared > 0, 1.0 / np.where(self.k_squared > 0, self.k_squared, 1.0), 0.0
        )
        # Parseval weights of the half spectrum: interior x1 modes stand for two
        weight = np.full(k_half.size, 2.0)
        weight[0] = 1.0
        if n % 2 == 0:
            weight[-1] = 1.0
        self._parseval = weight[None, None, :] / float(n) ** 6
        self.shape = (n, n, n)
        self.spacing = 2 * np.pi / n

    def forward(self, values):
        """Real FFT over the last three axes (``(..., n3, n2, n1)``)."""
        return scipy.fft.rfftn(values, axes=(-3, -2, -1), workers=-1)

    def inverse(self, spectrum):
        """Inverse of :meth:`forward`."""
        return scipy.fft.irfftn(spectrum, s=self.shape, axes=(-3, -2, -1), workers=-1)

    def project(self, u_hat):
        """Remove the gradient part: ``û - k (k·û)/|k|²`` (in place), then return it."""
        k_dot_u = self.k[0] * u_hat[0] + self.k[1] * u_hat[1] + self.k[2] * u_hat[2]
        k_dot_u *= self._inverse_k_squared
        for i in range(3):
            u_hat[i] -= self.k[i] * k_dot_u
        return u_hat

    def initial_state(self, seed):
        """Fluids at rest in random blobs (tanh-smoothed interfaces), dealiased.

        Returns
        -------
        u_hat, rho_hat : ndarray
        """
        rng = np.random.default_rng(seed)
        noise = scipy.fft.rfftn(rng.standard_normal((_SEED_GRID,) * 3))
        seed_k = (
            scipy.fft.rfftfreq(_SEED_GRID, 1.0 / _SEED_GRID)[None, None, :],
            scipy.fft.fftfreq(_SEED_GRID, 1.0 / _SEED_GRID)[None, :, None],
            scipy.fft.fftfreq(_SEED_GRID, 1.0 / _SEED_GRID)[:, None, None],
        )
        magnitude = np.sqrt(seed_k[0] ** 2 + seed_k[1] ** 2 + seed_k[2] ** 2)
        # shell spectrum E(k) ∝ k⁴ exp(-2 (k/k0)²); amplitude ∝ sqrt(E / k²)
        amplitude = magnitude * np.exp(-((magnitude / BLOB_WAVENUMBER) ** 2))
        keep = np.ones(magnitude.shape, dtype=bool)
        for axis_k in seed_k:
            keep &= np.abs(axis_k) <= min(_SEED_MODES, self.k_max)
        spectrum = noise * amplitude * keep
        blob_hat = np.zeros(self.k_squared.shape, dtype=complex)
        modes = min(_SEED_MODES, self.k_max)
        rows = np.r_[0 : modes + 1, -modes:0]
        blob_hat[np.ix_(rows, rows, np.arange(modes + 1))] = spectrum[
            np.ix_(rows, rows, np.arange(modes + 1))
        ]
        blob = self.inverse(blob_hat)
        blob /= np.std(blob)
        density = RHO_LIGHT + (RHO_HEAVY - RHO_LIGHT) * 0.5 * (1 + np.tanh(blob / INTERFACE_WIDTH))
        rho_hat = self.forward(density) * self.dealias
        u_hat = np.zeros((3, *self.k_squared.shape), dtype=complex)
        return u_hat, rho_hat

    def rhs(self, u_hat, rho_hat):
        """Time derivatives ``(du_hat/dt, drho_hat/dt)`` of the state."""
        k = self.k
        spectra = np.empty((9, *self.k_squared.shape), dtype=complex)
        spectra[0:3] = u_hat
        spectra[3] = 1j * (k[1] * u_hat[2] - k[2] * u_hat[1])
        spectra[4] = 1j * (k[2] * u_hat[0] - k[0] * u_hat[2])
        spectra[5] = 1j * (k[0] * u_hat[1] - k[1] * u_hat[0])
        for i in range(3):
            spectra[6 + i] = 1j * k[i] * rho_hat
        fields = self.inverse(spectra)
        u, omega, grad_rho = fields[0:3], fields[3:6], fields[6:9]
        products = np.empty((4, *self.shape))
        products[0] = u[1] * omega[2] - u[2] * omega[1]
        products[1] = u[2] * omega[0] - u[0] * omega[2]
        products[2] = u[0] * omega[1] - u[1] * omega[0]
        products[3] = u[0] * grad_rho[0] + u[1] * grad_rho[1] + u[2] * grad_rho[2]
        nonlinear = self.forward(products) * self.dealias
        du = nonlinear[0:3]
        mean_density = rho_hat[0, 0, 0].real / float(self.grid) ** 3
        buoyancy = -GRAVITY * rho_hat / mean_density
        buoyancy[0, 0, 0] = 0.0
        du[self.gravity_component] += buoyancy
        self.project(du)
        du -= self.viscosity * self.k_squared * u_hat
        drho = -nonlinear[3] - self.diffusivity * self.k_squared * rho_hat
        drho[0, 0, 0] = 0.0
        return du, drho

    def step(self, u_hat, rho_hat, dt):
        """One classical RK4 step of size ``dt``; returns the new ``(u_hat, rho_hat)``."""
        k1u, k1r = self.rhs(u_hat, rho_hat)
        k2u, k2r = self.rhs(u_hat + 0.5 * dt * k1u, rho_hat + 0.5 * dt * k1r)
        k3u, k3r = self.rhs(u_hat + 0.5 * dt * k2u, rho_hat + 0.5 * dt * k2r)
        k4u, k4r = self.rhs(u_hat + dt * k3u, rho_hat + dt * k3r)
        new_u = u_hat + dt / 6 * (k1u + 2 * k2u + 2 * k3u + k4u)
        new_rho = rho_hat + dt / 6 * (k1r + 2 * k2r + 2 * k3r + k4r)
        return self.project(new_u), new_rho

    def stable_step(self, u_hat):
        """Largest step allowed by the CFL number, diffusion and :data:`DT_MAX`."""
        speed = self.max_speed(u_hat)
        limits = [
            DT_MAX,
            _DIFFUSIVE_LIMIT
            / (max(self.viscosity, self.diffusivity) * float(self.k_squared[self.dealias].max())),
        ]
        if speed > 0:
            limits.append(CFL * self.spacing / speed)
        return min(limits)

    def max_speed(self, u_hat):
        """``Σ_i max|u_i|`` over the grid (the advective speed of the CFL condition)."""
        return float(np.abs(self.inverse(u_hat)).max(axis=(1, 2, 3)).sum())

    def _energy(self, spectrum):
        return float(np.sum(self._parseval * np.abs(spectrum) ** 2))

    def kinetic_energy(self, u_hat):
        """``½⟨|u|²⟩`` over the box."""
        return 0.5 * sum(self._energy(u_hat[i]) for i in range(3))

    def density_variance(self, rho_hat):
        """``⟨(ρ - ρ̄)²⟩``."""
        fluctuation = rho_hat.copy()
        fluctuation[0, 0, 0] = 0.0
        return self._energy(fluctuation)

    def dissipation(self, u_hat):
        """``ε = ν⟨|ω|²⟩ = ν Σ k²|û|²`` (the mean rate of kinetic-energy dissipation)."""
        return self.viscosity * sum(
            float(np.sum(self._parseval * self.k_squared * np.abs(u_hat[i]) ** 2)) for i in range(3)
        )

    def kmax_eta(self, u_hat):
        """Resolution ``k_max η`` with ``η = (ν³/ε)^(1/4)`` and ``k_max = (N - 1)//3``."""
        eps = self.dissipation(u_hat)
        if eps <= 0:
            return math.inf
        return self.k_max * (self.viscosity**3 / eps) ** 0.25

    def velocity(self, u_hat):
        """Physical velocity, ``(n3, n2, n1, 3)``, components along ``x1, x2, x3``."""
        return np.moveaxis(self.inverse(u_hat), 0, -1)

    def sheet_velocity(self, u_hat, x1):
        """In-plane velocity ``(u2, u3)`` on the plane ``x1``, ``(n3, n2, 2)``.

        The Fourier series along ``x1`` is summed at ``x1`` itself, so the plane is exact
        for the band-limited field at any ``x1`` (not only at nodes).
        """
        n = self.grid
        # half-spectrum weights of the real series along x1 (the Nyquist mode is dealiased)
        weight = np.full(n // 2 + 1, 2.0)
        weight[0] = 1.0
        if n % 2 == 0:
            weight[-1] = 1.0
        phase = weight * np.exp(1j * self.k[0][0, 0, :] * float(x1))
        planes = scipy.fft.ifftn(u_hat[1:3], axes=(-3, -2), workers=-1)
        return np.moveaxis((planes @ phase).real / n, 0, -1)

    def density(self, rho_hat):
        """Physical density, ``(n3, n2, n1)``."""
        return self.inverse(rho_hat)

    def density_gradient(self, rho_hat):
        """Spectral ``∇ρ``, ``(n3, n2, n1, 3)``, components along ``x1, x2, x3``."""
        spectra = np.stack([1j * self.k[i] * rho_hat for i in range(3)])
        return np.moveaxis(self.inverse(spectra), 0, -1)


def synthesize(
    grid=64,
    seed=0,
    reynolds=None,
    schmidt=1.0,
    frames=3,
    frame_dt=0.005,
    gravity_axis="x3",
    t_start=None,
    t_max=100.0,
    store_gradient=True,
    sheet_x1=None,
    progress=False,
):
    """Run the Boussinesq solver from rest and record frames of the flow.

    Parameters
    ----------
    grid : int
        Points per side ``N`` of the periodic box ``[0, 2π)³`` (at least 16).
    seed : int
        Seed of the random blobs; the same seed gives the same run.
    reynolds : float, optional
        ``Re = 1/ν``; default :func:`default_reynolds` of ``grid``.
    schmidt : float
        ``Sc``; 1 as in the JHTDB data set.
    frames : int
        Number of frames to record (at least 1).
    frame_dt : float
        Time between frames (time units ``L0/U0``); the paper used 0.005.
    gravity_axis : {"x1", "x2", "x3"}
        Gravity points along ``-gravity_axis``.
    t_start : float, optional
        Record the first frame at this time instead of at the kinetic-energy peak
        (a short run, e.g. for tests).
    t_max : float
        Give up if no kinetic-energy peak appears by this time.
    store_gradient : bool
        Also return the exact spectral density gradient of each frame.
    sheet_x1 : float, optional
        Keep only the in-plane velocity ``(u2, u3)`` on the plane ``x1 = sheet_x1``
        (length units; the box is periodic, so any value) instead of the full velocity.
    progress : bool
        Show a progress bar (tqdm).

    Returns
    -------
    SynthResult
    """
    from tqdm import tqdm

    if not isinstance(grid, (int, np.integer)) or grid < 16:
        raise RimclError(f"the grid must be an integer of at least 16, got {grid!r}")
    reynolds = default_reynolds(grid) if reynolds is None else float(reynolds)
    if not reynolds > 0 or not schmidt > 0:
        raise RimclError("the Reynolds and Schmidt numbers must be positive")
    if frames < 1 or not frame_dt > 0:
        raise RimclError("need at least one frame and a positive frame spacing")
    if t_start is not None and not t_start >= 0:
        raise RimclError(f"the start time must be >= 0, got {t_start}")
    if sheet_x1 is not None and not math.isfinite(sheet_x1):
        raise RimclError(f"the sheet velocity plane x1 must be finite, got {sheet_x1}")
    check_synth_memory(grid, frames)
    solver = BoussinesqSolver(grid, reynolds, schmidt, gravity_axis)
    u_hat, rho_hat = solver.initial_state(seed)
    history = {"time": [], "kinetic_energy": [], "density_variance": [], "dissipation": []}

    def record(time, u_h, rho_h):
        history["time"].append(time)
        history["kinetic_energy"].append(solver.kinetic_energy(u_h))
        history["density_variance"].append(solver.density_variance(rho_h))
        history["dissipation"].append(solver.dissipation(u_h))

    time = 0.0
    record(time, u_hat, rho_hat)
    bar = tqdm(desc="spin-up", unit="step", disable=None if progress else True, leave=False)
    with bar:
        while True:
            dt = solver.stable_step(u_hat)
            if t_start is not None:
                if time >= t_start:
                    break
                dt = min(dt, t_start - time)
            elif time + dt > t_max:
                raise RimclError(
                    f"no kinetic-energy peak before t = {t_max:g}; the flow may be too viscous"
                )
            new_u, new_rho = solver.step(u_hat, rho_hat, dt)
            record(time + dt, new_u, new_rho)
            bar.update()
            bar.set_postfix(t=f"{time + dt:.3f}", K=f"{history['kinetic_energy'][-1]:.3e}")
            energies = history["kinetic_energy"]
            if t_start is None and len(energies) > 2 and energies[-1] < energies[-2]:
                # the previous state is the peak: keep it and drop the step past it
                break
            u_hat, rho_hat, time = new_u, new_rho, time + dt
    start = time
    result_frames = {"density": [], "velocity": [], "velocity_sheet": [], "density_gradient": []}
    times = []
    bar = tqdm(
        total=frames, desc="frames", unit="frame", disable=None if progress else True, leave=False
    )
    with bar:
        for index in range(frames):
            if index:
                substeps = max(1, math.ceil(frame_dt / solver.stable_step(u_hat)))
                for _ in range(substeps):
                    u_hat, rho_hat = solver.step(u_hat, rho_hat, frame_dt / substeps)
                time = start + index * frame_dt
                record(time, u_hat, rho_hat)
            times.append(time)
            result_frames["density"].append(solver.density(rho_hat))
            if sheet_x1 is None:
                result_frames["velocity"].append(solver.velocity(u_hat))
            else:
                result_frames["velocity_sheet"].append(solver.sheet_velocity(u_hat, sheet_x1))
            if store_gradient:
                result_frames["density_gradient"].append(solver.density_gradient(rho_hat))
            bar.update()
    order = np.argsort(history["time"], kind="stable")
    history = {key: np.asarray(values)[order] for key, values in history.items()}
    params = {
        "grid": int(grid),
        "seed": int(seed),
        "reynolds": reynolds,
        "schmidt": float(schmidt),
        "atwood": ATWOOD,
        "rho_light": RHO_LIGHT,
        "rho_heavy": RHO_HEAVY,
        "gravity": GRAVITY,
        "gravity_axis": gravity_axis,
        "blob_wavenumber": BLOB_WAVENUMBER,
        "interface_width": INTERFACE_WIDTH,
        "frames": int(frames),
        "frame_dt": float(frame_dt),
        "velocity_stored": "full" if sheet_x1 is None else "sheet",
        "sheet_x1": None if sheet_x1 is None else float(sheet_x1),
        "start": "time" if t_start is not None else "kinetic-energy peak",
        "t_first_frame": float(start),
        "kmax_eta_last_frame": solver.kmax_eta(u_hat),
        "steps": int(len(history["time"]) - 1),
    }
    return SynthResult(
        times=np.array(times),
        density=result_frames["density"],
        velocity=result_frames["velocity"] if sheet_x1 is None else None,
        density_gradient=result_frames["density_gradient"] if store_gradient else None,
        history=history,
        params=params,
        velocity_sheet=result_frames["velocity_sheet"] if sheet_x1 is not None else None,
        sheet_x1=None if sheet_x1 is None else float(sheet_x1),
    )


def write_synth(result, path, *, overwrite=False):
    """Write a :class:`SynthResult` as a rimcl field file (periodic box, origin 0).

    Parameters
    ----------
    result : SynthResult
    path : str or Path
    overwrite : bool

    Returns
    -------
    pathlib.Path
    """
    params = result.params
    attrs = {
        "title": f"rimcl synthetic buoyancy-driven turbulence, {params['grid']}^3",
        "source": "rimcl field synth (pseudo-spectral Boussinesq solver)",
        "length_unit": "L0 (the box is 2*pi L0)",
        "time_unit": "L0/U0",
        "axes": f"x1, x2, x3; gravity along -{params['gravity_axis']}",
        **{key: value for key, value in params.items() if value is not None},
        "history": {key: values.tolist() for key, values in result.history.items()},
    }
    return write_field(
        path,
        density=result.density,
        velocity=result.velocity,
        velocity_sheet=result.velocity_sheet,
        sheet_x1=result.sheet_x1,
        density_gradient=result.density_gradient,
        times=result.times,
        origin=(0.0, 0.0, 0.0),
        spacing=result.spacing,
        boundary="periodic",
        attrs=attrs,
        config=params,
        overwrite=overwrite,
    )


def run_synth(path, *, overwrite=False, **options):
    """Run :func:`synthesize` and write the result to ``path``.

    The output is checked before the run, so an existing file or an unwritable
    directory is refused at once.

    Parameters
    ----------
    path : str or Path
    overwrite : bool
    **options
        Passed to :func:`synthesize`.

    Returns
    -------
    SynthResult
    """
    check_output(path, overwrite)
    result = synthesize(**options)
    write_synth(result, path, overwrite=overwrite)
    return result


def history_table(result, rows=12):
    """A short text table of the run: time, kinetic energy, density variance.

    Parameters
    ----------
    result : SynthResult
    rows : int
        About how many steps of the spin-up to show (the frames are always shown).

    Returns
    -------
    str
    """
    history = result.history
    times = history["time"]
    frame_rows = [int(np.argmin(np.abs(times - t))) for t in result.times]
    spin_up = np.flatnonzero(times < result.times[0])
    shown = sorted(set(spin_up[:: max(1, math.ceil(spin_up.size / rows))]) | set(frame_rows))
    lines = [f"{'time':>9}  {'kinetic energy':>14}  {'density variance':>16}  note"]
    at_peak = result.params["start"] != "time"
    for i in shown:
        notes = []
        if i in frame_rows:
            notes.append(f"frame {frame_rows.index(i)}")
        if at_peak and i == frame_rows[0]:
            notes.append("kinetic-energy peak (to one step)")
        lines.append(
            f"{times[i]:9.4f}  {history['kinetic_energy'][i]:14.6e}  "
            f"{history['density_variance'][i]:16.6e}  {', '.join(notes)}".rstrip()
        )
    p = result.params
    lines.append(
        f"grid {p['grid']}^3, Re {p['reynolds']:g}, Sc {p['schmidt']:g}, Atwood {p['atwood']:.4f}, "
        f"{p['steps']} steps, k_max*eta {p['kmax_eta_last_frame']:.2f}"
    )
    return "\n".join(lines)
