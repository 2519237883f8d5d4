"""Compiled per-ray bookkeeping between the Embree calls (numba, ``nogil``).

Why compiled: around Embree's ~170 ns per ray, the same steps written as NumPy array passes
(ray origins, segment bounds, hit points, masking-ray starts, per-facet look-ups, tallies)
cost ~200 ns per sample on a 512² heightfield (measured), so the pipeline ran at ~55–60 % of
raw Embree throughput; one fused loop per stage does the same arithmetic in a few ns per ray
and releases the GIL, so both threads run in parallel.

Vectorised passes: the heavier per-ray arithmetic (groove-frame rotations, Fresnel weights,
bins, masking-ray starts) runs in branch-free loops over tiles of ``TILE`` rays that LLVM
compiles to AVX2 (4 doubles per instruction), with the per-facet look-ups (indexed loads,
which it does not vectorise on this CPU) in scalar loops between them, and without a libm call
per ray (``cos_sin``, ``_atan_approx``; bins near an edge by ``Bins.locate``'s arithmetic). Those
use ``error_model="numpy"``: a zero-divisor check is a branch per division, which keeps a
loop scalar (the values a select then discards may be inf or NaN). Measured on the bench
V-groove scene: the exact analytic path went from ~200 to ~45 ns per ray.

Reproducibility: every kernel is a loop in ray order that evaluates each ray on its own, with
no fast-math (no FMA contraction or reassociation); sums (``block_tallies``) add a block's
rays in ray order, like ``np.bincount``. Results are therefore independent of batch size and
thread count. When they replaced the NumPy code they gave its results bitwise (checked on six
configurations); tests/test_kernels.py checks each against the NumPy statement of what it
computes.

Units and frames are the callers' (``tracer``/``streams``/``paths``/``tallies``): tile
coordinates, unit directions, distances along the ray.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from microsim.analytic.fresnel import fresnel_real_scalar

__all__ = [
    "fresnel_mode",
    "fresnel_weights",
    "surely_escaping",
    "stratified_origins",
    "stratified_groove_starts",
    "segment_setup",
    "falling_first_segment",
    "segment_finish",
    "first_segment_hits",
    "tabled_primary",
    "block_tallies",
    "apply_escape",
    "facet_mirror",
    "analytic_vgroove",
    "cos_sin",
    "locate_one",
    "groove_frame_directions",
    "bin_rays",
    "add_blocks",
    "bin_index",
]

# tracer status codes (``tracer.HIT`` ...) and ledger classes (``paths.SINGLE`` ...),
# repeated here as compile-time constants; ``paths``/``tracer`` assert they agree
HIT, ESCAPED, UNRESOLVED, MISSED = 0, 1, 2, 3
SINGLE, MASKED, DOWNWARD, RAY_UNRESOLVED, RAY_MISSED = 0, 1, 2, 3, 4
FRESNEL_REAL, FRESNEL_MIRROR, FRESNEL_NONE = 0, 1, 2  # ``_fresnel_weight``'s modes
CLEAR_MARGIN = 1.0 + 1e-6  # a masking ray is skipped when wo_z > this × slope bound × |wo_h|

_compiled = njit(cache=True, nogil=True)
_inlined = njit(cache=True, nogil=True, inline="always")  # small helpers of the per-ray loops
# branch-free passes the compiler vectorises: float division by zero gives inf/NaN there
# instead of raising (the check is a branch per division), values the selects then discard
_vectorised = njit(cache=True, nogil=True, error_model="numpy")
TILE = 1024  # rays per tile of a kernel's vectorised passes (its scratch stays in L1/L2)
_vector_inlined = njit(cache=True, nogil=True, error_model="numpy", inline="always")


@_vector_inlined
def _stratum(r, xi, n_total, rows):
    """Ray r's place (r as a float) in its stratum of a row-major sweep of ``rows`` rows:
    s = (r + ξ)/N · rows; (s − row, row) with row = ⌊s⌋ capped at rows − 1."""
    s = (r + xi) / n_total * rows
    row = min(math.floor(s), rows - 1.0)
    return s - row, row


@_vectorised
def stratified_origins(u, r0, n, block, n_total, rows, lx, ly, azimuth, strata, x, y, psi):
    """Stratified origins and groove azimuths of rays r0 … r0 + n − 1 (``streams.
    chunk_origins``; r0 a multiple of ``block``) from their uniforms ``u``: block j of the
    chunk (m rays) holds ξ, η (and ψ/2π if ``azimuth``) as runs of m numbers from
    u[k·block·j], k = 3 if ``azimuth`` else 2. Ray r's stratum (``_stratum``) gives
    x = (s − ⌊s⌋)·Lx − Lx/2, y = (⌊s⌋ + η)/rows · Ly − Ly/2, and ψ = 2π·(ψ/2π) if
    ``azimuth``. With groove ``strata`` (``Tracer.groove_strata``: V-grooves, azimuth) x and
    ψ are stratified over the grooves in order of tilt and the rows instead
    (``_groove_strata``). Writes ``x``, ``y`` (and ``psi``)."""
    per_ray = 3 if azimuth else 2
    offset = np.arange(block).astype(np.float64)  # q as a float: the loop then vectorises
    for j in range((n + block - 1) // block):
        lo = j * block
        m = min(block, n - lo)
        base = per_ray * lo
        first = float(r0 + lo)  # float(r0 + lo) + q = float(r0 + lo + q) exactly (< 2⁵³)
        for q in range(m):
            frac, row = _stratum(first + offset[q], u[base + q], n_total, rows)
            x[lo + q] = frac * lx - lx / 2
            y[lo + q] = (row + u[base + m + q]) / rows * ly - ly / 2
        if azimuth:
            _groove_strata(u, base, base + 2 * m, first, m, n_total, rows, strata, lo, x, psi)


@_vectorised
def stratified_groove_starts(u, r0, n, block, n_total, rows, lx, strata, x, psi):
    """x and groove azimuth ψ of stratified rays r0 … r0 + n − 1 as ``stratified_origins``
    (``azimuth``) gives them, from ξ and ψ/2π alone: block j (m rays) holds them as two runs
    of m numbers from u[2·block·j] (``streams.groove_starts``)."""
    offset = np.arange(block).astype(np.float64)
    for j in range((n + block - 1) // block):
        lo = j * block
        m = min(block, n - lo)
        base = 2 * lo
        first = float(r0 + lo)
        for q in range(m):
            frac, _ = _stratum(first + offset[q], u[base + q], n_total, rows)
            x[lo + q] = frac * lx - lx / 2
        _groove_strata(u, base, base + m, first, m, n_total, rows, strata, lo, x, psi)


@_vector_inlined
def _groove_strata(u, at_xi, at_psi, first, m, n_total, rows, strata, lo, x, psi):
    """Groove azimuths ψ of m rays from their uniforms u[at_psi …] (ξ at u[at_xi …]), ray
    ``first`` + q at x[lo + q], psi[lo + q]. Without ``strata`` (an empty array): ψ = 2π·u.
    With them, (left rims x of the grooves in order of tilt (G,), groove width) of equal-width
    V-grooves along y (whose BRDF does not depend on y): the ray's stratum (s − ⌊s⌋ =
    (k + φ)/G, row ⌊s⌋) is mapped to position φ across the k-th groove in order of tilt,
    x = strata[k] + φ·W, and ψ = 2π(row + u)/rows is stratified by the row. Both maps keep
    every stratum's measure (x uniform over the tile, ψ over [0, 2π)), so the estimate stays
    unbiased; rays 2k and 2k + 1 then meet grooves of neighbouring tilt at neighbouring
    azimuths, which halves the rays a V-groove run needs for a given error (the collapsed-
    strata error estimate stays valid: tests/test_kernels.py)."""
    rim = strata[0]
    if len(rim) == 0:
        for q in range(m):
            psi[lo + q] = 2 * np.pi * u[at_psi + q]
        return
    width, g = strata[1], len(rim)
    for q in range(m):
        frac, row = _stratum(first + q, u[at_xi + q], n_total, rows)
        psi[lo + q] = 2 * np.pi * ((row + u[at_psi + q]) / rows)
        rank = frac * g
        k = min(math.floor(rank), g - 1.0)
        x[lo + q] = rim[int(k)] + (rank - k) * width


@_vector_inlined
def _wall_distance(x, d, half):
    """Distance ≥ 0 along a ray at coordinate x with direction component d to the wall
    ±half it heads for (inf if parallel)."""
    if d == 0.0:
        return math.inf
    return max((math.copysign(half, d) - x) / d, 0.0)


@_vector_inlined
def _segment_bounds(x, y, z, dx, dy, dz, hx, hy, zmax):
    """Distances along a ray at (x, y, z) with direction (dx, dy, dz) to the x wall, the y
    wall, the nearer of the two, and up to zmax (inf unless rising)."""
    a = _wall_distance(x, dx, hx)
    b = _wall_distance(y, dy, hy)
    t = max((zmax - z) / dz, 0.0) if dz > 0.0 else math.inf
    return a, b, min(a, b), t


@_compiled
def _setup_ray(k, x, y, z, dx, dy, dz, hx, hy, zmax, eps, rel, o32, tq, top):
    """Slot k of a segment's Embree input for the ray at (x, y, z) along (dx, dy, dz): float32
    origin ``o32[k]`` (kept strictly inside the tile, ``_strictly_inside``), tfar
    ``tq[k]`` = min(wall distance, distance to zmax when rising)·(1 + rel) + eps (float32; inf
    beyond float32) and ``top[k]``: whether it reaches the top no later than a wall."""
    _, _, w, t = _segment_bounds(x, y, z, dx, dy, dz, hx, hy, zmax)
    tq[k] = np.float32(min(w, t) * (1.0 + rel) + eps)
    top[k] = t <= w
    o32[k, 0] = _strictly_inside(np.float32(x), np.float32(hx))
    o32[k, 1] = _strictly_inside(np.float32(y), np.float32(hy))
    o32[k, 2] = np.float32(z)


@_compiled
def _strictly_inside(v, half):
    """A float32 coordinate moved (by one ulp at most) off the tile's walls ±half into the
    tile. A ray exactly on the wall runs along the mesh's boundary edge, which Embree's
    watertight test can give to the absent neighbouring triangle: measured, 23 of 10⁹ primary
    rays on the bench mesh (starts within half an ulp of +L/2 round onto the wall) leaked
    through the surface before this."""
    if v >= half:
        return np.nextafter(half, np.float32(0.0))
    if v <= -half:
        return np.nextafter(-half, np.float32(0.0))
    return v


@_compiled
def segment_setup(
    ox,
    oy,
    oz,
    dx,
    dy,
    dz,
    shared,
    live,
    d32,
    hx,
    hy,
    zmax,
    eps,
    rel,
    status,
    o32,
    d32k,
    tq,
    keep,
    top,
):
    """First half of one segment of the periodic walk (``Tracer._walk_columns``).

    Live ray i (global index ``live[i]``) at (ox, oy, oz)[i] with direction (dx, dy, dz)[j]
    (j = 0 if ``shared`` else i) and float32 copy ``d32[j]``: a ray rising from at or above
    ``zmax`` has escaped (``status`` ← ESCAPED); every other ray gets slot k of the Embree
    input (``_setup_ray``; direction ``d32k[k]`` unless shared) and ``keep[k]`` = i.
    Returns k, the number of rays to trace."""
    k = 0
    for i in range(len(live)):
        j = 0 if shared else i
        if dz[j] > 0.0 and oz[i] >= zmax:
            status[live[i]] = ESCAPED
            continue
        _setup_ray(
            k, ox[i], oy[i], oz[i], dx[j], dy[j], dz[j], hx, hy, zmax, eps, rel, o32, tq, top
        )
        if not shared:
            d32k[k, 0] = d32[i, 0]
            d32k[k, 1] = d32[i, 1]
            d32k[k, 2] = d32[i, 2]
        keep[k] = i
        k += 1
    return k


@_vectorised
def falling_first_segment(x, y, z, dx, dy, dz, shared, hx, hy, zmax, eps, rel, o32, tq, keep, top):
    """``segment_setup`` for the first segment of falling rays (d_z < 0) that all start
    inside the tile, along (dx, dy, dz)[j] (j = 0 if ``shared`` else i): none escapes, so
    ray i takes slot i (``keep[i]`` = i). In loops the compiler vectorises: the same
    ``_segment_bounds`` and float32 arithmetic as ``_setup_ray``, the walls' inner float32
    neighbours computed once (``_strictly_inside``). Returns the number of rays."""
    hx32, hy32 = np.float32(hx), np.float32(hy)
    ix = np.nextafter(hx32, np.float32(0.0))
    iy = np.nextafter(hy32, np.float32(0.0))
    for i in range(len(x)):
        j = 0 if shared else i
        _, _, w, t = _segment_bounds(x[i], y[i], z[i], dx[j], dy[j], dz[j], hx, hy, zmax)
        tq[i] = np.float32(min(w, t) * (1.0 + rel) + eps)
        top[i] = t <= w
        keep[i] = i
    for i in range(len(x)):
        u, v = np.float32(x[i]), np.float32(y[i])
        u = ix if u >= hx32 else (-ix if u <= -hx32 else u)
        v = iy if v >= hy32 else (-iy if v <= -hy32 else v)
        o32[i, 0], o32[i, 1], o32[i, 2] = u, v, np.float32(z[i])
    return len(x)


@_vectorised
def first_segment_hits(pid, tfar, ox, oy, oz, dx, dy, dz, shared, status, prim, px, py, pz):
    """``segment_finish``'s hits for the first segment of an intersect query whose slot i is
    ray i (``first=``): where ``pid[i]`` ≥ 0, status HIT, ``prim`` and the float64 point
    o + t·d (direction j = 0 if ``shared`` else i), in a loop the compiler vectorises; the
    rays without a hit are left to ``segment_finish``."""
    for i in range(len(pid)):
        j = 0 if shared else i
        t = np.float64(tfar[i])
        hit = pid[i] >= 0
        status[i] = HIT if hit else status[i]
        prim[i] = pid[i] if hit else prim[i]
        px[i] = ox[i] + t * dx[j]
        py[i] = oy[i] + t * dy[j]
        pz[i] = oz[i] + t * dz[j]


@_compiled
def segment_finish(
    k,
    pid,
    tfar,
    occlusion,
    keep,
    top,
    live,
    ox,
    oy,
    oz,
    dx,
    dy,
    dz,
    shared,
    falling_shared,
    d32k,
    hx,
    hy,
    zmax,
    zmin,
    eps,
    status,
    prim,
    px,
    py,
    pz,
    nlive,
    nox,
    noy,
    noz,
    ndx,
    ndy,
    ndz,
    nd32,
):
    """Second half of a segment: Embree's answers ``pid`` (primID or geomID, −1 = none) and
    ``tfar`` (float32, intersect queries) for the k traced rays of ``segment_setup``.

    A hit sets ``status`` ← HIT and, for intersect queries, ``prim`` and the float64 point
    o + t·d (``px``, ``py``, ``pz``, by global index). A ray without a hit whose top is no
    farther than its nearer wall (``top``) has escaped (not for ``falling_shared``: one shared
    falling direction never reaches the top); for the others the segment's distances are
    recomputed (``_segment_bounds``, as in the setup): a ray that would leave below
    zmin − eps (or never meets a wall) has leaked (MISSED); the others re-enter through the
    opposite wall at the same height: the wall point, clipped into the tile, moved to
    −copysign(half, d) on the axis (or axes) whose wall it reached. The re-entering rays are
    written compacted to
    ``nlive``/``nox``/``noy``/``noz`` (and ``ndx``/``ndy``/``ndz``/``nd32`` unless shared).
    Returns their number."""
    m = 0
    for q in range(k):
        i = keep[q]
        g = live[i]
        j = 0 if shared else i
        if pid[q] >= 0:
            status[g] = HIT
            if not occlusion:
                prim[g] = pid[q]
                t = np.float64(tfar[q])
                px[g] = ox[i] + t * dx[j]
                py[g] = oy[i] + t * dy[j]
                pz[g] = oz[i] + t * dz[j]
            continue
        if not falling_shared and top[q]:
            status[g] = ESCAPED
            continue
        a, b, w, _ = _segment_bounds(ox[i], oy[i], oz[i], dx[j], dy[j], dz[j], hx, hy, zmax)
        x = ox[i] + w * dx[j]
        y = oy[i] + w * dy[j]
        z = oz[i] + w * dz[j]
        if z < zmin - eps or not math.isfinite(w):
            status[g] = MISSED
            continue
        x = min(max(x, -hx), hx)  # rounding along the wall
        y = min(max(y, -hy), hy)
        if a <= w:
            x = -math.copysign(hx, dx[j])
        if b <= w:
            y = -math.copysign(hy, dy[j])
        nlive[m] = g
        nox[m] = x
        noy[m] = y
        noz[m] = z
        if not shared:
            ndx[m] = dx[j]
            ndy[m] = dy[j]
            ndz[m] = dz[j]
            nd32[m, 0] = d32k[q, 0]
            nd32[m, 1] = d32k[q, 1]
            nd32[m, 2] = d32k[q, 2]
        m += 1
    return m


@_compiled
def fill_horizon(vx, vy, vz, faces, slope, x0, y0, cw, ch, cmax, cslope):
    """The coarse bounds of ``horizon_clear``: for every facet (vertex columns ``vx/vy/vz``,
    ``faces``, facet slope ``slope`` = |∇h|), every cell of the (ny, nx) grid of cells
    cw × ch from (x0, y0) that its bounding box overlaps gets the facet's highest vertex in
    ``cmax`` and its slope in ``cslope`` (running maxima; start from −inf and 0)."""
    ny, nx = cmax.shape
    for f in range(len(faces)):
        a, b, c = faces[f, 0], faces[f, 1], faces[f, 2]
        i0 = max(int(math.floor((min(vx[a], vx[b], vx[c]) - x0) / cw)), 0)
        i1 = min(int(math.floor((max(vx[a], vx[b], vx[c]) - x0) / cw)), nx - 1)
        j0 = max(int(math.floor((min(vy[a], vy[b], vy[c]) - y0) / ch)), 0)
        j1 = min(int(math.floor((max(vy[a], vy[b], vy[c]) - y0) / ch)), ny - 1)
        top = max(vz[a], vz[b], vz[c])
        for j in range(j0, j1 + 1):
            for i in range(i0, i1 + 1):
                cmax[j, i] = max(cmax[j, i], top)
                cslope[j, i] = max(cslope[j, i], slope[f])


@_compiled
def horizon_clear(x, y, z, dx, dy, dz, x0, y0, cw, ch, cmax, cslope, zmax, tol):
    """Whether a ray from (x, y, z) on a periodic heightfield (at or just above it), rising
    along (dx, dy, dz), surely clears the surface before it rises above ``zmax``, decided on
    a coarse grid of cells (``fill_horizon``: highest vertex ``cmax`` and steepest facet
    ``cslope`` of the facets overlapping each cell) without tracing it. The ray's height
    z + s·cot (s horizontal distance, cot = dz/|d_h|) is followed cell by cell (2-D DDA,
    indices wrapped) up to s = (zmax − z)/cot; a cell is cleared when the ray enters it above
    the cell's highest vertex (+ ``tol``), or when it stays above the Lipschitz bound
    h(p) ≤ z + Σ cslope·(run in each cell so far) at the cell's entry and exit (in the first
    cell, where the ray starts on the surface: cot > cslope). Any doubt — a cell fails, or
    more than 64 cells — returns False (the ray is traced)."""
    if dz <= 0.0:
        return False
    h = math.sqrt(dx * dx + dy * dy)
    if h == 0.0:
        return True
    cot = dz / h
    s_end = (zmax + tol - z) / cot
    if s_end <= 0.0:
        return True
    ny, nx = cmax.shape
    ux, uy = dx / h, dy / h
    gx, gy = (x - x0) / cw, (y - y0) / ch
    ix, iy = int(math.floor(gx)), int(math.floor(gy))
    tx, dtx, sx = math.inf, math.inf, 0
    if ux > 0.0:
        tx, dtx, sx = (ix + 1 - gx) * cw / ux, cw / ux, 1
    elif ux < 0.0:
        tx, dtx, sx = (gx - ix) * cw / -ux, cw / -ux, -1
    ty, dty, sy = math.inf, math.inf, 0
    if uy > 0.0:
        ty, dty, sy = (iy + 1 - gy) * ch / uy, ch / uy, 1
    elif uy < 0.0:
        ty, dty, sy = (gy - iy) * ch / -uy, ch / -uy, -1
    s_in, bound = 0.0, z
    cx, cy = ix % nx, iy % ny  # the cell, wrapped; stepped by ±1 below (no modulo per step)
    for step in range(64):
        s_out = min(tx, ty, s_end)
        slope = cslope[cy, cx] * CLEAR_MARGIN
        z_in = z + cot * s_in
        if z_in <= cmax[cy, cx] + tol:  # the cell may reach the ray: Lipschitz chain
            if step == 0:
                if not cot > slope:
                    return False
            elif not (
                z_in - tol > bound and z + cot * s_out - tol > bound + slope * (s_out - s_in)
            ):
                return False
        bound += slope * (s_out - s_in)
        if s_out >= s_end:
            return True
        if tx < ty:
            cx += sx
            cx = 0 if cx == nx else (nx - 1 if cx < 0 else cx)
            s_in = tx
            tx += dtx
        else:
            cy += sy
            cy = 0 if cy == ny else (ny - 1 if cy < 0 else cy)
            s_in = ty
            ty += dty
    return False


@_compiled
def horizon_clear_all(px, py, pz, dx, dy, dz, hz, zmax, out):
    """``horizon_clear`` for rays from (px, py, pz)[i] (in the tile) along (dx, dy, dz)[i]
    on the grid ``hz`` (x0, y0, cw, ch, cmax, cslope, tol); writes ``out``."""
    for i in range(len(px)):
        out[i] = horizon_clear(
            px[i],
            py[i],
            pz[i],
            dx[i],
            dy[i],
            dz[i],
            hz[0],
            hz[1],
            hz[2],
            hz[3],
            hz[4],
            hz[5],
            zmax,
            hz[6],
        )


@_compiled
def tabled_primary(
    hs,
    prim,
    px,
    py,
    pz,
    code,
    fweight,
    nx,
    ny,
    nz,
    lift,
    wo32,
    fbin,
    fclear,
    hz,
    geometry,
    status,
    weight,
    where,
    masking,
):
    """Ledger class, Fresnel weight and bin of primary rays from their first hits, looked up
    per facet (``paths.FacetTable``: ``code``, ``fweight``, unit normal ``nx/ny/nz``,
    ``lift`` = n·v0 + eps, mirror direction ``wo32`` (float32, used as float64 too),
    bin ``fbin``, ``fclear``: lit facets whose rays surely escape), and the masking rays of
    the other lit ones (code SINGLE) that the coarse grid ``hz`` (``horizon_clear``'s
    x0, y0, cw, ch, cmax, cslope, tol) cannot clear, set up as the first
    segment of their walk (``Tracer.escape_columns(first=...)``). Masking ray m of primary
    ray ``mi[m]`` starts at its hit point p moved along n onto the facet plane and eps above
    it, p − (p·n − lift)·n, wrapped into the tile (``sx/sy/sz``), along the facet's mirror
    direction (``mdx``… ``md32``), with its Embree input in slot m (``_setup_ray``: ``o32``,
    ``tq``, ``top``; ``keep[m]`` = m). A start at or above zmax has nothing above it: the ray
    escapes without a masking ray (as ``segment_setup`` decides). ``hs`` is the walk status:
    HIT, MISSED/ESCAPED (→ RAY_MISSED) or UNRESOLVED. Writes ``status``, ``weight`` (0
    without a hit) and ``where`` (the facet bin for lit rays, else −1) of every ray; returns
    the number of masking rays. In tiles of ``TILE`` rays: the look-ups one by one, the
    starts in a vectorised loop, the masking rays by ``masking_starts``."""
    tile = np.empty((10, TILE))  # per-ray scratch of one tile
    a_, b_, e_, lift_, x_, y_, z_ = tile[0], tile[1], tile[2], tile[3], tile[4], tile[5], tile[6]
    dx_, dy_, dz_ = tile[7], tile[8], tile[9]
    cand = np.empty(TILE, np.bool_)
    m = 0
    for t in range(0, len(hs), TILE):
        n = min(TILE, len(hs) - t)
        for j in range(n):  # one by one: the hit facet's entries (indexed loads)
            i = t + j
            h = hs[i]
            hit = h == HIT
            f = prim[i] if hit else 0
            c = code[f]
            miss = RAY_MISSED if (h == MISSED) | (h == ESCAPED) else RAY_UNRESOLVED
            status[i] = c if hit else miss
            weight[i] = fweight[f] if hit else 0.0
            where[i] = fbin[f] if hit & (c == SINGLE) else -1
            cand[j] = hit & (c == SINGLE) & (not fclear[f])  # else: escapes, no masking ray
            a_[j], b_[j], e_[j], lift_[j] = nx[f], ny[f], nz[f], lift[f]
            dx_[j], dy_[j], dz_[j] = wo32[f, 0], wo32[f, 1], wo32[f, 2]
        for j in range(n):  # vectorised: the masking rays' starts on the facet planes
            i = t + j
            a, b, e = a_[j], b_[j], e_[j]
            off = px[i] * a + py[i] * b + pz[i] * e - lift_[j]
            x_[j], y_[j], z_[j] = px[i] - off * a, py[i] - off * b, pz[i] - off * e
        m = masking_starts(cand, t, n, x_, y_, z_, dx_, dy_, dz_, hz, geometry, m, masking)
    return m


@_vectorised
def surely_escaping(dx, dy, dz, slope, out):
    """out[i] = dz > slope·√(dx² + dy²): rays rising more steeply than the surface can
    (``Tracer.surely_escapes``, ``traced_primary``), vectorised."""
    for i in range(len(dx)):
        out[i] = dz[i] > slope * math.sqrt(dx[i] * dx[i] + dy[i] * dy[i])


@_vectorised
def fresnel_weights(c, n2, k2, fresnel_mode, weight):
    """weight[i] = F(c[i]) (``_fresnel_weight``), 0 where c ≤ 0 (no hit, back-facing), in a
    vectorised loop (``_fresnel_weights``)."""
    _fresnel_weights(c, len(c), n2, k2, fresnel_mode, weight, 0)


@_vectorised
def traced_primary(
    hs,
    prim,
    px,
    py,
    pz,
    wx,
    wy,
    wz,
    nx,
    ny,
    nz,
    lift,
    trace_masking,
    clear_slope,
    hz,
    groove,
    geometry,
    status,
    cosine,
    wox,
    woy,
    woz,
    masking,
):
    """``tabled_primary`` for rays that each carry their own incident direction wl (``wx/wy/
    wz``, length N, or 1: one shared), so nothing can be tabled per facet: per hit facet n
    (unit normal ``nx/ny/nz``, ``lift`` = n·v0 + eps), c = n·wl (``cosine``: 0 without a hit
    or back-facing, for ``fresnel_weights``); back-facing (c ≤ 0): RAY_UNRESOLVED; else the
    mirror direction wo = 2c·n − wl (``wox/woy/woz``, float64); DOWNWARD if wo_z ≤ 0, else
    SINGLE. With
    ``trace_masking`` the SINGLE rays whose float32 wo rises more steeply than
    ``clear_slope`` (× ``CLEAR_MARGIN`` as in ``Tracer.surely_escapes``; inf: none), that
    start at or above zmax or that clear the coarse grid ``hz`` (``horizon_clear``) escape
    without a ray, and the others get their masking ray set up
    as the first segment of their walk, exactly as ``tabled_primary`` (float64 direction wo,
    its float32 copy in ``md32``); returns the number of masking rays (0 without
    ``trace_masking``: the caller decides masking itself). ``groove``: V-groove surfaces'
    per-facet (rim x, tanθ σ, rim-to-rim width W, rim-to-bottom extent) and a tolerance
    (``Tracer.groove_clear``; empty arrays otherwise): a ray whose exact masking margin
    s(1 + tanθ σ wo_x/wo_z) − W (``VGrooveProfile.margin_from_rim``) is below −tolerance
    escapes without a ray (the margins within it are left to Embree)."""
    shared = len(wx) == 1
    grim, gtan, gwidth, gextent, gtol = groove
    grooved = len(grim) > 0
    tile = np.empty((11, TILE))  # per-ray scratch of one tile
    a_, b_, e_, lift_, x_, y_, z_ = tile[0], tile[1], tile[2], tile[3], tile[4], tile[5], tile[6]
    rim_, tan_, width_, extent_ = tile[7], tile[8], tile[9], tile[10]
    cand = np.empty(TILE, np.bool_)
    slope = CLEAR_MARGIN * clear_slope
    m = 0
    for t in range(0, len(hs), TILE):
        n = min(TILE, len(hs) - t)
        for j in range(n):  # one by one: the hit facet's normal and lift (indexed loads)
            f = prim[t + j] if hs[t + j] == HIT else 0
            a_[j], b_[j], e_[j], lift_[j] = nx[f], ny[f], nz[f], lift[f]
        if grooved:
            for j in range(n):
                f = prim[t + j] if hs[t + j] == HIT else 0
                rim_[j], tan_[j], width_[j], extent_[j] = grim[f], gtan[f], gwidth[f], gextent[f]
        for j in range(n):  # vectorised: reflection and class
            i = t + j
            k = 0 if shared else i
            h = hs[i]
            a, b, e = a_[j], b_[j], e_[j]
            c = wx[k] * a + wy[k] * b + wz[k] * e
            oz = 2.0 * c * e - wz[k]
            st = SINGLE if oz > 0.0 else DOWNWARD
            st = st if c > 0.0 else RAY_UNRESOLVED
            miss = RAY_MISSED if (h == MISSED) | (h == ESCAPED) else RAY_UNRESOLVED
            status[i] = st if h == HIT else miss
            cosine[i] = c if (h == HIT) & (c > 0.0) else 0.0
            wox[i], woy[i], woz[i] = 2.0 * c * a - wx[k], 2.0 * c * b - wy[k], oz
        for j in range(n):  # vectorised: masking candidates and their starts
            i = t + j
            ox, oy, oz = wox[i], woy[i], woz[i]
            gx, gy = np.float64(np.float32(ox)), np.float64(np.float32(oy))
            gz = np.float64(np.float32(oz))
            steep = gz > slope * math.sqrt(gx * gx + gy * gy)  # escapes: no masking ray
            if grooved:  # clears the opposite facet by more than the tolerance: escapes
                s = min(abs(px[i] - rim_[j]), extent_[j])
                steep |= groove_margin(s, tan_[j], width_[j], ox, oz) < -gtol
            cand[j] = trace_masking & (status[i] == SINGLE) & (not steep)
            a, b, e = a_[j], b_[j], e_[j]
            off = px[i] * a + py[i] * b + pz[i] * e - lift_[j]  # on the facet plane, eps above
            x_[j], y_[j], z_[j] = px[i] - off * a, py[i] - off * b, pz[i] - off * e
        m = masking_starts(
            cand, t, n, x_, y_, z_, wox[t:], woy[t:], woz[t:], hz, geometry, m, masking
        )
    return m


@_compiled
def masking_starts(cand, t, n, x_, y_, z_, ox_, oy_, oz_, hz, geometry, m, masking):
    """The masking rays of the candidates j < n of a tile starting at ray t (``cand``: lit,
    rising, not surely escaping), from (``x_``, ``y_``, ``z_``) along (``ox_``, ``oy_``,
    ``oz_``) traced as its float32 copy: a start at or above zmax has nothing above it and one
    that clears the coarse grid ``hz`` (``horizon_clear``) escapes; the others, wrapped into
    the tile, get slot m onwards of the first segment of their walk (``_setup_ray``;
    ``keep[m]`` = m, ``mi[m]`` = their ray). ``geometry``: (hx, hy, zmax, eps, rel);
    ``masking``: the ``paths.MaskingRays`` arrays (mi, sx, sy, sz, mdx, mdy, mdz, md32, o32,
    tq, keep, top). Returns the new m."""
    hx, hy, zmax, eps, rel = geometry
    mi, sx, sy, sz, mdx, mdy, mdz, md32, o32, tq, keep, top = masking
    for j in range(n):
        if not cand[j]:
            continue
        x, y, z = x_[j], y_[j], z_[j]
        if z >= zmax:  # nothing above: escaped
            continue
        if x < -hx or x >= hx:  # into the tile
            x = (x + hx) % (2.0 * hx) - hx
        if y < -hy or y >= hy:
            y = (y + hy) % (2.0 * hy) - hy
        ox, oy, oz = ox_[j], oy_[j], oz_[j]
        if horizon_clear(
            x, y, z, ox, oy, oz, hz[0], hz[1], hz[2], hz[3], hz[4], hz[5], zmax, hz[6]
        ):
            continue  # clears the coarse grid: escaped
        sx[m], sy[m], sz[m] = x, y, z
        mdx[m], mdy[m], mdz[m] = ox, oy, oz
        md32[m, 0], md32[m, 1], md32[m, 2] = np.float32(ox), np.float32(oy), np.float32(oz)
        _setup_ray(m, x, y, z, ox, oy, oz, hx, hy, zmax, eps, rel, o32, tq, top)
        keep[m] = m
        mi[m] = t + j
        m += 1
    return m


@_compiled
def block_tallies(
    status, weight, where, block, acc, touched, out_bin, out_sums, out_cnt, offsets, ln, lf
):
    """Per-block sums of a batch of whole blocks of ``block`` rays (``tallies.split_tallies``),
    added in ray order, stored sparsely (only the bins a block touches: a block has at most
    ``block`` events, while a fine grid has thousands of bins).

    For single-bounce rays with a bin (``where`` ≥ 0): Σw, Σw² and the pair sum
    (w_2k·w_2k+1 where rays 2k and 2k + 1, counted from the batch start, are both tallied in
    the same bin) accumulate in the dense scratch ``acc`` (3, bins) (zero on entry and on
    return) and the counts in ``touched`` (bins,) int64; block b's bins are then written, in
    the order first touched, to ``out_bin``/``out_sums`` (3, N)/``out_cnt`` between
    ``offsets[b]`` and ``offsets[b + 1]``. Ledger counts and Fresnel sums per class go to
    ``ln``, ``lf`` (blocks, classes)."""
    n = len(status)
    j = 0
    for b in range((n + block - 1) // block):
        offsets[b] = j
        lo, hi = b * block, min(n, (b + 1) * block)
        n0 = n1 = n2 = n3 = n4 = 0  # ledger sums in registers, per class
        f0 = f1 = f2 = f3 = f4 = 0.0
        for i in range(lo, hi):
            s = status[i]
            if s == SINGLE:
                n0 += 1
                f0 += weight[i]
            elif s == MASKED:
                n1 += 1
                f1 += weight[i]
            elif s == DOWNWARD:
                n2 += 1
                f2 += weight[i]
            elif s == RAY_UNRESOLVED:
                n3 += 1
                f3 += weight[i]
            else:
                n4 += 1
                f4 += weight[i]
            if s == SINGLE and where[i] >= 0:
                k = where[i]
                out_bin[j] = k  # kept (j advances) only on the bin's first event: no branch
                j += touched[k] == 0
                w = weight[i]
                acc[0, k] += w
                acc[1, k] += w * w
                touched[k] += 1
        ln[b, SINGLE], ln[b, MASKED], ln[b, DOWNWARD] = n0, n1, n2
        ln[b, RAY_UNRESOLVED], ln[b, RAY_MISSED] = n3, n4
        lf[b, SINGLE], lf[b, MASKED], lf[b, DOWNWARD] = f0, f1, f2
        lf[b, RAY_UNRESOLVED], lf[b, RAY_MISSED] = f3, f4
        for i in range(lo, hi - 1, 2):
            if (
                status[i] == SINGLE
                and status[i + 1] == SINGLE
                and where[i] >= 0
                and where[i] == where[i + 1]
            ):
                acc[2, where[i]] += weight[i] * weight[i + 1]
        for q in range(offsets[b], j):
            k = out_bin[q]
            for m in range(3):
                out_sums[m, q] = acc[m, k]
                acc[m, k] = 0.0
            out_cnt[q] = touched[k]
            touched[k] = 0
    offsets[(n + block - 1) // block] = j


@_compiled
def apply_escape(status, rays, esc, from_escape):
    """``status[rays[m]] = from_escape[esc[m]]`` for the masking rays' walk statuses ``esc``."""
    for m in range(len(esc)):
        status[rays[m]] = from_escape[esc[m]]


