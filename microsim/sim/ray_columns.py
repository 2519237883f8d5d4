"""The single-bounce tally passes: (status, weight, bin) per primary ray (``RayOutcome``) on
per-axis columns — traced (``trace_columns``), looked up in a facet table (``trace_tabled``)
or in the V-groove closed form (``analytic_columns``)."""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from microsim.bins import Bins
from microsim.jit import TILE

from . import fresnel_kernels, vgroove_kernels
from .drawn_primary import cast_drawn_tabled
from .engine import primary, segments
from .facet_tables import FacetTable
from .ledger import MASKED, SINGLE
from .masking_rays import FROM_ESCAPE, MaskingRays, primary_hits, segment_geometry
from .ray_bins import locate_single
from .scratch import WorkArray, WorkColumns
from .streams import BLOCK, StratifiedDraw
from .tracer import Tracer
from .vgroove_profile import GrooveMasking, VGrooveCaster

__all__ = [
    "RayOutcome",
    "TabledMasking",
    "columns",
    "GrooveFrameWork",
    "groove_frame_rays",
    "trace_columns",
    "tabled_masking_rays",
    "drawn_masking_rays",
    "trace_tabled",
    "analytic_columns",
]


class RayOutcome(NamedTuple):
    """What the tallies need of each primary ray: ``status`` (n,) int8 ledger class,
    ``weight`` (n,) Fresnel F(n·wi), ``bin`` (n,) int64 flat bin of wo or −1."""

    status: np.ndarray
    weight: np.ndarray
    bin: np.ndarray


class TabledMasking(NamedTuple):
    """``tabled_masking_rays``' answer: the ``outcome`` so far (the status of rays with a
    masking ray still SINGLE) and the first ``m`` of ``mask`` set up, not yet traced."""

    outcome: RayOutcome
    mask: MaskingRays
    m: int

    def traced(self, tracer: Tracer) -> RayOutcome:
        """The outcome once the masking rays are traced on ``tracer`` (their primaries'
        status set from their walks)."""
        self.mask.trace(tracer, self.m, self.outcome.status)
        return self.outcome


# this thread's work arrays (``scratch``)
_TRACED_WO = WorkColumns("traced-wo")
_TRACED_COSINE = WorkArray("traced-cosine")
_ANALYTIC_WO = WorkColumns("analytic-wo")
_ANALYTIC_TILE = WorkArray("analytic-tile", rows=15)  # ``analytic_vgroove``'s scratch
_ANALYTIC_NEAR = WorkArray("analytic-near", np.bool_)


def tabled_masking_rays(
    tracer: Tracer, table: FacetTable, wi: np.ndarray, origins
) -> TabledMasking:
    """``trace_tabled`` up to its masking rays (``TabledMasking``): the m masking rays set up
    but not yet traced (the status of their primary rays still SINGLE)."""
    x = columns(origins)
    wi = np.asarray(wi, dtype=np.float64)
    down = [float(-c) for c in wi]
    facets, ledger, mask = _tabled_work(table, len(x[0]))
    outcome = RayOutcome(*ledger)
    grid = tracer.grid_walk(x, down)
    if grid is not None:  # the grid walk fused with the look-ups, tile by tile
        m = primary.cast_tabled_primary(
            tuple(x), tuple(down), grid, table.ahead, facets, tracer.horizon,
            segment_geometry(tracer), ledger, mask.kernel_args(),
        )  # fmt: skip
        return TabledMasking(outcome, mask, m)
    hs, prim, p = primary_hits(tracer, x, down, (-wi).astype(np.float32)[None])
    walk = segments.WalkResult(hs, prim, *p)
    m = primary.tabled_primary(
        walk, facets, tracer.horizon, segment_geometry(tracer), ledger, mask.kernel_args()
    )
    return TabledMasking(outcome, mask, m)


_NO_STARTS = (np.empty(0),) * 3  # ``Tracer.grid_walk``'s starts when a kernel draws its own


