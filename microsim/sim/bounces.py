"""Scattering orders: paths followed beyond the first bounce (``simulate(..., bounces=K)``).

A single-bounce path ends at its first facet hit: the reflected ray either escapes (ledger
``single``) or meets the surface again (``masked``, or ``downward`` when wo_z ≤ 0). With
``bounces`` = K > 1 the path goes on from that second hit: every bounce b at a facet with
unit normal n multiplies the carried weight by the exact Fresnel factor F(c_b), c_b = −d·n
for the incoming direction d, and reflects d to d + 2c_b·n; the path ends when a reflected
ray escapes (tallied in the bin of its direction, under its order = number of bounces), or
is cut off. The weight escaping at order k in bin B, over N primary rays and the bin's
projected solid angle Ω_B, is the bin average of the order-k term of the surface's BRDF
(f̄_B,k = Σ w / (N Ω_B), as for order 1, Mikkelsen 2009, eq. 9); the sum over orders is the
explicit surface's whole BRDF (the quantity Heitz et al. 2016 write as a sum over the path
lengths of a random walk on a Smith microsurface).

``bounces``: an int K in [1, ``MAX_BOUNCES``] (the path is cut after K bounces if still
inside: ``cut_bounces``), or "all": continue until the path escapes or its weight falls
below ``WEIGHT_FLOOR`` (``cut_weight``), with at most ``MAX_BOUNCES`` bounces
(``cut_bounces``) so that every path terminates. One chain serves every K
(``chain_task``): K = 1 is its first bounce alone, traced by the single-bounce paths of
``paths`` (the reflected ray only has to be tested for escape: an occlusion query); K > 1 and
"all" continue with the paths of this module, whose first bounce is the same.

Per-order tallies: orders 1, 2, 3 and ≥ 4 (``ORDER_SLOTS`` = min(K, 4) slots) share the bin
grid; order slot o of bin B is the flat tally index o·(Θ·Φ) + B, so the running sums, the
paired-strata standard error (``tallies.bin_estimate``), realisations and resume work
unchanged on (slots · bins) tallies. A path ends in exactly one (slot, bin) or in no bin.

Ledger of a path (``TERMINAL``): ``escaped_1`` … ``escaped_4plus`` (escaped after that many
bounces), ``cut_bounces`` (still inside after the last allowed bounce), ``cut_weight``
(weight below the floor), ``unresolved_path`` (a walk hit its wrap cap, or a numerically
back-facing hit) and ``missed_path`` (a leak through the mesh); each class takes away the
weight its paths carry at the end, so per primary ray
    1 = Σ_escaped + cut + unresolved + missed + absorbed,
absorbed (the Fresnel losses 1 − Π F_b) being the rest. The first-bounce ledger
(``paths.LEDGER``: single/masked/downward… with F of the first hit) is kept for the same rays.

Trace paths: ``BouncePath`` (Embree, heightfields and traced V-grooves; each bounce is one
Embree intersect call over the still-live paths, compacted, between two compiled passes,
``bounce_kernels.bounce_step``; the reflected ray is both the masking test and the next hit, so a
continuing path costs one Embree ray per bounce). ``AnalyticBouncePath``
(``masking="analytic"``, V-grooves): the exact float64 chain between a groove's two walls
(``vgroove_kernels.analytic_vgroove_bounces``), no Embree. Their per-block tallies:
``tallies.split_order_tallies``. ``masking="exact"`` (Embree primary hit,
float64 masking) has no bounce chain: it is refused for K > 1.

Reproducibility: every path is followed on its own (compiled per-ray loops, Embree per
ray, Fresnel in real arithmetic), so results are bitwise independent of threads and chunks.
"""

from __future__ import annotations

import numbers
from dataclasses import replace
from functools import partial
from typing import Callable, NamedTuple

import numpy as np

from microsim.bins import Bins
from microsim.errors import UsageError
from microsim.jit import read_only

