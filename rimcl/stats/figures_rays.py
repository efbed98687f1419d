"""Figures of the traced rays: ``ray_deflection`` (|Δθ| against |N| L, with the paper's
literature studies marked) and ``path_length`` (S / L against the incidence angle).
"""

import numpy as np
from matplotlib import colormaps
from matplotlib.figure import Figure
from matplotlib.lines import Line2D

from rimcl.stats.figures_common import CASE_MARKERS, case_label, new_figure, panel_title

#: Rays drawn per case in the deflection scatter plot (the case files hold the whole sample).
MAX_SCATTER_RAYS = 1000
#: Incidence angle (rad) separating the two groups of the deflection plot (the paper's).
OBLIQUE_THETA0 = 0.6

#: Studies of the paper's Table 1 (tab:studies): reference, flow, Δn_max, fluid index n.
#: The paper estimated |N| as Δn_max / n over a characteristic length; with that length
#: taken as the depth L, |N| L = Δn_max / n. The deflections these studies reported are
#: not in the paper's text, so only their |N| L is marked.
LITERATURE_STUDIES = (
    ("Vanselow et al. 2018", "hot jet, air", 9.9e-5, 1.0003),
    ("Guo et al. 2016", "shock on a conical vehicle, air", 2.0e-5, 1.0003),
    ("Elsinga et al. 2005", "shear layer, air (theory)", 9.0e-5, 1.0003),
    ("Elsinga et al. 2005", "shear layer, air (PIV & BOS)", 6.9e-5, 1.0003),
    ("Elsinga et al. 2005", "expansion fan, air (theory)", 7.4e-5, 1.0003),
    ("Elsinga et al. 2005", "expansion fan, air (PIV & BOS)", 7.1e-5, 1.0003),
    ("Stella et al. 2001", "premixed flames, air-propane", 1.3e-3, 1.0003),
    ("Raffel et al. 1998", "shock wave, air", 1.0e-4, 1.0003),
    ("Kirmse et al. 2011", "shock wave, air", 6.3e-6, 1.0003),
    ("Oljaca & Gunaratne 2009", "plane shear layer, water", 3.4e-4, 1.333),
)


