"""Ray-traced single-bounce BRDF from the explicit microfacet integral (Mikkelsen eq. 9).

Parallel primary rays from wi fall on the periodic surface from origins spread uniformly over
one tile (uniform origins on a horizontal plane = flux-weighted sampling of the surface seen
from wi, i.e. the (n_j·wi) dx_j / ((n·wi) dA) factor of eq. 9). At the first hit with unit
facet normal n a ray carries the weight F(n·wi) (exact Fresnel) and reflects to
wo = 2(wi·n)n − wi; if wo points up and the reflected ray escapes (visibility V), the weight is
tallied in the (θo, Δφ) bin of wo. The bin average of eq. 9 is then

    f̄_B = Σ_rays w / (N Ω_B),      Ω_B = bin projected solid angle (``Bins``),

and its standard error, since ray r samples its own stratum [r/N, (r+1)/N) of the tile, from
collapsed strata (pairs of adjacent strata, ``_estimate``): with x_r = w_r·1[r in B],
    se_B = √(Σx² − 2 Σ_k x_2k x_2k+1) / (N Ω_B),
where Σ_k runs over the pairs (2k, 2k+1) and Σ_k x_2k x_2k+1 is the tally ``sum_pair``. The
per-ray (i.i.d.) formula √((Σw²/N − (Σw/N)²)/(N − 1)) / Ω_B ignores the stratification and
overestimates the error (measured ≈ 2.7× in σ on a 128² Gaussian heightfield with 2·10⁵ rays;
the pair estimate ≈ 1.35×, its collapse bias — tests/test_stderr.py); it is kept for
independent origins and for ``isotropic`` runs.

Every primary ray ends in exactly one ledger class: ``single`` (escaped after one bounce),
``masked`` (the reflected ray met the surface), ``downward`` (wo_z ≤ 0: a multiple-scattering
event), ``unresolved`` (wrap cap reached, or a numerically back-facing hit) or ``missed`` (no
hit at all: impossible for a closed periodic surface). ``single_fresnel`` is the measured
single-bounce albedo ρ(θi) (Mikkelsen eq. 27); ``lost``/``lost_fresnel`` are the unweighted and
Fresnel-weighted fractions that single scattering loses (masked + downward).

Reproducibility: the rays of (realisation r, incidence i) are cut into fixed blocks of
``BLOCK`` rays; block b draws its numbers from its own slot of the stream seeded with
(seed, r, i) (``_block_generator``) and is tallied on its own; block tallies are summed in
block order. A ``chunk`` (a whole number of blocks) is traced as one batch — every per-ray
operation is elementwise, in compiled loops that evaluate each ray alone (``kernels``;
Fresnel, whose complex NumPy kernels round by array position, is evaluated per block or in
real arithmetic) and the tallies add each block's rays in ray order — so results are
bitwise identical for any ``threads``/``chunk``. The same makes runs resumable: an
interrupted run keeps its exact running sums and block counts (``Result.tallies``), and
``simulate(resume=...)`` continues with the next block (see ``simulate``).

V-grooves (``surface.azimuth_average``): each ray gets its own uniformly random groove azimuth
ψ; wi is rotated by −ψ about z into the groove frame, traced, and wo binned against the
rotated incident azimuth (Δφ is rotation-invariant). This gives the isotropic V-cavity BRDF;
the random ψ makes neighbouring strata less alike, which the pair estimate still handles (it
only becomes more conservative). Heightfields with no more facets
than an incidence has rays use a per-facet table of Fresnel weight, mirror direction and bin
(``_facet_table``): only the two ray casts remain per ray.

Masking offsets: traced masking rays start eps ≈ 2 float32 ulp of the largest coordinate above
the facet (1.2e-7 on a unit tile). The resulting bias scales like eps/feature depth, amplified
~1/cos θo near the horizon: on heightfields with features ≥ 1e-3 of the tile it is ~1e-4
relative (≪ 0.1%); on a unit tile of 4000 V-grooves it was measured at +0.1–0.4% for θo ≥ 80°
(below the statistical error of 10⁶ rays), and ``masking="exact"`` removes it.

``masking="analytic"`` (V-grooves only) replaces Embree altogether: every rim lies at z = 0,
so the groove a falling ray enters at z = 0 decides its facet, and the hit follows in closed
form (``VGrooveCaster``); masking is the same float64 test as ``"exact"``. Same rays, bins and
per-block streams as the traced paths (they agree ray by ray except where Embree's float32 hit
is within a few ulp of a groove edge or masking threshold: tests/test_analytic_vgroove.py),
with the Fresnel weight in real arithmetic (``fresnel.fresnel_real_scalar``) and batches of
``ANALYTIC_BATCH`` blocks sized for the cache. It is the fast path; the traced paths stay the
reference in the tests.
"""
from __future__ import annotations

import functools
import hashlib
import itertools
import os
import signal
import threading
import time
from collections import deque
from concurrent.futures import ThreadPoolExecutor, wait
from dataclasses import dataclass
from functools import partial
from typing import Callable, Iterator, Sequence

import numpy as np

from microsim.analytic._checks import check_memory, integer, short, spherical_deg
from microsim.analytic.fresnel import fresnel, resolve_material
from microsim.checkpoints import checkpoint
from microsim.errors import UsageError

from . import kernels
from .bins import Bins
from .progress import RaysDone
from .result import Result
from .scratch import work
from .tracer import (ESCAPED, HIT, MISSED, TFAR_REL, UNRESOLVED, Hits, Tracer, VGrooveCaster,
                     VGrooveProfile)

__all__ = ["simulate", "ray_events", "Events", "BLOCK", "LEDGER", "MASKING", "ORIGINS"]

BLOCK = 4096
ANALYTIC_BATCH = 16         # blocks per vectorised batch of masking="analytic" (measured best)
SINGLE, MASKED, DOWNWARD, RAY_UNRESOLVED, RAY_MISSED = range(5)
LEDGER = ("single", "masked", "downward", "unresolved", "missed")
MASKING = ("traced", "exact", "analytic")
assert (SINGLE, MASKED, DOWNWARD) == (0, 1, 2)             # _analytic_columns relies on it
assert (SINGLE, MASKED, DOWNWARD, RAY_UNRESOLVED, RAY_MISSED) == (
    kernels.SINGLE, kernels.MASKED, kernels.DOWNWARD, kernels.RAY_UNRESOLVED, kernels.RAY_MISSED)
ORIGINS = ("stratified", "independent")
MAX_RAYS = 2 ** 48
"""Most primary rays per incidence (2.8·10¹⁴): a ray's stratum position r + ξ is a float64,
which above 2⁴⁸ keeps fewer than 5 bits of the jitter ξ; at ~10⁷ rays/s it is also a year of
tracing. Memory does not depend on it (rays are drawn and tallied one chunk at a time)."""
MAX_THREADS = 1024
MAX_CHUNK = 2 ** 22
"""Most rays per thread task: every task holds ~200 bytes per ray of work arrays (0.8 GB)."""
IN_FLIGHT = 2
"""Thread tasks submitted ahead per thread: the scheduler keeps at most IN_FLIGHT·threads
tasks queued or running, so memory and the reaction to an interrupt do not depend on rays."""
EVENT_BYTES = 65
"""Bytes per ray of ``Events``: status 1, weight 8, wo 24, normal 24, margin 8."""
BIN_BYTES_TALLY = 72
"""Bytes per bin per (realisation, incidence): the running sums Σw, Σw², Σpairs, counts
(32 B), their copies in ``Result.tallies`` (32 B) and the per-realisation BRDF (8 B)."""
BIN_BYTES_INCIDENCE = 96
"""Bytes per bin per incidence in the Result: brdf, stderr, counts, sums, pooled tally (≈12
float64 arrays)."""
BIN_BYTES_THREAD = 32
"""Bytes per bin per running thread task: its scratch sums and touched flags."""


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


