"""Figures of a study (DESIGN §7): the paper's set, readable, with their numbers beside them.

Each figure is written as ``<name>.png`` and ``<name>.pdf`` (with the versions in the file
metadata) and ``<name>.json``: every number drawn, by panel and series, with the
configuration and versions. Figures are drawn with matplotlib's object API on the Agg
canvas (no pyplot state, no display needed). They draw what :mod:`rimcl.stats.compute` computed
(the ``stats.json`` document) and the per-tracer samples of :mod:`rimcl.stats.tables`; they never
import :mod:`rimcl.stats.compute`.

Figures: ``ray_deflection`` (|Δθ| against |N|L, the paper's literature studies marked),
``path_length`` (S/L against |θ0|), ``position_error`` (PDFs of |ε_x|/L, their peak and
median against G), ``velocity_error`` and ``acceleration_error`` (PDFs of the relative
errors, the angle to ``u^ref`` and to ``u``, the paper's mean and spread and the robust
statistics against G), ``error_budget`` (optics, imaging, total and baseline against G,
with a verdict per case), ``convergence`` (statistics against the number of tracers),
``maps`` (u3 and a3: truth, uniform medium, air-like and water-like cases) and
``tracer_shape`` (PDFs of ΔA/A and of the circularity, per regime). Every statistic drawn
against G carries its bootstrap 95 % interval as an error bar. :func:`write_dt_sweep_figure`
draws the refraction and baseline errors of several studies against Δt.
"""

import textwrap
from pathlib import Path

import numpy as np
from matplotlib import colormaps
from matplotlib.figure import Figure
from matplotlib.lines import Line2D
from matplotlib.ticker import FixedLocator, FuncFormatter, MaxNLocator, NullFormatter, NullLocator

from rimcl import __version__
from rimcl.core.provenance import atomic_path, to_json
from rimcl.stats.tables import (
    angle_deg,
    area_changes,
    density_estimate,
    first_frame_rows,
    kept_rows,
    position_errors,
    write_json,
)

FIGURE_NAMES = (
    "ray_deflection",
    "path_length",
    "position_error",
    "velocity_error",
    "acceleration_error",
    "error_budget",
    "convergence",
    "maps",
    "tracer_shape",
)
#: Rays drawn per case in the deflection scatter plot (the case files hold the whole sample).
MAX_SCATTER_RAYS = 1000
#: Incidence angle (rad) separating the two groups of the deflection plot (the paper's).
OBLIQUE_THETA0 = 0.6
#: Bins per decade of the logarithmic parts of the relative-error histograms.
BINS_PER_DECADE = 6
PANEL_SIZE = (4.6, 3.6)
#: Studies of the paper's Table 1 (tab:studies): reference, flow, Δn_max, fluid index n.
#: The paper estimated |N| as Δn_max / n over a characteristic length; with that length
#: taken as the depth L, |N| L = Δn_max / n. The deflections these studies reported are
#: not in the paper's text, so only their |N| L is marked.
LITERATURE_STUDIES = (
    ("Vanselow et al. 2018", "hot jet, air", 9.9e-5, 1.0003),
    ("Guo et al. 2016", "shock on a conical vehicle, air", 2.0e-5, 1.0003),
    ("Elsinga et al. 2005", "shear layer, air (theory)", 9.0e-5, 1.0003),
    ("Elsinga et al. 2005", "shear layer, air (PIV & BOS)", 6.9e-5, 1.0003),
    ("Elsinga et al. 2005", "expansion fan, air (theory)", 7.4e-5, 1.0003),
    ("Elsinga et al. 2005", "expansion fan, air (PIV & BOS)", 7.1e-5, 1.0003),
    ("Stella et al. 2001", "premixed flames, air-propane", 1.3e-3, 1.0003),
    ("Raffel et al. 1998", "shock wave, air", 1.0e-4, 1.0003),
    ("Kirmse et al. 2011", "shock wave, air", 6.3e-6, 1.0003),
    ("Oljaca & Gunaratne 2009", "plane shear layer, water", 3.4e-4, 1.333),
)
#: Quantities of the kinematic figures: (stats key, symbol, what it is).
KINEMATIC_BLOCKS = (
    ("velocity", "u", "velocity, differences"),
    ("acceleration", "a", "acceleration, differences"),
    ("velocity_fit", "u", "velocity, polynomial fit"),
    ("acceleration_fit", "a", "acceleration, polynomial fit"),
)
G_LABEL = "G = Kρ (Gladstone–Dale product)"
DELTA_N_LABEL = "Δn_max (largest index difference)"
#: Markers of the cases where shape, not colour, tells them apart.
CASE_MARKERS = ("o", "s", "^", "D", "v", "P", "X", "*")


def _case_label(case):
    symbol = "Δn_max" if case.get("abscissa") == "delta_n_max" else "G"
    return f"{case['name']} ({symbol} = {case['G']:.3g})"


def _case_colors(count):
    return [colormaps["viridis"](value) for value in np.linspace(0.0, 0.9, max(count, 1))]


def _new_figure(rows, cols, size=PANEL_SIZE):
    figure = Figure(figsize=(size[0] * cols, size[1] * rows), dpi=120, layout="constrained")
    axes = figure.subplots(rows, cols, squeeze=False)
    return figure, axes


def _title(ax, letter, text, fontsize=9):
    """Panel letter and title as one left-aligned title: the two can never overlap.

    Wrapped to the panel's width (constrained layout makes room above a panel, not
    beside it, so a title wider than its panel would run into its neighbour).
    """
    # the width before layout, less what labels and colour bars will take
    width_pt = 0.85 * ax.get_position().width * ax.figure.get_figwidth() * 72.0
    characters = max(20, int(width_pt / (0.55 * fontsize)))
    ax.set_title(textwrap.fill(f"({letter}) {text}", characters), loc="left", fontsize=fontsize)


def _kinematic_rows(tables, group):
    """Kept rows of a kinematic group; empty columns where the file lacks the group."""
    table = getattr(tables, group)
    if table:
        return kept_rows(tables, table)
    symbol = "u" if group.startswith("velocity") else "a"
    names = ["id", *(f"{symbol}{c}_{k}" for c in "23" for k in ("true", "ref", "meas"))]
    return {name: np.zeros(0) for name in names}


def _ticks_at(axis, values):
    """Label a log axis at the given values only: over less than a decade or two, its
    minor-tick labels would run into each other."""
    axis.set_major_locator(FixedLocator(sorted(values)))
    axis.set_major_formatter(FuncFormatter(lambda value, _: f"{value:.3g}"))
    axis.set_minor_locator(NullLocator())


def _suptitle(figure, text, fontsize=9):
    """The figure's title, wrapped to its width (no explicit line breaks needed)."""
    characters = max(30, int(figure.get_figwidth() * 72.0 * 0.95 / (0.55 * fontsize)))
    lines = [textwrap.fill(line, characters) for line in text.split("\n")]
    figure.suptitle("\n".join(lines), fontsize=fontsize)


def _symlog_edges(magnitude_floor, magnitude_top):
    """Histogram edges: linear inside ``±floor``, ``BINS_PER_DECADE`` log bins beyond."""
    decades = max(np.log10(magnitude_top / magnitude_floor), 1.0 / BINS_PER_DECADE)
    outer = magnitude_floor * np.logspace(0.0, decades, int(np.ceil(decades * BINS_PER_DECADE)) + 1)
    inner = np.linspace(-magnitude_floor, magnitude_floor, 5)[1:-1]
    return np.concatenate([-outer[::-1], inner, outer])


