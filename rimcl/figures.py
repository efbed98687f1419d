"""Figures of a study (DESIGN §7): the paper's set, readable, with their numbers beside them.

Each figure is written as ``<name>.png`` and ``<name>.pdf`` (with the versions in the file
metadata) and ``<name>.json``: every number drawn, by panel and series, with the
configuration and versions. Figures are drawn with matplotlib's object API on the Agg
canvas (no pyplot state, no display needed).

Figures: ``ray_deflection`` (|Δθ| against |N|L), ``path_length`` (S/L against |θ0|),
``position_error`` (PDFs of |ε_x|/L and their peaks against G and Δn_max),
``velocity_error`` and ``acceleration_error`` (PDFs of the relative errors, systematic and
random errors against G, magnitude and angle errors), ``error_budget`` (refraction against
finite-difference errors), ``maps`` (u3 and a3: truth, air-like and water-like cases) and
``tracer_shape`` (PDFs of ΔA/A and of the circularity).
"""

from pathlib import Path

import numpy as np
from matplotlib import colormaps
from matplotlib.figure import Figure
from matplotlib.ticker import FixedLocator, FuncFormatter, NullLocator

from rimcl import __version__
from rimcl.provenance import atomic_path, to_json
from rimcl.tables import (
    angle_deg,
    area_changes,
    density_estimate,
    flagged_tracers,
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
    "maps",
    "tracer_shape",
)
#: Rays drawn per case in the deflection scatter plot (the case files hold the whole sample).
MAX_SCATTER_RAYS = 1000
#: Incidence angle (rad) separating the two marker groups of the deflection plot (the paper's).
OBLIQUE_THETA0 = 0.6
#: Bins per decade of the logarithmic parts of the relative-error histograms.
BINS_PER_DECADE = 6
PANEL_SIZE = (4.6, 3.6)


def _case_label(case):
    return f"{case['name']} (G = {case['G']:.3g})"


def _case_colors(count):
    return [colormaps["viridis"](value) for value in np.linspace(0.0, 0.9, max(count, 1))]


def _new_figure(rows, cols):
    figure = Figure(
        figsize=(PANEL_SIZE[0] * cols, PANEL_SIZE[1] * rows), dpi=120, layout="constrained"
    )
    axes = figure.subplots(rows, cols, squeeze=False)
    return figure, axes


def _kept_rows(tables, table):
    excluded_ids, _ = flagged_tracers(tables)
    keep = ~np.isin(table["id"].astype(np.int64), excluded_ids)
    return {name: values[keep] for name, values in table.items()}


