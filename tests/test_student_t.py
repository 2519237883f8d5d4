"""The Student-t slope distribution (``analytic.student_t``): its slope law is the Gamma scale
mixture of Gaussians it claims, γ = 2 is GGX and large γ Beckmann, its Smith Λ equals the
numerical integral of the slope marginal, and its samplers (normals, visible normals above and
below the horizon, anisotropic) draw the densities they state."""

import numpy as np
import pytest
from scipy import integrate, stats

from microsim import analytic as an
from microsim.analytic.student_t import student_t_k, student_t_lambda
from microsim.errors import UsageError
from microsim.stats import sidak
from microsim.testing import assert_sampler_matches
from microsim.vectors import spherical_deg

ALPHA = 0.01


@pytest.mark.parametrize("gamma", [2.0, 2.5, 3.0, 5.0, 20.0])
def test_smith_lambda_is_the_integral_of_the_slope_marginal(gamma):
    """Λ(μ) = (1/μ)∫_μ^∞ (q − μ) P2(q) dq (Smith 1967) with P2 the Student-t marginal of
    ν = 2γ − 2 dof and scale α/√2, integrated by quadrature to 1e-13: the closed form holds to
    rounding; and microsim's projected-area integration (``method="numerical"``) agrees (to
    its absolute accuracy where Λ is tiny)."""
    alpha = 0.3
    nu, scale = 2.0 * gamma - 2.0, alpha / np.sqrt(2.0)
    ndf = an.StudentT(alpha, gamma)
    thetas = np.radians([5.0, 30.0, 60.0, 80.0, 89.0])
    for th in thetas:
        mu = 1.0 / np.tan(th)
        integral = integrate.quad(
            lambda q: (q - mu) * stats.t.pdf(q / scale, nu) / scale,
            mu,
            np.inf,
            epsabs=0.0,
            epsrel=1e-13,
            limit=500,
        )[0]
        assert student_t_lambda(np.cos(th), alpha, gamma) == pytest.approx(integral / mu, rel=1e-9)
    w = spherical_deg(np.degrees(thetas), np.zeros(len(thetas)))
    np.testing.assert_allclose(
        ndf.smith_lambda(w, "closed"), ndf.smith_lambda(w, "numerical"), rtol=1e-6, atol=1e-12
    )


def test_gamma_two_is_ggx():
    c = np.linspace(0.0, 1.0, 41)
    st, ggx = an.StudentT(0.25, 2.0), an.GGX(0.25)
    np.testing.assert_allclose(st.D_cos(c), ggx.D_cos(c), rtol=1e-13)
    np.testing.assert_allclose(st.smith_lambda_cos(c), ggx.smith_lambda_cos(c), rtol=1e-12)
    u = np.linspace(0.0, 1.0, 11)
    np.testing.assert_allclose(st.tilt_quantile_rad(u), ggx.tilt_quantile_rad(u), rtol=1e-13)
    assert student_t_k(2.0) == pytest.approx(0.5, rel=1e-15)
    assert st.horizon_area == pytest.approx(ggx.horizon_area, rel=1e-15)


def test_large_gamma_tends_to_beckmann():
    """(1 + ρ²/γ')^−γ → e^{−ρ²} with relative error ≈ ρ⁴/(2γ): at γ = 1e6 and ρ² ≤ 4 below 1e-5."""
    st, beck = an.StudentT(0.3, 1e6), an.Beckmann(0.3)
    theta = np.arctan(0.3 * np.sqrt(np.linspace(0.0, 4.0, 9)))
    np.testing.assert_allclose(st.D_cos(np.cos(theta)), beck.D_cos(np.cos(theta)), rtol=1e-5)
    c = np.cos(np.radians([10.0, 45.0, 70.0, 85.0]))
    # (relative where Λ matters: G = 1/(1 + Λ) sees an absolute error)
    np.testing.assert_allclose(
        st.smith_lambda_cos(c), beck.smith_lambda_cos(c), rtol=1e-4, atol=1e-12
    )
    assert st.horizon_area == pytest.approx(beck.horizon_area, rel=1e-5)