from . import bounce_kernels, fresnel_kernels, vgroove_kernels
from .arguments import check_masking_bounces
from .engine import codes, segments
from .facet_tables import FacetTable, facet_table, uses_facet_table
from .ledger import DIELECTRIC_COLUMNS, ORDER_NAMES, TERMINAL
from .masking_rays import primary_hits
from .paths import ANALYTIC_BATCH, LEDGER, Incidence, choose_path
from .ray_columns import GrooveFrameWork, columns, groove_frame_rays
from .scratch import WorkArray, WorkColumns
from .streams import block_rotation
from .tallies import chunk_order_tallies, chunk_tallies
from .tracer import UNRESOLVED, Tracer
from .vgroove_profile import GrooveMasking, VGrooveCaster, casts_primaries

__all__ = [
    "MAX_BOUNCES",
    "WEIGHT_FLOOR",
    "TERMINAL",
    "ORDER_NAMES",
    "check_bounces",
    "bounce_limit",
    "order_slots",
    "trace_bounces",
    "analytic_bounces",
    "ChainLimits",
    "ChainOutcome",
    "ChainPath",
    "BouncePath",
    "AnalyticBouncePath",
    "choose_bounce_path",
    "chain_task",
    "ledger_classes",
]

MAX_BOUNCES = 256
"""Most bounces of a path (``bounces="all"`` and the largest int): guarantees termination.
Far above what the catalogue's surfaces need (the highest order seen on m ≈ 0.5 Gaussian
tiles is ~12); whatever it cuts is in the ledger (``cut_bounces``)."""
RETRY_WRAPS = 2**17
"""Largest wrap cap of a re-traced grazing reflected ray (``resolve_grazing``): rays with
|d_z| below ~(relief/tile)·2⁻¹⁶ stay unresolved (ledger ``unresolved_path``)."""
WEIGHT_FLOOR = 1e-6
"""``bounces="all"``: a path whose carried weight falls below this is cut (``cut_weight``)."""


class ChainOutcome(NamedTuple):
    """Per primary ray, what the order tallies need of its bounce chain: ``status1`` (N,) int8
    and ``weight1`` (N,) the first-bounce class (``paths.LEDGER``) and Fresnel weight;
    ``term`` (N,) int8 and ``wterm`` (N,) the terminal class (``TERMINAL``) and carried
    weight; ``where`` (N,) int64 the flat tally index slot·nbin + bin of the escape direction,
    −1 for paths that do not escape."""

    status1: np.ndarray
    weight1: np.ndarray
    term: np.ndarray
    wterm: np.ndarray
    where: np.ndarray


# this thread's work arrays (``scratch``): a chain's first facets, each step's escapes and the
# next step's rays (two generations: step b writes what step b + 1 reads)
_BOUNCE_FRAME = GrooveFrameWork.declare("bounce-frame")
_BOUNCE_FACET = WorkArray("bounce-facet", np.int64)
_BOUNCE_ESCAPE = WorkArray("bounce-escape", np.int64)
_BOUNCE_ESCAPE_DIRECTION = WorkColumns("bounce-escape-direction")
_NEXT_LIVE = WorkArray("bounce-next-live", np.int64, generations=2)
_NEXT_START = WorkColumns("bounce-next-start", generations=2)
_NEXT_DIRECTION = WorkColumns("bounce-next-direction", generations=2)
_NEXT_D32 = WorkArray("bounce-next-d32", np.float32, columns=3, generations=2)
_NEXT_WEIGHT = WorkArray("bounce-next-weight", generations=2)
_BOUNCE_COSINE = WorkArray("bounce-cosine")


def check_bounces(bounces):
    """``bounces`` as an int in [1, ``MAX_BOUNCES``] or the string "all"; else a UsageError."""
    if isinstance(bounces, str):
        if bounces == "all":
            return "all"
    elif isinstance(bounces, numbers.Integral) and not isinstance(bounces, (bool, np.bool_)):
        if 1 <= int(bounces) <= MAX_BOUNCES:
            return int(bounces)
    raise UsageError(
        f"bounces must be an integer in [1, {MAX_BOUNCES}] (bounces per path) or 'all' "
        f"(until the path escapes or its weight falls below {WEIGHT_FLOOR:g}), got {bounces!r}"
    )


