"""The ``error_budget`` figure: optics, imaging, total refraction, noise floor and baseline
errors against G, with the verdict of each case (:func:`rimcl.stats.document.budget_verdict`) below.
"""

from matplotlib.figure import Figure

from rimcl.stats.figures_common import (
    KINEMATIC_BLOCKS,
    PANEL_SIZE,
    dig,
    figure_title,
    panel_title,
    statistic_against_g,
)

#: Parts of the error budget: (label, where in a case, style).
BUDGET_PARTS = (
    ("optics", ("optics",), {"marker": "o", "color": "tab:blue"}),
    ("imaging", ("imaging",), {"marker": "s", "color": "tab:orange"}),
    ("total refraction", (), {"marker": "D", "color": "k"}),
    ("baseline (no refraction)", ("baseline",), {"marker": "^", "color": "tab:green"}),
    ("noise floor (two exposures)", ("noise_floor",), {"marker": "v", "color": "tab:gray"}),
)


def _summary_at(*path):
    """A getter of the summary at ``path`` in a case (``None`` where missing)."""
    return lambda case: dig(case, *path)


def _position_median_at(*prefix):
    """A getter of the median position error of a part, as a summary of key ``value``."""

    def getter(case):
        value = dig(case, *prefix, "position_error_median_over_L")
        if value is None:
            return None
        interval = dig(case, *prefix, "position_error_median_over_L_ci95")
        return {"value": value, "ci95": {"value": interval}}

    return getter


def draw_error_budget(cases):
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
    if not any("noise_floor" in case for case in cases):
        parts = parts[:-1]
    panels = {
        "a": statistic_against_g(
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
    panel_title(axes[0], "a", "position error")
    for index, group in enumerate(groups, start=1):
        key = f"{'u' if group.startswith('velocity') else 'a'}3"
        letter = chr(ord("a") + index)
        panels[letter] = statistic_against_g(
            axes[index],
            positive,
            [(label, _summary_at(*prefix, group, key), style) for label, prefix, style in parts],
            "rms_normalized",
            absolute=True,
            legend=False,
        )
        axes[index].set_ylabel(f"rms(ε_{key}) / rms({key})")
        panel_title(axes[index], letter, dict((g, d) for g, _, d in KINEMATIC_BLOCKS)[group])
    text_ax = figure.add_subplot(grid[rows, :])
    text_ax.set_axis_off()
    text_ax.text(
        0.0, 1.0, "\n".join(verdicts), va="top", ha="left", fontsize=7, transform=text_ax.transAxes
    )
    # one legend for every panel, beside the verdicts: the panels' data stay uncovered
    handles, labels = axes[1 if len(axes) > 1 else 0].get_legend_handles_labels()
    text_ax.legend(handles, labels, loc="upper right", fontsize=7, ncol=2)
    panels["verdicts"] = verdicts
    figure_title(
        figure,
        "Error budget: optics (mean of the traced ray image points), imaging (renderer, "
        "threshold, centroid: total minus optics, tracer by tracer),\ntheir total, the "
        "noise floor (two independent exposures) and the baseline (bars: bootstrap 95 % "
        "intervals). Imaging can lie above the total: "
        "where the image moves against its rays' mean (a threshold cutting a reshaped "
        "image), the two parts partly cancel in the total",
        fontsize=9,
    )
    return figure, {"panels": panels}
