"""PIV vectors in the files other PIV tools read (:func:`export_vectors`).

By the suffix of the path:

- ``.nc``: netCDF-4 / HDF5 that xarray opens (``xarray.open_dataset(path,
  engine="h5netcdf")``): coordinates ``x`` (columns) and ``y`` (rows) as dimension scales,
  variables ``u``, ``v`` (displacement, px per frame pair), ``flags`` (1: an outlier
  replaced), ``mask`` (1: no light in the window), ``peak_ratio``; with a pixel size and a
  time step also ``x_m``, ``y_m`` (m) and ``u_ms``, ``v_ms`` (m/s); ``units`` on every
  variable, the configuration as a global attribute;
- ``.txt``: OpenPIV's text layout (``openpiv.tools.save``): one row per vector, columns
  ``x y u v flags mask``, tab-separated, a ``#`` header naming columns and units (px and
  px per pair, or m and m/s with a pixel size and a time step);
- ``.mat``: a PIVlab-style MATLAB file (``scipy.io.savemat``): cell arrays of one frame pair
  ``x``, ``y`` (MATLAB's 1-based pixel coordinates: rimcl's pixel ``i`` is ``i + 1``),
  ``u_original``, ``v_original``, ``typevector_original`` (1 a vector, 2 replaced, 0
  masked), ``u_filtered``, ``v_filtered``, ``typevector_filtered`` (the same, masked
  vectors NaN), ``units``, ``calxy`` (m per px, 1 without a scale), ``calu`` (m/s per px
  per pair), and ``rimcl_config`` (JSON).

Coordinates are those of the vectors (:mod:`rimcl.piv.analysis`): ``x`` along image
columns, ``y`` along image rows, ``u`` and ``v`` the displacement along them.
"""

import json
from pathlib import Path

import numpy as np

from rimcl.core.atomic import atomic_path, check_output
from rimcl.core.errors import RimclError
from rimcl.core.provenance import to_json, versions
from rimcl.piv.analysis import WindowGrid

FORMATS = {".nc": "netCDF-4 (xarray)", ".txt": "OpenPIV text", ".mat": "PIVlab .mat"}
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
    path, result, mask=None, pixel_size_m=None, dt_s=None, config=None, overwrite=True
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

    Returns
    -------
    Path
    """
    path = Path(path)
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
        "coordinates": "x along image columns, y along image rows (pixels); u, v the "
        "displacement of frame B relative to A along x and y",
    }
    writer = {".nc": _write_netcdf, ".txt": _write_openpiv, ".mat": _write_pivlab}[suffix]
    with atomic_path(path, overwrite=overwrite) as tmp:
        writer(tmp, result, flags, mask, scaled, record)
    return path


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


def _write_openpiv(tmp, result, flags, mask, scaled, record):
    if scaled is None:
        columns = [result.x, result.y, result.dx, result.dy]
        units = "x, y in px; u, v in px per frame pair"
    else:
        columns = [scaled["x_m"], scaled["y_m"], scaled["u_ms"], scaled["v_ms"]]
        units = "x, y in m; u, v in m/s"
    table = np.column_stack([c.ravel() for c in columns] + [flags.ravel(), mask.ravel()])
    header = (
        f"rimcl PIV vectors, OpenPIV layout ({units}; flags 1: outlier replaced; mask 1: "
        f"no light); {record['coordinates']}\nx\ty\tu\tv\tflags\tmask"
    )
    np.savetxt(tmp, table, fmt="%.8e", delimiter="\t", header=header, comments="# ")


def _write_pivlab(tmp, result, flags, mask, scaled, record):
    from scipy.io import savemat

    def cell(values):
        holder = np.empty((1, 1), dtype=object)
        holder[0, 0] = np.asarray(values, dtype=np.float64)
        return holder

    typevector = np.where(flags == 1, 2.0, 1.0)
    typevector[mask == 1] = 0.0
    filtered_u = np.where(mask == 1, np.nan, result.dx)
    filtered_v = np.where(mask == 1, np.nan, result.dy)
    calxy = 1.0 if scaled is None else float(record["pixel_size_m"])
    calu = 1.0 if scaled is None else float(record["pixel_size_m"]) / float(record["dt_s"])
    with open(tmp, "wb") as stream:
        savemat(
            stream,
            {
                "x": cell(result.x + 1.0),
                "y": cell(result.y + 1.0),
                "u_original": cell(result.dx),
                "v_original": cell(result.dy),
                "typevector_original": cell(typevector),
                "u_filtered": cell(filtered_u),
                "v_filtered": cell(filtered_v),
                "typevector_filtered": cell(typevector),
                "calxy": calxy,
                "calu": calu,
                "units": "x, y in px (1-based, MATLAB); u, v in px per frame pair; "
                "calxy m per px and calu m/s per px per pair (1: no scale given)",
                "rimcl_config": json.dumps(json.loads(to_json(record))),
            },
            format="5",
            do_compression=True,
        )


def run_analyze(
    path_a, path_b, output, settings=None, exports=(), pixel_size_m=None, dt_s=None, overwrite=False
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

    Returns
    -------
    PivResult
    """
    from rimcl.piv.analysis import analyze_files, read_tiff

    if (pixel_size_m is None) != (dt_s is None):
        raise RimclError("give both the pixel size (m) and the time between frames (s), or none")
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
            export_vectors(path, result, mask, pixel_size_m, dt_s, config, overwrite)
    return result
