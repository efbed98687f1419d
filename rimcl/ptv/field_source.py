"""The field a measurement reads and the refractive index each case makes of it.

:func:`open_source` opens a field file (or takes an open reader); :func:`case_of` turns a
case name or Gladstone–Dale product into a :class:`CaseIndex`, which yields each frame's
refractive-index field (a density file through ``n = 1 + G ρ`` or a fluid's ``n(T)``/``n(S)``;
a ``delta_n`` file as stored). :func:`uniform_like` and :func:`reference_step` give the
uniform medium and integration step of the reference images, shared by PTV and PIV.
"""

import dataclasses
import math
from pathlib import Path

import numpy as np

from rimcl.core.errors import RimclError
from rimcl.fields.field import Field
from rimcl.fields.media import index_from_density
from rimcl.optics.trace import default_step


def open_source(field, stack):
    """A field file reader: from a path, the shipped sample (None), or an open reader."""
    if field is None:
        from rimcl.fields.sample import sample_path

        field = sample_path()
    if isinstance(field, (str, Path)):
        from rimcl.fields.field_reader import FieldFile

        return stack.enter_context(FieldFile(field)), str(Path(field).resolve())
    path = getattr(field, "path", None)
    return field, "<in memory>" if path is None else str(Path(path).resolve())


@dataclasses.dataclass(frozen=True)
class CaseIndex:
    """How one case turns the field file into refractive index.

    Attributes
    ----------
    name : str
        ``C0``…``C4``, ``G=…``, ``dT=…``/``dS=…`` or ``delta_n``.
    g : float
        Gladstone–Dale product (NaN for ``delta_n`` files and fluid cases).
    fluid : rimcl.fields.media.Fluid, optional
        For a fluid case: the fluid whose ``n(T)`` or ``n(S)`` maps the density.
    difference : float
        ``ΔT`` (K) or ``ΔS`` (g/kg) of a fluid case.
    light, heavy : float
        The field's two dimensionless densities (fluid cases).
    """

    name: str
    g: float
    fluid: object = None
    difference: float = 0.0
    light: float = 1.0
    heavy: float = 1.105

    def mean_index(self, source, frame, time):
        """The case's mean refractive index at a frame: what a camera is focused through
        and what surrounds the tracers (Mie)."""
        return float(self.field(source, frame, time).n_ref)

    def field(self, source, frame, time):
        """The field of a stored frame, or interpolated in time when ``frame`` is None."""
        if self.fluid is None:
            return _load_frame(source, frame, time, self.g)
        if self.difference == 0:
            # a uniform fluid: straight rays at the fluid's index (which a wall refracts)
            return uniform_like(source, float(self.fluid.index()))
        # G = 1 gives δn = ρ - mean ρ and n_ref = 1 + mean ρ: the density, at any time
        unit = _load_frame(source, frame, time, 1.0)
        density = unit.delta_n.astype(np.float64) + (unit.n_ref - 1.0)
        index = index_from_density(
            density, self.fluid, self.difference, unit.gradient, self.light, self.heavy
        )
        return Field.from_arrays(
            index.delta_n,
            spacing=unit.spacing,
            origin=unit.origin,
            n_ref=index.n_ref,
            gradient=index.gradient,
            boundary=unit.boundary,
            attrs={**unit.attrs, "case": self.name},
        )


#: The case name of a field file that stores its own refractive index (runs as is).
DELTA_N_CASE = "delta_n"
#: A fluid case fits a density field whose values reach within this share of the light and
#: heavy densities' difference of either (the mixing sample: 1.0004 … 1.1023 of 1 … 1.105)
_DENSITY_FIT = 0.25


