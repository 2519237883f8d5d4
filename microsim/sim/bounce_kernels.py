"""One step of the Embree bounce chain (``bounces.trace_bounces``, ``bounce_step``): per live
path, weight w ← w·F(c), c = −d·n, mirror direction wo = d + 2c·n, the terminal class of a
path that ends and the next ray (on the facet plane, eps above it) of one that goes on.

Live path i (global index ``live[i]``, carried weight ``w[i]``) was traced along direction j
(j = 0 if the directions are shared, else i) with walk outcome (status, prim, point)[i]
(``Tracer.trace_columns``); the ray traced at step b is the primary ray (b = 1) or the ray
reflected at bounce b − 1. Per path:

* ESCAPED at b ≥ 2: the path leaves after order b − 1 (``term`` ESC_*, ``wterm`` = w, its
  direction listed in ``Escapes`` for binning by the caller);
* no hit (MISSED, UNRESOLVED; ESCAPED at b = 1): PATH_MISSED / PATH_UNRESOLVED, weight w;
* a hit at b > limit: CUT_BOUNCES (the path would go on; weight w);
* a back-facing hit (c = −d·n ≤ 0): PATH_UNRESOLVED;
* otherwise bounce b: w ← w·F(c) (``fresnel_weight``), wo = d + 2c·n (the mirror direction
  2(wi·n)n − wi with wi = −d); below the weight floor the path is cut (CUT_WEIGHT, weight
  w·F); a downward wo at the last bounce (b = limit) is cut (CUT_BOUNCES: it must meet the
  surface again); else the reflected ray is set up for the next step: it starts at
  p − (p·n − lift)·n (on the facet plane, eps above it; lift = n·v0 + eps, ``FacetPlanes``)
  wrapped into the tile, along wo (and its float32 copy), compacted into ``NextRays``.

The first-bounce ledger of the same rays (``status1``, ``weight1``: the classes and Fresnel
weights of ``paths.LEDGER``, as the single-bounce paths give them) is written at b = 1
(SINGLE provisionally for a rising wo) and settled at b = 2 (MASKED if the reflected ray met
the surface, RAY_UNRESOLVED / RAY_MISSED if its walk failed).

With a ``FirstBounceTable`` in use, the incidence's facet table's Fresnel weights and bins
per facet serve the first bounce (the values the per-ray arithmetic gives, bitwise: same
Fresnel kernel, same float64 mirror direction): its facet is kept in ``first_facet`` and a
path escaping after order 1 gets ``where`` = its facet's bin there instead of being listed in
``Escapes``.

Each step also writes the cosine c of every live path's bounce (0 where the path made none
at this step: it ended before reflecting), which ``spectral_step`` turns into the weights of
W materials at once (spectral runs, ``spectral``)."""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from microsim.jit import compiled, inlined

from .engine.codes import (
    CUT_BOUNCES,
    CUT_WEIGHT,
    DOWNWARD,
    ESCAPED,
    HIT,
    MASKED,
    MISSED,
    PATH_MISSED,
    PATH_UNRESOLVED,
    RAY_MISSED,
    RAY_UNRESOLVED,
    SINGLE,
    UNRESOLVED,
    order_class,
)
from .engine.facets import Facets, facet_plane
from .fresnel_kernels import fresnel_weight


class RayDirections(NamedTuple):
    """The unit directions the live paths were traced along: one shared direction (index 0)
    when ``shared``, else one per path."""

    dx: np.ndarray
    dy: np.ndarray
    dz: np.ndarray
    shared: bool


class FacetPlanes(NamedTuple):
    """The tracer's ``facets`` (``engine.facets.Facets``: unit normals, their planes' offsets
    n·v0 and the start offset eps — a reflected ray starts on the plane n·x = n·v0 + eps, the
    facet's "lift") and the tile's half extents ``half_x``, ``half_y``."""

    facets: Facets
    half_x: float
    half_y: float