# --- ray generation ----------------------------------------------------------------------
def _rotate_z(w: np.ndarray, c: np.ndarray, s: np.ndarray) -> np.ndarray:
    """Rotate vectors (N, 3) about +z by the angles whose cosines/sines are ``c``/``s`` (N,)."""
    out = np.empty(np.broadcast_shapes(w.shape, c.shape + (3,)))
    out[:, 0] = c * w[..., 0] - s * w[..., 1]
    out[:, 1] = s * w[..., 0] + c * w[..., 1]
    out[:, 2] = w[..., 2]
    return out


def _chunk_columns(tracer: Tracer, n_total: int, blocks, key, azimuth: bool,
                   origins: str = "stratified"):
    """Origin columns [x, y, z] and groove azimuths ψ (None unless ``azimuth``) of the rays of
    consecutive ``blocks``, in this thread's work arrays (valid until its next call). Every
    origin starts at z = zmax + top_margin.

    Each block draws ξ, η, then (``azimuth``) ψ/2π, n each (n its length), from its own slot
    of the stream ``key`` (``_block_generator``), so its rays do not depend on the chunking.
    ``origins="stratified"``: ray r of n_total gets a stratum q ∈ [(r)/N, (r+1)/N) of a
    row-major sweep of the tile (``rows`` rows, ~square strata), jittered uniformly inside it;
    y is jittered inside its row (``kernels.stratified_origins``). The union of strata is the
    whole tile, so origins are uniform over one period (and a block covers a compact strip:
    coherent rays). ``origins="independent"``: i.i.d. uniform origins over the whole tile,
    then sorted row-major on a ~square grid of the block's size (coherence only: the set is
    unchanged).
    """
    blocks = list(blocks)
    lo = blocks[0] * BLOCK
    n = min(n_total, (blocks[-1] + 1) * BLOCK) - lo
    x, y, z = (work("chunk-" + a, n) for a in "xyz")
    z.fill(tracer.zmax + tracer.top_margin)
    psi = work("chunk-psi", n if azimuth else 0)
    lx, ly = tracer.tile
    per_ray = 3 if azimuth else 2
    rng = _block_generator(key, blocks[0], per_ray)       # consecutive slots from here on
    u = work("chunk-uniform", per_ray * n)                # ξ, η (, ψ/2π) of each block in turn
    rng.random(out=u)
    if origins == "independent":
        for b in blocks:
            k = b * BLOCK - lo
            m, base = min(n - k, BLOCK), per_ray * k
            xi, eta = u[base:base + m], u[base + m:base + 2 * m]
            rows = max(1, int(round(np.sqrt(m * ly / lx))))
            order = np.lexsort((xi, np.minimum(np.floor(eta * rows), rows - 1)))
            x[k:k + m], y[k:k + m] = xi[order] * lx - lx / 2, eta[order] * ly - ly / 2
            if azimuth:
                psi[k:k + m] = 2 * np.pi * u[base + 2 * m:base + 3 * m][order]
    else:
        rows = max(1, int(round(np.sqrt(n_total * ly / lx))))
        kernels.stratified_origins(u, lo, n, BLOCK, float(n_total), float(rows), float(lx),
                                   float(ly), azimuth, x, y, psi)
    return [x, y, z], (psi if azimuth else None)


def _block_rays(tracer: Tracer, n_total: int, block: int, key: Sequence[int], azimuth: bool,
                origins: str = "stratified"):
    """Origins (n, 3) and groove azimuths ψ (n,) (zeros unless ``azimuth``) of one block
    (``_chunk_columns``)."""
    cols, psi = _chunk_columns(tracer, n_total, [block], key, azimuth, origins)
    return np.stack(cols, axis=1), (psi.copy() if azimuth else np.zeros(len(cols[0])))


_streams = threading.local()


@functools.lru_cache(maxsize=64)
def _stream_state(key: tuple) -> dict:
    """Initial PCG64 state of the random stream ``key`` = (seed, realisation, incidence)."""
    return np.random.PCG64(np.random.SeedSequence(list(key))).state


def _block_generator(key, block: int, per_ray: int) -> np.random.Generator:
    """This thread's generator positioned at block ``block``'s slot of stream ``key``: block b
    owns the numbers [b·k·BLOCK, (b + 1)·k·BLOCK) of the PCG64 stream seeded with
    SeedSequence(key), k = ``per_ray`` numbers per ray (ξ, η, and ψ for groove azimuths, in
    runs of the block's length), so every block's rays depend only on (key, b), whatever the
    chunking, and one generator serves consecutive blocks."""
    try:
        rng = _streams.rng
    except AttributeError:
        rng = _streams.rng = np.random.Generator(np.random.PCG64())
    rng.bit_generator.state = _stream_state(tuple(int(k) for k in key))
    rng.bit_generator.advance(block * per_ray * BLOCK)
    return rng


def _fresnel_by_block(c: np.ndarray, rows: np.ndarray, ior) -> np.ndarray:
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


_FROM_ESCAPE = np.zeros(4, dtype=np.int8)                  # tracer status -> ledger class
_FROM_ESCAPE[[HIT, ESCAPED, UNRESOLVED, MISSED]] = [MASKED, SINGLE, RAY_UNRESOLVED, RAY_MISSED]


def _trace(tracer: Tracer, profile, wi: np.ndarray, origins, psi, ior, azimuth: bool) -> Events:
    """Follow primary rays from direction ``wi`` (global) to their ledger class (vectorised).

    ``origins`` is a batch of whole ``BLOCK``s (the last may be short); the outcome of every
    ray is independent of the batch size (see ``_fresnel_by_block``)."""
    n = len(origins)
    if azimuth:                                          # trace in the groove frame: wi by −ψ
        cpsi, spsi = np.cos(psi), np.sin(psi)
        wl = _rotate_z(wi, cpsi, -spsi)
        hits = (_analytic_hits(tracer, profile, origins, wl)
                if isinstance(profile, VGrooveCaster) else tracer.first_hit(origins, -wl))
    else:
        wl = np.broadcast_to(wi, (n, 3))
        hits = tracer.first_hit(origins, -np.asarray(wi, dtype=np.float64))  # one shared direction
    status = np.full(n, RAY_UNRESOLVED, dtype=np.int8)
    status[hits.status == MISSED] = RAY_MISSED
    status[hits.status == ESCAPED] = RAY_MISSED          # a falling ray cannot escape
    weight = np.zeros(n)
    wo = np.full((n, 3), np.nan)
    margin = np.full(n, np.nan)
    h = np.flatnonzero(hits.status == HIT)
    nrm = hits.normal[h]
    c = np.einsum("ij,ij->i", wl[h], nrm)
    front = c > 0                                        # back-facing hits stay unresolved
    h, nrm, c = h[front], nrm[front], c[front]
    weight[h] = _fresnel_by_block(c, h, ior)
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
    wo[h] = wlo if not azimuth else _rotate_z(wlo, cpsi[h], spsi[h])   # back by +ψ
    normal = np.full((n, 3), np.nan)
    normal[h] = nrm if not azimuth else _rotate_z(nrm, cpsi[h], spsi[h])
    return Events(status=status, weight=weight, wo=wo, normal=normal, margin=margin)


def _analytic_hits(tracer: Tracer, caster: VGrooveCaster, origins, wl) -> "Hits":
    """``Tracer.first_hit`` of rays ``origins`` along −``wl`` (N, 3), computed exactly by
    ``caster`` (masking="analytic"): every ray hits; ``point`` holds x only (y, z are NaN,
    unused by the V-groove masking test)."""
    prim, x = caster.first_hit_columns(origins[:, 0], origins[:, 2], wl[:, 0], wl[:, 2])
    point = np.full((len(prim), 3), np.nan)
    point[:, 0] = x
    return Hits(status=np.full(len(prim), HIT, dtype=np.int8), prim=prim, point=point,
                normal=tracer.normals[prim])


