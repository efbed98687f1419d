"""Figures of a study: the paper's set, readable, with their numbers beside them.

Each figure is written as ``<name>.png`` and ``<name>.pdf`` (with the versions in the file
metadata) and ``<name>.json``: every number drawn, by panel and series, with the
configuration and versions. Figures are drawn with matplotlib's object API on the Agg
canvas (no pyplot state, no display needed). They draw what :mod:`rimcl.stats.document`
computed (the ``stats.json`` document) and the per-tracer samples of
:mod:`rimcl.stats.tables`; they never import :mod:`rimcl.stats.document`.

Figures: ``ray_deflection`` (|Δθ| against |N|L, the paper's literature studies marked),
``path_length`` (S/L against |θ0|), ``position_error`` (PDFs of |ε_x|/L, their peak and
median against G), ``velocity_error`` and ``acceleration_error`` (PDFs of the relative
errors, the angle to ``u^ref`` and to ``u``, the paper's mean and spread and the robust
statistics against G), ``error_budget`` (optics, imaging, total and baseline against G,
with a verdict per case), ``convergence`` (statistics against the number of tracers),
``maps`` (u3 and a3: truth, uniform medium, air-like and water-like cases) and
``tracer_shape`` (PDFs of ΔA/A and of the circularity, per regime). Every statistic drawn
against G carries its bootstrap 95 % interval as an error bar.

This module lists the set (:data:`FIGURE_NAMES`) and draws and writes it; each family of
figures is drawn in a module of its own (:mod:`~rimcl.stats.figures_rays`,
:mod:`~rimcl.stats.figures_errors`, :mod:`~rimcl.stats.figures_budget`,
:mod:`~rimcl.stats.figures_convergence`, :mod:`~rimcl.stats.figures_tracer_shape`) with the
helpers of :mod:`~rimcl.stats.figures_common`. Figures across studies:
:mod:`~rimcl.stats.figures_dt_sweep` (errors against Δt) and
:mod:`~rimcl.stats.figures_numerics` (the paper's Appendix A).
"""

from pathlib import Path

from rimcl.stats.figures_budget import draw_error_budget
from rimcl.stats.figures_common import DELTA_N_LABEL, G_LABEL, finish_axes, save_figure
from rimcl.stats.figures_convergence import draw_convergence
from rimcl.stats.figures_errors import (
    draw_acceleration_error,
    draw_maps,
    draw_position_error,
    draw_velocity_error,
)
from rimcl.stats.figures_rays import draw_path_length, draw_ray_deflection
from rimcl.stats.figures_tracer_shape import draw_tracer_shape

FIGURE_NAMES = (
    "ray_deflection",
    "path_length",
    "position_error",
    "velocity_error",
    "acceleration_error",
    "error_budget",
    "convergence",
    "maps",
    "tracer_shape",
)

_BUILDERS = {
    "ray_deflection": draw_ray_deflection,
    "path_length": draw_path_length,
    "position_error": draw_position_error,
    "velocity_error": draw_velocity_error,
    "acceleration_error": draw_acceleration_error,
    "error_budget": lambda all_tables, cases: draw_error_budget(cases),
    "convergence": lambda all_tables, cases: draw_convergence(cases),
    "maps": draw_maps,
    "tracer_shape": draw_tracer_shape,
}


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
    cases = stats["cases"]
    by_index = any(case["G"] is None for case in cases)
    if by_index:
        # fluid cases and δn files have no G: every case is placed by its Δn_max instead
        cases = [{**case, "G": case["delta_n_max"], "abscissa": "delta_n_max"} for case in cases]
    figure, data = _BUILDERS[name](all_tables, cases)
    if by_index:
        for ax in figure.axes:
            if ax.get_xlabel() == G_LABEL:
                ax.set_xlabel(DELTA_N_LABEL)
    finish_axes(figure)
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
    for name in FIGURE_NAMES:
        figure, data = draw_figure(name, all_tables, stats)
        written += save_figure(figure, name, data, stats, out_dir, overwrite)
    return written
