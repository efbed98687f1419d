"""The result of a PTV measurement and its files.

:class:`RenderResult` holds everything a run measured (and its reusable :class:`Reference`);
:func:`merge_results` joins the results of tracer shards into the whole run's;
:func:`write_render` writes the render file (``rimcl_schema = "render"``,
``schema_version = 2``: per-tracer tables as ``(id, frame)`` datasets; every dataset
documented on the render file format page of the docs) and
:func:`write_frame_image` the full first frame as a 16-bit PNG or TIFF.
"""

import dataclasses
import itertools
from pathlib import Path

import numpy as np

from rimcl.core.atomic import atomic_path, check_output
from rimcl.core.errors import RimclError
from rimcl.core.provenance import stamp_h5, to_json
from rimcl.core.tables_h5 import label_table, mark_si, si_per_unit, write_tracer_table

SCHEMA = "render"


#: 2: per-tracer tables as (id, frame) datasets (1: one 1-D row per tracer and frame)
SCHEMA_VERSION = 2


@dataclasses.dataclass
class Reference:
    """The case-independent part of a render run: true tracks and reference images.

    Attributes
    ----------
    key : dict
        The configuration it was made for (compared when it is reused).
    tracks : ndarray, shape (F, N, 2)
        True tracer positions ``(x2, x3)`` at each frame.
    true_velocity, true_acceleration : ndarray, shape (F, N, 2) or None
        Flow velocity ``u(x_k, t_k)`` and Lagrangian acceleration ``Du/Dt`` along the true
        tracks at each frame; None for a single frame.
    outside : ndarray, bool, shape (F, N)
        True positions outside the velocity grid (clamped fields only).
    images : dict of str to ndarray (F, N)
        Reference image columns (:data:`rimcl.imaging.frames.IMAGE_COLUMNS`; ``scale`` is the
        factor reused for the measured images).
    floor_images : dict of str to ndarray (F, N)
        ``x2``, ``x3`` and ``flags`` of a second exposure of the reference with independent
        sensor noise draws (the noise floor; the reference's own columns on a noiseless
        camera).
    ray_counts : dict of str to int
        Trace status counts of all reference rays, plus ``vignetted``.
    ray_steps : int
        Integration steps of all reference rays.
    """

    key: dict
    tracks: np.ndarray
    true_velocity: np.ndarray
    true_acceleration: np.ndarray
    outside: np.ndarray
    images: dict
    floor_images: dict
    ray_counts: dict
    ray_steps: int


@dataclasses.dataclass
class RenderResult:
    """Everything :func:`write_render` writes.

    Attributes
    ----------
    attrs : dict
        Root attributes of the output file.
    config : dict
        The full configuration (recorded with versions and device).
    tracers : dict of str to ndarray
        One row per tracer and frame (frame-major: all tracers of frame 0 first).
    kinematics : dict of str to (dict of str to ndarray, or None)
        The tables ``velocity``, ``acceleration`` (the paper's differences),
        ``velocity_fit`` and ``acceleration_fit`` (sliding polynomial fit): one row per
        tracer and evaluation frame, frame-major; None where the run has too few frames.
    rays : dict of str to ndarray
        A random subsample of the measured rays of the first frame.
    ray_attrs : dict
        Status counts of all rays traced (measured and reference).
    reference : Reference
        Reusable for another case with the same configuration.
    timings : dict of str to float
        Wall time per stage (s): ``track``, ``trace``, ``render``, ``centroid``.
    frame_image : ndarray of uint16, shape (rows, columns) or None
        The full first frame (measured), if asked for.
    device : pyopencl.Device
    """

    attrs: dict
    config: dict
    tracers: dict
    kinematics: dict
    rays: dict
    ray_attrs: dict
    reference: Reference
    timings: dict
    frame_image: np.ndarray
    device: object


def _join_frames(parts, frames):
    """Frame-major rows of shards ``(F * N_i,)`` joined into ``(F * sum N_i,)``."""
    return np.concatenate([p.reshape(frames, -1) for p in parts], axis=1).reshape(-1)