class PathLedger(NamedTuple):
    """Per primary ray (global index): first-bounce class and Fresnel weight (``status1``,
    ``weight1``), terminal class and carried weight (``term``, ``wterm``) and the flat tally
    index of its escape (``where``, −1 if none)."""

    status1: np.ndarray
    weight1: np.ndarray
    term: np.ndarray
    wterm: np.ndarray
    where: np.ndarray


class Escapes(NamedTuple):
    """Paths escaping at this step, for binning by the caller: global index and direction."""

    index: np.ndarray
    dx: np.ndarray
    dy: np.ndarray
    dz: np.ndarray


class NextRays(NamedTuple):
    """The continuing paths, compacted: global index ``live``, start (x, y, z), direction
    (dx, dy, dz) and its float32 copy ``d32`` (k, 3), carried weight ``w``."""

    live: np.ndarray
    x: np.ndarray
    y: np.ndarray
    z: np.ndarray
    dx: np.ndarray
    dy: np.ndarray
    dz: np.ndarray
    d32: np.ndarray
    w: np.ndarray


class FirstBounceTable(NamedTuple):
    """``facet_tables.FacetTable``'s per-facet Fresnel ``weight`` and ``bin`` for the first bounce
    (``use`` False: not used, placeholder arrays), and ``first_facet`` per primary ray, the
    facet of its first bounce."""

    use: bool
    weight: np.ndarray
    bin: np.ndarray
    first_facet: np.ndarray


@compiled
def bounce_step(
    b,
    limit,
    floor,
    live,
    w,
    walk,
    rays,
    facets,
    material,
    ledger,
    escapes,
    nxt,
    table,
    cosine,
):
    """One step ``b`` of the bounce chain (``bounces.trace_bounces``) over the live paths
    (module docstring): returns (continuing paths m, escapes e).

    Arguments: step ``b``, bounce ``limit``, weight ``floor``, the live paths' global indices
    ``live`` and weights ``w``; ``walk`` (``engine.segments.WalkResult`` of the rays traced
    at this step), ``rays`` (``RayDirections``), ``facets`` (``FacetPlanes``), ``material``
    (``fresnel_kernels.FresnelMaterial``), ``ledger`` (``PathLedger``, written),
    ``escapes`` (``Escapes``, written), ``nxt`` (``NextRays``, written), ``table``
    (``FirstBounceTable``) and ``cosine`` (≥ len(live), written: c of each live path's bounce
    at this step, 0 without one; a back-facing hit's c ≤ 0)."""
    hs, prim, px, py, pz = walk
    dx, dy, dz, shared = rays
    planes, hx, hy = facets
    n2, k2, fresnel_mode = material
    status1, weight1 = ledger.status1, ledger.weight1
    use_table, tab_weight, first_facet = table.use, table.weight, table.first_facet
    m = 0
    e = 0
    for i in range(len(live)):
        g = live[i]
        j = 0 if shared else i
        h = hs[i]
        cosine[i] = 0.0
        if b == 2:
            _settle_first_ray(status1, g, h)
        if h == ESCAPED and b >= 2:
            e = _escape(ledger, escapes, table, b, g, w[i], (dx[j], dy[j], dz[j]), e)
            continue
        if h != HIT:
            walk_failed = RAY_UNRESOLVED if h == UNRESOLVED else RAY_MISSED
            path_failed = PATH_UNRESOLVED if h == UNRESOLVED else PATH_MISSED
            end_unresolved(ledger, b, g, w[i], path_failed, walk_failed)
            continue
        if b > limit:
            end_path(ledger, g, CUT_BOUNCES, w[i])
            continue
        f = prim[i]
        a0, a1, a2, plane = facet_plane(planes, f)
        c = -(dx[j] * a0 + dy[j] * a1 + dz[j] * a2)
        cosine[i] = c
        if c <= 0.0:  # back-facing
            end_unresolved(ledger, b, g, w[i], PATH_UNRESOLVED, RAY_UNRESOLVED)
            continue
        if use_table and b == 1:
            fw = tab_weight[f]
            first_facet[g] = f
        else:
            fw = fresnel_weight(c, n2, k2, fresnel_mode)
        wn = w[i] * fw
        ox = dx[j] + 2.0 * c * a0
        oy = dy[j] + 2.0 * c * a1
        oz = dz[j] + 2.0 * c * a2
        if b == 1:
            weight1[g] = fw
            status1[g] = SINGLE if oz > 0.0 else DOWNWARD
        if wn < floor:
            end_path(ledger, g, CUT_WEIGHT, wn)
            continue
        if b == limit and not oz > 0.0:
            end_path(ledger, g, CUT_BOUNCES, wn)
            continue
        p, n, o = (px[i], py[i], pz[i]), (a0, a1, a2), (ox, oy, oz)
        continue_path(nxt, m, g, p, n, plane + planes.eps, (hx, hy), o, wn)
        m += 1
    return m, e


