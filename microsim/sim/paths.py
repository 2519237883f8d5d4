"""Trace paths: how a chunk of primary rays is followed to its ledger class, weight and bin.

At its first hit with unit facet normal n a primary ray from wi carries the weight F(n·wi)
(exact Fresnel) and reflects to wo = 2(wi·n)n − wi; if wo points up and the reflected ray
escapes (visibility V), the weight counts in the (θo, Δφ) bin of wo — one sample of the
explicit microfacet integral (Mikkelsen 2009, eq. 9). Every primary ray ends in exactly one
ledger class (``LEDGER``): ``single`` (escaped after one bounce), ``masked`` (the reflected ray
met the surface), ``downward`` (wo_z ≤ 0: a multiple-scattering event), ``unresolved`` (wrap
cap reached, or a numerically back-facing hit) or ``missed`` (no hit at all: impossible for a
closed periodic surface). These are the single-bounce paths (``simulate(bounces=1)``, the
default); module ``bounces`` follows masked and downward paths on to their later bounces.

One interface, ``TracePath.follow(blocks) -> (status, weight, bin)``, chosen once per
(surface, masking, incidence) by ``choose_path``:

- ``AnalyticVGroovePath`` (``masking="analytic"``, V-grooves): no Embree. Every rim lies at
  z = 0, so the groove a falling ray enters decides its facet and the hit follows in closed
  form (``VGrooveCaster``); masking is the float64 test of ``"exact"``. Same rays, bins and
  streams as the traced paths, which stay the reference in the tests.
- ``RotatedIncidencePath`` (``isotropic=True``): each block's incidence azimuth rotated by its
  own ψ_b (``streams.block_rotation``).
- ``FacetTablePath``: surfaces without azimuth averaging and with no more facets than the
  incidence has rays look up Fresnel weight, mirror direction and bin per hit facet
  (``facet_table``); only the two ray casts remain per ray.
- ``TracedPath``: everything else (Embree hit; masking traced, or exact for V-grooves).

V-grooves (``surface.azimuth_average``): each ray gets its own uniformly random groove azimuth
ψ; wi is rotated by −ψ about z into the groove frame, traced, and wo binned against the rotated
incident azimuth (Δφ is rotation-invariant). This gives the isotropic V-cavity BRDF.

Masking offsets: traced masking rays start eps ≈ 2 float32 ulp of the largest coordinate above
the facet (1.2e-7 on a unit tile). The resulting bias scales like eps/feature depth, amplified
~1/cos θo near the horizon: on heightfields with features ≥ 1e-3 of the tile it is ~1e-4
relative (≪ 0.1 %); on a unit tile of 4000 V-grooves it was measured at +0.1–0.4 % for
θo ≥ 80° (below the statistical error of 10⁶ rays), and ``masking="exact"`` removes it.

Bitwise reproducibility: every per-ray operation is elementwise, in compiled loops that
evaluate each ray alone (``engine``, ``*_kernels``); Fresnel, whose complex NumPy kernels
round by array position, is evaluated per block (``fresnel_by_block``) or in real arithmetic.
So a ray's outcome never depends on the chunk it is traced in. ``trace_events`` is the per-ray
diagnostic path behind ``ray_events`` (full ``Events``, slower).
Directions are unit vectors in the global frame pointing away from the surface; φi in degrees.
"""

from __future__ import annotations

import os
import threading
import weakref
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from microsim.analytic.fresnel import fresnel
from microsim.errors import UsageError

from . import bin_kernels, fresnel_kernels, vgroove_kernels
from .bins import Bins
from .engine import beam, primary, segments
from .engine.jit import TILE
from .ledger import DOWNWARD, LEDGER, MASKED, RAY_MISSED, RAY_UNRESOLVED, SINGLE
from .scratch import WorkArray, WorkColumns
from .streams import BLOCK, block_rotation, block_span, chunk_origins, groove_starts
from .tracer import (
    ESCAPED,
    HIT,
    MISSED,
    TFAR_REL,
    UNRESOLVED,
    Hits,
    Tracer,
    VGrooveCaster,
    VGrooveProfile,
)

__all__ = [
    "SINGLE",
    "MASKED",
    "DOWNWARD",
    "RAY_UNRESOLVED",
    "RAY_MISSED",
    "LEDGER",
    "MASKING",
    "Events",
    "tracer_for",
    "GrooveFrameWork",
    "trace_events",
    "Incidence",
    "TracePath",
    "TracedPath",
    "FacetTablePath",
    "RotatedIncidencePath",
    "AnalyticVGroovePath",
    "choose_path",
    "FacetTable",
    "facet_table",
    "uses_facet_table",
    "trace_tabled",
    "primary_hits",
    "trace_columns",
    "analytic_columns",
]

