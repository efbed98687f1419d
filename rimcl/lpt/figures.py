"""Figures of an LPT run, drawn from its statistics (``lpt_stats.json``).

- ``lpt_position_error``: rms refraction error of the 3-D position per component (px on
  the focus plane) against ``G`` (or ``ΔT``/``ΔS``), without and with the volume
  self-calibration, with bootstrap 95 % intervals;
- ``lpt_kinematic_error``: ``rms(ε)/rms(truth)`` of velocity and acceleration per
  component, without and with the self-calibration;
- ``lpt_disparity_pdf``: PDF of the tracers' disparity (largest over cameras, px) per
  case, through the field, with the self-calibration, and through the uniform fluid;
- ``lpt_lost_matches``: the fraction of matches lost at each tolerance against ``G``.

Each figure is written as PNG, PDF and the JSON of its numbers
(:func:`rimcl.stats.figures_common.save_figure`).
"""

import numpy as np

from rimcl.stats.figures_common import (
    case_colors,
    errorbars,
    finish_axes,
    new_figure,
    panel_title,
    save_figure,
)

COMPONENTS = ("x1", "x2", "x3")
FIGURE_NAMES = (
    "lpt_position_error",
    "lpt_kinematic_error",
    "lpt_disparity_pdf",
    "lpt_lost_matches",
)
_WITH = (
    ("refraction", "without self-calibration", "-"),
    ("refraction_self_calibrated", "self-calibrated", "--"),
)


def _abscissa(cases):
    """The cases' x values and the axis label (G, else ΔT/ΔS); None for a case without."""
    first = next(iter(cases.values()))["abscissa"]
    label = "G = Kρ (Gladstone–Dale product)" if first["name"] == "G" else first["name"]
    if first["unit"]:
        label += f" ({first['unit']})"
    return [case["abscissa"]["value"] for case in cases.values()], label


def _series(ax, xs, summaries, scale, statistic, **style):
    """One line with error bars of ``summary[statistic]`` (× ``scale``) at ``xs``."""
    points = [
        (x, s[statistic] * scale, None if s.get("ci95") is None else _interval(s, statistic, scale))
        for x, s in zip(xs, summaries, strict=True)
        if x is not None and x > 0 and s is not None and s.get(statistic) is not None
    ]
    if not points:
        return {"x": [], "value": [], "ci95": []}
    x, value, interval = (list(column) for column in zip(*points, strict=True))
    line = ax.plot(x, np.abs(value), lw=1, ls=style.pop("ls", "-"), **style)
    errorbars(ax, x, value, interval, True, color=line[0].get_color(), marker="o", ms=3)
    return {"x": x, "value": value, "ci95": interval}


def _interval(summary, statistic, scale):
    interval = summary["ci95"]
    if isinstance(interval, dict):
        interval = interval.get(statistic)
    return None if interval is None else [v * scale for v in interval]


def _legend(ax):
    """The legend, where something was drawn (a case that kept no tracer draws nothing)."""
    if ax.get_legend_handles_labels()[0]:
        ax.legend(fontsize=6)


def _log_axes(ax, label, ylabel):
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel(label)
    ax.set_ylabel(ylabel)
    ax.grid(True, which="major", alpha=0.3)


def draw_position_error(document):
    cases = document["cases"]
    xs, label = _abscissa(cases)
    figure, axes = new_figure(1, 1)
    ax = axes[0, 0]
    data = []
    colors = case_colors(3)
    for axis, color in zip(COMPONENTS, colors, strict=True):
        for key, name, style in _WITH:
            summaries = [c["position"][axis][key] for c in cases.values()]
            scales = [1.0 / c["pixel_size"] for c in cases.values()]
            scaled = [
                None
                if s is None or s["rms"] is None
                else {
                    **s,
                    "rms": s["rms"] * f,
                    "ci95": None if s["ci95"] is None else [v * f for v in s["ci95"]],
                }
                for s, f in zip(summaries, scales, strict=True)
            ]
            entry = _series(
                ax, xs, scaled, 1.0, "rms", color=color, ls=style, label=f"{axis}, {name}"
            )
            data.append({"component": axis, "series": name, **entry})
    _log_axes(ax, label, "rms position error, meas − ref (px)")
    _legend(ax)
    panel_title(ax, "a", "3-D position: refraction error per component")
    return figure, {"unit": "px on the focus plane", "series": data}