@_vector_inlined
def _fresnel_weight(c, n2, k2, fresnel_mode):
    """F(c) for c > 0 by ``fresnel_mode``: FRESNEL_REAL ``fresnel_real_scalar`` onto η² with
    n2 = n², k2 = k²; FRESNEL_MIRROR 1; FRESNEL_NONE 0 (η = 1: nothing reflects off grazing)."""
    if fresnel_mode == FRESNEL_REAL:
        return fresnel_real_scalar(c, n2, k2)
    return 1.0 if fresnel_mode == FRESNEL_MIRROR else 0.0


@_compiled
def facet_mirror(
    nx, ny, nz, wix, wiy, wiz, n2, k2, fresnel_mode, weight, code, wox, woy, woz, wo32
):
    """Per facet with unit normal n (``nx/ny/nz``) lit from wi: the Fresnel weight F(n·wi)
    (``weight``, 0 if back-facing; ``_fresnel_weight``), the mirror direction
    wo = 2(n·wi)·n − wi (``wox/woy/woz``, float32 copy ``wo32``) and the class a primary hit
    gets (``code``): SINGLE if lit and wo rises (a masking ray decides), DOWNWARD if lit and
    wo points down, RAY_UNRESOLVED if back-facing (n·wi ≤ 0)."""
    for f in range(len(nx)):
        c = nx[f] * wix + ny[f] * wiy + nz[f] * wiz
        x = 2.0 * c * nx[f] - wix
        y = 2.0 * c * ny[f] - wiy
        z = 2.0 * c * nz[f] - wiz
        wox[f] = x
        woy[f] = y
        woz[f] = z
        wo32[f, 0] = np.float32(x)
        wo32[f, 1] = np.float32(y)
        wo32[f, 2] = np.float32(z)
        if c <= 0.0:
            code[f] = RAY_UNRESOLVED
            weight[f] = 0.0
        else:
            code[f] = SINGLE if z > 0.0 else DOWNWARD
            weight[f] = _fresnel_weight(c, n2, k2, fresnel_mode)


