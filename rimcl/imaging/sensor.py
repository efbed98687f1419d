"""A camera sensor: photoelectrons, shot and read noise, full well, gain and ADC.

Two modes:

- ``noise=False`` (default): today's deterministic camera (:func:`rimcl.imaging.render.quantize`):
  the rendered light times one scale per tracer (its reference image peaks at full scale),
  rounded and clipped to ``[0, 2**bit_depth - 1]``;
- ``noise=True``: the reference image of a tracer peaks at ``peak_electrons`` mean
  photoelectrons; every pixel collects ``N ~ Poisson(signal + background)`` electrons
  (clipped at the full well), gains read noise ``σ_read z`` and is converted to
  ``round(e / gain)`` counts, clipped to the ADC range.

**Random numbers.** Every draw is a pure function of ``(seed, pass, frame, tracer, row,
column)``, with ``row, column`` the pixel in the global sheet grid, and an OpenCL kernel
can reproduce them. The measured image of a tracer (through the field) and its reference
image (through the uniform medium) are one exposure of the same camera: they share the
draws (:data:`MEASURED_PASS` is :data:`REFERENCE_PASS`; common random numbers), so their
difference is refraction alone and a uniform medium gives exactly zero; every case of a
study gets the same draws too. The camera's own noise is measured apart, by a second
exposure of the reference with independent draws (:data:`FLOOR_PASS`): the *noise
floor*. Philox-4x32-10
(Salmon et al., SC'11; the Random123 generator, in plain uint32/uint64 NumPy arithmetic)
maps the counter ``(column, row, tracer, 2 frame + pass)`` under the key ``(seed mod 2³²,
seed div 2³²)`` to four uint32 words ``w0 … w3``, turned into uniforms
``u_i = (w_i + 0.5) / 2³²``. Per pixel, in this exact order of float64 operations:

- shot noise, mean ``m ≤`` :data:`POISSON_INVERSION_MAX`: inversion with ``u0``:
  ``p = exp(-m); c = p; k = 0; while u0 > c and k < KMAX: k += 1; p = p * (m / k); c += p``;
- shot noise, ``m >`` :data:`POISSON_INVERSION_MAX`: a rounded normal,
  ``k = max(0, rint(m + sqrt(m) z0))`` with ``z0 = sqrt(-2 log u0) cos(2π u1)`` (mean
  ``m``, variance ``m + 1/12``; the Poisson skewness ``1/sqrt(m) < 0.25`` is neglected);
- read noise: ``σ_read z1`` with ``z1 = sqrt(-2 log u2) cos(2π u3)``.

The integer words are bit-exact on any device; the float64 transforms (``exp``, ``log``,
``sqrt``, ``cos``) may differ in the last ulp between libraries, which changes a count only
when a value falls within ~1e-16 of a rounding boundary.
"""

import dataclasses
import typing

import numpy as np

from rimcl.core.errors import RimclError
from rimcl.imaging.render import BIT_DEPTHS, quantize, scale_for

#: Draws of the reference exposure (through the uniform medium).
REFERENCE_PASS = 0
#: Draws of the measured exposure: the reference's (common random numbers), so that the
#: refraction error ``measured - reference`` holds no sensor noise.
MEASURED_PASS = REFERENCE_PASS
#: Draws of a second, independent exposure of the reference: the noise floor.
FLOOR_PASS = 1
#: The pass ids a noise key may hold.
PASS_IDS = (REFERENCE_PASS, FLOOR_PASS)
#: Largest mean drawn by Poisson inversion; above it the rounded normal approximation.
POISSON_INVERSION_MAX = 16.0
#: Inversion stops here (P(N > 64) < 1e-20 at a mean of 16).
POISSON_INVERSION_KMAX = 64

_PHILOX_M = (0xD2511F53, 0xCD9E8D57)
_PHILOX_W = (0x9E3779B9, 0xBB67AE85)
_PHILOX_ROUNDS = 10
_LOW32 = np.uint64(0xFFFFFFFF)
_TWO_POW_M32 = 2.0**-32


class NoiseKey(typing.NamedTuple):
    """Which draws an image gets: pass (:data:`REFERENCE_PASS`, shared by the measured
    image, or :data:`FLOOR_PASS`), frame and tracer."""

    pass_id: int
    frame: int
    tracer: int


