"""Pictures of a field file: a planar slice of density (or δn), |∇n| and velocity."""

import numpy as np

from rimcl import __version__
from rimcl.core.atomic import atomic_path
from rimcl.core.errors import RimclError
from rimcl.core.provenance import to_json
from rimcl.fields.field_reader import FieldFile

QUANTITIES = ("all", "density", "gradient", "velocity")
# plane -> (axis normal to it, horizontal axis, vertical axis), as x-indices 0, 1, 2
PLANES = {"x2x3": (0, 1, 2), "x1x2": (2, 0, 1), "x1x3": (1, 0, 2)}
# array axis of x1, x2, x3 in (n3, n2, n1) arrays
_ARRAY_AXIS = (2, 1, 0)
_ARROWS = 24


def _plane_values(values, plane, node):
    """A 2-D ``(vertical, horizontal)`` slice of a ``(n3, n2, n1[, c])`` array.

    Dropping one of the array axes ``(x3, x2, x1)`` leaves the other two in the
    (vertical, horizontal) order of :data:`PLANES`.
    """
    return np.take(values, node, axis=_ARRAY_AXIS[PLANES[plane][0]])


def slice_figure(path, *, frame=0, time=None, plane="x2x3", at=None, quantity="all",
                 case=None, k_rho=None):  # fmt: skip
    """A matplotlib figure of one planar slice of a field file.

    Parameters
    ----------
    path : str or Path
        A rimcl field file.
    frame : int
        Stored frame (ignored when ``time`` is given).
    time : float, optional
        Interpolate between frames to this time.
    plane : {"x2x3", "x1x2", "x1x3"}
        The slice plane; ``x2x3`` is parallel to the light sheet.
    at : float, optional
        Position of the plane along its normal axis (length units); default the middle
        node. The nearest node plane is shown.
    quantity : {"all", "density", "gradient", "velocity"}
        ``density`` shows ρ (or ``δn`` when a case is given), ``gradient`` ``|∇ρ|`` (or
        ``|∇n|``), ``velocity`` the in-plane speed with arrows.
    case, k_rho : optional
        A Gladstone–Dale case or ``G``: show ``δn`` and ``|∇n|`` instead of ρ and ``|∇ρ|``.

    Returns
    -------
    matplotlib.figure.Figure
    """
    import matplotlib

    matplotlib.use("Agg")
    from matplotlib.figure import Figure

    if quantity not in QUANTITIES:
        raise RimclError(f"quantity must be one of {QUANTITIES}, got {quantity!r}")
    if plane not in PLANES:
        raise RimclError(f"plane must be one of {tuple(PLANES)}, got {plane!r}")
    with FieldFile(path) as ff:
        normal, horizontal, vertical = PLANES[plane]
        counts = np.array(ff.shape[::-1])
        if at is None:
            node = counts[normal] // 2
        else:
            node = round(float((at - ff.origin[normal]) / ff.spacing[normal]))
            if not 0 <= node < counts[normal]:
                hi = ff.origin[normal] + (counts[normal] - 1) * ff.spacing[normal]
                raise RimclError(
                    f"x{normal + 1} = {at:g} is outside the field ({ff.origin[normal]:g} .. {hi:g})"
                )
        position = ff.origin[normal] + node * ff.spacing[normal]
        wanted = ["density", "gradient", "velocity"] if quantity == "all" else [quantity]
        if "velocity" in wanted and not ff.has_full_velocity:
            if quantity == "velocity":
                only = f" but on the sheet x1 = {ff.velocity_sheet_x1:g}" if ff.has_velocity else ""
                raise RimclError(f"{path} holds no velocity{only}")
            wanted.remove("velocity")
        optical = case is not None or k_rho is not None or ff.kind == "delta_n"
        if ff.kind == "density" and not optical:
            # G = 1 turns δn into ρ - mean ρ and ∇n into ∇ρ; add the mean back for ρ
            field = ff.field_at(time, k_rho=1.0) if time is not None else ff.field(frame, 1.0)
            scalar = field.delta_n + field.attrs["density_mean"]
            scalar_label, gradient_label = "density ρ", "|∇ρ|"
        else:
            if time is not None:
                field = ff.field_at(time, k_rho, case=case)
            else:
                field = ff.field(frame, k_rho, case=case)
            scalar = field.delta_n
            scalar_label, gradient_label = "δn = n - n_ref", "|∇n|"
        length_unit = str(ff.attrs.get("length_unit", "length units")).split(" (")[0]
        panels = {}
        if "density" in wanted:
            panels["density"] = (_plane_values(scalar, plane, node), scalar_label)
        if "gradient" in wanted:
            magnitude = np.sqrt(np.sum(field.gradient.astype(np.float64) ** 2, axis=-1))
            label = f"{gradient_label} (1/{length_unit})"
            panels["gradient"] = (_plane_values(magnitude, plane, node), label)
        if "velocity" in wanted:
            velocity = ff.velocity_at(time) if time is not None else ff.velocity(frame)
            in_plane = _plane_values(velocity, plane, node)[..., [horizontal, vertical]]
            panels["velocity"] = (
                in_plane,
                f"in-plane speed |(u{horizontal + 1}, u{vertical + 1})|",
            )
        when = float(field.attrs["time"])
        title = ff.attrs.get("title") or ff.path.name
        case_note = f", case {field.attrs['case']}" if "case" in field.attrs and optical else ""
        lo = ff.origin
        hi = ff.origin + (counts - 1) * ff.spacing
        spacing = ff.spacing
    # pixels are centred on the nodes
    half = 0.5 * spacing
    extent = (lo[horizontal] - half[horizontal], hi[horizontal] + half[horizontal],
              lo[vertical] - half[vertical], hi[vertical] + half[vertical])  # fmt: skip
    figure = Figure(figsize=(5.2 * len(panels), 4.8), layout="constrained")
    for axes, (name, (values, label)) in zip(
        figure.subplots(1, len(panels), squeeze=False)[0], panels.items(), strict=True
    ):
        if name == "velocity":
            speed = np.hypot(values[..., 0], values[..., 1])
            image = axes.imshow(speed, origin="lower", extent=extent, cmap="viridis")
            step = max(1, max(speed.shape) // _ARROWS)
            grid_h = np.linspace(lo[horizontal], hi[horizontal], speed.shape[1])[::step]
            grid_v = np.linspace(lo[vertical], hi[vertical], speed.shape[0])[::step]
            axes.quiver(grid_h, grid_v, values[::step, ::step, 0], values[::step, ::step, 1],
                        color="white", alpha=0.8)  # fmt: skip
        else:
            cmap = (
                "RdBu_r" if label.startswith("δn") else "magma" if name == "gradient" else "cividis"
            )
            image = axes.imshow(values, origin="lower", extent=extent, cmap=cmap)
        figure.colorbar(image, ax=axes, shrink=0.85, label=label)
        axes.set_xlabel(f"x{horizontal + 1} ({length_unit})")
        axes.set_ylabel(f"x{vertical + 1} ({length_unit})")
        axes.set_title(label.split(" (")[0])
    figure.suptitle(f"{title}: x{normal + 1} = {position:.4g}, t = {when:.6g}{case_note}")
    return figure


def save_figure(figure, output, *, config=None, overwrite=False):
    """Save a figure as PNG or PDF (by suffix), atomically, with the configuration embedded.

    Parameters
    ----------
    figure : matplotlib.figure.Figure
    output : str or Path
        ``.png`` or ``.pdf``.
    config : dict, optional
        Recorded in the file's metadata with the rimcl version.
    overwrite : bool
    """
    from pathlib import Path

    suffix = Path(output).suffix.lower().lstrip(".")
    if suffix not in ("png", "pdf"):
        raise RimclError(f"figures are written as .png or .pdf, not {output}")
    key = "Description" if suffix == "png" else "Subject"
    metadata = {"Creator" if suffix == "pdf" else "Software": f"rimcl {__version__}",
                key: to_json(config or {})}  # fmt: skip
    with atomic_path(output, overwrite=overwrite) as tmp:
        figure.savefig(tmp, format=suffix, dpi=110, metadata=metadata)
    return Path(output)
