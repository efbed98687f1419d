"""Gradients of gridded scalars: spectral for periodic boxes, central differences otherwise.

Arrays are C-ordered ``(n3, n2, n1)``: array axis 2 is ``x1``, axis 1 is ``x2``,
axis 0 is ``x3``. Gradients are returned as ``(n3, n2, n1, 3)`` with components along
``x1, x2, x3``.
"""

import numpy as np
import scipy.fft

from rimcl.core.errors import RimclError

# array axis holding each coordinate x1, x2, x3
_AXIS_OF = (2, 1, 0)

# interior central-difference stencils (offsets, weights) by order
_CENTRAL = {
    2: ((-1, 1), (-0.5, 0.5)),
    4: ((-2, -1, 1, 2), (1 / 12, -8 / 12, 8 / 12, -1 / 12)),
    6: ((-3, -2, -1, 1, 2, 3), (-1 / 60, 9 / 60, -45 / 60, 45 / 60, -9 / 60, 1 / 60)),
}


def _one_sided_weights(offsets, order=1):
    """Finite-difference weights for the first derivative at 0 from ``offsets``."""
    offsets = np.asarray(offsets, dtype=float)
    count = offsets.size
    vander = np.vander(offsets, count, increasing=True).T
    rhs = np.zeros(count)
    rhs[order] = 1.0
    return np.linalg.solve(vander, rhs)


def central_difference(values, spacing, axis, order=4, periodic=False):
    """First derivative along one array axis by central differences.

    Near the ends of a non-periodic axis the stencil becomes one-sided with the same
    number of points, so the order of accuracy holds everywhere.

    Parameters
    ----------
    values : ndarray
        Samples on a uniform grid.
    spacing : float
        Grid spacing along ``axis`` (length units).
    axis : int
        Array axis to differentiate.
    order : {2, 4, 6}
    periodic : bool
        Wrap around the axis (the grid holds one full period, endpoint excluded).

    Returns
    -------
    ndarray, float64, same shape as ``values``
    """
    if order not in _CENTRAL:
        raise RimclError(f"finite-difference order must be one of {sorted(_CENTRAL)}")
    data = np.moveaxis(np.asarray(values, dtype=np.float64), axis, 0)
    count = data.shape[0]
    offsets, weights = _CENTRAL[order]
    width = max(offsets)
    if count < 2 * width + 1:
        raise RimclError(
            f"an axis with {count} points is too short for order-{order} differences "
            f"(needs {2 * width + 1})"
        )
    result = np.zeros_like(data)
    if periodic:
        for off, w in zip(offsets, weights, strict=True):
            result += w * np.roll(data, -off, axis=0)
        return np.moveaxis(result / spacing, 0, axis)
    inner = slice(width, count - width)
    for off, w in zip(offsets, weights, strict=True):
        result[inner] += w * data[width + off : count - width + off]
    stencil_size = 2 * width + 1
    for i in list(range(width)) + list(range(count - width, count)):
        start = 0 if i < width else count - stencil_size
        local = np.arange(start, start + stencil_size) - i
        local_w = _one_sided_weights(local)
        result[i] = np.tensordot(local_w, data[start : start + stencil_size], axes=(0, 0))
    return np.moveaxis(result / spacing, 0, axis)


def spectral_derivative(values, spacing, axis):
    """First derivative along one axis of a periodic grid by FFT.

    The grid is one full period sampled without its endpoint (period = n * spacing).
    The Nyquist mode of an even-length axis is zeroed (its derivative is not real).

    Returns
    -------
    ndarray, float64, same shape as ``values``
    """
    data = np.asarray(values, dtype=np.float64)
    count = data.shape[axis]
    wavenumber = 2 * np.pi * scipy.fft.rfftfreq(count, d=spacing)
    if count % 2 == 0:
        wavenumber[-1] = 0.0
    shape = [1] * data.ndim
    shape[axis] = wavenumber.size
    spectrum = scipy.fft.rfft(data, axis=axis, workers=-1)
    spectrum *= 1j * wavenumber.reshape(shape)
    return scipy.fft.irfft(spectrum, n=count, axis=axis, workers=-1)


def gradient(values, spacing, method="fd4", periodic=False):
    """Gradient of a ``(n3, n2, n1)`` scalar field.

    Parameters
    ----------
    values : ndarray, shape (n3, n2, n1)
    spacing : sequence of 3 float
        ``(h1, h2, h3)`` along ``x1, x2, x3``.
    method : {"fd2", "fd4", "fd6", "spectral"}
        ``spectral`` requires a periodic grid.
    periodic : bool

    Returns
    -------
    ndarray, float64, shape (n3, n2, n1, 3)
        Components along ``x1, x2, x3``.
    """
    values = np.asarray(values)
    if values.ndim != 3:
        raise RimclError(f"a scalar field must have shape (n3, n2, n1), got {values.shape}")
    if method == "spectral" and not periodic:
        raise RimclError("spectral gradients need a periodic field")
    parts = []
    for component in range(3):
        axis, h = _AXIS_OF[component], float(spacing[component])
        if values.shape[axis] == 1:
            parts.append(np.zeros(values.shape))
        elif method == "spectral":
            parts.append(spectral_derivative(values, h, axis))
        elif method in ("fd2", "fd4", "fd6"):
            # short axes (a 2-D field stored a few cells thick) take the widest stencil
            # that fits
            order = int(method[2])
            while order > 2 and values.shape[axis] < order + 1:
                order -= 2
            if values.shape[axis] < 3:
                step = np.diff(values.astype(np.float64), axis=axis) / h
                parts.append(np.repeat(step, values.shape[axis], axis=axis))
            else:
                parts.append(central_difference(values, h, axis, order=order, periodic=periodic))
        else:
            raise RimclError(f"unknown gradient method {method!r}")
    return np.stack(parts, axis=-1)