def _panel_letter(ax, letter):
    ax.set_title(f"({letter})", loc="left", fontweight="bold")


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
    """Symmetric-log x axis with at most four labelled decades on each side of zero."""
    floor, top = edges[len(edges) // 2 + 1], edges[-1]
    ax.set_xscale("symlog", linthresh=floor, linscale=0.5)
    low, high = round(np.log10(floor)), round(np.log10(top))
    stride = max(1, int(np.ceil((high - low + 1) / 4)))
    exponents = list(range(high, low, -stride))
    ticks = [-(10.0**k) for k in exponents] + [0.0] + [10.0**k for k in reversed(exponents)]
    ax.xaxis.set_major_locator(FixedLocator(ticks))
    ax.xaxis.set_minor_locator(NullLocator())

    def label(value, _position):
        if value == 0:
            return "0"
        sign = "−" if value < 0 else ""
        return f"${sign}10^{{{round(np.log10(abs(value)))}}}$"

    ax.xaxis.set_major_formatter(FuncFormatter(label))


def _draw_pdf_series(ax, series, edges, colors, xlabel):
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
    ax.legend(fontsize=7)


def _error_against_g(ax, cases, block_of, keys, statistic, ylabel, title):
    """|statistic| of the relative errors against G, one line per quantity; returns data."""
    data = []
    markers = ("o", "s", "^")
    for key, marker in zip(keys, markers, strict=True):
        g_values, values, signs = [], [], []
        for case in cases:
            value = block_of(case)[key][statistic]
            if case["G"] > 0 and value is not None and value != 0:
                g_values.append(case["G"])
                values.append(abs(value))
                signs.append(int(np.sign(value)))
        name = "|" + key + "|" if key != "magnitude" else "magnitude"
        ax.plot(g_values, values, "-" + marker, label=name)
        for g, value, sign in zip(g_values, values, signs, strict=True):
            if sign < 0:
                ax.plot(g, value, marker, mfc="white", color="k", ms=4)
        data.append({"label": key, "G": g_values, "abs_value": values, "sign": signs})
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("G = Kρ (Gladstone–Dale product)")
    ax.set_ylabel(ylabel)
    ax.set_title(title, fontsize=9)
    ax.grid(True, which="major", alpha=0.3)
    ax.legend(
        fontsize=7,
        title="open black: mean < 0" if statistic == "systematic" else None,
        title_fontsize=7,
    )
    return data


def _ray_deflection(all_tables, cases):
    figure, axes = _new_figure(1, 1)
    ax = axes[0, 0]
    colors = _case_colors(len(cases))
    panel = {"x": "|N| L", "y": "|Δθ| (rad)", "series": []}
    lows, highs = [], []
    for tables, case, color in zip(all_tables, cases, colors, strict=True):
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
        near = theta0 <= OBLIQUE_THETA0
        ax.scatter(
            n_l[near],
            deflection[near],
            s=4,
            color=color,
            marker="o",
            alpha=0.5,
            label=_case_label(case) + f", |θ0| ≤ {OBLIQUE_THETA0}",
        )
        ax.scatter(
            n_l[~near],
            deflection[~near],
            s=6,
            color=color,
            marker="^",
            alpha=0.5,
            label=_case_label(case) + f", |θ0| > {OBLIQUE_THETA0}",
        )
        if n_l.size:
            lows.append(n_l.min())
            highs.append(n_l.max())
    if lows:
        line = np.array([min(lows), max(highs)])
        ax.plot(line, line, "k--", lw=1, label="|Δθ| = |N| L")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("|N| L (path-averaged transverse ∇n/n times slab depth L)")
    ax.set_ylabel("ray deflection |Δθ| (rad)")
    ax.set_title("Ray deflection (frame-0 ray sample, rays with status ok)", fontsize=9)
    ax.grid(True, which="major", alpha=0.3)
    ax.legend(fontsize=6, markerscale=2, ncol=2)
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
            t_edges,
            s_edges,
            np.where(counts.T > 0, counts.T, np.nan),
            cmap="viridis",
            shading="flat",
        )
        figure.colorbar(mesh, ax=ax, label="rays per bin")
        curve = np.linspace(0.0, t_edges[-1], 200)
        ax.plot(curve, 1.0 / np.cos(curve), "r--", lw=1.2, label="1 / cos|θ0|")
        ax.set_xlabel("incidence angle |θ0| (rad)")
        ax.set_ylabel("path length S / L")
        ax.set_title(_case_label(case), fontsize=9)
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
        errors = position_errors(_kept_rows(tables, tables.tracers), tables.length)
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
            ax_pdf.plot(
                [],
                [],
                color=color,
                label=f"{_case_label(case)}: |ε_x| = 0 exactly"
                if grid.size == 0
                else _case_label(case),
            )
            continue
        ax_pdf.plot(grid, density, color=color, label=_case_label(case))
        ax_pdf.plot(entry["peak_over_L"], density.max(), "o", color=color, mec="k")
    ax_pdf.set_xscale("log")
    ax_pdf.set_xlabel("position error |ε_x| / L")
    ax_pdf.set_ylabel("PDF of log10(|ε_x| / L)")
    ax_pdf.grid(True, which="major", alpha=0.3)
    ax_pdf.legend(fontsize=7)
    _panel_letter(ax_pdf, "a")

    positive = [c for c in cases if c["G"] > 0 and c["position_error_peak_over_L"] > 0]
    g_values = np.array([c["G"] for c in positive])
    peaks = np.array([c["position_error_peak_over_L"] for c in positive])
    ax_peak.plot(g_values, peaks, "ko-", label="PDF peak")
    for case in positive:
        ax_peak.annotate(
            case["name"],
            (case["G"], case["position_error_peak_over_L"]),
            textcoords="offset points",
            xytext=(4, -10),
            fontsize=7,
        )
    if peaks.size:
        guide = np.exp(np.mean(np.log(peaks / g_values))) * g_values
        ax_peak.plot(g_values, guide, "k:", lw=1, label="slope 1")
    ax_peak.set_xscale("log")
    ax_peak.set_yscale("log")
    ax_peak.set_xlabel("G = Kρ")
    ax_peak.set_ylabel("|ε_x| / L at the PDF peak")
    ratios = [c["delta_n_max"] / c["G"] for c in positive]
    if ratios:
        ratio = float(np.median(ratios))
        top = ax_peak.secondary_xaxis("top", functions=(lambda g: g * ratio, lambda d: d / ratio))
        top.set_xlabel("Δn_max")
    ax_peak.grid(True, which="major", alpha=0.3)
    ax_peak.legend(fontsize=7, loc="upper left")
    _panel_letter(ax_peak, "b")
    peak_data = {
        "G": g_values.tolist(),
        "peak_over_L": peaks.tolist(),
        "delta_n_max": [c["delta_n_max"] for c in positive],
    }
    return figure, {"panels": {"a": {"series": series}, "b": peak_data}}


