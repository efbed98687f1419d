"""The paper's Appendix A: does the answer depend on the step or on the grid?

The paper checked its position errors by halving the integration step and by refining the
grid (its Fig. A.1: PDFs of ``|ε_x|`` that collapse). rimcl does the same on the study's
own scene, for one case, with the positions of the first frame: the step halved, and the
grid coarsened to every second node (the field and its gradient sampled from the full
grid, so only the interpolation between nodes changes). If the PDFs collapse, neither the
step nor the grid decides the result; if the coarse grid moves them, the field's resolution
does.
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
        ``case``, ``runs``: per run name (``"step h"``, ``"step h/2"``, ``"grid n"``,
        ``"grid n/2"``) its ``step``, ``grid_n3_n2_n1``, ``errors_over_L`` (list) and their
        ``median_over_L``, and the same of the optics means; ``step_ratio`` and
        ``grid_ratio``: medians at h/2 over h and on the coarse over the full grid.
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
            "grid n/2": (StridedSource(source, 2), step),
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

    return {
        "case": case,
        "runs": runs,
        "step_ratio": ratio("step h/2", "step h", "median_over_L"),
        "grid_ratio": ratio("grid n/2", "grid n", "median_over_L"),
        "optics_step_ratio": ratio("step h/2", "step h", "optics_median_over_L"),
        "optics_grid_ratio": ratio("grid n/2", "grid n", "optics_median_over_L"),
    }
