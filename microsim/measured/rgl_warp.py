"""The coordinates and tables of the RGL ".bsdf" format: unit coordinates of directions and
the piecewise-linear 2D tables the readers interpolate and warp by.

Unit coordinates: a direction of polar angle θ and azimuth φ (radians) has
u_θ = √(2θ/π) ∈ [0, 1] (θ = u_θ² π/2: nodes crowd towards the pole, where lobes are narrow)
and u_φ = (φ + π)/(2π) ∈ [0, 1]. For an isotropic file the half vector's azimuth is taken
relative to the incidence's, φm − φi, wrapped into u_φ ∈ [0, 1) (Δφ = 0 is u_φ = ½).

The warp (Mitsuba's continuous ``Marginal2D``): a grid of values v on the unit square, read
bilinearly, normalised per slice to integrate to 1, is a density p(x, y). Its map from
(x, y) to the square is (F_y(y), F_{x|y}(x)): the marginal CDF of y (rows) and the CDF of x
(columns) along the row at y, both exact for the bilinear density (piecewise quadratic); CDFs
of neighbouring θi slices are interpolated linearly, like every other table. Sampling runs
the map backwards. The readers evaluate with the inverse map only.
"""

from __future__ import annotations

import numpy as np

__all__ = ["Table2D", "theta2u", "u2theta", "phi2u", "u2phi", "elevation"]


# --- the parameterisation ---------------------------------------------------------------------
def theta2u(theta):
    """u_θ = √(2θ/π) of a polar angle θ (radians)."""
    return np.sqrt(np.maximum(theta, 0.0) * (2.0 / np.pi))


def u2theta(u):
    """The polar angle θ = u² π/2 (radians) of u_θ."""
    return u * u * (0.5 * np.pi)


def phi2u(phi):
    """u_φ = (φ + π)/(2π) of an azimuth φ (radians)."""
    return (phi + np.pi) / (2.0 * np.pi)


def u2phi(u):
    """The azimuth φ = (2u − 1)π (radians) of u_φ."""
    return (2.0 * u - 1.0) * np.pi


def elevation(d):
    """Polar angle 2 asin(|d − n|/2): accurate near the pole (the readers' formula)."""
    dist = np.sqrt(d[..., 0] ** 2 + d[..., 1] ** 2 + (d[..., 2] - 1.0) ** 2)
    return 2.0 * np.arcsin(np.clip(0.5 * dist, 0.0, 1.0))


def _lerp(a, b, t):
    return a + (b - a) * t