@inlined
def end_path(ledger, g, path_class, w):
    """End path ``g`` as ``path_class`` carrying weight ``w``."""
    ledger.term[g] = path_class
    ledger.wterm[g] = w


@inlined
def _escape(ledger, escapes, table, b, g, w, d, e):
    """Path ``g`` escapes after order b − 1 with weight ``w`` along ``d``: binned here from
    the first bounce's facet at b = 2 with a table in use, else listed in ``escapes`` at
    slot ``e``. Returns the number of escapes listed."""
    end_path(ledger, g, order_class(b - 1), w)
    if table.use and b == 2:
        ledger.where[g] = table.bin[table.first_facet[g]]
        return e
    escapes.index[e] = g
    escapes.dx[e], escapes.dy[e], escapes.dz[e] = d
    return e + 1


@inlined
def _settle_first_ray(status1, g, h):
    """At step 2, the first reflected ray's walk outcome ``h`` settles the provisional
    SINGLE of path ``g``: MASKED if it met the surface, RAY_UNRESOLVED / RAY_MISSED if its
    walk failed."""
    if status1[g] == SINGLE:
        if h == HIT:
            status1[g] = MASKED
        elif h == UNRESOLVED:
            status1[g] = RAY_UNRESOLVED
        elif h == MISSED:
            status1[g] = RAY_MISSED


@inlined
def end_unresolved(ledger, b, g, w, path_class, first_class):
    """End path ``g`` with carried weight ``w`` as ``path_class`` (its walk failed or its
    hit faces away); at step 1 its first-bounce class is ``first_class``, weight 0."""
    end_path(ledger, g, path_class, w)
    if b == 1:
        ledger.status1[g] = first_class
        ledger.weight1[g] = 0.0


@inlined
def next_start(p, n, lift, half):
    """The start of the ray that continues a path from the hit ``p`` (px, py, pz): moved along
    the unit normal ``n`` onto the plane n·x = ``lift`` (its facet plane, eps on the side the
    ray leaves to), wrapped into the tile (``half`` extents)."""
    px, py, pz = p
    a0, a1, a2 = n
    hx, hy = half
    off = px * a0 + py * a1 + pz * a2 - lift
    x, y, z = px - off * a0, py - off * a1, pz - off * a2
    if x < -hx or x >= hx:  # into the tile
        x = (x + hx) % (2.0 * hx) - hx
    if y < -hy or y >= hy:
        y = (y + hy) % (2.0 * hy) - hy
    return x, y, z


@inlined
def continue_path(nxt, m, g, p, n, lift, half, o, wn):
    """Write continuing path ``g`` to slot ``m`` of ``nxt``: its next ray starts at the hit
    ``p`` (px, py, pz) moved along the unit normal ``n`` onto its facet plane and eps above
    it (``lift`` = n·v0 + eps), wrapped into the tile (``half`` extents), along ``o``,
    carrying weight ``wn``."""
    x, y, z = next_start(p, n, lift, half)
    ox, oy, oz = o
    nxt.live[m] = g
    nxt.x[m], nxt.y[m], nxt.z[m] = x, y, z
    nxt.dx[m], nxt.dy[m], nxt.dz[m] = ox, oy, oz
    nxt.d32[m, 0] = np.float32(ox)
    nxt.d32[m, 1] = np.float32(oy)
    nxt.d32[m, 2] = np.float32(oz)
    nxt.w[m] = wn