# fdlibm's __kernel_sin / __kernel_cos polynomial coefficients (Sun Microsystems 1993, |r| ≤ π/4)
_S = (
    -1.66666666666666324348e-01,
    8.33333333332248946124e-03,
    -1.98412698298579493134e-04,
    2.75573137070700676789e-06,
    -2.50507602534068634195e-08,
    1.58969099521155010221e-10,
)
_C = (
    4.16666666666666019037e-02,
    -1.38888888888741095749e-03,
    2.48015872894767294178e-05,
    -2.75573143513906633035e-07,
    2.08757232129817482790e-09,
    -1.13596475577881948265e-11,
)
_PIO2_HI = 1.57079632673412561417e00  # π/2 in two parts: the first has 33 bits, so q·_PIO2_HI
_PIO2_LO = 6.07710050650619224932e-11  # is exact for |q| < 2²⁰ (Cody–Waite reduction)
# atan t = t·P(t²) on [0, 1] (least-squares Chebyshev fit in t², degree 9): max error
# 2.1e-9 rad, checked against math.atan2 in tests/test_kernels.py
_ATAN = (
    0.9999999990538162,
    -0.33333296715255056,
    0.1999854225669279,
    -0.14264389606202937,
    0.10953448560542803,
    -0.08407874681541322,
    0.05804036235197402,
    -0.031264406303775444,
    0.010962383774980159,
    -0.001804475721007023,
)
ATAN_ERROR = 3e-9  # rad: bound on _atan_approx's error (fit error + rounding)