def draw_ray_deflection(all_tables, cases):
    figure = Figure(figsize=(10.0, 7.4), dpi=120, layout="constrained")
    ax, ax_studies = figure.subplots(2, 1, gridspec_kw={"height_ratios": [3, 1.3]})
    panel = {"x": "|N| L", "y": "|Δθ| (rad)", "series": [], "literature": []}
    lows, highs = [], []
    groups = (
        ("tab:blue", f"0 ≤ |θ0| ≤ {OBLIQUE_THETA0}"),
        ("tab:red", f"{OBLIQUE_THETA0} < |θ0|"),
    )
    case_handles = []
    for index, (tables, case) in enumerate(zip(all_tables, cases, strict=True)):
        rays = tables.rays
        if not rays:
            continue
        ok = (rays["status"] == 0) & (rays["deflection"] > 0) & (rays["n_metric"] > 0)
        # evenly strided through the sample, which is ordered by tracer
        usable = np.flatnonzero(ok)
        picks = np.linspace(0, max(usable.size - 1, 0), min(usable.size, MAX_SCATTER_RAYS))
        shown = usable[np.unique(picks.astype(int))]
        n_l = rays["n_metric"][shown] * tables.length
        deflection = rays["deflection"][shown]
        theta0 = np.abs(rays["theta0"][shown])
        panel["series"].append(
            {
                "label": case_label(case),
                "NL": n_l.tolist(),
                "deflection": deflection.tolist(),
                "theta0": theta0.tolist(),
                "n_sampled": int(ok.size),
                "n_zero_or_failed": int(np.count_nonzero(~ok)),
            }
        )
        marker = CASE_MARKERS[index % len(CASE_MARKERS)]
        near = theta0 <= OBLIQUE_THETA0
        for mask, (color, _) in zip((near, ~near), groups, strict=True):
            ax.scatter(n_l[mask], deflection[mask], s=5, color=color, marker=marker, alpha=0.35)
        case_handles.append(
            Line2D([], [], marker=marker, color="0.3", linestyle="none", label=case_label(case))
        )
        if n_l.size:
            lows.append(n_l.min())
            highs.append(n_l.max())
    literature_x = [delta_n / n for _, _, delta_n, n in LITERATURE_STUDIES]
    line = np.array([min([*lows, *literature_x]), max([*highs, *literature_x])])
    ax.plot(line, line, "k--", lw=1)
    # the literature studies on their own axis below: their |N| L only (no deflection is
    # in the paper's text, see LITERATURE_STUDIES), one row per study
    literature_handles = []
    for index, ((reference, flow, delta_n, n), x) in enumerate(
        zip(LITERATURE_STUDIES, literature_x, strict=True)
    ):
        marker = CASE_MARKERS[index % len(CASE_MARKERS)]
        color = colormaps["tab10"](index % 10)
        ax_studies.plot([x], [index + 1], marker=marker, color=color, mfc="white", ms=6)
        literature_handles.append(
            Line2D(
                [],
                [],
                marker=marker,
                color=color,
                mfc="white",
                linestyle="none",
                label=f"{index + 1}. {reference}: {flow}, Δn_max = {delta_n:.2g}",
            )
        )
        panel["literature"].append(
            {"reference": reference, "flow": flow, "delta_n_max": delta_n, "n": n, "NL": x}
        )
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax_studies.set_xscale("log")
    ax_studies.set_xlim(ax.get_xlim())  # the same |N| L axis as (a)
    ax.set_xlabel("|N| L (path-averaged transverse ∇n/n times slab depth L)")
    ax_studies.set_xlabel("|N| L ≈ Δn_max / n (the same axis as (a))")
    ax.set_ylabel("ray deflection |Δθ| (rad)")
    panel_title(ax, "a", "Ray deflection (frame-0 ray sample, rays with status ok)", fontsize=8)
    ax_studies.set_ylim(0.3, len(LITERATURE_STUDIES) + 0.7)
    ax_studies.set_yticks(range(1, len(LITERATURE_STUDIES) + 1))
    ax_studies.set_ylabel("study (legend)")
    ax_studies.grid(True, which="major", axis="x", alpha=0.3)
    panel_title(
        ax_studies,
        "b",
        "The studies of the paper's Table 1: |N| L ≈ Δn_max / n over their depth (the paper "
        "gives no deflection for them)",
        fontsize=8,
    )
    ax.grid(True, which="major", alpha=0.3)
    angle_handles = [
        Line2D([], [], marker="o", color=color, linestyle="none", label=label)
        for color, label in groups
    ]
    guide = [Line2D([], [], color="k", linestyle="--", label="|Δθ| = |N| L")]
    first = ax.legend(handles=angle_handles + guide + case_handles, fontsize=6, loc="upper left")
    ax.add_artist(first)
    figure.legend(
        handles=literature_handles,
        fontsize=6,
        loc="outside right center",
        title="literature (paper's Table 1)",
        title_fontsize=6,
    )
    return figure, {"panels": {"a": panel}}


def draw_path_length(all_tables, cases):
    with_rays = [(t, c) for t, c in zip(all_tables, cases, strict=True) if t.rays]
    cols = min(max(len(with_rays), 1), 3)
    rows = max(1, -(-len(with_rays) // cols))
    figure, axes = new_figure(rows, cols)
    panels = {}
    for index, (tables, case) in enumerate(with_rays):
        ax = axes.flat[index]
        rays = tables.rays
        ok = rays["status"] == 0
        theta0 = np.abs(rays["theta0"][ok])
        s_over_l = rays["path_length"][ok] / tables.length
        counts, t_edges, s_edges = np.histogram2d(theta0, s_over_l, bins=(40, 40))
        mesh = ax.pcolormesh(
            t_edges, s_edges, np.where(counts.T > 0, counts.T, np.nan), cmap="viridis"
        )
        figure.colorbar(mesh, ax=ax, label="rays per bin")
        curve = np.linspace(0.0, t_edges[-1], 200)
        ax.plot(curve, 1.0 / np.cos(curve), "r--", lw=1.2, label="1 / cos|θ0|")
        ax.set_xlabel("incidence angle |θ0| (rad)")
        ax.set_ylabel("path length S / L")
        panel_title(ax, chr(ord("a") + index), case_label(case))
        ax.legend(fontsize=7, loc="upper left")
        panels[case["name"]] = {
            "theta0_edges": t_edges.tolist(),
            "S_over_L_edges": s_edges.tolist(),
            "counts": counts.tolist(),
        }
    for ax in list(axes.flat)[len(with_rays) :]:
        ax.set_axis_off()
    return figure, {"panels": panels}