@pytest.mark.parametrize("gamma", [2.0, 3.0, 5.0])
def test_tilt_law_is_the_gamma_mixture_of_gaussians(gamma):
    """Slopes drawn as the Gamma(γ − 1) scale mixture of Gaussians (per-axis variance
    α²(γ − 1)/(2w)) have |s| distributed as the tilt CDF says (KS, level 0.01 over the three
    cases); and the tilt density integrates to 1 with the quantile inverting the CDF."""
    alpha = 0.3
    ndf = an.StudentT(alpha, gamma)
    rng = np.random.default_rng(int(gamma * 10))
    w = rng.gamma(gamma - 1.0, size=200_000)
    s = rng.standard_normal((2, w.size)) * alpha * np.sqrt((gamma - 1.0) / (2.0 * w))
    r = np.hypot(*s)
    p = stats.kstest(r, lambda x: ndf.cdf_theta_rad(np.arctan(x))).pvalue
    assert p > sidak(ALPHA, 3)
    total = integrate.quad(ndf.tilt_pdf_rad, 0.0, 0.5 * np.pi, limit=200)[0]
    assert total == pytest.approx(1.0, abs=1e-9)
    u = np.array([1e-6, 0.1, 0.5, 0.9, 0.999])
    np.testing.assert_allclose(ndf.cdf_theta_rad(ndf.tilt_quantile_rad(u)), u, rtol=1e-10)


@pytest.mark.parametrize("gamma", [3.0, 5.0])
@pytest.mark.parametrize("theta", [20.0, 75.0])
def test_visible_normals_follow_their_density(gamma, theta):
    """Pearson χ² (``assert_sampler_matches``, Šidák over the 4 cases) of 10⁵ visible normals
    against D_v(m) = ⟨v, m⟩⁺ D(m)/((1 + Λ(v)) cos θ_v)."""
    ndf = an.StudentT(0.4, gamma)
    v = spherical_deg(theta, 30.0)

    def sample(u1, u2):
        return ndf.sample_visible(np.broadcast_to(v, (len(u1), 3)), u1, u2)

    def pdf(m):
        return np.where(m[:, 2] > 0, ndf.pdf_visible(m, np.broadcast_to(v, m.shape)), 0.0)

    assert_sampler_matches(sample, pdf, n=100_000, n_tests=4)


def test_the_sampler_detects_a_wrong_visible_density():
    """The same χ² rejects the visible normals of γ = 3 against the γ = 5 density."""
    v = spherical_deg(60.0, 0.0)
    drawn, stated = an.StudentT(0.4, 3.0), an.StudentT(0.4, 5.0)
    with pytest.raises(AssertionError):
        assert_sampler_matches(
            lambda u1, u2: drawn.sample_visible(np.broadcast_to(v, (len(u1), 3)), u1, u2),
            lambda m: np.where(
                m[:, 2] > 0, stated.pdf_visible(m, np.broadcast_to(v, m.shape)), 0.0
            ),
            n=100_000,
        )


@pytest.mark.parametrize("theta, phi", [(30.0, 10.0), (70.0, 100.0)])
def test_anisotropic_visible_normals_follow_their_density(theta, phi):
    ndf = an.AnisotropicStudentT(0.15, 0.4, 3.0, 25.0)
    v = spherical_deg(theta, phi)

    def sample(u1, u2):
        return ndf.sample_visible(np.broadcast_to(v, (len(u1), 3)), u1, u2)

    def pdf(m):
        return np.where(m[:, 2] > 0, ndf.pdf_visible(m, np.broadcast_to(v, m.shape)), 0.0)

    assert_sampler_matches(sample, pdf, n=100_000, n_tests=2)


@pytest.mark.parametrize(
    "bad, name",
    [({"alpha": 0.3, "gamma": 1.9}, "gamma"), ({"alpha": -1.0, "gamma": 3.0}, "alpha")],
)
def test_bad_parameters_name_themselves(bad, name):
    with pytest.raises(UsageError, match=name):
        an.StudentT(**bad)
