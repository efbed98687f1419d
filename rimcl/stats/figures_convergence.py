"""The ``convergence`` figure: headline statistics against the number of tracers (nested
subsamples), one compact panel per quantity, those not converged marked
(:mod:`rimcl.stats.convergence`).
"""

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

#: Statistics of the convergence figure: (key in ``convergence``, name, line style).
CONVERGENCE_STATISTICS = (
    ("rms_normalized", "rms(ε)/rms(truth)", "-"),
    ("random", "the paper's random error std(ε/truth)", "--"),
)


def _title_note(series):
    """What a panel's title says of its marked series: the cases whose value jumps with N
    (the curve is not flat), apart from those a few rows or tracers carry (the curve may
    be flat: the mark is about the sample's tail, not the curve)."""
    names = {"rms_normalized": "rms", "random": "std"}
    parts = []
    for label, wanted in (
        ("jumps with N", {"jump"}),
        ("a tail carries", {"few rows", "few tracers", "heavy tail"}),
    ):
        marked = {name: [] for name in names.values()}
        for entry in series:
            if wanted & set(entry["reasons"]):
                marked[names[entry["statistic"]]].append(entry["case"])
        found = [f"{name} {', '.join(cases)}" for name, cases in marked.items() if cases]
        if found:
            parts.append(f"{label}: " + " / ".join(found))
    return "".join(f"; {part}" for part in parts)


def draw_convergence(cases):
    """One compact panel per quantity: each statistic over the nested subsamples, divided
    by its value at N, so that a converged statistic is a flat line at 1 and a jump of the
    value at N shows as the subsamples' points far from 1."""
    groups = [g for g, *_ in KINEMATIC_BLOCKS if any(g in c.get("convergence", {}) for c in cases)]
    columns = max(min(len(groups), 2), 1)
    figure, axes = new_figure(max(-(-len(groups) // 2), 1), columns)
    colors = case_colors(len(cases))
    panels = {}
    letters = (chr(ord("a") + i) for i in range(26))
    descriptions = {g: d for g, _, d in KINEMATIC_BLOCKS}
    for ax, group in zip(axes.flat, groups, strict=False):
        component = f"{'u' if group.startswith('velocity') else 'a'}3"
        series, widest = [], []
        for case, color in zip(cases, colors, strict=True):
            convergence = case.get("convergence", {})
            if case["G"] <= 0:
                continue
            for statistic, _, style in CONVERGENCE_STATISTICS:
                entry = dig(convergence, group, component, statistic)
                if entry is None or not entry["value"] or not entry["value"][-1]:
                    continue
                full = entry["value"][-1]
                path = f"{group}.{component}.{statistic}"
                flagged = path in convergence["not_converged"]
                reasons = convergence.get("reasons", {}).get(path, [])
                points = [
                    (n, v / full, None if ci is None else [ci[0] / full, ci[1] / full], ci)
                    for n, v, ci in zip(
                        convergence["n_tracers"], entry["value"], entry["ci95"], strict=True
                    )
                    if v is not None
                ]
                ns, ratios, intervals, original = zip(*points, strict=True)
                widest = max(widest, list(ns), key=lambda sizes: (len(sizes), sizes[-1:]))
                ax.plot(ns, ratios, style, color=color, lw=1)
                errorbars(
                    ax,
                    ns,
                    ratios,
                    intervals,
                    False,
                    color=color,
                    marker="^" if statistic == "random" else "o",
                    ms=4,
                    mfc="white" if flagged else color,
                )
                series.append(
                    {
                        "label": case_label(case),
                        "case": case["name"],
                        "statistic": statistic,
                        "n_tracers": list(ns),
                        "value": [v * full for v in ratios],
                        "ci95": list(original),
                        "relative_to_n": list(ratios),
                        "not_converged": flagged,
                        "reasons": reasons,
                    }
                )
        ax.axhline(1.0, color="0.5", lw=0.8)
        ax.set_xscale("log")
        ax.set_yscale("log")
        ticks_at(ax.xaxis, widest)
        ax.set_xlabel("tracers used (nested subsamples)")
        ax.set_ylabel(f"value / value at N, {component}")
        ax.grid(True, which="major", alpha=0.3)
        letter = next(letters)
        note = _title_note(series)
        panel_title(ax, letter, f"{component}, {descriptions[group]}{note}", fontsize=8)
        panels[letter] = {"group": group, "series": series}
    for ax in list(axes.flat)[len(groups) :]:
        ax.set_axis_off()
    handles = [
        Line2D([], [], color=color, label=case_label(case))
        for case, color in zip(cases, colors, strict=True)
        if case["G"] > 0
    ]
    handles += [
        Line2D(
            [], [], color="k", linestyle=style, marker="^" if key == "random" else "o", label=name
        )
        for key, name, style in CONVERGENCE_STATISTICS
    ]
    handles.append(
        Line2D([], [], marker="o", mfc="white", color="k", linestyle="none", label="not converged")
    )
    figure.legend(handles=handles, loc="outside right center", fontsize=7)
    figure_title(
        figure,
        "Convergence with the number of tracers: each statistic over nested subsamples "
        "divided by its value at N (1: converged; open markers: not converged, by a jump "
        "out of the N/4 or N/2 interval, or a few rows or tracers or a heavy tail carrying "
        "it, which a flat curve can hide); bars: bootstrap 95 % intervals",
        fontsize=9,
    )
    return figure, {"panels": panels}
