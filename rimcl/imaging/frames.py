"""The camera's side of a measurement: ray image points → per-tracer rows (NumPy engine).

For a batch of tracers, each with the image points ``r'`` of its rays, this
module renders each tracer's window image, digitises it, thresholds it and locates the
tracer, and also forms the optics mean ``x_opt``: the
light-weighted mean of the collected rays' image points, without pixels.

This is the readable reference engine (``engine = "numpy"``): one tracer at a time, in
Python. The device engine computes the same rows on the OpenCL device; tests compare the
two on the same inputs.

Columns of a batch result (arrays of shape ``(B,)``, one per tracer):

============ ======= ==============================================================
column       dtype   meaning
============ ======= ==============================================================
x2, x3       float64 centroid on the sheet (field length units); NaN if not found
x2_opt       float64 light-weighted mean of the collected rays' ``r'`` (no pixels)
x3_opt       float64
area         int64   pixels of the tracer's component
perimeter    float64 scikit-image's perimeter (4-neighbourhood), pixels
circularity  float64 ``P² / (4π A)``
n_rays_ok    int64   rays that reached the camera (traced ok and collected)
flags        int64   :class:`rimcl.imaging.centroid.TracerFlag` bits
peak         float64 brightest pixel before clipping, in counts
scale        float64 counts per unit of light (set by the reference image)
x2_<v>       float64 centroid at variant threshold ``v`` of :data:`THRESHOLD_VARIANTS`
x3_<v>       float64 (the same digitised image, located again); NaN if not found
flags_<v>    int64   the flags at that threshold (its own ``BELOW_THRESHOLD``,
                     ``SPLIT``, ``TOUCHES_EDGE``; the rays' and saturation bits shared)
============ ======= ==============================================================

The variant thresholds cost no tracing and no rendering: the tracer is located again in the
counts of its window, so every measurement carries what the threshold ×½ and ×2 would have
measured (the sensitivity band of :mod:`rimcl.stats.sensitivity`).
"""

import dataclasses
import time

import numpy as np
from threadpoolctl import threadpool_limits

from rimcl.core.errors import RimclError
from rimcl.imaging.centroid import CENTROID_WEIGHTS, NO_POSITION, TracerFlag, locate, not_found
from rimcl.imaging.render import Renderer
from rimcl.imaging.sensor import NoiseKey, Sensor

SCALINGS = ("reference", "per_image")
#: What a split image (several components) or one whose rays spread past the window does
#: to its tracer: ``exclude`` it from the statistics, or locate it by its ``brightest``
#: component as a detection over a whole frame does (the paper's), noted.
SPLIT_MODES = ("exclude", "brightest")
#: Other thresholds every tracer is located at too: (column suffix, factor on the threshold).
THRESHOLD_VARIANTS = (("threshold_half", 0.5), ("threshold_double", 2.0))
#: The columns of a tracer located at one variant threshold (``<name>_<suffix>``).
VARIANT_COLUMNS = {"x2": np.float64, "x3": np.float64, "flags": np.int64}
IMAGE_COLUMNS = {
    "x2": np.float64,
    "x3": np.float64,
    "x2_opt": np.float64,
    "x3_opt": np.float64,
    "area": np.int64,
    "perimeter": np.float64,
    "circularity": np.float64,
    "n_rays_ok": np.int64,
    "flags": np.int64,
    "peak": np.float64,
    "scale": np.float64,
    **{
        f"{name}_{suffix}": dtype
        for suffix, _ in THRESHOLD_VARIANTS
        for name, dtype in VARIANT_COLUMNS.items()
    },
}


def empty_columns(shape):
    """Image columns filled with NaN (floats) or 0 (integers), each of ``shape``."""
    return {
        name: np.full(shape, np.nan if dtype is np.float64 else 0, dtype=dtype)
        for name, dtype in IMAGE_COLUMNS.items()
    }


