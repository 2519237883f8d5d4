"""Anisotropic Beckmann and GGX (``analytic.anisotropic``) from first principles: normalisation,
the isotropic limit, rotation, the exact Smith Λ against the projected-area identity, the
sampler against its pdf, and the isotropic stand-in renderers use (MaterialX) against the
figures it is known for."""

import numpy as np
import pytest

from microsim import analytic as an
from microsim.vectors import spherical, spherical_deg

CASES = [
    (an.AnisotropicBeckmann, 0.1, 0.8, 0.0),
    (an.AnisotropicBeckmann, 0.3, 0.15, 35.0),
    (an.AnisotropicGGX, 0.1, 0.8, 0.0),
    (an.AnisotropicGGX, 0.4, 0.2, -60.0),
]
IDS = [f"{c.__name__}-{ax}-{ay}-{r}" for c, ax, ay, r in CASES]


def _hemisphere(n_theta=600, n_phi=720):
    """Midpoint nodes of the upper hemisphere in (θ, φ) with dω weights (tilt grid graded
    towards the normal, where narrow lobes live)."""
    u = (np.arange(n_theta) + 0.5) / n_theta
    theta = 0.5 * np.pi * u**2
    dtheta = 0.5 * np.pi * 2 * u / n_theta
    phi = (np.arange(n_phi) + 0.5) * 2 * np.pi / n_phi
    t, p = np.meshgrid(theta, phi, indexing="ij")
    h = spherical(t, p)
    dw = np.sin(t) * dtheta[:, None] * (2 * np.pi / n_phi)
    return h, dw


H, DW = _hemisphere()


@pytest.mark.parametrize("cls, ax, ay, rot", CASES, ids=IDS)
def test_normalised_as_every_ndf(cls, ax, ay, rot):
    ndf = cls(ax, ay, rot)
    total = np.sum(ndf.D(H) * H[..., 2] * DW)
    assert total == pytest.approx(1.0, abs=2e-3)  # midpoint rule on 600 × 720 nodes


@pytest.mark.parametrize("cls, iso", [(an.AnisotropicBeckmann, an.Beckmann),
                                      (an.AnisotropicGGX, an.GGX)])  # fmt: skip
def test_equal_roughness_is_the_isotropic_ndf(cls, iso):
    rng = np.random.default_rng(1)
    h = spherical(rng.uniform(0, 1.5, 500), rng.uniform(0, 2 * np.pi, 500))
    w = spherical(rng.uniform(0, 1.55, 500), rng.uniform(0, 2 * np.pi, 500))
    a, b = cls(0.37, 0.37, 23.0), iso(0.37)
    np.testing.assert_allclose(a.D(h), b.D(h), rtol=1e-12, atol=1e-300)  # subnormal tails
    np.testing.assert_allclose(an.smith_lambda(w, a), an.smith_lambda(w, b), rtol=1e-12)


@pytest.mark.parametrize("cls", [an.AnisotropicBeckmann, an.AnisotropicGGX])
def test_rotation_turns_the_distribution_with_it(cls):
    rng = np.random.default_rng(2)
    t, p = rng.uniform(0, 1.4, 300), rng.uniform(0, 2 * np.pi, 300)
    a, b = cls(0.2, 0.6, 0.0), cls(0.2, 0.6, 40.0)
    np.testing.assert_allclose(b.D(spherical(t, p + np.radians(40))), a.D(spherical(t, p)),
                               rtol=1e-12)  # fmt: skip
    np.testing.assert_allclose(
        an.smith_lambda(spherical(t, p + np.radians(40)), b),
        an.smith_lambda(spherical(t, p), a),
        rtol=1e-12,
    )


@pytest.mark.parametrize("cls, ax, ay, rot", CASES, ids=IDS)
@pytest.mark.parametrize("theta, phi", [(30, 0), (60, 30), (75, 90), (85, 200), (60, 135)])
def test_smith_lambda_satisfies_the_projected_area_identity(cls, ax, ay, rot, theta, phi):
    """The projected-area identity with Smith G1 = 1/(1 + Λ): ∫ G1 max(w·h, 0) D dω = cos θ_w, i.e.
    1 + Λ(w) = ∫ max(w·h, 0) D dω / cos θ_w — the exact Λ against quadrature."""
    ndf = cls(ax, ay, rot)
    w = spherical_deg(theta, phi)
    integral = np.sum(np.maximum(H @ w, 0.0) * ndf.D(H) * DW)
    lam = float(an.smith_lambda(w, ndf))
    assert 1.0 + lam == pytest.approx(integral / w[2], rel=3e-3)


