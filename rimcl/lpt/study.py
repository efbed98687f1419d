"""``rimcl study`` with ``run.mode = "lpt"``: the LPT chain over the scene's cases.

The study directory receives ``lpt/`` (``lpt_stats.json`` and the case files of
:func:`rimcl.lpt.run.run_lpt`), ``figures/lpt_*.png`` (:mod:`rimcl.lpt.figures`),
``stats.json`` (``{"config": …, "cases": [], "lpt": <lpt_stats.json>}``) and
``summary.md`` (:func:`rimcl.lpt.run.summary_lines`). A rerun of the same scene keeps the
finished results unless forced.
"""

import json
from pathlib import Path

from rimcl.core.fingerprint import input_changes
from rimcl.lpt.config import LptScene
from rimcl.lpt.files import lpt_inputs
from rimcl.lpt.run import run_lpt, summary_lines
from rimcl.stats.tables import write_json

LPT_DIR = "lpt"


def _finished(path, study, say):
    """The earlier ``lpt_stats.json`` of this same scene and input content, or None (with
    a line saying why it is measured again)."""
    try:
        previous = json.loads(Path(path).read_text())
    except (OSError, ValueError):
        return None
    if previous.get("study_scene") != study.scene_record():
        return None
    changes = input_changes(previous.get("inputs"), lpt_inputs(study.field_path))
    if changes:
        say(f"lpt: {Path(path).name} {'; '.join(changes)}; measuring again")
        return None
    return previous


def run_lpt_study(study, out_dir, *, force=False, figures=True, report=None):
    """Run the LPT chain of a study scene into ``out_dir``.

    Parameters
    ----------
    study : rimcl.scene.study_config.StudyConfig
        The study, parsed once from its scene.
    out_dir : Path
    force : bool
        Redo it even if a finished run of the same scene is there.
    figures : bool
    report : callable, optional
        One line of text per step.

    Returns
    -------
    stats : dict
        The study's ``stats.json`` document.
    ran : list of str
        ``["lpt/<case>", …]`` measured in this call (empty when kept).
    """
    say = report or (lambda line: None)
    lpt_scene = LptScene(study)
    folder = Path(out_dir) / LPT_DIR
    document = None if force else _finished(folder / "lpt_stats.json", study, say)
    ran = []
    if document is None:
        say(f"lpt: cases {', '.join(study.names)}")

        def progress(case, frame, frames):
            # every frame: a case runs minutes on a CPU, never silent for all of them
            say(
                f"lpt {case}: frame {frame}/{frames}"
                + (", triangulating" if frame == frames else "")
            )

        document = run_lpt(
            lpt_scene,
            folder,
            device=study.shared.run.device,
            progress=progress,
            overwrite=True,
        )
        ran = [f"lpt/{case}" for case in document["cases"]]
    else:
        say(f"lpt: finished earlier, kept ({folder / 'lpt_stats.json'})")
    if figures:
        from rimcl.lpt.figures import write_lpt_figures

        write_lpt_figures(document, Path(out_dir) / "figures", overwrite=True)
    stats = {
        "config": {"scene": study.scene_record(), "study_dir": str(out_dir)},
        "cases": [],
        "lpt": document,
    }
    write_json(Path(out_dir) / "stats.json", stats, True)
    (Path(out_dir) / "summary.md").write_text(summary_markdown(document), encoding="utf-8")
    return stats, ran


#: The lines of :func:`rimcl.lpt.run.summary_lines` that :func:`summary_markdown` tabulates.
_TABULATED = ("position refraction rms", "velocity rms", "acceleration rms")


def summary_markdown(document):
    """The LPT study's ``summary.md``: per case a heading, a table of the refraction errors
    per component (position in px, velocity and acceleration as rms(ε)/rms(truth) with the
    baseline) and the other results as a list.

    Parameters
    ----------
    document : dict
        ``lpt_stats.json`` (:func:`rimcl.lpt.run.run_lpt`).

    Returns
    -------
    str
    """
    from rimcl.lpt.run import COMPONENTS

    def _cell(value):
        return "n/a" if value is None else f"{value:.3g}"

    text = summary_lines(document)
    lines = [
        "# LPT study",
        "",
        f"{text[0]}; configuration `scene.toml`, every number `stats.json`.",
    ]
    cases = iter(document["cases"].items())
    for line in text[1:]:
        if not line.startswith("  "):
            name, case = next(cases)
            lines += ["", f"## {name}", "", line.partition(": ")[2] + ".", ""]
            lines += ["| | " + " | ".join(COMPONENTS) + " |", "|---|" + "---|" * len(COMPONENTS)]
            position = case["position"]
            lines.append(
                "| position refraction rms (px) | "
                + " | ".join(_cell(position[k]["refraction_rms_px"]) for k in COMPONENTS)
                + " |"
            )
            for label in ("velocity", "acceleration"):
                block = case[label]
                lines.append(
                    f"| {label} rms(ε)/rms(truth) (baseline) | "
                    + " | ".join(
                        f"{_cell(block[k]['refraction']['rms_normalized'])} "
                        f"({_cell(block[k]['baseline']['rms_normalized'])})"
                        for k in COMPONENTS
                    )
                    + " |"
                )
            lines.append("")
        elif not line.strip().startswith(_TABULATED):
            label, colon, values = line.strip().partition(": ")
            lines.append(f"- **{label}**: {values}" if colon else f"- {label}")
    return "\n".join(lines).replace("\n\n\n", "\n\n") + "\n"