def case_of(source, case, k_rho, fluid_config):
    """The :class:`CaseIndex` of a case; files of δn carry their own index.

    A fluid case (``dT=``, ``dS=``) maps a density field's two fluids onto the fluid's
    ``n(T)`` or ``n(S)``: the light and heavy densities are the scene's
    (``fluid.light_density``, ``fluid.heavy_density``), else those the file records
    (``rho_light``, ``rho_heavy``), else 1 and 1.105. A field whose densities do not span
    them is refused, naming both, as is a fluid case on a file that stores its index.
    """
    from rimcl.fields.cases import fluid_case, resolve_k_rho

    if case is not None and str(case).strip() == DELTA_N_CASE:
        case = None
        if getattr(source, "kind", "density") != "delta_n":
            raise RimclError(
                f"case {DELTA_N_CASE} runs a field file that stores its refractive index; "
                f"{getattr(source, 'path', 'this field')} stores a density: give a case "
                "(C0..C4, G=<value>, dT=<K>, dS=<g/kg>)"
            )
    if getattr(source, "kind", "density") == "delta_n":
        if case is not None or k_rho is not None:
            scalar = getattr(source, "attrs", {}).get("scalar", "delta_n")
            raise RimclError(
                f"{getattr(source, 'path', 'this field file')} holds a {scalar} field as its "
                f"refractive index: it runs as is (case {DELTA_N_CASE}); case "
                f"{case if case is not None else f'K*rho={k_rho}'} does not apply"
            )
        return CaseIndex(DELTA_N_CASE, float("nan"))
    difference = None if case is None else fluid_case(case)
    if difference is None:
        return CaseIndex(*resolve_k_rho(case, k_rho))
    fluid = fluid_config.build()
    if fluid is None:
        raise RimclError(f"case {case} needs a fluid: set [fluid] kind (water, air, saltwater)")
    quantity, value = difference
    if (quantity == "salinity") != (fluid.kind == "saltwater"):
        raise RimclError(
            f"case {case}: a {fluid.kind} case varies the {fluid.unit}, not {quantity}"
        )
    light, heavy = fluid_densities(source, fluid_config)
    check_density_fit(source, case, light, heavy)
    return CaseIndex(str(case).strip(), float("nan"), fluid, value, light, heavy)


def fluid_densities(source, fluid_config):
    """The light and heavy densities of a fluid case: the scene's, else the file's, else
    1 and 1.105 (:data:`rimcl.fields.media.MIXING_DENSITIES`)."""
    from rimcl.fields.media import MIXING_DENSITIES

    attrs = getattr(getattr(source, "source", source), "attrs", None) or {}
    pairs = (
        (fluid_config.light_density, fluid_config.heavy_density),
        (attrs.get("rho_light"), attrs.get("rho_heavy")),
        MIXING_DENSITIES,
    )
    chosen = [next(float(p[k]) for p in pairs if p[k] is not None) for k in (0, 1)]
    if not chosen[1] > chosen[0]:
        raise RimclError(
            f"the heavy density ({chosen[1]:g}) must exceed the light one ({chosen[0]:g})"
        )
    return tuple(chosen)


def check_density_fit(source, case, light, heavy):
    """Refuse a fluid case on a density field whose values do not span ``light … heavy``.

    The field's range is the file's recorded ``scalar_range`` or that of its first frame.
    """
    whole = getattr(source, "source", source)  # a box cut of a file: the whole file
    recorded = (getattr(whole, "attrs", None) or {}).get("scalar_range")
    if recorded is not None and len(recorded) == 2:
        lo, hi = (float(v) for v in recorded)
    else:
        density = whole.density(0)
        lo, hi = float(np.min(density)), float(np.max(density))
    slack = _DENSITY_FIT * (heavy - light)
    if lo < light - slack or hi > heavy + slack or (hi - lo) < (heavy - light) - 2 * slack:
        raise RimclError(
            f"case {case}: the field's densities ({lo:.6g} … {hi:.6g}) do not fit the fluid "
            f"model's light and heavy fluids ({light:.6g} and {heavy:.6g}); set "
            "fluid.light_density and fluid.heavy_density to the field's two fluids, or "
            "import the temperature or salinity itself (rimcl field import)"
        )


def _load_frame(source, frame, time, k_rho):
    """The field of a stored frame, or interpolated in time when ``frame`` is None."""
    arguments = () if math.isnan(k_rho) else (k_rho,)
    if frame is None:
        return source.field_at(time, *arguments)
    return source.field(frame, *arguments)


def uniform_like(source, n_ref=1.0):
    """A uniform field (index ``n_ref``) with the grid's extent and boundary, on 2 nodes per axis.

    Tracing through it gives the same floats as through a zero δn on the full grid (the
    interpolated δn and ∇n are exactly 0 either way), without a full-size copy.
    """
    spacing = np.asarray(source.spacing, dtype=np.float64)
    counts = np.asarray(source.shape)[::-1]
    periodic = source.boundary == "periodic"
    extent = spacing * (counts if periodic else counts - 1)
    return Field.from_arrays(
        np.zeros((2, 2, 2), dtype=np.float32),
        spacing=extent / 2 if periodic else extent,
        origin=source.origin,
        n_ref=float(n_ref),
        gradient=np.zeros((2, 2, 2, 3), dtype=np.float32),
        boundary=source.boundary,
    )


def reference_step(step, source):
    """The step of the reference traces: the one the user gave, or the tracer's default
    for this grid at n = 1 (what a zero-G case of the same grid uses)."""
    if step is not None:
        return float(step)
    probe = Field.from_arrays(
        np.zeros((2, 2, 2), dtype=np.float32),
        spacing=source.spacing,
        n_ref=1.0,
        gradient=np.zeros((2, 2, 2, 3), dtype=np.float32),
    )
    return default_step(probe)
