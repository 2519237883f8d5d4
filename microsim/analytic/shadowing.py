"""Smith shadowing–masking G (Smith 1967; Heitz 2014; docs/design.md, "Shadowing and Fresnel");
the V-groove G (Mikkelsen 2009, eq. 25) and the ``shadowing``-string functions are in ``masking``.

Directions are unit (..., 3) arrays pointing away from the surface, macro normal n = +z; every
function takes its directions first, ``(wi, wo, h, ...)`` or ``(w, h, ...)``, then the NDF.
Every G here is dimensionless in [0, 1], finite everywhere (also h = n and θ = 90°), and 0 for
a direction at or below the horizon (the macro surface itself blocks it) or on the back of the
facet (χ⁺(w·h) = 0).

Both families satisfy the projected-area identity ∫ G1(w, h)(w·h)⁺ D(h) dω_h = cos θ_w: Smith by
construction of Λ, the V-groove because a groove pairs h with its mirror image (−h_x, −h_y, h_z)
and for such a pair min(w·h, 2h_z w_z)⁺ + min(w·h', 2h_z w_z)⁺ = 2 h_z w_z (w·h + w·h' = 2h_z w_z),
so the identity holds for every centrally symmetric D, in particular every isotropic one.

Smith Λ without a closed form is integrated numerically (projected-area identity):
    Λ(w) cos θ_w = ∫ [(w·h)⁺ − w·h] D(h) dω_h,
which has no cancellation. For isotropic D the φ_h integral is analytic (``_azimuthal_excess``)
and ln(Λ cos θ_w) is tabulated once per NDF (cached, weakly keyed by the NDF) on 961 nodes
uniform in ln cot θ_w, each by a 1D Gauss–Legendre quadrature over θ_h on panels placed at the
NDF's tilt quantiles (so narrow lobes are resolved), at the edges of an Empirical's bins, and
geometrically towards the kink at θ_h = 90° − θ_w (quadrature error ~1e-13). The table is
interpolated by PCHIP: relative error of Λ ≲ 6e-5 wherever Λ > 1e-30, checked against the
Beckmann and GGX closed forms in tests/test_shadowing.py. Anisotropic Empirical NDFs are
integrated in 2D over their (θ, φ) cells into a (θ_w, φ_w) table interpolated bilinearly;
G1 = 1/(1 + Λ) is accurate to 1e-4 there (tests/test_shadowing.py).
"""

from __future__ import annotations

import weakref

import numpy as np

from microsim import checks as _checks
from microsim import vectors
from microsim.errors import UsageError

__all__ = ["smith_lambda", "smith_g1", "smith_g2"]

_GL_X, _GL_W = np.polynomial.legendre.leggauss(8)
_TABLES: "weakref.WeakKeyDictionary" = weakref.WeakKeyDictionary()


# --- numerical Smith Λ ------------------------------------------------------------------------
def _azimuthal_excess(sin_w, cos_w, sin_h, cos_h):
    """∫₀^{2π} [(a cos φ + b)⁺ − (a cos φ + b)] dφ = 2[√(a²−b²) − b arccos(b/a)] for a > b ≥ 0,
    else 0; a = sinθ_w sinθ_h, b = cosθ_w cosθ_h (the closed-form φ_h integral of Λ)."""
    a = sin_w * sin_h
    b = cos_w * cos_h
    over = a > b
    with np.errstate(divide="ignore", invalid="ignore"):
        val = 2.0 * (np.sqrt(np.maximum(a * a - b * b, 0.0)) - b * np.arccos(np.clip(b / a, -1, 1)))
    return np.where(over, np.maximum(val, 0.0), 0.0)


def _tilt_breakpoints(ndf) -> np.ndarray:
    """θ_h (radians) that split [0, π/2] into panels on which D is smooth and well resolved."""
    edges = getattr(ndf, "theta_edges", None)
    if edges is not None:  # Empirical: D is constant between its bin edges
        return np.unique(np.concatenate([edges, np.linspace(0, 0.5 * np.pi, 33)]))
    u = np.concatenate(
        [np.linspace(0.0, 1.0, 65)[1:-1], np.logspace(-10, -2, 9), 1.0 - np.logspace(-10, -2, 9)]
    )
    q = np.asarray(ndf.tilt_quantile_rad(u), dtype=np.float64)
    return np.unique(np.concatenate([q[np.isfinite(q)], np.linspace(0, 0.5 * np.pi, 33)]))