def bounce_limit(bounces) -> tuple[int, float]:
    """(most bounces, weight floor) of a checked ``bounces``: (K, 0) or (``MAX_BOUNCES``,
    ``WEIGHT_FLOOR``) for "all"."""
    return (MAX_BOUNCES, WEIGHT_FLOOR) if bounces == "all" else (int(bounces), 0.0)


def order_slots(bounces) -> int:
    """Order slots tallied: min(K, 4) (orders 1, 2, 3, ≥ 4); 4 for "all"."""
    return 4 if bounces == "all" else min(int(bounces), 4)


def ledger_classes(bounces, transmission: bool = False) -> int:
    """Ledger columns of a tally: the first-bounce classes, plus the terminal ones for K > 1
    (a dielectric interface's ``DIELECTRIC_COLUMNS`` for any K)."""
    if transmission:
        return len(LEDGER) + len(DIELECTRIC_COLUMNS)
    return len(LEDGER) + (0 if bounces == 1 else len(TERMINAL))


class ChainLimits(NamedTuple):
    """Where a bounce chain stops and how it is tallied: at most ``limit`` bounces, paths
    whose weight falls below ``floor`` cut (``bounce_limit``); ``nbin`` bins per order
    slot."""

    limit: int
    floor: float
    nbin: int


class SpectralChain(NamedTuple):
    """W materials weighting one traced chain (``trace_bounces``' ``spectrum``): their
    ``bounce_kernels.SpectralMaterials`` and the weight ``floor`` each is cut at."""

    materials: bounce_kernels.SpectralMaterials
    floor: float

    def ledger(self, n: int) -> bounce_kernels.SpectralLedger:
        """The empty ``SpectralLedger`` of ``n`` primary rays: every weight 1, every path
        going on (``term`` −1), no escape (``where`` −1)."""
        shape = (n, len(self.materials.n2))
        return bounce_kernels.SpectralLedger(
            np.empty(shape, dtype=np.int8),
            np.zeros(shape),
            np.full(shape, -1, dtype=np.int8),
            np.empty(shape),
            np.full(shape, -1, dtype=np.int64),
            np.ones(shape),
        )


def trace_bounces(
    tracer: Tracer,
    wi,
    phi_i,
    bins: Bins,
    origins,
    psi,
    ior,
    chain: ChainLimits,
    table: FacetTable | None = None,
    spectrum: SpectralChain | None = None,
) -> ChainOutcome | bounce_kernels.SpectralLedger:
    """The ``ChainOutcome`` of primary rays followed through the bounce chain on Embree.

    Rays start at ``origins`` (N, 3) or 3 columns, falling along −wi (one shared direction
    when ``psi`` is None, else wi rotated by −ψ per ray into its groove frame, as
    ``ray_columns.trace_columns``). Each step traces the live paths' rays (``Tracer.
    trace_columns``: the periodic walk, wraps exact as there) and hands the hits to
    ``bounce_kernels.bounce_step``, which weights, reflects, ends or continues each path and
    compacts the continuing ones, within ``chain``'s limits. Escape directions are binned
    with Δφ against ``phi_i``, or φi − ψ in the groove frame. ``table``: the incidence's
    ``facet_tables.FacetTable`` (shared direction only), whose per-facet Fresnel weights and
    bins replace the per-ray arithmetic of the first bounce with the same values.
    ``spectrum``: a ``SpectralChain`` (the chain then traced with ``ior`` None and no weight
    floor): after every step its materials weight the step's bounces
    (``bounce_kernels.spectral_step``), and the ``SpectralLedger`` of all of them is
    returned."""
    x = columns(origins)
    n = len(x[0])
    out = ChainOutcome(
        np.empty(n, dtype=np.int8),
        np.zeros(n),
        np.full(n, -1, dtype=np.int8),  # −1 until the path ends
        np.empty(n),
        np.full(n, -1, dtype=np.int64),
    )
    spectral = None if spectrum is None else spectrum.ledger(n)
    (hs, prim, p), d, shared = primary_rays(tracer, x, wi, psi)
    phi = float(phi_i) if psi is None else phi_i - np.degrees(psi)
    live = np.arange(n, dtype=np.int64)
    w = np.ones(n)
    hx, hy = float(tracer.half[0]), float(tracer.half[1])
    facets = bounce_kernels.FacetPlanes(tracer.facets, hx, hy)
    material = fresnel_kernels.fresnel_material(ior)
    first = _first_bounce_table(table if psi is None else None, n)
    b = 1
    while True:
        k = len(live)
        par = b % 2  # generation: written at this step, read by the next
        esc, ed = _BOUNCE_ESCAPE(k), _BOUNCE_ESCAPE_DIRECTION(k)
        nxt, cosine = next_rays(k, par), _BOUNCE_COSINE(k)
        m, e = bounce_kernels.bounce_step(
            b, chain.limit, chain.floor, live, w, segments.WalkResult(hs, prim, *p),
            bounce_kernels.RayDirections(*d, shared), facets, material,
            bounce_kernels.PathLedger(*out), bounce_kernels.Escapes(esc, *ed), nxt, first,
            cosine,
        )  # fmt: skip
        if e:
            slot = min(b - 1, min(chain.limit, 4)) - 1
            bin_escapes(bins, esc[:e], [c[:e] for c in ed], phi, slot * chain.nbin, out.where)
        if spectral is not None:
            m = bounce_kernels.spectral_step(
                b, spectrum.floor, live, cosine, bounce_kernels.PathLedger(*out),
                spectrum.materials, spectral, nxt, m,
            )  # fmt: skip
        if m == 0:
            break
        live, w, d, (hs, prim, p) = trace_continuing(tracer, nxt, m)
        shared = False
        b += 1
    return out if spectral is None else spectral