def _kinematic_error(all_tables, cases, symbol, group, title):
    """Velocity (``u``) or acceleration (``a``) error figure, six panels as the paper's."""
    figure, axes = _new_figure(2, 3)
    colors = _case_colors(len(cases))
    tables_kept = [_kept_rows(tables, getattr(tables, group)) for tables in all_tables]
    panels = {}
    quantity = "velocity" if symbol == "u" else "acceleration"
    for ax, letter, component in (
        (axes[0, 0], "a", "3"),
        (axes[0, 1], "b", "2"),
        (axes[0, 2], "c", "magnitude"),
    ):
        samples = [_relative_errors(t, symbol, component, "meas", "ref") for t in tables_kept]
        series, edges = _pdf_series(samples, cases)
        if component == "magnitude":
            xlabel = f"ε_|{symbol}| / |{symbol}|  (relative error of |{symbol}|)"
        else:
            xlabel = f"ε_{symbol}{component} / {symbol}{component}  (relative error)"
        _draw_pdf_series(ax, series, edges, colors, xlabel)
        _panel_letter(ax, letter)
        panels[letter] = {"quantity": xlabel, "bin_edges": edges.tolist(), "series": series}
    keys = (f"{symbol}2", f"{symbol}3", "magnitude")
    panels["d"] = _error_against_g(
        axes[1, 0],
        cases,
        lambda c: c[quantity],
        keys,
        "systematic",
        "|systematic error| = |mean(ε/truth)|",
        "systematic relative error (fraction)",
    )
    _panel_letter(axes[1, 0], "d")
    panels["e"] = _error_against_g(
        axes[1, 1],
        cases,
        lambda c: c[quantity],
        keys,
        "random",
        "random error = std(ε/truth)",
        "random relative error (fraction)",
    )
    _panel_letter(axes[1, 1], "e")

    ax = axes[1, 2]
    angle_series = []
    for tables, case, color in zip(tables_kept, cases, colors, strict=True):
        angles = angle_deg(
            (tables[f"{symbol}2_meas"], tables[f"{symbol}3_meas"]),
            (tables[f"{symbol}2_ref"], tables[f"{symbol}3_ref"]),
        )
        grid, density = density_estimate(angles, log=True)
        # the kernel's tails would reach past the largest possible angle
        grid, density = grid[grid <= 180.0], density[grid <= 180.0]
        angle_series.append(
            {
                "label": _case_label(case),
                "angle_deg": grid.tolist(),
                "pdf_log10": density.tolist(),
                "n_zero": int(np.count_nonzero(angles == 0)),
            }
        )
        if grid.size < 2:
            ax.plot([], [], color=color, label=f"{_case_label(case)}: angle = 0 exactly")
            continue
        ax.plot(grid, density, color=color, label=_case_label(case))
    ax.set_xscale("log")
    ax.set_xlabel(f"angle between {symbol}' and {symbol}^ref (degrees)")
    ax.set_ylabel("PDF of log10(angle)")
    ax.grid(True, which="major", alpha=0.3)
    ax.legend(fontsize=7)
    _panel_letter(ax, "f")
    panels["f"] = {"series": angle_series}
    figure.suptitle(title)
    return figure, {"panels": panels}


