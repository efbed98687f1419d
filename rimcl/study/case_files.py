"""A study's case files: where each case's render file lives and whether one can be kept.

Shared by the single-process study (:mod:`rimcl.study.run`) and the distributed one
(:mod:`rimcl.study.distributed`), so that neither imports the other: a case file is kept only if
it is a readable render file of its case, complete for the scene's tracers and frames, and
measured for the same scene in every key that changes the numbers.
"""

from pathlib import Path

from rimcl.core.errors import RimclError, first_line
from rimcl.core.fingerprint import describe_change, input_changes

#: Scene keys that do not change the measurement: a study may resume with other values.
RUN_ONLY_KEYS = (
    ("run", "numerics"),
    ("run", "device"),
    ("run", "rays_per_batch"),
    ("run", "mode"),
    ("run", "scheduler"),
    ("run", "shard_tracers"),
    ("run", "engine"),
    ("run", "sensitivity"),
)
#: Key of a case file's recorded configuration holding the study's scene.
SCENE_RECORD = "study_scene"


#: Section of a recorded scene holding the fingerprints of the files the study read
#: (:func:`input_record`): not a scene key, so never in ``scene.toml``.
INPUTS = "inputs"


def input_record(study):
    """The fingerprints (:func:`rimcl.core.fingerprint.fingerprint`) of the files a study
    reads: ``{"field file": ...}`` (the scene's field file, else the shipped sample)."""
    from rimcl.core.fingerprint import fingerprint
    from rimcl.fields.sample import sample_path

    return {"field file": fingerprint(study.field_path or sample_path())}


def comparable_scene(study):
    """The scene of a :class:`~rimcl.scene.study_config.StudyConfig` without
    :data:`RUN_ONLY_KEYS`, with the fingerprints of its input files (:data:`INPUTS`; a
    fresh dict): a result recorded with another content of the field file is not this
    scene's."""
    trimmed = study.scene_record()
    for section, name in RUN_ONLY_KEYS:
        trimmed.get(section, {}).pop(name, None)
    trimmed[INPUTS] = input_record(study)
    return trimmed


def scene_differences(old, new):
    """Lines ``section.key: old -> new`` for every key of ``new`` that ``old`` differs in
    (a changed input file: ``its field file changed since (…)``)."""
    return [
        describe_change(name, old.get(section, {}).get(name), value)
        if section == INPUTS
        else f"{section}.{name}: {old.get(section, {}).get(name)!r} -> {value!r}"
        for section, table in new.items()
        for name, value in table.items()
        if old.get(section, {}).get(name) != value
    ]


def case_path(out_dir, case):
    """Render file of one case in a study directory."""
    return Path(out_dir) / "cases" / f"{case}.h5"


def check_case_file(path, study, case):
    """Why a study's case file cannot be kept for ``study``, or None if it can.

    A case file is kept only if it is a readable render file of ``case`` with every group
    and the row counts of the study's tracers, and its recorded scene equals the study's
    in every key that changes the measurement (:data:`RUN_ONLY_KEYS` may differ).

    Parameters
    ----------
    path : str or Path
    study : rimcl.scene.study_config.StudyConfig
    case : str
        The case name the file must hold.

    Returns
    -------
    str or None
        One line saying why the file must be measured again.
    """
    from rimcl.stats.render_file import load_render

    path = Path(path)
    try:
        tables = load_render(path)
    except RimclError as exc:
        return f"unreadable or incomplete ({exc})"
    except Exception as exc:  # whatever h5py raises for a damaged file
        return f"damaged ({type(exc).__name__}: {first_line(exc)})"
    if tables.case != case:
        return f"holds case {tables.case!r}, not {case!r}"
    recorded = tables.provenance.get("config", {}).get(SCENE_RECORD)
    if not isinstance(recorded, dict):
        return "records no study scene (written by rimcl render or an older rimcl)"
    changes = scene_differences(recorded, comparable_scene(study))
    inputs = input_changes(recorded.get(INPUTS), input_record(study))
    if inputs:
        return "; ".join(inputs) + ": its numbers are not this input's"
    if changes:
        shown = "; ".join(changes[:3]) + ("; ..." if len(changes) > 3 else "")
        return f"made for another scene ({shown})"
    for group, wanted in expected_rows(study.shared).items():
        table = getattr(tables, group) or {}
        found = len(table["id"]) if "id" in table else 0
        if found != wanted:
            return f"incomplete ({group} has {found} rows, the scene needs {wanted})"
    return None


def expected_rows(config):
    """Rows of each table of a complete case file measured with ``config`` (a
    :class:`rimcl.scene.config.MeasureConfig`; 0: no such table)."""
    count, frames = config.tracers.count, config.time.frames
    window = config.time.fit_window
    fitted = count * (frames - window + 1) if frames >= window else 0
    return {
        "tracers": count * frames,
        "velocity": count * (frames - 1),
        "acceleration": count * max(frames - 2, 0),
        "velocity_fit": fitted,
        "acceleration_fit": fitted,
    }
