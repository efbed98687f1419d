"""Ray weights from Mie scattering by the tracer particles (paper §3.2).

A tracer in the light sheet scatters the sheet's light; a ray leaving it in the direction
``d`` carries the intensity scattered at the angle ``θ = arccos(k · d)`` between the sheet's
propagation direction ``k`` and ``d`` (the paper: "the intensity of a light ray, given by
the initial direction in the Mie scattering"). The intensity depends on the polarisation of
the sheet relative to the scattering plane (the plane of ``k`` and ``d``):

- ``"perpendicular"``: ``|S1(θ)|²`` (field perpendicular to every ray's scattering plane);
- ``"parallel"``: ``|S2(θ)|²``;
- ``"unpolarised"``: ``(|S1|² + |S2|²) / 2``;
- a linear polarisation direction ``p`` (a 3-vector perpendicular to ``k``): the field
  splits per ray into ``p · e⊥`` and ``p · e∥``, ``I = |S1|² (p·e⊥)² + |S2|² (p·e∥)²``
  with ``e⊥ = k × d / |k × d|`` and ``e∥ = e⊥ × k``. This is a real laser sheet.

Intensities are miepython's (MIT) in Wiscombe's normalisation (``norm="wiscombe"``,
dimensionless ``|S|²``); only their ratios matter, since each tracer's image is scaled by
its reference image. miepython evaluates the series one angle at a time in Python (13 s for
1.3e5 angles of a 10 µm particle), so :meth:`MieWeights.intensities` sums the same series
(miepython's coefficients ``a_n, b_n``, the π_n/τ_n recurrences of Bohren & Huffman) for
all angles at once; the tests hold it to miepython's intensities at 1e-6 relative.
"""

import dataclasses

import miepython
import numpy as np

from rimcl.core.errors import RimclError

POLARISATIONS = ("perpendicular", "parallel", "unpolarised")
_ANGLE_CHUNK = 1 << 16  # angles summed at once: keeps the work arrays at a few MB
_PARALLEL_TOLERANCE = 1e-9  # |k × d| below this: d along k, where S1 = S2


def _unit_vector(value, name):
    vector = np.asarray(value, dtype=np.float64).reshape(-1)
    norm = np.linalg.norm(vector) if vector.size == 3 else 0.0
    if vector.size != 3 or not np.all(np.isfinite(vector)) or norm == 0:
        raise RimclError(f"{name} must be a nonzero 3-vector (x1, x2, x3), got {value!r}")
    return vector / norm