def _relative_errors(table, symbol, component, measured, reference):
    """``ε / truth`` of a component (``"2"``, ``"3"``) or of the magnitude (``"magnitude"``)."""
    columns = (f"{symbol}2", f"{symbol}3")
    if component == "magnitude":
        meas = np.hypot(*(table[f"{c}_{measured}"] for c in columns))
        ref = np.hypot(*(table[f"{c}_{reference}"] for c in columns))
        true = np.hypot(*(table[f"{c}_true"] for c in columns))
    else:
        meas, ref, true = (
            table[f"{symbol}{component}_{kind}"] for kind in (measured, reference, "true")
        )
    usable = np.isfinite(meas - ref) & (true != 0)
    return (meas[usable] - ref[usable]) / true[usable]


def _pdf_series(samples_by_case, cases):
    """Histograms of relative errors on common symmetric-log bins, one series per case.

    Returns the series (``pdf``: probability density of ``ε / truth``) and the bin edges.
    """
    magnitudes = np.concatenate([np.abs(s[s != 0]) for s in samples_by_case] or [np.empty(0)])
    if magnitudes.size == 0:
        edges = np.array([-1.0, 1.0])
    else:
        floor = 10.0 ** np.floor(np.log10(np.percentile(magnitudes, 1)))
        top = 10.0 ** np.ceil(np.log10(magnitudes.max()))
        edges = _symlog_edges(floor, top)
    series = []
    for case, sample in zip(cases, samples_by_case, strict=True):
        entry = {"label": _case_label(case), "n": int(sample.size), "pdf": []}
        entry["exactly_zero"] = bool(sample.size and np.all(sample == 0))
        if sample.size and not entry["exactly_zero"]:
            counts, _ = np.histogram(sample, bins=edges)
            entry["pdf"] = (counts / sample.size / np.diff(edges)).tolist()
        series.append(entry)
    return series, edges