# --- piecewise-linear 2D tables (the readers' Marginal2D, continuous variant) -----------------
class Table2D:
    """A stack of 2D grids ``data`` (params…, H, W) on the unit square (nodes i/(W−1),
    j/(H−1); x ↔ columns, y ↔ rows), linear in each parameter between ``param_values``
    (clamped outside). ``warp=True``: normalised per slice and with the CDFs of the
    continuous marginal–conditional map (module docstring); else raw values."""

    def __init__(self, data, param_values=(), warp: bool = False):
        data = np.asarray(data, dtype=np.float64)
        self.H, self.W = data.shape[-2:]
        self.params = [np.asarray(p, dtype=np.float64) for p in param_values]
        res = data.shape[:-2]
        v = data.reshape(-1, self.H, self.W)
        strides, slices = [0] * len(res), 1
        for i in range(len(res) - 1, -1, -1):
            strides[i] = slices if res[i] > 1 else 0
            slices *= res[i]
        self.strides = strides
        if warp:
            dx, dy = 1.0 / (self.W - 1), 1.0 / (self.H - 1)
            cond = np.cumsum(0.5 * dx * (v[:, :, :-1] + v[:, :, 1:]), axis=2)  # (S, H, W−1)
            rows = cond[:, :, -1]
            marg = np.cumsum(0.5 * dy * (rows[:, :-1] + rows[:, 1:]), axis=1)  # (S, H−1)
            with np.errstate(divide="ignore"):
                norm = 1.0 / marg[:, -1]
            self.cond = (cond * norm[:, None, None]).reshape(len(v), -1)
            self.marg = marg * norm[:, None]
            v = v * norm[:, None, None]
        self.data = v.reshape(len(v), -1)

    def _weights(self, params):
        """Slice indices (N, C) and weights (N, C) of the 2^D corners around ``params``."""
        n = np.broadcast_shapes(*(np.shape(p) for p in params)) if params else ()
        idx, wts = [np.zeros(n, dtype=np.intp)], [np.ones(n)]
        for d, values in enumerate(self.params):
            if values.size == 1:
                continue
            x = np.broadcast_to(np.asarray(params[d], dtype=np.float64), n).reshape(-1)
            i = np.clip(np.sum(values[:-1, None] < x[None, :], axis=0) - 1, 0, values.size - 2)
            w1 = np.clip((x - values[i]) / (values[i + 1] - values[i]), 0.0, 1.0).reshape(n)
            i = i.reshape(n)
            st = self.strides[d]
            idx = [a + k * st for a in idx for k in (i, i + 1)]
            wts = [w * f for w in wts for f in (1.0 - w1, w1)]
        return np.stack(idx, axis=-1), np.stack(wts, axis=-1)

    @staticmethod
    def _get(table, corners, index):
        sl, wt = corners
        return np.sum(table[sl, index[..., None]] * wt, axis=-1)

    def _at(self, table, corners, index, n):
        return self._get(table, corners, np.clip(index, 0, n - 1))

    def eval(self, pos, params=()):
        """Bilinear value at ``pos`` (N, 2) = (x, y) ∈ [0, 1]² (clipped)."""
        corners = self._weights(params)
        W, H = self.W, self.H
        p = np.clip(pos, 0.0, 1.0) * (W - 1, H - 1)
        o = np.minimum(p.astype(np.intp), (W - 2, H - 2))
        t = p - o
        i = o[..., 0] + o[..., 1] * W
        n = W * H
        v00, v10 = self._at(self.data, corners, i, n), self._at(self.data, corners, i + 1, n)
        v01 = self._at(self.data, corners, i + W, n)
        v11 = self._at(self.data, corners, i + W + 1, n)
        return _lerp(_lerp(v00, v10, t[..., 0]), _lerp(v01, v11, t[..., 0]), t[..., 1])

    def invert(self, u, params=()):
        """The warp of ``u`` (N, 2) in the half vector's square to s (N, 2) ∈ [0, 1]² and the
        density there (the readers' ``invert``)."""
        corners = self._weights(params)
        W, H = self.W, self.H
        nd, nc, nm = W * H, (W - 1) * H, H - 1
        p = np.clip(u, 0.0, 1.0) * (W - 1, H - 1)
        o = np.minimum(p.astype(np.intp), (W - 2, H - 2))
        t = p - o
        px, py = o[..., 0], o[..., 1]
        tx, ty = t[..., 0], t[..., 1]
        i = py * W + px
        v00, v10 = self._at(self.data, corners, i, nd), self._at(self.data, corners, i + 1, nd)
        v01 = self._at(self.data, corners, i + W, nd)
        v11 = self._at(self.data, corners, i + W + 1, nd)
        c0, c1 = _lerp(v00, v01, ty), _lerp(v10, v11, ty)
        pdf = _lerp(c0, c1, tx)
        x = tx * _lerp(c0, c1, 0.5 * tx) / (W - 1)
        oc = py * (W - 1)
        left = _lerp(
            self._at(self.cond, corners, oc + px - 1, nc),
            self._at(self.cond, corners, oc + (W - 1) + px - 1, nc),
            ty,
        )
        x = x + np.where(px > 0, left, 0.0)
        r0 = self._at(self.cond, corners, oc + W - 2, nc)
        r1 = self._at(self.cond, corners, oc + 2 * (W - 1) - 1, nc)
        with np.errstate(divide="ignore", invalid="ignore"):
            x = x / _lerp(r0, r1, ty)
        y = ty * _lerp(r0, r1, 0.5 * ty) / (H - 1)
        below = self._at(self.marg, corners, py - 1, nm)
        y = y + np.where(py > 0, below, 0.0)
        return np.stack([x, y], axis=-1), pdf

    def sample(self, s, params=()):
        """The forward warp: s (N, 2) ∈ [0, 1]² to u in the half vector's square, the exact
        inverse of ``invert`` (the readers' ``sample`` up to their shortcut for nearly
        constant patches)."""
        corners = self._weights(params)
        W, H = self.W, self.H
        nc, nm, nd = (W - 1) * H, H - 1, W * H
        s = np.clip(np.asarray(s, dtype=np.float64), 0.0, 1.0)
        sx, sy = s[..., 0], s[..., 1]
        row = _search(nm, lambda k: self._at(self.marg, corners, k, nm) < sy, sy.shape)
        sy = sy - np.where(row > 0, self._at(self.marg, corners, row - 1, nm), 0.0)
        oc = row * (W - 1)
        r0 = self._at(self.cond, corners, oc + W - 2, nc)
        r1 = self._at(self.cond, corners, oc + 2 * (W - 1) - 1, nc)
        ty = _segment(sy * (H - 1), r0, r1)
        sx = sx * _lerp(r0, r1, ty)

        def cdf_x(k):
            return _lerp(
                self._at(self.cond, corners, oc + k, nc),
                self._at(self.cond, corners, oc + (W - 1) + k, nc),
                ty,
            )

        col = np.minimum(_search(W - 1, lambda k: cdf_x(k) < sx, sx.shape), W - 2)
        sx = sx - np.where(col > 0, cdf_x(col - 1), 0.0)
        i = row * W + col
        v00, v10 = self._at(self.data, corners, i, nd), self._at(self.data, corners, i + 1, nd)
        v01 = self._at(self.data, corners, i + W, nd)
        v11 = self._at(self.data, corners, i + W + 1, nd)
        c0, c1 = _lerp(v00, v01, ty), _lerp(v10, v11, ty)
        tx = _segment(sx * (W - 1), c0, c1)
        u = np.stack([(col + tx) / (W - 1), (row + ty) / (H - 1)], axis=-1)
        return u, _lerp(c0, c1, tx)


def _search(n: int, below, shape) -> np.ndarray:
    """Smallest k ∈ [0, n − 1] with ``below(k)`` false (n − 1 if none), per point of
    ``shape``: bisection on a vectorised predicate monotone in k (Dr.Jit's ``binary_search``
    on [0, n − 1])."""
    lo = np.zeros(shape, dtype=np.intp)
    hi = np.full_like(lo, n - 1)
    for _ in range(int(np.ceil(np.log2(max(n, 2)))) + 1):
        mid = (lo + hi) >> 1
        go = below(mid)
        lo = np.where(go, np.minimum(mid + 1, hi), lo)
        hi = np.where(go, hi, mid)
    return lo


def _segment(a, v0, v1) -> np.ndarray:
    """t ∈ [0, 1] with ∫₀ᵗ lerp(v0, v1, τ) dτ = a (a in patch units): the stable root
    2a/(v0 + √(v0² + 2a(v1 − v0)))."""
    with np.errstate(divide="ignore", invalid="ignore"):
        t = 2.0 * a / (v0 + np.sqrt(np.maximum(v0 * v0 + 2.0 * a * (v1 - v0), 0.0)))
    return np.clip(np.where(np.isfinite(t), t, 0.0), 0.0, 1.0)