@dataclasses.dataclass(frozen=True)
class MieWeights:
    """Mie scattering intensity of each ray of a tracer, from its initial direction.

    Attributes
    ----------
    diameter_um : float
        Particle diameter (µm).
    particle_index : float
        Real refractive index of the particle (e.g. 1.59 polystyrene, 1.45 DEHS oil,
        1.52 glass).
    fluid_index : float
        Refractive index of the fluid around it (1.000277 air, 1.335 water at 532 nm).
    wavelength_nm : float
        Vacuum wavelength of the light sheet (nm).
    sheet_direction : tuple of 3 float
        Propagation direction of the sheet ``(x1, x2, x3)``; normalised.
    polarisation : str or tuple of 3 float
        ``"perpendicular"``, ``"parallel"``, ``"unpolarised"`` (per ray, relative to its
        scattering plane) or a linear polarisation direction perpendicular to
        ``sheet_direction``.
    particle_absorption : float
        Imaginary part ``k ≥ 0`` of the particle index (``m = n - i k``).
    """

    diameter_um: float = 10.0
    particle_index: float = 1.59
    fluid_index: float = 1.0
    wavelength_nm: float = 532.0
    sheet_direction: tuple = (0.0, 1.0, 0.0)
    polarisation: object = "unpolarised"
    particle_absorption: float = 0.0

    def __post_init__(self):
        for name in ("diameter_um", "particle_index", "fluid_index", "wavelength_nm"):
            value = getattr(self, name)
            if not (np.isfinite(value) and value > 0):
                raise RimclError(f"mie {name} must be a positive number, got {value!r}")
        if not (np.isfinite(self.particle_absorption) and self.particle_absorption >= 0):
            raise RimclError(
                f"mie particle_absorption must be >= 0, got {self.particle_absorption!r}"
            )
        if self.particle_index == self.fluid_index and self.particle_absorption == 0:
            raise RimclError(
                "mie: a particle with the fluid's index scatters no light "
                f"(both {self.particle_index})"
            )
        direction = _unit_vector(self.sheet_direction, "mie sheet_direction")
        object.__setattr__(self, "sheet_direction", tuple(direction.tolist()))
        if isinstance(self.polarisation, str):
            if self.polarisation not in POLARISATIONS:
                raise RimclError(
                    f"unknown mie polarisation {self.polarisation!r}; choose from "
                    f"{', '.join(POLARISATIONS)} or give a direction [x1, x2, x3]"
                )
        else:
            field = _unit_vector(self.polarisation, "mie polarisation")
            if abs(field @ direction) > 1e-6:
                raise RimclError(
                    f"the mie polarisation {field.tolist()} must be perpendicular to the "
                    f"sheet direction {direction.tolist()}"
                )
            object.__setattr__(self, "polarisation", tuple(field.tolist()))

    @property
    def relative_index(self):
        """Particle index relative to the fluid, ``m = (n - i k) / n_fluid``."""
        return complex(self.particle_index, -self.particle_absorption) / self.fluid_index

    @property
    def size_parameter(self):
        """``x = π d n_fluid / λ`` (dimensionless)."""
        return np.pi * self.diameter_um * self.fluid_index / (1e-3 * self.wavelength_nm)

    def scattering_cosines(self, directions):
        """``cos θ = k · d`` of unit ray directions ``(..., 3)`` → ``(...)``."""
        return np.asarray(directions, dtype=np.float64) @ np.asarray(self.sheet_direction)

    def _scaled_coefficients(self):
        """``(2n + 1) / (n (n + 1))`` times ``a_n`` and ``b_n``, complex, shape (n_terms,)."""
        a, b = miepython.coefficients(self.relative_index, self.size_parameter)
        order = np.arange(1, len(a) + 1)
        scale = (2 * order + 1) / (order * (order + 1))
        return scale * a, scale * b

    def intensities(self, cosines):
        """``|S1|²`` and ``|S2|²`` (Wiscombe normalisation) at scattering cosines.

        Parameters
        ----------
        cosines : array_like, shape (K,)
            ``cos θ`` in ``[-1, 1]``.

        Returns
        -------
        perpendicular, parallel : ndarray, float64, shape (K,)
            ``|S1|²`` and ``|S2|²``.
        """
        mu = np.clip(np.asarray(cosines, dtype=np.float64).reshape(-1), -1.0, 1.0)
        scaled_a, scaled_b = self._scaled_coefficients()
        perpendicular = np.empty(mu.shape)
        parallel = np.empty(mu.shape)
        for start in range(0, len(mu), _ANGLE_CHUNK):
            part = slice(start, start + _ANGLE_CHUNK)
            s1, s2 = _amplitudes(mu[part], scaled_a, scaled_b)
            perpendicular[part] = np.abs(s1) ** 2
            parallel[part] = np.abs(s2) ** 2
        return perpendicular, parallel

    def device_table(self):
        """The series as ``cl/rimcl_mie.h`` reads it, and its ``RIMCL_MIE`` mode.

        Returns
        -------
        mode : int
            1 perpendicular, 2 parallel, 3 unpolarised, 4 a polarisation direction.
        table : ndarray, float64, shape (6 + 4 n_terms,)
            Sheet direction, polarisation direction (zeros unless mode 4), then the scaled
            ``a_n``, ``b_n`` of every order as ``(Re a, Im a, Re b, Im b)``.
        """
        scaled_a, scaled_b = self._scaled_coefficients()
        terms = np.stack([scaled_a.real, scaled_a.imag, scaled_b.real, scaled_b.imag])
        modes = {"perpendicular": 1, "parallel": 2, "unpolarised": 3}
        if isinstance(self.polarisation, str):
            mode, polarisation = modes[self.polarisation], np.zeros(3)
        else:
            mode, polarisation = 4, np.asarray(self.polarisation, dtype=np.float64)
        table = np.concatenate([self.sheet_direction, polarisation, terms.T.reshape(-1)])
        return mode, np.ascontiguousarray(table, dtype=np.float64)

    def weights(self, directions):
        """Light carried by each ray, from its initial unit direction.

        Parameters
        ----------
        directions : array_like, shape (..., 3)
            Unit initial directions of the rays (as leaving the tracer).

        Returns
        -------
        ndarray, float64, shape (...)
        """
        directions = np.asarray(directions, dtype=np.float64)
        flat = directions.reshape(-1, 3)
        perpendicular, parallel = self.intensities(self.scattering_cosines(flat))
        if self.polarisation == "perpendicular":
            weights = perpendicular
        elif self.polarisation == "parallel":
            weights = parallel
        elif self.polarisation == "unpolarised":
            weights = 0.5 * (perpendicular + parallel)
        else:
            sheet = np.asarray(self.sheet_direction)
            normal = np.cross(sheet, flat)
            length = np.linalg.norm(normal, axis=1)
            along = length < _PARALLEL_TOLERANCE
            # e⊥ of each ray's scattering plane; along k the plane is undefined but S1 = S2
            share_perpendicular = np.ones(len(flat))
            e_perp = normal[~along] / length[~along, None]
            share_perpendicular[~along] = (e_perp @ np.asarray(self.polarisation)) ** 2
            weights = share_perpendicular * perpendicular + (1 - share_perpendicular) * parallel
        return weights.reshape(directions.shape[:-1])

    def describe(self):
        """Plain-value description for output files."""
        return {
            "mie": True,
            "diameter_um": self.diameter_um,
            "particle_index": self.particle_index,
            "particle_absorption": self.particle_absorption,
            "fluid_index": self.fluid_index,
            "wavelength_nm": self.wavelength_nm,
            "sheet_direction": list(self.sheet_direction),
            "polarisation": (
                self.polarisation if isinstance(self.polarisation, str) else list(self.polarisation)
            ),
            "size_parameter": self.size_parameter,
            "normalisation": "wiscombe",
        }