def _error_budget(cases):
    figure, axes = _new_figure(1, 2)
    panels = {}
    for ax, quantity, symbol, letter in (
        (axes[0, 0], "velocity", "u", "a"),
        (axes[0, 1], "acceleration", "a", "b"),
    ):
        positive = [c for c in cases if c["G"] > 0]
        g_values = [c["G"] for c in positive]
        rows = {}
        for key, style in ((f"{symbol}3", "o"), ("magnitude", "s")):
            refraction = [c[quantity][key]["rms_normalized"] for c in positive]
            baseline = [c["baseline"][quantity][key]["rms_normalized"] for c in positive]
            ax.plot(g_values, refraction, "-" + style, label=f"refraction, {key}")
            ax.plot(
                g_values,
                baseline,
                "--" + style,
                mfc="white",
                label=f"finite differences + rendering, {key}",
            )
            rows[key] = {"refraction": refraction, "baseline": baseline}
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel("G = Kρ")
        ax.set_ylabel("rms(ε) / rms(truth)")
        ax.set_title(
            f"{quantity}: refraction ({symbol}' − {symbol}^ref) against "
            f"baseline ({symbol}^ref − {symbol})",
            fontsize=9,
        )
        ax.grid(True, which="major", alpha=0.3)
        ax.legend(fontsize=7)
        _panel_letter(ax, letter)
        panels[letter] = {"G": g_values, **rows}
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
    figure, axes = _new_figure(2, 3)
    panels = {}
    for row, (symbol, group, unit) in enumerate(
        (("u", "velocity", "velocity"), ("a", "acceleration", "acceleration"))
    ):
        truth_tables = _kept_rows(all_tables[air], getattr(all_tables[air], group))
        frame0 = all_tables[air].tracers
        first = frame0["frame"] == np.min(frame0["frame"])
        position = dict(
            zip(
                frame0["id"][first].tolist(),
                zip(frame0["x2_true"][first], frame0["x3_true"][first], strict=True),
                strict=True,
            )
        )
        columns = (
            ("truth", air, "true"),
            (_case_label(cases[air]), air, "meas"),
            (_case_label(cases[water]), water, "meas"),
        )
        truth = truth_tables[f"{symbol}3_true"]
        limit = float(np.percentile(np.abs(truth), 98)) if truth.size else 1.0
        for col, (label, index, kind) in enumerate(columns):
            ax = axes[row, col]
            table = _kept_rows(all_tables[index], getattr(all_tables[index], group))
            xy = np.array([position.get(int(i), (np.nan, np.nan)) for i in table["id"]])
            values = table[f"{symbol}3_{kind}"]
            if xy.size:
                mesh = ax.scatter(
                    xy[:, 0], xy[:, 1], c=values, s=12, cmap="RdBu_r", vmin=-limit, vmax=limit
                )
                figure.colorbar(
                    mesh, ax=ax, label=f"{symbol}3 ({unit}, field units)", extend="both"
                )
            ax.set_aspect("equal")
            ax.set_xlabel("x2 (field length units)")
            ax.set_ylabel("x3 (field length units)")
            title = "truth" if kind == "true" else f"measured, {label}"
            ax.set_title(f"{symbol}3: {title}", fontsize=9)
            panels[f"{symbol}3 {title}"] = {
                "id": table["id"].tolist(),
                "x2": xy[:, 0].tolist() if xy.size else [],
                "x3": xy[:, 1].tolist() if xy.size else [],
                "value": values.tolist(),
            }
    figure.suptitle("Tracer maps at the first frame (colour range: truth's 98th percentile)")
    return figure, {"panels": panels}


