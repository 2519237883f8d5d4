"""Compiled per-ray bookkeeping between the Embree calls (numba, ``nogil``).

Why compiled: around Embree's ~170 ns per ray, the same steps written as NumPy array passes
(ray origins, segment bounds, hit points, masking-ray starts, per-facet look-ups, tallies)
cost ~200 ns per sample on a 512² heightfield (measured), so the pipeline ran at ~55–60 % of
raw Embree throughput; one fused loop per stage does the same arithmetic in a few ns per ray
and releases the GIL, so both threads run in parallel.

Reproducibility: every kernel is a loop in ray order that evaluates, per ray, exactly the
floating-point operations (same order, no fast-math, so no FMA contraction or reassociation)
of the NumPy expressions it replaced; sums (``block_tallies``) add rays in ray order, like
``np.bincount``. Results are therefore independent of batch size and thread count, and
bitwise those of the NumPy formulation (tests/test_kernels.py checks both).

Units and frames are the callers' (``tracer``/``estimator``): tile coordinates, unit
directions, distances along the ray.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

from microsim.analytic.fresnel import fresnel_real_scalar

__all__ = ["stratified_xy", "segment_setup", "segment_finish", "tabled_primary",
           "block_tallies", "apply_escape", "facet_mirror", "analytic_vgroove",
           "add_block"]

# tracer status codes (``tracer.HIT`` ...) and ledger classes (``estimator.SINGLE`` ...),
# repeated here as compile-time constants; ``estimator``/``tracer`` assert they agree
HIT, ESCAPED, UNRESOLVED, MISSED = 0, 1, 2, 3
SINGLE, MASKED, DOWNWARD, RAY_UNRESOLVED, RAY_MISSED = 0, 1, 2, 3, 4
FRESNEL_REAL, FRESNEL_MIRROR, FRESNEL_NONE = 0, 1, 2     # analytic_vgroove's fresnel_mode

_compiled = njit(cache=True, nogil=True)


@_compiled
def stratified_xy(r0, xi, eta, n_total, rows, lx, ly, x, y):
    """Stratified origins of rays r0, r0 + 1, … (``estimator._block_rays``): ray r's stratum
    q = (r + ξ)/N · rows of a row-major sweep of ``rows`` rows, x = (q − ⌊q⌋)·Lx − Lx/2,
    y = (⌊q⌋ + η)/rows · Ly − Ly/2 (⌊q⌋ capped at rows − 1). Writes ``x``, ``y`` (N,)."""
    for i in range(len(xi)):
        q = (float(r0 + i) + xi[i]) / n_total * rows
        row = min(math.floor(q), rows - 1.0)
        x[i] = (q - row) * lx - lx / 2
        y[i] = (row + eta[i]) / rows * ly - ly / 2


@_compiled
def _wall_distance(x, d, half):
    """Distance ≥ 0 along a ray at coordinate x with direction component d to the wall
    ±half it heads for (inf if parallel)."""
    if d == 0.0:
        return math.inf
    return max((math.copysign(half, d) - x) / d, 0.0)


@_compiled
def segment_setup(ox, oy, oz, dx, dy, dz, shared, live, d32, hx, hy, zmax, eps, rel,
                  status, o32, d32k, tq, keep, tw, tt, tx, ty):
    """First half of one segment of the periodic walk (``Tracer._walk_columns``).

    Live ray i (global index ``live[i]``) at (ox, oy, oz)[i] with direction (dx, dy, dz)[j]
    (j = 0 if ``shared`` else i) and float32 copy ``d32[j]``: a ray rising from at or above
    ``zmax`` has escaped (``status`` ← ESCAPED); every other ray gets its float32 origin
    ``o32[k]`` (and direction ``d32k[k]`` unless shared), its Embree tfar
    ``tq[k]`` = min(wall distance, distance to zmax when rising)·(1 + rel) + eps (float32;
    inf beyond float32), ``keep[k]`` = i and the distances ``tw`` (nearest wall), ``tt`` (top),
    ``tx``, ``ty`` (x and y walls). Returns k, the number of rays to trace."""
    k = 0
    for i in range(len(live)):
        j = 0 if shared else i
        if dz[j] > 0.0 and oz[i] >= zmax:
            status[live[i]] = ESCAPED
            continue
        a = _wall_distance(ox[i], dx[j], hx)
        b = _wall_distance(oy[i], dy[j], hy)
        w = min(a, b)
        t = max((zmax - oz[i]) / dz[j], 0.0) if dz[j] > 0.0 else math.inf
        tq[k] = np.float32(min(w, t) * (1.0 + rel) + eps)
        o32[k, 0] = np.float32(ox[i])
        o32[k, 1] = np.float32(oy[i])
        o32[k, 2] = np.float32(oz[i])
        if not shared:
            d32k[k, 0] = d32[i, 0]
            d32k[k, 1] = d32[i, 1]
            d32k[k, 2] = d32[i, 2]
        keep[k] = i
        tw[k] = w
        tt[k] = t
        tx[k] = a
        ty[k] = b
        k += 1
    return k


@_compiled
def segment_finish(k, pid, tfar, occlusion, keep, live, ox, oy, oz, dx, dy, dz, shared,
                   falling_shared, d32k, tw, tt, tx, ty, hx, hy, zmin, eps,
                   status, prim, px, py, pz, nlive, nox, noy, noz, ndx, ndy, ndz, nd32):
    """Second half of a segment: Embree's answers ``pid`` (primID or geomID, −1 = none) and
    ``tfar`` (float32, intersect queries) for the k traced rays of ``segment_setup``.

    A hit sets ``status`` ← HIT and, for intersect queries, ``prim`` and the float64 point
    o + t·d (``px``, ``py``, ``pz``, by global index). A ray without a hit whose top distance
    is no larger than its wall distance has escaped (not for ``falling_shared``: one shared
    falling direction never reaches the top); a ray that would leave below zmin − eps (or
    never meets a wall) has leaked (MISSED); every other ray re-enters through the opposite
    wall at the same height: its wall point, clipped into the tile, moved to −copysign(half,
    d) on the axis (or axes) whose wall it reached. The re-entering rays are written compacted
    to ``nlive``/``nox``/``noy``/``noz`` (and ``ndx``/``ndy``/``ndz``/``nd32`` unless shared).
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
        w = tw[q]
        if not falling_shared and tt[q] <= w:
            status[g] = ESCAPED
            continue
        x = ox[i] + w * dx[j]
        y = oy[i] + w * dy[j]
        z = oz[i] + w * dz[j]
        if z < zmin - eps or not math.isfinite(w):
            status[g] = MISSED
            continue
        x = min(max(x, -hx), hx)                        # rounding along the wall
        y = min(max(y, -hy), hy)
        if tx[q] <= w:
            x = -math.copysign(hx, dx[j])
        if ty[q] <= w:
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
def tabled_primary(hs, prim, px, py, pz, code, fweight, nx, ny, nz, lift, wox, woy, woz,
                   wo32, fbin, status, weight, where, mi, sx, sy, sz, mdx, mdy, mdz, md32):
    """Ledger class, Fresnel weight and bin of primary rays from their first hits, looked up
    per facet (``estimator._FacetTable``: ``code``, ``fweight``, unit normal ``nx/ny/nz``,
    ``lift`` = n·v0 + eps, mirror direction ``wox/woy/woz`` and its float32 copy ``wo32``,
    bin ``fbin``), and the masking rays of the lit ones (code SINGLE): ray ``mi[m]`` starts at
    its hit point p moved along n onto the facet plane and eps above it,
    p − (p·n − lift)·n (``sx/sy/sz``), along the facet's mirror direction (``mdx``… ``md32``).
    ``hs`` is the walk status: HIT, MISSED/ESCAPED (→ RAY_MISSED) or UNRESOLVED. Writes
    ``status``, ``weight`` (0 without a hit), ``where`` (the facet bin for lit rays, else
    untouched); returns the number of masking rays."""
    m = 0
    for i in range(len(hs)):
        h = hs[i]
        if h != HIT:
            status[i] = RAY_MISSED if (h == MISSED or h == ESCAPED) else RAY_UNRESOLVED
            continue
        f = prim[i]
        c = code[f]
        status[i] = c
        weight[i] = fweight[f]
        if c != SINGLE:
            continue
        a, b, e = nx[f], ny[f], nz[f]
        off = px[i] * a + py[i] * b + pz[i] * e - lift[f]
        sx[m] = px[i] - off * a
        sy[m] = py[i] - off * b
        sz[m] = pz[i] - off * e
        mdx[m] = wox[f]
        mdy[m] = woy[f]
        mdz[m] = woz[f]
        md32[m, 0] = wo32[f, 0]
        md32[m, 1] = wo32[f, 1]
        md32[m, 2] = wo32[f, 2]
        where[i] = fbin[f]
        mi[m] = i
        m += 1
    return m


