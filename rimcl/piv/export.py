"""PIV vectors in the files other PIV tools read (:func:`export_vectors`).

By the suffix of the path:

- ``.nc``: netCDF-4 / HDF5 that xarray opens (``xarray.open_dataset(path,
  engine="h5netcdf")``): coordinates ``x`` (columns) and ``y`` (rows) as dimension scales,
  variables ``u``, ``v`` (displacement, px per frame pair), ``flags`` (1: an outlier
  replaced), ``mask`` (1: no light in the window), ``peak_ratio``; with a pixel size and a
  time step also ``x_m``, ``y_m`` (m) and ``u_ms``, ``v_ms`` (m/s); ``units`` on every
  variable, the configuration as a global attribute. Always rimcl's image orientation;
- ``.txt``: the text file of ``openpiv.tools.save``: one row per vector in the grid's row
  order (top row of windows first), columns ``x y u v flags mask``, tab-separated, the
  header line ``# x<TAB>y<TAB>u<TAB>v<TAB>flags<TAB>mask`` first, then ``#`` lines with
  rimcl's units, the orientation and ``rimcl_record`` (JSON: configuration, versions,
  scales); ``numpy.loadtxt(path)`` reads it as OpenPIV's ``tools.display_vector_field``
  does. Coordinates are OpenPIV's: a window of pixels
  ``c … c + N − 1`` is centred at ``c + N/2`` (rimcl: ``c + (N − 1)/2``, so ``x = x_rimcl +
  1/2``). ``y-up`` (the default) is OpenPIV's ``tools.transform_coordinates``: the row
  coordinates reversed (the top row of windows carries the largest ``y``), ``v = −dy``
  (up the frame); ``y-down`` keeps OpenPIV's image coordinates (``y``, ``v`` down the
  frame). px and px per pair, or with a pixel size and a time step m and m/s (OpenPIV's
  ``scaling.uniform`` with ``u`` in px per ``dt``); values printed ``%.8e`` (OpenPIV's
  default ``%.4e`` keeps 5 digits);
- ``.mat``: what PIVlab's *Export → MAT file* writes (``+export/mat_file_save.m``, all frames
  of a session: cells of one frame pair), by ``scipy.io.savemat``: ``x``, ``y``,
  ``u_original``, ``v_original``, ``typevector_original`` (1 a vector, 2 replaced, 0
  masked), ``u_filtered``, ``v_filtered`` (masked vectors NaN), ``typevector_filtered``,
  ``u_smoothed``, ``v_smoothed`` (empty: rimcl does not smooth), ``calxy`` (m per px, 1
  without a scale), ``calu``, ``calv`` (m/s per px per pair, or ±1 without scales),
  ``units`` (PIVlab's ``'[m] respectively [m/s]'`` or ``'[px] respectively [px/frame]'``),
  ``information``, and rimcl's ``orientation`` and ``rimcl_config`` (JSON). As in PIVlab
  the values are calibrated: ``u_original = calu × dx``, ``v_original = calv × dy``,
  ``x = calxy × x_px``, from MATLAB's 1-based pixel coordinates ``x_px = x_rimcl + 1``;
  ``y-down`` is PIVlab's default axes (``y = calxy × (y_rimcl + 1)``, ``calv = calu``),
  ``y-up`` its "y increases to the top" (``y = calxy × (rows − y_rimcl − 1)``, ``calv =
  −calu``).

Coordinates of :class:`rimcl.piv.analysis.PivResult`: ``x`` along image columns, ``y`` along
image rows (row 0 at the top, pixel centres at integers), ``dx``, ``dy`` the displacement
along them.
"""

import json
from pathlib import Path

import numpy as np

from rimcl.core.atomic import atomic_path, check_output
from rimcl.core.errors import RimclError
from rimcl.core.provenance import to_json, versions
from rimcl.piv.analysis import WindowGrid

