"""The frames each camera's sensor records: every tracer, background and noise everywhere.

rimcl locates each tracer in its own window (:func:`rimcl.lpt.images.locate_view`), as a
measurement of that tracer alone. A tracking code given rimcl's dataset sees what the sensor
records instead: the light of every tracer added on one frame (overlapping images add, as
light does), the sensor's background and its shot and read noise over every pixel, digitised
once (:meth:`rimcl.imaging.sensor.Sensor.digitize`). Each tracer's light is rendered from the
same image points and ray weights as its located image (the camera's
:class:`~rimcl.imaging.render.Renderer`), so the frame holds the images rimcl measured,
apart from the noise draw: a frame's noise is keyed ``(pass, frame, FRAME_ID - camera)``,
tracer ids below it (``c N + i``) key the located windows.

The cost is linear in the tracers (one window each) plus the pixels (one noise draw each).
"""

import numpy as np

from rimcl.imaging.sensor import NoiseKey

#: Noise id of camera 0's full frame (camera ``c`` uses ``FRAME_ID - c``): above every
#: located tracer's id ``c N + i``.
FRAME_ID = (1 << 32) - 1


def recorded_frame(imaging, view, light, scale, key, pixels):
    """The counts one camera records in one frame.

    Parameters
    ----------
    imaging : rimcl.imaging.frames.Imaging
        The camera's renderer and sensor.
    view : rimcl.lpt.views.View
        Every tracer's ray image points ``images`` (N, K, 2) px (NaN: a failed ray).
    light : ndarray, shape (N, K)
        Light per ray (:func:`rimcl.lpt.images.ray_light`).
    scale : float
        Sensor units per unit of light (the rig's exposure).
    key : (int, int, int)
        ``(pass, frame, camera index)``.
    pixels : tuple of 2 int
        The sensor's columns and rows.

    Returns
    -------
    ndarray, uint16, shape (rows, columns)
    """
    renderer = imaging.renderer
    columns, rows = (int(p) for p in pixels)
    raw = np.zeros((rows, columns))
    usable = np.all(np.isfinite(view.images), axis=-1)
    for k in np.flatnonzero(usable.any(axis=1)):
        points = renderer.to_pixels(view.images[k][usable[k]])
        window = renderer.window_for(points)
        image, _ = renderer.render(points, light[k][usable[k]], window)
        r0, r1 = max(window.row0, 0), min(window.row0 + window.height, rows)
        c0, c1 = max(window.col0, 0), min(window.col0 + window.width, columns)
        if r0 < r1 and c0 < c1:
            raw[r0:r1, c0:c1] += image[r0 - window.row0 : r1 - window.row0,
                                       c0 - window.col0 : c1 - window.col0]  # fmt: skip
    pass_id, frame, camera_index = key
    noise = NoiseKey(pass_id, frame, FRAME_ID - camera_index)
    counts, _ = imaging.sensor.digitize(raw, scale, 0, 0, noise)
    return counts.astype(np.uint16)
