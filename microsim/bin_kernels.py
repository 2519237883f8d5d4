"""Flat (θo, Δφ) bins of directions (``Bins.locate``): θo bin ⌊θo·n_θ/90°⌋, Δφ = φo − φi
in degrees against the bin edges, angles by ``trig.atan2_portable``; and the parts of the
simulation's vectorised bin pass (``sim.ray_bins.bin_rays``): its branch-free guess by
``trig.atan_approx`` and the exact decision near an edge."""

from __future__ import annotations

import math

from .jit import compiled, inlined, vector_inlined
from .trig import ATAN_ERROR, atan2_portable, atan_approx


@compiled
def locate_one(ox, oy, oz, phi_i_deg, n_theta, n_phi, folded, edges):
    """``Bins.locate`` of one direction o against the incident azimuth ``phi_i_deg`` (degrees,
    any value): φi taken to (−180°, 180°] as ``bins._half_turn`` does, then ``_bin_of``. The
    exact decision of ``ray_bins.bin_rays`` near an edge, ties included."""
    phi_i = phi_i_deg % 360.0  # np.mod's (Python's) float remainder
    phi_i = phi_i - 360.0 if phi_i > 180.0 else phi_i
    return _bin_of(ox, oy, oz, phi_i, n_theta, n_phi, folded, edges)


@vector_inlined
def bin_guess(ox, oy, oz, ex, ey, n_theta, n_phi, t_scale, p_scale, gt, gp):
    """Branch-free part of ``ray_bins.bin_rays``: the flat folded bin of the rising direction o
    against the unit azimuth (ex, ey) from ``atan_approx`` (θ bins ``t_scale`` per radian,
    Δφ bins ``p_scale`` per radian and half a bin shifted), and whether either angle lies
    within ``gt``/``gp`` (bins) of an edge, where the guess may differ from ``Bins.locate``'s:
    (flat, near)."""
    rho = math.sqrt(ox * ox + oy * oy)
    zenith = rho == 0.0  # φo = atan2(±0, ±0): along ±x, as NumPy's arctan2 takes it
    hx = math.copysign(1.0, ox) if zenith else ox
    hy = 0.0 if zenith else oy
    u = atan_approx(rho, oz) * t_scale
    v = atan_approx(abs(ex * hy - ey * hx), ex * hx + ey * hy) * p_scale + 0.5
    k, j = int(u), int(v)
    fu, fv = u - k, v - j
    near = (fu < gt) | (fu > 1.0 - gt) | (fv < gp) | (fv > 1.0 - gp)
    return min(k, n_theta - 1) * n_phi + min(j, n_phi - 1), near


@inlined
def locate_folded(ox, oy, oz, ex, ey, phi_i_deg, n_theta, edges, scales):
    """``Bins.locate`` of the rising unit direction o on a folded grid (``n_theta``, Δφ
    ``edges`` in degrees) against the incident azimuth (ex, ey) = (cos φi, sin φi),
    ``phi_i_deg`` in degrees, for one ray: ``bin_guess`` (``scales`` = ``bin_scales``), and
    near an edge ``locate_one``'s exact arithmetic (as ``ray_bins.bin_rays``)."""
    ts, fs, gt, gf = scales
    n_phi = len(edges) - 1
    flat, near = bin_guess(ox, oy, oz, ex, ey, n_theta, n_phi, ts, fs, gt, gf)
    if near:
        return locate_one(ox, oy, oz, phi_i_deg, n_theta, n_phi, True, edges)
    return flat


@vector_inlined
def bin_scales(n_theta, n_phi):
    """(θ bins per radian, Δφ bins per radian, guards in bins) of a folded grid for
    ``bin_guess``: the guards are twice ``ATAN_ERROR``."""
    t_scale, p_scale = n_theta / (0.5 * math.pi), (n_phi - 1) / math.pi
    return t_scale, p_scale, 2.0 * ATAN_ERROR * t_scale, 2.0 * ATAN_ERROR * p_scale


@inlined
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


@compiled
def direction_angles(x, y, z, theta, phi):
    """θ = atan2(√(x² + y²), z) and φ = atan2(y, x) in radians (``atan2_portable``) of the
    directions (x, y, z); writes ``theta`` and ``phi``."""
    for i in range(len(x)):
        theta[i] = atan2_portable(math.sqrt(x[i] * x[i] + y[i] * y[i]), z[i])
        phi[i] = atan2_portable(y[i], x[i])


@compiled
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
