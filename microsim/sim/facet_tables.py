"""Facet tables: what a primary ray from one shared incidence does on each facet (Fresnel
weight, mirror direction, bin, whether its masking ray surely escapes), built once per
incidence and kept by the ``Tracer`` for repeated calls (``facet_table``)."""

from __future__ import annotations

import threading
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from microsim.bins import Bins
from microsim.surfaces.heightfields import TABLED_FACETS_MAX, TABLES_KEPT_BYTES

from . import dielectric_kernels, fresnel_kernels
from .engine import beam
from .engine.facets import Facets
from .heightfield_caster import NO_STEPS, steps_over
from .ledger import MASKED, SINGLE
from .ray_bins import locate_single
from .scratch import WorkArray, WorkColumns
from .tracer import Tracer

__all__ = [
    "FacetTable",
    "InterfaceTable",
    "TABLES_KEPT",
    "facet_table",
    "interface_table",
    "steep_facets",
    "uses_facet_table",
]

_TABLE_WO = WorkColumns("table-wo")  # this thread's work arrays (``scratch``)
_TABLE_BIN = WorkArray("table-bin", np.int64)


@dataclass(frozen=True)
class FacetTable:
    """What a primary ray from ``wi`` does on each facet of a surface traced without azimuth
    averaging (wi is then the same for every ray): ``code`` (F,) int8 SINGLE (lit, reflects
    upwards: a masking ray decides), DOWNWARD or RAY_UNRESOLVED (back-facing); ``weight`` (F,)
    Fresnel F(n·wi) (0 when back-facing); ``wo32`` (F, 3) the mirror direction
    wo = 2(wi·n)n − wi in float32 — the direction Embree traces the masking ray along, whose
    float64 value the walk uses too; ``bin`` (F,) int32 flat bin index of wo (from float64
    wo; −1 below the horizon); the tracer's ``facets`` (``engine.facets.Facets``: a point p
    starts its masking ray at p − (p·n − lift) n, lift = n·v0 + eps: on the facet plane, eps
    above it);
    ``clear`` (F,) bool: lit facets whose rays all escape without a masking ray, because
    their mirror direction rises more steeply than the surface can (``Tracer.surely_escapes``)
    or, on heightfield grids, because the beam of them clears the relief (``beam``);
    ``ahead`` (ny, nx) int8 on heightfield grids (else ``NO_STEPS``): per cell, the cells a
    primary ray from wi that enters the relief there surely steps over
    (``heightfield_caster.steps_over``). 26 bytes per facet, and one per grid cell, besides
    the tracer's own columns."""

    code: np.ndarray
    weight: np.ndarray
    bin: np.ndarray
    wo32: np.ndarray
    facets: Facets
    clear: np.ndarray
    ahead: np.ndarray


