"""The Student-t slope distribution ("STD", Ribardière et al. 2017): from GGX (γ = 2) to Beckmann
(γ → ∞), isotropic and anisotropic.

Slope law (Ribardière et al. 2017; the form below is re-derived here, not copied): with
k = (γ − 1) α²,

    P22(s) = (1 + |s|²/k)^−γ / (π α²),      D(h) = P22(s(h)) / cos⁴θ_h,

normalised as every microsim NDF (∫ D cos θ_h dω = 1; Mikkelsen 2009, eq. 14). It is the
bivariate Student-t with ν = 2γ − 2 degrees of freedom and scale σ = α/√2 per axis, i.e. a Gamma
scale mixture of Gaussians: given w ~ Gamma(γ − 1, 1) each slope axis is N(0, α²(γ − 1)/(2w))
(how NVlabs/facet-forge samples it). γ = 2 is GGX exactly; γ → ∞ tends to Beckmann(m = α).
The slope magnitude r = |s| has the CDF F(r) = 1 − (1 + r²/k)^−(γ−1) (the tilt CDF with
r = tan θ_h): GGX's r²/(α² + r²) at γ = 2. Only γ ≥ 2 is taken: below, D diverges at
grazing facets (D ∝ cos^{2γ−4} θ_h as θ_h → 90°), and Λ is infinite for γ ≤ 3/2.

Smith Λ (derived here from Λ(μ) = (1/μ)∫_μ^∞ (q − μ) P2(q) dq, Smith 1967, with P2 the 1-D
marginal, Student-t with ν dof and scale σ; μ = cot θ, a = μ/α):

    Λ = K (1 + a²/(γ − 1))^{3/2−γ} / a − T_ν(−a√2),
    K = Γ(γ − ½) √(γ − 1) / (Γ(γ − 1) √π (2γ − 3)),

T_ν the Student-t CDF (``scipy.special.stdtr``); the first term is ∫_μ^∞ q P2 dq / μ. At γ = 2:
K = ½ and Λ = (√(1 + 1/a²) − 1)/2, GGX's; γ → ∞ gives Beckmann's. tests/test_student_t.py checks
it against the projected-area identity integrated numerically (``smith``). Near grazing Λ cos θ →
K α (``horizon_area``: the projected area of the visible facets for a view at the horizon, per
unit macro area).

Visible normals (``sample_visible``, views on either side of the horizon, as Heitz & d'Eon 2014
do for Beckmann): in the frame stretched to unit roughness with the view v at polar angle θ and
azimuth 0, the visible slope x̃ along v has density ∝ (a − x̃)⁺ p1(x̃), a = cot θ (negative
below the horizon), p1 the unit-α marginal, with CDF

    F(x) = a T_ν(x√2) + K (1 + x²/(γ − 1))^{3/2−γ},  x ≤ a   (F(a) = a(1 + Λ) for a > 0),

inverted by safeguarded Newton with bisection in asinh x (the tails are algebraic). Given x̃ the
transverse slope is the conditional of the bivariate t: Student-t with ν + 1 dof and scale
√((ν/2 + x̃²)/(ν + 1)). γ = 2 uses GGX's closed-form sampler (Heitz 2018). The anisotropic
distribution stretches as ``anisotropic`` does.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import special

from microsim import checks as _checks

from .anisotropic import AnisotropicNDF
from .ndf import NDF, _cos_array, _ggx_visible, _sin2, _unit_interval, slope_space_visible

__all__ = ["StudentT", "AnisotropicStudentT", "student_t_lambda", "student_t_k"]

GAMMA_MAX = 1e6
"""Largest γ taken (beyond it the distribution is Beckmann to the last digits that matter)."""


def _check_gamma(gamma) -> float:
    return _checks.in_range("gamma", gamma, 2.0, GAMMA_MAX)


def student_t_k(gamma: float) -> float:
    """K(γ) = Γ(γ − ½) √(γ − 1) / (Γ(γ − 1) √π (2γ − 3)) (module docstring): ∫_x^∞ q p1(q) dq =
    K (1 + x²/(γ − 1))^{3/2−γ} for the unit-α 1-D slope marginal p1; ½ for GGX, → 1/(2√π)."""
    g = float(gamma)
    return float(
        np.exp(special.gammaln(g - 0.5) - special.gammaln(g - 1.0))
        * np.sqrt(g - 1.0)
        / (np.sqrt(np.pi) * (2.0 * g - 3.0))
    )


def _profile(rho2, gamma: float):
    """(1 + ρ²/(γ − 1))^−γ: the slope density at stretched radius² ρ² = |s|²/α², times π α²."""
    with np.errstate(over="ignore"):
        return np.exp(-gamma * np.log1p(rho2 / (gamma - 1.0)))


def _rho2_cdf(x, gamma: float):
    """P(ρ² ≤ x) = 1 − (1 + x/(γ − 1))^−(γ−1)."""
    with np.errstate(over="ignore"):
        return -np.expm1(-(gamma - 1.0) * np.log1p(x / (gamma - 1.0)))


def _rho2_quantile(u, gamma: float):
    """ρ² at cumulative probability u: (γ − 1) expm1(−ln(1 − u)/(γ − 1)); inf at u = 1."""
    with np.errstate(divide="ignore", over="ignore"):
        return (gamma - 1.0) * np.expm1(-np.log1p(-u) / (gamma - 1.0))


def student_t_lambda(cos_theta, alpha, gamma: float):
    """Smith Λ of the Student-t distribution at cos θ (array, clipped to [0, 1]) for roughness
    ``alpha`` (scalar or broadcasting array) and γ ≥ 2 (module docstring); 0 at the normal,
    +inf at the horizon."""
    c = np.clip(np.asarray(cos_theta, dtype=np.float64), 0.0, 1.0)
    nu = 2.0 * gamma - 2.0
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        a = c / (alpha * np.sqrt(_sin2(c)))  # inf at c = 1, 0 at c = 0
        lead = student_t_k(gamma) * np.exp((1.5 - gamma) * np.log1p(a * a / (gamma - 1.0))) / a
        lam = np.maximum(lead - special.stdtr(nu, -np.sqrt(2.0) * a), 0.0)
    return np.where(c == 1.0, 0.0, np.where(c == 0.0, np.inf, lam))


def _visible_cdf(a, x, gamma: float):
    """F(x) = a T_ν(x√2) + K (1 + x²/(γ − 1))^{3/2−γ} (module docstring) and its derivative
    (a − x) p1(x)."""
    nu = 2.0 * gamma - 2.0
    k = student_t_k(gamma)
    with np.errstate(over="ignore", divide="ignore"):
        tail = np.exp((1.5 - gamma) * np.log1p(x * x / (gamma - 1.0)))
        # p1(x) = (2γ − 3) K / (γ − 1) · (1 + x²/(γ − 1))^{1/2−γ}: the derivative of the tail term
        p1 = (2.0 * gamma - 3.0) * k / (gamma - 1.0) * tail / (1.0 + x * x / (gamma - 1.0))
    return a * special.stdtr(nu, np.sqrt(2.0) * x) + k * tail, (a - x) * p1


def _visible_slope_x(a, u, gamma: float):
    """x̃ ≤ a with F(x̃) = u F(a), vectorised: the bracket's lower end by doubling, then Newton
    steps kept inside the bracket (bisection in asinh x otherwise), to |Δx| ≤ 1e-12 (1 + |x|)."""
    target = u * _visible_cdf(a, a, gamma)[0]
    hi = a.copy()
    lo = np.minimum(a, 0.0) - 1.0
    for _ in range(2100):  # |lo| doubles: reaches 1e308 long before
        low = _visible_cdf(a, lo, gamma)[0] > target
        if not low.any():
            break
        lo = np.where(low, 2.0 * lo, lo)
    x = 0.5 * (lo + hi)
    act = np.arange(len(a))
    for _ in range(300):
        xa, aa = x[act], a[act]
        f, df = _visible_cdf(aa, xa, gamma)
        g = f - target[act]
        lo_a = np.where(g < 0, xa, lo[act])
        hi_a = np.where(g > 0, xa, hi[act])
        with np.errstate(divide="ignore", invalid="ignore"):
            x_new = xa - g / df
        bad = ~np.isfinite(x_new) | (x_new <= lo_a) | (x_new >= hi_a)
        mid = np.sinh(0.5 * (np.arcsinh(lo_a) + np.arcsinh(hi_a)))
        x_next = np.where(g == 0, xa, np.where(bad, mid, x_new))
        lo[act], hi[act], x[act] = lo_a, hi_a, x_next
        done = (g == 0) | (np.abs(x_next - xa) <= 1e-12 * (1.0 + np.abs(xa)))
        done |= hi_a - lo_a <= 1e-15 * (1.0 + np.abs(hi_a))
        act = act[~done]
        if len(act) == 0:
            break
    return np.minimum(x, a)


def _student_t_visible(v, alpha: float, gamma: float, u1, u2):
    """Visible normals of the isotropic Student-t distribution (module docstring)."""
    nu = 2.0 * gamma - 2.0

    def slopes(a, u1, u2):
        x = _visible_slope_x(a, u1, gamma)
        return x, special.stdtrit(nu + 1.0, u2) * np.sqrt((0.5 * nu + x * x) / (nu + 1.0))

    return slope_space_visible(v, alpha, u1, u2, slopes)


@dataclass(frozen=True, repr=False)
class StudentT(NDF):
    """Student-t slope distribution (module docstring): roughness ``alpha`` > 0, tail ``gamma``
    ≥ 2 (2: GGX; large: Beckmann(m = α)). D = (1 + tan²θ/k)^−γ / (π α² cos⁴θ), k = (γ − 1)α²."""

    alpha: float
    gamma: float
    name = "student-t"
    has_closed_smith = True
    has_visible_sampler = True
    scene_params = {"alpha": (1e-6, 10.0), "gamma": (2.0, GAMMA_MAX)}

    def __post_init__(self):
        object.__setattr__(self, "alpha", _checks.positive("alpha", self.alpha))
        object.__setattr__(self, "gamma", _check_gamma(self.gamma))

    def params(self) -> dict:
        return {"alpha": self.alpha, "gamma": self.gamma}

    @property
    def horizon_area(self) -> float:
        """lim Λ(θ) cos θ as θ → 90°: K(γ) α (GGX α/2, Beckmann α/(2√π))."""
        return student_t_k(self.gamma) * self.alpha

    def D_cos(self, cos_theta):
        """D(cos θ) in sr⁻¹, as c^{2γ−4} (c² + s²/k)^−γ / (π α²) in logarithms (finite at both
        ends, and for large γ); 0 for c ≤ 0."""
        c = np.minimum(_cos_array(cos_theta), 1.0)
        cs = np.where(c > 0.0, c, 1.0)
        s2 = _sin2(cs)
        k = (self.gamma - 1.0) * self.alpha**2
        with np.errstate(over="ignore", divide="ignore"):
            power = 0.0 if self.gamma == 2.0 else (2.0 * self.gamma - 4.0) * np.log(cs)
            d = np.exp(power - self.gamma * np.log1p(s2 * (1.0 / k - 1.0)))
        return np.where(c > 0.0, d / (np.pi * self.alpha**2), 0.0)

    def _cdf_theta(self, theta):
        """P(θ_h ≤ θ) = 1 − (1 + tan²θ/k)^−(γ−1)."""
        t = np.clip(np.asarray(theta, dtype=np.float64), 0.0, 0.5 * np.pi)
        return _rho2_cdf((np.tan(t) / self.alpha) ** 2, self.gamma)

    def tilt_quantile_rad(self, u):
        """θ_h with tan²θ = α² ρ²(u) (``_rho2_quantile``); u = 1 gives π/2."""
        rho2 = _rho2_quantile(_unit_interval(u), self.gamma)
        with np.errstate(invalid="ignore"):
            return np.where(np.isinf(rho2), 0.5 * np.pi, np.arctan(self.alpha * np.sqrt(rho2)))

    def smith_lambda_cos(self, cos_theta):
        """Smith Λ (module docstring), cos θ in [0, 1]."""
        return student_t_lambda(_cos_array(cos_theta), self.alpha, self.gamma)

    def _sample_visible(self, v, u1, u2):
        """GGX's closed form at γ = 2, else the visible-slope inversion (module docstring)."""
        if self.gamma == 2.0:
            return _ggx_visible(v, self.alpha, u1, u2)
        return _student_t_visible(v, self.alpha, self.gamma, u1, u2)


