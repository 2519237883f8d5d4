"""Paths through a dielectric interface on a heightfield grid, each followed to its end in one
compiled loop (``trace_grid_interface``; ``dielectric.trace_dielectric`` is the same estimator
step by step, through Embree on other meshes).

On a heightfield tile (``heightfield_caster.HeightfieldGrid``) every ray of a path, the
primary one and each continuation, from above the surface or from below it (inside the
medium), is walked on the grid (``heightfield_caster.cast_one``, exact in float64), so a path
needs no Embree call and no pass over arrays between its interactions: walk, interaction
(``dielectric_kernels.interact``: Fresnel, roulette, the next ray), walk again, until the path
ends; a path that leaves the relief is binned there (``bin_kernels.locate_folded``: the bins
of ``Bins.locate``) and written to the same ``dielectric.InterfaceOutcome`` as the step-by-step
path. The estimator is that of ``dielectric`` — the same interactions, roulette draws, ledger
and bins — and so are the results, except where the float64 walk and Embree's float32 mesh
find different hits (rays within rounding of an edge): the two agree path by path on all but
a few in 10⁵ (``tests/test_interface_grid.py``).

Continuation rays: one that surely leaves the relief (steeper than the steepest facet, away
from the surface on its side: ``Tracer.surely_escapes``'s bound) is not walked; the others are
walked with the wrap cap their direction needs (``Tracer.wraps_needed``, at most
``bounces.RETRY_WRAPS``, beyond which they stay unresolved, as ``bounces.resolve_grazing``
leaves them). Used for incidences with one direction on a folded bin grid; the others take
``dielectric``'s path (on the same grid walk, one step at a time).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from microsim.bin_kernels import bin_scales, locate_folded
from microsim.bins import Bins
from microsim.jit import read_only, vector_inlined, vectorised

from .bounce_kernels import FacetPlanes, PathLedger, next_start
from .bounces import RETRY_WRAPS
from .dielectric_kernels import (
    CONTINUES,
    ESCAPES,
    FACES_AWAY,
    TOTAL_REFLECTION,
    TRACED,
    PathSides,
    end_escape,
    interact,
    path_uniform,
)
from .engine.codes import ESCAPED, HIT, MISSED, SINGLE, UNRESOLVED
from .engine.horizon import rises_clear
from .facet_tables import InterfaceTable, interface_table
from .heightfield_caster import NO_STEPS, cast_one, direction_terms
from .horizon_bounds import CLEAR_MARGIN
from .scratch import WorkArray
from .streams import BLOCK
from .tallies import ledger_columns
from .tally_kernels import ChunkSums, close_block, tally_path
from .tracer import BASE_WRAPS, Tracer

__all__ = [
    "GridWalk",
    "FoldedBinning",
    "NO_TABLE",
    "uses_grid_walk",
    "grid_walk_of",
    "folded_binning",
    "grid_interface_paths",
    "trace_grid_interface",
]


# this thread's work arrays (``scratch``)
_INSIDE = WorkArray("grid-path-inside", np.bool_)
_BELOW = WorkArray("grid-path-below")


class GridWalk(NamedTuple):
    """What the walk of a path's rays reads: ``geometry`` (``HeightfieldGrid.geometry``, its
    wrap cap that of primary rays), ``cell_min`` (per cell its lowest vertex), ``slope``
    (a continuing ray rising above its side's surface more steeply than this surely leaves;
    inf: none known), ``crossings`` (tile-wall crossings per unit of |d_h|/|d_z| while a ray
    crosses the relief) and ``retry_wraps`` (the largest wrap cap)."""

    geometry: tuple
    cell_min: np.ndarray
    slope: float
    crossings: float
    retry_wraps: int


NO_TABLE = InterfaceTable(
    read_only(np.zeros(1)),
    read_only(np.zeros(1, dtype=np.int8)),
    read_only(np.zeros((1, 2), np.int32)),
)
"""The placeholder table of an incidence without one (``grid_interface_paths``'s ``first``
then comes with ``use`` False); read-only, as a kept table's arrays: one compiled kernel."""


class FoldedBinning(NamedTuple):
    """The escapes' bins: a folded grid's ``n_theta`` and Δφ ``edges`` (degrees), its
    ``bin_scales``, the incident azimuth (``ex``, ``ey``) = (cos φi, sin φi) and ``phi_deg``,
    order ``slots`` per side and ``nbin`` bins per slot."""

    n_theta: int
    edges: np.ndarray
    scales: tuple
    ex: float
    ey: float
    phi_deg: float
    slots: int
    nbin: int


def uses_grid_walk(tracer: Tracer, bins: Bins, wi, psi) -> bool:
    """Whether an incidence from ``wi`` takes the grid walk: a heightfield grid walked by the
    tracer (``Tracer.grid``), one incident direction (``psi`` None) and a folded bin grid."""
    return tracer.grid is not None and psi is None and bins.folded