def merge_results(parts):
    """Join the results of consecutive shards of one run into the whole run's result.

    Parameters
    ----------
    parts : sequence of RenderResult
        From :func:`rimcl.ptv.measure.run_render` with ``shard`` ranges that tile ``0..N``
        in order.

    Returns
    -------
    RenderResult
        Equal, table by table, to the result of the unsharded run.
    """
    parts = list(parts)
    first = parts[0]
    frames = int(first.attrs["n_frames"])
    ranges = [tuple(p.config["shard"]) for p in parts]
    total = int(first.config["tracers"])
    if (
        ranges[0][0] != 0
        or ranges[-1][1] != total
        or any(a[1] != b[0] for a, b in itertools.pairwise(ranges))
    ):
        raise RimclError(f"shards {ranges} do not tile the {total} tracers in order")

    def rows(tables):
        if tables[0] is None:
            return None
        evaluated = len(np.unique(tables[0]["frame"]))
        return {k: _join_frames([t[k] for t in tables], evaluated) for k in tables[0]}

    tracers = {k: _join_frames([p.tracers[k] for p in parts], frames) for k in first.tracers}
    ray_attrs = dict(first.ray_attrs)
    for name in ray_attrs:
        if name != "sampled_from_frame":
            ray_attrs[name] = sum(p.ray_attrs[name] for p in parts)
    refs = [p.reference for p in parts]
    key = {**refs[0].key, "shard": [0, total]}
    reference = Reference(
        key=key,
        tracks=np.concatenate([r.tracks for r in refs], axis=1),
        true_velocity=None
        if refs[0].true_velocity is None
        else np.concatenate([r.true_velocity for r in refs], axis=1),
        true_acceleration=None
        if refs[0].true_acceleration is None
        else np.concatenate([r.true_acceleration for r in refs], axis=1),
        outside=np.concatenate([r.outside for r in refs], axis=1),
        images={k: np.concatenate([r.images[k] for r in refs], axis=1) for k in refs[0].images},
        floor_images={
            k: np.concatenate([r.floor_images[k] for r in refs], axis=1)
            for k in refs[0].floor_images
        },
        ray_counts={k: sum(r.ray_counts[k] for r in refs) for k in refs[0].ray_counts},
        ray_steps=sum(r.ray_steps for r in refs),
    )
    frame_image = None
    if first.frame_image is not None:
        stacked = np.sum([p.frame_image.astype(np.int64) for p in parts], axis=0)
        full_scale = int(first.config["render"]["full_scale"])
        frame_image = np.minimum(stacked, full_scale).astype(np.uint16)
    return RenderResult(
        attrs={
            **first.attrs,
            "n_tracers": total,
            "delta_n_max": max(p.attrs["delta_n_max"] for p in parts),
        },
        config={**first.config, "shard": [0, total]},
        tracers=tracers,
        kinematics={k: rows([p.kinematics[k] for p in parts]) for k in first.kinematics},
        rays={k: np.concatenate([p.rays[k] for p in parts]) for k in first.rays},
        ray_attrs=ray_attrs,
        reference=reference,
        timings={k: sum(p.timings[k] for p in parts) for k in first.timings},
        frame_image=frame_image,
        device=first.device,
    )


def write_render(path, result, overwrite=False):
    """Write a :class:`RenderResult` to an HDF5 file, atomically and stamped.

    Parameters
    ----------
    path : str or Path
    result : RenderResult
    overwrite : bool
        Replace an existing file (otherwise an existing file is an error).

    Returns
    -------
    pathlib.Path
    """
    import h5py

    path = Path(path)
    # SI value of one unit of a column (m, m/s, m/s², s), where the scales are known
    si = si_per_unit(result.attrs.get("length_m"), result.attrs.get("time_s"))
    with atomic_path(path, overwrite=overwrite) as tmp, h5py.File(tmp, "w") as h5:
        for name, value in result.attrs.items():
            h5.attrs[name] = value
        stamp_h5(h5, result.config, result.device)
        h5.attrs["timings_s"] = to_json(result.timings)
        groups = {"tracers": result.tracers, **result.kinematics, "rays": result.rays}
        for group_name, table in groups.items():
            if table is None:
                continue
            group = h5.create_group(group_name)
            # named dimensions and units, for xarray.open_dataset(path, group=...):
            # (id, frame) for the per-tracer tables, ray for the rays
            if group_name == "rays":
                for name, values in table.items():
                    group.create_dataset(name, data=values)
                label_table(group, "ray")
            else:
                write_tracer_table(group, table)
            mark_si(group, si)
        for name, value in result.ray_attrs.items():
            h5["rays"].attrs[name] = value
    return path


def check_frame_image(path, overwrite=False):
    """Refuse, before any work, a frame-image path that is not PNG or TIFF or not writable.

    Returns
    -------
    pathlib.Path
    """
    path = Path(path)
    if path.suffix.lower() not in (".png", ".tif", ".tiff"):
        raise RimclError(f"frame image {path} must end in .png, .tif or .tiff")
    return check_output(path, overwrite)


def write_frame_image(path, result, overwrite=False):
    """Write the full first-frame image as a 16-bit PNG or TIFF (x3 upwards).

    The configuration and versions go into the image's text metadata.
    """
    from PIL import Image, PngImagePlugin

    from rimcl.core.provenance import versions

    if result.frame_image is None:
        raise RimclError("this result holds no frame image (run with frame_image=True)")
    path = check_frame_image(path, overwrite)
    note = to_json({"config": result.config, "versions": versions()})
    image = Image.fromarray(np.ascontiguousarray(result.frame_image[::-1]))
    with atomic_path(path, overwrite=overwrite) as tmp:
        if path.suffix.lower() == ".png":
            info = PngImagePlugin.PngInfo()
            info.add_text("rimcl", note)
            image.save(tmp, format="PNG", pnginfo=info)
        else:
            image.save(tmp, format="TIFF", description=note)
    return path