def next_rays(k: int, generation: int) -> bounce_kernels.NextRays:
    """This thread's arrays for at most ``k`` continuing paths, in ``generation`` (written by
    one step, read by the next)."""
    return bounce_kernels.NextRays(
        _NEXT_LIVE(k, generation), *_NEXT_START(k, generation),
        *_NEXT_DIRECTION(k, generation), _NEXT_D32(k, generation), _NEXT_WEIGHT(k, generation),
    )  # fmt: skip


def trace_continuing(
    tracer: Tracer, nxt: bounce_kernels.NextRays, m: int, leaving: np.ndarray | None = None
) -> tuple:
    """(global indices, weights, direction columns, walk hits) of the ``m`` continuing paths
    written to ``nxt``, their rays traced (``Tracer.trace_columns``; grazing ones re-traced
    with a larger wrap cap, ``resolve_grazing``). ``leaving``: (m,) bool, rays known to leave
    the relief without a hit (``Tracer.surely_escapes`` on their side): not traced, they get
    the status their walk would end with, ESCAPED rising or MISSED falling."""
    live, w = nxt.live[:m], nxt.w[:m]
    d = [nxt.dx[:m], nxt.dy[:m], nxt.dz[:m]]
    starts, d32 = [nxt.x[:m], nxt.y[:m], nxt.z[:m]], nxt.d32[:m]
    if leaving is None or not leaving.any():
        hs, prim, p = tracer.trace_columns(starts, d, d32)
        resolve_grazing(tracer, starts, d, d32, hs, prim, p)
        return live, w, d, (hs, prim, p)
    hs = np.where(d[2] > 0.0, codes.ESCAPED, codes.MISSED).astype(np.int8)
    prim, p = np.full(m, -1, dtype=np.int32), [np.empty(m) for _ in range(3)]
    rest = np.flatnonzero(~leaving)
    if rest.size:
        starts, d_rest, d32 = [c[rest] for c in starts], [c[rest] for c in d], d32[rest]
        h, q, points = tracer.trace_columns(starts, d_rest, d32)
        resolve_grazing(tracer, starts, d_rest, d32, h, q, points)
        hs[rest], prim[rest] = h, q
        for column, traced in zip(p, points):
            column[rest] = traced
    return live, w, d, (hs, prim, p)


