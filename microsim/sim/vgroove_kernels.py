"""The V-groove closed form (``masking="analytic"``, ``vgroove_profile.VGrooveCaster``): per ray, wi
rotated by −ψ into its groove frame, the exact float64 primary hit (the groove crossed at
z = 0 decides the facet), the masking margin s(1 + tanθ σ wo_x/wo_z) − W
(``VGrooveProfile.margin_from_rim``), and the bounce chain between a groove's two walls.
Tile coordinates in the groove frame (x across the grooves, z up)."""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from microsim.bin_kernels import bin_guess, bin_scales, locate_one
from microsim.jit import TILE, compiled, inlined, vector_inlined, vectorised
from microsim.trig import cos_sin

from .engine.codes import (
    CUT_BOUNCES,
    CUT_WEIGHT,
    DOWNWARD,
    MASKED,
    PATH_UNRESOLVED,
    RAY_UNRESOLVED,
    SINGLE,
    order_class,
)
from .engine.primary import groove_margin
from .fresnel_kernels import fresnel_tile, fresnel_weight


class GrooveBins(NamedTuple):
    """How ``analytic_vgroove`` bins the reflected directions: on a ``folded`` grid
    (``n_theta``, Δφ ``edges`` in degrees) itself, against φi (``phi_i_deg``) less ψ;
    otherwise not (the caller bins them)."""

    phi_i_deg: float
    folded: bool
    n_theta: int
    edges: np.ndarray


class GrooveChainLedger(NamedTuple):
    """Per ray, ``analytic_vgroove_bounces``' answer: first-bounce class and Fresnel weight
    (``status1``, ``weight1``), terminal class and carried weight (``term``, ``wterm``),
    bounces made (``order``) and the escape direction in the groove frame (``wox``, ``woy``,
    ``woz``; NaN unless escaped)."""

    status1: np.ndarray
    weight1: np.ndarray
    term: np.ndarray
    wterm: np.ndarray
    order: np.ndarray
    wox: np.ndarray
    woy: np.ndarray
    woz: np.ndarray


@vector_inlined
def groove_frame(psi, wi):
    """wi rotated by −ψ into the groove frame: (wx, wy, wz, cos ψ, sin ψ) (``cos_sin``)."""
    cp, sp = cos_sin(psi)
    return cp * wi[0] + sp * wi[1], -sp * wi[0] + cp * wi[1], wi[2], cp, sp


