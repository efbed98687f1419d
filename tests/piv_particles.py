"""Synthetic PIV images for the correlation tests: a small NumPy erf-Gaussian renderer.

Particle images are pixel-integrated Gaussians (exact, no peak locking), as rimcl's exact
renderer makes them, but drawn without OpenCL or rays so that the tests stay fast.
Coordinates follow :mod:`rimcl.piv.analysis`: ``x`` along columns, ``y`` along rows, pixel
``(i, j)`` covering ``[j, j+1) x [i, i+1)``.
"""

import numpy as np
from scipy.special import ndtr


def render_particles(x, y, shape, sigma, brightness=1.0):
    """Image of point particles blurred by a pixel-integrated Gaussian PSF.

    Parameters
    ----------
    x, y : ndarray, shape (N,)
        Particle centres (pixels; pixel centres at integer coordinates, as rimcl's PIV).
    shape : tuple of 2 int
        Image ``(rows, columns)``.
    sigma : float
        PSF standard deviation (pixels); the image diameter is ``d = 4 sigma``.
    brightness : float or ndarray (N,)
        Light per particle.

    Returns
    -------
    ndarray, float64, shape ``shape``
    """
    reach = int(np.ceil(5 * sigma)) + 1
    offsets = np.arange(-reach, reach + 1)
    brightness = np.broadcast_to(np.asarray(brightness, dtype=np.float64), x.shape)

    def tables(centres):
        # pixel centres at integer coordinates: pixel j spans [j - 1/2, j + 1/2)
        first = np.floor(centres + 0.5).astype(np.int64)[:, None] + offsets[None, :]
        weights = ndtr((first + 0.5 - centres[:, None]) / sigma) - ndtr(
            (first - 0.5 - centres[:, None]) / sigma
        )
        return first, weights

    cols, wx = tables(np.asarray(x, dtype=np.float64))
    rows, wy = tables(np.asarray(y, dtype=np.float64))
    patches = brightness[:, None, None] * wy[:, :, None] * wx[:, None, :]
    rr = np.broadcast_to(rows[:, :, None], patches.shape)
    cc = np.broadcast_to(cols[:, None, :], patches.shape)
    inside = (rr >= 0) & (rr < shape[0]) & (cc >= 0) & (cc < shape[1])
    image = np.zeros(shape)
    np.add.at(image, (rr[inside], cc[inside]), patches[inside])
    return image


def particle_pair(displacement, shape=(256, 256), density=0.03, diameter=3.0, seed=0, bits=16):
    """An image pair of particles moved by ``displacement(x, y) -> (dx, dy)`` (pixels).

    Particles are seeded uniformly over the image and a band around it (so particles
    enter as well as leave), at ``density`` per pixel; the displacement is applied at
    each particle's first position. Images are quantised to ``bits`` with an isolated
    particle peaking at half full scale.

    Returns
    -------
    image_a, image_b : ndarray, uint16, shape ``shape``
    """
    rng = np.random.default_rng(seed)
    band = 8.0
    height, width = shape
    area = (height + 2 * band) * (width + 2 * band)
    count = rng.poisson(density * area)
    # the image spans [-0.5, width - 0.5) (pixel centres at integer coordinates)
    x = rng.uniform(-band, width + band, count) - 0.5
    y = rng.uniform(-band, height + band, count) - 0.5
    dx, dy = displacement(x, y)
    sigma = diameter / 4
    full = 2**bits - 1
    peak = (ndtr(0.5 / sigma) - ndtr(-0.5 / sigma)) ** 2
    scale = 0.5 * full / peak
    images = []
    for px, py in ((x, y), (x + dx, y + dy)):
        raw = render_particles(px, py, shape, sigma) * scale
        images.append(np.clip(np.rint(raw), 0, full).astype(np.uint16))
    return images[0], images[1]


def uniform(shift_x, shift_y):
    """A displacement function moving every particle by the same amount (pixels)."""

    def move(x, y):
        return np.full_like(x, shift_x), np.full_like(y, shift_y)

    return move
