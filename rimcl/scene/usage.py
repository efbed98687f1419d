"""Which command uses which scene key, and the one rule for keys a command does not use.

Every command that takes a scene reads the same keys (:mod:`rimcl.scene.keys`), but each
uses only some of them. :func:`users` says which commands use a key; :func:`check_use`
applies the rule:

- A scene is written for one of two kinds of measurement: the **planar** one (``rimcl
  study`` in the ``ptv``, ``piv`` and ``both`` modes, ``rimcl render``, ``rimcl piv render``
  and ``sequence``, ``rimcl trace``) or the **volume** one (``rimcl lpt run`` and ``render``,
  ``rimcl study`` with ``run.mode = "lpt"``).
- A key set to anything but its default that no command of the command's kind uses is
  refused, in one line naming every such key (``field.box`` in ``rimcl lpt run``, ``[rig]``
  in ``rimcl render``).
- Within the planar kind one scene serves every command (a study's scene renders one of
  its cases): a single-case command names the keys it does not use in one note line
  (``piv.pixels`` in ``rimcl render``) and goes on. ``rimcl study`` uses every planar key
  (``run.mode`` picks which).

A key left at its default changes nothing wherever it is ignored, so complete scenes
(``--print-default-scene``, a study's ``scene.toml``) run everywhere.
"""

from rimcl.core.errors import RimclError
from rimcl.scene.keys import SCENE_KEYS

#: Command tags: the planar ``study`` (PTV/PIV modes), ``render``, ``piv`` (``piv render``
#: and ``piv sequence``), ``trace``, and ``lpt`` (``lpt run``, ``lpt render`` and
#: ``study`` with ``run.mode = "lpt"``), with the names the messages and docs use.
COMMANDS = {
    "study": "rimcl study (ptv, piv, both)",
    "render": "rimcl render",
    "piv": "rimcl piv render/sequence",
    "trace": "rimcl trace",
    "lpt": "rimcl lpt run/render, rimcl study --mode lpt",
}
PLANAR = frozenset({"study", "render", "piv", "trace"})
VOLUME = frozenset({"lpt"})
_ALL = PLANAR | VOLUME
_IMAGING = frozenset({"study", "render", "piv", "lpt"})  # commands that make images

#: The commands using each section's keys ...
_SECTION_USERS = {
    "field": _ALL,
    "time": frozenset({"study", "render", "lpt"}),
    "cases": _ALL,
    "tracers": _ALL,
    "camera": frozenset({"study", "render", "piv"}),
    "renderer": frozenset({"study", "render"}),
    "integrator": _ALL,
    "sensor": _IMAGING,
    "mie": _IMAGING,
    "fluid": _ALL,
    "run": _ALL,
    "piv": frozenset({"study", "piv"}),
    "rig": VOLUME,
    "illumination": VOLUME,
    "lpt": VOLUME,
}
#: ... and the keys used by fewer (or other) commands than their section.
_KEY_USERS = {
    "field.box": frozenset({"study", "render", "piv"}),
    "field.x_sheet": PLANAR,
    "field.depth": PLANAR,
    "field.length_m": _IMAGING,
    "field.time_s": _IMAGING,
    "field.velocity_m_s": _IMAGING,
    "time.dt_multiples": frozenset({"study"}),
    "cases.thresholds": frozenset({"study", "render"}),
    "tracers.count": frozenset({"study", "render", "trace", "lpt"}),
    "tracers.margin": frozenset({"study", "render"}),
    "camera.fan": frozenset({"study", "render", "trace"}),
    "camera.pupil_rays": frozenset({"study", "render"}),
    "run.engine": _IMAGING,
    "run.numerics": frozenset({"study"}),
    "run.sensitivity": frozenset({"study"}),
    "run.ray_sample": frozenset({"study", "render"}),
    "run.rays_per_batch": _IMAGING,
    "run.scheduler": frozenset({"study"}),
    "run.shard_tracers": frozenset({"study"}),
}
_LENS_ONLY = (
    "focal_length_mm",
    "magnification",
    "working_distance_mm",
    "pixel_pitch_um",
    "sensor_pixels",
    "window_thickness_mm",
    "window_index",
    "outside_index",
)
#: Keys only some cameras use (``camera.kind``), in the commands that build the camera.
CAMERA_KINDS = {
    "renderer.pixels": ("plane", "pupil"),
    "piv.pixels": ("plane", "pupil"),
    "camera.fan": ("plane",),
    "camera.pupil_rays": ("pupil", "lens"),
    "camera.aperture_diameter": ("pupil",),
    "camera.focal_length": ("pupil",),
    "camera.f_number": ("pupil", "lens"),
    "camera.distance": ("pupil",),
    "camera.view_angle": ("pupil",),
    **{f"camera.{name}": ("lens",) for name in _LENS_ONLY},
}
#: What sets instead what a key sets for the other cameras.
_INSTEAD = {
    "renderer.pixels": "the lens camera's images are camera.sensor_pixels",
    "piv.pixels": "the lens camera's frames are camera.sensor_pixels",
}
#: Longest list of key names in one line (the rest are counted).
_LISTED = 8