@_compiled
def block_tallies(status, weight, where, block, acc, touched, out_bin, out_sums, out_cnt,
                  offsets, ln, lf):
    """Per-block sums of a batch of whole blocks of ``block`` rays (``estimator._split_tallies``),
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
        for i in range(lo, hi):
            s = status[i]
            ln[b, s] += 1
            lf[b, s] += weight[i]
            if s == SINGLE and where[i] >= 0:
                k = where[i]
                if touched[k] == 0:
                    out_bin[j] = k
                    j += 1
                w = weight[i]
                acc[0, k] += w
                acc[1, k] += w * w
                touched[k] += 1
        for i in range(lo, hi - 1, 2):
            if (status[i] == SINGLE and status[i + 1] == SINGLE and where[i] >= 0
                    and where[i] == where[i + 1]):
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


@_compiled
def facet_mirror(nx, ny, nz, wix, wiy, wiz, cos, code, wox, woy, woz, wo32):
    """Per facet with unit normal n (``nx/ny/nz``) lit from wi: c = n·wi (``cos``), the mirror
    direction wo = 2c·n − wi (``wox/woy/woz``, float32 copy ``wo32``) and the class a primary
    hit gets (``code``): SINGLE if lit and wo rises (a masking ray decides), DOWNWARD if lit
    and wo points down, RAY_UNRESOLVED if back-facing (c ≤ 0)."""
    for f in range(len(nx)):
        c = nx[f] * wix + ny[f] * wiy + nz[f] * wiz
        x = 2.0 * c * nx[f] - wix
        y = 2.0 * c * ny[f] - wiy
        z = 2.0 * c * nz[f] - wiz
        cos[f] = c
        wox[f] = x
        woy[f] = y
        woz[f] = z
        wo32[f, 0] = np.float32(x)
        wo32[f, 1] = np.float32(y)
        wo32[f, 2] = np.float32(z)
        code[f] = RAY_UNRESOLVED if c <= 0.0 else (SINGLE if z > 0.0 else DOWNWARD)


@_compiled
def analytic_vgroove(x, z, psi, wi, cos_phi, sin_phi, half, x_left, x_right, w_left, depth,
                     facet_rim, facet_wall, facet_sigma, facet_nx, facet_nz, facet_signed_tan,
                     facet_width, n2, k2, fresnel_mode, n_theta, n_phi, folded,
                     status, weight, where, wox, woy, woz):
    """``masking="analytic"`` for rays from (x, ·, z) with groove azimuths ψ (``estimator.
    _analytic_columns``; the geometry is ``tracer.VGrooveCaster``'s, its per-groove and
    per-facet columns passed as arrays). Per ray, in the groove frame (wi rotated by −ψ, with
    cos ψ, sin ψ from t = tan(ψ/2): ((1 − t²), 2t)/(1 + t²)):

    * the primary hit (``VGrooveCaster.groove_hits``): the z = 0 crossing x0, wrapped into the
      tile; its groove k; the left wall unless the bottom comes first; the hit's distance
      s = |x0 − rim| w/(w − σ a D) from the facet's rim;
    * the Fresnel weight F(c), c = n·wi (``fresnel_mode``: FRESNEL_REAL ``fresnel_real_scalar``
      onto n2 = n², k2 = k²; FRESNEL_MIRROR 1; FRESNEL_NONE 0, η = 1 and c > 0), the mirror
      direction wo (groove frame, ``wox/woy/woz``) and the masking margin
      s(1 + tanθ σ wo_x/wo_z) − W (``VGrooveProfile.margin_from_rim``): class MASKED if > 0,
      DOWNWARD if wo_z ≤ 0 (wins), RAY_UNRESOLVED if back-facing (c ≤ 0, weight 0), else SINGLE;
    * for folded bins, the bin of wo against the rotated incident azimuth e (``Bins.locate``
      to rounding: θo = atan2(|wo_h|, wo_z), folded Δφ = atan2(|e × wo_h|, e·wo_h)), written to ``where``
      for SINGLE rays (−1 otherwise); unfolded bins are left to the caller (``where`` = −1).
    """
    g = len(x_left)
    scale = g / (2.0 * half)
    t_scale = n_theta / (math.pi / 2)
    p_scale = (n_phi - 1) / math.pi
    for i in range(len(x)):
        t = math.tan(0.5 * psi[i])
        d = 1.0 / (1.0 + t * t)
        cp, sp = (1.0 - t * t) * d, (2.0 * d) * t
        wx = cp * wi[0] + sp * wi[1]
        wy = -sp * wi[0] + cp * wi[1]
        wz = wi[2]
        x0 = x[i] - (z / wz) * wx                                # z = 0 crossing
        if x0 < -half or x0 >= half:
            x0 = (x0 + half) % (2 * half) - half
        k = min(int((x0 + half) * scale), g - 1)                 # ±1 at most
        if x0 < x_left[k] and k > 0:
            k -= 1
        if x0 >= x_right[k] and k < g - 1:
            k += 1
        ad = (-wx / wz) * depth[k]
        f = 2 * k + (1 if x0 - x_left[k] + ad >= w_left[k] else 0)
        w, sig = facet_wall[f], facet_sigma[f]
        s = abs(x0 - facet_rim[f]) * w / (w - sig * ad)
        nx, nz = facet_nx[f], facet_nz[f]
        c = wx * nx + wz * nz
        ox = 2.0 * c * nx - wx
        oy = -wy
        oz = 2.0 * c * nz - wz
        wox[i], woy[i], woz[i] = ox, oy, oz
        where[i] = -1
        if c <= 0.0:                                             # back-facing: unresolved
            status[i] = RAY_UNRESOLVED
            weight[i] = 0.0
            continue
        if fresnel_mode == FRESNEL_REAL:
            weight[i] = fresnel_real_scalar(c, n2, k2)
        else:                                                    # mirror 1, no interface 0
            weight[i] = 1.0 if fresnel_mode == FRESNEL_MIRROR else 0.0
        if oz <= 0.0:
            status[i] = DOWNWARD
            continue
        if s * (1.0 + facet_signed_tan[f] * ox / oz) - facet_width[f] > 0.0:
            status[i] = MASKED
            continue
        status[i] = SINGLE
        if folded:
            ex = cp * cos_phi + sp * sin_phi
            ey = -sp * cos_phi + cp * sin_phi
            theta = math.atan2(math.sqrt(ox * ox + oy * oy), oz)
            it = min(int(theta * t_scale), n_theta - 1)
            dphi = math.atan2(abs(ex * oy - ey * ox), ex * ox + ey * oy)
            ip = min(int(dphi * p_scale + 0.5), n_phi - 1)
            where[i] = it * n_phi + ip


@_compiled
def add_block(sum_w, sum_w2, count, sum_pair, bins, sw, sw2, cnt, sp):
    """Add one block's sparse sums (``block_tallies``: bins ``bins``, distinct) to the running
    per-bin totals; bins the block did not touch add nothing (as + 0 would)."""
    for q in range(len(bins)):
        k = bins[q]
        sum_w[k] += sw[q]
        sum_w2[k] += sw2[q]
        count[k] += cnt[q]
        sum_pair[k] += sp[q]
