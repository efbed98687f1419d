"""A box cut out of a field file, read as a field file of its own (clamped boundary).

The paper traced a 512³ eighth of the 1024³ JHTDB box; :class:`CroppedSource` gives the
same kind of cut of any rimcl field file (a π³ eighth of the shipped 2π sample, say)
without writing a new file. Fields are computed on the whole grid first and then cut, so
spectral gradients of a periodic box stay exact inside the cut; outside it the cut is
clamped, as a finite DNS cut-out is.
"""

import numpy as np

from rimcl.core.errors import RimclError
from rimcl.fields.field import Field

_AXES = ("x1", "x2", "x3")


class CroppedSource:
    """The nodes of ``source`` inside an axis-aligned box.

    Parameters
    ----------
    source : FieldFile
        An open field file (or anything with its interface).
    box : sequence of 3 (lo, hi) pairs
        Extent along ``x1, x2, x3`` (field length units); nodes within ``[lo, hi]`` are
        kept (to 1e-9 of a cell), at least 2 per axis.
    """

    def __init__(self, source, box):
        self.source = source
        box = np.asarray(box, dtype=np.float64)
        if box.shape != (3, 2) or not np.all(np.isfinite(box)) or np.any(box[:, 1] <= box[:, 0]):
            raise RimclError(
                f"field.box must be three [lo, hi] pairs with lo < hi (x1, x2, x3), got "
                f"{box.tolist()}"
            )
        origin = np.asarray(source.origin, dtype=np.float64)
        spacing = np.asarray(source.spacing, dtype=np.float64)
        counts = np.asarray(source.shape)[::-1]
        first = np.ceil((box[:, 0] - origin) / spacing - 1e-9).astype(int)
        last = np.floor((box[:, 1] - origin) / spacing + 1e-9).astype(int)
        for axis in range(3):
            if first[axis] < 0 or last[axis] >= counts[axis] or last[axis] - first[axis] < 1:
                hi = origin[axis] + (counts[axis] - 1) * spacing[axis]
                raise RimclError(
                    f"field.box along {_AXES[axis]} ({box[axis, 0]:g} .. {box[axis, 1]:g}) "
                    f"must hold at least 2 nodes of the grid ({origin[axis]:g} .. {hi:g})"
                )
        # (n3, n2, n1) array slices of the kept nodes
        self._slices = tuple(slice(first[a], last[a] + 1) for a in (2, 1, 0))
        self.origin = origin + first * spacing
        self.spacing = spacing
        self.shape = tuple(int(last[a] - first[a] + 1) for a in (2, 1, 0))
        self.boundary = "clamp"
        self.box = box

    @property
    def path(self):
        return self.source.path

    @property
    def kind(self):
        return getattr(self.source, "kind", "density")

    @property
    def times(self):
        return self.source.times

    @property
    def n_frames(self):
        return self.source.n_frames

    @property
    def has_velocity(self):
        return self.source.has_velocity

    def field(self, frame=0, k_rho=None):
        """The refractive-index field of one frame, cut to the box.

        ``n_ref`` stays the whole grid's, so ``n`` itself is unchanged by the cut.
        """
        whole = self.source.field(frame) if k_rho is None else self.source.field(frame, k_rho)
        return self._cut(whole)

    def _cut(self, whole):
        cut = (*self._slices, slice(None))
        return Field.from_arrays(
            whole.delta_n[self._slices],
            spacing=whole.spacing,
            origin=self.origin,
            n_ref=whole.n_ref,
            gradient=whole.gradient[cut],
            boundary="clamp",
            attrs={**whole.attrs, "box": self.box.tolist()},
        )

    def field_at(self, time, k_rho=None):
        """The field at any time within the stored frames (interpolated), cut to the box."""
        arguments = () if k_rho is None else (k_rho,)
        return self._cut(self.source.field_at(time, *arguments))

    def sheet_velocity(self, time, x1):
        """In-plane velocity on the sheet, cut to the box: shape (n3, n2, 2)."""
        return self.source.sheet_velocity(time, x1)[self._slices[0], self._slices[1]]

    def describe(self):
        return {"box": self.box.tolist(), "shape_n3_n2_n1": list(self.shape)}


class StridedSource:
    """Every ``stride``-th node of ``source`` along each axis: the same flow on a coarser
    grid (the paper's Appendix A compares two grid resolutions).

    The field and its gradient are computed on the full grid and then sampled, so the
    coarse grid carries exact node values; only the interpolation between nodes is coarser.
    A periodic box keeps its period (its node count must divide by ``stride``).
    """

    def __init__(self, source, stride=2):
        stride = int(stride)
        counts = np.asarray(source.shape)
        if stride < 1:
            raise RimclError(f"the grid stride must be at least 1, got {stride}")
        if source.boundary == "periodic" and np.any(counts % stride):
            raise RimclError(
                f"a periodic grid of {tuple(counts)} nodes does not divide by {stride}"
            )
        self.source = source
        self.stride = stride
        self._slices = (slice(None, None, stride),) * 3
        self.origin = np.asarray(source.origin, dtype=np.float64)
        self.spacing = np.asarray(source.spacing, dtype=np.float64) * stride
        self.shape = tuple(len(range(0, int(n), stride)) for n in counts)
        self.boundary = source.boundary
        if min(self.shape) < 2:
            raise RimclError(f"stride {stride} leaves fewer than 2 nodes along an axis")

    path = CroppedSource.path
    kind = CroppedSource.kind
    times = CroppedSource.times
    n_frames = CroppedSource.n_frames
    has_velocity = CroppedSource.has_velocity
    field = CroppedSource.field
    field_at = CroppedSource.field_at

    def _cut(self, whole):
        return Field.from_arrays(
            whole.delta_n[self._slices],
            spacing=self.spacing,
            origin=self.origin,
            n_ref=whole.n_ref,
            gradient=whole.gradient[(*self._slices, slice(None))],
            boundary=self.boundary,
            attrs={**whole.attrs, "stride": self.stride},
        )

    def sheet_velocity(self, time, x1):
        """The sheet velocity on the coarse nodes: shape (n3, n2, 2)."""
        return self.source.sheet_velocity(time, x1)[:: self.stride, :: self.stride]

    def describe(self):
        return {"stride": self.stride, "shape_n3_n2_n1": list(self.shape)}