def _symlog_ticks(ax, edges):
    """Symmetric-log x axis with at most three labelled decades on each side of zero."""
    floor, top = edges[len(edges) // 2 + 1], edges[-1]
    ax.set_xscale("symlog", linthresh=floor, linscale=0.5)
    low, high = round(np.log10(floor)), round(np.log10(top))
    stride = max(1, int(np.ceil((high - low + 1) / 3)))
    # none within a decade of the linear part, where the labels would crowd
    exponents = list(range(high, low + 1, -stride)) or [high]
    ticks = [-(10.0**k) for k in exponents] + [0.0] + [10.0**k for k in reversed(exponents)]
    ax.xaxis.set_major_locator(FixedLocator(ticks))
    ax.xaxis.set_minor_locator(NullLocator())

    def label(value, _position):
        if value == 0:
            return "0"
        sign = "−" if value < 0 else ""
        return f"${sign}10^{{{round(np.log10(abs(value)))}}}$"

    ax.xaxis.set_major_formatter(FuncFormatter(label))


def _draw_pdf_series(ax, series, edges, colors, xlabel, legend=True):
    centres = np.where(
        edges[:-1] * edges[1:] > 0,
        np.sign(edges[1:]) * np.sqrt(np.abs(edges[:-1] * edges[1:])),
        0.5 * (edges[:-1] + edges[1:]),
    )
    for entry, color in zip(series, colors, strict=True):
        if entry["exactly_zero"]:
            ax.plot([], [], color=color, label=f"{entry['label']}: ε = 0 exactly")
        elif entry["pdf"]:
            density = np.asarray(entry["pdf"])
            shown = np.where(density > 0, density, np.nan)
            ax.plot(centres, shown, "-o", ms=2.5, color=color, label=entry["label"])
    if len(edges) > 2:
        _symlog_ticks(ax, edges)
    ax.set_yscale("log")
    ax.set_xlabel(xlabel)
    ax.set_ylabel("PDF")
    ax.grid(True, which="major", alpha=0.3)
    if legend:
        ax.legend(fontsize=6)


def _errorbars(ax, xs, values, intervals, absolute, **style):
    """Points with their 95 % intervals; with ``absolute``, ``|value|`` on a log axis.

    An interval that holds 0 cannot be drawn below ``|value|`` on a log axis: its bar
    then goes up only and its marker is an open triangle pointing down. One call of
    ``errorbar`` per kind of point (drawing them one by one is slow).

    Returns
    -------
    bool
        Whether any interval holds zero.
    """
    groups = {False: ([], [], [], []), True: ([], [], [], [])}
    for x, value, interval in zip(xs, values, intervals, strict=True):
        shown = abs(value) if absolute else value
        if interval is None:
            low = high = shown
            holds_zero = False
        else:
            low, high = interval
            holds_zero = absolute and low <= 0 <= high
            if absolute:
                low, high = (shown, max(-low, high)) if holds_zero else sorted(map(abs, interval))
        group = groups[bool(holds_zero)]
        for column, number in zip(
            group, (x, shown, max(shown - low, 0.0), max(high - shown, 0.0)), strict=True
        ):
            column.append(number)
    for holds_zero, (x, shown, below, above) in groups.items():
        if x:
            extra = {"marker": "v", "mfc": "white"} if holds_zero else {}
            ax.errorbar(
                x, shown, yerr=[below, above], capsize=2, linestyle="none", **{**style, **extra}
            )
    return bool(groups[True][0])


def _statistic_against_g(
    ax, cases, series_specs, statistic, absolute=False, dodge=0.06, legend=True
):
    """Statistics against G with 95 % error bars, one line per series; returns the data.

    ``series_specs`` lists ``(label, getter, style)``; ``getter(case)`` gives the summary
    dict (with ``ci95``) or ``None``. Series are shifted a little along G (log axis) so
    their bars do not hide each other. Without ``legend`` the labelled handles are still
    made (a figure legend can collect them).
    """
    data, any_zero = [], False
    offsets = (np.arange(len(series_specs)) - (len(series_specs) - 1) / 2) * dodge
    for (label, getter, style), offset in zip(series_specs, offsets, strict=True):
        g_values, values, intervals = [], [], []
        for case in cases:
            summary = getter(case)
            value = None if summary is None else summary[statistic]
            if case["G"] > 0 and value is not None and (value != 0 or not absolute):
                g_values.append(case["G"])
                values.append(value)
                intervals.append(summary["ci95"][statistic])
        shift = 10.0**offset
        xs = [g * shift for g in g_values]
        shown = [abs(v) if absolute else v for v in values]
        line = ax.plot(xs, shown, "-", lw=1, **{k: v for k, v in style.items() if k != "marker"})
        color = line[0].get_color()
        marker_style = {"color": color, "marker": style.get("marker", "o"), "ms": 4}
        any_zero |= _errorbars(ax, xs, values, intervals, absolute, **marker_style)
        ax.plot([], [], "-" + style.get("marker", "o"), color=color, ms=4, label=label)
        data.append({"label": label, "G": g_values, "value": values, "ci95": intervals})
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel(G_LABEL)
    ax.grid(True, which="major", alpha=0.3)
    if any_zero:
        ax.plot([], [], "v", mfc="white", color="k", ms=4, label="95 % interval holds 0")
    if legend:
        ax.legend(fontsize=6)
    return data


def _ray_deflection(all_tables, cases):
    figure, axes = _new_figure(1, 1, size=(10.0, 5.6))
    ax = axes[0, 0]
    panel = {"x": "|N| L", "y": "|Δθ| (rad)", "series": [], "literature": []}
    lows, highs = [], []
    groups = (
        ("tab:blue", f"0 ≤ |θ0| ≤ {OBLIQUE_THETA0}"),
        ("tab:red", f"{OBLIQUE_THETA0} < |θ0|"),
    )
    case_handles = []
    for index, (tables, case) in enumerate(zip(all_tables, cases, strict=True)):
        rays = tables.rays
        if not rays:
            continue
        ok = (rays["status"] == 0) & (rays["deflection"] > 0) & (rays["n_metric"] > 0)
        # evenly strided through the sample, which is ordered by tracer
        usable = np.flatnonzero(ok)
        picks = np.linspace(0, max(usable.size - 1, 0), min(usable.size, MAX_SCATTER_RAYS))
        shown = usable[np.unique(picks.astype(int))]
        n_l = rays["n_metric"][shown] * tables.length
        deflection = rays["deflection"][shown]
        theta0 = np.abs(rays["theta0"][shown])
        panel["series"].append(
            {
                "label": _case_label(case),
                "NL": n_l.tolist(),
                "deflection": deflection.tolist(),
                "theta0": theta0.tolist(),
                "n_sampled": int(ok.size),
                "n_zero_or_failed": int(np.count_nonzero(~ok)),
            }
        )
        marker = CASE_MARKERS[index % len(CASE_MARKERS)]
        near = theta0 <= OBLIQUE_THETA0
        for mask, (color, _) in zip((near, ~near), groups, strict=True):
            ax.scatter(n_l[mask], deflection[mask], s=5, color=color, marker=marker, alpha=0.35)
        case_handles.append(
            Line2D([], [], marker=marker, color="0.3", linestyle="none", label=_case_label(case))
        )
        if n_l.size:
            lows.append(n_l.min())
            highs.append(n_l.max())
    literature_x = [delta_n / n for _, _, delta_n, n in LITERATURE_STUDIES]
    line = np.array([min([*lows, *literature_x]), max([*highs, *literature_x])])
    ax.plot(line, line, "k--", lw=1)
    # the literature studies as a rug along the bottom: their |N| L only (see LITERATURE_STUDIES)
    rug = ax.get_xaxis_transform()
    literature_handles = []
    for index, ((reference, flow, delta_n, n), x) in enumerate(
        zip(LITERATURE_STUDIES, literature_x, strict=True)
    ):
        marker = CASE_MARKERS[index % len(CASE_MARKERS)]
        color = colormaps["tab10"](index % 10)
        # staggered heights: several studies share nearly the same |N| L
        height = 0.04 + 0.035 * (index % 4)
        ax.plot([x, x], [0.0, height], color=color, lw=1.2, transform=rug)
        ax.plot([x], [height], marker=marker, color=color, mfc="white", ms=5, transform=rug)
        literature_handles.append(
            Line2D(
                [],
                [],
                marker=marker,
                color=color,
                mfc="white",
                linestyle="none",
                label=f"{reference}: {flow}, Δn_max = {delta_n:.2g}",
            )
        )
        panel["literature"].append(
            {"reference": reference, "flow": flow, "delta_n_max": delta_n, "n": n, "NL": x}
        )
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("|N| L (path-averaged transverse ∇n/n times slab depth L)")
    ax.set_ylabel("ray deflection |Δθ| (rad)")
    _title(
        ax,
        "a",
        "Ray deflection (frame-0 ray sample, rays with status ok); ticks along the bottom: "
        "|N| L ≈ Δn_max / n of the studies of the paper's Table 1",
        fontsize=8,
    )
    ax.grid(True, which="major", alpha=0.3)
    angle_handles = [
        Line2D([], [], marker="o", color=color, linestyle="none", label=label)
        for color, label in groups
    ]
    guide = [Line2D([], [], color="k", linestyle="--", label="|Δθ| = |N| L")]
    first = ax.legend(handles=angle_handles + guide + case_handles, fontsize=6, loc="upper left")
    ax.add_artist(first)
    figure.legend(
        handles=literature_handles,
        fontsize=6,
        loc="outside right center",
        title="literature (paper's Table 1)",
        title_fontsize=6,
    )
    return figure, {"panels": {"a": panel}}


def _path_length(all_tables, cases):
    with_rays = [(t, c) for t, c in zip(all_tables, cases, strict=True) if t.rays]
    cols = min(max(len(with_rays), 1), 3)
    rows = max(1, -(-len(with_rays) // cols))
    figure, axes = _new_figure(rows, cols)
    panels = {}
    for index, (tables, case) in enumerate(with_rays):
        ax = axes.flat[index]
        rays = tables.rays
        ok = rays["status"] == 0
        theta0 = np.abs(rays["theta0"][ok])
        s_over_l = rays["path_length"][ok] / tables.length
        counts, t_edges, s_edges = np.histogram2d(theta0, s_over_l, bins=(40, 40))
        mesh = ax.pcolormesh(
            t_edges, s_edges, np.where(counts.T > 0, counts.T, np.nan), cmap="viridis"
        )
        figure.colorbar(mesh, ax=ax, label="rays per bin")
        curve = np.linspace(0.0, t_edges[-1], 200)
        ax.plot(curve, 1.0 / np.cos(curve), "r--", lw=1.2, label="1 / cos|θ0|")
        ax.set_xlabel("incidence angle |θ0| (rad)")
        ax.set_ylabel("path length S / L")
        _title(ax, chr(ord("a") + index), _case_label(case))
        ax.legend(fontsize=7, loc="upper left")
        panels[case["name"]] = {
            "theta0_edges": t_edges.tolist(),
            "S_over_L_edges": s_edges.tolist(),
            "counts": counts.tolist(),
        }
    for ax in list(axes.flat)[len(with_rays) :]:
        ax.set_axis_off()
    return figure, {"panels": panels}


def _position_error(all_tables, cases):
    figure, axes = _new_figure(1, 2)
    ax_pdf, ax_peak = axes[0]
    colors = _case_colors(len(cases))
    series = []
    for tables, case, color in zip(all_tables, cases, colors, strict=True):
        errors = position_errors(kept_rows(tables, tables.tracers), tables.length)
        grid, density = density_estimate(errors, log=True)
        entry = {
            "label": _case_label(case),
            "x_over_L": grid.tolist(),
            "pdf_log10": density.tolist(),
            "peak_over_L": case["position_error_peak_over_L"],
            "n_zero": int(np.count_nonzero(errors == 0)),
            "n": int(errors.size),
        }
        series.append(entry)
        if grid.size < 2:
            note = {0: ": no tracer used", 1: ""}.get(grid.size, "")
            if grid.size == 0 and errors.size:
                note = ": |ε_x| = 0 exactly"
            ax_pdf.plot([], [], color=color, label=_case_label(case) + note)
            continue
        ax_pdf.plot(grid, density, color=color, label=_case_label(case))
        peak = entry["peak_over_L"]
        ax_pdf.plot(
            peak, np.interp(np.log10(peak), np.log10(grid), density), "o", color=color, mec="k"
        )
    ax_pdf.set_xscale("log")
    ax_pdf.set_xlabel("position error |ε_x| / L")
    ax_pdf.set_ylabel("PDF of log10(|ε_x| / L)")
    ax_pdf.grid(True, which="major", alpha=0.3)
    ax_pdf.legend(fontsize=6, title="dots: PDF peaks", title_fontsize=6)
    _title(ax_pdf, "a", "PDF of the position error, per case")

    def position(key):
        return lambda case: (
            None
            if case[key] is None
            else {"value": case[key], "ci95": {"value": case[f"{key}_ci95"]}}
        )

    positive = [c for c in cases if c["G"] > 0]
    data = _statistic_against_g(
        ax_peak,
        positive,
        [
            (
                "PDF peak of |ε_x| / L",
                position("position_error_peak_over_L"),
                {"marker": "o", "color": "k"},
            ),
            (
                "median of |ε_x| / L",
                position("position_error_median_over_L"),
                {"marker": "s", "color": "tab:orange"},
            ),
        ],
        "value",
        absolute=True,
    )
    ax_peak.set_ylabel("|ε_x| / L (bars: bootstrap 95 % intervals)")
    ratios = [c["delta_n_max"] / c["G"] for c in positive]
    if ratios:
        ratio = float(np.median(ratios))
        top = ax_peak.secondary_xaxis("top", functions=(lambda g: g * ratio, lambda d: d / ratio))
        top.set_xlabel("Δn_max")
    _title(ax_peak, "b", "peak and median against G")
    return figure, {"panels": {"a": {"series": series}, "b": data}}


def _kinematic_error(all_tables, cases, group, title):
    """Velocity (``u``) or acceleration (``a``) error figure: the paper's six panels and two."""
    symbol = "u" if group.startswith("velocity") else "a"
    figure, axes = _new_figure(2, 4)
    colors = _case_colors(len(cases))
    tables_kept = [_kinematic_rows(tables, group) for tables in all_tables]
    panels = {}
    for ax, letter, component in (
        (axes[0, 0], "a", "3"),
        (axes[0, 1], "b", "2"),
        (axes[0, 2], "c", "magnitude"),
    ):
        samples = [_relative_errors(t, symbol, component, "meas", "ref") for t in tables_kept]
        series, edges = _pdf_series(samples, cases)
        if component == "magnitude":
            xlabel = f"ε_|{symbol}| / |{symbol}| (relative error of the magnitude)"
            text = f"PDF of ε_|{symbol}| / |{symbol}|"
        else:
            xlabel = f"ε_{symbol}{component} / {symbol}{component} (relative error)"
            text = f"PDF of ε_{symbol}{component} / {symbol}{component}"
        _draw_pdf_series(ax, series, edges, colors, xlabel, legend=False)
        _title(ax, letter, text)
        panels[letter] = {"quantity": xlabel, "bin_edges": edges.tolist(), "series": series}

    ax = axes[0, 3]
    angle_series = []
    for tables, case, color in zip(tables_kept, cases, colors, strict=True):
        measured = (tables[f"{symbol}2_meas"], tables[f"{symbol}3_meas"])
        entry = {"label": _case_label(case)}
        for against, style in (("ref", "-"), ("true", "--")):
            angles = angle_deg(
                measured, (tables[f"{symbol}2_{against}"], tables[f"{symbol}3_{against}"])
            )
            grid, density = density_estimate(angles, log=True)
            # the kernel's tails would reach past the largest possible angle
            grid, density = grid[grid <= 180.0], density[grid <= 180.0]
            entry[against] = {
                "angle_deg": grid.tolist(),
                "pdf_log10": density.tolist(),
                "n_zero": int(np.count_nonzero(angles == 0)),
            }
            if grid.size >= 2:
                ax.plot(grid, density, style, color=color, lw=1)
        angle_series.append(entry)
    ax.set_xscale("log")
    ax.set_xlabel(f"angle between {symbol}' and {symbol}^ref or {symbol} (degrees)")
    ax.set_ylabel("PDF of log10(angle)")
    ax.grid(True, which="major", alpha=0.3)
    _title(
        ax,
        "d",
        f"direction of {symbol}': solid, angle to {symbol}^ref (refraction); dashed, "
        f"to {symbol} (refraction and baseline, the paper's)",
        fontsize=8,
    )
    panels["d"] = {"series": angle_series}

    components = ((f"{symbol}3", "o"), (f"{symbol}2", "s"), ("magnitude", "^"))

    def summary_of(key, conditioned=False):
        def getter(case):
            summary = case.get(group, {}).get(key)
            return summary["conditioned"] if summary and conditioned else summary

        return getter

    def name(key):
        return f"|{symbol}|" if key == "magnitude" else key

    panels["e"] = _statistic_against_g(
        axes[1, 0],
        cases,
        [(f"{name(k)}: |mean(ε/{name(k)})|", summary_of(k), {"marker": m}) for k, m in components],
        "systematic",
        absolute=True,
    )
    axes[1, 0].set_ylabel("|systematic error| = |mean(ε/truth)|")
    _title(axes[1, 0], "e", "the paper's systematic error")
    panels["f"] = _statistic_against_g(
        axes[1, 1],
        cases,
        [(f"{name(k)}: std(ε/{name(k)})", summary_of(k), {"marker": m}) for k, m in components],
        "random",
        absolute=True,
    )
    axes[1, 1].set_ylabel("random error = std(ε/truth)")
    _title(axes[1, 1], "f", "the paper's random error (may not converge)")
    panels["g"] = _statistic_against_g(
        axes[1, 2],
        cases,
        [
            (f"{name(k)}: rms(ε)/rms({name(k)})", summary_of(k), {"marker": m})
            for k, m in components
        ],
        "rms_normalized",
        absolute=True,
    )
    axes[1, 2].set_ylabel("rms(ε) / rms(truth)")
    _title(axes[1, 2], "g", "robust: rms(ε) / rms(truth)")
    key = f"{symbol}3"
    panels["h"] = _statistic_against_g(
        axes[1, 3],
        cases,
        [
            (f"IQR of ε_{key}/{key}", summary_of(key), {"marker": "o"}),
            (f"IQR, |{key}| ≥ ½ rms({key})", summary_of(key, True), {"marker": "s"}),
            (
                f"|median| of ε_{key}/{key}",
                _with_statistic(summary_of(key), "median"),
                {"marker": "^"},
            ),
        ],
        "iqr",
        absolute=True,
    )
    axes[1, 3].set_ylabel("interquartile range (or |median|) of ε/truth")
    _title(axes[1, 3], "h", f"robust: quartiles of ε_{key}/{key}")
    # the cases of panels (a)-(d) in one legend beside them, off the data
    exactly_zero = {entry["label"] for entry in panels["a"]["series"] if entry["exactly_zero"]}
    handles = [
        Line2D(
            [],
            [],
            color=color,
            label=_case_label(case)
            + (": ε = 0 exactly" if _case_label(case) in exactly_zero else ""),
        )
        for case, color in zip(cases, colors, strict=True)
    ]
    figure.legend(handles=handles, loc="outside right upper", fontsize=7, title="(a)–(d)")
    _suptitle(figure, title + " (bars: bootstrap 95 % intervals)", fontsize=11)
    return figure, {"panels": panels}


def _with_statistic(getter, statistic):
    """A getter whose ``iqr`` is another statistic of the summary (to share a panel)."""

    def renamed(case):
        summary = getter(case)
        if summary is None:
            return None
        return {"iqr": summary[statistic], "ci95": {"iqr": summary["ci95"][statistic]}}

    return renamed


#: Parts of the error budget: (label, where in a case, style).
BUDGET_PARTS = (
    ("optics", ("optics",), {"marker": "o", "color": "tab:blue"}),
    ("imaging", ("imaging",), {"marker": "s", "color": "tab:orange"}),
    ("total refraction", (), {"marker": "D", "color": "k"}),
    ("baseline (no refraction)", ("baseline",), {"marker": "^", "color": "tab:green"}),
)


def _summary_at(*path):
    """A getter of the summary at ``path`` in a case (``None`` where missing)."""
    return lambda case: _dig(case, *path)


def _position_median_at(*prefix):
    """A getter of the median position error of a part, as a summary of key ``value``."""

    def getter(case):
        value = _dig(case, *prefix, "position_error_median_over_L")
        if value is None:
            return None
        interval = _dig(case, *prefix, "position_error_median_over_L_ci95")
        return {"value": value, "ci95": {"value": interval}}

    return getter


def _error_budget(cases):
    with_budget = any("optics" in case for case in cases)
    groups = [g for g, *_ in KINEMATIC_BLOCKS if any(g in case for case in cases)]
    panels_count = 1 + len(groups)
    cols = min(panels_count, 3)
    rows = -(-panels_count // cols)
    verdicts = [c["budget_verdict"]["text"] for c in cases if c.get("budget_verdict")]
    if not verdicts:
        verdicts = [
            "no optics columns in these render files: refraction (total) against the baseline only"
        ]
    text_height = 0.3 + 0.17 * len(verdicts)
    figure = Figure(
        figsize=(PANEL_SIZE[0] * cols, PANEL_SIZE[1] * rows + text_height),
        dpi=120,
        layout="constrained",
    )
    grid = figure.add_gridspec(rows + 1, cols, height_ratios=[PANEL_SIZE[1]] * rows + [text_height])
    axes = [figure.add_subplot(grid[i // cols, i % cols]) for i in range(panels_count)]
    positive = [c for c in cases if c["G"] > 0]
    parts = BUDGET_PARTS if with_budget else BUDGET_PARTS[2:]
    panels = {
        "a": _statistic_against_g(
            axes[0],
            positive,
            [
                (label, _position_median_at(*prefix), style)
                for label, prefix, style in parts
                if prefix != ("baseline",)
            ],
            "value",
            absolute=True,
            legend=False,
        )
    }
    axes[0].set_ylabel("median |ε_x| / L")
    _title(axes[0], "a", "position error")
    for index, group in enumerate(groups, start=1):
        key = f"{'u' if group.startswith('velocity') else 'a'}3"
        letter = chr(ord("a") + index)
        panels[letter] = _statistic_against_g(
            axes[index],
            positive,
            [(label, _summary_at(*prefix, group, key), style) for label, prefix, style in parts],
            "rms_normalized",
            absolute=True,
            legend=False,
        )
        axes[index].set_ylabel(f"rms(ε_{key}) / rms({key})")
        _title(axes[index], letter, dict((g, d) for g, _, d in KINEMATIC_BLOCKS)[group])
    text_ax = figure.add_subplot(grid[rows, :])
    text_ax.set_axis_off()
    text_ax.text(
        0.0, 1.0, "\n".join(verdicts), va="top", ha="left", fontsize=7, transform=text_ax.transAxes
    )
    # one legend for every panel, beside the verdicts: the panels' data stay uncovered
    handles, labels = axes[1 if len(axes) > 1 else 0].get_legend_handles_labels()
    text_ax.legend(handles, labels, loc="upper right", fontsize=7, ncol=2)
    panels["verdicts"] = verdicts
    _suptitle(
        figure,
        "Error budget: optics (mean of the traced ray image points), imaging (renderer, "
        "threshold, centroid),\ntheir total, and the baseline (bars: bootstrap 95 % intervals)",
        fontsize=9,
    )
    return figure, {"panels": panels}


def _dig(node, *path):
    """``node[path[0]][path[1]]...``, or ``None`` where a level is missing."""
    for key in path:
        if not isinstance(node, dict) or key not in node:
            return None
        node = node[key]
    return node


#: Statistics of the convergence figure: (key in ``convergence``, axis label, title).
CONVERGENCE_COLUMNS = (
    ("random", "std(ε/truth)", "the paper's random error"),
    ("rms_normalized", "rms(ε) / rms(truth)", "rms(ε) / rms(truth)"),
    ("iqr", "IQR of ε/truth", "IQR of ε/truth"),
    (
        "conditioned_rms_normalized",
        "rms ratio where |truth| ≥ ½ rms",
        "rms ratio, |truth| ≥ ½ rms(truth)",
    ),
)


def _convergence(cases):
    groups = [g for g, *_ in KINEMATIC_BLOCKS if any(g in c.get("convergence", {}) for c in cases)]
    rows = max(len(groups), 1)
    figure, axes = _new_figure(rows, len(CONVERGENCE_COLUMNS))
    colors = _case_colors(len(cases))
    panels = {}
    letters = (chr(ord("a") + i) for i in range(26))
    for row, group in enumerate(groups):
        component = f"{'u' if group.startswith('velocity') else 'a'}3"
        description = dict((g, d) for g, _, d in KINEMATIC_BLOCKS)[group]
        for col, (statistic, ylabel, text) in enumerate(CONVERGENCE_COLUMNS):
            ax = axes[row, col]
            series, growing, widest = [], [], []
            for case, color in zip(cases, colors, strict=True):
                convergence = case.get("convergence", {})
                entry = _dig(convergence, group, component, statistic)
                if entry is None or case["G"] <= 0:
                    continue
                flagged = f"{group}.{component}.{statistic}" in convergence["not_converged"]
                points = [
                    (n, v, ci)
                    for n, v, ci in zip(
                        convergence["n_tracers"], entry["value"], entry["ci95"], strict=True
                    )
                    if v is not None and v != 0
                ]
                if not points:
                    continue
                ns, values, intervals = zip(*points, strict=True)
                widest = max(widest, list(ns), key=lambda sizes: (len(sizes), sizes[-1:]))
                marker = "^" if flagged else "o"
                ax.plot(ns, np.abs(values), "-", color=color, lw=1)
                _errorbars(
                    ax,
                    ns,
                    values,
                    intervals,
                    True,
                    color=color,
                    marker=marker,
                    ms=4,
                    mfc="white" if flagged else color,
                )
                if flagged:
                    growing.append(case["name"])
                series.append(
                    {
                        "label": _case_label(case),
                        "n_tracers": list(ns),
                        "value": list(values),
                        "ci95": list(intervals),
                        "not_converged": flagged,
                    }
                )
            ax.set_xscale("log")
            ax.set_yscale("log")
            # the sizes of the case with the most subsamples: the sizes of cases of other N
            # would sit too close to them to be labelled
            _ticks_at(ax.xaxis, widest)
            ax.set_xlabel("tracers used (nested subsamples)")
            ax.set_ylabel(f"{ylabel}, {component}")
            ax.grid(True, which="major", alpha=0.3)
            letter = next(letters)
            note = f"; not converged: {', '.join(growing)}" if growing else ""
            _title(ax, letter, f"{text}; {description}{note}", fontsize=8)
            panels[letter] = {"group": group, "statistic": statistic, "series": series}
    if not groups:
        for ax in axes.flat:
            ax.set_axis_off()
    handles = [
        Line2D([], [], marker="o", color=color, label=_case_label(case))
        for case, color in zip(cases, colors, strict=True)
        if case["G"] > 0
    ]
    handles.append(
        Line2D(
            [],
            [],
            marker="^",
            mfc="white",
            color="k",
            linestyle="none",
            label="still growing: not converged",
        )
    )
    figure.legend(handles=handles, loc="outside right center", fontsize=7)
    _suptitle(
        figure,
        "Convergence with the number of tracers (|value|; bars: bootstrap 95 % intervals)",
        fontsize=9,
    )
    return figure, {"panels": panels}


def _air_and_water(cases):
    """Indices of the cases shown as 'air' and 'water': C1 and C4, else the extreme G > 0."""
    names = [c["name"] for c in cases]
    positive = [i for i, c in enumerate(cases) if c["G"] > 0] or list(range(len(cases)))
    air = names.index("C1") if "C1" in names else positive[0]
    water = names.index("C4") if "C4" in names else positive[-1]
    return air, water


def _maps(all_tables, cases):
    air, water = _air_and_water(cases)
    figure, axes = _new_figure(2, 4, size=(4.2, 3.6))
    panels = {}
    acceleration = "acceleration_fit" if all_tables[air].acceleration_fit else "acceleration"
    frame0 = first_frame_rows(all_tables[air].tracers)
    position = dict(
        zip(
            frame0["id"].tolist(),
            zip(frame0["x2_true"], frame0["x3_true"], strict=True),
            strict=True,
        )
    )
    letters = iter("abcdefgh")
    for row, (symbol, group) in enumerate((("u", "velocity"), ("a", acceleration))):
        truth = first_frame_rows(_kinematic_rows(all_tables[air], group))
        truth = truth.get(f"{symbol}3_true", np.zeros(0))
        limit = float(np.percentile(np.abs(truth), 98)) if truth.size else 1.0
        columns = (
            ("truth", air, "true"),
            ("uniform medium (no refraction)", air, "ref"),
            (f"measured, {_case_label(cases[air])}", air, "meas"),
            (f"measured, {_case_label(cases[water])}", water, "meas"),
        )
        for col, (label, index, kind) in enumerate(columns):
            ax = axes[row, col]
            table = first_frame_rows(_kinematic_rows(all_tables[index], group))
            values = table.get(f"{symbol}3_{kind}", np.zeros(0))
            xy = np.array([position.get(int(i), (np.nan, np.nan)) for i in table.get("id", [])])
            if xy.size:
                mesh = ax.scatter(
                    xy[:, 0], xy[:, 1], c=values, s=9, cmap="RdBu_r", vmin=-limit, vmax=limit
                )
                figure.colorbar(mesh, ax=ax, label=f"{symbol}3 (field units)", extend="both")
            ax.set_aspect("equal")
            ax.set_xlabel("x2 (field length units)")
            ax.set_ylabel("x3 (field length units)")
            method = " (fit)" if group.endswith("_fit") else ""
            _title(ax, next(letters), f"{symbol}3{method}: {label}", fontsize=8)
            panels[f"{symbol}3 {label}"] = {
                "id": table.get("id", np.zeros(0)).tolist(),
                "x2": xy[:, 0].tolist() if xy.size else [],
                "x3": xy[:, 1].tolist() if xy.size else [],
                "value": values.tolist(),
            }
    _suptitle(
        figure,
        "Velocity u3 and acceleration a3 at the first frame "
        "(colour range: the truth's 98th percentile; uniform medium: the measurement "
        "noise without refraction)",
        fontsize=9,
    )
    return figure, {"panels": panels}


#: Cases whose spreads of ΔA/A differ by more than this factor get separate axes.
REGIME_SPREAD_RATIO = 20.0


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


def _tracer_shape(all_tables, cases):
    kept = [kept_rows(tables, tables.tracers) for tables in all_tables]
    changes = [area_changes(table) for table in kept]
    regimes = _shape_regimes(changes)
    figure, axes = _new_figure(2, len(regimes))
    colors = _case_colors(len(cases))
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
            label = _case_label(cases[i]) + ("" if peak is None else f": peak {peak:.3g}")
            ax.stairs(np.where(density > 0, density, np.nan), edges, color=colors[i], label=label)
            series.append({"label": _case_label(cases[i]), "pdf": density.tolist(), "peak": peak})
        ax.set_yscale("log")
        ax.xaxis.set_major_locator(MaxNLocator(5))
        ax.set_xlabel("area change ΔA / A (A: uniform medium)")
        ax.set_ylabel("PDF")
        ax.grid(True, which="major", alpha=0.3)
        ax.legend(fontsize=6)
        letter = next(letters)
        _title(ax, letter, f"ΔA / A, {regime}; bins of {width / pixel_step:.0f} px²")
        panels[letter] = {"bin_edges": edges.tolist(), "series": series}
    for col, (regime, members) in enumerate(regimes):
        ax = axes[1, col]
        series = []
        samples = [kept[i]["circularity_meas"] for i in members]
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
            label = _case_label(cases[i]) + ("" if peak is None else f": peak {peak:.3g}")
            ax.stairs(np.where(density > 0, density, np.nan), edges, color=colors[i], label=label)
            series.append({"label": _case_label(cases[i]), "pdf": density.tolist(), "peak": peak})
        ax.set_yscale("log")
        ax.xaxis.set_major_locator(MaxNLocator(5))
        ax.set_xlabel("circularity C = P² / (4π A') (1: a disc)")
        ax.set_ylabel("PDF")
        ax.grid(True, which="major", alpha=0.3)
        ax.legend(fontsize=6)
        letter = next(letters)
        _title(ax, letter, f"circularity, {regime}")
        panels[letter] = {"bin_edges": edges.tolist(), "series": series}
    _suptitle(
        figure,
        "Tracer image shape (ΔA/A peak: fullest whole-pixel bin; C peak: kernel density mode)",
        fontsize=9,
    )
    return figure, {"panels": panels}


def _velocity_error(all_tables, cases):
    return _kinematic_error(
        all_tables, cases, "velocity", "Velocity error from refraction, ε_u = u' − u^ref"
    )


def _acceleration_error(all_tables, cases):
    group = "acceleration_fit" if any(t.acceleration_fit for t in all_tables) else "acceleration"
    method = "polynomial fit" if group.endswith("_fit") else "three-point differences"
    title = f"Acceleration error from refraction, ε_a = a' − a^ref ({method})"
    return _kinematic_error(all_tables, cases, group, title)


_BUILDERS = {
    "ray_deflection": _ray_deflection,
    "path_length": _path_length,
    "position_error": _position_error,
    "velocity_error": _velocity_error,
    "acceleration_error": _acceleration_error,
    "error_budget": lambda all_tables, cases: _error_budget(cases),
    "convergence": lambda all_tables, cases: _convergence(cases),
    "maps": _maps,
    "tracer_shape": _tracer_shape,
}


def _finish_axes(figure):
    """Make log axes drawable and readable.

    A log axis with nothing positive to show (every error exactly zero, as in a uniform
    medium) goes back to linear with a note, instead of failing to draw. Log axes
    spanning more than three decades lose their minor ticks: too dense to read, and
    drawing them doubles the time to save a figure.
    """
    for ax in figure.axes:
        if ax.get_label() == "<colorbar>" or not ax.axison:
            continue
        for axis, data_high, set_scale in (
            (ax.xaxis, ax.dataLim.x1, ax.set_xscale),
            (ax.yaxis, ax.dataLim.y1, ax.set_yscale),
        ):
            if axis.get_scale() != "log":
                continue
            if not (np.isfinite(data_high) and data_high > 0):
                set_scale("linear")
                ax.text(
                    0.5,
                    0.5,
                    "nothing to show: every value is zero",
                    ha="center",
                    va="center",
                    transform=ax.transAxes,
                    color="0.4",
                )
                continue
            shown_low, shown_high = sorted(abs(v) for v in axis.get_view_interval())
            if shown_low > 0 and shown_high / shown_low > 1e3:
                axis.set_minor_locator(NullLocator())


def draw_figure(name, all_tables, stats):
    """One figure and the numbers it draws.

    Parameters
    ----------
    name : str
        One of :data:`FIGURE_NAMES`.
    all_tables : list of RenderTables
        Sorted as ``stats["cases"]`` (by ``G``).
    stats : dict
        The ``stats.json`` document of the same tables.

    Returns
    -------
    figure : matplotlib.figure.Figure
    data : dict
        ``{"panels": ...}``: every number drawn, by panel and series.
    """
    cases = stats["cases"]
    by_index = any(case["G"] is None for case in cases)
    if by_index:
        # fluid cases and δn files have no G: every case is placed by its Δn_max instead
        cases = [{**case, "G": case["delta_n_max"], "abscissa": "delta_n_max"} for case in cases]
    figure, data = _BUILDERS[name](all_tables, cases)
    if by_index:
        for ax in figure.axes:
            if ax.get_xlabel() == G_LABEL:
                ax.set_xlabel(DELTA_N_LABEL)
    _finish_axes(figure)
    return figure, data


def save_figure(figure, name, data, stats, out_dir, overwrite):
    """``<name>.png``, ``.pdf`` (versions in the metadata) and ``.json`` (the numbers).

    ``stats`` needs ``versions`` and ``config`` (recorded in every file).
    """
    description = to_json({"versions": stats["versions"], "numbers": f"see {name}.json"})
    targets = {
        "png": {
            "Title": f"rimcl {name}",
            "Software": f"rimcl {__version__}",
            "Description": description,
        },
        "pdf": {
            "Title": f"rimcl {name}",
            "Creator": f"rimcl {__version__}",
            "Subject": description,
        },
    }
    written = []
    for extension, metadata in targets.items():
        path = out_dir / f"{name}.{extension}"
        with atomic_path(path, overwrite=overwrite) as tmp:
            figure.savefig(tmp, format=extension, metadata=metadata)
        # the layout found for the first file serves the next (same size): solving it
        # again costs as much as drawing
        figure.set_layout_engine("none")
        written.append(path)
    path = out_dir / f"{name}.json"
    document = {"figure": name, **data, "config": stats["config"], "versions": stats["versions"]}
    write_json(path, document, overwrite=overwrite)
    written.append(path)
    return written


def write_figures(all_tables, stats, out_dir, overwrite=True):
    """Draw every figure of a set of cases, with the numbers behind each one.

    Parameters
    ----------
    all_tables : list of RenderTables
        Sorted as ``stats["cases"]`` (by ``G``).
    stats : dict
        The ``stats.json`` document of the same tables.
    out_dir : str or Path
        Created if missing; receives ``<name>.png``, ``<name>.pdf`` and ``<name>.json``
        for each name of :data:`FIGURE_NAMES`.
    overwrite : bool
        Replace existing files (otherwise an existing file is an error).

    Returns
    -------
    list of Path
        The files written.
    """
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    written = []
    for name in FIGURE_NAMES:
        figure, data = draw_figure(name, all_tables, stats)
        written += save_figure(figure, name, data, stats, out_dir, overwrite)
    return written


#: Quantities of the Δt sweep: (stats key, component).
DT_SWEEP_QUANTITIES = (
    ("velocity", "u3"),
    ("acceleration", "a3"),
    ("velocity_fit", "u3"),
    ("acceleration_fit", "a3"),
)


def dt_sweep_data(stats_by_dt):
    """Refraction and baseline ``rms(ε)/rms(truth)`` of each case against Δt.

    Parameters
    ----------
    stats_by_dt : dict of float to dict
        The ``stats.json`` document of one study per time step Δt (field time units).

    Returns
    -------
    dict
        ``dt`` (sorted), and per case name and quantity (``velocity``, ``acceleration``,
        and the ``_fit`` ones where every study has them) the lists ``refraction``,
        ``refraction_ci95``, ``baseline``, ``baseline_ci95`` (one entry per Δt, ``None``
        where missing), ``dominates`` (refraction above baseline at that Δt, ``None`` where
        unknown), ``wholly_above`` (the refraction interval wholly above the baseline's),
        ``refraction_dominates_dt`` (the Δt values where it dominates).
    """
    dts = sorted(stats_by_dt)
    documents = [stats_by_dt[dt] for dt in dts]
    names = []
    for document in documents:
        names += [case["name"] for case in document["cases"] if case["name"] not in names]
    quantities = [
        (group, component)
        for group, component in DT_SWEEP_QUANTITIES
        if all(any(group in case for case in doc["cases"]) for doc in documents)
    ]
    cases = {}
    for name in names:
        by_quantity = {}
        for group, component in quantities:
            entry = {
                key: [] for key in ("refraction", "refraction_ci95", "baseline", "baseline_ci95")
            }
            for document in documents:
                case = next((c for c in document["cases"] if c["name"] == name), {})
                for kind, summary in (
                    ("refraction", _dig(case, group, component)),
                    ("baseline", _dig(case, "baseline", group, component)),
                ):
                    entry[kind].append(None if summary is None else summary["rms_normalized"])
                    entry[f"{kind}_ci95"].append(
                        None if summary is None else summary["ci95"]["rms_normalized"]
                    )
            entry["dominates"] = [
                None if r is None or b is None else r > b
                for r, b in zip(entry["refraction"], entry["baseline"], strict=True)
            ]
            entry["wholly_above"] = [
                None if r is None or b is None else r[0] > b[1]
                for r, b in zip(entry["refraction_ci95"], entry["baseline_ci95"], strict=True)
            ]
            entry["refraction_dominates_dt"] = [
                dt for dt, flag in zip(dts, entry["dominates"], strict=True) if flag
            ]
            by_quantity[f"{group}.{component}"] = entry
        cases[name] = by_quantity
    return {"dt": dts, "cases": cases, "quantities": [f"{g}.{c}" for g, c in quantities]}


def draw_dt_sweep(stats_by_dt):
    """The Δt sweep figure: refraction (solid) and baseline (dashed) against Δt per case.

    Below the panels, one line per case lists the Δt at which refraction exceeds the
    baseline, for each quantity.

    Returns
    -------
    figure : matplotlib.figure.Figure
    data : dict
        ``{"panels": dt_sweep_data(...)}``.
    """
    data = dt_sweep_data(stats_by_dt)
    quantities = data["quantities"]
    names = list(data["cases"])
    count = max(len(quantities), 1)
    cols = min(count, 2)
    rows = -(-count // cols)
    characters = int(PANEL_SIZE[0] * cols * 72 / (0.55 * 7))
    lines = []
    for name in names:
        parts = []
        for quantity in quantities:
            dominated = data["cases"][name][quantity]["refraction_dominates_dt"]
            listed = ", ".join(f"{dt:.3g}" for dt in dominated) if dominated else "none"
            parts.append(f"{quantity}: {listed}")
        line = f"{name}: refraction above baseline at Δt = " + "; ".join(parts)
        lines += textwrap.wrap(line, characters, subsequent_indent="    ")
    text_height = 0.3 + 0.17 * len(lines)
    figure = Figure(
        figsize=(PANEL_SIZE[0] * cols + 2.0, PANEL_SIZE[1] * rows + text_height),
        dpi=120,
        layout="constrained",
    )
    grid = figure.add_gridspec(rows + 1, cols, height_ratios=[PANEL_SIZE[1]] * rows + [text_height])
    colors = _case_colors(len(names))
    for index, quantity in enumerate(quantities):
        ax = figure.add_subplot(grid[index // cols, index % cols])
        for name, color in zip(names, colors, strict=True):
            entry = data["cases"][name][quantity]
            for kind, marker in (("refraction", "o"), ("baseline", "s")):
                points = [
                    (dt, v, ci)
                    for dt, v, ci in zip(
                        data["dt"], entry[kind], entry[f"{kind}_ci95"], strict=True
                    )
                    if v is not None and v > 0
                ]
                if not points:
                    continue
                dts, values, intervals = zip(*points, strict=True)
                ax.plot(dts, values, "-" if kind == "refraction" else "--", color=color, lw=1)
                _errorbars(
                    ax,
                    dts,
                    values,
                    intervals,
                    True,
                    color=color,
                    marker=marker,
                    ms=4,
                    mfc=color if kind == "refraction" else "white",
                )
        ax.set_xscale("log")
        ax.set_yscale("log")
        _ticks_at(ax.xaxis, data["dt"])
        ax.set_xlabel("time step Δt (field time units)")
        ax.set_ylabel("rms(ε) / rms(truth)")
        ax.grid(True, which="major", alpha=0.3)
        group, component = quantity.split(".")
        description = dict((g, d) for g, _, d in KINEMATIC_BLOCKS)[group]
        _title(ax, chr(ord("a") + index), f"{description}, {component}")
    handles = [
        Line2D([], [], color=c, marker="o", label=n) for n, c in zip(names, colors, strict=True)
    ]
    handles += [
        Line2D([], [], color="k", marker="o", label="refraction (u' − u^ref)"),
        Line2D(
            [], [], color="k", marker="s", mfc="white", linestyle="--", label="baseline (u^ref − u)"
        ),
    ]
    figure.legend(handles=handles, loc="outside right upper", fontsize=7)
    text_ax = figure.add_subplot(grid[rows, :])
    text_ax.set_axis_off()
    text_ax.text(
        0.0,
        1.0,
        "\n".join(lines),
        va="top",
        ha="left",
        fontsize=7,
        transform=text_ax.transAxes,
    )
    _suptitle(
        figure,
        "Refraction against baseline with the time step (bars: bootstrap 95 % intervals)",
        fontsize=9,
    )
    _finish_axes(figure)
    return figure, {"panels": data}


def write_dt_sweep_figure(stats_by_dt, out_dir, overwrite=True, name="dt_sweep"):
    """Write the Δt sweep figure (``<name>.png``, ``.pdf``, ``.json``).

    Parameters
    ----------
    stats_by_dt : dict of float to dict
        The ``stats.json`` document of one study per Δt.
    out_dir : str or Path
        Created if missing.
    overwrite : bool
    name : str

    Returns
    -------
    data : dict
        :func:`dt_sweep_data` (with ``refraction_dominates_dt`` per case and quantity).
    """
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    figure, data = draw_dt_sweep(stats_by_dt)
    first = stats_by_dt[min(stats_by_dt)]
    record = {"config": {"dt_sweep": sorted(stats_by_dt)}, "versions": first["versions"]}
    save_figure(figure, name, data, record, out_dir, overwrite)
    return data["panels"]


def write_numerics_figure(numerics, out_dir, versions, overwrite=True, name="numerics"):
    """The paper's Appendix A figure: PDFs of ``|ε_x| / L`` at two steps and two grids.

    Parameters
    ----------
    numerics : dict
        :func:`rimcl.ptv.numerics.numerical_convergence`'s result.
    out_dir : str or Path
    versions : dict
        Software versions recorded with the figure.

    Returns
    -------
    list of Path
    """
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    runs = numerics["runs"]
    every = [v for run in runs.values() for v in run["errors_over_L"] + run["optics_errors_over_L"]]
    positive = [v for v in every if v > 0]
    figure, axes = _new_figure(1, 2)
    panels = {}
    if positive:
        edges = np.logspace(np.log10(min(positive)) - 0.1, np.log10(max(positive)) + 0.1, 21)
        for ax, (letter, pair, what) in zip(
            np.ravel(axes),
            (
                ("a", ("step h", "step h/2"), "integration step"),
                ("b", ("grid n", "grid n/2"), "grid resolution"),
            ),
            strict=True,
        ):
            series = []
            for run_name, color in zip(pair, ("k", "tab:orange"), strict=True):
                run = runs[run_name]
                grid = "×".join(str(n) for n in run["grid_n3_n2_n1"][::-1])
                label = f"{run_name} (Δ = {run['step']:.3g}, {grid})"
                for key, style, suffix in (
                    ("errors_over_L", "-", "centroids"),
                    ("optics_errors_over_L", "--", "optics"),
                ):
                    values = np.asarray(run[key])
                    # density per decade: the PDF of log10 |ε_x|/L, readable on a log axis
                    density, _ = np.histogram(
                        np.log10(values[values > 0]), bins=np.log10(edges), density=True
                    )
                    centres = np.sqrt(edges[1:] * edges[:-1])
                    ax.step(
                        centres,
                        density,
                        where="mid",
                        color=color,
                        linestyle=style,
                        label=f"{label}, {suffix}",
                    )
                    series.append({"run": run_name, "kind": suffix, "pdf": density.tolist()})
            ax.set_xscale("log")
            ax.xaxis.set_minor_formatter(NullFormatter())
            ax.set_xlabel("|ε_x| / L")
            ax.set_ylabel("PDF of log10(|ε_x| / L)")
            ax.set_title(f"({letter}) {numerics['case']}: {what}", loc="left", fontsize="medium")
            ax.set_ylim(0, 1.7 * ax.get_ylim()[1])
            ax.legend(fontsize="x-small", loc="upper left")
            panels[letter] = {"bin_edges": edges.tolist(), "series": series}
    figure.suptitle(
        "Appendix A: the position error at two integration steps and two grid resolutions"
        if positive
        else "Appendix A: no position errors to compare"
    )
    data = {"panels": panels, "ratios": {k: v for k, v in numerics.items() if "ratio" in k}}
    record = {"config": {"numerics": {"case": numerics["case"]}}, "versions": versions}
    return save_figure(figure, name, data, record, out_dir, overwrite)