def draw_kinematic_error(document):
    cases = document["cases"]
    xs, label = _abscissa(cases)
    figure, axes = new_figure(1, 2)
    data = {}
    colors = case_colors(3)
    for ax, letter, quantity in zip(axes[0], "ab", ("velocity", "acceleration"), strict=True):
        data[quantity] = []
        for axis, color in zip(COMPONENTS, colors, strict=True):
            for key, name, style in _WITH:
                summaries = [c[quantity][axis][key] for c in cases.values()]
                entry = _series(
                    ax,
                    xs,
                    summaries,
                    1.0,
                    "rms_normalized",
                    color=color,
                    ls=style,
                    label=f"{axis}, {name}",
                )
                data[quantity].append({"component": axis, "series": name, **entry})
        _log_axes(ax, label, "rms(ε) / rms(truth)")
        _legend(ax)
        panel_title(ax, letter, f"{quantity}: refraction error per component")
    return figure, data


def draw_disparity_pdf(document):
    cases = document["cases"]
    figure, axes = new_figure(1, 1)
    ax = axes[0, 0]
    colors = case_colors(len(cases))
    data = []
    for (name, case), color in zip(cases.items(), colors, strict=True):
        for kind, label, style in (
            ("meas", "field", "-"),
            ("vsc", "self-calibrated", "--"),
            ("ref", "uniform fluid", ":"),
        ):
            block = case["disparity"].get(kind)
            if block is None:
                continue
            histogram = block["histogram"]
            edges = np.asarray(histogram["edges_px"])
            centres = np.sqrt(edges[:-1] * edges[1:])
            pdf = np.asarray(histogram["pdf_per_px"])
            ax.plot(
                centres,
                np.where(pdf > 0, pdf, np.nan),
                ls=style,
                color=color,
                label=f"{name}, {label}",
            )
            data.append({"case": name, "series": label, **histogram})
    for tolerance in document["scene"]["lpt"]["match_tolerances_px"]:
        ax.axvline(tolerance, color="0.6", lw=0.8)
    _log_axes(ax, "disparity: largest over cameras (px)", "PDF (1/px)")
    _legend(ax)
    panel_title(ax, "a", "disparity of the tracers (grey: match tolerances)")
    return figure, {"series": data}


def draw_lost_matches(document):
    cases = document["cases"]
    xs, label = _abscissa(cases)
    tolerances = document["scene"]["lpt"]["match_tolerances_px"]
    figure, axes = new_figure(1, 1)
    ax = axes[0, 0]
    colors = case_colors(len(tolerances))
    data = []
    for tolerance, color in zip(tolerances, colors, strict=True):
        for kind, name, style in (
            ("meas", "without self-calibration", "-"),
            ("vsc", "self-calibrated", "--"),
        ):
            key = f"{tolerance:g}px"
            values = [
                c["disparity"][kind]["lost_fraction"][key] if kind in c["disparity"] else None
                for c in cases.values()
            ]
            shown = [(x, v) for x, v in zip(xs, values, strict=True) if x and v is not None]
            if shown:
                x, v = zip(*shown, strict=True)
                ax.plot(x, v, "o", ls=style, color=color, ms=3, label=f"> {tolerance:g} px, {name}")
            data.append(
                {"tolerance_px": tolerance, "series": name, "x": xs, "lost_fraction": values}
            )
    ax.set_xscale("log")
    ax.set_ylim(-0.02, 1.02)
    ax.set_xlabel(label)
    ax.set_ylabel("fraction of matches lost")
    ax.grid(True, which="major", alpha=0.3)
    _legend(ax)
    panel_title(ax, "a", "matches lost: disparity above the tolerance")
    return figure, {"series": data}


DRAWERS = dict(
    zip(
        FIGURE_NAMES,
        (draw_position_error, draw_kinematic_error, draw_disparity_pdf, draw_lost_matches),
        strict=True,
    )
)


def write_lpt_figures(document, out_dir, overwrite=True):
    """Draw every LPT figure of a run's statistics into ``out_dir``; returns the paths."""
    out_dir.mkdir(parents=True, exist_ok=True)
    stats = {"versions": document["versions"], "config": {"scene": document["scene"]}}
    written = []
    for name, draw in DRAWERS.items():
        figure, data = draw(document)
        finish_axes(figure)
        written += save_figure(figure, name, data, stats, out_dir, overwrite)
    return written