@dataclasses.dataclass(frozen=True)
class Imaging:
    """How the camera turns a tracer's rays into a located tracer.

    Attributes
    ----------
    renderer : Renderer
        Pixels, PSF, window and bit depth.
    threshold : float
        Grey threshold in counts (pixels strictly above it belong to tracers).
    centroid_weights : {"excess", "grey"}
        See :mod:`rimcl.imaging.centroid`.
    sensor : rimcl.imaging.sensor.Sensor, optional
        Digitises the rendered light (default: the deterministic camera of the renderer's
        bit depth: scale, round, clip).
    scaling : {"reference", "per_image"}
        ``reference``: each tracer's measured image uses the scale of its reference image
        (comparable images); ``per_image``: every image is scaled to its own
        peak, as the paper "rescaled to a 10-bit dynamic range" (a distorted image then
        keeps its full brightness and grows above the threshold).
    split : {"exclude", "brightest"}
        :data:`SPLIT_MODES`: ``exclude`` leaves a split image, or one whose rays spread
        past the largest window, out of the statistics (flags ``split``,
        ``rays_outside_window``); ``brightest`` keeps its brightest component's centroid,
        as a detection over the whole frame finds it, and only notes the flags.
    """

    renderer: Renderer
    threshold: float
    centroid_weights: str = "excess"
    scaling: str = "reference"
    sensor: Sensor = None
    split: str = "exclude"

    def __post_init__(self):
        if self.split not in SPLIT_MODES:
            raise RimclError(f"unknown split mode {self.split!r}; choose from {SPLIT_MODES}")
        if self.sensor is None:
            object.__setattr__(self, "sensor", Sensor(bit_depth=self.renderer.bit_depth))
        elif int(self.sensor.bit_depth) != int(self.renderer.bit_depth):
            raise RimclError(
                f"the sensor has {self.sensor.bit_depth} bits but the renderer "
                f"{self.renderer.bit_depth}"
            )
        if self.centroid_weights not in CENTROID_WEIGHTS:
            raise RimclError(
                f"unknown centroid weights {self.centroid_weights!r}; "
                f"choose from {CENTROID_WEIGHTS}"
            )
        if self.scaling not in SCALINGS:
            raise RimclError(f"unknown image scaling {self.scaling!r}; choose from {SCALINGS}")
        full_scale = self.renderer.full_scale
        if not (np.isfinite(self.threshold) and 0 <= self.threshold < full_scale):
            raise RimclError(
                f"the threshold must be in [0, {full_scale}) counts of the "
                f"{self.renderer.bit_depth}-bit camera, got {self.threshold}"
            )

    def variant_thresholds(self):
        """``(suffix, threshold in counts)`` of each of :data:`THRESHOLD_VARIANTS` (one at or
        above full scale finds no tracer: ``BELOW_THRESHOLD``)."""
        return tuple(
            (suffix, factor * float(self.threshold)) for suffix, factor in THRESHOLD_VARIANTS
        )

    def describe(self):
        return {
            **self.renderer.describe(),
            "threshold": float(self.threshold),
            "centroid_weights": self.centroid_weights,
            "scaling": self.scaling,
            "sensor": self.sensor.describe(),
        }


def optics_mean(points, weights):
    """Light-weighted mean image point of each tracer, ignoring unusable rays.

    Parameters
    ----------
    points : ndarray, shape (B, K, 2)
        Ray image points ``r' = (x2, x3)``.
    weights : ndarray, shape (B, K)
        Light per ray; 0 for rays that did not reach the camera.

    Returns
    -------
    ndarray, shape (B, 2)
        NaN for a tracer with no light.
    """
    total = weights.sum(axis=1)
    safe = np.where((weights > 0)[..., None], points, 0.0)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.einsum("bk,bkc->bc", weights, safe) / total[:, None]


