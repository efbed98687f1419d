"""How a study's summary writes numbers: significant digits, percentages, intervals, and
Markdown tables."""

import math


def significant(value, digits=3):
    """``value`` to ``digits`` significant digits, without an exponent between 1e-3 and
    1e6 (``2134`` reads ``2130``, not ``2.13e+03``)."""
    if value == 0 or not 1e-3 <= abs(value) < 1e6:
        return f"{value:.{digits}g}"
    decimals = digits - 1 - math.floor(math.log10(abs(value)))
    return f"{round(value, decimals):.{max(decimals, 0)}f}"


def percent(value):
    """A fraction as percent with 3 significant digits, ``n/a`` for ``None``."""
    return "n/a" if value is None else f"{significant(100 * value)} %"


def number(value):
    """A number with 3 significant digits, ``n/a`` for ``None``."""
    return "n/a" if value is None else f"{value:.3g}"


def with_interval(value, interval, scale=1.0, unit=""):
    """``value [lo, hi]``: 3 significant digits for the value, 2 for the interval's ends.

    Parameters
    ----------
    value : float or None
    interval : [float, float] or None
    scale : float
        Factor applied to all three (100 for percent).
    unit : str
        Appended after the interval (``" %"``).
    """
    if value is None:
        return "n/a"
    text = significant(scale * value)
    if interval is not None:
        text += f" [{significant(scale * interval[0], 2)}, {significant(scale * interval[1], 2)}]"
    return text + unit


def table(header, rows):
    """A Markdown table; a ``|`` inside a cell (``|ε_x|``) is escaped."""

    def line(cells):
        return "| " + " | ".join(cell.replace("|", "\\|") for cell in cells) + " |"

    return [line(header), "|" + "---|" * len(header), *(line(row) for row in rows)]


def percent_of(summary, key):
    return with_interval(summary[key], summary["ci95"][key], 100.0, " %")