# fdlibm's s_atan.c / e_atan2.c (Sun Microsystems 1993): atan(k/2) for k = 1, 2, 3 and π/2 in
# two parts, and the odd/even polynomial coefficients of atan on |t| ≤ 7/16
_ATAN_HI = (
    4.63647609000806093515e-01,
    7.85398163397448278999e-01,
    9.82793723247329054082e-01,
    1.57079632679489655800e00,
)
_ATAN_LO = (
    2.26987774529616870924e-17,
    3.06161699786838301793e-17,
    1.39033110312309984516e-17,
    6.12323399573676603587e-17,
)
_AT = (
    3.33333333333329318027e-01,
    -1.99999999998764832476e-01,
    1.42857142725034663711e-01,
    -1.11111104054623557880e-01,
    9.09088713343650656196e-02,
    -7.69187620504482999495e-02,
    6.66107313738753120669e-02,
    -5.83357013379057348645e-02,
    4.97687799461593236017e-02,
    -3.65315727442169155270e-02,
    1.62858201153657823623e-02,
)
_PI_LO = 1.2246467991473531772e-16  # π − fl(π)


@_inlined
def _atan_fdlibm(t):
    """atan t for t ≥ 0 (not NaN), fdlibm's s_atan.c: reduced to |t'| ≤ 7/16 by
    atan t = atan(k/2) + atan t' (k = 1, 2, 3) or π/2 − atan(1/t), then its degree-22 odd
    polynomial; error < 1 ulp. Plain IEEE arithmetic only (no libm, no fused multiply-add:
    numba contracts nothing without fastmath), so every x86-64 machine gets the same bits."""
    if t >= 7.378697629483821e19:  # 2⁶⁶: atan t = π/2 to double precision
        return _ATAN_HI[3] + _ATAN_LO[3]
    k = -1
    if t >= 0.4375:
        if t < 0.6875:
            k, t = 0, (2.0 * t - 1.0) / (2.0 + t)
        elif t < 1.1875:
            k, t = 1, (t - 1.0) / (t + 1.0)
        elif t < 2.4375:
            k, t = 2, (t - 1.5) / (1.0 + 1.5 * t)
        else:
            k, t = 3, -1.0 / t
    elif t < 1.862645149230957e-09:  # 2⁻²⁹: atan t = t to double precision
        return t
    z = t * t
    w = z * z
    a = _AT
    s1 = z * (a[0] + w * (a[2] + w * (a[4] + w * (a[6] + w * (a[8] + w * a[10])))))
    s2 = w * (a[1] + w * (a[3] + w * (a[5] + w * (a[7] + w * a[9]))))
    if k < 0:
        return t - t * (s1 + s2)
    return _ATAN_HI[k] - ((t * (s1 + s2) - _ATAN_LO[k]) - t)