def philox4x32(counter, key):
    """Philox-4x32-10 of counters under one key (Random123's ``philox4x32``).

    Parameters
    ----------
    counter : sequence of 4 array_like of uint32
        The counter words ``c0 … c3`` (broadcast together).
    key : sequence of 2 int
        The key words ``k0, k1`` (< 2³²).

    Returns
    -------
    list of 4 ndarray, uint32
        The output words.
    """
    words = [np.asarray(c, dtype=np.uint32).astype(np.uint64) for c in counter]
    words = list(np.broadcast_arrays(*words))
    k0, k1 = (int(k) & 0xFFFFFFFF for k in key)
    m0, m1 = (np.uint64(m) for m in _PHILOX_M)
    for round_index in range(_PHILOX_ROUNDS):
        if round_index:
            k0 = (k0 + _PHILOX_W[0]) & 0xFFFFFFFF
            k1 = (k1 + _PHILOX_W[1]) & 0xFFFFFFFF
        product0 = m0 * words[0]  # < 2⁶⁴: exact in uint64
        product1 = m1 * words[2]
        words = [
            (product1 >> np.uint64(32)) ^ words[1] ^ np.uint64(k0),
            product1 & _LOW32,
            (product0 >> np.uint64(32)) ^ words[3] ^ np.uint64(k1),
            product0 & _LOW32,
        ]
    return [w.astype(np.uint32) for w in words]


def pixel_uniforms(seed, key, rows, columns):
    """Four uniforms in ``(0, 1)`` per pixel, shape ``(4, *broadcast(rows, columns))``.

    Parameters
    ----------
    seed : int
        ``0 ≤ seed < 2**64``.
    key : NoiseKey
    rows, columns : array_like of int
        Global pixel indices on the sheet grid (may be negative).
    """
    seed = int(seed)
    pass_id, frame, tracer = (int(v) for v in key)
    if seed < 0 or seed >= 1 << 64:
        raise RimclError(f"the noise seed must be in [0, 2**64), got {seed}")
    if pass_id not in PASS_IDS or not 0 <= frame < 1 << 31:
        raise RimclError(f"bad noise key {key!r}: pass must be 0 or 1, frame in [0, 2**31)")
    if not 0 <= tracer < 1 << 32:
        raise RimclError(f"the tracer id must be in [0, 2**32), got {tracer}")
    wrap = np.int64(0xFFFFFFFF)
    counter = (
        np.asarray(columns, dtype=np.int64) & wrap,
        np.asarray(rows, dtype=np.int64) & wrap,
        tracer,
        2 * frame + pass_id,
    )
    words = philox4x32(counter, (seed & 0xFFFFFFFF, seed >> 32))
    return np.stack([(w.astype(np.float64) + 0.5) * _TWO_POW_M32 for w in words])


def _box_muller(u_radius, u_angle):
    return np.sqrt(-2.0 * np.log(u_radius)) * np.cos(2.0 * np.pi * u_angle)


def poisson_from_uniforms(mean, u0, u1):
    """Poisson draws from uniforms (inversion up to the cutoff, rounded normal above).

    Parameters
    ----------
    mean : ndarray, float64
        Means ``≥ 0``.
    u0, u1 : ndarray, float64
        Uniforms in ``(0, 1)``, same shape.

    Returns
    -------
    ndarray, float64
        Integer-valued counts.
    """
    mean = np.asarray(mean, dtype=np.float64)
    counts = np.empty(mean.shape)
    small = mean <= POISSON_INVERSION_MAX
    m, u = mean[small], u0[small]
    term = np.exp(-m)
    cumulative = term.copy()
    k = np.zeros(m.shape)
    for step in range(1, POISSON_INVERSION_KMAX + 1):
        k += u > cumulative  # the loop of the docstring, all pixels at once
        term = term * (m / step)
        cumulative = cumulative + term
    counts[small] = k
    large = ~small
    m = mean[large]
    counts[large] = np.maximum(0.0, np.rint(m + np.sqrt(m) * _box_muller(u0[large], u1[large])))
    return counts


