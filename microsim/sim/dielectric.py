"""Paths through a dielectric interface: reflection *and* transmission on an explicit surface
(``simulate(..., transmission=True)``).

The surface separates air (index 1, above) from a medium of index η (below); its facet normals
point into the air. Light comes from above (θi in [0, 90): air → medium) or from below (θi in
(90, 180], wi_z < 0: the surface lit from inside the medium, medium → air). At every hit the
path is reflected or refracted with the exact unpolarised Fresnel factor of the dielectric
interface, total internal reflection included (``dielectric_kernels``: Russian roulette, the
weight of a lossless path stays 1), and goes on from either side until it leaves the relief:
upward past its top or downward past its bottom. A path leaving on the incidence's side is
reflected, on the other side transmitted; each is tallied under its order (the number of
interactions: 1, 2, 3, ≥ 4) in the bin of its direction, θo measured from the pole of the side
it leaves by. The bin average f̄_B = Σ w / (N Ω_B) (Mikkelsen 2009, eq. 9, on either
hemisphere) is the BRDF, resp. the BTDF, in the radiance convention: Σ_B f̄_B Ω_B over both is
the fraction R + T of the incident flux, and the BTDF obeys Walter et al. 2007's generalised
reciprocity f_t(i, o)/η_o² = f_t(o, i)/η_i² (eq. 21; docs/dielectric.md).

A complex index (k > 0) is an absorbing medium whose bulk keeps what it refracts: the path
reflects with the weight F (as the opaque chain of ``bounces``) and the rest is absorbed; such
a medium can be lit from above only. ``bounces``: K cuts the path after K interactions
(``cut_bounces``), "all" follows it until it leaves (at most ``bounces.MAX_BOUNCES``).

Tallies: 2·O order slots × bins (O = ``bounces.order_slots``): the O reflected slots, then the
O transmitted ones (``tallies.simulation_result`` splits them into ``brdf_orders`` and
``btdf_orders``); the ledger has the ``ledger.DIELECTRIC_TERMINAL`` classes and the
``ledger.TIR_ORDERS`` columns. Traced masking only, on heightfields and V-grooves, with the
periodic wrap: step by step (``trace_dielectric``: each step's rays through ``Tracer.
trace_columns``, Embree or a heightfield's grid walk), or on a heightfield grid in one compiled
loop per chunk (``interface_grid``, the same estimator); a continuing ray that
surely leaves the relief (steeper than the steepest facet, away from the surface on its side)
is not traced (``leaving``, ``bounces.trace_continuing``: its walk's outcome is known, so no
number changes); bitwise reproducible as the opaque chains are (each path on its own, its
roulette draws a hash of its number).
"""

from __future__ import annotations

from typing import Callable, NamedTuple

import numpy as np

from microsim.bins import Bins
from microsim.errors import UsageError

from . import bounce_kernels, dielectric_kernels
from .bounces import (
    BouncePath,
    ChainLimits,
    bin_escapes,
    bounce_limit,
    next_rays,
    order_slots,
    primary_rays,
    trace_continuing,
)
from .dielectric_kernels import Interface, PathSides, Roulette, SideEscapes
from .engine import segments
from .engine.codes import SINGLE
from .facet_tables import uses_facet_table
from .interface_grid import trace_grid_interface, uses_grid_walk
from .ray_bins import locate_single
from .ray_columns import columns
from .scratch import WorkArray, WorkColumns
from .streams import block_span
from .tallies import ChunkTallies, chunk_of, chunk_sums, ledger_columns, split_order_tallies
from .tally_kernels import ChunkSums
from .tracer import Tracer

__all__ = [
    "ROULETTE_STREAM",
    "InterfaceOutcome",
    "check_transmission",
    "check_light_from_below",
    "interface_task",
    "interface_of",
    "roulette_stream",
    "trace_dielectric",
    "leaving",
    "bin_side_escapes",
    "DielectricPath",
]

ROULETTE_STREAM = 0xD1E1
"""Extra key of the roulette's stream (``roulette_stream``), apart from the origins' streams."""