def grid_walk_of(tracer: Tracer) -> GridWalk:
    """The ``GridWalk`` of ``tracer``'s heightfield grid."""
    g = tracer.grid
    depth = tracer.zmax - tracer.zmin + tracer.top_margin
    return GridWalk(
        g.geometry(tracer.zmin, tracer.zmax, tracer.max_wraps),
        g.cell_min,
        CLEAR_MARGIN * tracer.rise_bound,
        depth * (1.0 / tracer.tile[0] + 1.0 / tracer.tile[1]),
        RETRY_WRAPS,
    )


def folded_binning(bins: Bins, phi_deg: float, slots: int, nbin: int) -> FoldedBinning:
    """The ``FoldedBinning`` of a folded ``bins`` against the incident azimuth ``phi_deg``."""
    n_phi = len(bins.phi_edges) - 1
    return FoldedBinning(
        int(bins.n_theta),
        np.ascontiguousarray(bins.phi_edges, dtype=np.float64),
        bin_scales(int(bins.n_theta), n_phi),
        math.cos(math.radians(phi_deg)),
        math.sin(math.radians(phi_deg)),
        float(phi_deg),
        int(slots),
        int(nbin),
    )


@vector_inlined
def _tally_index(binning, transmitted, order, loc):
    """The flat tally index of an escape after ``order`` interactions into bin ``loc`` (−1:
    none): (side·slots + min(order, slots) − 1)·nbin + loc, the transmitted slots after the
    reflected ones."""
    if loc < 0:
        return -1
    slot = (binning.slots if transmitted else 0) + min(order, binning.slots) - 1
    return slot * binning.nbin + loc


@vector_inlined
def _wrap_cap(dx, dy, dz, walk):
    """The wrap cap of a continuing ray (``Tracer.wraps_needed``, at least the primaries' and
    at most ``walk.retry_wraps``)."""
    need = BASE_WRAPS + math.ceil(walk.crossings * math.sqrt(dx * dx + dy * dy) / abs(dz))
    base = walk.geometry[9]
    if need <= base:
        return base
    return int(min(need, walk.retry_wraps))