def primary_rays(tracer: Tracer, x, wi, psi) -> tuple:
    """(hits, direction columns, shared) of the primary rays from ``x`` along −wi (one
    shared direction when ``psi`` is None, else per ray in its groove frame). Rays lit from
    below (wi_z < 0: a dielectric's medium, ``dielectric``) rise from under the relief."""
    if psi is None:
        d = [np.array([-float(c)]) for c in wi]
        d32 = np.array([[c[0] for c in d]], dtype=np.float32)
        shared = [float(c[0]) for c in d]
        if shared[2] > 0.0:
            return tracer.trace_columns(x, shared, d32), d, True
        return primary_hits(tracer, x, shared, d32), d, True
    _, d, d32 = groove_frame_rays(psi, wi, _BOUNCE_FRAME)
    return tracer.trace_columns(x, d, d32), d, False


_NO_WEIGHT, _NO_BIN = read_only(np.zeros(1)), read_only(np.zeros(1, dtype=np.int32))


def _first_bounce_table(table: FacetTable | None, n: int) -> bounce_kernels.FirstBounceTable:
    """The first bounce's look-ups for ``n`` rays: ``table``'s per-facet Fresnel weights and
    bins, or none (read-only placeholders, typed as a kept table's arrays: one compiled
    ``bounce_step``) when ``table`` is None."""
    if table is None:
        return bounce_kernels.FirstBounceTable(False, _NO_WEIGHT, _NO_BIN, _BOUNCE_FACET(1))
    return bounce_kernels.FirstBounceTable(True, table.weight, table.bin, _BOUNCE_FACET(n))


def bin_escapes(bins: Bins, rows, wo, phi, offset, where) -> None:
    """Set ``where[rows]`` to ``offset`` (one, or one per row) + the bin of the escape
    directions ``wo`` (3 columns), Δφ against ``phi`` (a scalar, or per ray of the chunk), −1
    outside the grid."""
    ph = phi if np.ndim(phi) == 0 else phi[rows]
    loc = bins.locate_xyz(wo[0], wo[1], wo[2], ph)
    where[rows] = np.where(loc >= 0, offset + loc, -1)


def resolve_grazing(tracer: Tracer, x, d, d32, hs, prim, p) -> None:
    """Re-trace the reflected rays whose walk reached the wrap cap (UNRESOLVED): a ray
    reflected at grazing angles rises or falls so slowly (|d_z| ~ 1e-4) that it crosses the
    tile thousands of times before it escapes or meets the surface, beyond ``Tracer.
    max_wraps`` (set for primary rays up to 89.5°). Each is traced again from its start with
    the wrap cap 2^k ≥ ``Tracer.wraps_needed`` of its direction (rays grouped by k, so a
    ray's outcome depends on itself alone, not on its batch), at most ``RETRY_WRAPS``;
    ``hs``/``prim``/``p`` are updated in place. Rays that need more stay unresolved."""
    u = np.flatnonzero(hs == UNRESOLVED)
    if u.size == 0:
        return
    need = tracer.wraps_needed(d[0][u], d[1][u], d[2][u])
    with np.errstate(divide="ignore"):
        k = np.ceil(np.log2(np.maximum(need, 1.0)))
    for cls in np.unique(k[np.isfinite(k)]):
        cap = 2 ** int(cls)
        if cap <= tracer.max_wraps or cap > RETRY_WRAPS:
            continue
        sel = u[k == cls]
        h2, p2, q2 = tracer.trace_columns(
            [c[sel] for c in x], [c[sel] for c in d], d32[sel], wraps=cap
        )
        hs[sel], prim[sel] = h2, p2
        for c in range(3):
            p[c][sel] = q2[c]