FORMATS = {".nc": "netCDF-4 (xarray)", ".txt": "OpenPIV text", ".mat": "PIVlab .mat"}
#: Orientations of the ``.txt`` and ``.mat`` exports (module docstring).
ORIENTATIONS = ("y-up", "y-down")
#: PIVlab's ``information`` of its MAT export (``+export/mat_file_save.m``).
PIVLAB_INFORMATION = (
    "The first dimension of the variables is the frame number.",
    "Typevector is 0 for masked vector, 1 for regular vector, 2 for filtered vector",
    "u_original and v_original are the unmodified velocities from the cross-correlation.",
    "u_filtered and v_filtered is the above incl. your data validation selection.",
    "u_smoothed and v_smoothed is the above incl. your smoothing selection.",
)
#: A window is without light when its brightest pixel, in both frames, lies within this
#: share of the frame's range (1st percentile to 99.9th) above the 1st percentile.
DARK_SHARE = 0.05


def light_mask(image_a, image_b, result):
    """Windows of the final pass without light in either frame (outside the sheet or the
    lit region): 1 there, else 0.

    A window is dark when its brightest pixel lies less than ``max(1, DARK_SHARE × range)``
    counts above the frame's 1st percentile in both frames (``range``: 1st to 99.9th
    percentile).

    Parameters
    ----------
    image_a, image_b : array_like, shape (rows, columns)
    result : rimcl.piv.analysis.PivResult

    Returns
    -------
    ndarray, uint8, shape of the vector grid
    """
    grid = WindowGrid.for_image(result.image_shape, int(result.window), result.settings.overlap)
    dark = np.ones(grid.shape, dtype=bool)
    for image in (image_a, image_b):
        image = np.asarray(image, dtype=np.float64)
        floor, top = np.percentile(image, [1.0, 99.9])
        level = floor + max(1.0, DARK_SHARE * (top - floor))
        for r, row in enumerate(grid.rows):
            for c, col in enumerate(grid.cols):
                window = image[row : row + grid.size, col : col + grid.size]
                dark[r, c] &= bool(window.max() <= level)
    return dark.astype(np.uint8)


def _scaled(result, pixel_size_m, dt_s):
    """Positions (m) and velocities (m/s), or None without both scales."""
    if pixel_size_m is None or dt_s is None:
        return None
    if not (pixel_size_m > 0 and dt_s > 0 and np.isfinite(pixel_size_m) and np.isfinite(dt_s)):
        raise RimclError(
            f"the pixel size and time step must be positive, got {pixel_size_m}, {dt_s}"
        )
    speed = pixel_size_m / dt_s
    return {
        "x_m": result.x * pixel_size_m,
        "y_m": result.y * pixel_size_m,
        "u_ms": result.dx * speed,
        "v_ms": result.dy * speed,
    }