MASKING = ("traced", "exact", "analytic")
ANALYTIC_BATCH = 16  # blocks per vectorised batch of masking="analytic" (measured best)
assert (SINGLE, MASKED, DOWNWARD) == (0, 1, 2)  # vgroove_kernels.analytic_vgroove relies on it

_FROM_ESCAPE = np.zeros(4, dtype=np.int8)  # tracer status -> ledger class
_FROM_ESCAPE[[HIT, ESCAPED, UNRESOLVED, MISSED]] = [MASKED, SINGLE, RAY_UNRESOLVED, RAY_MISSED]


@dataclass(frozen=True)
class Events:
    """Per-ray outcome of primary rays (global frame).

    ``status`` (N,) int8 index into ``LEDGER``; ``weight`` (N,) Fresnel weight F(n·wi) (0 when
    nothing was hit); ``wo`` (N, 3) reflected direction (NaN without a hit); ``normal`` (N, 3)
    facet normal (rotated back to the global frame for azimuth-averaged grooves);
    ``margin`` (N,) exact V-groove masking margin (> 0 ⇔ masked; NaN unless computed).
    """

    status: np.ndarray
    weight: np.ndarray
    wo: np.ndarray
    normal: np.ndarray
    margin: np.ndarray


_REUSED: dict = {}  # id(weakref to surface) → (weakref, fingerprint, masking, prepared)
_REUSE_SLOTS = 2
TRACER_BACKEND = "auto"
"""The simulations' Embree backend (``Tracer``): coherent packets over the library embreex
ships when they bind (the scene and BVH build in 0.10 s instead of embreex's ~0.5 s on the
bench mesh; tracing at about the same rate on AVX2), else embreex. ``MICROSIM_EMBREE_PACKETS=0``
forces embreex, which stays the reference path of the tests."""
GRID_CASTER = True
"""Simulations find the primary hits on heightfield tiles by walking the grid
(``heightfield_caster``, ``Tracer.cast_falling``): faster than Embree up to θi ≈ 80° on
the bench mesh, exact in float64, the same facet as Embree's but for edge ties. ``GRID_SWITCH``
= "0" in the environment (or ``GRID_CASTER = False``) keeps every ray on Embree."""
GRID_SWITCH = "MICROSIM_GRID_CASTER"
_REUSE_LOCK = threading.Lock()


def tracer_for(surface, masking: str, fingerprint: str | None = None):
    """(tracer, masking profile, azimuth) of ``surface``: its ``Tracer``; None for traced
    masking, else the V-groove ``VGrooveProfile`` ("exact") or ``VGrooveCaster``
    ("analytic"); whether each ray gets its own groove azimuth (``surface.azimuth_average``).
    UsageError for "exact"/"analytic" on a surface that is not azimuth-averaged V-grooves.

    Reuse: with ``fingerprint`` (``surface.fingerprint()``, the mesh's identity) the prepared
    tracer is kept for the same surface object — at most the ``_REUSE_SLOTS`` most recent
    (surface, masking) pairs, dropped when their surface is garbage-collected — and handed
    out again while its mesh is unchanged, so repeated ``simulate`` calls on one surface
    (``simulate_auto``'s batches, sweeps over θi, speed runs) build the Embree scene and BVH
    once. Tracers are read-only after construction and shared safely between threads."""
    grid = GRID_CASTER and os.environ.get(GRID_SWITCH, "1") != "0"
    if fingerprint is None:
        return _prepare(surface, masking, grid)
    with _REUSE_LOCK:
        for ref, fp, mode, prepared in list(_REUSED.values()):
            if ref() is surface and fp == fingerprint and mode == (masking, grid):
                return prepared
    prepared = _prepare(surface, masking, grid)
    try:  # the entry goes with its surface (dict.pop is atomic: safe in a GC callback)
        ref = weakref.ref(surface, lambda r: _REUSED.pop(id(r), None))
    except TypeError:  # not weak-referenceable: no reuse
        return prepared
    with _REUSE_LOCK:
        _REUSED[id(ref)] = (ref, fingerprint, (masking, grid), prepared)
        for key in list(_REUSED)[:-_REUSE_SLOTS]:
            _REUSED.pop(key, None)
    return prepared


