"""The study's costly sensitivity variants: each case measured again with one setting changed.

Every study carries the variants that need no new measurement (the excluded tracers counted
by their optics error; the threshold ×½ and ×2, located again in the same images:
:mod:`rimcl.stats.sensitivity`). ``rimcl study --sensitivity`` (scene key
``run.sensitivity``) measures every case twice more, each with one setting that changes
the tracing: the other interpolation (trilinear ↔ bspline3) and four times the rays per
tracer. The render files go to ``sensitivity/<variant>/cases/<case>.h5`` (kept between runs
like the cases'); their headline numbers (:func:`rimcl.stats.sensitivity.headline_values`)
join the case's ``sensitivity`` entry in ``stats.json`` and the verdicts are made again
(:func:`rimcl.stats.sensitivity.bands`). Each variant costs about one study.
"""

import copy

from rimcl.stats.sensitivity import MEASURED_VARIANTS
from rimcl.study.case_files import case_path, check_case_file

#: The variants: (name in stats.json and summary.md, directory).
VARIANTS = tuple(
    zip(
        MEASURED_VARIANTS,
        ("interpolation", "rays_x4"),
        strict=True,
    )
)


def variant_scene(scene, directory):
    """The scene with one setting changed (``directory`` of :data:`VARIANTS`)."""
    changed = copy.deepcopy(scene)
    if directory == "interpolation":
        current = scene["integrator"]["interp"]
        changed["integrator"]["interp"] = "trilinear" if current == "bspline3" else "bspline3"
    elif directory == "rays_x4":
        if scene["camera"]["kind"] == "plane":
            changed["camera"]["fan"] = 2 * scene["camera"]["fan"]
        else:
            changed["camera"]["pupil_rays"] = 4 * scene["camera"]["pupil_rays"]
    else:
        raise ValueError(f"unknown variant {directory!r}")
    return changed


def measure_variants(study, out_dir, cases, force=False, progress=False, say=None):
    """Measure every case under every variant (finished files are kept).

    Parameters
    ----------
    study : rimcl.scene.study_config.StudyConfig
        The study; each variant is its scene record with one setting changed, parsed anew.
    out_dir : Path
        The study directory.
    cases : list of (str, str)
        ``(name, case)`` as the study measures them.

    Returns
    -------
    files : dict
        ``{variant name: {case name: Path}}``.
    measured : list of str
        ``variant/case`` of the files measured now.
    """
    from rimcl.ptv.measure import run_render
    from rimcl.ptv.render_file import write_render
    from rimcl.scene.study_config import StudyConfig
    from rimcl.study.case_files import SCENE_RECORD, comparable_scene

    say = say or (lambda line: None)
    files, measured = {}, []
    for name, directory in VARIANTS:
        changed = StudyConfig.from_scene(variant_scene(study.scene_record(), directory))
        folder = out_dir / "sensitivity" / directory
        case_path(folder, "any").parent.mkdir(parents=True, exist_ok=True)
        references = []
        files[name] = {}
        for case_name, case in cases:
            path = case_path(folder, case_name)
            files[name][case_name] = path
            if path.exists() and not force and check_case_file(path, changed, case_name) is None:
                continue
            say(f"sensitivity, {name}: {case_name}")
            result = run_render(
                changed.field_path or None,
                case=case,
                config=changed.measure(case_name),
                reference=references,
                progress=progress,
            )
            if all(r is not result.reference for r in references):
                references.append(result.reference)
            result.config[SCENE_RECORD] = comparable_scene(changed)
            write_render(path, result, overwrite=True)
            measured.append(f"{directory}/{case_name}")
    return files, measured


def add_variants(stats, files):
    """Join the variants' headline numbers to each case and make the verdicts again."""
    from rimcl.stats.render_file import load_render
    from rimcl.stats.sensitivity import bands, headline_values

    for case in stats["cases"]:
        entry = case.get("sensitivity")
        if entry is None:
            continue
        for name, paths in files.items():
            path = paths.get(case["name"])
            if path is not None and path.exists():
                entry["variants"][name] = headline_values(load_render(path))
        entry["bands"] = bands(case, entry["variants"])
