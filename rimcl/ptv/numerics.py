"""The paper's Appendix A: does the answer depend on the step or on the grid?

The paper checked its position errors by halving the integration step and by refining the
grid (its Fig. A.1: PDFs of ``|ε_x|`` that collapse). rimcl does the same on the study's
own scene, for one case, with the positions of the first frame: the step halved and
quartered (a refinement), and the grid coarsened to every second and every fourth node
(the field and its gradient sampled from the full grid, so only the interpolation between
nodes changes). A grid finer than the data cannot be measured; the three grids give its
effect by Richardson extrapolation instead: the observed order ``p`` of the median's
changes ``n/4 → n/2 → n`` and the change a finer grid would still make,
``|m(n) − m(n/2)| / (2^p − 1)``, relative to ``m(n)``; likewise the step's, from
``h → h/2 → h/4``. If the PDFs collapse and the estimates are small, neither the step nor
the grid decides the result.
"""

import dataclasses
from contextlib import ExitStack

import numpy as np

from rimcl.fields.crop import StridedSource
from rimcl.optics.trace import default_step
from rimcl.ptv.field_source import case_of, open_source
from rimcl.ptv.measure import run_render
from rimcl.scene.config import TimeConfig, TracerConfig

#: Tracers measured per run (the first of the study's tracers, same seed).
NUMERICS_TRACERS = 200
#: Log-spaced bins of |ε_x| / L for the PDFs.
PDF_BINS = 40


def _errors(result, measured="meas", reference="ref"):
    rows = result.tracers
    usable = rows["flags"] == 0
    error = np.hypot(
        rows[f"x2_{measured}"] - rows[f"x2_{reference}"],
        rows[f"x3_{measured}"] - rows[f"x3_{reference}"],
    )
    return error[usable] / result.attrs["length_L"]


def numerical_convergence(study, case="C1", tracers=NUMERICS_TRACERS):
    """``|ε_x| / L`` of one case at the default step, at half of it, and on a grid of every
    second node, with the study's scene otherwise.

    Parameters
    ----------
    study : rimcl.scene.study_config.StudyConfig
        The study (its field and the case's configuration).
    case : str
        The case measured (default C1, air, as the paper's Appendix A).
    tracers : int
        At most this many of the scene's tracers (first frame only).

    Returns
    -------
    dict
        ``case``, ``runs``: per run name (``"step h"``, ``"step h/2"``, ``"step h/4"``,
        ``"grid n"``, ``"grid n/2"``, ``"grid n/4"``) its ``step``, ``grid_n3_n2_n1``,
        ``errors_over_L`` (list) and their ``median_over_L``, and the same of the optics
        means; ``step_ratio`` and ``grid_ratio``: medians at h/2 over h and on the coarse
        over the full grid; ``step_richardson``, ``grid_richardson`` (and ``optics_*``):
        :func:`richardson` of the medians.
    """
    config = study.measure(case)
    config = dataclasses.replace(
        config,
        time=TimeConfig(frames=1, start_frame=config.time.start_frame),
        tracers=TracerConfig(
            count=min(int(config.tracers.count), int(tracers)),
            seed=config.tracers.seed,
            margin=config.tracers.margin,
        ),
    )
    field_path = study.field_path or None
    runs = {}
    with ExitStack() as stack:
        source, _name = open_source(field_path, stack)
        index = case_of(source, case, None, config.fluid)
        first = index.field(source, config.time.start_frame, source.times[0])
        step = config.integrator.step or default_step(first)
        plans = {
            "step h": (source, step),
            "step h/2": (source, step / 2),
            "step h/4": (source, step / 4),
            "grid n/2": (StridedSource(source, 2), step),
            "grid n/4": (StridedSource(source, 4), step),
        }
        for name, (reader, run_step) in plans.items():
            integrator = dataclasses.replace(config.integrator, step=run_step)
            result = run_render(
                reader, case=case, config=dataclasses.replace(config, integrator=integrator)
            )
            errors, optics = _errors(result), _errors(result, "opt", "opt_ref")
            runs[name] = {
                "step": run_step,
                "grid_n3_n2_n1": list(reader.shape),
                "errors_over_L": errors.tolist(),
                "median_over_L": float(np.median(errors)) if errors.size else None,
                "optics_errors_over_L": optics.tolist(),
                "optics_median_over_L": float(np.median(optics)) if optics.size else None,
            }
    runs["grid n"] = runs["step h"]

    def ratio(a, b, key):
        top, bottom = runs[a][key], runs[b][key]
        return None if not top or not bottom else top / bottom

    def medians(names, key):
        return [runs[name][key] for name in names]

    return {
        "case": case,
        "runs": runs,
        "step_ratio": ratio("step h/2", "step h", "median_over_L"),
        "grid_ratio": ratio("grid n/2", "grid n", "median_over_L"),
        "optics_step_ratio": ratio("step h/2", "step h", "optics_median_over_L"),
        "optics_grid_ratio": ratio("grid n/2", "grid n", "optics_median_over_L"),
        # coarse to fine; the study's own run is the step's coarsest and the grid's finest
        "step_richardson": richardson(medians(STEP_RUNS, "median_over_L"), 0),
        "grid_richardson": richardson(medians(GRID_RUNS, "median_over_L"), 2),
        "optics_step_richardson": richardson(medians(STEP_RUNS, "optics_median_over_L"), 0),
        "optics_grid_richardson": richardson(medians(GRID_RUNS, "optics_median_over_L"), 2),
    }


#: The runs of each check, coarse to fine.
STEP_RUNS = ("step h", "step h/2", "step h/4")
GRID_RUNS = ("grid n/4", "grid n/2", "grid n")


def richardson(values, own):
    """Richardson's estimate from three values at resolutions halved each time.

    Parameters
    ----------
    values : sequence of 3 float or None
        The quantity, coarse to fine.
    own : int
        Which of them the study reports.

    Returns
    -------
    dict or None
        ``order``: the observed order ``p = log2(|v0 − v1| / |v1 − v2|)``;
        ``extrapolated``: ``v2 + (v2 − v1) / (2^p − 1)``; ``relative_change``:
        ``|extrapolated − v_own| / v_own``, what infinite resolution would change. None
        where a value is missing, the changes vanish or do not shrink (not in the
        asymptotic range: the three runs then say no more than their PDFs).
    """
    if any(v is None for v in values) or not values[own]:
        return None
    coarse, middle, fine = values
    first, second = abs(coarse - middle), abs(middle - fine)
    if second == 0 or first <= second:
        return None
    order = float(np.log2(first / second))
    extrapolated = fine + (fine - middle) / (2.0**order - 1.0)
    return {
        "order": order,
        "extrapolated": float(extrapolated),
        "relative_change": float(abs(extrapolated - values[own]) / values[own]),
    }