def _prepare(surface, masking: str, grid: bool):
    tracer = Tracer(surface, backend=TRACER_BACKEND, grid=grid)
    azimuth = bool(getattr(surface, "azimuth_average", False))
    profile = None
    if masking in ("exact", "analytic"):
        if not azimuth:
            raise UsageError(
                f"masking={masking!r} is only available for azimuth-averaged V-groove surfaces "
                "(azimuth_average=True); use masking='traced'"
            )
        profile = VGrooveProfile(tracer) if masking == "exact" else VGrooveCaster(tracer)
    return tracer, profile, azimuth


def _rotate_z(w: np.ndarray, c: np.ndarray, s: np.ndarray) -> np.ndarray:
    """Rotate vectors (N, 3) about +z by the angles whose cosines/sines are ``c``/``s`` (N,)."""
    out = np.empty(np.broadcast_shapes(w.shape, c.shape + (3,)))
    out[:, 0] = c * w[..., 0] - s * w[..., 1]
    out[:, 1] = s * w[..., 0] + c * w[..., 1]
    out[:, 2] = w[..., 2]
    return out


def fresnel_by_block(c: np.ndarray, rows: np.ndarray, ior) -> np.ndarray:
    """Fresnel weights F(c) of the rays ``rows`` (sorted indices into a batch of whole blocks),
    evaluated with one ``fresnel`` call per block.

    NumPy's complex kernels round the last bit differently in the SIMD body and in the scalar
    tail of an array (measured: (η² − 1)·z over a complex array differs by 1 ulp depending on
    the position), so evaluating block by block keeps every weight independent of how many
    blocks share a batch; all other per-ray operations are elementwise and position-independent.
    """
    if rows.size == 0:
        return np.zeros(0)
    cuts = np.searchsorted(rows, np.arange(BLOCK, int(rows[-1]) + 1, BLOCK))
    return np.concatenate([fresnel(part, ior) for part in np.split(c, cuts)])


# --- per-ray events (diagnostics: ray_events) ----------------------------------------------
def trace_events(
    tracer: Tracer, profile, wi: np.ndarray, origins, psi, ior, azimuth: bool
) -> Events:
    """Follow primary rays from direction ``wi`` (global) to their ledger class (vectorised),
    keeping every per-ray quantity (``Events``).

    ``origins`` is a batch of whole ``BLOCK``s (the last may be short); the outcome of every
    ray is independent of the batch size (see ``fresnel_by_block``)."""
    n = len(origins)
    if azimuth:  # trace in the groove frame: wi by −ψ
        cpsi, spsi = np.cos(psi), np.sin(psi)
        wl = _rotate_z(wi, cpsi, -spsi)
        hits = (
            _analytic_hits(tracer, profile, origins, wl)
            if isinstance(profile, VGrooveCaster)
            else tracer.first_hit(origins, -wl)
        )
    else:
        wl = np.broadcast_to(wi, (n, 3))
        hits = tracer.first_hit(origins, -np.asarray(wi, dtype=np.float64))  # one shared direction
    status = np.full(n, RAY_UNRESOLVED, dtype=np.int8)
    status[hits.status == MISSED] = RAY_MISSED
    status[hits.status == ESCAPED] = RAY_MISSED  # a falling ray cannot escape
    weight = np.zeros(n)
    wo = np.full((n, 3), np.nan)
    margin = np.full(n, np.nan)
    h = np.flatnonzero(hits.status == HIT)
    nrm = hits.normal[h]
    c = np.einsum("ij,ij->i", wl[h], nrm)
    front = c > 0  # back-facing hits stay unresolved
    h, nrm, c = h[front], nrm[front], c[front]
    weight[h] = fresnel_by_block(c, h, ior)
    wlo = 2.0 * c[:, None] * nrm - wl[h]
    up = wlo[:, 2] > 0
    status[h[~up]] = DOWNWARD
    hu = h[up]
    if profile is not None:
        m = profile.masking_margin(hits.prim[hu], hits.point[hu], wlo[up])
        margin[hu] = m
        status[hu] = np.where(m > 0, MASKED, SINGLE)
    else:
        status[hu] = _FROM_ESCAPE[tracer.escapes(hits.point[hu], nrm[up], wlo[up])]
    wo[h] = wlo if not azimuth else _rotate_z(wlo, cpsi[h], spsi[h])  # back by +ψ
    normal = np.full((n, 3), np.nan)
    normal[h] = nrm if not azimuth else _rotate_z(nrm, cpsi[h], spsi[h])
    return Events(status=status, weight=weight, wo=wo, normal=normal, margin=margin)