def image_batch(
    imaging, points, usable, weights, flags, scales=None, timings=None, canvas=None, noise=None
):
    """Render, digitise and locate each tracer of a batch (NumPy engine).

    Parameters
    ----------
    imaging : Imaging
    points : ndarray, float64, shape (B, K, 2)
        Image points ``r'`` of each tracer's ``K`` rays (sheet coordinates).
    usable : ndarray, bool, shape (B, K)
        Rays traced ``ok`` and collected by the camera.
    weights : ndarray, float64, shape (K,) or (B, K)
        Light per ray (uniform or Mie weights).
    flags : ndarray, int, shape (B,)
        Flags already known (failed or vignetted rays).
    scales : ndarray, shape (B,), optional
        Counts per unit of light of each tracer; None for the reference pass, which sets
        them from its own images (peak → full scale). Ignored with ``per_image`` scaling.
    timings : dict, optional
        ``render`` and ``centroid`` seconds are added to it.
    canvas : rimcl.imaging.render.FrameImage, optional
        Receives each window's counts (for a full-frame picture).
    noise : (int, int, ndarray), optional
        ``(pass_id, frame, tracer_ids)``: the keys of a noisy sensor's draws
        (:class:`rimcl.imaging.sensor.NoiseKey`); ``tracer_ids`` of shape (B,).

    Returns
    -------
    dict of str to ndarray, shape (B,)
        The columns of :data:`IMAGE_COLUMNS`.
    """
    count = len(points)
    weights = np.broadcast_to(np.asarray(weights, dtype=np.float64), usable.shape)
    light = np.where(usable, weights, 0.0)
    out = empty_columns(count)
    out["x2_opt"], out["x3_opt"] = optics_mean(points, light).T
    out["n_rays_ok"][:] = usable.sum(axis=1)
    timings = {"render": 0.0, "centroid": 0.0} if timings is None else timings
    renderer = imaging.renderer
    per_image = imaging.scaling == "per_image"
    # one small matrix product per tracer: a multi-threaded BLAS spends 10x longer
    # starting its threads than computing (measured on 2 cores)
    with threadpool_limits(limits=1, user_api="blas"):
        for k in range(len(points)):
            tracer_flags = TracerFlag(int(flags[k]))
            scale = None if scales is None or per_image else float(scales[k])
            saturated = False
            if not usable[k].any():
                blob, window = not_found(tracer_flags | TracerFlag.NO_RAYS), None
                variants = {}
            else:
                start = time.perf_counter()
                pixels = renderer.to_pixels(points[k][usable[k]])
                window = renderer.window_for(pixels)
                raw, outside = renderer.render(pixels, weights[k][usable[k]], window)
                if outside:
                    tracer_flags |= TracerFlag.RAYS_OUTSIDE_WINDOW
                if scale is None:
                    scale = imaging.sensor.scale_for(raw)
                key = None if noise is None else NoiseKey(noise[0], noise[1], int(noise[2][k]))
                counts, saturated = imaging.sensor.digitize(
                    raw, scale, window.row0, window.col0, key
                )
                out["peak"][k] = float(np.max(raw)) * scale
                middle = time.perf_counter()
                blob = locate(counts, imaging.threshold, imaging.centroid_weights)
                variants = {
                    suffix: locate(counts, value, imaging.centroid_weights, shape=False)
                    for suffix, value in imaging.variant_thresholds()
                }
                timings["render"] += middle - start
                timings["centroid"] += time.perf_counter() - middle
                if canvas is not None and np.isfinite(scale):  # NaN: a window without light
                    canvas.add(window, counts)
            if saturated:
                tracer_flags |= TracerFlag.SATURATED
            for suffix, _ in THRESHOLD_VARIANTS:
                located = variants.get(suffix, blob)
                out[f"flags_{suffix}"][k] = int(tracer_flags | located.flags)
                if not located.flags & NO_POSITION:
                    position = renderer.to_sheet(
                        [window.col0 + located.col, window.row0 + located.row]
                    )
                    out[f"x2_{suffix}"][k], out[f"x3_{suffix}"][k] = position
            tracer_flags |= blob.flags
            if not blob.flags & NO_POSITION:
                position = renderer.to_sheet([window.col0 + blob.col, window.row0 + blob.row])
                out["x2"][k], out["x3"][k] = position
            out["area"][k] = blob.area
            out["perimeter"][k] = blob.perimeter
            out["circularity"][k] = blob.circularity
            out["flags"][k] = int(tracer_flags)
            out["scale"][k] = np.nan if scale is None else scale
    return out
