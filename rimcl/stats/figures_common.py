"""What every study figure shares: panel layout, titles, case labels and colours, and files.

Panel helpers (:func:`new_figure`, :func:`panel_title`, :func:`figure_title`), the relative-error
PDFs of log-magnitudes (:func:`pdf_series`, :func:`draw_pdf_series`), statistics
against ``G`` with their bootstrap 95 % intervals (:func:`statistic_against_g`,
:func:`errorbars`), the last touches to log axes (:func:`finish_axes`) and
:func:`save_figure`, which writes a figure as PNG, PDF and the JSON of its numbers. Used by
the PTV figures here and by :mod:`rimcl.piv.figures`.
"""

import textwrap

import numpy as np
from matplotlib import colormaps
from matplotlib.figure import Figure
from matplotlib.ticker import FixedLocator, FuncFormatter, NullLocator

from rimcl import __version__
from rimcl.core.atomic import atomic_path
from rimcl.core.provenance import to_json
from rimcl.stats.tables import kept_rows, write_json

#: Bins per decade of the logarithmic parts of the relative-error histograms.
BINS_PER_DECADE = 6
PANEL_SIZE = (4.6, 3.6)

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


def case_label(case):
    symbol = "Δn_max" if case.get("abscissa") == "delta_n_max" else "G"
    return f"{case['name']} ({symbol} = {case['G']:.3g})"


def case_colors(count):
    return [colormaps["viridis"](value) for value in np.linspace(0.0, 0.9, max(count, 1))]


def new_figure(rows, cols, size=PANEL_SIZE):
    figure = Figure(figsize=(size[0] * cols, size[1] * rows), dpi=120, layout="constrained")
    axes = figure.subplots(rows, cols, squeeze=False)
    return figure, axes


def panel_title(ax, letter, text, fontsize=9):
    """Panel letter and title as one left-aligned title: the two can never overlap.

    Wrapped to the panel's width (constrained layout makes room above a panel, not
    beside it, so a title wider than its panel would run into its neighbour).
    """
    # the width before layout, less what labels and colour bars will take
    width_pt = 0.85 * ax.get_position().width * ax.figure.get_figwidth() * 72.0
    characters = max(20, int(width_pt / (0.55 * fontsize)))
    ax.set_title(textwrap.fill(f"({letter}) {text}", characters), loc="left", fontsize=fontsize)


def kinematic_rows(tables, group):
    """Kept rows of a kinematic group; empty columns where the file lacks the group."""
    table = getattr(tables, group)
    if table:
        return kept_rows(tables, table)
    symbol = "u" if group.startswith("velocity") else "a"
    names = ["id", *(f"{symbol}{c}_{k}" for c in "23" for k in ("true", "ref", "meas"))]
    return {name: np.zeros(0) for name in names}


def ticks_at(axis, values):
    """Label a log axis at the given values only: over less than a decade or two, its
    minor-tick labels would run into each other."""
    axis.set_major_locator(FixedLocator(sorted(values)))
    axis.set_major_formatter(FuncFormatter(lambda value, _: f"{value:.3g}"))
    axis.set_minor_locator(NullLocator())


def physical_axis(ax, which, factor, label):
    """A second axis in physical units (the plotted values times ``factor``), where the
    scene gives the scale; nothing without it (``factor`` None).

    Parameters
    ----------
    ax : matplotlib.axes.Axes
    which : {"x", "y"}
        ``x``: an axis on top; ``y``: one on the right.
    factor : float or None
        Physical units per plotted unit (e.g. µm per L).
    label : str

    Returns
    -------
    matplotlib.axes.Axes or None
        The second axis (None without ``factor``).
    """
    if factor is None:
        return None
    functions = (lambda value: value * factor, lambda value: value / factor)
    if which == "x":
        second = ax.secondary_xaxis("top", functions=functions)
        second.set_xlabel(label)
    else:
        second = ax.secondary_yaxis("right", functions=functions)
        second.set_ylabel(label)
    return second


def physical_unit(kind, length_m=None, time_s=None):
    """Physical units per field unit of a plotted quantity, and the unit's name.

    Parameters
    ----------
    kind : {"position", "time", "velocity", "acceleration"}
    length_m, time_s : float, optional
        Metres per field length unit and seconds per field time unit.

    Returns
    -------
    factor : float
        Millimetres, milliseconds, mm/s or m/s² per field unit; 1 where a scale it needs
        is unknown.
    unit : str
        ``mm``, ``ms``, ``mm/s``, ``m/s²``; or ``field length units``, ``field time units``,
        ``field units`` without the scales.
    """
    has_time = length_m is not None and time_s is not None
    if kind == "position":
        return (length_m * 1e3, "mm") if length_m is not None else (1.0, "field length units")
    if kind == "time":
        return (time_s * 1e3, "ms") if time_s is not None else (1.0, "field time units")
    if kind == "velocity":
        return (length_m / time_s * 1e3, "mm/s") if has_time else (1.0, "field units")
    if kind == "acceleration":
        return (length_m / time_s**2, "m/s²") if has_time else (1.0, "field units")
    raise ValueError(f"unknown kind {kind!r}")


def figure_title(figure, text, fontsize=9):
    """The figure's title, wrapped to its width (no explicit line breaks needed)."""
    characters = max(30, int(figure.get_figwidth() * 72.0 * 0.95 / (0.55 * fontsize)))
    lines = [textwrap.fill(line, characters) for line in text.split("\n")]
    figure.suptitle("\n".join(lines), fontsize=fontsize)


def relative_errors(table, symbol, component, measured, reference):
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


