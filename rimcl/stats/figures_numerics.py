"""The numerics figure (the paper's Appendix A): PDFs of |ε_x| / L at three integration steps
(the study's, half and a quarter of it) and three grid resolutions (the data's, every second
and every fourth node), with Richardson's estimate of what a finer step or grid would change.
"""

from pathlib import Path

import numpy as np
from matplotlib.ticker import NullFormatter

from rimcl.stats.figures_common import new_figure, save_figure


def write_numerics_figure(numerics, out_dir, versions, overwrite=True, name="numerics"):
    """The paper's Appendix A figure: PDFs of ``|ε_x| / L`` at three steps and three grids.

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
    figure, axes = new_figure(1, 2)
    panels = {}
    if positive:
        edges = np.logspace(np.log10(min(positive)) - 0.1, np.log10(max(positive)) + 0.1, 21)
        for ax, (letter, pair, what, check) in zip(
            np.ravel(axes),
            (
                ("a", ("step h", "step h/2", "step h/4"), "integration step", "step"),
                ("b", ("grid n", "grid n/2", "grid n/4"), "grid resolution", "grid"),
            ),
            strict=True,
        ):
            series = []
            for run_name, color in zip(pair, ("k", "tab:orange", "tab:blue"), strict=True):
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
            finer = _richardson_line(numerics, check, pair)
            ax.set_title(
                f"({letter}) {numerics['case']}: {what}\n{finer}", loc="left", fontsize="small"
            )
            ax.set_ylim(0, 2.2 * ax.get_ylim()[1])  # room for the six-line legend
            ax.legend(fontsize="x-small", loc="upper left")
            panels[letter] = {"bin_edges": edges.tolist(), "series": series}
    figure.suptitle(
        "Appendix A: the position error at three integration steps and three grid resolutions"
        if positive
        else "Appendix A: no position errors to compare"
    )
    data = {
        "panels": panels,
        "ratios": {k: v for k, v in numerics.items() if k.endswith("ratio")},
        "richardson": {k: v for k, v in numerics.items() if k.endswith("richardson")},
    }
    record = {"config": {"numerics": {"case": numerics["case"]}}, "versions": versions}
    return save_figure(figure, name, data, record, out_dir, overwrite)


def _richardson_line(numerics, check, runs):
    """What a finer step or grid would change, in words (centroids; optics in brackets)."""
    medians = {numerics["runs"][name]["median_over_L"] for name in runs}
    parts = []
    for prefix, what in (("", "median"), ("optics_", "optics")):
        estimate = numerics.get(f"{prefix}{check}_richardson")
        if estimate:
            parts.append(
                f"{what} {100 * estimate['relative_change']:.2g} % (order {estimate['order']:.2g})"
            )
        elif prefix == "" and len(medians) == 1:
            parts.append(f"{what} unchanged")
        else:
            parts.append(f"{what} n/a: its changes do not shrink")
    return f"a finer {check} (Richardson) would move the\n" + ";\n".join(parts)