@vectorised
def grid_interface_paths(
    xs, ys, zs, down, walk, chain, facets, interface, roulette, sides, ledger, binning, tables,
    tally,
):  # fmt: skip
    """Follow the paths from the starts (``xs``, ``ys``, ``zs``)[g] along the primary
    direction ``down`` (3 floats; rising when lit from below) to their ends (module
    docstring), writing ``ledger`` (``bounce_kernels.PathLedger``: classes, weights and the
    flat tally index side·slots·nbin + order·nbin + bin of each escape) and ``sides``
    (``dielectric_kernels.PathSides``), and adding each path to its block's tallies as it ends
    (``tally`` = (block, sums, tir_col): ``tally_kernels.order_block_tallies``' arguments, the
    same sums in the same order). ``walk``: ``GridWalk``; ``chain``: (limit, floor);
    ``facets``: ``bounce_kernels.FacetPlanes``; ``interface``, ``roulette``: as
    ``dielectric_kernels.interact``; ``binning``: ``FoldedBinning``; ``tables``: (use_first,
    first), whether the ``facet_tables.InterfaceTable`` ``first`` of the primary direction
    ends the paths that leave the relief at once (with the values ``interact`` gives them).

    One loop, not a helper per path: numba copies an inlined helper into its caller before
    typing, at a cost that grows with the square of its size (``microsim.jit``)."""
    block, sums, tir_col = tally
    outcome = (ledger.status1, ledger.weight1, ledger.term, ledger.wterm, ledger.where, sides.tir)
    use_first, first = tables
    geometry = walk.geometry
    cell = geometry[4]
    above, below = (1.0, geometry[1]), (-1.0, walk.cell_min)
    limit, floor = chain
    half = (facets.half_x, facets.half_y)
    primary = direction_terms(down[0], down[1], down[2], cell)
    j = 0
    sums.offsets[0] = 0
    for b in range((len(xs) + block - 1) // block):
        lo, hi = b * block, min(len(xs), (b + 1) * block)
        for g in range(lo, hi):
            x, y, z = xs[g], ys[g], zs[g]  # each ray's start: the primary's, then the next's
            dx, dy, dz = down
            side = below if sides.from_below else above
            terms, cap, w = primary, geometry[9], 1.0
            order = 1
            while True:  # path g's rays, to its end
                walks = True  # one call site of the (inlined) walk: it is compiled once
                if order > 1:
                    side = below if sides.inside[g] else above
                    if rises_clear(dx, dy, side[0] * dz, walk.slope):
                        # surely leaves the relief: away from its side's surface (up above
                        # it, down below it: ``side[0]`` = ±1) more steeply than any facet
                        h, f, px, py, pz = ESCAPED if dz > 0.0 else MISSED, -1, 0.0, 0.0, 0.0
                        walks = False
                    elif dz == 0.0:
                        h, f, px, py, pz = UNRESOLVED, -1, 0.0, 0.0, 0.0
                        walks = False
                    else:
                        terms = direction_terms(dx, dy, dz, cell)
                        cap = _wrap_cap(dx, dy, dz, walk)
                if walks:
                    h, f, px, py, pz = cast_one(
                        x, y, z, dx, dy, dz, terms, geometry, side, cap, NO_STEPS
                    )
                if order == 1 and use_first and h == HIT and first.flags[f] != FACES_AWAY:
                    fw = first.weight[f]
                    reflect = first.flags[f] == TOTAL_REFLECTION
                    reflect = reflect or path_uniform(roulette.stream, roulette.ray0 + g, 1) < fw
                    loc = first.bin[f, 0 if reflect else 1]
                    if loc != TRACED:  # leaves the relief at once: order 1, on its side
                        ledger.status1[g], ledger.weight1[g] = SINGLE, 1.0
                        if first.flags[f] == TOTAL_REFLECTION:
                            sides.tir[g] |= np.int8(1)
                        # the escape's direction falls if it was reflected from above or
                        # refracted from below, as the primary rises or falls
                        transmitted = end_escape(ledger, sides, 2, g, 1.0, -dz if reflect else dz)
                        ledger.where[g] = _tally_index(binning, transmitted, 1, loc)
                        break
                what, wn, ox, oy, oz, offset, normal = interact(
                    order, limit, floor, g, w, h, f, (dx, dy, dz), facets, interface, roulette,
                    sides, ledger,
                )  # fmt: skip
                if what == ESCAPES:
                    transmitted = end_escape(ledger, sides, order, g, w, dz)
                    loc = locate_folded(
                        dx, dy, abs(dz), binning.ex, binning.ey, binning.phi_deg,
                        binning.n_theta, binning.edges, binning.scales,
                    )  # fmt: skip
                    ledger.where[g] = _tally_index(binning, transmitted, order - 1, loc)
                    break
                if what != CONTINUES:
                    break
                x, y, z = next_start((px, py, pz), normal, offset, half)
                dx, dy, dz = ox, oy, oz
                w = wn
                order += 1
            j = tally_path(g, g - lo, b, j, outcome, sums, tir_col)
        close_block(b, j, sums)


def trace_grid_interface(
    tracer: Tracer, wi, phi_i, bins: Bins, origins, path, out, sums: ChunkSums
) -> None:
    """``dielectric.trace_dielectric`` by the grid walk (``uses_grid_walk``): the paths from
    ``origins`` (3 columns, on the plane above the relief; moved under it when lit from below)
    along −wi, written to the ``dielectric.InterfaceOutcome`` ``out`` (``where`` −1 and
    ``tir`` 0 on entry), each path added to its block's tallies in ``sums`` as it ends
    (``tallies.chunk_sums``: ``BLOCK``-ray blocks, the dielectric ledger's
    ``tallies.ledger_columns``). ``path``: (chain, interface, roulette, table) — the
    ``bounces.ChainLimits``, the ``dielectric_kernels.Interface`` and ``Roulette``, and
    whether the incidence's first interactions may come from a facet table (one incidence
    direction for all its rays, a lossless medium: ``facet_tables.interface_table``)."""
    chain, interface, roulette, table = path
    xs, ys, zs = (np.ascontiguousarray(c, dtype=np.float64) for c in origins)
    down = tuple(-float(c) for c in wi)
    from_below = down[2] > 0.0
    if from_below:  # the starts moved under the relief
        zs = _BELOW(len(xs))
        zs.fill(tracer.zmin - tracer.top_margin)
    inside = _INSIDE(len(xs))
    inside.fill(from_below)
    sides = PathSides(inside, from_below, out.tir)
    half = float(tracer.half[0]), float(tracer.half[1])
    facets = FacetPlanes(tracer.facets, *half)
    binning = folded_binning(bins, float(phi_i), min(chain.limit, 4), chain.nbin)
    walk = grid_walk_of(tracer)
    use_first = bool(table and not interface.absorbing)
    first = interface_table(tracer, wi, interface, binning, walk.slope) if use_first else NO_TABLE
    grid_interface_paths(
        xs, ys, zs, down, walk, (int(chain.limit), float(chain.floor)),
        facets, interface, roulette, sides, PathLedger(*out[:5]), binning, (use_first, first),
        (BLOCK, sums, ledger_columns(True)[1]),
    )  # fmt: skip