def _amplitudes(mu, scaled_a, scaled_b):
    """``S1, S2`` (up to conjugation) at cosines ``mu``, summing the series over orders.

    ``π_n`` and ``τ_n`` are real, so the real and imaginary parts are summed apart: the
    same operations, in the same order, as the complex sums make on each part (their
    products with the promoted zero imaginary parts add nothing), at a third of the work.
    """
    a_re, a_im = np.real(scaled_a), np.imag(scaled_a)
    b_re, b_im = np.real(scaled_b), np.imag(scaled_b)
    sums = [np.zeros(mu.shape) for _ in range(4)]  # Re S1, Im S1, Re S2, Im S2
    pi_previous = np.zeros(mu.shape)  # π_0
    pi_current = np.ones(mu.shape)  # π_1
    for n in range(1, len(scaled_a) + 1):
        tau = n * mu * pi_current - (n + 1) * pi_previous
        sums[0] += a_re[n - 1] * pi_current + b_re[n - 1] * tau
        sums[1] += a_im[n - 1] * pi_current + b_im[n - 1] * tau
        sums[2] += a_re[n - 1] * tau + b_re[n - 1] * pi_current
        sums[3] += a_im[n - 1] * tau + b_im[n - 1] * pi_current
        pi_previous, pi_current = (
            pi_current,
            ((2 * n + 1) * mu * pi_current - (n + 1) * pi_previous) / n,
        )
    s1 = np.empty(mu.shape, dtype=np.complex128)
    s2 = np.empty(mu.shape, dtype=np.complex128)
    s1.real, s1.imag = sums[0], sums[1]
    s2.real, s2.imag = sums[2], sums[3]
    return s1, s2


def ray_weights(directions, mie=None):
    """Weights of rays from their initial directions: Mie intensities, or 1 when off.

    Parameters
    ----------
    directions : array_like, shape (..., 3)
    mie : MieWeights, optional

    Returns
    -------
    ndarray, float64, shape (...)
    """
    directions = np.asarray(directions)
    if mie is None:
        return np.ones(directions.shape[:-1])
    return mie.weights(directions)
