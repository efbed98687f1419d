"""Figures of the measurement errors: ``position_error`` (PDFs of |ε_x| / L, their peak and
median against G), ``velocity_error`` and ``acceleration_error`` (PDFs of the relative errors,
the direction error, the paper's and the robust statistics against G) and ``maps`` (u3 and a3:
truth, uniform medium, an air-like and a water-like case).
"""

import numpy as np
from matplotlib.lines import Line2D

from rimcl.stats.figures_common import (
    case_colors,
    case_label,
    draw_pdf_series,
    figure_title,
    kinematic_rows,
    new_figure,
    panel_title,
    pdf_series,
    physical_axis,
    physical_unit,
    relative_errors,
    statistic_against_g,
)
from rimcl.stats.tables import (
    angle_deg,
    density_estimate,
    first_frame_rows,
    kept_rows,
    position_errors,
)


def draw_position_error(all_tables, cases):
    figure, axes = new_figure(1, 2)
    ax_pdf, ax_peak = axes[0]
    colors = case_colors(len(cases))
    series = []
    for tables, case, color in zip(all_tables, cases, colors, strict=True):
        errors = position_errors(kept_rows(tables, tables.tracers), tables.length)
        grid, density = density_estimate(errors, log=True)
        zeros = int(np.count_nonzero(errors == 0))
        # a log axis has no place for |ε_x| = 0 (an image that did not move): the curve is
        # the density of the others times their share, and the label counts the zeros
        share = 1.0 - zeros / errors.size if errors.size else 1.0
        density = density * share
        entry = {
            "label": case_label(case),
            "x_over_L": grid.tolist(),
            "pdf_log10": density.tolist(),
            "nonzero_share": share,
            "peak_over_L": case["position_error_peak_over_L"],
            "n_zero": zeros,
            "n": int(errors.size),
        }
        series.append(entry)
        if grid.size < 2:
            note = {0: ": no tracer used", 1: ""}.get(grid.size, "")
            if grid.size == 0 and errors.size:
                note = ": |ε_x| = 0 exactly"
            ax_pdf.plot([], [], color=color, label=case_label(case) + note)
            continue
        zero_note = f" ({zeros} of {errors.size} exactly 0, off the axis)" if zeros else ""
        ax_pdf.plot(grid, density, color=color, label=case_label(case) + zero_note)
        # every competing mode (one where the PDF has a single peak)
        modes = case.get("position_error_modes_over_L") or [entry["peak_over_L"]]
        entry["modes_over_L"] = modes
        for mode in modes:
            height = np.interp(np.log10(mode), np.log10(grid), density)
            ax_pdf.plot(mode, height, "o", color=color, mec="k")
    ax_pdf.set_xscale("log")
    ax_pdf.set_xlabel("position error |ε_x| / L")
    ax_pdf.set_ylabel("PDF of log10(|ε_x| / L) (× share of |ε_x| > 0)")
    ax_pdf.grid(True, which="major", alpha=0.3)
    ax_pdf.legend(fontsize=6, title="dots: PDF peaks (two: two modes)", title_fontsize=6)
    # µm per L where the scene gives the field's size (field.length_m); every case one field
    first = all_tables[0] if all_tables else None
    um_per_l = (
        first.length * first.length_m * 1e6
        if first is not None and first.length_m is not None
        else None
    )
    physical_axis(ax_pdf, "x", um_per_l, "|ε_x| (µm)")
    panel_title(ax_pdf, "a", "PDF of the position error, per case")

    def position(key):
        # no one peak where two modes compete: its value and interval jump between them
        ambiguous = key == "position_error_peak_over_L"
        return lambda case: (
            None
            if case[key] is None or (ambiguous and case.get("position_error_peak_ambiguous"))
            else {"value": case[key], "ci95": {"value": case[f"{key}_ci95"]}}
        )

    positive = [c for c in cases if c["G"] > 0]
    two_modes = [c["name"] for c in positive if c.get("position_error_peak_ambiguous")]
    peak_label = "PDF peak of |ε_x| / L" + (
        f" (none: two modes at {', '.join(two_modes)})" if two_modes else ""
    )
    data = statistic_against_g(
        ax_peak,
        positive,
        [
            (
                peak_label,
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
    physical_axis(ax_peak, "y", um_per_l, "|ε_x| (µm)")
    panel_title(ax_peak, "b", "peak and median against G")
    return figure, {"panels": {"a": {"series": series}, "b": data}}


def _kinematic_error(all_tables, cases, group, title):
    """Velocity (``u``) or acceleration (``a``) error figure: the paper's six panels and two."""
    symbol = "u" if group.startswith("velocity") else "a"
    figure, axes = new_figure(2, 4)
    colors = case_colors(len(cases))
    tables_kept = [kinematic_rows(tables, group) for tables in all_tables]
    panels = {}
    for ax, letter, component in (
        (axes[0, 0], "a", "3"),
        (axes[0, 1], "b", "2"),
        (axes[0, 2], "c", "magnitude"),
    ):
        samples = [relative_errors(t, symbol, component, "meas", "ref") for t in tables_kept]
        series, edges = pdf_series(samples, cases)
        if component == "magnitude":
            xlabel = f"ε_|{symbol}| / |{symbol}| (relative error of the magnitude)"
            text = f"PDF of ε_|{symbol}| / |{symbol}|"
        else:
            xlabel = f"ε_{symbol}{component} / {symbol}{component} (relative error)"
            text = f"PDF of ε_{symbol}{component} / {symbol}{component}"
        draw_pdf_series(ax, series, edges, colors, xlabel, legend=False)
        panel_title(ax, letter, text)
        panels[letter] = {"quantity": xlabel, "bin_edges": edges.tolist(), "series": series}

    ax = axes[0, 3]
    angle_series = []
    for tables, case, color in zip(tables_kept, cases, colors, strict=True):
        measured = (tables[f"{symbol}2_meas"], tables[f"{symbol}3_meas"])
        entry = {"label": case_label(case)}
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
    panel_title(
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

    def marks(statistic):
        """Per component: whether a case's statistic has not converged (drawn open, no bar)."""
        return [_not_converged(f"{group}.{key}.{statistic}") for key, _ in components]

    panels["e"] = statistic_against_g(
        axes[1, 0],
        cases,
        [(f"{name(k)}: |mean(ε/{name(k)})|", summary_of(k), {"marker": m}) for k, m in components],
        "systematic",
        absolute=True,
        marks=marks("systematic"),
    )
    axes[1, 0].set_ylabel("|systematic error| = |mean(ε/truth)|")
    panel_title(axes[1, 0], "e", "the paper's systematic error (open: not converged)")
    panels["f"] = statistic_against_g(
        axes[1, 1],
        cases,
        [(f"{name(k)}: std(ε/{name(k)})", summary_of(k), {"marker": m}) for k, m in components],
        "random",
        absolute=True,
        marks=marks("random"),
    )
    axes[1, 1].set_ylabel("random error = std(ε/truth)")
    panel_title(axes[1, 1], "f", "the paper's random error (open: not converged)")
    panels["g"] = statistic_against_g(
        axes[1, 2],
        cases,
        [
            (f"{name(k)}: rms(ε)/rms({name(k)})", summary_of(k), {"marker": m})
            for k, m in components
        ],
        "rms_normalized",
        absolute=True,
        marks=marks("rms_normalized"),
    )
    axes[1, 2].set_ylabel("rms(ε) / rms(truth)")
    panel_title(axes[1, 2], "g", "rms(ε) / rms(truth) (open: a tail carries it)")
    key = f"{symbol}3"
    panels["h"] = statistic_against_g(
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
    panel_title(axes[1, 3], "h", f"robust: quartiles of ε_{key}/{key}")
    # the cases of panels (a)-(d) in one legend beside them, off the data
    exactly_zero = {entry["label"] for entry in panels["a"]["series"] if entry["exactly_zero"]}
    handles = [
        Line2D(
            [],
            [],
            color=color,
            label=case_label(case)
            + (": ε = 0 exactly" if case_label(case) in exactly_zero else ""),
        )
        for case, color in zip(cases, colors, strict=True)
    ]
    figure.legend(handles=handles, loc="outside right upper", fontsize=7, title="(a)–(d)")
    figure_title(
        figure,
        title + " (bars: bootstrap 95 % intervals; open markers without bars: not converged)",
        fontsize=11,
    )
    return figure, {"panels": panels}


def _not_converged(path):
    """``mark(case)``: whether ``path`` is among the case's not-converged statistics."""
    return lambda case: path in case.get("convergence", {}).get("not_converged", [])


def _with_statistic(getter, statistic):
    """A getter whose ``iqr`` is another statistic of the summary (to share a panel)."""

    def renamed(case):
        summary = getter(case)
        if summary is None:
            return None
        return {"iqr": summary[statistic], "ci95": {"iqr": summary["ci95"][statistic]}}

    return renamed


def _air_and_water(cases):
    """Indices of the cases shown as 'air' and 'water': C1 and C4, else the extreme G > 0."""
    names = [c["name"] for c in cases]
    positive = [i for i, c in enumerate(cases) if c["G"] > 0] or list(range(len(cases)))
    air = names.index("C1") if "C1" in names else positive[0]
    water = names.index("C4") if "C4" in names else positive[-1]
    return air, water


def draw_maps(all_tables, cases):
    air, water = _air_and_water(cases)
    figure, axes = new_figure(2, 4, size=(4.2, 3.6))
    panels = {}
    # the paper's three-point differences, as the summary's table of its statistics
    acceleration = "acceleration"
    tracers = all_tables[air].tracers
    frame0 = int(np.min(tracers["frame"])) if tracers["frame"].size else 0
    # each value drawn where its tracer is at the value's own frame (a three-point
    # acceleration belongs to the middle frame, a fit to the window's centre)
    position = dict(
        zip(
            zip(tracers["id"].tolist(), tracers["frame"].tolist(), strict=True),
            zip(tracers["x2_true"], tracers["x3_true"], strict=True),
            strict=True,
        )
    )
    letters = iter("abcdefgh")
    # mm and mm/s, m/s² where the render files record the field's scales; else field units
    scales = (all_tables[air].length_m, all_tables[air].time_s)
    mm, length_unit = physical_unit("position", *scales)
    for row, (symbol, group) in enumerate((("u", "velocity"), ("a", acceleration))):
        factor, unit = physical_unit("velocity" if symbol == "u" else "acceleration", *scales)
        truth = first_frame_rows(kinematic_rows(all_tables[air], group))
        truth = factor * truth.get(f"{symbol}3_true", np.zeros(0))
        limit = float(np.percentile(np.abs(truth), 98)) if truth.size else 1.0
        columns = (
            ("truth", air, "true"),
            ("uniform medium (no refraction)", air, "ref"),
            (f"measured, {case_label(cases[air])}", air, "meas"),
            (f"measured, {case_label(cases[water])}", water, "meas"),
        )
        for col, (label, index, kind) in enumerate(columns):
            ax = axes[row, col]
            table = first_frame_rows(kinematic_rows(all_tables[index], group))
            values = factor * table.get(f"{symbol}3_{kind}", np.zeros(0))
            ids = table.get("id", np.zeros(0))
            frames = table.get("frame", np.full(len(ids), frame0))
            xy = mm * np.array(
                [
                    position.get((int(i), int(f)), (np.nan, np.nan))
                    for i, f in zip(ids, frames, strict=True)
                ]
            )
            if xy.size:
                mesh = ax.scatter(
                    xy[:, 0], xy[:, 1], c=values, s=9, cmap="RdBu_r", vmin=-limit, vmax=limit
                )
                figure.colorbar(mesh, ax=ax, label=f"{symbol}3 ({unit})", extend="both")
            ax.set_aspect("equal")
            ax.set_xlabel(f"x2 ({length_unit})")
            ax.set_ylabel(f"x3 ({length_unit})")
            method = " (fit)" if group.endswith("_fit") else ""
            panel_title(ax, next(letters), f"{symbol}3{method}: {label}", fontsize=8)
            panels[f"{symbol}3 {label}"] = {
                "units": {"x2": length_unit, "x3": length_unit, "value": unit},
                "id": table.get("id", np.zeros(0)).tolist(),
                "x2": xy[:, 0].tolist() if xy.size else [],
                "x3": xy[:, 1].tolist() if xy.size else [],
                "value": values.tolist(),
            }
    figure_title(
        figure,
        "Velocity u3 (forward differences, first frame) and acceleration a3 (three-point "
        "differences, second frame), each at its tracers' positions of that frame "
        "(colour range: the truth's 98th percentile; uniform medium: the measurement "
        "noise without refraction)",
        fontsize=9,
    )
    return figure, {"panels": panels}


def draw_velocity_error(all_tables, cases):
    return _kinematic_error(
        all_tables,
        cases,
        "velocity",
        "Velocity error from refraction, ε_u = u' − u^ref (forward differences, the paper's "
        "and the summary's table's)",
    )


def draw_acceleration_error(all_tables, cases):
    # the estimator of the summary's table of the paper's statistics, which (e)-(f) draw
    title = (
        "Acceleration error from refraction, ε_a = a' − a^ref (three-point differences, "
        "the paper's and the summary's table's)"
    )
    return _kinematic_error(all_tables, cases, "acceleration", title)
