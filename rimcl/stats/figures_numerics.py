"""The numerics figure (the paper's Appendix A): PDFs of |ε_x| / L at two integration steps
and two grid resolutions.
"""

from pathlib import Path

import numpy as np
from matplotlib.ticker import NullFormatter

from rimcl.stats.figures_common import new_figure, save_figure


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
    figure, axes = new_figure(1, 2)
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