def pdf_series(samples_by_case, cases):
    """PDFs of the magnitude of relative errors on common log bins, one series per case.

    A log-magnitude PDF has no gap at zero and no lopsided axis: ``pdf`` is the probability
    density of ``log10 |ε / truth|`` over the non-zero errors (it integrates to 1 over
    ``log10`` of the bin edges); ``n_zero`` counts the exact zeros, which it leaves out.
    The sign is in the systematic error and the quartiles.

    Returns the series and the bin edges (magnitudes, increasing).
    """
    magnitudes = np.concatenate([np.abs(s[s != 0]) for s in samples_by_case] or [np.empty(0)])
    magnitudes = magnitudes[np.isfinite(magnitudes)]
    if magnitudes.size == 0:
        edges = np.array([0.1, 1.0])
    else:
        floor = 10.0 ** np.floor(np.log10(np.percentile(magnitudes, 0.5)))
        top = 10.0 ** np.ceil(np.log10(magnitudes.max()))
        decades = max(round(np.log10(top / floor)), 1)
        edges = floor * np.logspace(0.0, decades, decades * BINS_PER_DECADE + 1)
    series = []
    for case, sample in zip(cases, samples_by_case, strict=True):
        sample = sample[np.isfinite(sample)]
        nonzero = np.abs(sample[sample != 0])
        entry = {"label": case_label(case), "n": int(sample.size), "pdf": []}
        entry["n_zero"] = int(sample.size - nonzero.size)
        entry["exactly_zero"] = bool(sample.size and nonzero.size == 0)
        if nonzero.size:
            # the few below the lowest edge join its bin: every error is counted
            counts, _ = np.histogram(np.clip(nonzero, edges[0], edges[-1]), bins=edges)
            entry["pdf"] = (counts / nonzero.size / np.diff(np.log10(edges))).tolist()
        series.append(entry)
    return series, edges


def draw_pdf_series(ax, series, edges, colors, xlabel, legend=True):
    centres = np.sqrt(edges[:-1] * edges[1:])
    for entry, color in zip(series, colors, strict=True):
        if entry["exactly_zero"]:
            ax.plot([], [], color=color, label=f"{entry['label']}: ε = 0 exactly")
        elif entry["pdf"]:
            ax.plot(centres, entry["pdf"], "-", lw=1.2, color=color, label=entry["label"])
    ax.set_xscale("log")
    ax.set_ylim(bottom=0)
    ax.set_xlabel(xlabel)
    ax.set_ylabel("PDF of log10 |ε / truth|")
    ax.grid(True, which="major", alpha=0.3)
    if legend:
        ax.legend(fontsize=6)


def errorbars(ax, xs, values, intervals, absolute, **style):
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


def statistic_against_g(
    ax, cases, series_specs, statistic, absolute=False, dodge=0.06, legend=True, marks=None
):
    """Statistics against G with 95 % error bars, one line per series; returns the data.

    ``series_specs`` lists ``(label, getter, style)``; ``getter(case)`` gives the summary
    dict (with ``ci95``) or ``None``. Series are shifted a little along G (log axis) so
    their bars do not hide each other. Without ``legend`` the labelled handles are still
    made (a figure legend can collect them). ``marks``, one per series, lists functions
    ``mark(case)`` that say whether the case's value has not converged: such a point is
    drawn open and without its bar (an interval that does not cover), and listed in the
    data's ``not_converged``.
    """
    data, any_zero, any_marked = [], False, False
    offsets = (np.arange(len(series_specs)) - (len(series_specs) - 1) / 2) * dodge
    marks = marks or [None] * len(series_specs)
    for (label, getter, style), offset, mark in zip(series_specs, offsets, marks, strict=True):
        g_values, values, intervals, flagged = [], [], [], []
        for case in cases:
            summary = getter(case)
            value = None if summary is None else summary[statistic]
            if case["G"] > 0 and value is not None and (value != 0 or not absolute):
                g_values.append(case["G"])
                values.append(value)
                intervals.append(summary["ci95"][statistic])
                flagged.append(bool(mark is not None and mark(case)))
        shift = 10.0**offset
        xs = [g * shift for g in g_values]
        shown = [abs(v) if absolute else v for v in values]
        line = ax.plot(xs, shown, "-", lw=1, **{k: v for k, v in style.items() if k != "marker"})
        color = line[0].get_color()
        marker_style = {"color": color, "marker": style.get("marker", "o"), "ms": 4}
        kept = [i for i, f in enumerate(flagged) if not f]
        any_zero |= errorbars(
            ax,
            [xs[i] for i in kept],
            [values[i] for i in kept],
            [intervals[i] for i in kept],
            absolute,
            **marker_style,
        )
        if len(kept) < len(flagged):
            any_marked = True
            ax.plot(
                [x for x, f in zip(xs, flagged, strict=True) if f],
                [v for v, f in zip(shown, flagged, strict=True) if f],
                linestyle="none",
                mfc="white",
                **marker_style,
            )
        ax.plot([], [], "-" + style.get("marker", "o"), color=color, ms=4, label=label)
        data.append(
            {
                "label": label,
                "G": g_values,
                "value": values,
                "ci95": intervals,
                "not_converged": flagged,
            }
        )
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel(G_LABEL)
    ax.grid(True, which="major", alpha=0.3)
    if any_zero:
        ax.plot([], [], "v", mfc="white", color="k", ms=4, label="95 % interval holds 0")
    if any_marked:
        ax.plot([], [], "o", mfc="white", color="k", ms=4, label="not converged (no interval)")
    if legend:
        ax.legend(fontsize=6)
    return data


def dig(node, *path):
    """``node[path[0]][path[1]]...``, or ``None`` where a level is missing."""
    for key in path:
        if not isinstance(node, dict) or key not in node:
            return None
        node = node[key]
    return node


def finish_axes(figure):
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