def _analytic_hits(tracer: Tracer, caster: VGrooveCaster, origins, wl) -> Hits:
    """``Tracer.first_hit`` of rays ``origins`` along −``wl`` (N, 3), computed exactly by
    ``caster`` (masking="analytic"): every ray hits; ``point`` holds x only (y, z are NaN,
    unused by the V-groove masking test)."""
    prim, x = caster.first_hit_columns(origins[:, 0], origins[:, 2], wl[:, 0], wl[:, 2])
    point = np.full((len(prim), 3), np.nan)
    point[:, 0] = x
    return Hits(
        status=np.full(len(prim), HIT, dtype=np.int8),
        prim=prim,
        point=point,
        normal=tracer.normals[prim],
    )


# --- the tally paths: (status, weight, bin) per ray ----------------------------------------
@dataclass(frozen=True)
class FacetTable:
    """What a primary ray from ``wi`` does on each facet of a surface traced without azimuth
    averaging (wi is then the same for every ray): ``code`` (F,) int8 SINGLE (lit, reflects
    upwards: a masking ray decides), DOWNWARD or RAY_UNRESOLVED (back-facing); ``weight`` (F,)
    Fresnel F(n·wi) (0 when back-facing); ``wo32`` (F, 3) the mirror direction
    wo = 2(wi·n)n − wi in float32 — the direction Embree traces the masking ray along, whose
    float64 value the walk uses too; ``bin`` (F,) int32 flat bin index of wo (from float64
    wo; −1 below the horizon); ``normal_cols`` (3 × (F,)) and ``lift`` (F,) = n·v0 + eps (a
    point p starts its masking ray at p − (p·n − lift) n: on the facet plane, eps above it);
    ``clear`` (F,) bool: lit facets whose rays all escape without a masking ray, because
    their mirror direction rises more steeply than the surface can (``Tracer.surely_escapes``)
    or, on heightfield grids, because the beam of them clears the relief (``beam``).
    26 bytes per facet besides the tracer's own columns."""

    code: np.ndarray
    weight: np.ndarray
    bin: np.ndarray
    wo32: np.ndarray
    normal_cols: tuple
    lift: np.ndarray
    clear: np.ndarray


TABLES_KEPT = 4
"""Facet tables a ``Tracer`` keeps for repeated calls at the same incidence (the most recent;
13 MB each on the bench's 524 288-facet mesh)."""
_TABLES_LOCK = threading.Lock()


def facet_table(
    tracer: Tracer,
    wi: np.ndarray,
    ior,
    bins: Bins,
    phi_i: float,
    pool: ThreadPoolExecutor | None = None,
    parts: int = 1,
) -> FacetTable:
    """The ``FacetTable`` of incidence ``wi`` (``fresnel_kernels.facet_mirror``; Fresnel weights in
    compiled real arithmetic, ``fresnel.fresnel_real_scalar``; bins by ``Bins.locate``), computed
    in ``parts`` contiguous facet ranges on ``pool`` (each facet's entries depend on that
    facet alone, so the split changes nothing). Bins are ``Bins.locate``'s
    (``locate_single``: a compiled pass on folded grids).

    A ``Tracer`` keeps its ``TABLES_KEPT`` most recent tables (read-only arrays), so that
    repeated calls at one incidence — ``simulate_auto``'s batches, a run resumed, the same
    surface simulated again — build each once; the tracer itself is immutable, so a kept
    table stays exact."""
    key = (tuple(float(w) for w in wi), fresnel_kernels.fresnel_mode(ior), bins, float(phi_i))
    kept = getattr(tracer, "facet_tables", {})  # (a stand-in without it keeps nothing)
    with _TABLES_LOCK:
        table = kept.pop(key, None)
        if table is not None:
            kept[key] = table  # most recent last
            return table
    table = _build_facet_table(tracer, wi, ior, bins, phi_i, pool, parts)
    for array in (table.code, table.weight, table.bin, table.wo32, table.clear):
        array.flags.writeable = False
    with _TABLES_LOCK:
        kept[key] = table
        for old in list(kept)[:-TABLES_KEPT]:
            kept.pop(old, None)
    return table