class InterfaceOutcome(NamedTuple):
    """``bounces.ChainOutcome`` of paths through a dielectric interface, with ``tir`` (N,)
    int8: per path its total-internal-reflection bits (``dielectric_kernels.PathSides``)."""

    status1: np.ndarray
    weight1: np.ndarray
    term: np.ndarray
    wterm: np.ndarray
    where: np.ndarray
    tir: np.ndarray

    @classmethod
    def empty(cls, n: int) -> "InterfaceOutcome":
        """The outcome arrays of ``n`` paths before they are followed (no escape bin, no
        total internal reflection)."""
        return cls(
            np.empty(n, dtype=np.int8),
            np.zeros(n),
            np.empty(n, dtype=np.int8),
            np.empty(n),
            np.full(n, -1, dtype=np.int64),
            np.zeros(n, dtype=np.int8),
        )

    @classmethod
    def work(cls, n: int) -> "InterfaceOutcome":
        """``empty``'s arrays as this thread's work arrays (``scratch``): for an outcome
        consumed before the thread follows other paths."""
        out = cls(*(w(n) for w in _OUTCOME))
        out.weight1.fill(0.0)
        out.where.fill(-1)
        out.tir.fill(0)
        return out


# this thread's work arrays (``scratch``): each step's escapes (the next step's rays are the
# bounce chain's, ``bounces.next_rays``)
_OUTCOME = tuple(
    WorkArray(f"interface-outcome-{name}", dtype)
    for name, dtype in (
        ("status1", np.int8),
        ("weight1", np.float64),
        ("term", np.int8),
        ("wterm", np.float64),
        ("where", np.int64),
        ("tir", np.int8),
    )
)
_ESCAPE = WorkArray("interface-escape", np.int64)
_ESCAPE_DIRECTION = WorkColumns("interface-escape-direction")
_ESCAPE_SIDE = WorkArray("interface-escape-side", np.bool_)
_ESCAPE_BIN = WorkArray("interface-escape-bin", np.int64)


def check_transmission(transmission, ior) -> bool:
    """``transmission`` as a bool, checked against the resolved material ``ior`` (an index or
    None): UsageError for a non-bool, or with transmission for a mirror or an index of 1 (no
    interface)."""
    if not isinstance(transmission, (bool, np.bool_)):
        raise UsageError(f"transmission must be True or False, got {transmission!r}")
    if transmission and (ior is None or complex(ior) == 1):
        raise UsageError(
            "transmission=True needs a material with an index n (> 0, != 1) or n+ik: "
            f"the medium below the surface, got {'a mirror' if ior is None else 'n = 1'}"
        )
    return bool(transmission)


def check_light_from_below(ior, theta_i) -> None:
    """UsageError if an incidence of ``theta_i`` (degrees) lights an absorbing medium (k > 0)
    from inside: its bulk keeps the light."""
    below = [t for t in theta_i if t > 90.0]
    if below and ior is not None and complex(ior).imag > 0:
        raise UsageError(
            f"theta_i {below[0]:g} lights the surface from inside an absorbing medium "
            f"(k = {complex(ior).imag:g} > 0), whose bulk keeps the light: use theta_i in [0, 90)"
        )


def interface_of(ior, tracer: Tracer) -> Interface:
    """The kernel's ``Interface`` of the resolved index ``ior`` on ``tracer``'s surface."""
    eta = complex(ior)
    return Interface(eta.real**2, eta.imag**2, eta.imag > 0, float(tracer.eps))


def roulette_stream(key) -> np.uint64:
    """The roulette's 64-bit stream word of the random stream ``key`` (seed, realisation,
    incidence)."""
    seq = np.random.SeedSequence(list(key) + [ROULETTE_STREAM])
    return np.uint64(seq.generate_state(1, np.uint64)[0])


