"""The one exception type for user-facing errors.

Library code raises :class:`RimclError` for bad input or an unusable environment; the
CLI turns it into one clear error line and a non-zero exit.
"""


class RimclError(Exception):
    """A problem the user can fix: bad input, a missing device, an unwritable output."""


def first_line(exc):
    """The first line of an exception's text, or its type name if it has none (HDF5, zip
    and NumPy errors often span several lines)."""
    lines = str(exc).strip().splitlines()
    return lines[0] if lines else type(exc).__name__
