"""Flow data: the field file, the built-in Boussinesq solver, JHTDB import, the sample.

Submodules: :mod:`~rimcl.fields.cases` (Gladstone–Dale cases), the field file's
:mod:`~rimcl.fields.field_layout`, :mod:`~rimcl.fields.field_reader`,
:mod:`~rimcl.fields.field_writer` and :mod:`~rimcl.fields.field_loading`,
:mod:`~rimcl.fields.synth` (``rimcl field synth``),
:mod:`~rimcl.fields.jhtdb` (``rimcl field import``), :mod:`~rimcl.fields.plot`
(``rimcl field show``).
"""

from importlib import resources

from rimcl.core.errors import RimclError

#: File name of the shipped sample inside the ``rimcl.samples`` package.
SAMPLE_NAME = "mixing64.h5"
#: Metres per field length unit of the shipped sample as the default scene sees it: its 2π
#: box is the field of view of a 2048-px sensor of 6.5 µm pixels at M = 0.2 (66.6 mm).
SAMPLE_LENGTH_M = 2048 * 6.5e-6 / 0.2 / (2 * 3.141592653589793)


def sample_path():
    """Path of the shipped sample field (64³ synthetic buoyancy-driven turbulence).

    Found through :mod:`importlib.resources`, so it works from a checkout, an editable
    install and a wheel.

    Returns
    -------
    str
    """
    sample = resources.files("rimcl.samples").joinpath(SAMPLE_NAME)
    if not sample.is_file():
        raise RimclError(
            f"the shipped sample {SAMPLE_NAME} is missing from the rimcl.samples package; "
            "regenerate it as data_samples/README.md says"
        )
    return str(sample)