@dataclass(frozen=True)
class _FacetTable:
    """What a primary ray from ``wi`` does on each facet of a surface traced without azimuth
    averaging (wi is then the same for every ray): ``code`` (F,) int8 SINGLE (lit, reflects
    upwards: a masking ray decides), DOWNWARD or RAY_UNRESOLVED (back-facing); ``weight`` (F,)
    Fresnel F(n·wi) (0 when back-facing); ``wo32`` (F, 3) the mirror direction
    wo = 2(wi·n)n − wi in float32 — the direction Embree traces the masking ray along, whose
    float64 value the walk uses too; ``bin`` (F,) int32 flat bin index of wo (from float64
    wo; −1 below the horizon); ``normal_cols`` (3 × (F,)) and ``lift`` (F,) = n·v0 + eps (a
    point p starts its masking ray at p − (p·n − lift) n: on the facet plane, eps above it).
    25 bytes per facet besides the tracer's own columns."""

    code: np.ndarray
    weight: np.ndarray
    bin: np.ndarray
    wo32: np.ndarray
    normal_cols: tuple
    lift: np.ndarray


def _facet_table(tracer: Tracer, wi: np.ndarray, ior, bins: Bins, phi_i: float,
                 pool: ThreadPoolExecutor | None = None, parts: int = 1) -> _FacetTable:
    """The ``_FacetTable`` of incidence ``wi`` (``kernels.facet_mirror``; Fresnel weights in
    compiled real arithmetic, ``fresnel.fresnel_real_scalar``; bins by ``Bins.locate``), computed
    in ``parts`` contiguous facet ranges on ``pool`` (each facet's entries depend on that
    facet alone, so the split changes nothing)."""
    f = len(tracer.faces)
    ncols = tracer.normal_columns
    weight, code = np.empty(f), np.empty(f, dtype=np.int8)
    wo32, where = np.empty((f, 3), dtype=np.float32), np.empty(f, dtype=np.int32)
    wi = [float(w) for w in wi]
    fresnel_args = kernels.fresnel_mode(ior)

    def fill(part: slice) -> None:
        wo = [work("table-wo-" + a, part.stop - part.start) for a in "xyz"]
        kernels.facet_mirror(*(a[part] for a in ncols), *wi, *fresnel_args[1:], fresnel_args[0],
                             weight[part], code[part], *wo, wo32[part])
        where[part] = bins.locate_xyz(*wo, phi_i)

    cuts = np.linspace(0, f, max(1, int(parts)) + 1).astype(int)
    slices = [slice(a, b) for a, b in zip(cuts[:-1], cuts[1:])]
    list(pool.map(fill, slices) if pool is not None else map(fill, slices))
    return _FacetTable(code=code, weight=weight, bin=where, wo32=wo32, normal_cols=ncols,
                       lift=tracer.masking_lift)


def _uses_facet_table(tracer: Tracer, profile, azimuth: bool, rotate: bool, n_total: int) -> bool:
    """Whether ``_chunk_tallies`` traces through a per-facet table: surfaces without azimuth
    averaging or per-block rotation, with no more facets than the incidence has rays."""
    return not azimuth and not rotate and profile is None and len(tracer.faces) <= n_total


def _facet_table_key(wi, ior, bins: Bins, phi_i) -> tuple:
    return ("facet-table", tuple(np.asarray(wi, dtype=np.float64)), ior, bins, float(phi_i))


def _trace_tabled(tracer: Tracer, table: _FacetTable, wi: np.ndarray, origins):
    """(status, weight, bin) per primary ray, looked up per hit facet in ``table`` (the fast
    path for surfaces without azimuth averaging: only the two ray casts are per ray, the rest
    is one compiled pass, ``kernels.tabled_primary``). ``origins``: (N, 3) or 3 columns."""
    x = _columns(origins)
    n = len(x[0])
    wi = np.asarray(wi, dtype=np.float64)
    hs, prim, p = tracer.trace_columns(x, [float(-c) for c in wi], (-wi).astype(np.float32)[None])
    status, weight = np.empty(n, dtype=np.int8), np.empty(n)
    where = np.empty(n, dtype=np.int64)
    mi = work("tabled-ray", n, np.int64)                  # the masking rays, this thread's
    start = [work("tabled-start-" + a, n) for a in "xyz"]
    wo = [work("tabled-wo-" + a, n) for a in "xyz"]
    wo32, o32 = work("tabled-wo32", (n, 3), np.float32), work("tabled-o32", (n, 3), np.float32)
    tq, keep = work("tabled-tfar", n, np.float32), work("tabled-keep", n, np.int64)
    top = work("tabled-top", n, np.bool_)
    m = kernels.tabled_primary(hs, prim, *p, table.code, table.weight, *table.normal_cols,
                               table.lift, table.wo32, table.bin,
                               float(tracer.half[0]), float(tracer.half[1]), tracer.zmax,
                               tracer.eps, TFAR_REL, status, weight, where, mi, *start, *wo, wo32,
                               o32, tq, keep, top)
    esc = tracer.escape_columns([c[:m] for c in start], [c[:m] for c in wo], wo32[:m],
                                first=(o32, tq, keep, top))
    kernels.apply_escape(status, mi[:m], esc, _FROM_ESCAPE)
    return status, weight, where


def _columns(origins) -> list:
    """Three contiguous float64 columns from an (N, 3) array or a sequence of 3 columns."""
    if isinstance(origins, np.ndarray):
        return [np.ascontiguousarray(origins[:, k], dtype=np.float64) for k in range(3)]
    return [np.ascontiguousarray(c, dtype=np.float64) for c in origins]


def _stack32(cols) -> np.ndarray:
    """(N, 3) float32 array from three (N,) columns."""
    out = np.empty((len(cols[0]), 3), dtype=np.float32)
    for k in range(3):
        out[:, k] = cols[k]
    return out


def _trace_columns(tracer: Tracer, profile, wi, phi_i, bins: Bins, origins, psi, ior):
    """(status, weight, bin) per primary ray — the fast path of ``_trace`` for tallies, on
    per-axis columns. ``psi`` None: one shared direction −wi. ``psi`` (N,) (``azimuth_average``
    surfaces): each ray is traced in its groove frame (wi rotated by −ψ) and binned there too —
    Δφ = φo − φi is unchanged by the rotation, so wo is located against the rotated incident
    azimuth φi − ψ instead of being rotated back."""
    x = _columns(origins)
    n = len(x[0])
    if psi is None:
        wl = [float(c) for c in wi]
        down = [-c for c in wl]
        hs, prim, p = tracer.trace_columns(x, down, np.array([down], dtype=np.float32))
    else:
        cp, sp = np.cos(psi), np.sin(psi)
        wl = [cp * wi[0] + sp * wi[1], -sp * wi[0] + cp * wi[1], np.full(n, float(wi[2]))]
        down = [-c for c in wl]
        hs, prim, p = tracer.trace_columns(x, down, _stack32(down))
    status = np.full(n, RAY_UNRESOLVED, dtype=np.int8)
    status[(hs == MISSED) | (hs == ESCAPED)] = RAY_MISSED   # a falling ray cannot escape
    weight = np.zeros(n)
    where = np.full(n, -1, dtype=np.int64)
    h = np.flatnonzero(hs == HIT)
    pr = prim[h]
    nc = [c[pr] for c in tracer.normal_columns]
    wh = wl if psi is None else [c[h] for c in wl]
    c = wh[0] * nc[0] + wh[1] * nc[1] + wh[2] * nc[2]
    front = c > 0                                           # back-facing hits stay unresolved
    if not front.all():
        h, pr, c = h[front], pr[front], c[front]
        nc = [a[front] for a in nc]
        wh = wh if psi is None else [a[front] for a in wh]
    weight[h] = _fresnel_by_block(c, h, ior)
    wo = [2.0 * c * nc[k] - wh[k] for k in range(3)]
    up = wo[2] > 0
    hu, pu = h, pr
    if not up.all():
        status[h[~up]] = DOWNWARD
        hu, pu = h[up], pr[up]
        wo, nc = [a[up] for a in wo], [a[up] for a in nc]
    if profile is not None:
        margin = profile.margin_columns(pu, p[0][hu], wo[0], wo[2])
        status[hu] = np.where(margin > 0, MASKED, SINGLE)
    else:
        ph = [a[hu] for a in p]
        off = ph[0] * nc[0] + ph[1] * nc[1] + ph[2] * nc[2] - tracer.masking_lift[pu]
        start = [ph[k] - off * nc[k] for k in range(3)]
        status[hu] = _FROM_ESCAPE[tracer.escape_columns(start, wo, _stack32(wo))]
    single = status[hu] == SINGLE
    hs_ = hu[single]
    ws = np.stack([a[single] for a in wo], axis=1)
    where[hs_] = bins.locate(ws, phi_i if psi is None else phi_i - np.degrees(psi[hs_]))
    return status, weight, where