def export_vectors(
    path,
    result,
    mask=None,
    pixel_size_m=None,
    dt_s=None,
    config=None,
    overwrite=True,
    orientation="y-up",
):
    """Write the vectors of ``result`` in the format of the path's suffix (module docstring).

    Parameters
    ----------
    path : str or Path
        Ending ``.nc``, ``.txt`` or ``.mat``.
    result : rimcl.piv.analysis.PivResult
    mask : ndarray, shape of the grid, optional
        1 where a window has no light (:func:`light_mask`); default none masked.
    pixel_size_m : float, optional
        Metres per pixel in the object (with ``dt_s``: velocities in m/s too).
    dt_s : float, optional
        Seconds between the two frames.
    config : dict, optional
        Recorded in the file.
    overwrite : bool
    orientation : {"y-up", "y-down"}
        Of the ``.txt`` and ``.mat`` files: ``y`` and ``v`` up the frame (OpenPIV after
        ``tools.transform_coordinates``; PIVlab's "y increases to the top") or down it
        (image coordinates). The ``.nc`` file is always in image coordinates.

    Returns
    -------
    Path
    """
    path = Path(path)
    if orientation not in ORIENTATIONS:
        raise RimclError(f"unknown orientation {orientation!r}: give " + " or ".join(ORIENTATIONS))
    suffix = path.suffix.lower()
    if suffix not in FORMATS:
        raise RimclError(
            f"cannot export vectors to {path.name}: give a path ending in "
            + ", ".join(f"{s} ({name})" for s, name in FORMATS.items())
        )
    check_output(path, overwrite)
    mask = np.zeros(result.dx.shape, np.uint8) if mask is None else np.asarray(mask, np.uint8)
    if mask.shape != result.dx.shape:
        raise RimclError(f"the mask has shape {mask.shape}, the vectors {result.dx.shape}")
    flags = (~np.asarray(result.valid, dtype=bool)).astype(np.uint8)
    scaled = _scaled(result, pixel_size_m, dt_s)
    record = {
        "config": config or {},
        "versions": versions(),
        "pixel_size_m": pixel_size_m,
        "dt_s": dt_s,
        # the .nc file keeps the vectors' image coordinates whatever the orientation asked
        "orientation": "y-down" if suffix == ".nc" else orientation,
        "coordinates": _COORDINATES[suffix][orientation],
    }
    writer = {".nc": _write_netcdf, ".txt": _write_openpiv, ".mat": _write_pivlab}[suffix]
    with atomic_path(path, overwrite=overwrite) as tmp:
        writer(tmp, result, flags, mask, scaled, record)
    return path


_IMAGE = (
    "x along image columns, y along image rows (pixels, row 0 at the top); u, v the "
    "displacement of frame B relative to A along x and y"
)
_COORDINATES = {
    ".nc": {"y-up": _IMAGE, "y-down": _IMAGE},
    ".txt": {
        "y-up": "OpenPIV's physical coordinates (tools.transform_coordinates): x to the right, "
        "y up (the window rows' coordinates reversed), v up the frame; a window of pixels "
        "c..c+N-1 centred at c+N/2",
        "y-down": "OpenPIV's image coordinates: x to the right, y and v down the frame from "
        "the top-left corner; a window of pixels c..c+N-1 centred at c+N/2",
    },
    ".mat": {
        "y-up": "PIVlab's axes with y increasing to the top: y = calxy*(rows - y_px), "
        "calv = -calu (v up the frame); x_px, y_px MATLAB's 1-based pixel coordinates",
        "y-down": "PIVlab's default axes: x to the right, y down the frame from the top-left "
        "pixel, calv = calu (v down); x_px, y_px MATLAB's 1-based pixel coordinates",
    },
}


def _write_netcdf(tmp, result, flags, mask, scaled, record):
    import h5py

    with h5py.File(tmp, "w") as h5:
        h5.attrs["rimcl_schema"] = "piv_vectors_netcdf"
        h5.attrs["rimcl_record"] = to_json(record)
        columns, rows = result.x[0, :], result.y[:, 0]
        h5["x"] = columns.astype(np.float64)
        h5["y"] = rows.astype(np.float64)
        for name in ("x", "y"):
            h5[name].make_scale(name)
            h5[name].attrs["units"] = "pixel"
        h5["x"].attrs["long_name"] = "window centre along image columns"
        h5["y"].attrs["long_name"] = "window centre along image rows"
        variables = {
            "u": (result.dx, "pixel", "displacement along x, frame B relative to A"),
            "v": (result.dy, "pixel", "displacement along y, frame B relative to A"),
            "flags": (flags, "1", "1: outlier replaced by the median of its neighbours"),
            "mask": (mask, "1", "1: no light in the window in either frame"),
            "peak_ratio": (result.peak_ratio, "1", "highest correlation peak over the second"),
        }
        if scaled is not None:
            variables.update(
                x_m=(scaled["x_m"], "m", "window centre along x"),
                y_m=(scaled["y_m"], "m", "window centre along y"),
                u_ms=(scaled["u_ms"], "m s-1", "velocity along x"),
                v_ms=(scaled["v_ms"], "m s-1", "velocity along y"),
            )
        for name, (values, units, meaning) in variables.items():
            h5[name] = np.asarray(values)
            h5[name].attrs["units"] = units
            h5[name].attrs["long_name"] = meaning
            h5[name].dims[0].attach_scale(h5["y"])
            h5[name].dims[1].attach_scale(h5["x"])