def _build_facet_table(tracer, wi, ior, bins, phi_i, pool, parts) -> FacetTable:
    """``facet_table`` built (not looked up)."""
    f = len(tracer.faces)
    ncols = tracer.normal_columns
    weight, code = np.empty(f), np.empty(f, dtype=np.int8)
    wo32, where = np.empty((f, 3), dtype=np.float32), np.empty(f, dtype=np.int32)
    wi = [float(w) for w in wi]
    fresnel_args = fresnel_kernels.fresnel_mode(ior)

    def fill(part: slice) -> None:
        wo = _TABLE_WO(part.stop - part.start)
        fresnel_kernels.facet_mirror(
            *(a[part] for a in ncols),
            *wi,
            *fresnel_args[1:],
            fresnel_args[0],
            weight[part],
            code[part],
            *wo,
            wo32[part],
        )
        rising = np.where(wo[2] > 0.0, SINGLE, MASKED).astype(np.int8)  # the others: −1
        where[part] = -1
        locate_single(bins, rising, wo, phi_i, None, where[part])

    cuts = np.linspace(0, f, max(1, int(parts)) + 1).astype(int)
    slices = [slice(a, b) for a, b in zip(cuts[:-1], cuts[1:])]
    list(pool.map(fill, slices) if pool is not None else map(fill, slices))
    clear = steep_facets(tracer, code, wo32)
    if tracer.beam is not None:  # heightfield grids: whole beams cleared (``beam``)
        candidates, cleared = (code == SINGLE) & ~clear, np.empty(f, dtype=np.bool_)

        def clear_beams(part: slice) -> None:
            beam.beam_clear(part.start, candidates[part], wo32[part], tracer.beam, cleared[part])

        list(pool.map(clear_beams, slices) if pool is not None else map(clear_beams, slices))
        clear |= cleared
    return FacetTable(
        code=code,
        weight=weight,
        bin=where,
        wo32=wo32,
        normal_cols=ncols,
        lift=tracer.masking_lift,
        clear=clear,
    )


def steep_facets(tracer: Tracer, code: np.ndarray, wo32: np.ndarray) -> np.ndarray:
    """Lit facets (``code`` SINGLE) whose float32 mirror direction ``wo32`` (F, 3), traced as
    its float64 value, rises more steeply than the surface can (``Tracer.surely_escapes``):
    the facet table's ``clear`` before any beam is cleared."""
    wo = wo32.astype(np.float64)
    return (code == SINGLE) & tracer.surely_escapes(wo[:, 0], wo[:, 1], wo[:, 2])


def uses_facet_table(tracer: Tracer, profile, azimuth: bool, rotate: bool, n_total: int) -> bool:
    """Whether ``choose_path`` traces through a per-facet table: surfaces without azimuth
    averaging or per-block rotation, with no more facets than the incidence has rays."""
    return not azimuth and not rotate and profile is None and len(tracer.faces) <= n_total


def _segment_geometry(tracer: Tracer) -> tuple:
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
        primary.apply_escape(status, self.ray[:m], esc, _FROM_ESCAPE)


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
_TABLE_WO = WorkColumns("table-wo")
_NEAR_EDGE = WorkArray("near-edge", np.bool_)
_TRACED_WO = WorkColumns("traced-wo")
_TRACED_COSINE = WorkArray("traced-cosine")
_ANALYTIC_WO = WorkColumns("analytic-wo")
_ANALYTIC_TILE = WorkArray("analytic-tile", rows=15)  # ``analytic_vgroove``'s scratch
_ANALYTIC_NEAR = WorkArray("analytic-near", np.bool_)


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
    segments.falling_first_segment(*x, *d, shared, *_segment_geometry(tracer), *first)
    return first


def primary_hits(tracer: Tracer, x, down, d32) -> tuple:
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


def tabled_masking_rays(tracer: Tracer, table: FacetTable, wi: np.ndarray, origins):
    """``trace_tabled`` up to its masking rays: (status, weight, bin, ``MaskingRays``, m) with
    the m masking rays set up but not yet traced (the status of their primary rays still
    SINGLE)."""
    x = _columns(origins)
    n = len(x[0])
    wi = np.asarray(wi, dtype=np.float64)
    down = [float(-c) for c in wi]
    status, weight = np.empty(n, dtype=np.int8), np.empty(n)
    where = np.empty(n, dtype=np.int64)
    mask = MaskingRays.work(n)
    facets = primary.FacetColumns(
        table.code,
        table.weight,
        *table.normal_cols,
        table.lift,
        table.wo32,
        table.bin,
        table.clear,
    )
    ledger = primary.PrimaryLedger(status, weight, where)
    grid = tracer.grid_walk(x, down)
    if grid is not None:  # the grid walk fused with the look-ups, tile by tile
        m = primary.cast_tabled_primary(
            tuple(x), tuple(down), grid, facets, tracer.horizon, _segment_geometry(tracer),
            ledger, mask.kernel_args(),
        )  # fmt: skip
        return status, weight, where, mask, m
    hs, prim, p = primary_hits(tracer, x, down, (-wi).astype(np.float32)[None])
    walk = segments.WalkResult(hs, prim, *p)
    m = primary.tabled_primary(
        walk, facets, tracer.horizon, _segment_geometry(tracer), ledger, mask.kernel_args()
    )
    return status, weight, where, mask, m