def _analytic_columns(caster: VGrooveCaster, wi, phi_i, bins: Bins, x, z: float, psi, ior):
    """(status, weight, bin) per primary ray of ``masking="analytic"``: ``_trace_columns`` for
    V-grooves with the primary hit computed exactly by ``caster`` instead of Embree (every ray
    hits; ``VGrooveCaster.groove_hits``), the masking test ``margin_from_rim`` on the hit's
    distance from its rim, all in the groove frame (wi rotated by −ψ, n_y = 0), in one
    compiled pass (``kernels.analytic_vgroove``). Rays start at x (N,) (y is irrelevant:
    grooves run along y) and height ``z``."""
    n = len(x)
    status, weight = np.empty(n, dtype=np.int8), np.empty(n)
    where = np.empty(n, dtype=np.int64)
    wo = [np.empty(n) for _ in range(3)]
    mode, n2, k2 = kernels.fresnel_mode(ior)
    phi = np.radians(phi_i)
    c = caster
    kernels.analytic_vgroove(np.ascontiguousarray(x, dtype=np.float64), float(z),
                             np.ascontiguousarray(psi, dtype=np.float64),
                             np.asarray(wi, dtype=np.float64), float(np.cos(phi)),
                             float(np.sin(phi)), float(c.half), c.x_left, c.x_right, c.w_left,
                             c.depth, c.facet_rim, c.facet_wall, c.facet_sigma, c.facet_nx,
                             c.facet_nz, c.facet_signed_tan, c.facet_width, n2, k2, mode,
                             bins.n_theta, bins.n_phi, bins.folded, status, weight, where, *wo)
    if not bins.folded:
        single = status == SINGLE
        ws = np.stack([a[single] for a in wo], axis=1)
        where[single] = bins.locate(ws, phi_i - np.degrees(psi[single]))
    return status, weight, where


def _split_tallies(status, weight, where, n_blocks: int, nbin: int) -> "_ChunkTallies":
    """Per-block tallies of a batch of whole blocks (``kernels.block_tallies``): for each
    block, its bins (sparse: only those it touches) with Σw, Σw², counts and Σ_pairs w w', and
    its ledger counts and Fresnel sums. Rays are added in ray order, so every block's sums
    are bitwise those of the block alone.

    Pair sum (collapsed strata, see ``_estimate``): rays 2k and 2k+1 of the run (adjacent
    strata; ``BLOCK`` is even and batches start on a block boundary, so pairs never straddle
    a block) contribute w_2k·w_2k+1 to their bin when both are single-bounce events in the
    same bin. A trailing unpaired ray (odd last block) has no partner and adds nothing."""
    n = len(status)
    acc, touched = np.zeros((3, nbin)), np.zeros(nbin, dtype=np.int64)
    out_bin, out_sums = work("tally-bin", n, np.int64), work("tally-sums", (3, n))
    out_cnt, offsets = work("tally-count", n, np.int64), np.empty(n_blocks + 1, dtype=np.int64)
    ln = np.zeros((n_blocks, len(LEDGER)), dtype=np.int64)
    lf = np.zeros((n_blocks, len(LEDGER)))
    kernels.block_tallies(status, weight, where, BLOCK, acc, touched, out_bin, out_sums,
                          out_cnt, offsets, ln, lf)
    used = int(offsets[-1])                 # the blocks' bins, copied out of the work arrays
    return _ChunkTallies((out_bin[:used].copy(), out_sums[:, :used].copy(),
                          out_cnt[:used].copy(), offsets, ln, lf))


class _ChunkTallies:
    """The per-block tallies of one chunk (``_split_tallies``), handed out once (``take``):
    taking releases them, so a finished future its caller still holds keeps no arrays
    (memory stays independent of the number of rays)."""

    def __init__(self, parts: tuple):
        self._parts = parts
        self.blocks = len(parts[3]) - 1

    def take(self) -> tuple:
        """(bins, sums (3, ·), counts, offsets, ledger counts, ledger Fresnel sums)."""
        parts, self._parts = self._parts, None
        if parts is None:
            raise RuntimeError("these chunk tallies were already taken")
        return parts


# --- tallies -------------------------------------------------------------------------------
_ROTATION_STREAM = 0x150   # extra key of the per-block incidence-azimuth generator


def _block_rotation(key, block: int) -> float:
    """Incidence-azimuth rotation ψ_b (radians, uniform in [0, 2π)) of block ``block``."""
    return 2.0 * np.pi * np.random.default_rng(list(key) + [block, _ROTATION_STREAM]).random()


def _rotated_tallies(tracer, profile, wi, phi_i, bins, ior, n_total, blocks, key, origins):
    """(status, weight, bin) with the incidence azimuth of every block rotated by its own ψ_b
    about the macro normal, the bins taken relative to the rotated azimuth φi + ψ_b: φi is
    then uniform, which averages a statistically isotropic surface's realisation over incident
    azimuths without changing the expected BRDF. One shared direction per block keeps the
    batch coherent."""
    out = []
    for b in blocks:
        starts, _ = _chunk_columns(tracer, n_total, [b], key, False, origins)
        psi = _block_rotation(key, b)
        c, s = np.cos(psi), np.sin(psi)
        wb = np.array([c * wi[0] - s * wi[1], s * wi[0] + c * wi[1], wi[2]])
        out.append(_trace_columns(tracer, profile, wb, phi_i + np.degrees(psi), bins, starts,
                                  None, ior))
    return tuple(np.concatenate(parts) for parts in zip(*out))


def _chunk_tallies(tracer, profile, wi, phi_i, bins, ior, n_total, blocks, *, key, azimuth,
                   origins="stratified", rotate=False):
    """Per-block tallies of a chunk of consecutive blocks (one thread task), traced as one batch.

    Every block draws its own rays (``_chunk_columns``); per-ray work is position-independent
    and the tallies are split per block (``_split_tallies``), so the result is bitwise the same
    for any chunk size or thread count. Surfaces without azimuth averaging use a per-facet
    table of Fresnel weight, mirror direction and bin (``_facet_table``, built once per
    incidence and shared by the threads) when the mesh has no more facets than the incidence
    has rays. ``rotate`` (statistically isotropic surfaces without ``azimuth_average``): rotate
    the incidence azimuth per block (``_rotated_tallies``); rays of a block share ψ_b, so the
    per-ray standard error then omits the (small) azimuth-to-azimuth scatter of one surface."""
    blocks = list(blocks)
    nbin = bins.shape[0] * bins.shape[1]
    if isinstance(profile, VGrooveCaster):              # cache-sized batches of blocks
        wi, z = np.asarray(wi, dtype=np.float64), tracer.zmax + tracer.top_margin
        parts = []
        for a in range(0, len(blocks), ANALYTIC_BATCH):
            (x, _, _), psi = _chunk_columns(tracer, n_total, blocks[a:a + ANALYTIC_BATCH], key,
                                            True, origins)
            parts.append(_analytic_columns(profile, wi, phi_i, bins, x, z, psi, ior))
        status, weight, where = (np.concatenate(c) for c in zip(*parts))
    elif rotate and not azimuth:
        status, weight, where = _rotated_tallies(tracer, profile, wi, phi_i, bins, ior, n_total,
                                                 blocks, key, origins)
    elif _uses_facet_table(tracer, profile, azimuth, rotate, n_total):
        starts, _ = _chunk_columns(tracer, n_total, blocks, key, False, origins)
        table = tracer.memo(_facet_table_key(wi, ior, bins, phi_i),
                            lambda: _facet_table(tracer, wi, ior, bins, phi_i))
        status, weight, where = _trace_tabled(tracer, table, wi, starts)
    else:
        starts, psi = _chunk_columns(tracer, n_total, blocks, key, azimuth, origins)
        status, weight, where = _trace_columns(tracer, profile, wi, phi_i, bins, starts,
                                               psi if azimuth else None, ior)
    return _split_tallies(status, weight, where, len(blocks), nbin)


