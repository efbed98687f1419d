"""Each camera's tracer images, made and located as the measurement makes them.

A tracer's rays reach a camera at image points (px, :func:`rimcl.lpt.views.view`); each ray
carries the light the tracer scatters towards it: its Mie intensity at the ray's own
scattering angle (:class:`rimcl.imaging.mie.MieWeights`, from the ``[mie]`` section; the
illumination's direction is ``mie.sheet_direction``), or 1 with Mie off, divided by the
rays per tracer so that a tracer's light does not depend on the count. The rays are
rendered in a window per tracer (pixel-integrated Gaussians of the camera's diffraction
σ, :class:`rimcl.imaging.render.Renderer` ``exact``), digitised by the sensor
(:class:`rimcl.imaging.sensor.Sensor`, shot and read noise when ``sensor.noise``) and
located by the thresholded grey-weighted centroid (:func:`rimcl.imaging.centroid.locate`,
and again at the threshold ×½ and ×2 in the same digitised image: the sensitivity band),
by either engine of PTV (``run.engine``): the NumPy engine,
:func:`rimcl.imaging.frames.image_batch`, or the device's image kernel
(:class:`rimcl.imaging.device.PointImager`, ``cl/image.cl``) on the same image points, whose
centroids equal the NumPy engine's to the last bit where the digitised images agree. The
same call gives the optics centroid (the light-weighted mean of the rays' image points, no
pixels): the optics part of the error; the located centroid minus it is the imaging part.

**Exposure.** A camera records light with one gain for every tracer (not one per tracer):
the rig's exposure is set so that the median tracer of the brightest camera (its
reference image through the uniform fluid at the first frame, in focus) peaks at
``lpt.exposure`` of the sensor's level (full scale without noise, ``sensor.peak_electrons``
with noise). With Mie weights the cameras at other scattering angles see dimmer (or
brighter, clipped) tracers. Each camera's threshold is ``lpt.threshold`` of its own median
tracer's peak (counts), as an experimenter sets it per camera.

**Pixels.** LPT pixel coordinates put pixel ``(0, 0)``'s centre at ``(0, 0)``; the renderer's
pixel ``i`` spans ``[i, i + 1)``, so its origin is ``(-0.5, -0.5)`` with a pixel size of 1.

**Noise draws** are keyed ``(pass, frame, c N + i)`` for tracer ``i`` of camera ``c``: the
image through the field and the one through the uniform fluid share pass 0 (common random
numbers: their difference is refraction alone), the noise floor's second exposure of the
uniform fluid draws pass 1; independent between cameras, the same in every case.
"""

import dataclasses

import numpy as np

from rimcl.imaging.centroid import EXCLUDING, TracerFlag
from rimcl.imaging.frames import THRESHOLD_VARIANTS, Imaging, image_batch
from rimcl.imaging.mie import ray_weights
from rimcl.imaging.render import Renderer, Window
from rimcl.imaging.sensor import FLOOR_PASS, MEASURED_PASS, REFERENCE_PASS, Sensor

#: Pixel-coordinate origin of the renderer for LPT pixels (pixel centres at integers).
ORIGIN = (-0.5, -0.5)
PASSES = {"ref": REFERENCE_PASS, "meas": MEASURED_PASS, "floor": FLOOR_PASS}


def renderer_for(camera, bit_depth, max_window=512):
    """The exact renderer of ``camera``'s pixels and diffraction PSF."""
    return Renderer(
        "exact",
        1.0,
        ORIGIN,
        psf_sigma=camera.psf_sigma_px,
        max_window=max_window,
        bit_depth=bit_depth,
    )


def ray_light(view, mie=None):
    """Light per ray of each tracer, shape (N, K): Mie intensity (or 1) over K.

    Parameters
    ----------
    view : rimcl.lpt.views.View
    mie : rimcl.imaging.mie.MieWeights, optional
    """
    return ray_weights(view.directions, mie) / view.directions.shape[1]


def _unit_peak(renderer):
    """Peak of the image of a unit of light centred on a pixel (before the sensor)."""
    image, _ = renderer.render(np.array([[0.5, 0.5]]) + renderer.pad, np.ones(1), _square(renderer))
    return float(image.max())


def _square(renderer):
    side = 2 * renderer.pad + 2
    return Window(0, 0, side, side)


@dataclasses.dataclass(frozen=True)
class Exposure:
    """The rig's exposure and each camera's threshold.

    Attributes
    ----------
    scale : float
        Sensor units per unit of light (counts without noise, mean photoelectrons with).
    counts_per_light : float
        Counts per unit of light of the noiseless camera of the same exposure.
    thresholds : tuple of float
        Grey threshold of each camera (counts).
    median_light : tuple of float
        Each camera's median tracer light (in units of a ray of weight 1).
    unit_peaks : tuple of float
        Peak of each camera's image of a unit of light centred on a pixel.
    """

    scale: float
    counts_per_light: float
    thresholds: tuple
    median_light: tuple
    unit_peaks: tuple

    def describe(self):
        return dataclasses.asdict(self)