def trace_dielectric(
    tracer: Tracer,
    wi,
    phi_i,
    bins: Bins,
    origins,
    psi,
    ior,
    chain: ChainLimits,
    roulette: Roulette,
) -> InterfaceOutcome:
    """The ``InterfaceOutcome`` of primary rays followed through the dielectric interface.

    Rays start at ``origins`` (3 columns on the plane above the relief; moved under it when
    lit from below, wi_z < 0) along −wi (one shared direction when ``psi`` is None, else wi
    rotated by −ψ per ray into its groove frame, as ``bounces.trace_bounces``). Each step
    traces the live paths' rays (``bounces.trace_continuing``) and hands the hits to
    ``dielectric_kernels.interface_step``; escapes are binned with Δφ against ``phi_i`` (or
    φi − ψ in the groove frame) into slot (side·O + order)·nbin + bin."""
    x = columns(origins)
    n = len(x[0])
    from_below = float(wi[2]) < 0.0
    if from_below:
        x[2] = np.full(n, tracer.zmin - tracer.top_margin)
    out = InterfaceOutcome.empty(n)
    sides = PathSides(np.full(n, from_below), from_below, out.tir)
    ledger = bounce_kernels.PathLedger(*out[:5])
    (hs, prim, p), d, shared = primary_rays(tracer, x, wi, psi)
    phi = float(phi_i) if psi is None else phi_i - np.degrees(psi)
    live, w = np.arange(n, dtype=np.int64), np.ones(n)
    hx, hy = float(tracer.half[0]), float(tracer.half[1])
    facets = bounce_kernels.FacetPlanes(tracer.facets, hx, hy)
    interface = interface_of(ior, tracer)
    slots = min(chain.limit, 4)
    b = 1
    while True:
        k = len(live)
        par = b % 2
        esc = SideEscapes(_ESCAPE(k), *_ESCAPE_DIRECTION(k), _ESCAPE_SIDE(k))
        nxt = next_rays(k, par)
        m, e = dielectric_kernels.interface_step(
            b, chain.limit, chain.floor, live, w, segments.WalkResult(hs, prim, *p),
            bounce_kernels.RayDirections(*d, shared), facets, interface, roulette, sides,
            ledger, esc, nxt,
        )  # fmt: skip
        if e:
            order = min(b - 1, slots) - 1
            offset = (esc.transmitted[:e] * slots + order) * chain.nbin
            bin_side_escapes(bins, esc, e, phi, offset, out.where)
        if m == 0:
            break
        sure = leaving(tracer, nxt, m, sides.inside)
        live, w, d, (hs, prim, p) = trace_continuing(tracer, nxt, m, sure)
        shared = False
        b += 1
    return out


def bin_side_escapes(bins: Bins, esc: SideEscapes, e: int, phi, offset, where) -> None:
    """``bounces.bin_escapes`` of the first ``e`` escapes of ``esc`` (directions in the upper
    hemisphere, flipped up when they left downward): with one incident azimuth ``phi`` on a
    folded grid by ``ray_bins.locate_single`` (compiled and vectorised, ``Bins.locate``'s bin
    for every direction, ties on an edge included), else by ``Bins.locate``."""
    rows, wo = esc.index[:e], [c[:e] for c in esc[1:4]]
    if not (bins.folded and np.ndim(phi) == 0):
        bin_escapes(bins, rows, wo, phi, offset, where)
        return
    found = _ESCAPE_BIN(e)
    every = np.full(e, SINGLE, dtype=np.int8)  # locate_single bins the SINGLE rows
    locate_single(bins, every, wo, float(phi), None, found)
    where[rows] = offset + found


def leaving(tracer: Tracer, nxt, m: int, inside: np.ndarray) -> np.ndarray:
    """Which of the ``m`` continuing rays surely leave the relief: away from the surface on
    their own side (up in the air, down inside the medium, ``inside`` per path) more steeply
    than the steepest facet, they cannot meet it again (``Tracer.surely_escapes``, the
    Lipschitz bound of ``horizon_bounds.rise_bound``, which holds either way up)."""
    dz = nxt.dz[:m]
    return tracer.surely_escapes(nxt.dx[:m], nxt.dy[:m], np.where(inside[nxt.live[:m]], -dz, dz))