def drawn_masking_rays(
    tracer: Tracer, table: FacetTable, wi: np.ndarray, draw: StratifiedDraw
) -> TabledMasking | None:
    """``tabled_masking_rays`` of the stratified rays of ``draw`` with their origins drawn in
    the grid walk's own pass (``drawn_primary.cast_drawn_tabled``): the same bits, the chunk's
    origins never written out. None where their grid walk does not apply (no grid, a rising
    direction, a start outside the tile): the caller traces their origin columns."""
    down = [float(-c) for c in wi]
    grid = tracer.grid_walk(_NO_STARTS, down)  # the kernel checks the starts it draws
    if grid is None:
        return None
    facets, ledger, mask = _tabled_work(table, draw.n)
    m = cast_drawn_tabled(
        draw, BLOCK, tuple(down), grid, table.ahead, facets, tracer.horizon,
        segment_geometry(tracer), ledger, mask.kernel_args(),
    )  # fmt: skip
    return None if m < 0 else TabledMasking(RayOutcome(*ledger), mask, m)


def _tabled_work(table: FacetTable, n: int) -> tuple:
    """The facet table as the kernels read it (``primary.FacetColumns``), a fresh
    ``primary.PrimaryLedger`` of n rays and the masking rays' work arrays for them."""
    facets = primary.FacetColumns(
        table.code, table.weight, table.facets, table.wo32, table.bin, table.clear
    )
    ledger = primary.PrimaryLedger(
        np.empty(n, dtype=np.int8), np.empty(n), np.empty(n, dtype=np.int64)
    )
    return facets, ledger, MaskingRays.work(n)


def trace_tabled(tracer: Tracer, table: FacetTable, wi: np.ndarray, origins) -> RayOutcome:
    """The ``RayOutcome`` of primary rays, looked up per hit facet in ``table`` (the fast
    path for surfaces without azimuth averaging: only the two ray casts are per ray, the rest
    is one compiled pass, ``primary.tabled_primary``). ``origins``: (N, 3) or 3 columns."""
    return tabled_masking_rays(tracer, table, wi, origins).traced(tracer)


def columns(origins) -> list:
    """Three contiguous float64 columns from an (N, 3) array or a sequence of 3 columns."""
    if isinstance(origins, np.ndarray):
        return [np.ascontiguousarray(origins[:, k], dtype=np.float64) for k in range(3)]
    return [np.ascontiguousarray(c, dtype=np.float64) for c in origins]


class GrooveFrameWork(NamedTuple):
    """The work arrays (``scratch``) of ``groove_frame_rays``: the rotated wi and the ray
    direction −wl (3 columns each) and its float32 (N, 3) copy."""

    wl: WorkColumns
    down: WorkColumns
    d32: WorkArray

    @classmethod
    def declare(cls, name: str) -> "GrooveFrameWork":
        return cls(
            WorkColumns(name + "-wl"),
            WorkColumns(name + "-down"),
            WorkArray(name + "-d32", np.float32, columns=3),
        )


_TRACED_FRAME = GrooveFrameWork.declare("traced-frame")


def groove_frame_rays(psi, wi, scratch: GrooveFrameWork) -> tuple:
    """Per ray, wi rotated by −ψ into its groove frame: (wl, down, d32) — the rotated wi and
    the ray direction −wl as 3 columns each and its float32 (N, 3) copy
    (``vgroove_kernels.groove_frame_directions``), in this thread's ``scratch`` arrays."""
    n = len(psi)
    wl, down, d32 = scratch.wl(n), scratch.down(n), scratch.d32(n)
    vgroove_kernels.groove_frame_directions(
        np.ascontiguousarray(psi, dtype=np.float64),
        np.asarray(wi, dtype=np.float64),
        *wl,
        *down,
        d32,
    )
    return wl, down, d32