def openpiv_columns(result, pixel_size_m=None, dt_s=None, orientation="y-up"):
    """The columns ``x, y, u, v`` of OpenPIV's text file for ``result`` (module docstring).

    Parameters
    ----------
    result : rimcl.piv.analysis.PivResult
    pixel_size_m, dt_s : float, optional
        With both: m and m/s, else px and px per frame pair.
    orientation : {"y-up", "y-down"}

    Returns
    -------
    tuple of 4 ndarray, float64, shape of the vector grid
        ``x, y`` (px or m), ``u, v`` (px per pair or m/s), in OpenPIV's conventions.
    """
    x = np.asarray(result.x, np.float64) + 0.5
    y = np.asarray(result.y, np.float64) + 0.5
    u = np.asarray(result.dx, np.float64)
    v = np.asarray(result.dy, np.float64)
    if orientation == "y-up":  # openpiv.tools.transform_coordinates
        y, v = y[::-1, :], -v
    if pixel_size_m is not None and dt_s is not None:  # openpiv.scaling.uniform
        _scaled(result, pixel_size_m, dt_s)  # checks the scales
        speed = pixel_size_m / dt_s
        x, y, u, v = x * pixel_size_m, y * pixel_size_m, u * speed, v * speed
    return x, y, u, v


def _write_openpiv(tmp, result, flags, mask, scaled, record):
    columns = openpiv_columns(result, record["pixel_size_m"], record["dt_s"], record["orientation"])
    if scaled is None:
        units = "x, y in px; u, v in px per frame pair"
    else:
        units = "x, y in m; u, v in m/s"
    table = np.column_stack([c.ravel() for c in columns] + [flags.ravel(), mask.ravel()])
    header = (
        "x\ty\tu\tv\tflags\tmask\n"
        f"rimcl PIV vectors in openpiv.tools.save's layout; {units}; flags 1: outlier "
        f"replaced; mask 1: no light\norientation {record['orientation']}: "
        f"{record['coordinates']}\nrimcl_record {to_json(record)}"
    )
    np.savetxt(tmp, table, fmt="%.8e", delimiter="\t", header=header, comments="# ")


def pivlab_variables(result, mask=None, pixel_size_m=None, dt_s=None, orientation="y-up"):
    """The variables of PIVlab's MAT export for ``result`` (module docstring).

    Parameters
    ----------
    result : rimcl.piv.analysis.PivResult
    mask : ndarray, shape of the grid, optional
        1 where a window has no light.
    pixel_size_m, dt_s : float, optional
        With both: calibrated (m, m/s), else px and px per frame pair.
    orientation : {"y-up", "y-down"}

    Returns
    -------
    dict
        ``x, y, u_original, v_original, typevector_original, u_filtered, v_filtered,
        typevector_filtered`` (ndarray, float64, shape of the grid), ``calxy, calu, calv``
        (float) and ``units`` (str), PIVlab's names and meanings.
    """
    mask = np.zeros(result.dx.shape, np.uint8) if mask is None else np.asarray(mask, np.uint8)
    scaled = _scaled(result, pixel_size_m, dt_s)
    calxy = 1.0 if scaled is None else float(pixel_size_m)
    calu = 1.0 if scaled is None else float(pixel_size_m) / float(dt_s)
    x_px = np.asarray(result.x, np.float64) + 1.0  # MATLAB's 1-based pixels
    y_px = np.asarray(result.y, np.float64) + 1.0
    if orientation == "y-up":  # PIVlab's calibrate.xy with y increasing to the top
        y_px, calv = result.image_shape[0] - y_px, -calu
    else:
        calv = calu
    typevector = np.where(np.asarray(result.valid, bool), 1.0, 2.0)
    typevector[mask == 1] = 0.0
    u, v = calu * np.asarray(result.dx, np.float64), calv * np.asarray(result.dy, np.float64)
    return {
        "x": calxy * x_px,
        "y": calxy * y_px,
        "u_original": u,
        "v_original": v,
        "typevector_original": typevector,
        "u_filtered": np.where(mask == 1, np.nan, u),
        "v_filtered": np.where(mask == 1, np.nan, v),
        "typevector_filtered": typevector,
        "calxy": calxy,
        "calu": calu,
        "calv": calv,
        "units": "[px] respectively [px/frame]" if scaled is None else "[m] respectively [m/s]",
    }