class DielectricPath(BouncePath):
    """``BouncePath`` whose chains go through a dielectric interface (``trace_dielectric``),
    each block's roulette drawing from the incidence's stream at its rays' numbers."""

    def __init__(self, incidence, azimuth: bool, rotate: bool, chain: ChainLimits):
        super().__init__(incidence, azimuth, rotate, chain)
        self.stream = roulette_stream(incidence.key)
        tracer = incidence.tracer
        self.table = uses_facet_table(tracer, None, azimuth, rotate, incidence.rays)
        self.tallied = 2 * order_slots(chain.limit) * chain.nbin  # both sides' order slots × bins

    def trace(self, wi, phi_i, starts, psi, blocks) -> InterfaceOutcome:
        """The paths from ``starts`` (``follow``'s outcome): step by step, or on a heightfield
        grid in one compiled loop where it applies
        (``interface_grid.uses_grid_walk``)."""
        if not uses_grid_walk(self.incidence.tracer, self.incidence.bins, wi, psi):
            return self._step_by_step(wi, phi_i, starts, psi, blocks)
        x = columns(starts)
        out = InterfaceOutcome.empty(len(x[0]))  # kept by the caller
        self._on_grid(wi, phi_i, x, blocks, out, self._sums(len(x[0]), blocks))
        return out

    def tallies(self, blocks) -> ChunkTallies:
        """The per-block tallies of the paths of ``blocks`` over 2·O order slots × bins: on a
        heightfield grid summed as each path ends (``interface_grid``), else from the
        outcome (``tallies.split_order_tallies``); the same sums either way."""
        blocks = list(blocks)
        return ChunkTallies.joined([self._group_tallies(*g) for g in self.groups(blocks)])

    def _group_tallies(self, wi, phi_i, starts, psi, blocks) -> ChunkTallies:
        inc = self.incidence
        if not uses_grid_walk(inc.tracer, inc.bins, wi, psi):
            out = self._step_by_step(wi, phi_i, starts, psi, blocks)
            n_blocks = len(blocks)
            return split_order_tallies(**out._asdict(), n_blocks=n_blocks, nbin_total=self.tallied)
        x = columns(starts)
        sums = self._sums(len(x[0]), blocks)
        self._on_grid(wi, phi_i, x, blocks, InterfaceOutcome.work(len(x[0])), sums)
        return chunk_of(sums)

    def _sums(self, n: int, blocks) -> ChunkSums:
        """The ``tally_kernels.ChunkSums`` of ``n`` paths in ``blocks``."""
        return chunk_sums(n, len(blocks), self.tallied, ledger_columns(True)[0])

    def _roulette(self, blocks) -> Roulette:
        return Roulette(self.stream, block_span(self.incidence.rays, list(blocks))[0])

    def _step_by_step(self, wi, phi_i, starts, psi, blocks) -> InterfaceOutcome:
        inc = self.incidence
        roulette = self._roulette(blocks)
        return trace_dielectric(
            inc.tracer, wi, phi_i, inc.bins, starts, psi, inc.ior, self.chain, roulette
        )

    def _on_grid(self, wi, phi_i, x, blocks, out, sums) -> None:
        inc = self.incidence
        interface = interface_of(inc.ior, inc.tracer)
        path = (self.chain, interface, self._roulette(blocks), self.table)
        trace_grid_interface(inc.tracer, wi, phi_i, inc.bins, x, path, out, sums)


def interface_task(incidence, azimuth: bool, isotropic: bool, bounces) -> Callable:
    """The thread task of one incidence through a dielectric interface: ``task(blocks)``
    follows the paths of those blocks (``DielectricPath``, at most a checked ``bounces``
    interactions) and returns their per-block tallies over 2·O order slots × bins
    (``DielectricPath.tallies``)."""
    nbin = incidence.bins.shape[0] * incidence.bins.shape[1]
    limit, floor = bounce_limit(bounces)
    chain = ChainLimits(int(limit), float(floor), nbin)
    path = DielectricPath(incidence, azimuth, bool(isotropic and not azimuth), chain)
    return path.tallies