def _lambda_cos_product(ndf, cos_w: np.ndarray) -> np.ndarray:
    """Λ(θ_w) cos θ_w = ∫ D(θ_h) sinθ_h · excess(θ_w, θ_h) dθ_h by panel Gauss–Legendre."""
    cos_w = np.asarray(cos_w, dtype=np.float64)
    sin_w = np.sqrt((1.0 - cos_w) * (1.0 + cos_w))
    lo = np.arcsin(np.clip(cos_w, 0.0, 1.0))  # excess = 0 for θ_h < 90° − θ_w
    half_pi = 0.5 * np.pi
    span = (half_pi - lo)[:, None]
    refine = lo[:, None] + span * 4.0 ** -np.arange(1, 14)[None, :]
    master = np.clip(_tilt_breakpoints(ndf)[None, :], lo[:, None], half_pi)
    edges = np.sort(
        np.concatenate([lo[:, None], refine, master, np.full_like(lo[:, None], half_pi)], axis=1),
        axis=1,
    )
    a, b = edges[:, :-1, None], edges[:, 1:, None]
    t = 0.5 * (a + b) + 0.5 * (b - a) * _GL_X  # (n_w, n_panels, n_gl)
    wt = 0.5 * (b - a) * _GL_W
    f = (
        ndf.D_cos(np.cos(t))
        * np.sin(t)
        * _azimuthal_excess(sin_w[:, None, None], cos_w[:, None, None], np.sin(t), np.cos(t))
    )
    return np.sum(f * wt, axis=(1, 2))


class _IsotropicLambdaTable:
    """PCHIP table of ln(Λ cos θ_w) against v = ln(cot θ_w) for one isotropic NDF.

    In these variables Beckmann's ln Λ is nearly quadratic and GGX's nearly linear, so the
    relative error of Λ is uniform (≲ 6e-5 for Λ > 1e-30). Near the horizon (v < −12, θ_w
    within 6e-6 rad of 90°) the value at v = −12 is used (Λ cos θ_w changes by O(cos θ_w) there);
    towards the normal (v > 12) ln(Λ cos θ_w) is extrapolated linearly in v with slope ≤ −2
    (Λ ∝ tan²θ_w at least, for any D bounded at 90°), so Λ(θ_w = 0) = 0 exactly.
    """

    V_MAX, FLOOR = 12.0, 1e-300

    def __init__(self, ndf):
        v = np.linspace(-self.V_MAX, self.V_MAX, 961)
        c = 1.0 / np.sqrt(1.0 + np.exp(-2.0 * v))
        y = np.concatenate([_lambda_cos_product(ndf, chunk) for chunk in np.array_split(c, 8)])
        ln_y = np.log(np.maximum(y, self.FLOOR))
        self._v0, self._dv = v[0], v[1] - v[0]
        from scipy.interpolate import PchipInterpolator  # imported when a table is built

        self._coef = PchipInterpolator(v, ln_y).c  # (4, n − 1) cubic per interval
        self._end, self._slope = ln_y[-1], min((ln_y[-1] - ln_y[-2]) / self._dv, -2.0)

    def _ln_y(self, v):
        """PCHIP value at v ∈ [−V_MAX, V_MAX], indexing the uniform grid directly."""
        k = np.clip(((v - self._v0) / self._dv).astype(np.intp), 0, self._coef.shape[1] - 1)
        t = v - (self._v0 + k * self._dv)
        c = self._coef
        return ((c[0, k] * t + c[1, k]) * t + c[2, k]) * t + c[3, k]

    def lambda_cos(self, cos_w):
        c = np.clip(np.asarray(cos_w, dtype=np.float64), 0.0, 1.0)
        with np.errstate(divide="ignore", invalid="ignore"):
            v = np.log(c) - 0.5 * np.log1p(-c * c)
            ln_y = np.where(
                v > self.V_MAX,
                self._end + self._slope * (v - self.V_MAX),
                self._ln_y(np.clip(v, -self.V_MAX, self.V_MAX)),
            )
            y = np.exp(ln_y)
            y = np.where(y > 1e3 * self.FLOOR, y, 0.0)
            return np.where(c > 0.0, y / c, np.inf)


