"""The one exception type for user-facing errors.

Library code raises :class:`RimclError` for bad input or an unusable environment; the
CLI turns it into one clear error line and a non-zero exit.
"""


class RimclError(Exception):
    """A problem the user can fix: bad input, a missing device, an unwritable output."""