@inlined
def _groove_facet(x0, r, half, scale, grooves):
    """The facet met by a ray crossing z = 0 at x0 inside the tile with horizontal advance
    r = −wi_x/wi_z per unit depth (groove frame; equal-width V-grooves,
    ``vgroove_profile.VGrooveCaster``; ``scale`` = grooves per unit x; ``grooves``: the caster's
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


@inlined
def _groove_hit(x, psi, wi, zw, half, scale, grooves):
    """The exact primary hit of the ray from (x, ·, z) with groove azimuth ψ (zw = z/wi_z):
    ``groove_frame``, the z = 0 crossing x0 wrapped into the tile, ``_groove_facet``.
    Returns (wi in the groove frame (wx, wy, wz), facet f, s)."""
    wx, wy, wz, _, _ = groove_frame(psi, wi)
    x0 = x - zw * wx  # z = 0 crossing
    if x0 < -half or x0 >= half:
        x0 = (x0 + half) % (2 * half) - half
    f, num, den = _groove_facet(x0, -wx / wz, half, scale, grooves)
    return wx, wy, wz, f, num / den


@vector_inlined
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


@vectorised
def groove_frame_directions(psi, wi, wx, wy, wz, dx, dy, dz, d32):
    """Per ray i: the incident direction wi rotated by −ψ_i into its groove frame (``wx``,
    ``wy``, ``wz``; ``groove_frame``, as ``analytic_vgroove`` does), the ray direction −w
    (``dx``, ``dy``, ``dz``) and its float32 copy ``d32`` (N, 3); vectorised but for the
    interleaved float32 copy."""
    w3 = (wi[0], wi[1], wi[2])  # scalars: a store cannot alias them
    for i in range(len(psi)):
        x, y, z, _, _ = groove_frame(psi[i], w3)
        wx[i], wy[i], wz[i] = x, y, z
        dx[i], dy[i], dz[i] = -x, -y, -z
    for i in range(len(psi)):
        d32[i, 0], d32[i, 1], d32[i, 2] = np.float32(dx[i]), np.float32(dy[i]), np.float32(dz[i])


@vectorised
def analytic_vgroove(x, z, psi, wi, groove, material, bins, out, wo, scratch):
    """``masking="analytic"`` for rays from (x, ·, z) with groove azimuths ψ (``ray_columns.
    analytic_columns``; the geometry is ``vgroove_profile.VGrooveCaster``'s, its per-groove and per-
    facet columns passed as one ``GrooveProfile``). Per ray, in the groove frame: the
    primary hit (``_groove_hit``) and its class, Fresnel weight and mirror direction wo
    (``_groove_reflection``; ``status``, ``weight``); on a ``folded`` grid (``n_theta``, Δφ
    ``edges`` in degrees: ``GrooveBins``) the bin of wo for SINGLE rays against φi less ψ,
    as ``bin_rays`` (``where``, −1 for the others); otherwise ``where`` = −1 and wo in the
    columns ``wo`` for the caller to bin. ``out``: (status, weight, where) (N,), written. In
    tiles of ``TILE`` rays, passes: the arithmetic before and after the per-facet look-ups,
    and the bins, in branch-free loops the compiler vectorises (AVX2 has no gather it deems
    worth using, so an indexed load keeps a loop scalar), the look-ups and the bins near an
    edge one by one — the same arithmetic as ``_groove_hit``/``_groove_reflection`` ray by
    ray (so ``analytic_vgroove_bounces`` agrees bitwise) and ``bin_rays``'s bins.
    ``groove``: ``vgroove_profile.GrooveProfile`` (the caster's ``profile``); ``material``:
    ``fresnel_kernels.FresnelMaterial``; ``scratch``: (tile (15, TILE) float64, near (TILE,)
    bool)."""
    half, x_left, x_right, w_left, depth = groove[:5]
    facet_rim, facet_wall, facet_sigma, facet_nx, facet_nz = groove[5:10]
    facet_signed_tan, facet_width = groove[10:]
    n2, k2, fresnel_mode = material
    phi_i_deg, folded, n_theta, edges = bins
    status, weight, where = out
    wox, woy, woz = wo
    tile, near = scratch
    scale = len(x_left) / (2.0 * half)
    zw = z / wi[2]
    grooves = (x_left, x_right, w_left, depth, facet_rim, facet_wall, facet_sigma)
    w3 = (wi[0], wi[1], wi[2])  # scalars: a store cannot alias them, the loops vectorise
    n_phi = len(edges) - 1
    ts, fs, gt, gf = bin_scales(n_theta, n_phi)
    cos_phi, sin_phi = math.cos(math.radians(phi_i_deg)), math.sin(math.radians(phi_i_deg))
    wx, wy, x0, cp, sp, num, den = tile[0], tile[1], tile[2], tile[3], tile[4], tile[5], tile[6]
    nx, nz, tan, width, c = tile[7], tile[8], tile[9], tile[10], tile[11]
    ox, oy, oz = tile[12], tile[13], tile[14]
    for t in range(0, len(x), TILE):
        m = min(TILE, len(x) - t)
        # the tile's rays as views indexed from 0: an index the compiler can tell is not
        # negative needs no wrap-around, so the loops load and store whole vectors
        psi_t, x_t, status_t, where_t = psi[t:], x[t:], status[t:], where[t:]
        for j in range(m):  # vectorised: groove frame and z = 0 crossing
            wx[j], wy[j], _, cp[j], sp[j] = groove_frame(psi_t[j], w3)
            x0[j] = x_t[j] - zw * wx[j]
        for j in range(m):  # one by one: wrap, groove, facet (indexed loads)
            xj = x0[j]
            if xj < -half or xj >= half:
                xj = (xj + half) % (2 * half) - half
            f, num[j], den[j] = _groove_facet(xj, -wx[j] / w3[2], half, scale, grooves)
            nx[j], nz[j] = facet_nx[f], facet_nz[f]
            tan[j], width[j] = facet_signed_tan[f], facet_width[f]
        for j in range(m):  # vectorised: reflection and class
            status_t[j], c[j], ox[j], oy[j], oz[j] = _groove_reflection(
                wx[j], wy[j], w3[2], num[j] / den[j], nx[j], nz[j], tan[j], width[j]
            )
        fresnel_tile(c, m, n2, k2, fresnel_mode, weight, t)
        if not folded:  # the caller bins wo
            wox_t, woy_t, woz_t = wox[t:], woy[t:], woz[t:]
            for j in range(m):
                wox_t[j], woy_t[j], woz_t[j] = ox[j], oy[j], oz[j]
                where_t[j] = -1
            continue
        for j in range(m):  # vectorised: bins against φi rotated by −ψ (``bin_rays``)
            ex = cp[j] * cos_phi + sp[j] * sin_phi
            ey = -sp[j] * cos_phi + cp[j] * sin_phi
            flat, near[j] = bin_guess(ox[j], oy[j], oz[j], ex, ey, n_theta, n_phi, ts, fs, gt, gf)
            where_t[j] = flat if status_t[j] == SINGLE else -1
        for j in range(m):  # near an edge: Bins.locate's own arithmetic
            if near[j] and status_t[j] == SINGLE:
                phi = phi_i_deg - psi_t[j] * (180.0 / math.pi)
                where_t[j] = locate_one(ox[j], oy[j], oz[j], phi, n_theta, n_phi, True, edges)


@compiled
def analytic_vgroove_bounces(x, z, psi, wi, groove, material, limit, floor, ledger):
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
    (``fresnel_weight``); the chain stops when the path escapes (``term`` ESC_*, ``wterm``,
    its direction in the groove frame ``wox``/``woy``/``woz``), after ``limit``
    bounces with the path still inside (CUT_BOUNCES), below the weight ``floor``
    (CUT_WEIGHT) or at a back-facing hit (PATH_UNRESOLVED, only from rounding). ``order`` =
    bounces made. ``groove``: ``vgroove_profile.GrooveProfile`` (the caster's ``profile``);
    ``material``: ``fresnel_kernels.FresnelMaterial``; ``ledger``: ``GrooveChainLedger``,
    written."""
    half, x_left, x_right, w_left, depth = groove[:5]
    facet_rim, facet_wall, facet_sigma, facet_nx, facet_nz = groove[5:10]
    facet_signed_tan, facet_width = groove[10:]
    n2, k2, fresnel_mode = material
    status1, weight1, term, wterm, order, wox, woy, woz = ledger
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
                _end_back_facing(ledger, i, b, weight)
                break
            fw = fresnel_weight(c, n2, k2, fresnel_mode)
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
                term[i] = order_class(b)
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
            f, s = _other_wall(groove, f, s, ox, oz)
            dx, dy, dz = ox, oy, oz
            b += 1


@inlined
def _end_back_facing(ledger, i, b, weight):
    """End chain ``i`` at a back-facing hit of bounce ``b`` (PATH_UNRESOLVED, ``weight``
    carried; at b = 1 its first-bounce class is RAY_UNRESOLVED, weight 0)."""
    ledger.term[i] = PATH_UNRESOLVED
    ledger.wterm[i] = weight
    ledger.order[i] = b - 1
    if b == 1:
        ledger.status1[i] = RAY_UNRESOLVED
        ledger.weight1[i] = 0.0


@inlined
def _other_wall(groove, f, s, ox, oz):
    """(facet f xor 1, s') where the ray reflected at distance ``s`` from the rim of facet
    ``f`` along (``ox``, ·, ``oz``) meets its groove's other wall (``analytic_vgroove_bounces``:
    t and s', s' clipped to the wall)."""
    facet_wall, facet_sigma, facet_signed_tan, facet_width = (
        groove.facet_wall, groove.facet_sigma, groove.facet_signed_tan, groove.facet_width,
    )  # fmt: skip
    f2 = f ^ 1
    sg = facet_sigma[f]
    tan2 = abs(facet_signed_tan[f2])
    tt = (s * abs(facet_signed_tan[f]) - (facet_width[f] - s) * tan2) / (oz - sg * ox * tan2)
    return f2, min(max(facet_width[f] - s - sg * tt * ox, 0.0), facet_wall[f2])