class _AnisotropicLambdaTable:
    """Bilinear (θ_w, φ_w) table of Λ for an anisotropic Empirical NDF.

    Λ cos θ_w = ∫ (w·h)⁻ D dω + w·m − cos θ_w with m = ∫ h D dω exact per cell (m_z = 1), so
    only the negative part (w·h)⁻ = max(−w·h, 0) is integrated numerically (4 Gauss × 6
    midpoint points per cell); it lives where the cells cross the plane ⟂ w. Nodes: θ_w every
    1° plus 0.25° steps above 80°, φ_w every 7.5°. Λ is clamped at ≥ 0 (a sample whose mean
    normal is not exactly n could make it slightly negative).
    """

    N_GL, N_PHI_SUB = 4, 6

    def __init__(self, ndf):
        gx, gw = np.polynomial.legendre.leggauss(self.N_GL)
        ta, tb = ndf.theta_edges[:-1, None], ndf.theta_edges[1:, None]
        theta = 0.5 * (ta + tb) + 0.5 * (tb - ta) * gx  # (n_t, N_GL)
        wtheta = 0.5 * (tb - ta) * gw * np.sin(theta)
        pa, pb = ndf.phi_edges[:-1, None], ndf.phi_edges[1:, None]
        sub = (np.arange(self.N_PHI_SUB) + 0.5) / self.N_PHI_SUB
        phi = pa + (pb - pa) * sub  # (n_p, N_SUB)
        wphi = (pb - pa) / self.N_PHI_SUB * np.ones_like(sub)
        h = vectors.spherical(theta[:, :, None, None], phi[None, None, :, :]).reshape(-1, 3)
        weight = (
            ndf.cell_D[:, None, :, None] * wtheta[:, :, None, None] * wphi[None, None, :, :]
        ).reshape(-1)
        keep = weight > 0
        self._h, self._weight = h[keep], weight[keep]
        # exact transverse mean normal: ∫ sin²θ dθ ∫ (cos φ, sin φ) dφ per cell
        te, pe = ndf.theta_edges, ndf.phi_edges
        s2 = np.diff(te / 2 - np.sin(2 * te) / 4)[:, None]
        self._mx = np.sum(ndf.cell_D * s2 * np.diff(np.sin(pe))[None, :])
        self._my = np.sum(ndf.cell_D * s2 * -np.diff(np.cos(pe))[None, :])
        self.theta_nodes = np.radians(
            np.unique(np.concatenate([np.arange(0.0, 80.0, 1.0), np.arange(80.0, 90.01, 0.25)]))
        )
        self.phi_nodes = np.radians(np.arange(0.0, 360.1, 7.5))
        t, p = np.meshgrid(self.theta_nodes, self.phi_nodes, indexing="ij")
        self.y = np.maximum(self.direct(vectors.spherical(t, p)), 0.0)  # Λ cos θ_w

    def direct(self, w):
        """Λ cos θ_w by the cell quadrature at unit directions w (..., 3), no table."""
        flat = w.reshape(-1, 3)
        neg = np.concatenate(
            [
                np.maximum(-(blk @ self._h.T), 0.0) @ self._weight
                for blk in np.array_split(flat, max(1, len(flat) // 256))
            ]
        )
        return (neg + flat[:, 0] * self._mx + flat[:, 1] * self._my).reshape(w.shape[:-1])

    def lambda_w(self, w):
        c = np.clip(w[..., 2], 0.0, 1.0)
        theta = np.arccos(c)
        phi = np.mod(np.arctan2(w[..., 1], w[..., 0]), 2.0 * np.pi)
        tn, pn = self.theta_nodes, self.phi_nodes
        i = np.clip(np.searchsorted(tn, theta, side="right") - 1, 0, len(tn) - 2)
        j = np.clip(np.searchsorted(pn, phi, side="right") - 1, 0, len(pn) - 2)
        a = (theta - tn[i]) / (tn[i + 1] - tn[i])
        b = (phi - pn[j]) / (pn[j + 1] - pn[j])
        y = (
            (1 - a) * (1 - b) * self.y[i, j]
            + a * (1 - b) * self.y[i + 1, j]
            + (1 - a) * b * self.y[i, j + 1]
            + a * b * self.y[i + 1, j + 1]
        )
        with np.errstate(divide="ignore", invalid="ignore"):
            return np.where(c > 0.0, y / c, np.inf)


def _table(ndf, kind):
    """The cached numerical-Λ table of ``ndf`` (built on first use; weakly keyed by the NDF)."""
    tables = _TABLES.setdefault(ndf, {})
    if kind not in tables:
        tables[kind] = kind(ndf)
    return tables[kind]


def _lambda(ndf, w: np.ndarray, method: str = "auto") -> np.ndarray:
    """Smith Λ(w) for unit w (no validation); inf at cos θ_w ≤ 0."""
    if method not in ("auto", "closed", "numerical"):
        raise UsageError(f"method must be one of 'auto', 'closed', 'numerical', got {method!r}")
    c = w[..., 2]
    if hasattr(ndf, "smith_lambda_w") and method != "numerical":  # anisotropic, closed form
        return np.where(c > 0.0, ndf.smith_lambda_w(w), np.inf)
    if not getattr(ndf, "isotropic", True):
        return _table(ndf, _AnisotropicLambdaTable).lambda_w(w)
    closed = getattr(ndf, "has_closed_smith", False)
    if method == "closed" and not closed:
        raise UsageError(
            f"method='closed' needs an NDF with a closed-form Smith Λ; "
            f"{type(ndf).__name__} has none (use 'auto' or 'numerical')"
        )
    if closed and method != "numerical":
        pos = c > 0.0
        lam = np.full(c.shape, np.inf)
        lam[pos] = ndf.smith_lambda_cos(c[pos])
        return lam
    return _table(ndf, _IsotropicLambdaTable).lambda_cos(c)


def smith_lambda(w, ndf, method: str = "auto"):
    """Smith Λ(w) (dimensionless, ≥ 0; inf at θ_w = 90°) for upper-hemisphere unit w.

    ``method``: "auto" (closed form when ``ndf.has_closed_smith``, else numerical), "closed",
    or "numerical" (projected-area identity, see the module docstring; forced even when a
    closed form exists, for checking it).
    """
    w = _checks.directions("w", w, upper=True)
    return _lambda(ndf, w, method)


def _g1_from_lambda(lam, w_dot_h, cos_w):
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where((w_dot_h > 0.0) & (cos_w > 0.0), 1.0 / (1.0 + lam), 0.0)


def smith_g1(w, h, ndf):
    """Smith masking G1(w, h) = χ⁺(w·h)/(1 + Λ(w)) (Smith 1967; Heitz 2014; docs/design.md,
    "Shadowing and Fresnel")."""
    w = _checks.directions("w", w)
    h = _checks.directions("h", h)
    _checks.broadcast({"w": w, "h": h})
    return _g1_from_lambda(_lambda(ndf, w), vectors.dot(w, h), w[..., 2])


def _smith_g2(ndf, wi, wo, wih, woh, correlated: bool):
    lam_i, lam_o = _lambda(ndf, wi), _lambda(ndf, wo)
    if correlated:
        ok = (wih > 0.0) & (woh > 0.0) & (wi[..., 2] > 0.0) & (wo[..., 2] > 0.0)
        with np.errstate(invalid="ignore"):
            return np.where(ok, 1.0 / (1.0 + lam_i + lam_o), 0.0)
    return _g1_from_lambda(lam_i, wih, wi[..., 2]) * _g1_from_lambda(lam_o, woh, wo[..., 2])


def smith_g2(wi, wo, h, ndf, correlated: bool = False):
    """Smith shadowing–masking: separable G1(wi)G1(wo), or height-correlated
    χ⁺(wi·h)χ⁺(wo·h)/(1 + Λ(wi) + Λ(wo)) when ``correlated``."""
    wi = _checks.directions("wi", wi)
    wo = _checks.directions("wo", wo)
    h = _checks.directions("h", h)
    _checks.broadcast({"wi": wi, "wo": wo, "h": h})
    return _smith_g2(ndf, wi, wo, vectors.dot(wi, h), vectors.dot(wo, h), correlated)