@dataclass
class _Tally:
    """Running sums for one (realisation, incidence), added block by block in block order."""

    sum_w: np.ndarray
    sum_w2: np.ndarray
    count: np.ndarray
    led_n: np.ndarray
    led_f: np.ndarray
    sum_pair: np.ndarray

    @classmethod
    def empty(cls, nbin: int) -> "_Tally":
        return cls(np.zeros(nbin), np.zeros(nbin), np.zeros(nbin, np.int64),
                   np.zeros(len(LEDGER), np.int64), np.zeros(len(LEDGER)), np.zeros(nbin))

    def items(self) -> tuple:
        """The sums in the order of a block's tallies (``_split_tallies``)."""
        return (self.sum_w, self.sum_w2, self.count, self.led_n, self.led_f, self.sum_pair)

    def add_chunk(self, chunk: _ChunkTallies) -> int:
        """Add a chunk's per-block tallies, block by block in block order (callers add chunks
        in block order; ``kernels.add_blocks``); returns the number of blocks added."""
        kernels.add_blocks(self.sum_w, self.sum_w2, self.count, self.sum_pair, self.led_n,
                           self.led_f, *chunk.take())
        return chunk.blocks

    def add_totals(self, other: "_Tally") -> None:
        """Add another tally's running sums (pooling realisations)."""
        for total, part in zip(self.items(), other.items()):
            total += part


def _angles(name: str, value, what: str) -> np.ndarray:
    """``value`` (scalar or 1-D sequence of numbers) as a float64 array, or a UsageError."""
    if value is None or isinstance(value, (str, bytes)):
        raise UsageError(f"{name} must be {what}, got {short(value)}")
    try:
        a = np.atleast_1d(np.asarray(value, dtype=np.float64))
    except (TypeError, ValueError):
        raise UsageError(f"{name} must be {what}, got {short(value)}") from None
    if a.ndim != 1 or a.size == 0:
        raise UsageError(f"{name} must be {what}, got {short(value)}")
    return a


def _check_inputs(theta_i, phi_i, rays, threads, chunk, masking, seed=0):
    """Validated (θi, φi) arrays (degrees); raises a UsageError naming the first bad one of
    theta_i, phi_i, rays, threads, chunk, masking, seed (``MAX_RAYS``, ``MAX_THREADS``,
    ``MAX_CHUNK`` bound the integers)."""
    th = _angles("theta_i", theta_i, "a scalar or a non-empty 1-D sequence of degrees in [0, 90)")
    if not np.all((th >= 0) & (th < 90)):
        raise UsageError(f"theta_i must lie in [0, 90) degrees, got {short(theta_i)}")
    ph = _angles("phi_i", phi_i, f"finite degrees: a scalar or one per theta_i ({th.size})")
    if ph.size not in (1, th.size):
        raise UsageError(f"phi_i must be a scalar or one azimuth per theta_i ({th.size} values), "
                         f"got {ph.size}: {short(phi_i)}")
    ph = np.broadcast_to(ph, th.shape).copy()
    if not np.all(np.isfinite(ph)):
        raise UsageError(f"phi_i must be finite degrees (scalar or one per theta_i), got {short(phi_i)}")
    integer("rays", rays, 1, MAX_RAYS, " (primary rays per incidence)")
    integer("threads", threads, 1, MAX_THREADS)
    integer("chunk", chunk, 1, MAX_CHUNK, " (rays per thread task)")
    integer("seed", seed, 0, None, " (the random stream)")
    if not isinstance(masking, str) or masking not in MASKING:
        raise UsageError(f"masking must be one of {', '.join(MASKING)}, got {masking!r}")
    return th, ph


def _check_run_options(bins, origins, progress, progress_receives: str) -> None:
    """UsageError unless ``bins`` is a ``Bins``, ``origins`` one of ``ORIGINS`` and
    ``progress`` None or a callable (receiving ``progress_receives``)."""
    if not isinstance(bins, Bins):
        raise UsageError(f"bins must be a microsim.sim.Bins (e.g. Bins(45, 37)), got {bins!r}")
    if not isinstance(origins, str) or origins not in ORIGINS:
        raise UsageError(f"origins must be one of {', '.join(ORIGINS)}, got {origins!r}")
    if progress is not None and not callable(progress):
        raise UsageError(f"progress must be None or a callable receiving {progress_receives}, "
                         f"got {progress!r}")


def _is_surface(obj) -> bool:
    """A ``microsim.surfaces.Surface`` or an object with its mesh contract."""
    return all(hasattr(obj, a) for a in ("vertices", "faces", "tile_size", "periodic"))


def _surface_error(name: str, obj) -> UsageError:
    return UsageError(f"{name} must be a microsim.surfaces.Surface (e.g. microsim.surfaces."
                      f"vgrooves(4000, microsim.analytic.Beckmann(0.3)) or gaussian(...)), "
                      f"got {type(obj).__name__} {short(obj, 60)}")


def _realisation_list(surface, realisations):
    """(count, getter) over the surfaces to trace: ``surface`` alone, a list of surfaces, or
    (factory, seeds) built lazily one at a time (the getter checks what the factory returns)."""
    if realisations is None:
        if not _is_surface(surface):
            raise _surface_error("surface", surface)
        return 1, lambda r: surface
    if (isinstance(realisations, tuple) and len(realisations) == 2
            and callable(realisations[0])):
        factory, seeds = realisations
        try:
            seeds = list(seeds)
        except TypeError:
            raise UsageError(f"realisations: seeds must be a sequence, got {seeds!r}") from None
        if not seeds:
            raise UsageError("realisations must hold at least one seed")

        def build(r):
            s = factory(seeds[r])
            if not _is_surface(s):
                raise _surface_error(f"realisations: factory({seeds[r]!r}) returned "
                                     f"{type(s).__name__}; it", s)
            return s
        return len(seeds), build
    if isinstance(realisations, (str, bytes)) or not hasattr(realisations, "__iter__"):
        raise UsageError("realisations must be a non-empty list of surfaces or (factory, seeds), "
                         f"got {realisations!r}")
    lst = list(realisations)
    if not lst:
        raise UsageError("realisations must be a non-empty list of surfaces or (factory, seeds)")
    for k, s in enumerate(lst):
        if not _is_surface(s):
            raise _surface_error(f"realisations[{k}]", s)
    return len(lst), lambda r: lst[r]


def _tracer_for(surface, masking):
    tracer = Tracer(surface)
    azimuth = bool(getattr(surface, "azimuth_average", False))
    profile = None
    if masking in ("exact", "analytic"):
        if not azimuth:
            raise UsageError(f"masking={masking!r} is only available for V-groove surfaces "
                             "(azimuth_average=True); use masking='traced'")
        profile = VGrooveProfile(tracer) if masking == "exact" else VGrooveCaster(tracer)
    return tracer, profile, azimuth