@_inlined
def atan2_portable(y, x):
    """atan2(y, x) in (−π, π], bitwise the same on every IEEE-754 machine: fdlibm's e_atan2.c
    on ``_atan_fdlibm`` (error < 1 ulp), with C99's signed zeros (atan2(±0, −0) = ±π,
    atan2(±0, +0) = ±0) and infinities. NumPy's arctan2 and libm's atan2 are not: NumPy 2
    dispatches to AVX-512 SIMD code that differs from libm in the last ulp, so a direction
    exactly on a bin edge would fall on either side by machine. The one rule by which
    ``Bins.locate`` and the compiled bin passes take a direction's angles."""
    if x != x or y != y:
        return x + y
    neg_y = math.copysign(1.0, y) < 0.0
    neg_x = math.copysign(1.0, x) < 0.0
    ay, ax = abs(y), abs(x)
    if ay == 0.0:
        z = math.pi if neg_x else 0.0
    elif ax == 0.0:
        z = 0.5 * math.pi
    elif ax == math.inf:
        if ay == math.inf:
            z = 0.75 * math.pi if neg_x else 0.25 * math.pi
        else:
            z = math.pi if neg_x else 0.0
    elif ay == math.inf:
        z = 0.5 * math.pi
    else:
        z = _atan_fdlibm(ay / ax)
        if neg_x:
            z = math.pi - (z - _PI_LO)
    return -z if neg_y else z


@_vector_inlined
def cos_sin(psi):
    """(cos ψ, sin ψ) in float64 for |ψ| ≤ 2π (the rays' groove azimuths) without libm: ψ
    reduced by the nearest multiple q of π/2 (two-part π/2), fdlibm's kernel polynomials on
    |r| ≤ π/4, then the quadrant's swap and signs. Within 2.2e-16 of ``math.cos``/``math.sin``
    (tests/test_kernels.py); ~5 ns per ray against ~27 ns for libm's tan or sin + cos."""
    q = math.floor(psi * (2.0 / math.pi) + 0.5)
    r = (psi - q * _PIO2_HI) - q * _PIO2_LO
    z = r * r
    s = r + r * z * (_S[0] + z * (_S[1] + z * (_S[2] + z * (_S[3] + z * (_S[4] + z * _S[5])))))
    c = (
        1.0
        - 0.5 * z
        + z * z * (_C[0] + z * (_C[1] + z * (_C[2] + z * (_C[3] + z * (_C[4] + z * _C[5])))))
    )
    # the quadrant's swap and signs in floating point and selects (no branch, and AVX2 has
    # no packed int64 conversion), so that loops calling this vectorise
    quadrant = q - 4.0 * math.floor(0.25 * q)  # 0, 1, 2 or 3, exactly
    odd = (quadrant == 1.0) | (quadrant == 3.0)
    cos, sin = (s, c) if odd else (c, s)
    cos = -cos if (quadrant == 1.0) | (quadrant == 2.0) else cos
    return cos, (-sin if quadrant >= 2.0 else sin)


