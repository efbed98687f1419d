"""The one case a single-case command (``rimcl render``, ``rimcl piv render``,
``rimcl trace``) measures from a scene.

Every command starts from the same scene (:mod:`rimcl.scene.keys`); ``rimcl study`` runs all
of ``cases.names``, the single-case commands one of them.
"""

from rimcl.fields.field_loading import case_arguments


def command_case(scene, case=None, k_rho=None):
    """The case of a single-case command: the one asked for, else the scene's first case
    that is not the uniform medium ``C0`` (the default scene: ``C1``, air).

    A field file storing ``delta_n`` carries its own refractive index and takes no case
    (:func:`rimcl.fields.field_loading.case_arguments`).

    Parameters
    ----------
    scene : dict
        A checked scene (:func:`rimcl.scene.load.load_scene`).
    case : str, optional
        ``--case``.
    k_rho : float, optional
        ``--k-rho`` (the Gladstone–Dale product G).

    Returns
    -------
    case, k_rho : str or None, float or None
    """
    from rimcl.fields.field_reader import field_kind
    from rimcl.fields.sample import sample_path

    path = scene["field"]["path"] or None
    if case is None and k_rho is None and field_kind(path or sample_path()) != "delta_n":
        names = scene["cases"]["names"]
        case = next((name for name in names if name != "C0"), names[0])
    return case_arguments(path, case, k_rho)
