"""Figures of PIV errors over refractive-index cases.

Each figure is written as ``<name>.png``, ``<name>.pdf`` (versions in the file metadata)
and ``<name>.json`` (every number drawn, with configuration and versions), as
:mod:`rimcl.stats.figures` does, and with its panel helpers (:mod:`rimcl.stats.figures_common`):

- ``piv_vectors``: the vector map of the strongest case: true displacement, and the
  vectors measured through the field coloured by their refraction error (replaced vectors
  marked);
- ``piv_error_maps``: per case, maps of the refraction error, its optics part and the
  PIV baseline (pixels, one logarithmic colour scale per row);
- ``piv_error_pdfs``: PDFs of the relative refraction errors of ``u3``, ``u2`` and ``|u|``
  per case, their systematic and random parts against ``G``, and the rms errors in pixels
  (refraction, optics, baseline) against ``G``, with a second axis in mm/s where the field's
  scales are known (the other figures then say a pixel's µm and mm/s in their titles).

Input per case: the per-vector table and statistics of :mod:`rimcl.piv.study`
(``(case.vectors, case.stats)`` or :func:`rimcl.piv.study.load_piv_case`).
"""

from pathlib import Path

import numpy as np
from matplotlib.colors import LogNorm

from rimcl.core.provenance import versions
from rimcl.piv.study import velocity_table
from rimcl.stats.figures_common import (
    case_colors,
    case_label,
    draw_pdf_series,
    finish_axes,
    new_figure,
    pdf_series,
    physical_axis,
    relative_errors,
    save_figure,
)

FIGURE_NAMES = ("piv_vectors", "piv_error_maps", "piv_error_pdfs")
#: Arrows drawn along each axis of a vector map at most (every k-th vector beyond).
MAX_ARROWS = 40


def _pixel_size(stats):
    return stats["pixel_size_over_L"] * stats["length_L"]


def _per_px(stats):
    """``(µm, mm/s)`` of one pixel on the sheet and of one pixel of displacement in Δt,
    where the case records the field's scales (each None without the scale it needs)."""
    length_m, time_s = stats.get("length_m"), stats.get("time_s")
    if length_m is None:
        return None, None
    um = _pixel_size(stats) * length_m * 1e6
    return um, None if time_s is None else um * 1e-3 / (stats["dt"] * time_s)


def _scale_note(stats):
    """The suptitle's note of a pixel's size and speed, or '' without the scales."""
    um, mm_s = _per_px(stats)
    if um is None:
        return ""
    speed = "" if mm_s is None else f", 1 px per Δt = {mm_s:.3g} mm/s"
    return f"\n1 px = {um:.3g} µm on the sheet{speed}"


def _tables(cases):
    return [velocity_table(v, _pixel_size(s), s["dt"]) for v, s in cases]


def _listed(values):
    """Nested lists of an array for JSON, None where a value is not finite (no vector)."""
    values = np.asarray(values, dtype=np.float64)
    return np.where(np.isfinite(values), values, None).tolist()


def _letter(ax, letter):
    ax.set_title(f"({letter})", loc="left", fontweight="bold")


def _log_against_g(ax, ylabel, title):
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("G = Kρ (Gladstone–Dale product)")
    ax.set_ylabel(ylabel)
    ax.set_title(title, fontsize=9)
    ax.grid(True, which="major", alpha=0.3)


def _summary_against_g(ax, stats, statistic, ylabel, title):
    """|statistic| of the relative velocity errors against G for u2, u3, |u|; the data.

    Cases with G <= 0 or undefined (fluid cases) have no place on the log axis; a
    negative value is drawn open.
    """
    data = []
    for key, marker in (("u2", "o"), ("u3", "s"), ("magnitude", "^")):
        points = [
            (case["G"], case["velocity"][key][statistic])
            for case in stats
            if case["G"] is not None and case["G"] > 0
        ]
        points = [(g, value) for g, value in points if value]
        g_values = [g for g, _ in points]
        values = [abs(value) for _, value in points]
        signs = [int(np.sign(value)) for _, value in points]
        (line,) = ax.plot(g_values, values, "-" + marker, label=key)
        for g, value, sign in zip(g_values, values, signs, strict=True):
            if sign < 0:
                ax.plot(g, value, marker, mfc="white", color=line.get_color(), ms=5)
        data.append({"label": key, "G": g_values, "abs_value": values, "sign": signs})
    _log_against_g(ax, ylabel, title)
    ax.legend(fontsize=7, title="open: negative" if statistic == "systematic" else None)
    return data