class SpectralMaterials(NamedTuple):
    """W materials as ``spectral_step`` takes them: per material (column) n², k² and the
    mode of ``fresnel_kernels.FresnelMaterial``."""

    n2: np.ndarray
    k2: np.ndarray
    mode: np.ndarray


class SpectralLedger(NamedTuple):
    """Per primary ray and material (N, W): the ``PathLedger`` a run of that material writes
    (``status1``, ``weight1``, ``term``, ``wterm``, ``where``) and the weight ``w`` its path
    carries; ``term`` is −1 while that material's path goes on."""

    status1: np.ndarray
    weight1: np.ndarray
    term: np.ndarray
    wterm: np.ndarray
    where: np.ndarray
    w: np.ndarray


@compiled
def spectral_step(b, floor, live, cosine, geometry, materials, ledger, nxt, m):
    """Step ``b`` of a spectral chain: the ``bounce_step`` just made, traced with F = 1 and
    no weight floor (``geometry``: its ``PathLedger``, ``term`` −1 for paths not ended;
    ``cosine`` per live path), weighted for each of W ``materials`` (``SpectralMaterials``)
    into ``ledger`` (``SpectralLedger``) exactly as ``bounce_step`` weights one material:
    a path still carried by material l either ends here without a bounce (the geometry's
    class, ``where`` and weight w) or bounces with w ← w·F_l(c) (``fresnel_weight``), is cut
    below the weight ``floor`` (CUT_WEIGHT), ends where the geometry ended it after the bounce
    (CUT_BOUNCES), or goes on. The first-bounce class is the geometry's (settled at b = 2
    for the materials still on; kept provisional for one cut at b = 1, as its own run does).
    Then the ``m`` continuing paths of ``nxt`` (``NextRays``) are compacted to those some
    material still carries; returns their number."""
    n2, k2, modes = materials
    status1, weight1, term, wterm, where, w = ledger
    for i in range(len(live)):
        g = live[i]
        c = cosine[i]
        ended = geometry.term[g] >= 0
        for j in range(len(n2)):
            if b > 1 and term[g, j] >= 0:  # this material's path ended already
                continue
            if b <= 2:
                status1[g, j] = geometry.status1[g]
            if not c > 0.0:  # ended without a bounce
                term[g, j] = geometry.term[g]
                wterm[g, j] = w[g, j]
                where[g, j] = geometry.where[g]
                if b == 1:
                    weight1[g, j] = 0.0
                continue
            fw = fresnel_weight(c, n2[j], k2[j], modes[j])
            wn = w[g, j] * fw
            if b == 1:
                weight1[g, j] = fw
            if wn < floor:
                term[g, j] = CUT_WEIGHT
                wterm[g, j] = wn
            elif ended:
                term[g, j] = geometry.term[g]
                wterm[g, j] = wn
            else:
                w[g, j] = wn
    kept = 0
    for i in range(m):
        g = nxt.live[i]
        carried = False
        for j in range(len(n2)):
            carried = carried or term[g, j] < 0
        if carried:
            _move_next(nxt, i, kept)
            kept += 1
    return kept


@inlined
def _move_next(nxt, i, k):
    """Move continuing path ``i`` of ``nxt`` to slot ``k`` ≤ i."""
    nxt.live[k] = nxt.live[i]
    nxt.x[k], nxt.y[k], nxt.z[k] = nxt.x[i], nxt.y[i], nxt.z[i]
    nxt.dx[k], nxt.dy[k], nxt.dz[k] = nxt.dx[i], nxt.dy[i], nxt.dz[i]
    for a in range(3):
        nxt.d32[k, a] = nxt.d32[i, a]
    nxt.w[k] = nxt.w[i]
