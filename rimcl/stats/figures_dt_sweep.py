"""The Δt sweep figure: refraction and baseline errors of several studies against the time
step, with the Δt at which refraction dominates listed per case.
"""

import textwrap
from pathlib import Path

from matplotlib.figure import Figure
from matplotlib.lines import Line2D

from rimcl.stats.figures_common import (
    KINEMATIC_BLOCKS,
    PANEL_SIZE,
    case_colors,
    dig,
    errorbars,
    figure_title,
    finish_axes,
    panel_title,
    physical_axis,
    physical_unit,
    save_figure,
    ticks_at,
)

#: Quantities of the Δt sweep: (stats key, component).
DT_SWEEP_QUANTITIES = (
    ("velocity", "u3"),
    ("acceleration", "a3"),
    ("velocity_fit", "u3"),
    ("acceleration_fit", "a3"),
)


def dt_sweep_data(stats_by_dt):
    """Refraction, baseline and noise-floor ``rms(ε)/rms(truth)`` of each case against Δt.

    Parameters
    ----------
    stats_by_dt : dict of float to dict
        The ``stats.json`` document of one study per time step Δt (field time units).

    Returns
    -------
    dict
        ``dt`` (sorted), and per case name and quantity (``velocity``, ``acceleration``,
        and the ``_fit`` ones, each where two studies have it at least) the lists ``refraction``,
        ``refraction_ci95``, ``baseline``, ``baseline_ci95``, ``floor``, ``floor_ci95``
        (the noise floor; one entry per Δt, ``None`` where missing), ``dominates``
        (refraction above baseline at that Δt, ``None`` where unknown), ``wholly_above``
        (the refraction interval wholly above the baseline's), ``refraction_dominates_dt``
        (the Δt values where it dominates), ``above_floor`` and ``refraction_above_floor_dt``
        (refraction above the noise floor, the same way).
    """
    dts = sorted(stats_by_dt)
    documents = [stats_by_dt[dt] for dt in dts]
    names = []
    for document in documents:
        names += [case["name"] for case in document["cases"] if case["name"] not in names]
    # a quantity some Δt lacks (an acceleration needs 2m + 1 frames) is drawn where there
    # are two Δt values of it at least
    quantities = [
        (group, component)
        for group, component in DT_SWEEP_QUANTITIES
        if sum(any(group in case for case in doc["cases"]) for doc in documents) >= 2
    ]
    cases = {}
    for name in names:
        by_quantity = {}
        for group, component in quantities:
            entry = {
                f"{kind}{suffix}": []
                for kind in ("refraction", "baseline", "floor")
                for suffix in ("", "_ci95")
            }
            for document in documents:
                case = next((c for c in document["cases"] if c["name"] == name), {})
                for kind, summary in (
                    ("refraction", dig(case, group, component)),
                    ("baseline", dig(case, "baseline", group, component)),
                    ("floor", dig(case, "noise_floor", group, component)),
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
            # the camera's own noise: refraction above it is measured, below it is not
            entry["above_floor"] = [
                None if r is None or f is None else r > f
                for r, f in zip(entry["refraction"], entry["floor"], strict=True)
            ]
            entry["refraction_above_floor_dt"] = [
                dt for dt, flag in zip(dts, entry["above_floor"], strict=True) if flag
            ]
            by_quantity[f"{group}.{component}"] = entry
        cases[name] = by_quantity
    return {"dt": dts, "cases": cases, "quantities": [f"{g}.{c}" for g, c in quantities]}


def _time_scale(stats_by_dt):
    """Seconds per field time unit the studies record (``units.scales.time_s``), or None."""
    for document in stats_by_dt.values():
        for case in document.get("cases", []):
            time_s = dig(case, "units", "scales", "time_s")
            if time_s is not None:
                return time_s
    return None


def draw_dt_sweep(stats_by_dt):
    """The Δt sweep figure: refraction (solid), baseline (dashed) and noise floor (dotted)
    against Δt per case.

    Below the panels, one line per case lists the Δt at which refraction exceeds the
    baseline, for each quantity. Where the studies record the field's time scale, Δt is
    given in milliseconds too (a second axis on top, and in the lines).

    Returns
    -------
    figure : matplotlib.figure.Figure
    data : dict
        ``{"panels": dt_sweep_data(...)}``, with ``ms_per_time_unit`` (None without the
        scale).
    """
    data = dt_sweep_data(stats_by_dt)
    quantities = data["quantities"]
    names = list(data["cases"])
    # milliseconds where the studies record the field's time scale (every study one field)
    time_s = _time_scale(stats_by_dt)
    ms = None if time_s is None else physical_unit("time", time_s=time_s)[0]
    data["ms_per_time_unit"] = ms

    def shown(dt):
        return f"{dt:.3g}" if ms is None else f"{dt:.3g} ({dt * ms:.3g} ms)"

    count = max(len(quantities), 1)
    cols = min(count, 2)
    rows = -(-count // cols)
    characters = int(PANEL_SIZE[0] * cols * 72 / (0.55 * 7))
    lines = []
    for name in names:
        for key, words in (
            ("refraction_dominates_dt", "above the baseline"),
            ("refraction_above_floor_dt", "above the noise floor"),
        ):
            parts = []
            for quantity in quantities:
                where = data["cases"][name][quantity][key]
                parts.append(f"{quantity}: " + (", ".join(shown(dt) for dt in where) or "none"))
            line = f"{name}: refraction {words} at Δt = " + "; ".join(parts)
            lines += textwrap.wrap(line, characters, subsequent_indent="    ")
    text_height = 0.3 + 0.17 * len(lines)
    figure = Figure(
        figsize=(PANEL_SIZE[0] * cols + 2.0, PANEL_SIZE[1] * rows + text_height),
        dpi=120,
        layout="constrained",
    )
    grid = figure.add_gridspec(rows + 1, cols, height_ratios=[PANEL_SIZE[1]] * rows + [text_height])
    colors = case_colors(len(names))
    for index, quantity in enumerate(quantities):
        ax = figure.add_subplot(grid[index // cols, index % cols])
        for name, color in zip(names, colors, strict=True):
            entry = data["cases"][name][quantity]
            styles = {"refraction": ("o", "-"), "baseline": ("s", "--"), "floor": ("^", ":")}
            for kind, (marker, line) in styles.items():
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
                ax.plot(dts, values, line, color=color, lw=1)
                errorbars(
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
        ticks_at(ax.xaxis, data["dt"])
        ax.set_xlabel("time step Δt (field time units)")
        ax.set_ylabel("rms(ε) / rms(truth)")
        top = physical_axis(ax, "x", ms, "Δt (ms)")
        if top is not None:  # ticks at the studies' Δt, as below
            ticks_at(top.xaxis, [dt * ms for dt in data["dt"]])
        ax.grid(True, which="major", alpha=0.3)
        group, component = quantity.split(".")
        description = dict((g, d) for g, _, d in KINEMATIC_BLOCKS)[group]
        panel_title(ax, chr(ord("a") + index), f"{description}, {component}")
    handles = [
        Line2D([], [], color=c, marker="o", label=n) for n, c in zip(names, colors, strict=True)
    ]
    handles += [
        Line2D([], [], color="k", marker="o", label="refraction (u' − u^ref)"),
        Line2D(
            [], [], color="k", marker="s", mfc="white", linestyle="--", label="baseline (u^ref − u)"
        ),
        Line2D(
            [],
            [],
            color="k",
            marker="^",
            mfc="white",
            linestyle=":",
            label="noise floor (two exposures)",
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
    figure_title(
        figure,
        "Refraction against baseline and noise floor with the time step "
        "(bars: bootstrap 95 % intervals)",
        fontsize=9,
    )
    finish_axes(figure)
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