def _stride(shape):
    return max(1, int(np.ceil(max(shape) / MAX_ARROWS)))


def _vectors(cases):
    """Truth and measured vectors of the strongest case (largest Δn_max)."""
    vectors, stats = cases[-1]
    figure, axes = new_figure(1, 2)
    k = _stride(vectors["x"].shape)
    pick = (slice(None, None, k), slice(None, None, k))
    x, y = vectors["x"][pick], vectors["y"][pick]
    # one arrow scale for both panels: the longest true vector spans one grid spacing
    spacing = float(x[0, 1] - x[0, 0]) if x.shape[1] > 1 else 1.0
    longest = np.nanmax(np.hypot(vectors["dx_true"], vectors["dy_true"]))
    scale = longest / spacing if np.isfinite(longest) and longest > 0 else 1.0
    refraction = np.hypot(
        vectors["dx_field"] - vectors["dx_uniform"], vectors["dy_field"] - vectors["dy_uniform"]
    )
    panels = {}
    for ax, letter, kind, colour, label in (
        (axes[0, 0], "a", "true", np.hypot(vectors["dx_true"], vectors["dy_true"]), "|d| (px)"),
        (axes[0, 1], "b", "field", refraction, "refraction error |d' − d^ref| (px)"),
    ):
        u, v = vectors[f"dx_{kind}"][pick], vectors[f"dy_{kind}"][pick]
        arrows = ax.quiver(
            x,
            y,
            u,
            v,
            colour[pick],
            cmap="viridis",
            angles="xy",
            pivot="mid",
            scale_units="xy",
            scale=scale,
        )
        figure.colorbar(arrows, ax=ax, label=label)
        if kind == "field":
            replaced = ~vectors["valid_field"][pick]
            ax.plot(x[replaced], y[replaced], "rx", ms=5, label="replaced (outlier)")
            if replaced.any():
                ax.legend(fontsize=7, loc="upper right")
        ax.set_aspect("equal")
        ax.set_xlabel("x (px, along x2)")
        ax.set_ylabel("y (px, along x3)")
        title = "window-averaged truth" if kind == "true" else f"measured through {stats['name']}"
        shown = "all vectors" if k == 1 else f"every {k}th vector"
        ax.set_title(f"{title}, {shown}", fontsize=8, loc="right")
        _letter(ax, letter)
        panels[letter] = {
            "x_px": _listed(x),
            "y_px": _listed(y),
            "dx_px": _listed(u),
            "dy_px": _listed(v),
            "colour": _listed(colour[pick]),
            "colour_label": label,
        }
    figure.suptitle(
        f"PIV vectors, {case_label(stats)} (arrows: the longest true vector spans one "
        "window spacing)" + _scale_note(stats)
    )
    return figure, {"panels": panels}


def _error_maps(cases):
    rows = (
        ("refraction", "refraction |d' − d^ref| (px)"),
        ("optics", "optics part |ε_opt| (px)"),
        ("baseline", "baseline |d^ref − d_true| (px)"),
    )
    figure, axes = new_figure(len(rows), len(cases))
    panels = {}
    for row, (part, label) in enumerate(rows):
        maps = []
        for vectors, _ in cases:
            if part == "refraction":
                dx = vectors["dx_field"] - vectors["dx_uniform"]
                dy = vectors["dy_field"] - vectors["dy_uniform"]
            elif part == "optics":
                dx, dy = vectors["dx_optics"], vectors["dy_optics"]
            else:
                dx = vectors["dx_uniform"] - vectors["dx_true"]
                dy = vectors["dy_uniform"] - vectors["dy_true"]
            maps.append(np.where(vectors["used"], np.hypot(dx, dy), np.nan))
        positive = np.concatenate([m[np.isfinite(m) & (m > 0)] for m in maps])
        norm = None
        if positive.size:
            norm = LogNorm(vmin=max(positive.min(), positive.max() * 1e-5), vmax=positive.max())
        mesh = None
        for col, ((vectors, stats), values) in enumerate(zip(cases, maps, strict=True)):
            ax = axes[row, col]
            shown = np.where(values > 0, values, np.nan)
            if norm is not None and np.isfinite(shown).any():
                mesh = ax.pcolormesh(
                    vectors["x"], vectors["y"], shown, norm=norm, cmap="magma", shading="nearest"
                )
            else:
                ax.text(
                    0.5, 0.5, "zero everywhere", ha="center", va="center", transform=ax.transAxes
                )
            ax.set_aspect("equal")
            ax.set_xlabel("x (px)")
            ax.set_ylabel("y (px)")
            ax.set_title(f"{part}, {case_label(stats)}", fontsize=8, loc="right")
            panels[f"{part} {stats['name']}"] = {"magnitude_px": _listed(values)}
        if mesh is not None:  # one colour scale per row
            figure.colorbar(mesh, ax=axes[row, :].tolist(), label=label)
    figure.suptitle(
        "Per-vector errors (px): refraction, its optics part, and the PIV baseline"
        + _scale_note(cases[0][1])
    )
    return figure, {"panels": panels}


