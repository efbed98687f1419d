"""Whether render files can be compared in one ``stats.json``: the same scene, one case each.

Two render files differ by their case (name, ``G``, fluid) and by how they ran (device,
engine, batch size, shard); everything else in their recorded configuration (pixels,
tracers, seed, camera and fan, frames and fit, renderer and threshold, field, sheet...) is
the scene, and statistics of files of different scenes side by side would compare scenes,
not cases. :func:`scene_mismatches` lists what differs.
"""

#: Configuration keys (dotted) of a render file that belong to its case or its run, not to
#: the scene: they may differ between the files of one comparison.
CASE_OR_RUN_KEYS = (
    "case",
    "k_rho",
    "fluid",
    "engine",
    "rays_per_batch",
    "shard",
    "trace.device",
    # a study's scene record repeats the scene with the study's case list
    "study_scene",
)


def _flat(config, prefix=""):
    """``{"a.b": value}`` for every leaf of a nested configuration."""
    items = {}
    for key, value in config.items():
        name = f"{prefix}{key}"
        if any(name == skip or name.startswith(skip + ".") for skip in CASE_OR_RUN_KEYS):
            continue
        if isinstance(value, dict):
            items.update(_flat(value, name + "."))
        else:
            items[name] = value
    return items


def _shown(value):
    if isinstance(value, float):
        return f"{value:.6g}"
    text = str(value)
    return text if len(text) <= 40 else text[:39] + "…"


def scene_mismatches(all_tables):
    """What differs between the scenes of several render files.

    Parameters
    ----------
    all_tables : list of rimcl.stats.render_file.RenderTables

    Returns
    -------
    list of str
        One entry per differing key (``"render.threshold: 100 in a.h5, 500 in b.h5"``),
        each against the first file; empty when all were rendered from one scene.
    """
    first = all_tables[0]
    reference = _flat(first.provenance.get("config", {}))
    found = []
    for tables in all_tables[1:]:
        other = _flat(tables.provenance.get("config", {}))
        for key in sorted(set(reference) | set(other)):
            mine, theirs = reference.get(key, "absent"), other.get(key, "absent")
            if mine != theirs:
                found.append(
                    f"{key}: {_shown(mine)} in {first.path.name}, "
                    f"{_shown(theirs)} in {tables.path.name}"
                )
    return found
