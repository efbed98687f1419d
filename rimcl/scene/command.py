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


def place_sheet(scene, report=None):
    """The scene, its field able to move tracers on its sheet wherever the sheet is.

    The shipped sample stores its velocity only on ``x1 = 0``; a scene that puts the
    sheet (``field.x_sheet``) elsewhere on it runs instead on the same built-in flow with
    full velocity, generated once and cached
    (:func:`rimcl.fields.full_sample.full_velocity_sample`). Any other scene is returned
    as is (a user's file without the velocity there is refused where it is read).

    Parameters
    ----------
    scene : dict
        A checked scene; ``field.path`` is replaced in place when needed.
    report : callable, optional
        Told in one line when the flow is generated.

    Returns
    -------
    dict
    """
    from rimcl.core.errors import RimclError
    from rimcl.fields.field_reader import FieldFile
    from rimcl.fields.full_sample import full_velocity_sample
    from rimcl.fields.sample import sample_path

    field = scene["field"]
    if field["path"] or field["x_sheet"] is None:
        return scene
    with FieldFile(sample_path()) as sample:
        try:
            sample.sheet_velocity(sample.times[0], field["x_sheet"])
            return scene  # the stored plane (or a period away)
        except RimclError:
            pass
    field["path"] = str(full_velocity_sample(report=report))
    return scene
