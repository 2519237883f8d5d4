"""Empirical NDF: a histogram of measured facet normals (Mikkelsen 2009, eq. 14 and 17).

Mikkelsen 2009, eq. 17 defines the distribution of normals through the *projected* (macro-surface)
area: p(n) dn is the fraction of the macro area dA whose micro normal lies in dn, and
D(h) = p(h)/(h·n). So the weight of a facet is its projected area, facet area × n_z; on a
heightfield mesh every grid triangle has the same projected area and equal weights are exact.
With those weights D(h)(h·n) is the projected-area-weighted density of facet normals.

Binning (isotropic). Edges in θ_h are the weighted quantiles of the facet tilts, so every bin
holds the same weight (1/n_theta) and narrow lobes are resolved as finely as broad ones; any
quantile bin wider than ``max_bin_deg`` is split evenly, so the sparse tail is still resolved
in angle (bins beyond the largest tilt get D = 0: no facet is tilted that far). D is constant
per bin with ∫_bin D(h) h_z dω = π D Δ(sin²θ) = bin weight fraction, so ∫ D h_z dω = 1
exactly (up to rounding). Atoms (many identical tilts, e.g. a flat facet set) are smeared over
the bin that contains them.

Default bin counts (N facets): isotropic n_theta = clip(round(2 N^(1/3)), 4, 256) equal-weight
bins — 200 bins of 5000 facets (≈1.4 % noise) for N = 10⁶; anisotropic n_theta =
clip(round(N^(1/3)/2), 4, 128) and n_phi = 4 clip(round(N^(1/3)/16), 1, 32) uniform azimuth bins
(a multiple of 4 keeps the x and y axes on bin edges) — 50 × 24 cells of ≈ 830 facets for 10⁶.
"""

from __future__ import annotations

import numpy as np

from microsim import checks as _checks
from microsim import vectors
from microsim.errors import UsageError

from . import smith
from .ndf import NDF

__all__ = ["Empirical"]


def _default_n_theta(n_facets: int, isotropic: bool) -> int:
    cube = n_facets ** (1.0 / 3.0)
    if isotropic:
        return int(np.clip(round(2.0 * cube), 4, 256))
    return int(np.clip(round(cube / 2.0), 4, 128))


def _default_n_phi(n_facets: int) -> int:
    return 4 * int(np.clip(round(n_facets ** (1.0 / 3.0) / 16.0), 1, 32))


def _tilt(normals: np.ndarray) -> np.ndarray:
    """θ of unit vectors in radians, accurate near 0 (atan2 of the transverse length)."""
    return np.arctan2(np.hypot(normals[:, 0], normals[:, 1]), normals[:, 2])


def _quantile_edges(theta: np.ndarray, weights: np.ndarray, n_bins: int) -> np.ndarray:
    """Strictly increasing edges from 0 to π/2 at the weighted tilt quantiles k/n_bins.

    Each inner edge is the midpoint between the two sorted tilts on either side of the quantile,
    so no sample sits on an edge unless tilts are tied (ties collapse edges, which are dropped).
    """
    order = np.argsort(theta, kind="stable")
    ts = theta[order]
    cw = np.cumsum(weights[order])
    cw /= cw[-1]
    idx = np.searchsorted(cw, np.arange(1, n_bins) / n_bins, side="left")
    idx = np.clip(idx, 0, len(ts) - 1)
    inner = 0.5 * (ts[idx] + ts[np.minimum(idx + 1, len(ts) - 1)])
    edges = np.unique(np.concatenate([[0.0], inner, [0.5 * np.pi]]))
    return edges


def _split_wide(edges: np.ndarray, max_width: float) -> np.ndarray:
    """Split every bin wider than ``max_width`` into equal parts no wider than it."""
    widths = np.diff(edges)
    parts = np.maximum(1, np.ceil(widths / max_width - 1e-12)).astype(int)
    starts = np.repeat(edges[:-1], parts)
    steps = np.repeat(widths / parts, parts)
    offsets = np.arange(parts.sum()) - np.repeat(np.cumsum(parts) - parts, parts)
    return np.append(starts + offsets * steps, edges[-1])


