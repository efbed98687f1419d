"""The error blocks of one case: refraction, baseline, noise floor, optics and imaging parts.

Each block summarises, per kinematic group of the render file (``velocity``,
``acceleration`` and the ``_fit`` ones), the relative errors of the components, the magnitude
and the direction (:func:`vector_errors`), and for the refraction and budget blocks the
position error as well.
"""

import numpy as np

from rimcl.stats.render_file import FLOOR_COLUMNS, KINEMATIC_GROUPS, OPTICS_COLUMNS
from rimcl.stats.summaries import error_summary, finite_or_none, position_summary
from rimcl.stats.tables import angle_deg, position_error_vectors, rows_of


def vector_errors(table, symbol, measured, reference, bootstrap):
    """Relative-error summaries of one vector quantity: components, magnitude, angle.

    ``measured`` and ``reference`` are the vectors ``(v2, v3)`` compared; the error is
    their difference and the truth (denominator) is always the ``true`` column.
    """
    true = (table[f"{symbol}2_true"], table[f"{symbol}3_true"])
    ids = table["id"]
    angles = angle_deg(measured, reference)
    return {
        f"{symbol}2": error_summary(measured[0] - reference[0], true[0], ids, bootstrap),
        f"{symbol}3": error_summary(measured[1] - reference[1], true[1], ids, bootstrap),
        "magnitude": error_summary(
            np.hypot(*measured) - np.hypot(*reference), np.hypot(*true), ids, bootstrap
        ),
        "angle_deg_median": finite_or_none(np.median(angles)) if angles.size else None,
    }


def vector_columns(table, symbol, kind):
    return (table[f"{symbol}2_{kind}"], table[f"{symbol}3_{kind}"])


def _empty_kinematic(symbol):
    """A kinematic table with no rows (a render file of too few frames)."""
    names = ["id", *(f"{symbol}{c}_{k}" for c in "23" for k in ("true", "ref", "meas"))]
    return {name: np.zeros(0) for name in names}


def _has_optics(table, symbol):
    return all(name in table for name in OPTICS_COLUMNS[symbol])


def kinematic_blocks(tables, kept):
    """``{group: (symbol, kept rows)}`` of the kinematic groups the file holds."""
    blocks = {}
    for group, symbol, _, needed_from in KINEMATIC_GROUPS:
        table = getattr(tables, group)
        if table:
            blocks[group] = (symbol, rows_of(table, kept))
        elif needed_from is not None:
            blocks[group] = (symbol, _empty_kinematic(symbol))
    return blocks


def budget_part(tracers, blocks, length, pixel_size, bootstrap, part):
    """The ``optics`` or ``imaging`` block: position and kinematic errors of that part."""
    optical = position_error_vectors(tracers, "opt", "opt_ref")
    if part == "optics":
        position = optical
    else:
        total = position_error_vectors(tracers)
        position = (total[0] - optical[0], total[1] - optical[1])
    block = position_summary(position, tracers["id"], length, pixel_size, bootstrap)
    for group, (symbol, table) in blocks.items():
        if not _has_optics(table, symbol):
            continue
        opt, opt_ref = (
            vector_columns(table, symbol, "opt"),
            vector_columns(table, symbol, "opt_ref"),
        )
        if part == "optics":
            measured, reference = opt, opt_ref
        else:
            # the error the camera adds (total minus optics), on top of the reference
            reference = vector_columns(table, symbol, "ref")
            meas = vector_columns(table, symbol, "meas")
            measured = tuple(
                m - (o - o_ref) for m, o, o_ref in zip(meas, opt, opt_ref, strict=True)
            )
        block[group] = vector_errors(table, symbol, measured, reference, bootstrap)
    return block


def refraction_errors(tables, tracers, blocks, bootstrap):
    """Position summary and per kinematic group the refraction errors (``meas - ref``)."""
    errors = position_summary(
        position_error_vectors(tracers), tracers["id"], tables.length, tables.pixel_size, bootstrap
    )
    for group, (symbol, table) in blocks.items():
        errors[group] = vector_errors(
            table,
            symbol,
            vector_columns(table, symbol, "meas"),
            vector_columns(table, symbol, "ref"),
            bootstrap,
        )
    return errors


def noise_floor(tables, tracers, blocks, bootstrap):
    """The ``noise_floor`` block: two independent exposures through the uniform medium.

    The reference against its second exposure (``<q>_floor - <q>_ref``): what the sensor's
    noise alone moves a position, velocity or acceleration, located and differenced as
    every other block. None where the render file has no floor columns (an older file).
    """
    if not all(name in tracers for name in FLOOR_COLUMNS["x"]):
        return None
    block = position_summary(
        position_error_vectors(tracers, "floor", "ref"),
        tracers["id"],
        tables.length,
        tables.pixel_size,
        bootstrap,
    )
    for group, (symbol, table) in blocks.items():
        if all(name in table for name in FLOOR_COLUMNS[symbol]):
            block[group] = vector_errors(
                table,
                symbol,
                vector_columns(table, symbol, "floor"),
                vector_columns(table, symbol, "ref"),
                bootstrap,
            )
    return block
