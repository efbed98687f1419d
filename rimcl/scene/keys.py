"""Every key of a scene file, in the order of the printed default scene, and their defaults.

The table is assembled from one module per group of sections (:mod:`rimcl.scene.keys_imaging`,
:mod:`rimcl.scene.keys_physics`, :mod:`rimcl.scene.keys_run`, :mod:`rimcl.scene.keys_lpt`).
"""

import copy

from rimcl.scene.keys_imaging import imaging_keys
from rimcl.scene.keys_lpt import lpt_keys
from rimcl.scene.keys_physics import physics_keys
from rimcl.scene.keys_run import piv_keys, run_keys

#: Every key of a scene file, in the order of the printed default scene.
SCENE_KEYS = (*imaging_keys(), *physics_keys(), *run_keys(), *piv_keys(), *lpt_keys())
SECTIONS = tuple(dict.fromkeys(key.section for key in SCENE_KEYS))
KEYS_BY_NAME = {key.dotted: key for key in SCENE_KEYS}


def default_scene():
    """The scene with every key at its default.

    Returns
    -------
    dict of str to dict
        ``{section: {key: value}}``; ``None`` where the pipeline decides.
    """
    scene = {section: {} for section in SECTIONS}
    for key in SCENE_KEYS:
        scene[key.section][key.name] = copy.deepcopy(key.default)
    return scene