@dataclass(frozen=True, repr=False)
class AnisotropicStudentT(AnisotropicNDF):
    """Anisotropic Student-t distribution: ``alpha_x``, ``alpha_y`` > 0 along its axes turned by
    ``rotation`` degrees, tail ``gamma`` ≥ 2; the unit isotropic one stretched (``anisotropic``
    module docstring: Λ at the projected roughness is exact for any stretched family). Equals
    ``StudentT(α, γ)`` when αx = αy = α."""

    alpha_x: float
    alpha_y: float
    gamma: float
    rotation: float = 0.0
    name = "student-t-anisotropic"

    def __post_init__(self):
        self._check()
        object.__setattr__(self, "gamma", _check_gamma(self.gamma))

    def params(self) -> dict:
        return {**super().params(), "gamma": self.gamma}

    def _profile(self, rho2):
        return _profile(rho2, self.gamma)

    def _rho2_cdf(self, x):
        return _rho2_cdf(x, self.gamma)

    def _rho_quantile(self, u):
        return np.sqrt(_rho2_quantile(u, self.gamma))

    def _lambda(self, cos_w, alpha):
        return student_t_lambda(cos_w, alpha, self.gamma)

    def isotropic_at(self, alpha):
        """The isotropic Student-t distribution of roughness ``alpha`` and this γ."""
        return StudentT(alpha, self.gamma)