def _tracer_shape(all_tables, cases):
    figure, axes = _new_figure(1, 2)
    colors = _case_colors(len(cases))
    kept = [_kept_rows(tables, tables.tracers) for tables in all_tables]
    panels = {}
    for ax, letter, samples, peak_key, xlabel in (
        (
            axes[0, 0],
            "a",
            [area_changes(table) for table in kept],
            "area_change_peak",
            "tracer area change ΔA / A  (A: uniform-medium image)",
        ),
        (
            axes[0, 1],
            "b",
            [table["circularity_meas"] for table in kept],
            "circularity_peak",
            "circularity C = P² / (4π A')  (1: a disc)",
        ),
    ):
        pooled = np.concatenate(samples)
        pooled = pooled[np.isfinite(pooled)]
        low, high = (pooled.min(), pooled.max()) if pooled.size else (0.0, 1.0)
        if high == low:
            low, high = low - 0.5, high + 0.5
        edges = np.linspace(low, high, 61)
        series = []
        for sample, case, color in zip(samples, cases, colors, strict=True):
            finite = sample[np.isfinite(sample)]
            counts, _ = np.histogram(finite, bins=edges)
            density = counts / max(finite.size, 1) / np.diff(edges)
            peak = case[peak_key]
            label = f"{_case_label(case)}: peak {peak:.3g}"
            ax.stairs(np.where(density > 0, density, np.nan), edges, color=color, label=label)
            series.append({"label": _case_label(case), "pdf": density.tolist(), "peak": peak})
        ax.set_yscale("log")
        ax.set_xlabel(xlabel)
        ax.set_ylabel("PDF")
        ax.grid(True, which="major", alpha=0.3)
        ax.legend(fontsize=7)
        _panel_letter(ax, letter)
        panels[letter] = {"bin_edges": edges.tolist(), "series": series}
    figure.suptitle("Tracer image shape (peaks: mode of a kernel density estimate)")
    return figure, {"panels": panels}


def _velocity_error(all_tables, cases):
    title = "Velocity error from refraction, u' − u^ref"
    return _kinematic_error(all_tables, cases, "u", "velocity", title)


def _acceleration_error(all_tables, cases):
    title = "Acceleration error from refraction, a' − a^ref"
    return _kinematic_error(all_tables, cases, "a", "acceleration", title)


_BUILDERS = {
    "ray_deflection": _ray_deflection,
    "path_length": _path_length,
    "position_error": _position_error,
    "velocity_error": _velocity_error,
    "acceleration_error": _acceleration_error,
    "error_budget": lambda all_tables, cases: _error_budget(cases),
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
        if ax.get_label() == "<colorbar>":
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
    figure, data = _BUILDERS[name](all_tables, stats["cases"])
    _finish_axes(figure)
    return figure, data


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
    description = to_json({"versions": stats["versions"], "numbers": "see <name>.json"})
    for name in FIGURE_NAMES:
        figure, data = draw_figure(name, all_tables, stats)
        document = {
            "figure": name,
            **data,
            "config": stats["config"],
            "versions": stats["versions"],
        }
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
        for extension, metadata in targets.items():
            path = out_dir / f"{name}.{extension}"
            with atomic_path(path, overwrite=overwrite) as tmp:
                figure.savefig(tmp, format=extension, metadata=metadata)
            written.append(path)
        path = out_dir / f"{name}.json"
        write_json(path, document, overwrite=overwrite)
        written.append(path)
    return written