@dataclasses.dataclass(frozen=True)
class Sensor:
    """The camera's sensor and ADC.

    Attributes
    ----------
    bit_depth : int
        ADC bits, 8 … 16; counts run to ``2**bit_depth - 1``.
    noise : bool
        False: deterministic (today's camera, the other settings unused). True: shot noise,
        read noise, background, full well and gain.
    peak_electrons : float
        Mean photoelectrons at the peak pixel of a tracer's reference image.
    read_noise_e : float
        Read noise (e⁻ rms).
    background_e : float
        Mean background per pixel (e⁻), shot noise included.
    full_well_e : float
        Full-well capacity (e⁻); collected electrons are clipped there.
    gain_e_per_count : float, optional
        e⁻ per count; default ``full_well_e / (2**bit_depth - 1)`` (the full well fills
        the ADC range).
    seed : int
        Seed of the noise draws (``0 ≤ seed < 2**64``).
    """

    bit_depth: int = 10
    noise: bool = False
    peak_electrons: float = 10_000.0
    read_noise_e: float = 2.0
    background_e: float = 0.0
    full_well_e: float = 30_000.0
    gain_e_per_count: float = None
    seed: int = 0

    def __post_init__(self):
        if int(self.bit_depth) not in BIT_DEPTHS:
            raise RimclError(f"the sensor bit depth must be 8 to 16, got {self.bit_depth}")
        for name in ("peak_electrons", "full_well_e"):
            value = getattr(self, name)
            if not (np.isfinite(value) and value > 0):
                raise RimclError(f"sensor {name} must be positive, got {value!r}")
        for name in ("read_noise_e", "background_e"):
            value = getattr(self, name)
            if not (np.isfinite(value) and value >= 0):
                raise RimclError(f"sensor {name} must be >= 0, got {value!r}")
        gain = self.gain_e_per_count
        if gain is not None and not (np.isfinite(gain) and gain > 0):
            raise RimclError(f"sensor gain_e_per_count must be positive, got {gain!r}")
        if not 0 <= int(self.seed) < 1 << 64:
            raise RimclError(f"the sensor seed must be in [0, 2**64), got {self.seed}")

    @property
    def full_scale(self):
        """Largest count, ``2**bit_depth - 1``."""
        return 2 ** int(self.bit_depth) - 1

    @property
    def gain(self):
        """e⁻ per count (given, or the full well over the ADC range)."""
        if self.gain_e_per_count is not None:
            return float(self.gain_e_per_count)
        return self.full_well_e / self.full_scale

    def scale_for(self, reference_image):
        """The per-tracer scale set by its reference image (unscaled renderer output).

        Returns
        -------
        float
            Without noise: counts per unit light (the reference peak at full scale, as
            :func:`rimcl.imaging.render.scale_for`). With noise: mean photoelectrons per unit light
            (the reference peak at ``peak_electrons``). NaN for an empty image.
        """
        if not self.noise:
            return scale_for(reference_image, self.full_scale)
        return scale_for(reference_image, self.peak_electrons)

    def digitize(self, raw_image, scale, window_row0, window_col0, key):
        """The counts the camera records of a rendered window.

        Parameters
        ----------
        raw_image : ndarray, shape (rows, columns)
            Unscaled light per pixel (:meth:`rimcl.imaging.render.Renderer.render`).
        scale : float
            From :meth:`scale_for` of the tracer's reference image.
        window_row0, window_col0 : int
            Global sheet-grid pixel of the window's ``[0, 0]``.
        key : NoiseKey
            Unused without noise.

        Returns
        -------
        counts : ndarray, float64, shape (rows, columns)
            Integer-valued counts in ``[0, 2**bit_depth - 1]``.
        saturated : bool
            Some pixel reached the full well or was clipped at the ADC's full scale.
        """
        if not self.noise:
            return quantize(raw_image, scale, self.full_scale)
        if key is None:
            raise RimclError("a noisy sensor needs a NoiseKey (pass, frame, tracer) per image")
        raw_image = np.asarray(raw_image, dtype=np.float64)
        rows = int(window_row0) + np.arange(raw_image.shape[0])[:, None]
        columns = int(window_col0) + np.arange(raw_image.shape[1])[None, :]
        u0, u1, u2, u3 = pixel_uniforms(self.seed, key, rows, columns)
        mean = np.maximum(raw_image * scale, 0.0) + self.background_e
        electrons = poisson_from_uniforms(mean, u0, u1)
        well_full = electrons >= self.full_well_e
        electrons = np.minimum(electrons, self.full_well_e)
        if self.read_noise_e > 0:
            electrons = electrons + self.read_noise_e * _box_muller(u2, u3)
        counts = np.rint(electrons / self.gain)
        saturated = bool(np.any(well_full) or np.any(counts > self.full_scale))
        return np.clip(counts, 0, self.full_scale), saturated

    def describe(self):
        """Plain-value description for output files."""
        record = {"bit_depth": int(self.bit_depth), "full_scale": self.full_scale}
        record["noise"] = bool(self.noise)
        if self.noise:
            record.update(
                peak_electrons=self.peak_electrons,
                read_noise_e=self.read_noise_e,
                background_e=self.background_e,
                full_well_e=self.full_well_e,
                gain_e_per_count=self.gain,
                seed=int(self.seed),
                rng="philox4x32-10",
                poisson_inversion_max=POISSON_INVERSION_MAX,
            )
        return record