@_vector_inlined
def _atan_approx(y, x):
    """atan2(y, x) ∈ [0, π] for y ≥ 0 to within ``ATAN_ERROR`` rad (0 for x = y = 0), without
    libm and without branches: t = min/max of |x|, y in [0, 1], atan t = t·P(t²) with P the
    degree-9 Chebyshev fit ``_ATAN``, then reflected to the octant of (x, y)."""
    ax = abs(x)
    lo, hi = min(ax, y), max(ax, y)
    t = lo / hi if hi > 0.0 else 0.0
    z = t * t
    c = _ATAN
    p = c[5] + z * (c[6] + z * (c[7] + z * (c[8] + z * c[9])))
    a = t * (c[0] + z * (c[1] + z * (c[2] + z * (c[3] + z * (c[4] + z * p)))))
    a = 0.5 * math.pi - a if y > ax else a
    return math.pi - a if x < 0.0 else a


@_compiled
def locate_one(ox, oy, oz, phi_i_deg, n_theta, n_phi, folded, edges):
    """``Bins.locate`` of one direction o against the incident azimuth ``phi_i_deg`` (degrees,
    any value): φi taken to (−180°, 180°] as ``bins._half_turn`` does, then ``_bin_of``. The
    exact decision of ``bin_rays`` near an edge, ties included."""
    phi_i = phi_i_deg % 360.0  # np.mod's (Python's) float remainder
    phi_i = phi_i - 360.0 if phi_i > 180.0 else phi_i
    return _bin_of(ox, oy, oz, phi_i, n_theta, n_phi, folded, edges)


@_vector_inlined
def _groove_frame(psi, wi):
    """wi rotated by −ψ into the groove frame: (wx, wy, wz, cos ψ, sin ψ) (``cos_sin``)."""
    cp, sp = cos_sin(psi)
    return cp * wi[0] + sp * wi[1], -sp * wi[0] + cp * wi[1], wi[2], cp, sp


@_inlined
def _groove_facet(x0, r, half, scale, grooves):
    """The facet met by a ray crossing z = 0 at x0 inside the tile with horizontal advance
    r = −wi_x/wi_z per unit depth (groove frame; equal-width V-grooves,
    ``tracer.VGrooveCaster``; ``scale`` = grooves per unit x; ``grooves``: the caster's
    columns x_left, x_right, w_left, depth, facet_rim, facet_wall, facet_sigma): its groove k
    (the guess ⌊(x0 + half)·scale⌋ is off by one at most), the left wall unless the bottom
    comes first. Returns (f, |x0 − rim| w, w − σ a D): the hit's distance from the facet's
    rim is s = their ratio (``VGrooveCaster``'s s_L, s_R)."""
    x_left, x_right, w_left, depth, facet_rim, facet_wall, facet_sigma = grooves
    g = len(x_left)
    k = min(int((x0 + half) * scale), g - 1)
    if x0 < x_left[k] and k > 0:
        k -= 1
    if x0 >= x_right[k] and k < g - 1:
        k += 1
    ad = r * depth[k]
    f = 2 * k + (1 if x0 - x_left[k] + ad >= w_left[k] else 0)
    w = facet_wall[f]
    return f, abs(x0 - facet_rim[f]) * w, w - facet_sigma[f] * ad


@_inlined
def _groove_hit(x, psi, wi, zw, half, scale, grooves):
    """The exact primary hit of the ray from (x, ·, z) with groove azimuth ψ (zw = z/wi_z):
    ``_groove_frame``, the z = 0 crossing x0 wrapped into the tile, ``_groove_facet``.
    Returns (wi in the groove frame (wx, wy, wz), facet f, s)."""
    wx, wy, wz, _, _ = _groove_frame(psi, wi)
    x0 = x - zw * wx  # z = 0 crossing
    if x0 < -half or x0 >= half:
        x0 = (x0 + half) % (2 * half) - half
    f, num, den = _groove_facet(x0, -wx / wz, half, scale, grooves)
    return wx, wy, wz, f, num / den


@_vector_inlined
def groove_margin(s, signed_tan, width, ox, oz):
    """The exact V-groove masking margin s(1 + tanθ σ wo_x/wo_z) − W of a hit at horizontal
    distance s from its facet's rim, leaving along wo (``VGrooveProfile.margin_from_rim``):
    > 0 ⇔ masked by the opposite facet."""
    return s * (1.0 + signed_tan * ox / oz) - width


@_vector_inlined
def _groove_reflection(wx, wy, wz, s, nx, nz, signed_tan, width):
    """A primary hit at distance s from the rim of a facet with unit normal (nx, 0, nz),
    tanθ σ ``signed_tan`` and groove width ``width``, lit from the groove-frame
    wi = (wx, wy, wz): (ledger class, c = n·wi, mirror direction wo = 2c·n − wi) with the
    masking margin s(1 + tanθ σ wo_x/wo_z) − W (``VGrooveProfile.margin_from_rim``):
    RAY_UNRESOLVED if back-facing (c ≤ 0), else DOWNWARD if wo_z ≤ 0, MASKED if the margin
    is > 0, SINGLE otherwise. Branch-free (selects)."""
    c = wx * nx + wz * nz
    ox = 2.0 * c * nx - wx
    oy = -wy
    oz = 2.0 * c * nz - wz
    masked = groove_margin(s, signed_tan, width, ox, oz) > 0.0
    status = MASKED if masked else SINGLE
    status = DOWNWARD if oz <= 0.0 else status
    return (RAY_UNRESOLVED if c <= 0.0 else status), c, ox, oy, oz


@_vector_inlined
def _fresnel_weights(c, m, n2, k2, fresnel_mode, weight, t):
    """weight[t + j] = F(c[j]) (``_fresnel_weight``), 0 where c ≤ 0 (back-facing), for
    j < m: one loop per mode, so that each vectorises."""
    if fresnel_mode == FRESNEL_REAL:
        for j in range(m):
            weight[t + j] = 0.0 if c[j] <= 0.0 else fresnel_real_scalar(c[j], n2, k2)
    else:
        one = 1.0 if fresnel_mode == FRESNEL_MIRROR else 0.0
        for j in range(m):
            weight[t + j] = 0.0 if c[j] <= 0.0 else one


@_vectorised
def groove_frame_directions(psi, wi, wx, wy, wz, dx, dy, dz, d32):
    """Per ray i: the incident direction wi rotated by −ψ_i into its groove frame (``wx``,
    ``wy``, ``wz``; ``_groove_frame``, as ``analytic_vgroove`` does), the ray direction −w
    (``dx``, ``dy``, ``dz``) and its float32 copy ``d32`` (N, 3); vectorised but for the
    interleaved float32 copy."""
    w3 = (wi[0], wi[1], wi[2])  # scalars: a store cannot alias them
    for i in range(len(psi)):
        x, y, z, _, _ = _groove_frame(psi[i], w3)
        wx[i], wy[i], wz[i] = x, y, z
        dx[i], dy[i], dz[i] = -x, -y, -z
    for i in range(len(psi)):
        d32[i, 0], d32[i, 1], d32[i, 2] = np.float32(dx[i]), np.float32(dy[i]), np.float32(dz[i])


@_vector_inlined
def _bin_guess(ox, oy, oz, ex, ey, n_theta, n_phi, t_scale, p_scale, gt, gp):
    """Branch-free part of ``bin_rays``: the flat folded bin of the rising direction o
    against the unit azimuth (ex, ey) from ``_atan_approx`` (θ bins ``t_scale`` per radian,
    Δφ bins ``p_scale`` per radian and half a bin shifted), and whether either angle lies
    within ``gt``/``gp`` (bins) of an edge, where the guess may differ from ``Bins.locate``'s:
    (flat, near)."""
    rho = math.sqrt(ox * ox + oy * oy)
    zenith = rho == 0.0  # φo = atan2(±0, ±0): along ±x, as NumPy's arctan2 takes it
    hx = math.copysign(1.0, ox) if zenith else ox
    hy = 0.0 if zenith else oy
    u = _atan_approx(rho, oz) * t_scale
    v = _atan_approx(abs(ex * hy - ey * hx), ex * hx + ey * hy) * p_scale + 0.5
    k, j = int(u), int(v)
    fu, fv = u - k, v - j
    near = (fu < gt) | (fu > 1.0 - gt) | (fv < gp) | (fv > 1.0 - gp)
    return min(k, n_theta - 1) * n_phi + min(j, n_phi - 1), near


@_vector_inlined
def _bin_scales(n_theta, n_phi):
    """(θ bins per radian, Δφ bins per radian, guards in bins) of a folded grid for
    ``_bin_guess``: the guards are twice ``ATAN_ERROR``."""
    t_scale, p_scale = n_theta / (0.5 * math.pi), (n_phi - 1) / math.pi
    return t_scale, p_scale, 2.0 * ATAN_ERROR * t_scale, 2.0 * ATAN_ERROR * p_scale