def rig_exposure(cameras, reference_views, mie, sensor, exposure, threshold):
    """Set the rig's exposure from the tracers' reference views (first frame).

    Parameters
    ----------
    cameras : list of RigCamera
    reference_views : list of View
        Each camera's view of the tracers through the uniform fluid.
    mie : MieWeights or None
    sensor : rimcl.imaging.sensor.Sensor
    exposure : float
        Peak of the brightest camera's median tracer, as a fraction of the sensor's level.
    threshold : float
        Each camera's threshold above the sensor's mean background, as a fraction of its
        median tracer's peak.

    Returns
    -------
    Exposure
    """
    medians, peaks = [], []
    for camera, seen in zip(cameras, reference_views, strict=True):
        light = np.where(np.isfinite(seen.images[..., 0]), ray_light(seen, mie), 0.0)
        medians.append(float(np.median(light.sum(axis=1))))
        peaks.append(_unit_peak(renderer_for(camera, sensor.bit_depth)))
    brightest = max(m * p for m, p in zip(medians, peaks, strict=True))
    level = sensor.peak_electrons if sensor.noise else sensor.full_scale
    scale = exposure * level / brightest
    counts_per_light = scale / sensor.gain if sensor.noise else scale
    # above the background, as a PTV code thresholds: a dim camera's fraction of its median
    # peak can lie below the background's level, and then every window is one blob
    background = sensor.background_e / sensor.gain if sensor.noise else 0.0
    thresholds = tuple(
        float(background + threshold * m * p * counts_per_light)
        for m, p in zip(medians, peaks, strict=True)
    )
    return Exposure(float(scale), float(counts_per_light), thresholds, tuple(medians), tuple(peaks))


def camera_imaging(camera, index, exposure, sensor, max_window=512):
    """The :class:`~rimcl.imaging.frames.Imaging` of camera number ``index``."""
    return Imaging(
        renderer_for(camera, sensor.bit_depth, max_window),
        exposure.thresholds[index],
        sensor=sensor,
    )


@dataclasses.dataclass
class Located:
    """One camera's located tracers in one frame.

    Attributes
    ----------
    centroid : ndarray, shape (N, 2)
        Located image centroid (px); NaN where not found.
    optics : ndarray, shape (N, 2)
        Light-weighted mean of the rays' image points (px).
    flags : ndarray of int, shape (N,)
        :class:`rimcl.imaging.centroid.TracerFlag` bits.
    peak : ndarray, shape (N,)
        Brightest pixel before clipping (sensor units).
    variants : dict of str to (ndarray, ndarray)
        Per suffix of :data:`rimcl.imaging.frames.THRESHOLD_VARIANTS`: the centroid
        (N, 2) px and flags (N,) of each tracer located again at that threshold in the
        same digitised image.
    """

    centroid: np.ndarray
    optics: np.ndarray
    flags: np.ndarray
    peak: np.ndarray
    variants: dict


def device_imager(imaging, rays, tracers, device):
    """The device engine of one camera's ``imaging`` for ``rays`` per tracer and batches of
    ``tracers`` (None without a ``device``: the NumPy engine)."""
    from rimcl.imaging.device import PointImager

    return None if device is None else PointImager(imaging, rays, device, tracers)


def locate_view(imaging, view, light, scale, key, imager=None):
    """Render, digitise and locate every tracer of a view.

    Parameters
    ----------
    imaging : rimcl.imaging.frames.Imaging
    view : rimcl.lpt.views.View
    light : ndarray, shape (N, K)
        Light per ray (:func:`ray_light`).
    scale : float
        Sensor units per unit of light (:attr:`Exposure.scale`).
    key : (int, int, int)
        ``(pass, frame, camera index)`` of the noise draws.
    imager : rimcl.imaging.device.PointImager, optional
        The device engine of ``imaging`` and the view's rays per tracer
        (:func:`device_imager`); None: the NumPy engine.

    Returns
    -------
    Located
    """
    count = len(view.images)
    usable = np.all(np.isfinite(view.images), axis=-1)
    flags = np.where(view.failed > 0, int(TracerFlag.RAYS_FAILED), 0)
    pass_id, frame, camera_index = key
    ids = camera_index * count + np.arange(count)
    rays = (np.nan_to_num(view.images), usable, light, flags)
    options = {"scales": np.full(count, scale), "noise": (pass_id, frame, ids)}
    if imager is None:
        out = image_batch(imaging, *rays, **options)
    else:
        out = imager.image(*rays, **options)
    return Located(
        np.column_stack([out["x2"], out["x3"]]),
        np.column_stack([out["x2_opt"], out["x3_opt"]]),
        out["flags"],
        out["peak"],
        {
            suffix: (
                np.column_stack([out[f"x2_{suffix}"], out[f"x3_{suffix}"]]),
                out[f"flags_{suffix}"],
            )
            for suffix, _ in THRESHOLD_VARIANTS
        },
    )


def noiseless(sensor):
    """The deterministic sensor of the same bit depth (for the ray-count choice)."""
    return Sensor(bit_depth=sensor.bit_depth)


def unusable(flags):
    """True where a located tracer has no usable position (an excluding flag)."""
    return (np.asarray(flags) & int(EXCLUDING)) > 0