class Empirical(NDF):
    """Histogram NDF from facet normals with projected-area weights (Mikkelsen 2009, eq. 14, 17).

    ``normals``: (N, 3) unit facet normals with n_z > 0. ``weights``: (N,) projected areas
    (facet area × n_z; None = equal, exact for heightfield triangles), ≥ 0 with a positive sum.
    ``n_theta``: number of equal-weight tilt bins; ``n_phi``: azimuth bins (anisotropic only);
    ``max_bin_deg``: widest allowed tilt bin in degrees. ``isotropic=False`` makes D depend on
    φ_h through (θ, φ) cells; ``D_cos`` then is the azimuthal average and ``D``/``sample`` use
    the cells. See the module docstring for the binning rule and default counts.
    """

    name = "empirical"

    def __init__(
        self,
        normals,
        weights=None,
        n_theta: int | None = None,
        n_phi: int | None = None,
        isotropic: bool = True,
        max_bin_deg: float = 2.0,
    ):
        nrm = _checks.directions("normals", normals)
        if nrm.ndim != 2 or nrm.shape[0] == 0:
            raise UsageError(f"normals must be a non-empty array of shape (N, 3), got {nrm.shape}")
        if np.any(nrm[:, 2] <= 0.0):
            raise UsageError(
                "normals must point into the upper hemisphere (n_z > 0); "
                f"got n_z down to {nrm[:, 2].min():.6g}"
            )
        n = nrm.shape[0]
        w = self._check_weights(weights, n)
        self.isotropic = bool(isotropic)
        n_theta = (
            _default_n_theta(n, self.isotropic)
            if n_theta is None
            else int(_checks.in_range("n_theta", n_theta, 1, 100000))
        )
        if self.isotropic:
            n_phi = 1
        else:
            n_phi = (
                _default_n_phi(n)
                if n_phi is None
                else int(_checks.in_range("n_phi", n_phi, 1, 100000))
            )
        max_width = np.radians(
            _checks.in_range("max_bin_deg", max_bin_deg, 0.0, 90.0, lo_open=True)
        )
        theta = _tilt(nrm)
        self.theta_edges = _split_wide(_quantile_edges(theta, w, n_theta), max_width)
        self.phi_edges = np.linspace(0.0, 2.0 * np.pi, n_phi + 1)
        phi = np.mod(np.arctan2(nrm[:, 1], nrm[:, 0]), 2.0 * np.pi)
        cells, _, _ = np.histogram2d(theta, phi, bins=[self.theta_edges, self.phi_edges], weights=w)
        self.cell_weights = cells / cells.sum()  # (n_theta_bins, n_phi) fractions
        self.bin_weights = self.cell_weights.sum(axis=1)  # tilt marginal
        self.q_edges = np.sin(self.theta_edges) ** 2  # sin²θ: the tilt CDF is linear in it
        dq = np.diff(self.q_edges)
        self.bin_D = self.bin_weights / (np.pi * dq)  # azimuthal average per tilt bin
        self.cell_D = self.cell_weights / (0.5 * np.diff(self.phi_edges)[None, :] * dq[:, None])
        self.cdf_edges = np.concatenate([[0.0], np.cumsum(self.bin_weights)])
        self.cdf_edges[-1] = 1.0
        self.n_facets = n
        self.total_weight = float(w.sum())
        self.mean_normal = vectors.normalize(np.sum(nrm * w[:, None], axis=0))
        self.max_tilt = float(theta.max())

    @staticmethod
    def _check_weights(weights, n: int) -> np.ndarray:
        if weights is None:
            return np.ones(n)
        w = np.asarray(weights, dtype=np.float64)
        if w.shape != (n,):
            raise UsageError(f"weights must have shape ({n},) like normals, got {w.shape}")
        if not np.all(np.isfinite(w)) or np.any(w < 0):
            raise UsageError("weights must be finite projected areas >= 0")
        if not w.sum() > 0:
            raise UsageError("weights must have a positive sum")
        return w

    # --- NDF interface --------------------------------------------------------------------
    def params(self) -> dict:
        return {
            "n_facets": self.n_facets,
            "n_theta_bins": len(self.bin_weights),
            "n_phi_bins": len(self.phi_edges) - 1,
            "isotropic": self.isotropic,
        }

    def __repr__(self) -> str:
        p = self.params()
        return (
            f"Empirical(<{p['n_facets']} facets>, bins={p['n_theta_bins']}x"
            f"{p['n_phi_bins']}, isotropic={p['isotropic']})"
        )

    def tilt_breakpoints_rad(self) -> np.ndarray:
        """Quadrature panels: D is constant between the bin edges."""
        return np.unique(np.concatenate([self.theta_edges, np.linspace(0, 0.5 * np.pi, 33)]))

    def _smith_lambda(self, w, method: str = "auto"):
        """Λ(w) for unit w: an anisotropic histogram's from its (θ_w, φ_w) table (``smith``)."""
        if self.isotropic:
            return super()._smith_lambda(w, method)
        self._check_lambda_method(method)
        return smith.numerical_lambda_w(self, w)

    def _bin_of_q(self, q) -> np.ndarray:
        k = np.searchsorted(self.q_edges, q, side="right") - 1
        return np.clip(k, 0, len(self.bin_D) - 1)

    def D_cos(self, cos_theta):
        """Piecewise-constant D(θ_h) in sr⁻¹ (azimuthal average if anisotropic); 0 for cos ≤ 0."""
        c = np.asarray(cos_theta, dtype=np.float64)
        q = (1.0 - c) * (1.0 + c)
        return np.where(c > 0.0, self.bin_D[self._bin_of_q(q)], 0.0)

    def D(self, h):
        """D(h) in sr⁻¹; depends on φ_h too when anisotropic; 0 below the horizon."""
        h = _checks.directions("h", h)
        if self.isotropic:
            return self.D_cos(h[..., 2])
        k = self._bin_of_q(h[..., 0] ** 2 + h[..., 1] ** 2)
        phi = np.mod(np.arctan2(h[..., 1], h[..., 0]), 2.0 * np.pi)
        j = np.clip(
            np.searchsorted(self.phi_edges, phi, side="right") - 1, 0, len(self.phi_edges) - 2
        )
        return np.where(h[..., 2] > 0.0, self.cell_D[k, j], 0.0)

    def _cdf_theta(self, theta):
        """P(θ_h ≤ θ), θ in radians; piecewise linear in sin²θ."""
        t = np.clip(np.asarray(theta, dtype=np.float64), 0.0, 0.5 * np.pi)
        q = np.sin(t) ** 2
        k = self._bin_of_q(q)
        dq = self.q_edges[k + 1] - self.q_edges[k]
        return np.minimum(self.cdf_edges[k] + self.bin_weights[k] * (q - self.q_edges[k]) / dq, 1.0)

    def _tilt_bin_and_fraction(self, u):
        """Tilt bin k holding cumulative probability u and the position in it, in [0, 1]."""
        u = np.clip(np.asarray(u, dtype=np.float64), 0.0, 1.0)
        last = np.flatnonzero(self.bin_weights > 0)[-1]
        k = np.clip(np.searchsorted(self.cdf_edges, u, side="right") - 1, 0, last)
        with np.errstate(divide="ignore", invalid="ignore"):
            frac = np.where(
                self.bin_weights[k] > 0, (u - self.cdf_edges[k]) / self.bin_weights[k], 0.0
            )
        return k, np.clip(frac, 0.0, 1.0)

    def tilt_quantile_rad(self, u):
        """θ_h in radians at cumulative probability u (exact inverse of ``cdf_theta_rad``)."""
        k, frac = self._tilt_bin_and_fraction(u)
        q = self.q_edges[k] + frac * (self.q_edges[k + 1] - self.q_edges[k])
        return np.arcsin(np.sqrt(np.clip(q, 0.0, 1.0)))

    def sample(self, u1, u2):
        """Unit h ~ D(h)h_z from uniforms u1 (tilt), u2 (azimuth; conditional on the tilt bin)."""
        _checks.broadcast({}, {"u1": u1, "u2": u2})
        u1, u2 = np.broadcast_arrays(np.asarray(u1, float), np.asarray(u2, float))
        if self.isotropic:
            return super().sample(u1, u2)
        k, frac = self._tilt_bin_and_fraction(u1)
        q = self.q_edges[k] + frac * (self.q_edges[k + 1] - self.q_edges[k])
        theta = np.arcsin(np.sqrt(np.clip(q, 0.0, 1.0)))
        n_phi = self.cell_weights.shape[1]
        flat_cdf = np.concatenate([[0.0], np.cumsum(self.cell_weights.ravel())])
        row_lo, row_w = flat_cdf[k * n_phi], self.bin_weights[k]
        target = row_lo + np.clip(u2, 0.0, 1.0) * row_w  # conditional on row k
        cell = np.searchsorted(flat_cdf, target, side="right") - 1
        cell = np.clip(cell, k * n_phi, k * n_phi + n_phi - 1)
        j = cell - k * n_phi
        cell_w = self.cell_weights.ravel()[cell]
        with np.errstate(divide="ignore", invalid="ignore"):
            t = np.where(cell_w > 0, (target - flat_cdf[cell]) / cell_w, 0.5)
        phi = self.phi_edges[j] + np.clip(t, 0.0, 1.0) * np.diff(self.phi_edges)[j]
        return vectors.spherical(theta, phi)