def ray_events(surface, material, theta_i: float, phi_i: float = 0.0, rays: int = 100_000,
               seed: int = 0, masking: str = "traced") -> Events:
    """Per-ray outcomes of ``rays`` primary rays at one incidence (degrees), global frame.

    Same ray stream as ``simulate(surface, material, theta_i, ...)`` (realisation 0,
    incidence 0); for diagnostics and tests (paired comparisons of masking modes). The
    output is per ray (``EVENT_BYTES`` each): ray counts whose events exceed the memory limit
    are refused (``_checks.check_memory``).
    """
    th, ph = _check_inputs(theta_i, phi_i, rays, 1, 1, masking, seed)
    if th.size != 1:
        raise UsageError(f"theta_i must be a single incidence in degrees, got {theta_i!r}")
    if not _is_surface(surface):
        raise _surface_error("surface", surface)
    check_memory("rays", 2 * EVENT_BYTES * int(rays), f"ray_events of {int(rays):,} rays "
                 f"({EVENT_BYTES} bytes per ray, twice while concatenating)")
    ior = resolve_material(material)
    tracer, profile, azimuth = _tracer_for(surface, masking)
    wi = spherical_deg(th[0], ph[0])
    blocks = []
    for b in range(-(-int(rays) // BLOCK)):                 # block by block, as in simulate
        origins, psi = _block_rays(tracer, int(rays), b, (int(seed), 0, 0), azimuth)
        blocks.append(_trace(tracer, profile, wi, origins, psi, ior, azimuth))
    return Events(*(np.concatenate([getattr(e, f) for e in blocks])
                    for f in ("status", "weight", "wo", "normal", "margin")))


def _surface_meta(surface) -> dict:
    """JSON-able description of a traced surface (its own warnings plus the tracer's)."""
    warnings = list(getattr(surface, "warnings", ()))
    if not surface.periodic:
        warnings.append("the tile was traced as periodic although surface.periodic is False: "
                        "its seams act as steps")
    z = surface.vertices[:, 2]
    digest = hashlib.sha1(np.ascontiguousarray(surface.vertices, dtype=np.float64).tobytes())
    digest.update(np.ascontiguousarray(surface.faces, dtype=np.int64).tobytes())
    return {"kind": surface.kind, "fingerprint": digest.hexdigest()[:16],
            "nominal": dict(surface.nominal),
            "tile_size": [float(t) for t in surface.tile_size], "triangles": int(len(surface.faces)),
            "z_range": [float(np.min(z)), float(np.max(z))], "periodic": bool(surface.periodic),
            "warnings": warnings}


class _DeferredInterrupt:
    """While active (main thread only), SIGINT sets ``event`` instead of raising, so that the
    running sums are never left half-updated; ``simulate`` checks the event between chunks."""

    def __enter__(self):
        self.event = threading.Event()
        self._installed = threading.current_thread() is threading.main_thread()
        if self._installed:
            self._old = signal.signal(signal.SIGINT, lambda signum, frame: self.event.set())
        return self.event

    def __exit__(self, *exc):
        if self._installed:
            signal.signal(signal.SIGINT, signal.default_int_handler if self._old is None
                          else self._old)
        return False


def _run_config(th, ph, bins, seed, rays, masking, origins, material, n_real,
                isotropic) -> dict:
    """What a resumed run must share with the partial one (JSON-able, compared key by key)."""
    return {"theta_i": [float(t) for t in th], "phi_i": [float(p) for p in ph],
            "bins": bins.to_dict(), "seed": seed, "rays": rays, "masking": masking,
            "origins": origins, "material": material, "realisations": n_real,
            "isotropic": isotropic, "block": BLOCK}


def _resume_state(resume, config, n_real, n_th, nbin):
    """Running sums, blocks done (R, T) and surface metas restored from a partial ``Result``."""
    if not isinstance(resume, Result):
        raise UsageError(f"resume must be a microsim.sim.Result (a partial run), got {resume!r}")
    if resume.tallies is None:
        raise UsageError("resume holds no raw tallies (Result.tallies): it cannot be continued")
    old = _run_config(resume.theta_i, resume.phi_i, resume.bins, resume.meta.get("seed"),
                      resume.meta.get("rays"), resume.meta.get("masking"),
                      resume.meta.get("origins", "stratified"), resume.meta.get("material"),
                      int(resume.tallies["blocks"].shape[0]),
                      bool(resume.meta.get("isotropic", False)))
    old["block"] = resume.meta.get("block")
    diff = [f"{k} (partial run: {old[k]!r}, now: {config[k]!r})" for k in config
            if old[k] != config[k]]
    if diff:
        raise UsageError("resume does not match this run's configuration: " + "; ".join(diff))
    t = resume.tallies
    if "sum_pair" not in t:
        raise UsageError("resume holds no pair tally (Result.tallies['sum_pair'], written by an "
                         "older microsim): it cannot be continued")
    names = ("sum_w", "sum_w2", "count", "led_n", "led_f", "sum_pair")
    tallies = [[_Tally(*(t[k][r, i].copy() for k in names)) for i in range(n_th)]
               for r in range(n_real)]
    metas = resume.meta.get("realisations") if n_real > 1 else [resume.meta.get("surface")]
    return tallies, np.array(t["blocks"], dtype=np.int64), list(metas or [None] * n_real)


def _check_same_surface(old: dict | None, new: dict, r: int) -> None:
    if old is not None and old.get("fingerprint") != new["fingerprint"]:
        raise UsageError(f"resume does not match this run's configuration: surface of realisation "
                         f"{r} (partial run: {old.get('kind')} {old.get('fingerprint')}, now: "
                         f"{new['kind']} {new['fingerprint']})")


def simulate(surface, material, theta_i, phi_i=0.0, rays: int = 1_000_000, bins: Bins = Bins(),
             seed: int = 0, threads: int = 2, chunk: int = 2 ** 16, masking: str = "traced",
             realisations=None, progress: Callable[[RaysDone], None] | None = None,
             origins: str = "stratified", resume: Result | None = None,
             isotropic: bool = False) -> Result:
    """Bin-averaged single-bounce BRDF of ``surface`` by ray tracing (Mikkelsen eq. 9).

    ``material``: name, index n / n+ik or None (mirror), see ``resolve_material``.
    ``theta_i``: incidence polar angle(s) in degrees, each in [0, 90); ``phi_i`` azimuth(s) in
    degrees (scalar or one per θi). ``rays``: primary rays per incidence (spread over the
    realisations). ``bins``: outgoing (θo, Δφ) grid. ``seed``: random stream; results are
    bitwise identical for any ``threads`` and ``chunk`` (rays per thread task, rounded to
    whole ``BLOCK``s, at most ``MAX_CHUNK``; smaller when needed to give every thread a
    task). ``progress``: optional callback, called in the calling thread after every chunk is
    tallied with a ``RaysDone`` event (the rays that chunk added to its (realisation,
    incidence); the events of a pair sum to its rays and the last has ``finished=True``).
    Integers: ``rays`` in [1, ``MAX_RAYS``], ``threads`` in [1, ``MAX_THREADS``], ``seed``
    ≥ 0; every bad argument raises a ``UsageError`` naming it, before any work. Memory does
    not grow with ``rays``: chunks are scheduled lazily, at most ``IN_FLIGHT``·threads at a
    time; the per-bin tallies are checked against the memory limit up front
    (``BIN_BYTES_*``, ``_checks.check_memory``).
    ``masking``: "traced" (Embree, the reference), "exact" (Embree primary hit, float64
    V-groove masking test) or "analytic" (primary hit and masking both exact in float64, no
    Embree: ``VGrooveCaster``; the fast path) — the last two only for ``azimuth_average``
    V-groove surfaces. ``realisations``: None (trace ``surface``), a list of
    surfaces, or ``(factory, seeds)`` with ``factory(seed) -> Surface``; the BRDF then pools all
    realisations and ``stderr`` combines ray noise with realisation-to-realisation scatter.
    ``origins``: "stratified" (jittered strata over the tile, the default) or "independent"
    (i.i.d. uniform origins, sorted spatially per block) — see ``_block_rays``.
    ``isotropic``: rotate the incidence azimuth of every block by its own uniform ψ_b (bins
    taken relative to φi + ψ_b; ``_rotated_tallies``). Valid only for statistically isotropic
    surfaces (e.g. Gaussian or ABC heightfields with isotropic spectra): the expected BRDF is
    then unchanged and one tile is averaged over incident azimuths; it has no effect on
    ``azimuth_average`` surfaces (V-grooves, already azimuth-averaged per ray). Off by default.

    Standard error (``_estimate``): stratified origins use the collapsed-strata pair estimate
    (rays 2k, 2k+1 as one stratum); ``origins="independent"`` and ``isotropic=True`` use the
    per-ray formula (with ``isotropic`` neither includes the scatter between the blocks'
    azimuths ψ_b, which is shared by all rays of a block). ``meta["stderr_method"]`` records
    which ("pairs" or "per-ray").

    Interrupt and resume. A KeyboardInterrupt (SIGINT, or raised by ``progress``, by
    ``microsim.checkpoints.checkpoint("simulation")`` — called after every chunk, after
    ``progress`` — or by a factory) stops the run after the chunk in flight (within one
    thread task, well under a second at the default ``chunk``, whatever ``rays``) and
    *returns* a Result with ``meta["partial"] = True`` holding every complete block (``Result.rays`` counts them; incidences not started
    have 0 rays and NaN estimates). ``resume=<that Result>`` (same surface(s), material, θi,
    φi, bins, seed, rays, masking, origins, isotropic; else ValueError naming what differs)
    continues from the first block not yet done; the final tallies are bitwise identical to an uninterrupted
    run, because blocks are seeded by index and the raw running sums (``Result.tallies``) are
    stored exactly. Returns a ``Result`` (BRDF in sr⁻¹).
    """
    th, ph = _check_inputs(theta_i, phi_i, rays, threads, chunk, masking, seed)
    _check_run_options(bins, origins, progress, "microsim.sim.RaysDone events")
    if not isinstance(isotropic, (bool, np.bool_)):
        raise UsageError(f"isotropic must be True or False, got {isotropic!r}")
    ior = resolve_material(material)
    n_real, get_surface = _realisation_list(surface, realisations)
    rays, seed, threads = int(rays), int(seed), int(threads)
    per_real = [rays // n_real + (r < rays % n_real) for r in range(n_real)]
    if min(per_real) < 1:
        raise UsageError(f"rays must be >= the number of realisations ({n_real}), got {rays}")
    nbin = bins.shape[0] * bins.shape[1]
    check_memory("bins", nbin * (BIN_BYTES_TALLY * n_real * len(th) + BIN_BYTES_INCIDENCE
                                 * len(th) + BIN_BYTES_THREAD * threads),
                 f"the tallies of {nbin:,} bins × {len(th)} incidences × {n_real} realisations")
    chunk_blocks = max(1, int(round(int(chunk) / BLOCK)))
    material_meta = _json_material(material, ior)
    isotropic = bool(isotropic)
    config = _run_config(th, ph, bins, seed, rays, masking, origins, material_meta, n_real,
                         isotropic)
    if resume is None:
        tallies = [[_Tally.empty(nbin) for _ in th] for _ in range(n_real)]
        done = np.zeros((n_real, len(th)), dtype=np.int64)
        surfaces_meta = [None] * n_real
    else:
        tallies, done, surfaces_meta = _resume_state(resume, config, n_real, len(th), nbin)
    nblk = np.array([-(-n // BLOCK) for n in per_real], dtype=np.int64)
    done_before = done.copy()
    timings, build, interrupted = [], 0.0, False
    t_all = time.perf_counter()
    pool = _thread_pool(threads)
    with _DeferredInterrupt() as stop:
        try:
            for r in range(n_real):
                if np.all(done[r] >= nblk[r]):
                    continue
                t0 = time.perf_counter()
                surf = get_surface(r)
                smeta = _surface_meta(surf)
                _check_same_surface(surfaces_meta[r], smeta, r)
                tracer, profile, azimuth = _tracer_for(surf, masking)
                build += time.perf_counter() - t0
                surfaces_meta[r] = {**smeta, "eps": tracer.eps, "max_wraps": tracer.max_wraps}
                for i, (t_deg, p_deg) in enumerate(zip(th, ph)):
                    if stop.is_set():                   # SIGINT while building the surface
                        raise KeyboardInterrupt
                    start, end = int(done[r, i]), int(nblk[r])
                    if start >= end:
                        continue
                    if _uses_facet_table(tracer, profile, azimuth, isotropic, per_real[r]):
                        wi = spherical_deg(t_deg, p_deg)        # built by all threads at once
                        tracer.memo(_facet_table_key(wi, ior, bins, p_deg),
                                    partial(_facet_table, tracer, wi, ior, bins, p_deg, pool,
                                            threads))
                    work = partial(_chunk_tallies, tracer, profile, spherical_deg(t_deg, p_deg),
                                   p_deg, bins, ior, per_real[r], key=(seed, r, i),
                                   azimuth=azimuth, origins=origins, rotate=isotropic)

                    def tally(chunk, r=r, i=i, t_deg=t_deg):
                        """Add one chunk (main thread, block order), then report it."""
                        before = min(int(done[r, i]) * BLOCK, per_real[r])
                        done[r, i] += tallies[r][i].add_chunk(chunk)
                        after = min(int(done[r, i]) * BLOCK, per_real[r])
                        if progress is not None:
                            progress(RaysDone(realisation=r, realisations=n_real, incidence=i,
                                              theta_i=float(t_deg), rays=after - before,
                                              finished=bool(done[r, i] >= nblk[r])))
                        checkpoint("simulation")

                    _run_chunks(pool, work, _chunk_groups(start, end, chunk_blocks, threads),
                                IN_FLIGHT * threads, stop, tally)
                timings.append(time.perf_counter() - t0)
                del tracer, profile
        except KeyboardInterrupt:
            interrupted = True
    elapsed = time.perf_counter() - t_all
    n_done = np.minimum(done * BLOCK, np.array(per_real)[:, None])
    traced = int(n_done.sum() - np.minimum(done_before * BLOCK, np.array(per_real)[:, None]).sum())
    meta = {"surface": surfaces_meta[0], "realisations": surfaces_meta if n_real > 1 else None,
            "material": material_meta, "seed": seed, "rays": rays, "masking": masking,
            "origins": origins, "isotropic": isotropic,
            "stderr_method": "pairs" if origins == "stratified" and not isotropic else "per-ray",
            "partial": bool(np.any(done < nblk[:, None])),
            "interrupted": interrupted, "resumed": resume is not None,
            "threads": int(threads), "chunk_blocks": chunk_blocks,
            "block": BLOCK, "versions": _versions(), "seconds": elapsed,
            "seconds_scene_build": build, "seconds_per_realisation": timings,
            "rays_traced": traced,
            "rays_per_second": traced / (elapsed - build) if elapsed > build and traced else None}
    return _result(th, ph, bins, tallies, n_done, per_real, done, meta)


_POOLS: dict = {}
_POOLS_LOCK = threading.Lock()
os.register_at_fork(after_in_child=_POOLS.clear)   # a forked child has none of the threads


def _thread_pool(threads: int) -> ThreadPoolExecutor:
    """The process's pool of ``threads`` worker threads, kept between ``simulate`` calls: its
    threads keep their work arrays (``scratch``), so a run does not pay for faulting in fresh
    pages (expensive on this VM: ~4 µs per 4 KiB page), and ``simulate_auto``'s batches do not
    start threads anew."""
    with _POOLS_LOCK:
        if threads not in _POOLS:
            _POOLS[threads] = ThreadPoolExecutor(max_workers=threads,
                                                 thread_name_prefix=f"microsim-{threads}")
        return _POOLS[threads]


def _chunk_groups(start: int, end: int, chunk_blocks: int, threads: int) -> Iterator[range]:
    """Blocks start … end − 1 cut into consecutive thread tasks of ``chunk_blocks`` blocks,
    guided: no task takes more than 1/(2·threads) of the blocks still left, so the tasks
    shrink towards the end and the threads finish together (and a short run still gives
    every thread work). A generator: nothing is built ahead of the scheduler (``_run_chunks``),
    whatever the number of blocks."""
    a = start
    while a < end:
        step = min(chunk_blocks, max(1, (end - a) // (2 * threads)))
        yield range(a, a + step)
        a += step


def _run_chunks(pool: ThreadPoolExecutor, work, groups, depth: int, stop: threading.Event,
                consume) -> None:
    """Run ``work(group)`` on ``pool`` for the groups of the iterator ``groups``, submitting
    lazily with at most ``depth`` tasks queued or running, and hand each result to
    ``consume`` in group order (main thread). Raises KeyboardInterrupt when ``stop`` is set
    after a result was consumed; anything ``consume`` or a task raises propagates. On return
    no task of this call is left queued or running, so memory and the delay before an
    interrupt is honoured (one task) do not depend on the number of groups."""
    groups = iter(groups)
    pending: deque = deque(pool.submit(work, g) for g in itertools.islice(groups, depth))
    try:
        while pending:
            chunk = pending.popleft().result()     # in group order, blocks in block order
            nxt = next(groups, None)
            if nxt is not None:                     # keep the pool busy while we tally
                pending.append(pool.submit(work, nxt))
            consume(chunk)
            if stop.is_set():
                raise KeyboardInterrupt
    finally:
        for fut in pending:
            fut.cancel()
        wait(pending)


def _estimate(sum_w, sum_w2, n, omega, sum_pair=None):
    """BRDF and standard error of one tally (sr⁻¹); NaN when no ray was traced.

    With x_r = w_r·1[ray r in bin B] the bin mean is Σx/N. Per-ray (i.i.d.) error:
        se² = (Σx²/N − (Σx/N)²)/(N − 1).
    ``sum_pair`` given (stratified origins): collapsed strata — rays (2k, 2k+1) of adjacent
    strata are taken as two samples of one stratum of width 2/N, so
        se² = Σ_k (x_2k − x_2k+1)²/N² = (Σx² − 2 Σ_k x_2k x_2k+1)/N²
    (a trailing unpaired ray counts as paired with 0, adding x²/N²: conservative, one ray).
    Rule: the pair estimate, clipped at ≥ 0, is used where Σx² − 2Σ_k x_2k x_2k+1 exceeds the
    rounding level of that difference (64 ε Σx²); where it does not (no event, or every pair
    holding the bin's events is two equal weights) the per-ray formula is used instead, so a
    bin never gets a zero error that the per-ray formula would not give.
    Conservative: E[(x_2k − x_2k+1)²] = σ²_2k + σ²_2k+1 + (μ_2k − μ_2k+1)², so it exceeds the
    true variance by Σ_k (μ_2k − μ_2k+1)²/N², small when neighbouring strata are alike
    (collapsed strata, Cochran, Sampling Techniques, 3rd ed., §5A.12)."""
    if n < 1:
        return np.full_like(sum_w, np.nan), np.full_like(sum_w, np.nan)
    mean = sum_w / n
    var = np.maximum(sum_w2 / n - mean * mean, 0.0) / (n - 1) if n > 1 else np.nan
    if sum_pair is not None:
        diff = sum_w2 - 2.0 * sum_pair
        pair = np.maximum(diff, 0.0) / (float(n) * n)
        var = np.where(diff > 64 * np.finfo(float).eps * sum_w2, pair, var)
    se = np.sqrt(var) * np.ones_like(mean)
    return mean / omega, se / omega


def _result(th, ph, bins, tallies, n_done, per_real, done, meta) -> Result:
    """Assemble the Result from the running sums; ``n_done`` (R, T) rays tallied per
    realisation and incidence (== per_real for a complete run), ``done`` (R, T) blocks."""
    omega = bins.projected_solid_angle().ravel()
    shape = (len(th),) + bins.shape
    n_real = len(per_real)
    n_tot = n_done.sum(axis=0)
    pooled = [_Tally.empty(len(omega)) for _ in th]
    for r in range(n_real):
        for i in range(len(th)):
            pooled[i].add_totals(tallies[r][i])
    pairs = meta["stderr_method"] == "pairs"
    brdf, se_ray = map(np.array, zip(*[_estimate(p.sum_w, p.sum_w2, n_tot[i], omega,
                                                 p.sum_pair if pairs else None)
                                       for i, p in enumerate(pooled)]))
    extra = {}
    stderr = se_ray
    if n_real > 1:
        per = np.array([[_estimate(tallies[r][i].sum_w, tallies[r][i].sum_w2, n_done[r, i], omega)[0]
                         for i in range(len(th))] for r in range(n_real)])
        # scatter of the realisation means estimates the total variance of their mean (ray
        # noise included); the realisation component is what exceeds the ray noise
        total_var = np.full(per.shape[1:], np.nan)
        for i in range(len(th)):
            have = n_done[:, i] > 0
            if have.sum() > 1:
                total_var[i] = np.var(per[have, i], axis=0, ddof=1) / have.sum()
        se_real = np.sqrt(np.maximum(total_var - se_ray ** 2, 0.0))
        stderr = np.sqrt(se_ray ** 2 + se_real ** 2)
        extra = {"stderr_ray": se_ray.reshape(shape), "stderr_realisation": se_real.reshape(shape),
                 "brdf_realisations": per.reshape((n_real,) + shape),
                 "rays_realisations": np.array(per_real, dtype=np.int64)}
    led_n = np.array([p.led_n for p in pooled])
    led_f = np.array([p.led_f for p in pooled])
    with np.errstate(divide="ignore", invalid="ignore"):
        ledger = {name: led_n[:, k] / n_tot for k, name in enumerate(LEDGER)}
        for k, name in enumerate(LEDGER[:3]):
            ledger[f"{name}_fresnel"] = led_f[:, k] / n_tot
        ledger["lost"] = (led_n[:, MASKED] + led_n[:, DOWNWARD]) / n_tot
        ledger["lost_fresnel"] = (led_f[:, MASKED] + led_f[:, DOWNWARD]) / n_tot
    counts = {name: led_n[:, k] for k, name in enumerate(LEDGER)}
    raw = {"sum_w": np.array([[t.sum_w for t in row] for row in tallies]),
           "sum_w2": np.array([[t.sum_w2 for t in row] for row in tallies]),
           "count": np.array([[t.count for t in row] for row in tallies]),
           "led_n": np.array([[t.led_n for t in row] for row in tallies]),
           "led_f": np.array([[t.led_f for t in row] for row in tallies]),
           "sum_pair": np.array([[t.sum_pair for t in row] for row in tallies]),
           "blocks": done.copy(), "rays": n_done.astype(np.int64)}
    return Result(theta_i=th, phi_i=ph, bins=bins, brdf=brdf.reshape(shape),
                  stderr=stderr.reshape(shape), rays=n_tot.astype(np.int64),
                  ledger=ledger, ledger_counts=counts,
                  counts=np.array([p.count for p in pooled]).reshape(shape),
                  sum_w=np.array([p.sum_w for p in pooled]).reshape(shape),
                  sum_w2=np.array([p.sum_w2 for p in pooled]).reshape(shape),
                  meta=meta, tallies=raw, **extra)


def _json_material(material, ior):
    name = material if isinstance(material, str) else None
    if ior is None:
        return {"name": name or "mirror", "ior": None}
    c = complex(ior)
    return {"name": name, "ior": [c.real, c.imag]}


def _versions() -> dict:
    import platform

    import embreex
    out = {"numpy": np.__version__, "python": platform.python_version(),
           "embreex": getattr(embreex, "__version__", None)}
    if out["embreex"] is None:
        from importlib.metadata import version
        out["embreex"] = version("embreex")
    return out