def trace_tabled(tracer: Tracer, table: FacetTable, wi: np.ndarray, origins):
    """(status, weight, bin) per primary ray, looked up per hit facet in ``table`` (the fast
    path for surfaces without azimuth averaging: only the two ray casts are per ray, the rest
    is one compiled pass, ``primary.tabled_primary``). ``origins``: (N, 3) or 3 columns."""
    status, weight, where, mask, m = tabled_masking_rays(tracer, table, wi, origins)
    mask.trace(tracer, m, status)
    return status, weight, where


def _columns(origins) -> list:
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


def locate_single(bins: Bins, status, wo, phi_i: float, psi, where) -> None:
    """Set ``where`` to the bin of wo (3 columns) for the SINGLE rays, Δφ taken against
    φi (degrees) or, with groove azimuths ``psi`` (wo in each ray's groove frame), against
    φi − ψ: folded grids by ``bin_kernels.bin_rays`` (compiled, vectorised), unfolded ones by
    ``Bins.locate``."""
    if bins.folded:
        bin_kernels.bin_rays(
            status,
            *wo,
            np.empty(0) if psi is None else psi,
            psi is not None,
            float(phi_i),
            bins.n_theta,
            bins.phi_edges,
            _NEAR_EDGE(len(status)),
            where,
        )
        return
    single = np.flatnonzero(status == SINGLE)
    ws = np.stack([a[single] for a in wo], axis=1)
    where[single] = bins.locate(ws, phi_i if psi is None else phi_i - np.degrees(psi[single]))


def trace_columns(tracer: Tracer, profile, wi, phi_i, bins: Bins, origins, psi, ior):
    """(status, weight, bin) per primary ray — ``trace_events`` reduced to what the tallies
    need, on per-axis columns. ``psi`` None: one shared direction −wi. ``psi`` (N,)
    (``azimuth_average`` surfaces): each ray is traced in its groove frame (wi rotated by −ψ)
    and binned there too — Δφ = φo − φi is unchanged by the rotation, so wo is located against
    the rotated incident azimuth φi − ψ instead of being rotated back. After the primary walk
    one compiled pass (``primary.traced_primary``: Fresnel in real arithmetic, mirror
    direction, ledger class) sets up the masking rays (traced masking, ``profile`` None) or
    leaves them to ``profile`` (exact V-groove masking)."""
    x = _columns(origins)
    n = len(x[0])
    if psi is None:
        wl = [np.array([float(c)]) for c in wi]  # one shared direction
        down = [-float(c) for c in wi]
        hs, prim, p = primary_hits(tracer, x, down, np.array([down], dtype=np.float32))
    else:
        wl, down, d32 = groove_frame_rays(psi, wi, _TRACED_FRAME)
        hs, prim, p = primary_hits(tracer, x, down, d32)
    status, weight, where = np.empty(n, dtype=np.int8), np.empty(n), np.full(n, -1, np.int64)
    wo, cosine = _TRACED_WO(n), _TRACED_COSINE(n)
    mask = MaskingRays.work(n)
    mode, n2, k2 = fresnel_kernels.fresnel_mode(ior)
    m = primary.traced_primary(
        segments.WalkResult(hs, prim, *p),
        tuple(wl),
        (*tracer.normal_columns, tracer.masking_lift),
        profile is None,
        tracer.rise_bound,
        tracer.horizon,
        tracer.groove_clear,
        _segment_geometry(tracer),
        primary.TracedLedger(status, cosine, *wo),
        mask.kernel_args(),
    )
    fresnel_kernels.fresnel_weights(cosine, n2, k2, mode, weight)
    if profile is not None:
        hu = np.flatnonzero(status == SINGLE)
        margin = profile.margin_columns(prim[hu], p[0][hu], wo[0][hu], wo[2][hu])
        status[hu] = np.where(margin > 0, MASKED, SINGLE)
    else:
        mask.trace(tracer, m, status)
    locate_single(bins, status, wo, phi_i, psi, where)
    return status, weight, where