@_vectorised
def bin_rays(status, wox, woy, woz, psi, rotate, phi_i_deg, n_theta, edges, near, where):
    """``where[i]`` = ``Bins.locate`` of wo_i on the folded grid (``n_theta``, Δφ ``edges``
    in degrees) for the SINGLE rays (others untouched), against the incident azimuth
    ``phi_i_deg`` (degrees), less ψ_i when ``rotate`` (wo in the ray's groove frame: Δφ is
    unchanged by the rotation). Two passes: a branch-free one that the compiler vectorises
    (``_bin_guess``: ``_atan_approx`` angles, ~4× faster than the same arithmetic ray by
    ray) flags in ``near`` (bool work array) the rays whose angle lies within twice
    ``ATAN_ERROR`` of an edge; the second bins those with ``Bins.locate``'s own arithmetic
    (``locate_one``), so the result is ``Bins.locate``'s for every ray, ties on an edge
    included (a mirror at θo = 30° on 2° bins)."""
    n_phi = len(edges) - 1
    ts, fs, gt, gf = _bin_scales(n_theta, n_phi)
    cos_phi, sin_phi = math.cos(math.radians(phi_i_deg)), math.sin(math.radians(phi_i_deg))
    for i in range(len(status)):
        ex, ey = cos_phi, sin_phi
        if rotate:
            cp, sp = cos_sin(psi[i])
            ex = cp * cos_phi + sp * sin_phi
            ey = -sp * cos_phi + cp * sin_phi
        flat, near[i] = _bin_guess(wox[i], woy[i], woz[i], ex, ey, n_theta, n_phi, ts, fs, gt, gf)
        where[i] = flat if status[i] == SINGLE else where[i]
    for i in range(len(status)):
        if near[i] and status[i] == SINGLE:
            phi = phi_i_deg - psi[i] * (180.0 / math.pi) if rotate else phi_i_deg
            where[i] = locate_one(wox[i], woy[i], woz[i], phi, n_theta, n_phi, True, edges)


@_vectorised
def analytic_vgroove(
    x,
    z,
    psi,
    wi,
    half,
    x_left,
    x_right,
    w_left,
    depth,
    facet_rim,
    facet_wall,
    facet_sigma,
    facet_nx,
    facet_nz,
    facet_signed_tan,
    facet_width,
    n2,
    k2,
    fresnel_mode,
    phi_i_deg,
    folded,
    n_theta,
    edges,
    status,
    weight,
    where,
    wox,
    woy,
    woz,
):
    """``masking="analytic"`` for rays from (x, ·, z) with groove azimuths ψ (``paths.
    analytic_columns``; the geometry is ``tracer.VGrooveCaster``'s, its per-groove and
    per-facet columns passed as arrays). Per ray, in the groove frame: the primary hit
    (``_groove_hit``) and its class, Fresnel weight and mirror direction wo
    (``_groove_reflection``; ``status``, ``weight``); on a ``folded`` grid (``n_theta``,
    Δφ ``edges`` in degrees) the bin of wo for SINGLE rays against φi (``phi_i_deg``) less
    ψ, as ``bin_rays`` (``where``, −1 for the others); otherwise ``where`` = −1
    and wo in ``wox/woy/woz`` for the caller to bin. In tiles of ``TILE`` rays, passes: the
    arithmetic before and after the per-facet look-ups, and the bins, in branch-free loops
    the compiler vectorises (AVX2 has no gather it deems worth using, so an indexed load
    keeps a loop scalar), the look-ups and the bins near an edge one by one — the same
    arithmetic as ``_groove_hit``/``_groove_reflection`` ray by ray (so
    ``analytic_vgroove_bounces`` agrees bitwise) and ``bin_rays``'s bins."""
    scale = len(x_left) / (2.0 * half)
    zw = z / wi[2]
    grooves = (x_left, x_right, w_left, depth, facet_rim, facet_wall, facet_sigma)
    w3 = (wi[0], wi[1], wi[2])  # scalars: a store cannot alias them, the loops vectorise
    n_phi = len(edges) - 1
    ts, fs, gt, gf = _bin_scales(n_theta, n_phi)
    cos_phi, sin_phi = math.cos(math.radians(phi_i_deg)), math.sin(math.radians(phi_i_deg))
    tile = np.empty((15, TILE))  # per-ray scratch of one tile
    wx, wy, x0, cp, sp, num, den = tile[0], tile[1], tile[2], tile[3], tile[4], tile[5], tile[6]
    nx, nz, tan, width, c = tile[7], tile[8], tile[9], tile[10], tile[11]
    ox, oy, oz, near = tile[12], tile[13], tile[14], np.empty(TILE, np.bool_)
    for t in range(0, len(x), TILE):
        m = min(TILE, len(x) - t)
        for j in range(m):  # vectorised: groove frame and z = 0 crossing
            wx[j], wy[j], _, cp[j], sp[j] = _groove_frame(psi[t + j], w3)
            x0[j] = x[t + j] - zw * wx[j]
        for j in range(m):  # one by one: wrap, groove, facet (indexed loads)
            xj = x0[j]
            if xj < -half or xj >= half:
                xj = (xj + half) % (2 * half) - half
            f, num[j], den[j] = _groove_facet(xj, -wx[j] / w3[2], half, scale, grooves)
            nx[j], nz[j] = facet_nx[f], facet_nz[f]
            tan[j], width[j] = facet_signed_tan[f], facet_width[f]
        for j in range(m):  # vectorised: reflection and class
            status[t + j], c[j], ox[j], oy[j], oz[j] = _groove_reflection(
                wx[j], wy[j], w3[2], num[j] / den[j], nx[j], nz[j], tan[j], width[j]
            )
        _fresnel_weights(c, m, n2, k2, fresnel_mode, weight, t)
        if not folded:  # the caller bins wo
            for j in range(m):
                wox[t + j], woy[t + j], woz[t + j] = ox[j], oy[j], oz[j]
                where[t + j] = -1
            continue
        for j in range(m):  # vectorised: bins against φi rotated by −ψ (``bin_rays``)
            ex = cp[j] * cos_phi + sp[j] * sin_phi
            ey = -sp[j] * cos_phi + cp[j] * sin_phi
            flat, near[j] = _bin_guess(ox[j], oy[j], oz[j], ex, ey, n_theta, n_phi, ts, fs, gt, gf)
            where[t + j] = flat if status[t + j] == SINGLE else -1
        for j in range(m):  # near an edge: Bins.locate's own arithmetic
            if near[j] and status[t + j] == SINGLE:
                phi = phi_i_deg - psi[t + j] * (180.0 / math.pi)
                where[t + j] = locate_one(ox[j], oy[j], oz[j], phi, n_theta, n_phi, True, edges)


@_compiled
def add_blocks(sum_w, sum_w2, count, sum_pair, led_n, led_f, bins, sums, cnt, offsets, ln, lf):
    """Add a chunk's sparse per-block sums (``block_tallies``: block b's distinct bins are
    ``bins[offsets[b]:offsets[b + 1]]``) to the running totals, block by block in block order
    — bitwise what adding each block's dense sums would give (an untouched bin adds 0)."""
    for b in range(len(offsets) - 1):
        for q in range(offsets[b], offsets[b + 1]):
            k = bins[q]
            sum_w[k] += sums[0, q]
            sum_w2[k] += sums[1, q]
            count[k] += cnt[q]
            sum_pair[k] += sums[2, q]
        for c in range(led_n.shape[0]):
            led_n[c] += ln[b, c]
            led_f[c] += lf[b, c]


def fresnel_mode(ior) -> tuple:
    """(mode, n², k²) of ``_fresnel_weight`` for a resolved index ``ior`` (None = mirror)."""
    if ior is None:
        return FRESNEL_MIRROR, 0.0, 0.0
    eta = complex(ior)
    return (FRESNEL_NONE if eta == 1 else FRESNEL_REAL), eta.real**2, eta.imag**2


@_inlined
def _bin_of(x, y, z, phi_i, n_theta, n_phi, folded, edges):
    """Flat (θo, Δφ) bin of the unit direction (x, y, z) (``bin_index``), −1 if z ≤ 0: its
    angles θo = atan2(√(x² + y²), z) and φo = atan2(y, x) by ``atan2_portable``."""
    if not z > 0.0:
        return -1
    theta = atan2_portable(math.sqrt(x * x + y * y), z)
    phi = atan2_portable(y, x)
    to_deg = 180.0 / math.pi
    w = 180.0 / (n_phi - 1) if folded else 360.0 / n_phi
    it = min(int(theta * to_deg * (n_theta / 90.0)), n_theta - 1)
    d = phi * to_deg - phi_i
    if d < 0.0:
        d += 360.0
    if folded:
        if d > 180.0:
            d = 360.0 - d
    elif d >= 360.0 - 0.5 * w:
        d -= 360.0
    ip = min(max(math.floor(d / w + 0.5), 0.0), n_phi - 1.0)
    k = int(ip)
    if d < edges[k]:
        k -= 1
    if d >= edges[k + 1]:
        k += 1
    return it * n_phi + min(max(k, 0), n_phi - 1)


