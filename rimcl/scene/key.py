"""One key of a scene file: its section, name, default, type, meaning and limits.

:class:`SceneKey` describes a key; :func:`choices` gathers the allowed values of the keys
that name a method of a lower stage (camera, renderer, interpolation, ...), so the scene's
table and those stages cannot disagree.
"""

import dataclasses


@dataclasses.dataclass(frozen=True)
class SceneKey:
    """One key of a scene file.

    Attributes
    ----------
    section, name : str
        ``[section]`` and key name.
    default : object
        Value when the key is absent; ``None`` for keys whose default is decided by the
        pipeline (the printed scene shows them commented out, with ``example``).
    kind : {"str", "int", "float", "bool", "names", "thresholds", "box", "ints", "vector", \
            "floats", "tables"}
        ``names``: a list of strings; ``thresholds``: a table of case name to number;
        ``box``: three ``[lo, hi]`` pairs; ``ints``: a list of whole numbers >= 1;
        ``vector``: three numbers; ``floats``: a list of numbers; ``tables``: a list of
        tables (``[[section.name]]``, their keys checked by the stage using them).
    doc : str
        What the key means, with units.
    choices : tuple of str
        Allowed values of a ``str`` key (empty: any).
    minimum : float, optional
        Smallest allowed value of a number.
    positive : bool
        A number that must be strictly positive.
    example : object
        Value shown for a key whose default is ``None``.
    """

    section: str
    name: str
    default: object
    kind: str
    doc: str
    choices: tuple = ()
    minimum: float | None = None
    positive: bool = False
    example: object = None

    @property
    def dotted(self):
        return f"{self.section}.{self.name}"


def choices():
    """The allowed values of each ``str`` key that names a method, by kind of method."""
    from rimcl.imaging.centroid import CENTROID_WEIGHTS
    from rimcl.imaging.frames import SCALINGS, SPLIT_MODES
    from rimcl.imaging.render import RENDERERS
    from rimcl.optics.camera import CAMERAS
    from rimcl.optics.trace import INTERPOLATIONS, PRECISIONS
    from rimcl.scene.config import ENGINES

    return {
        "camera": CAMERAS,
        "weights": CENTROID_WEIGHTS,
        "renderer": RENDERERS,
        "interp": INTERPOLATIONS,
        "precision": PRECISIONS,
        "scale": SCALINGS,
        "split": SPLIT_MODES,
        "engine": ENGINES,
    }