def _write_pivlab(tmp, result, flags, mask, scaled, record):
    from scipy.io import savemat

    def cell(values):
        holder = np.empty((1, 1), dtype=object)
        holder[0, 0] = np.asarray(values, dtype=np.float64)
        return holder

    variables = pivlab_variables(
        result, mask, record["pixel_size_m"], record["dt_s"], record["orientation"]
    )
    contents = {
        name: cell(value) if isinstance(value, np.ndarray) else value
        for name, value in variables.items()
    }
    contents["u_smoothed"] = cell(np.zeros((0, 0)))
    contents["v_smoothed"] = cell(np.zeros((0, 0)))
    information = np.empty((len(PIVLAB_INFORMATION) + 1, 1), dtype=object)
    for row, line in enumerate(PIVLAB_INFORMATION):
        information[row, 0] = line
    information[-1, 0] = "rimcl: " + record["coordinates"]
    contents["information"] = information
    contents["orientation"] = record["orientation"]
    contents["rimcl_config"] = json.dumps(json.loads(to_json(record)))
    with open(tmp, "wb") as stream:
        savemat(stream, contents, format="5", do_compression=True)


def run_analyze(
    path_a,
    path_b,
    output,
    settings=None,
    exports=(),
    pixel_size_m=None,
    dt_s=None,
    overwrite=False,
    orientation="y-up",
):
    """What ``rimcl piv analyze`` does: :func:`rimcl.piv.analysis.analyze_files` (read,
    check, correlate, write the vectors), then each export (:func:`export_vectors`, with
    the :func:`light_mask` of the frames).

    Parameters
    ----------
    path_a, path_b : str or Path
    output : str or Path
        The HDF5 file of :func:`rimcl.piv.analysis.write_piv`.
    settings : rimcl.piv.analysis.PivSettings, optional
    exports : sequence of str or Path
        Further files, by suffix (:data:`FORMATS`).
    pixel_size_m, dt_s : float, optional
        Scales of the exports' velocities (both or neither).
    overwrite : bool
    orientation : {"y-up", "y-down"}
        Of the ``.txt`` and ``.mat`` exports (:func:`export_vectors`).

    Returns
    -------
    PivResult
    """
    from rimcl.piv.analysis import analyze_files, read_tiff

    if (pixel_size_m is None) != (dt_s is None):
        raise RimclError("give both the pixel size (m) and the time between frames (s), or none")
    if orientation not in ORIENTATIONS:
        raise RimclError(f"unknown orientation {orientation!r}: give " + " or ".join(ORIENTATIONS))
    for path in exports:
        check_output(path, overwrite)
        if Path(path).suffix.lower() not in FORMATS:
            raise RimclError(
                f"cannot export vectors to {Path(path).name}: give a path ending in "
                + ", ".join(FORMATS)
            )
    result = analyze_files(path_a, path_b, output, settings, overwrite=overwrite)
    if exports:
        image_a, image_b = read_tiff(path_a), read_tiff(path_b)
        mask = light_mask(image_a, image_b, result)
        inputs = {"image_a": str(Path(path_a).resolve()), "image_b": str(Path(path_b).resolve())}
        config = {"inputs": inputs, "piv": result.settings.describe()}
        for path in exports:
            export_vectors(path, result, mask, pixel_size_m, dt_s, config, overwrite, orientation)
    return result
