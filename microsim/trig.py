"""Portable trigonometry of the compiled passes, without libm: ``atan2_portable`` (fdlibm,
< 1 ulp, the same bits on every IEEE-754 machine: the one rule by which directions are
binned), ``cos_sin`` (fdlibm kernels, within 2.2e-16) and the branch-free ``atan_approx``
(within ``ATAN_ERROR`` rad) of the vectorised bin guesses. Angles in radians."""

from __future__ import annotations

import math

from .jit import inlined, vector_inlined

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


ATAN_ERROR = 3e-9  # rad: bound on atan_approx's error (fit error + rounding)


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


@inlined
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


@inlined
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


@vector_inlined
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


@vector_inlined
def atan_approx(y, x):
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