def trace_columns(
    tracer: Tracer, profile: GrooveMasking | None, wi, phi_i, bins: Bins, origins, psi, ior
) -> RayOutcome:
    """The ``RayOutcome`` of primary rays — ``trace_events`` reduced to what the tallies
    need, on per-axis columns. ``psi`` None: one shared direction −wi. ``psi`` (N,)
    (``azimuth_average`` surfaces): each ray is traced in its groove frame (wi rotated by −ψ)
    and binned there too — Δφ = φo − φi is unchanged by the rotation, so wo is located against
    the rotated incident azimuth φi − ψ instead of being rotated back. After the primary walk
    one compiled pass (``primary.traced_primary``: Fresnel in real arithmetic, mirror
    direction, ledger class) sets up the masking rays (traced masking, ``profile`` None) or
    leaves them to ``profile`` (exact V-groove masking). On a heightfield grid with one
    shared direction and traced masking, the walk, that pass and the masking rays' walk go
    tile by tile in one kernel (``primary.cast_traced_primary``: the same bits)."""
    x = columns(origins)
    n = len(x[0])
    status, weight, where = np.empty(n, dtype=np.int8), np.empty(n), np.full(n, -1, np.int64)
    wo, cosine = _TRACED_WO(n), _TRACED_COSINE(n)
    ledger = primary.TracedLedger(status, cosine, *wo)
    if psi is None:
        wl = [np.array([float(c)]) for c in wi]  # one shared direction
        down = [-float(c) for c in wi]
        d32 = np.array([down], dtype=np.float32)
        grid = tracer.grid_walk(x, down) if profile is None else None
    else:
        wl, down, d32 = groove_frame_rays(psi, wi, _TRACED_FRAME)
        grid = None
    if grid is not None:  # walk, pass and masking rays tile by tile
        primary.cast_traced_primary(
            tuple(x), tuple(down), grid, tracer.grid.cell_min, tracer.facets,
            tracer.rise_bound, tracer.horizon, tracer.groove_clear, segment_geometry(tracer),
            ledger, MaskingRays.work(TILE).kernel_args(), FROM_ESCAPE,
        )  # fmt: skip
    else:
        hs, prim, p = primary_hits(tracer, x, down, d32)
        mask = MaskingRays.work(n)
        m = primary.traced_primary(
            segments.WalkResult(hs, prim, *p),
            tuple(wl),
            tracer.facets,
            profile is None,
            tracer.rise_bound,
            tracer.horizon,
            tracer.groove_clear,
            segment_geometry(tracer),
            ledger,
            mask.kernel_args(),
        )
        if profile is not None:
            hu = np.flatnonzero(status == SINGLE)
            margin = profile.margin_columns(prim[hu], p[0][hu], wo[0][hu], wo[2][hu])
            status[hu] = np.where(margin > 0, MASKED, SINGLE)
        else:
            mask.trace(tracer, m, status)
    mode, n2, k2 = fresnel_kernels.fresnel_mode(ior)
    fresnel_kernels.fresnel_weights(cosine, n2, k2, mode, weight)
    locate_single(bins, status, wo, phi_i, psi, where)
    return RayOutcome(status, weight, where)


def analytic_columns(
    caster: VGrooveCaster, wi, phi_i, bins: Bins, x, z: float, psi, ior, out=None
) -> RayOutcome:
    """The ``RayOutcome`` of the primary rays of ``masking="analytic"``: ``trace_columns`` for
    V-grooves with the primary hit computed exactly by ``caster`` instead of Embree (every ray
    hits; ``VGrooveCaster.groove_hits``), the masking test ``margin_from_rim`` on the hit's
    distance from its rim, all in the groove frame (wi rotated by −ψ, n_y = 0), in one
    compiled pass (``vgroove_kernels.analytic_vgroove``, Fresnel in real arithmetic,
    ``fresnel.fresnel_real_scalar``). Rays start at x (N,) (y is irrelevant: grooves run
    along y) and height ``z``. They agree with the traced paths ray by ray except where
    Embree's float32 hit is within a few ulp of a groove edge or masking threshold
    (tests/test_analytic_vgroove.py). ``out``: a ``RayOutcome`` of arrays (N,) to fill
    and return instead of new ones."""
    n = len(x)
    if out is None:
        out = RayOutcome(np.empty(n, dtype=np.int8), np.empty(n), np.empty(n, dtype=np.int64))
    status, weight, where = out
    wo = _ANALYTIC_WO(0 if bins.folded else n)
    vgroove_kernels.analytic_vgroove(
        np.ascontiguousarray(x, dtype=np.float64),
        float(z),
        np.ascontiguousarray(psi, dtype=np.float64),
        np.asarray(wi, dtype=np.float64),
        caster.profile,
        fresnel_kernels.fresnel_material(ior),
        vgroove_kernels.GrooveBins(float(phi_i), bins.folded, bins.n_theta, bins.phi_edges),
        (status, weight, where),
        tuple(wo),
        (_ANALYTIC_TILE(TILE), _ANALYTIC_NEAR(TILE)),
    )
    if not bins.folded:
        locate_single(bins, status, wo, phi_i, psi, where)
    return RayOutcome(status, weight, where)