def analytic_bounces(
    caster: VGrooveCaster, wi, phi_i, bins: Bins, x, z, psi, ior, chain: ChainLimits
) -> ChainOutcome:
    """``trace_bounces`` for ``masking="analytic"`` V-grooves: the exact float64 chain
    (``vgroove_kernels.analytic_vgroove_bounces``) from rays at x (N,) and height ``z`` with groove
    azimuths ``psi``; escape directions binned against φi − ψ."""
    n = len(x)
    status1, weight1 = np.empty(n, dtype=np.int8), np.zeros(n)
    term, wterm = np.empty(n, dtype=np.int8), np.empty(n)
    order = np.empty(n, dtype=np.int64)
    wo = [np.empty(n) for _ in range(3)]
    ledger = vgroove_kernels.GrooveChainLedger(status1, weight1, term, wterm, order, *wo)
    vgroove_kernels.analytic_vgroove_bounces(
        np.ascontiguousarray(x, dtype=np.float64),
        float(z),
        np.ascontiguousarray(psi, dtype=np.float64),
        np.asarray(wi, dtype=np.float64),
        caster.profile,
        fresnel_kernels.fresnel_material(ior),
        int(chain.limit),
        float(chain.floor),
        ledger,
    )
    where = np.full(n, -1, dtype=np.int64)
    g = np.flatnonzero(term <= codes.ESC_4UP)
    if g.size:
        slot = np.minimum(order[g], min(chain.limit, 4)) - 1
        loc = bins.locate_xyz(wo[0][g], wo[1][g], wo[2][g], phi_i - np.degrees(psi[g]))
        where[g] = np.where(loc >= 0, slot * chain.nbin + loc, -1)
    return ChainOutcome(status1, weight1, term, wterm, where)


class ChainPath:
    """How the bounce chains of one ``Incidence`` are followed: ``follow(blocks)`` → the
    ``ChainOutcome`` of the rays of the consecutive ``blocks``, in ray order; bitwise
    independent of how blocks are grouped. Thread-safe: one path serves all worker threads."""

    def __init__(self, incidence: Incidence):
        self.incidence = incidence

    def follow(self, blocks) -> ChainOutcome:
        raise NotImplementedError


class BouncePath(ChainPath):
    """Embree bounce chain (``trace_bounces``) of one ``Incidence``: per-ray groove azimuths
    when ``azimuth``; per-block incidence rotations (``paths.RotatedIncidencePath``) when
    ``rotate``; the materials of a spectral run (``trace_bounces``) when ``spectrum``."""

    def __init__(
        self,
        incidence: Incidence,
        azimuth: bool,
        rotate: bool,
        chain: ChainLimits,
        table=None,
        spectrum: SpectralChain | None = None,
    ):
        super().__init__(incidence)
        self.azimuth, self.rotate, self.chain, self.table = azimuth, rotate, chain, table
        self.spectrum = spectrum

    def follow(self, blocks):
        out = [self.trace(*group) for group in self.groups(blocks)]
        if len(out) == 1:
            return out[0]
        return type(out[0])(*(np.concatenate(parts) for parts in zip(*out)))

    def groups(self, blocks):
        """The rays of ``blocks`` as (wi, phi_i, starts, psi, blocks) groups lit alike, in
        ray order: all at once, or block by block with its own rotation when ``rotate``."""
        inc = self.incidence
        if not self.rotate:
            starts, psi = inc.origins_of(blocks, self.azimuth)
            yield inc.wi, inc.phi_i, starts, psi if self.azimuth else None, blocks
            return
        wi = inc.wi
        for b in blocks:
            starts, _ = inc.origins_of([b], False)
            psi = block_rotation(inc.key, b)
            c, s = np.cos(psi), np.sin(psi)
            wb = np.array([c * wi[0] - s * wi[1], s * wi[0] + c * wi[1], wi[2]])
            yield wb, inc.phi_i + np.degrees(psi), starts, None, [b]

    def trace(self, wi, phi_i, starts, psi, blocks) -> ChainOutcome:
        """The chains of the rays of ``blocks`` from ``starts`` lit from ``wi`` (azimuth
        ``phi_i``; per-ray groove azimuths ``psi`` or None): ``trace_bounces``."""
        inc = self.incidence
        table = None if self.rotate else self.table
        return trace_bounces(
            inc.tracer, wi, phi_i, inc.bins, starts, psi, inc.ior, self.chain, table,
            self.spectrum,
        )  # fmt: skip


