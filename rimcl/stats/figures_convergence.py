"""The ``convergence`` figure: headline statistics against the number of tracers (nested
subsamples), those that keep growing marked (:mod:`rimcl.stats.convergence`).
"""

import numpy as np
from matplotlib.lines import Line2D

from rimcl.stats.figures_common import (
    KINEMATIC_BLOCKS,
    case_colors,
    case_label,
    dig,
    errorbars,
    figure_title,
    new_figure,
    panel_title,
    ticks_at,
)

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


def draw_convergence(cases):
    groups = [g for g, *_ in KINEMATIC_BLOCKS if any(g in c.get("convergence", {}) for c in cases)]
    rows = max(len(groups), 1)
    figure, axes = new_figure(rows, len(CONVERGENCE_COLUMNS))
    colors = case_colors(len(cases))
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
                entry = dig(convergence, group, component, statistic)
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
                errorbars(
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
                        "label": case_label(case),
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
            ticks_at(ax.xaxis, widest)
            ax.set_xlabel("tracers used (nested subsamples)")
            ax.set_ylabel(f"{ylabel}, {component}")
            ax.grid(True, which="major", alpha=0.3)
            letter = next(letters)
            note = f"; not converged: {', '.join(growing)}" if growing else ""
            panel_title(ax, letter, f"{text}; {description}{note}", fontsize=8)
            panels[letter] = {"group": group, "statistic": statistic, "series": series}
    if not groups:
        for ax in axes.flat:
            ax.set_axis_off()
    handles = [
        Line2D([], [], marker="o", color=color, label=case_label(case))
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
    figure_title(
        figure,
        "Convergence with the number of tracers (|value|; bars: bootstrap 95 % intervals)",
        fontsize=9,
    )
    return figure, {"panels": panels}