@_compiled
def direction_angles(x, y, z, theta, phi):
    """θ = atan2(√(x² + y²), z) and φ = atan2(y, x) in radians (``atan2_portable``) of the
    directions (x, y, z); writes ``theta`` and ``phi``."""
    for i in range(len(x)):
        theta[i] = atan2_portable(math.sqrt(x[i] * x[i] + y[i] * y[i]), z[i])
        phi[i] = atan2_portable(y[i], x[i])


@_compiled
def bin_index(x, y, z, phi_i, n_theta, n_phi, folded, edges, out):
    """Flat (θo, Δφ) bin index of the unit directions (x, y, z) (``Bins.locate``), their
    angles by ``atan2_portable``: θo in degrees,
    bin ⌊θo·n_θ/90⌋ (capped); Δφ = φ − φi in degrees (``phi_i``: one value, or one per
    direction, in (−180°, 180°]) taken to [0°, 360°), folded to [0°, 180°] or shifted to
    [−w/2, 360° − w/2); its bin the i with edges[i] ≤ Δφ < edges[i + 1] (capped), found from
    the uniform spacing w (bin k centred on k·w) and corrected against ``edges`` themselves;
    −1 where z ≤ 0 (``_bin_of``). Writes ``out``."""
    for i in range(len(x)):
        pi = phi_i[i if len(phi_i) > 1 else 0]
        out[i] = _bin_of(x[i], y[i], z[i], pi, n_theta, n_phi, folded, edges)


# --- scattering orders (``bounces``): paths followed beyond the first bounce ----------------
# terminal classes of a path (``bounces.TERMINAL``): escaped after order 1, 2, 3, >= 4; cut
# off by the bounce limit; cut off by the weight floor; unresolved; missed
ESC_1, ESC_2, ESC_3, ESC_4UP, CUT_BOUNCES, CUT_WEIGHT, PATH_UNRESOLVED, PATH_MISSED = range(8)
N_TERMINAL = 8


@_compiled
def _order_class(order):
    """Terminal class ESC_1 … ESC_4UP of a path escaping after ``order`` bounces."""
    return min(order, 4) - 1


@_compiled
def bounce_step(
    b,
    limit,
    floor,
    live,
    hs,
    prim,
    px,
    py,
    pz,
    dx,
    dy,
    dz,
    shared,
    w,
    nx,
    ny,
    nz,
    lift,
    hx,
    hy,
    n2,
    k2,
    fresnel_mode,
    status1,
    weight1,
    term,
    wterm,
    where,
    esc,
    edx,
    edy,
    edz,
    nlive,
    sx,
    sy,
    sz,
    ndx,
    ndy,
    ndz,
    nd32,
    nw,
    use_table,
    tab_weight,
    tab_bin,
    first_facet,
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
    * otherwise bounce b: w ← w·F(c) (``_fresnel_weight``), wo = d + 2c·n (the mirror
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
    instead of being listed in ``esc``. Returns (continuing paths m, escapes e)."""
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
            term[g] = _order_class(b - 1)
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
            fw = _fresnel_weight(c, n2, k2, fresnel_mode)
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


@_compiled
def analytic_vgroove_bounces(
    x,
    z,
    psi,
    wi,
    half,
    x_left,
    x_right,
    w_left,
    depth,
    facet_rim,
    facet_wall,
    facet_sigma,
    facet_nx,
    facet_nz,
    facet_signed_tan,
    facet_width,
    n2,
    k2,
    fresnel_mode,
    limit,
    floor,
    status1,
    weight1,
    term,
    wterm,
    order,
    wox,
    woy,
    woz,
):
    """The exact float64 bounce chain in a V-groove (``masking="analytic"``, ``bounces`` > 1).

    The primary hit is ``analytic_vgroove``'s (``_groove_hit``, so ``status1``/``weight1``
    equal its single-bounce classes and weights bitwise). A ray reflected inside a groove can
    only meet the groove's other wall (f ↔ f xor 1) before rising above z = 0, where nothing
    lies (every rim at z = 0): it does when it points down (wo_z ≤ 0) or when the masking
    margin s(1 + tanθ σ wo_x/wo_z) − W is > 0 (``VGrooveProfile.margin_from_rim``); otherwise
    the path escapes after this bounce. In the groove frame (x across, z up) a hit at distance
    s from the rim R of facet f (tilt tanθ, σ = ±1 towards the other rim) lies at
    (R + σs, −s tanθ); the other wall's points are (R + σW − σs', −s' tanθ'); the ray from the
    hit along (ox, oz) meets it after
        t = (s tanθ − (W − s) tanθ') / (oz − σ ox tanθ'),   s' = W − s − σ t ox,
    clipped to the wall [0, w_f']. Each bounce multiplies the weight by F(c), c = −d·n
    (``_fresnel_weight``); the chain stops when the path escapes (``term`` ESC_*, ``wterm``,
    its direction in the groove frame ``wox``/``woy``/``woz``), after ``limit`` bounces with
    the path still inside (CUT_BOUNCES), below the weight ``floor`` (CUT_WEIGHT) or at a
    back-facing hit (PATH_UNRESOLVED, only from rounding). ``order`` = bounces made."""
    scale = len(x_left) / (2.0 * half)
    zw = z / wi[2]
    grooves = (x_left, x_right, w_left, depth, facet_rim, facet_wall, facet_sigma)
    for i in range(len(x)):
        wx, wy, wz, f, s = _groove_hit(x[i], psi[i], wi, zw, half, scale, grooves)
        dx, dy, dz = -wx, -wy, -wz
        weight = 1.0
        wox[i], woy[i], woz[i] = math.nan, math.nan, math.nan
        b = 1
        while True:
            nx, nz = facet_nx[f], facet_nz[f]
            c = -(dx * nx + dz * nz)
            if c <= 0.0:  # back-facing: unresolved
                term[i] = PATH_UNRESOLVED
                wterm[i] = weight
                order[i] = b - 1
                if b == 1:
                    status1[i] = RAY_UNRESOLVED
                    weight1[i] = 0.0
                break
            fw = _fresnel_weight(c, n2, k2, fresnel_mode)
            weight *= fw
            ox = 2.0 * c * nx + dx
            oy = dy
            oz = 2.0 * c * nz + dz
            order[i] = b
            down = not oz > 0.0
            again = down or groove_margin(s, facet_signed_tan[f], facet_width[f], ox, oz) > 0.0
            if b == 1:
                weight1[i] = fw
                status1[i] = DOWNWARD if down else (MASKED if again else SINGLE)
            if not again:
                term[i] = _order_class(b)
                wterm[i] = weight
                wox[i], woy[i], woz[i] = ox, oy, oz
                break
            if b >= limit:
                term[i] = CUT_BOUNCES
                wterm[i] = weight
                break
            if weight < floor:
                term[i] = CUT_WEIGHT
                wterm[i] = weight
                break
            f2 = f ^ 1
            sg = facet_sigma[f]
            tan2 = abs(facet_signed_tan[f2])
            tt = (s * abs(facet_signed_tan[f]) - (facet_width[f] - s) * tan2) / (
                oz - sg * ox * tan2
            )
            s = min(max(facet_width[f] - s - sg * tt * ox, 0.0), facet_wall[f2])
            f = f2
            dx, dy, dz = ox, oy, oz
            b += 1


@_compiled
def order_block_tallies(
    status1,
    weight1,
    term,
    wterm,
    where,
    block,
    acc,
    touched,
    out_bin,
    out_sums,
    out_cnt,
    offsets,
    ln,
    lf,
):
    """``block_tallies`` for paths followed over several bounces (``bounces``): a path that
    escapes adds its carried weight ``wterm`` to its (order, bin) slot ``where`` (≥ 0; −1
    for paths that do not escape), with Σw, Σw², counts and the pair sum (rays 2k, 2k + 1 in
    the same slot) per block, stored sparsely as there. Ledger (blocks, 5 + N_TERMINAL):
    columns 0–4 count the first-bounce classes ``status1`` and sum their Fresnel weights
    ``weight1`` (``paths.LEDGER``), columns 5 + ``term`` the terminal classes and sum their
    carried weights ``wterm`` (the energy each class takes away)."""
    n = len(term)
    j = 0
    nl = 5
    for b in range((n + block - 1) // block):
        offsets[b] = j
        lo, hi = b * block, min(n, (b + 1) * block)
        for i in range(lo, hi):
            s = status1[i]
            ln[b, s] += 1
            lf[b, s] += weight1[i]
            t = term[i]
            ln[b, nl + t] += 1
            lf[b, nl + t] += wterm[i]
            k = where[i]
            if k >= 0:
                if touched[k] == 0:
                    out_bin[j] = k
                    j += 1
                v = wterm[i]
                acc[0, k] += v
                acc[1, k] += v * v
                touched[k] += 1
        for i in range(lo, hi - 1, 2):
            if where[i] >= 0 and where[i] == where[i + 1]:
                acc[2, where[i]] += wterm[i] * wterm[i + 1]
        for q in range(offsets[b], j):
            k = out_bin[q]
            for m in range(3):
                out_sums[m, q] = acc[m, k]
                acc[m, k] = 0.0
            out_cnt[q] = touched[k]
            touched[k] = 0
    offsets[(n + block - 1) // block] = j
