"""Figures of the traced rays: ``ray_deflection`` (|Δθ| of each case's rays against its
Δn_max, with the paper's literature studies on the same Δn_max axis) and ``path_length``
(S / L against the incidence angle).
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
#: Half-width (decades) of the strip each case's rays are spread over along Δn_max.
STRIP_DECADES = 0.08

#: Studies of the paper's Table 1 (tab:studies): reference, flow, Δn_max, fluid index n.
#: Their deflections, depths and gradient lengths are not in the paper's text, so only
#: their Δn_max is marked, on the Δn_max axis of the cases (a deflection would need the
#: path length through their gradients).
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


def _shown_rays(tables):
    """Up to :data:`MAX_SCATTER_RAYS` traced rays (status ok, deflected), evenly strided
    through the sample (ordered by tracer), and how many were sampled and left out."""
    rays = tables.rays
    ok = (rays["status"] == 0) & (rays["deflection"] > 0)
    usable = np.flatnonzero(ok)
    picks = np.linspace(0, max(usable.size - 1, 0), min(usable.size, MAX_SCATTER_RAYS))
    return usable[np.unique(picks.astype(int))], int(ok.size), int(np.count_nonzero(~ok))


def draw_ray_deflection(all_tables, cases):
    """(a) each case's ray deflections |Δθ| at its Δn_max (a strip per case, the two
    incidence groups in two colours, the median and 5th–95th percentiles as a bar), with
    the line through the weakest case's median that a deflection proportional to Δn_max
    would follow; (b) the literature studies' Δn_max on the same axis."""
    figure = Figure(figsize=(10.0, 7.4), dpi=120, layout="constrained")
    ax, ax_studies = figure.subplots(2, 1, gridspec_kw={"height_ratios": [3, 1.3]})
    panel = {"x": "Δn_max", "y": "|Δθ| (rad)", "series": [], "literature": []}
    groups = (
        ("tab:blue", f"0 ≤ |θ0| ≤ {OBLIQUE_THETA0}"),
        ("tab:red", f"{OBLIQUE_THETA0} < |θ0|"),
    )
    case_handles, medians = [], []
    rng = np.random.default_rng(0)  # the strip's spread only: the same figure every run
    for index, (tables, case) in enumerate(zip(all_tables, cases, strict=True)):
        if not tables.rays or not case["delta_n_max"] > 0:
            continue
        shown, sampled, left_out = _shown_rays(tables)
        rays = tables.rays
        deflection = rays["deflection"][shown]
        theta0 = np.abs(rays["theta0"][shown])
        delta_n = case["delta_n_max"]
        entry = {
            "label": case_label(case),
            "delta_n_max": delta_n,
            "deflection": deflection.tolist(),
            "theta0": theta0.tolist(),
            "NL": (rays["n_metric"][shown] * tables.length).tolist(),
            "n_sampled": sampled,
            "n_zero_or_failed": left_out,
            "median": None,
            "p05_p95": None,
        }
        panel["series"].append(entry)
        if not deflection.size:
            continue
        marker = CASE_MARKERS[index % len(CASE_MARKERS)]
        spread = 10.0 ** rng.uniform(-STRIP_DECADES, STRIP_DECADES, deflection.size)
        near = theta0 <= OBLIQUE_THETA0
        for mask, (color, _) in zip((near, ~near), groups, strict=True):
            ax.scatter(
                delta_n * spread[mask],
                deflection[mask],
                s=5,
                color=color,
                marker=marker,
                alpha=0.3,
            )
        median = float(np.median(deflection))
        low, high = np.percentile(deflection, [5, 95])
        entry["median"], entry["p05_p95"] = median, [float(low), float(high)]
        medians.append((delta_n, median))
        ax.errorbar(
            [delta_n],
            [median],
            yerr=[[median - low], [high - median]],
            fmt=marker,
            color="k",
            mfc="white",
            ms=7,
            capsize=3,
            zorder=3,
        )
        case_handles.append(
            Line2D([], [], marker=marker, color="0.3", linestyle="none", label=case_label(case))
        )
    if medians:
        weakest = min(medians)
        line = np.array([min(m[0] for m in medians), max(m[0] for m in medians)])
        ax.plot(line, weakest[1] * line / weakest[0], "k--", lw=1)
        panel["proportional_from"] = {"delta_n_max": weakest[0], "median": weakest[1]}
    # the literature studies on their own axis below: their Δn_max only (the paper gives
    # no deflection, depth or gradient length for them), one row per study
    literature_handles = []
    for index, (reference, flow, delta_n, n) in enumerate(LITERATURE_STUDIES):
        marker = CASE_MARKERS[index % len(CASE_MARKERS)]
        color = colormaps["tab10"](index % 10)
        ax_studies.plot([delta_n], [index + 1], marker=marker, color=color, mfc="white", ms=6)
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
            {"reference": reference, "flow": flow, "delta_n_max": delta_n, "n": n}
        )
    for case in cases:
        if case["delta_n_max"] > 0:
            ax_studies.axvline(case["delta_n_max"], color="0.6", lw=0.8, ls=":")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_ylabel("ray deflection |Δθ| (rad)")
    ax.set_xlabel("Δn_max of the case (rays spread a little along it to be seen)")
    ax_studies.set_xscale("log")
    low, high = ax.get_xlim()
    studies = [delta_n for *_, delta_n, _ in LITERATURE_STUDIES]
    ax_studies.set_xlim(min(low, 0.5 * min(studies)), max(high, 2.0 * max(studies)))
    ax.set_xlim(ax_studies.get_xlim())  # one Δn_max axis for (a) and (b)
    panel_title(
        ax,
        "a",
        "Ray deflection against the case's Δn_max (frame-0 rays, status ok; black: median "
        "and 5th–95th percentiles)",
        fontsize=8,
    )
    ax_studies.set_xlabel("Δn_max (maximum index difference; the same axis as (a))")
    ax_studies.set_ylim(0.3, len(LITERATURE_STUDIES) + 0.7)
    ax_studies.set_yticks(range(1, len(LITERATURE_STUDIES) + 1))
    ax_studies.set_ylabel("study (legend)")
    ax_studies.grid(True, which="major", axis="x", alpha=0.3)
    panel_title(
        ax_studies,
        "b",
        "The studies of the paper's Table 1 by their Δn_max (dotted: the cases'); the paper "
        "gives no deflection or path length for them",
        fontsize=8,
    )
    ax.grid(True, which="major", alpha=0.3)
    angle_handles = [
        Line2D([], [], marker="o", color=color, linestyle="none", label=label)
        for color, label in groups
    ]
    guide = [Line2D([], [], color="k", linestyle="--", label="|Δθ| ∝ Δn_max")]
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
