"""Loading a field file as a :class:`rimcl.Field` in one call (:func:`load_field`), and
the case or Gladstone–Dale product a file takes (:func:`case_arguments`).
"""

from rimcl.core.errors import RimclError
from rimcl.fields.field_reader import FieldFile, field_kind

#: The Gladstone–Dale case of a density file when none is given (air).
DEFAULT_CASE = "C1"


def case_arguments(path=None, case=None, k_rho=None):
    """The ``case`` and ``k_rho`` to use with a field file, from its metadata.

    A file storing ``delta_n`` carries its own refractive index and takes neither (giving
    one is refused); a density file takes the given case or ``K*rho``, else
    :data:`DEFAULT_CASE`.

    Parameters
    ----------
    path : str or Path, optional
        Field file; None is the shipped sample.
    case : str, optional
    k_rho : float, optional

    Returns
    -------
    case, k_rho : str or None, float or None
    """
    if path is None:
        from rimcl.fields.sample import sample_path

        path = sample_path()
    if field_kind(path) == "delta_n":
        if case is not None or k_rho is not None:
            raise RimclError(
                f"{path} stores delta_n (its own refractive index); a case or K*rho does not apply"
            )
        return None, None
    if case is None and k_rho is None:
        return DEFAULT_CASE, None
    return case, k_rho


def load_field(path=None, frame=0, *, k_rho=None, case=None, time=None):
    """Load one frame (or a time between frames) of a field file as a :class:`rimcl.Field`.

    Parameters
    ----------
    path : str or Path, optional
        A rimcl field file; None loads the shipped sample (:func:`rimcl.flow.sample_path`).
    frame : int
        Stored frame (ignored when ``time`` is given).
    k_rho : float, optional
        Gladstone–Dale product ``G``; or give ``case``. Needed for density files.
    case : str, optional
        ``"C0"`` … ``"C4"`` (see :data:`rimcl.fields.cases.CASES`).
    time : float, optional
        Interpolate in time between stored frames (linear; cubic with 4+ frames).

    Returns
    -------
    rimcl.Field
    """
    if path is None:
        from rimcl.fields.sample import sample_path

        path = sample_path()
    with FieldFile(path) as ff:
        if time is not None:
            return ff.field_at(time, k_rho, case=case)
        return ff.field(frame, k_rho, case=case)