@pytest.mark.parametrize("cls, ax, ay, rot", CASES, ids=IDS)
def test_sampler_follows_its_pdf(cls, ax, ay, rot):
    """2·10⁵ samples: their slopes, unstretched by (αx, αy) in the NDF's frame, have the unit
    distribution exactly (Kolmogorov–Smirnov of ρ² against its CDF — Beckmann 1 − e^{−ρ²},
    GGX ρ²/(1 + ρ²) — and of the slope azimuth against uniform, p > 1e-4: a correct sampler
    fails 1 in 10⁴ runs), and they estimate the projected area ∫ max(w·h, 0) D dω =
    (1 + Λ(w)) cos θ_w by E[max(w·h, 0)/cos θ_h] within 4 standard errors."""
    from scipy import stats

    ndf = cls(ax, ay, rot)
    rng = np.random.default_rng(3)
    n = 200_000
    h = ndf.sample(rng.random(n), rng.random(n))
    assert np.allclose(np.linalg.norm(h, axis=-1), 1.0) and np.all(h[..., 2] > 0)
    np.testing.assert_allclose(ndf.pdf(h), ndf.D(h) * h[..., 2])
    hl = ndf._to_local(h)
    sx, sy = -hl[..., 0] / hl[..., 2] / ax, -hl[..., 1] / hl[..., 2] / ay
    rho2 = sx**2 + sy**2
    cdf = (lambda r: -np.expm1(-r)) if cls is an.AnisotropicBeckmann else (lambda r: r / (1 + r))
    assert stats.kstest(rho2, cdf).pvalue > 1e-4
    assert stats.kstest(np.arctan2(sy, sx), stats.uniform(-np.pi, 2 * np.pi).cdf).pvalue > 1e-4
    for w in (spherical_deg(60, 30), spherical_deg(80, 100)):
        x = np.maximum(h @ w, 0.0) / h[..., 2]
        target = (1.0 + float(an.smith_lambda(w, ndf))) * w[2]
        assert abs(x.mean() - target) < 4 * x.std() / np.sqrt(n)


def test_the_isotropic_stand_in_misses_the_azimuth():
    """MaterialX's G2 with α = √(αx αy): for GGX αx = 0.1, αy = 0.8 at θ = 60° (wi = wo, height-
    correlated G2 = 1/(1 + 2Λ)) it gives 0.898 at every azimuth, where the exact Λ gives 0.985
    along x and 0.585 along y."""
    ndf = an.AnisotropicGGX(0.1, 0.8)
    iso = ndf.isotropic_equivalent()
    assert isinstance(iso, an.GGX) and iso.alpha == pytest.approx(np.sqrt(0.08))
    g2 = lambda lam: 1.0 / (1.0 + 2.0 * lam)  # noqa: E731
    assert g2(an.smith_lambda(spherical_deg(60, 0), iso)) == pytest.approx(0.898, abs=5e-4)
    assert g2(an.smith_lambda(spherical_deg(60, 0), ndf)) == pytest.approx(0.985, abs=5e-4)
    assert g2(an.smith_lambda(spherical_deg(60, 90), ndf)) == pytest.approx(0.585, abs=5e-4)


def test_torrance_sparrow_takes_an_anisotropic_ndf():
    """The model objects work unchanged: f(wi, wo) ≠ f with wo mirrored about the plane of
    incidence when the NDF is rotated (no mirror symmetry), and equals it when it is not."""
    wi = spherical_deg(40, 0)
    wo = spherical_deg(50, 150)
    mirrored = wo * np.array([1, -1, 1])
    rotated = an.TorranceSparrow(an.AnisotropicGGX(0.1, 0.5, 30.0), an.Smith(correlated=True))
    aligned = an.TorranceSparrow(an.AnisotropicGGX(0.1, 0.5, 0.0), an.Smith(correlated=True))
    assert rotated.f(wi, wo) != pytest.approx(rotated.f(wi, mirrored), rel=1e-3)
    assert aligned.f(wi, wo) == pytest.approx(aligned.f(wi, mirrored), rel=1e-12)


@pytest.mark.parametrize(
    "bad, name",
    [
        (dict(alpha_x=0, alpha_y=0.3), "alpha_x"),
        (dict(alpha_x=0.3, alpha_y=-1), "alpha_y"),
        (dict(alpha_x=0.3, alpha_y=0.3, rotation=float("nan")), "rotation"),
    ],
)
def test_bad_parameters_name_themselves(bad, name):
    from microsim.errors import UsageError

    with pytest.raises(UsageError, match=name):
        an.AnisotropicGGX(**bad)


@pytest.mark.parametrize("cls, ax, ay, rot", CASES, ids=IDS)
@pytest.mark.parametrize("theta, phi", [(20, 10), (70, 100)])
def test_visible_normals_follow_their_density(cls, ax, ay, rot, theta, phi):
    """Pearson χ² (``microsim.testing.assert_sampler_matches``, Šidák over the 8 cases) of
    10⁵ visible normals against D_v(m) = ⟨v, m⟩⁺ D(m)/((1 + Λ(v)) cos θ_v), which integrates to
    1 by the projected-area identity (checked here too)."""
    from microsim.testing import assert_sampler_matches

    ndf = cls(ax, ay, rot)
    v = spherical_deg(theta, phi)
    total = np.sum(ndf.pdf_visible(H, np.broadcast_to(v, H.shape)) * DW)
    assert total == pytest.approx(1.0, abs=5e-3)

    def sample(u1, u2):
        return ndf.sample_visible(np.broadcast_to(v, (len(u1), 3)), u1, u2)

    def pdf(m):
        return np.where(m[:, 2] > 0, ndf.pdf_visible(m, np.broadcast_to(v, m.shape)), 0.0)

    assert_sampler_matches(sample, pdf, n=100_000, n_tests=8)