def analytic_columns(caster: VGrooveCaster, wi, phi_i, bins: Bins, x, z: float, psi, ior, out=None):
    """(status, weight, bin) per primary ray of ``masking="analytic"``: ``trace_columns`` for
    V-grooves with the primary hit computed exactly by ``caster`` instead of Embree (every ray
    hits; ``VGrooveCaster.groove_hits``), the masking test ``margin_from_rim`` on the hit's
    distance from its rim, all in the groove frame (wi rotated by −ψ, n_y = 0), in one
    compiled pass (``vgroove_kernels.analytic_vgroove``, Fresnel in real arithmetic,
    ``fresnel.fresnel_real_scalar``). Rays start at x (N,) (y is irrelevant: grooves run
    along y) and height ``z``. They agree with the traced paths ray by ray except where
    Embree's float32 hit is within a few ulp of a groove edge or masking threshold
    (tests/test_analytic_vgroove.py). ``out``: (status, weight, bin) arrays (N,) to fill
    and return instead of new ones."""
    n = len(x)
    if out is None:
        out = np.empty(n, dtype=np.int8), np.empty(n), np.empty(n, dtype=np.int64)
    status, weight, where = out
    wo = _ANALYTIC_WO(0 if bins.folded else n)
    vgroove_kernels.analytic_vgroove(
        np.ascontiguousarray(x, dtype=np.float64),
        float(z),
        np.ascontiguousarray(psi, dtype=np.float64),
        np.asarray(wi, dtype=np.float64),
        caster.profile,
        fresnel_kernels.fresnel_material(ior),
        float(phi_i),
        bins.folded,
        bins.n_theta,
        bins.phi_edges,
        status,
        weight,
        where,
        *wo,
        _ANALYTIC_TILE(TILE),
        _ANALYTIC_NEAR(TILE),
    )
    if not bins.folded:
        locate_single(bins, status, wo, phi_i, psi, where)
    return status, weight, where


@dataclass(frozen=True, eq=False)
class Incidence:
    """One incidence on one traced surface: what every trace path needs. ``wi`` unit incident
    direction (global frame), ``phi_i`` its azimuth in degrees (Δφ is taken from it), ``ior``
    as ``resolve_material`` returns it, ``rays`` the primary rays N of this (realisation,
    incidence), ``key`` its random stream (seed, realisation, incidence), ``origins`` one of
    ``streams.ORIGINS``; ``replicates``: every block a stratified sweep of the whole tile by
    itself (``streams.chunk_origins``; ``simulate(isotropic=True)``)."""

    tracer: Tracer
    wi: np.ndarray
    phi_i: float
    bins: Bins
    ior: object
    rays: int
    key: tuple
    origins: str = "stratified"
    replicates: bool = False

    def origins_of(self, blocks, azimuth: bool):
        """Origin columns and groove azimuths of consecutive ``blocks`` (``chunk_origins``)."""
        return chunk_origins(
            self.tracer, self.rays, blocks, self.key, azimuth, self.origins, self.replicates
        )

    def groove_starts_of(self, blocks):
        """(x, ψ) of the rays of consecutive ``blocks``, as ``origins_of(blocks, True)``
        gives them: for the exact V-groove paths, where y plays no part (stratified origins:
        ``groove_starts``, y not even drawn)."""
        if self.origins == "stratified":
            return groove_starts(self.tracer, self.rays, blocks, self.key, self.replicates)
        (x, _, _), psi = self.origins_of(blocks, True)
        return x, psi


class TracePath:
    """How the primary rays of one ``Incidence`` are followed (module docstring).

    ``follow(blocks)`` → (status (n,) int8 ledger class, weight (n,) Fresnel F(n·wi),
    bin (n,) int64 flat bin of wo or −1) for the rays of the consecutive ``blocks``, in ray
    order; bitwise independent of how blocks are grouped. Thread-safe: one path serves all
    worker threads."""

    def __init__(self, incidence: Incidence):
        self.incidence = incidence

    def follow(self, blocks):
        raise NotImplementedError


