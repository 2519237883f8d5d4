"""One step of the Embree bounce chain (``bounces.trace_bounces``): per live path, weight
w ← w·F(c), c = −d·n, mirror direction wo = d + 2c·n, the terminal class of a path that ends
and the next ray (on the facet plane, eps above it) of one that goes on."""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

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
from .engine.jit import compiled
from .fresnel_kernels import fresnel_weight


class RayDirections(NamedTuple):
    """The unit directions the live paths were traced along: one shared direction (index 0)
    when ``shared``, else one per path."""

    dx: np.ndarray
    dy: np.ndarray
    dz: np.ndarray
    shared: bool


class FacetPlanes(NamedTuple):
    """The tracer's facets: unit normals (nx, ny, nz), ``lift`` = n·v0 + eps (the plane a
    reflected ray starts eps above) and the tile's half extents ``half_x``, ``half_y``."""

    nx: np.ndarray
    ny: np.ndarray
    nz: np.ndarray
    lift: np.ndarray
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
    """``paths.FacetTable``'s per-facet Fresnel ``weight`` and ``bin`` for the first bounce
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
):
    """One step of the bounce chain (``bounces.trace_bounces``) over the live paths.

    Live path i (global index ``live[i]``, carried weight ``w[i]``) was traced along
    (dx, dy, dz)[j] (j = 0 if ``shared`` else i) with walk outcome ``hs[i]``, ``prim[i]``,
    point (px, py, pz)[i] (``Tracer.trace_columns``); the ray traced at step ``b`` is the
    primary ray (b = 1) or the ray reflected at bounce b − 1. Per path:

    * ESCAPED at b ≥ 2: the path leaves after order b − 1 (``term`` ESC_*, ``wterm`` = w,
      its direction written to ``esc``/``edx``/``edy``/``edz`` for binning by the caller);
    * no hit (MISSED, UNRESOLVED; ESCAPED at b = 1): PATH_MISSED / PATH_UNRESOLVED, weight w;
    * a hit at b > ``limit``: CUT_BOUNCES (the path would go on; weight w);
    * a back-facing hit (c = −d·n ≤ 0): PATH_UNRESOLVED;
    * otherwise bounce b: w ← w·F(c) (``fresnel_weight``), wo = d + 2c·n (the mirror
      direction 2(wi·n)n − wi with wi = −d); below the ``floor`` the path is cut
      (CUT_WEIGHT, weight w·F); a downward wo at the last bounce (b = limit) is cut
      (CUT_BOUNCES: it must meet the surface again); else the reflected ray is set up for the
      next step: it starts at p − (p·n − lift)·n (on the facet plane, eps above it; ``lift``
      = n·v0 + eps) wrapped into the tile, along wo (float32 copy ``nd32``), compacted to
      ``nlive``/``sx``…``nw``.

    The first-bounce ledger of the same rays (``status1``, ``weight1``: the classes and
    Fresnel weights of ``paths.LEDGER``, as the single-bounce paths give them) is written at
    b = 1 (SINGLE provisionally for a rising wo) and settled at b = 2 (MASKED if the reflected
    ray met the surface, RAY_UNRESOLVED / RAY_MISSED if its walk failed).

    ``use_table``: the incidence's ``paths.FacetTable`` Fresnel weights ``tab_weight`` and
    bins ``tab_bin`` per facet serve the first bounce (the values the per-ray arithmetic
    gives, bitwise: same Fresnel kernel, same float64 mirror direction): its facet is kept in
    ``first_facet`` and a path escaping after order 1 gets ``where`` = its facet's bin here
    instead of being listed in ``esc``. Returns (continuing paths m, escapes e).

    Arguments: step ``b``, bounce ``limit``, weight ``floor``, the live paths' global indices
    ``live`` and weights ``w``; ``walk`` (``engine.segments.WalkResult`` of the traced
    rays: hs, prim, px, py, pz), ``rays`` (``RayDirections``), ``facets``
    (``FacetPlanes``: nx, ny, nz, lift, hx, hy),
    ``material`` (``fresnel_kernels.FresnelMaterial``), ``ledger`` (``PathLedger``,
    written), ``escapes`` (``Escapes``: esc, edx, edy, edz, written), ``nxt``
    (``NextRays``: nlive, sx…nw, written) and ``table`` (``FirstBounceTable``: use_table,
    tab_weight, tab_bin, first_facet)."""
    hs, prim, px, py, pz = walk
    dx, dy, dz, shared = rays
    nx, ny, nz, lift, hx, hy = facets
    n2, k2, fresnel_mode = material
    status1, weight1, term, wterm, where = ledger
    esc, edx, edy, edz = escapes
    nlive, sx, sy, sz, ndx, ndy, ndz, nd32, nw = nxt
    use_table, tab_weight, tab_bin, first_facet = table
    m = 0
    e = 0
    for i in range(len(live)):
        g = live[i]
        j = 0 if shared else i
        h = hs[i]
        if b == 2 and status1[g] == SINGLE:  # the first reflected ray's outcome
            if h == HIT:
                status1[g] = MASKED
            elif h == UNRESOLVED:
                status1[g] = RAY_UNRESOLVED
            elif h == MISSED:
                status1[g] = RAY_MISSED
        if h == ESCAPED and b >= 2:
            term[g] = order_class(b - 1)
            wterm[g] = w[i]
            if use_table and b == 2:
                where[g] = tab_bin[first_facet[g]]
                continue
            esc[e] = g
            edx[e], edy[e], edz[e] = dx[j], dy[j], dz[j]
            e += 1
            continue
        if h != HIT:
            term[g] = PATH_UNRESOLVED if h == UNRESOLVED else PATH_MISSED
            wterm[g] = w[i]
            if b == 1:
                status1[g] = RAY_UNRESOLVED if h == UNRESOLVED else RAY_MISSED
                weight1[g] = 0.0
            continue
        if b > limit:
            term[g] = CUT_BOUNCES
            wterm[g] = w[i]
            continue
        f = prim[i]
        a0, a1, a2 = nx[f], ny[f], nz[f]
        c = -(dx[j] * a0 + dy[j] * a1 + dz[j] * a2)
        if c <= 0.0:  # back-facing
            term[g] = PATH_UNRESOLVED
            wterm[g] = w[i]
            if b == 1:
                status1[g] = RAY_UNRESOLVED
                weight1[g] = 0.0
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
            term[g] = CUT_WEIGHT
            wterm[g] = wn
            continue
        if b == limit and not oz > 0.0:
            term[g] = CUT_BOUNCES
            wterm[g] = wn
            continue
        off = px[i] * a0 + py[i] * a1 + pz[i] * a2 - lift[f]
        x, y, z = px[i] - off * a0, py[i] - off * a1, pz[i] - off * a2
        if x < -hx or x >= hx:  # into the tile
            x = (x + hx) % (2.0 * hx) - hx
        if y < -hy or y >= hy:
            y = (y + hy) % (2.0 * hy) - hy
        nlive[m] = g
        sx[m], sy[m], sz[m] = x, y, z
        ndx[m], ndy[m], ndz[m] = ox, oy, oz
        nd32[m, 0] = np.float32(ox)
        nd32[m, 1] = np.float32(oy)
        nd32[m, 2] = np.float32(oz)
        nw[m] = wn
        m += 1
    return m, e
