"""The ``tracer_shape`` figure: PDFs of the image area change ΔA / A and of the circularity,
with air-like and water-like cases on axes of their own scale when their spreads differ much.
"""

import numpy as np
from matplotlib.ticker import MaxNLocator

from rimcl.stats.figures_common import (
    case_colors,
    case_label,
    figure_title,
    new_figure,
    panel_title,
)
from rimcl.stats.tables import area_changes, kept_rows

#: Cases whose spreads of ΔA/A differ by more than this factor get separate axes.
REGIME_SPREAD_RATIO = 20.0
#: Smallest median reference image area (px²) whose circularity describes a shape: the
#: perimeter of a blob of a few whole pixels is a pixel count (a 2 x 2 blob gives 0.32).
SHAPE_MIN_AREA_PX = 20.0


def _shape_regimes(changes):
    """Split the cases in two groups at the widest gap of their spreads of ΔA/A.

    The spread is the 98th percentile of ``|ΔA/A|``; the cases are split where two
    neighbouring spreads differ most, if by more than :data:`REGIME_SPREAD_RATIO`, so
    that air-like and water-like cases each get axes on their own scale.

    Returns
    -------
    list of (str, list of int)
        ``(name, case indices)`` of each regime drawn.
    """
    spreads = [float(np.percentile(np.abs(c), 98)) if c.size else 0.0 for c in changes]
    order = sorted(range(len(changes)), key=lambda i: spreads[i])
    floor = min([s for s in spreads if s > 0] or [1.0])
    logs = [np.log10(max(spreads[i], floor)) for i in order]
    gaps = np.diff(logs)
    if gaps.size and gaps.max() > np.log10(REGIME_SPREAD_RATIO):
        cut = int(np.argmax(gaps)) + 1
        return [
            ("small changes", sorted(order[:cut])),
            ("large changes", sorted(order[cut:])),
        ]
    return [("all cases", list(range(len(changes))))]


def draw_tracer_shape(all_tables, cases):
    kept = [kept_rows(tables, tables.tracers) for tables in all_tables]
    changes = [area_changes(table) for table in kept]
    regimes = _shape_regimes(changes)
    figure, axes = new_figure(2, len(regimes))
    colors = case_colors(len(cases))
    panels = {}
    letters = iter("abcd")
    for col, (regime, members) in enumerate(regimes):
        ax = axes[0, col]
        series = []
        pooled = np.concatenate([changes[i] for i in members])
        area_ref = np.concatenate([kept[i]["area_ref"] for i in members])
        pixel_step = 1.0 / float(np.median(area_ref[area_ref > 0])) if np.any(area_ref > 0) else 1.0
        low, high = (pooled.min(), pooled.max()) if pooled.size else (-0.5, 0.5)
        # whole-pixel bins (no kernel smoothing over the integer steps of the area)
        width = pixel_step * max(1.0, np.ceil((high - low) / pixel_step / 60.0))
        edges = np.arange(np.floor(low / width) - 0.5, np.ceil(high / width) + 1.0) * width
        for i in members:
            counts, _ = np.histogram(changes[i], bins=edges)
            density = counts / max(changes[i].size, 1) / np.diff(edges)
            peak = cases[i]["area_change_peak"]
            # a broad distribution's fullest bin says little: its median and spread instead
            label = case_label(cases[i])
            if changes[i].size:
                label += (
                    f": median {np.median(changes[i]):.2g}, "
                    f"|ΔA/A| 90 % {np.percentile(np.abs(changes[i]), 90):.2g}"
                )
            ax.stairs(np.where(density > 0, density, np.nan), edges, color=colors[i], label=label)
            series.append({"label": case_label(cases[i]), "pdf": density.tolist(), "peak": peak})
        ax.set_yscale("log")
        ax.xaxis.set_major_locator(MaxNLocator(5))
        ax.set_xlabel("area change ΔA / A (A: uniform medium)")
        ax.set_ylabel("PDF")
        ax.grid(True, which="major", alpha=0.3)
        ax.legend(fontsize=6)
        letter = next(letters)
        whole = (
            f"A ≈ {1.0 / pixel_step:.3g} px²: whole pixels, ΔA/A moves in steps of {pixel_step:.2g}"
        )
        panel_title(ax, letter, f"ΔA / A, {regime}; bins of {width / pixel_step:.0f} px² ({whole})")
        panels[letter] = {"bin_edges": edges.tolist(), "series": series}
    for col, (regime, members) in enumerate(regimes):
        ax = axes[1, col]
        letter = next(letters)
        area_ref = np.concatenate([kept[i]["area_ref"] for i in members])
        area_ref = area_ref[area_ref > 0]
        typical = float(np.median(area_ref)) if area_ref.size else 0.0
        if typical < SHAPE_MIN_AREA_PX:
            ax.set_axis_off()
            ax.text(
                0.5,
                0.5,
                f"({letter}) circularity not drawn: the images cover about {typical:.3g} px², "
                "and the perimeter of a blob of a few whole pixels is a pixel count, not a "
                f"shape (below {SHAPE_MIN_AREA_PX:g} px²)",
                ha="center",
                va="center",
                wrap=True,
                fontsize=8,
                transform=ax.transAxes,
            )
            panels[letter] = {"not_drawn": True, "median_area_px": typical}
            continue
        series = []
        samples = [kept[i]["circularity_meas"] for i in members]
        references = np.concatenate([kept[i]["circularity_ref"] for i in members])
        references = references[np.isfinite(references)]
        pooled = np.concatenate(samples)
        pooled = pooled[np.isfinite(pooled)]
        low, high = (pooled.min(), pooled.max()) if pooled.size else (0.5, 1.5)
        if high == low:
            low, high = low - 0.05, high + 0.05
        edges = np.linspace(low, high, 41)
        for i, sample in zip(members, samples, strict=True):
            finite = sample[np.isfinite(sample)]
            counts, _ = np.histogram(finite, bins=edges)
            density = counts / max(finite.size, 1) / np.diff(edges)
            peak = cases[i]["circularity_peak"]
            label = case_label(cases[i]) + ("" if peak is None else f": peak {peak:.3g}")
            ax.stairs(np.where(density > 0, density, np.nan), edges, color=colors[i], label=label)
            series.append({"label": case_label(cases[i]), "pdf": density.tolist(), "peak": peak})
        undistorted = float(np.median(references)) if references.size else None
        if undistorted is not None:
            # a disc of a few whole pixels has a pixel perimeter: its C is not 1
            ax.axvline(
                undistorted, color="k", ls="--", lw=1, label=f"uniform medium: {undistorted:.3g}"
            )
        ax.set_yscale("log")
        ax.xaxis.set_major_locator(MaxNLocator(5))
        ax.set_xlabel("circularity C = P²/(4πA'); dashed: undistorted")
        ax.set_ylabel("PDF")
        ax.grid(True, which="major", alpha=0.3)
        ax.legend(fontsize=6)
        panel_title(ax, letter, f"circularity, {regime}")
        panels[letter] = {
            "bin_edges": edges.tolist(),
            "series": series,
            "undistorted_median": undistorted,
        }
    figure_title(
        figure,
        "Tracer image shape: area change against the uniform medium's image, and circularity "
        "beside the undistorted image's (a pixelated disc is not 1)",
        fontsize=9,
    )
    return figure, {"panels": panels}
