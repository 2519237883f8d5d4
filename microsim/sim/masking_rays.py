"""The masking rays of the single-bounce paths (``MaskingRays``: set up by a compiled pass,
walked by ``Tracer.escape_columns``) and the primary hits they start from (``primary_hits``)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .engine import primary, segments
from .ledger import MASKED, RAY_MISSED, RAY_UNRESOLVED, SINGLE
from .periodic_walk import TFAR_REL, ColumnHits
from .scratch import WorkArray, WorkColumns
from .tracer import ESCAPED, HIT, MISSED, UNRESOLVED, Tracer

__all__ = [
    "FROM_ESCAPE",
    "MaskingRays",
    "segment_geometry",
    "falling_first_segment",
    "primary_hits",
]

FROM_ESCAPE = np.zeros(4, dtype=np.int8)  # tracer status -> ledger class
FROM_ESCAPE[[HIT, ESCAPED, UNRESOLVED, MISSED]] = [MASKED, SINGLE, RAY_UNRESOLVED, RAY_MISSED]


def segment_geometry(tracer: Tracer) -> tuple:
    """(hx, hy, zmax, eps, rel): what ``segments.setup_ray`` needs of the tile."""
    return float(tracer.half[0]), float(tracer.half[1]), tracer.zmax, tracer.eps, TFAR_REL


@dataclass(frozen=True)
class MaskingRays:
    """The masking rays a compiled pass sets up (``primary.tabled_primary``/``traced_primary``),
    in this thread's work arrays: primary ray ``ray[m]`` of masking ray m, its start and
    direction columns (``start``, ``d``; float32 ``d32``) and the first segment's Embree input
    (``o32``, ``tfar``, ``keep``, ``top``)."""

    ray: np.ndarray
    start: list
    d: list
    d32: np.ndarray
    o32: np.ndarray
    tfar: np.ndarray
    keep: np.ndarray
    top: np.ndarray

    @classmethod
    def work(cls, n: int) -> "MaskingRays":
        """This thread's masking rays for ``n`` primary rays (``scratch``)."""
        return cls(*(declared(n) for declared in _MASKING_RAYS))

    def kernel_args(self) -> tuple:
        """The arrays in the kernels' argument order (mi, sx…sz, mdx…mdz, md32, o32, tq,
        keep, top)."""
        return (self.ray, *self.start, *self.d, self.d32, self.o32, self.tfar, self.keep, self.top)

    def trace(self, tracer: Tracer, m: int, status: np.ndarray) -> None:
        """Walk the first ``m`` masking rays (``Tracer.escape_columns``) and set the ledger
        class of their primary rays in ``status``."""
        if m == 0:
            return
        esc = tracer.escape_columns(
            [c[:m] for c in self.start],
            [c[:m] for c in self.d],
            self.d32[:m],
            first=(self.o32, self.tfar, self.keep, self.top),
        )
        primary.apply_escape(status, self.ray[:m], esc, FROM_ESCAPE)


# this thread's work arrays (``scratch``)
_MASKING_RAYS = (  # MaskingRays' fields, in order
    WorkArray("masking-ray", np.int64),
    WorkColumns("masking-start"),
    WorkColumns("masking-direction"),
    WorkArray("masking-d32", np.float32, columns=3),
    WorkArray("masking-o32", np.float32, columns=3),
    WorkArray("masking-tfar", np.float32),
    WorkArray("masking-keep", np.int64),
    WorkArray("masking-top", np.bool_),
)
_PRIMARY_SEGMENT = (  # falling_first_segment's (o32, tfar, keep, top)
    WorkArray("primary-o32", np.float32, columns=3),
    WorkArray("primary-tfar", np.float32),
    WorkArray("primary-keep", np.int64),
    WorkArray("primary-top", np.bool_),
)


def falling_first_segment(tracer: Tracer, x, down) -> tuple:
    """The first segment's Embree input (o32, tfar, keep, top) of rays from x (3 columns,
    inside the tile: ``Tracer.holds``) along falling directions ``down`` (3 floats: one
    shared; or 3 columns) (``segments.falling_first_segment``, vectorised), for
    ``Tracer.trace_columns(first=...)``; None (the walk sets them up) unless every start
    lies in the tile and every direction falls."""
    n = len(x[0])
    shared = np.isscalar(down[0])
    d = [np.array([float(c)]) for c in down] if shared else down
    if not (tracer.holds(x) and np.all(d[2] < 0)):
        return None
    first = tuple(declared(n) for declared in _PRIMARY_SEGMENT)
    segments.falling_first_segment(*x, *d, shared, *segment_geometry(tracer), *first)
    return first


def primary_hits(tracer: Tracer, x, down, d32) -> ColumnHits:
    """(status, prim, point columns) of primary rays from the starts ``x`` (3 columns) along
    falling ``down`` (3 floats shared by all, with ``d32`` its float32 (1, 3) copy; or 3
    columns and (N, 3)): by the heightfield grid walk where the tracer has one
    (``Tracer.cast_falling``), else by Embree with the first segment set up in one
    vectorised pass (``falling_first_segment``)."""
    if np.isscalar(down[0]):
        cast = tracer.cast_falling(x, down)
        if cast is not None:
            return cast
    first = falling_first_segment(tracer, x, down)
    return tracer.trace_columns(x, down, d32, first=first)