def _error_pdfs(cases):
    stats = [s for _, s in cases]
    tables = _tables(cases)
    colors = case_colors(len(cases))
    figure, axes = new_figure(2, 3)
    panels = {}
    for ax, letter, component in (
        (axes[0, 0], "a", "3"),
        (axes[0, 1], "b", "2"),
        (axes[0, 2], "c", "magnitude"),
    ):
        samples = [relative_errors(t, "u", component, "meas", "ref") for t in tables]
        series, edges = pdf_series(samples, stats)
        if component == "magnitude":
            xlabel = "ε_|u| / |u|  (relative PIV refraction error of |u|)"
        else:
            xlabel = f"ε_u{component} / u{component}  (relative PIV refraction error)"
        draw_pdf_series(ax, series, edges, colors, xlabel)
        _letter(ax, letter)
        panels[letter] = {"quantity": xlabel, "bin_edges": edges.tolist(), "series": series}
    panels["d"] = _summary_against_g(
        axes[1, 0],
        stats,
        "systematic",
        "|systematic error| = |mean(ε/truth)|",
        "systematic relative error (fraction)",
    )
    _letter(axes[1, 0], "d")
    panels["e"] = _summary_against_g(
        axes[1, 1],
        stats,
        "random",
        "random error = std(ε/truth)",
        "random relative error (fraction)",
    )
    _letter(axes[1, 1], "e")
    ax = axes[1, 2]
    positive = [s for s in stats if s["G"] is not None and s["G"] > 0]
    g_values = [s["G"] for s in positive]
    parts = {}
    for key, style, label in (
        ("refraction_rms", "-o", "refraction"),
        ("optics_rms", "-s", "optics part"),
        ("baseline_rms", "--^", "PIV baseline"),
    ):
        values = [s["displacement_px"][key] for s in positive]
        ax.plot(g_values, [np.nan if v is None else v for v in values], style, label=label)
        parts[key] = values
    _log_against_g(ax, "rms per-vector error (px)", "displacement errors in pixels")
    # the same in mm/s where the field's scales are known (every case one pixel and Δt)
    mm_s = _per_px(stats[0])[1] if stats else None
    physical_axis(ax, "y", mm_s, "rms per-vector error (mm/s)")
    ax.legend(fontsize=7)
    _letter(ax, "f")
    panels["f"] = {"G": g_values, **parts}
    figure.suptitle("PIV velocity error from refraction, u' − u^ref")
    return figure, {"panels": panels}


_BUILDERS = {"piv_vectors": _vectors, "piv_error_maps": _error_maps, "piv_error_pdfs": _error_pdfs}


def draw_piv_figure(name, cases):
    """One figure and the numbers it draws.

    Parameters
    ----------
    name : str
        One of :data:`FIGURE_NAMES`.
    cases : list of (dict, dict)
        ``(vectors, stats)`` per case, sorted by ``delta_n_max``.

    Returns
    -------
    figure : matplotlib.figure.Figure
    data : dict
    """
    figure, data = _BUILDERS[name](cases)
    finish_axes(figure)
    return figure, data


def write_piv_figures(cases, out_dir, config=None, overwrite=True):
    """Draw every PIV figure, with the numbers behind each one.

    Parameters
    ----------
    cases : list of (dict, dict)
        ``(vectors, stats)`` per case (:mod:`rimcl.piv.study`); sorted here by ``delta_n_max``.
    out_dir : str or Path
        Created if missing; receives ``<name>.png``, ``.pdf`` and ``.json``.
    config : dict, optional
        Recorded in each JSON file.
    overwrite : bool

    Returns
    -------
    list of Path
    """
    cases = sorted(cases, key=lambda case: case[1]["delta_n_max"])
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    record = {"versions": versions(), "config": config or {}}
    written = []
    for name in FIGURE_NAMES:
        figure, data = draw_piv_figure(name, cases)
        written += save_figure(figure, name, data, record, out_dir, overwrite)
    return written