def users(key):
    """The command tags (:data:`COMMANDS`) that use a scene key.

    Parameters
    ----------
    key : rimcl.scene.key.SceneKey or str
        A key or its dotted name.

    Returns
    -------
    frozenset of str
    """
    dotted = key if isinstance(key, str) else key.dotted
    return _KEY_USERS.get(dotted, _SECTION_USERS[dotted.split(".", 1)[0]])


def command_tag(command, scene):
    """The tag of ``command`` on ``scene``: ``study`` is ``lpt`` with ``run.mode = "lpt"``."""
    if command == "study" and scene["run"]["mode"] == "lpt":
        return "lpt"
    return command


def _listed(names):
    shown = ", ".join(names[:_LISTED])
    return shown + (f" and {len(names) - _LISTED} more" if len(names) > _LISTED else "")


def _them(names):
    return "it" if len(names) == 1 else "them"


def _who(names):
    """The commands that do use ``names``, for a message."""
    tags = set().union(*(users(name) for name in names))
    return ", ".join(COMMANDS[tag] for tag in COMMANDS if tag in tags)


def _sources(names, given):
    """Where ``names`` were set: ``scene.toml and the options``."""
    return " and ".join(dict.fromkeys(given[name] for name in names))


def _default(key, scene):
    """The value a scene gets without ``key``: its default, but for ``field.time_s`` of the
    shipped sample the sample's own time scale (a study's ``scene.toml`` records it)."""
    if key.dotted == "field.time_s" and not scene["field"]["path"]:
        from rimcl.fields.field_reader import recorded_scales
        from rimcl.fields.sample import sample_path

        return recorded_scales(sample_path()).get("time_s")
    return key.default


def check_use(scene, given, command):
    """Refuse the keys a command's kind never uses; name those the command alone ignores.

    Parameters
    ----------
    scene : dict
        The checked scene (:func:`rimcl.scene.validate.validate_scene`).
    given : dict of str to str
        Dotted name of each key the scene file, preset or options set, to where it was set
        (``"scene.toml"``, ``"the options"``).
    command : str
        A tag of :data:`COMMANDS` (``study``: decided by ``run.mode``).

    Returns
    -------
    str or None
        A note naming the keys the command ignores (planar single-case commands), or None.

    Raises
    ------
    RimclError
        Naming every key set away from its default that no command of this kind uses.
    """
    if command not in COMMANDS:
        raise ValueError(f"unknown command {command!r}")
    tag = command_tag(command, scene)
    kind = VOLUME if tag in VOLUME else PLANAR
    changed = [
        key.dotted
        for key in SCENE_KEYS
        if key.dotted in given and scene[key.section][key.name] != _default(key, scene)
    ]
    foreign = [name for name in changed if not users(name) & kind]
    if foreign:
        name = {"study": f"rimcl study --mode {scene['run']['mode']}", "lpt": "rimcl lpt"}
        name = name.get(command, COMMANDS[command])
        them = _them(foreign)
        raise RimclError(
            f"{name} does not use {_listed(foreign)} (set in {_sources(foreign, given)}; used by "
            f"{_who(foreign)}): remove {them}, or run a command that uses {them}"
        )
    notes = [] if tag in ("lpt", "trace") else _camera_notes(scene, given, changed, tag)
    ignored = [name for name in changed if tag not in users(name)]
    if ignored and tag != "study":
        notes.insert(
            0,
            f"note: {COMMANDS[tag]} does not use {_listed(ignored)} "
            f"(set in {_sources(ignored, given)}; used by {_who(ignored)})",
        )
    return "\n".join(notes) or None


def _camera_notes(scene, given, changed, tag):
    """Refuse the options the scene's camera does not use; note such keys of a file."""
    kind = scene["camera"]["kind"]
    unused = [
        name
        for name, kinds in CAMERA_KINDS.items()
        if name in given and kind not in kinds and tag in users(name)
    ]
    from_options = [name for name in unused if given[name] == "the options"]
    if from_options:
        instead = "; ".join(_INSTEAD[name] for name in from_options if name in _INSTEAD)
        raise RimclError(
            f"the {kind} camera (camera.kind) does not use {_listed(from_options)}, given in "
            f"the options{'; ' + instead if instead else ''}: drop {_them(from_options)}, or "
            "choose a camera that uses " + _them(from_options)
        )
    in_file = [name for name in unused if name in changed]
    if not in_file:
        return []
    return [
        f"note: the {kind} camera (camera.kind) does not use {_listed(in_file)} "
        f"(set in {_sources(in_file, given)})"
    ]