class TracedPath(TracePath):
    """Embree primary hit; masking traced (``profile`` None) or decided exactly in float64
    (``VGrooveProfile``); groove azimuths per ray when ``azimuth``."""

    def __init__(self, incidence: Incidence, profile, azimuth: bool):
        super().__init__(incidence)
        self.profile, self.azimuth = profile, azimuth

    def follow(self, blocks):
        inc = self.incidence
        starts, psi = inc.origins_of(blocks, self.azimuth)
        return trace_columns(
            inc.tracer,
            self.profile,
            inc.wi,
            inc.phi_i,
            inc.bins,
            starts,
            psi if self.azimuth else None,
            inc.ior,
        )


class FacetTablePath(TracePath):
    """Embree primary and masking rays; weight, mirror direction and bin looked up per hit
    facet in a ``FacetTable`` built once for the incidence (``trace_tabled``)."""

    def __init__(self, incidence: Incidence, table: FacetTable):
        super().__init__(incidence)
        self.table = table

    def follow(self, blocks):
        inc = self.incidence
        starts, _ = inc.origins_of(blocks, False)
        return trace_tabled(inc.tracer, self.table, inc.wi, starts)


class RotatedIncidencePath(TracePath):
    """Every block's incidence azimuth rotated by its own ψ_b (``streams.block_rotation``)
    about the macro normal, bins taken relative to the rotated azimuth φi + ψ_b: φi is then
    uniform, which averages a statistically isotropic surface's realisation over incident
    azimuths without changing the expected BRDF. One shared direction per block keeps the
    batch coherent; the rays of a block share ψ_b, so each block (a sweep of the whole tile
    by itself, ``Incidence.replicates``) is one replicate, and the standard error comes from
    the scatter between blocks (``tallies.bin_estimate``), which holds the azimuth-to-azimuth
    scatter of the one surface."""

    def __init__(self, incidence: Incidence, profile):
        super().__init__(incidence)
        self.profile = profile

    def follow(self, blocks):
        inc, wi, out = self.incidence, self.incidence.wi, []
        for b in blocks:
            starts, _ = inc.origins_of([b], False)
            psi = block_rotation(inc.key, b)
            c, s = np.cos(psi), np.sin(psi)
            wb = np.array([c * wi[0] - s * wi[1], s * wi[0] + c * wi[1], wi[2]])
            out.append(
                trace_columns(
                    inc.tracer,
                    self.profile,
                    wb,
                    inc.phi_i + np.degrees(psi),
                    inc.bins,
                    starts,
                    None,
                    inc.ior,
                )
            )
        return tuple(np.concatenate(parts) for parts in zip(*out))


class AnalyticVGroovePath(TracePath):
    """``masking="analytic"``: closed-form V-groove hits and masking (``analytic_columns``),
    in cache-sized batches of ``ANALYTIC_BATCH`` blocks."""

    def __init__(self, incidence: Incidence, caster: VGrooveCaster):
        super().__init__(incidence)
        self.caster = caster

    def follow(self, blocks):
        inc, blocks = self.incidence, list(blocks)
        wi = np.asarray(inc.wi, dtype=np.float64)
        z = inc.tracer.zmax + inc.tracer.top_margin
        n = block_span(inc.rays, blocks)[1]
        out = np.empty(n, dtype=np.int8), np.empty(n), np.empty(n, dtype=np.int64)
        for a in range(0, len(blocks), ANALYTIC_BATCH):
            x, psi = inc.groove_starts_of(blocks[a : a + ANALYTIC_BATCH])
            lo = a * BLOCK
            part = tuple(c[lo : lo + len(x)] for c in out)
            analytic_columns(self.caster, wi, inc.phi_i, inc.bins, x, z, psi, inc.ior, part)
        return out


def choose_path(
    incidence: Incidence,
    profile,
    azimuth: bool,
    isotropic: bool = False,
    pool: ThreadPoolExecutor | None = None,
    parts: int = 1,
) -> TracePath:
    """The trace path of ``incidence`` on a surface prepared by ``tracer_for`` (``profile``,
    ``azimuth``), with ``isotropic`` block rotations or not. A facet table is built here, in
    ``parts`` facet ranges on ``pool`` (once per incidence, shared by the threads)."""
    inc = incidence
    if isinstance(profile, VGrooveCaster):
        return AnalyticVGroovePath(inc, profile)
    if isotropic and not azimuth:
        return RotatedIncidencePath(inc, profile)
    if uses_facet_table(inc.tracer, profile, azimuth, isotropic, inc.rays):
        return FacetTablePath(
            inc, facet_table(inc.tracer, inc.wi, inc.ior, inc.bins, inc.phi_i, pool, parts)
        )
    return TracedPath(inc, profile, azimuth)