class AnalyticBouncePath(ChainPath):
    """``masking="analytic"`` bounce chain (``analytic_bounces``), in batches of
    ``ANALYTIC_BATCH`` blocks."""

    def __init__(self, incidence: Incidence, caster: VGrooveCaster, chain: ChainLimits):
        super().__init__(incidence)
        self.caster, self.chain = caster, chain

    def follow(self, blocks):
        inc, blocks, parts = self.incidence, list(blocks), []
        wi = np.asarray(inc.wi, dtype=np.float64)
        z = inc.tracer.zmax + inc.tracer.top_margin
        for a in range(0, len(blocks), ANALYTIC_BATCH):
            x, psi = inc.groove_starts_of(blocks[a : a + ANALYTIC_BATCH])
            parts.append(
                analytic_bounces(
                    self.caster,
                    wi,
                    inc.phi_i,
                    inc.bins,
                    x,
                    z,
                    psi,
                    inc.ior,
                    self.chain,
                )
            )
        return ChainOutcome(*(np.concatenate(c) for c in zip(*parts)))


def choose_bounce_path(
    incidence: Incidence,
    profile: GrooveMasking | None,
    azimuth: bool,
    isotropic: bool,
    bounces,
    nbin: int,
    pool=None,
    parts: int = 1,
    materials: bounce_kernels.SpectralMaterials | None = None,
) -> ChainPath:
    """The bounce-chain path of ``incidence`` for a checked ``bounces`` > 1 on a surface
    prepared by ``tracer_cache.tracer_for``; ``nbin`` bins per order slot. Where the single-bounce
    paths use a facet table (``facet_tables.uses_facet_table``) it is built here too (``parts``
    facet ranges on ``pool``) and serves the first bounce. UsageError for
    ``masking="exact"`` (``profile`` a ``VGrooveProfile`` but not a caster).

    ``materials``: the W materials of a spectral run (``spectral``): the chain is traced once
    with F = 1 and no weight floor, each material weighting it (``SpectralChain``, with the
    floor of ``bounces``); Embree chains only (``spectral.check_spectral_run`` refuses
    ``masking="analytic"`` before any work)."""
    limit, floor = bounce_limit(bounces)
    spectrum = None if materials is None else SpectralChain(materials, float(floor))
    chain = ChainLimits(int(limit), 0.0 if spectrum is not None else float(floor), int(nbin))
    if casts_primaries(profile):
        assert spectrum is None, "the analytic V-groove chain weights one material"
        return AnalyticBouncePath(incidence, profile, chain)
    if profile is not None:  # a V-groove profile without its caster: masking="exact"
        check_masking_bounces("exact", bounces)
    rotate = bool(isotropic and not azimuth)
    inc, table = incidence, None
    if spectrum is not None:  # the geometry, traced with F = 1
        inc = replace(incidence, ior=None)
    if uses_facet_table(inc.tracer, profile, azimuth, rotate, inc.rays):
        table = facet_table(inc.tracer, inc.wi, inc.ior, inc.bins, inc.phi_i, pool, parts)
    return BouncePath(inc, azimuth, rotate, chain, table, spectrum)


def chain_task(
    incidence: Incidence,
    profile: GrooveMasking | None,
    azimuth: bool,
    isotropic: bool,
    bounces,
    pool=None,
    parts: int = 1,
) -> Callable:
    """The thread task of one incidence: ``task(blocks)`` follows the paths of those blocks up
    to a checked ``bounces`` and returns their per-block tallies (``tallies.ChunkTallies``).

    One chain, cut after K bounces: K = 1 is its first bounce alone, where the reflected
    ray's only question is whether it escapes, so it is an occlusion query (``paths``:
    ``choose_path``, tallied over the bins by ``tallies.split_tallies``); K > 1 and "all" go
    on from the reflected ray's hit (``choose_bounce_path``, tallied over order slots × bins
    by ``tallies.split_order_tallies``). The first bounce is the same in both: the same rays,
    classes and bins, so order 1 of any chain is the K = 1 estimate
    (``tests/test_bounces.py``)."""
    nbin = incidence.bins.shape[0] * incidence.bins.shape[1]
    if bounces == 1:
        path = choose_path(incidence, profile, azimuth, isotropic, pool, parts)
        return partial(chunk_tallies, path, nbin)
    path = choose_bounce_path(incidence, profile, azimuth, isotropic, bounces, nbin, pool, parts)
    return partial(chunk_order_tallies, path, nbin * order_slots(bounces))