TABLES_KEPT = 4
"""Facet tables a ``Tracer`` keeps for repeated calls at the same incidence: the most recent,
the older ones only while they add up to at most ``TABLES_KEPT_BYTES`` (13 MB each on the
bench's 524 288-facet mesh: all four; one beyond the newest on a 2048² heightfield, none on
a 4096² one)."""
PIECE_FACETS = 1 << 18
"""The most facets a facet table is built for at a time (its temporaries: ~100 B a facet)."""
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
    in ``parts`` contiguous facet ranges on ``pool``, each cut into pieces of at most
    ``PIECE_FACETS`` (each facet's entries depend on that facet alone, so the split changes
    nothing; the pieces keep the build's temporaries small). Bins are ``Bins.locate``'s
    (``locate_single``: a compiled pass on folded grids).

    A ``Tracer`` keeps its ``TABLES_KEPT`` most recent tables (read-only arrays), so that
    repeated calls at one incidence — ``simulate_auto``'s batches, a run resumed, the same
    surface simulated again — build each once; the tracer itself is immutable, so a kept
    table stays exact."""
    key = (tuple(float(w) for w in wi), fresnel_kernels.fresnel_mode(ior), bins, float(phi_i))
    return _kept(
        tracer,
        key,
        lambda: _build_facet_table(tracer, wi, ior, bins, phi_i, pool, parts),
        ("code", "weight", "bin", "wo32", "clear", "ahead"),
    )


def _kept(tracer: Tracer, key, build, arrays):
    """The table of ``key`` kept by ``tracer``, else ``build()``'s, its ``arrays`` made
    read-only and kept: the ``TABLES_KEPT`` most recent, the older ones only while their own
    arrays add up to at most ``TABLES_KEPT_BYTES``. ``tracer.facet_tables`` maps each key to
    (table, bytes of its arrays), most recent last."""
    kept = getattr(tracer, "facet_tables", {})  # (a stand-in without it keeps nothing)
    with _TABLES_LOCK:
        entry = kept.pop(key, None)
        if entry is not None:
            kept[key] = entry  # most recent last
            return entry[0]
    table = build()
    for name in arrays:
        getattr(table, name).flags.writeable = False
    with _TABLES_LOCK:
        kept[key] = (table, sum(getattr(table, name).nbytes for name in arrays))
        room, older = TABLES_KEPT_BYTES, list(kept)[-TABLES_KEPT:-1]
        while older and kept[older[-1]][1] <= room:  # the newest of the older ones first
            room -= kept[older.pop()][1]
        for old in list(kept)[: -TABLES_KEPT or None] + older:
            kept.pop(old, None)
    return table


class InterfaceTable(NamedTuple):
    """What a primary ray from one shared incidence does at its first interaction with each
    facet of a lossless dielectric interface (``dielectric_kernels.first_interactions``):
    ``weight`` (F,) its Fresnel F, ``flags`` (F,) int8 (``FACES_AWAY``, ``TOTAL_REFLECTION``)
    and ``bin`` (F, 2) int32, per choice (reflected, refracted), the bin its ray escapes into
    when it surely leaves the relief (−1 outside the grid) or ``TRACED``. 17 bytes per
    facet."""

    weight: np.ndarray
    flags: np.ndarray
    bin: np.ndarray


def interface_table(tracer: Tracer, wi, interface, binning, slope: float) -> InterfaceTable:
    """The ``InterfaceTable`` of primary rays lit from ``wi`` (from below when wi_z < 0) on
    the ``dielectric_kernels.Interface`` ``interface``, bins ``binning``
    (``interface_grid.FoldedBinning``), rays rising more steeply than ``slope`` surely
    leaving; kept by the tracer as ``facet_table``'s tables are."""
    d = tuple(-float(w) for w in wi)
    key = ("interface", d, interface, binning.n_theta, binning.edges.tobytes(), binning.phi_deg)

    def build() -> InterfaceTable:
        f = tracer.facets.count
        table = InterfaceTable(
            np.empty(f), np.empty(f, dtype=np.int8), np.empty((f, 2), dtype=np.int32)
        )
        inside = d[2] > 0.0
        dielectric_kernels.first_interactions(
            tracer.facets,
            d,
            inside,
            interface,
            (float(slope), tracer.beam, tracer.beam_below),
            binning,
            table.weight,
            table.flags,
            table.bin,
        )
        return table

    return _kept(tracer, key, build, ("weight", "flags", "bin"))


def _build_facet_table(tracer, wi, ior, bins, phi_i, pool, parts) -> FacetTable:
    """``facet_table`` built (not looked up)."""
    f = tracer.facets.count
    weight, code = np.empty(f), np.empty(f, dtype=np.int8)
    wo32, where = np.empty((f, 3), dtype=np.float32), np.empty(f, dtype=np.int32)
    clear = np.empty(f, dtype=np.bool_)
    wi = [float(w) for w in wi]
    fresnel_args = fresnel_kernels.fresnel_mode(ior)

    def fill(part: slice) -> None:
        wo = _TABLE_WO(part.stop - part.start)
        fresnel_kernels.facet_mirror(
            tracer.facets,
            part.start,
            *wi,
            *fresnel_args[1:],
            fresnel_args[0],
            weight[part],
            code[part],
            *wo,
            wo32[part],
        )
        rising = np.where(wo[2] > 0.0, SINGLE, MASKED).astype(np.int8)  # the others: −1
        found = _TABLE_BIN(part.stop - part.start)  # int64, as the rays' bins: one kernel
        found.fill(-1)
        locate_single(bins, rising, wo, phi_i, None, found)
        where[part] = found
        clear[part] = steep_facets(tracer, code[part], wo32[part])  # part by part: less memory

    pieces = max(1, int(parts)) * max(1, -(-f // (max(1, int(parts)) * PIECE_FACETS)))
    cuts = np.linspace(0, f, pieces + 1).astype(int)
    slices = [slice(a, b) for a, b in zip(cuts[:-1], cuts[1:])]
    list(pool.map(fill, slices) if pool is not None else map(fill, slices))
    if tracer.beam is not None:  # heightfield grids: whole beams cleared (``beam``)
        candidates, cleared = (code == SINGLE) & ~clear, np.empty(f, dtype=np.bool_)

        def clear_beams(part: slice) -> None:
            beam.beam_clear(part.start, candidates[part], wo32[part], tracer.beam, cleared[part])

        list(pool.map(clear_beams, slices) if pool is not None else map(clear_beams, slices))
        clear |= cleared
    down = [-w for w in wi]
    return FacetTable(
        code=code,
        weight=weight,
        bin=where,
        wo32=wo32,
        facets=tracer.facets,
        clear=clear,
        ahead=NO_STEPS if tracer.grid is None else steps_over(tracer.grid, down, tracer.zmax),
    )


def steep_facets(tracer: Tracer, code: np.ndarray, wo32: np.ndarray) -> np.ndarray:
    """Lit facets (``code`` SINGLE) whose float32 mirror direction ``wo32`` (F, 3), traced as
    its float64 value, rises more steeply than the surface can (``Tracer.surely_escapes``):
    the facet table's ``clear`` before any beam is cleared."""
    wo = wo32.astype(np.float64)
    return (code == SINGLE) & tracer.surely_escapes(wo[:, 0], wo[:, 1], wo[:, 2])


def table_pays(facets: int, rays: int) -> bool:
    """Whether a facet table is worth building for ``rays`` on a mesh of ``facets``: no more
    facets than rays (the table's build is one pass over the facets), and no more than
    ``TABLED_FACETS_MAX`` (larger meshes are traced ray by ray, so that their memory stays
    proportional to their heights)."""
    return facets <= rays and facets <= TABLED_FACETS_MAX


def uses_facet_table(tracer: Tracer, profile, azimuth: bool, rotate: bool, n_total: int) -> bool:
    """Whether ``choose_path`` traces through a per-facet table: surfaces without azimuth
    averaging or per-block rotation, where the table pays (``table_pays``)."""
    plain = not azimuth and not rotate and profile is None
    return plain and table_pays(tracer.facets.count, n_total)
