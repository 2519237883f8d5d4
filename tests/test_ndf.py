"""NDFs: normalisation (Mikkelsen 2009, eq. 14), CDF/quantile consistency, sampler χ², Smith Λ,
finiteness on the closed hemisphere, parameter validation."""

import numpy as np
import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st
from scipy import integrate, special
from support import pearson_chi2, sidak

from microsim import analytic as an
from microsim.vectors import spherical

HALF_PI = 0.5 * np.pi


# --- quadrature in x = 1 − cos θ on a logarithmic grid (resolves lobes of any width) --------
X_EDGES = np.concatenate([[0.0], np.logspace(-18, 0, 37)])


def integrate_x(f, x_max=1.0):
    """∫₀^x_max f(x) dx, split at logarithmically spaced points."""
    edges = np.append(X_EDGES[X_EDGES < x_max], x_max)
    return sum(
        integrate.quad(f, a, b, epsabs=1e-14, epsrel=1e-10, limit=200)[0]
        for a, b in zip(edges[:-1], edges[1:])
    )


def h_at(x):
    """Unit half vector with 1 − h_z = x (azimuth 0), its tangential part exact for tiny x."""
    return np.array([np.sqrt(x * (2.0 - x)), 0.0, 1.0 - x])


def projected_mass(ndf, x_max=1.0):
    """∫ D(h)(h·n) dω over 1 − h·n ≤ x_max: 2π ∫ D(h(x))(1 − x) dx (dω = 2π dx)."""
    return integrate_x(lambda x: 2 * np.pi * ndf.D(h_at(x)) * (1.0 - x), x_max)


NORMALISATION_CASES = (
    [an.Beckmann(m) for m in (0.01, 0.05, 0.3, 1, 1.5)]
    + [an.GGX(a) for a in (0.01, 0.3, 1)]
    + [an.BlinnPhong(e) for e in (0, 1, 100, 1e4)]
    + [an.VonMisesFisher(k) for k in (1e-3, 1, 17, 1024, 1e5)]
    + [an.ABC(b, c) for b in (1, 100, 1e4, 1e8) for c in (0.6, 1, 1 - 1e-9, 1 + 1e-9, 3)]
)


@pytest.mark.parametrize("ndf", NORMALISATION_CASES, ids=repr)
def test_normalisation(ndf):
    """∫ D(h)(h·n) dω = 1 (Mikkelsen 2009, eq. 14)."""
    with np.errstate(all="ignore"):
        mass = projected_mass(ndf)
    assert mass == pytest.approx(1.0, abs=1e-4)


CDF_CASES = [
    an.Beckmann(0.05),
    an.Beckmann(1.5),
    an.GGX(0.3),
    an.BlinnPhong(0),
    an.BlinnPhong(1e4),
    an.VonMisesFisher(1e-3),
    an.VonMisesFisher(1024),
    an.ABC(1e4, 1 + 1e-9),
    an.ABC(1e8, 0.6),
    an.ABC(1, 3),
]


@pytest.mark.parametrize("ndf", CDF_CASES, ids=repr)
def test_cdf_is_the_integral_of_the_tilt_density(ndf):
    """cdf_theta(θ) = ∫₀^θ 2π D cos sin dθ', integrated in θ with log-spaced break points."""
    for u in (1e-3, 0.1, 0.5, 0.9, 0.999):
        theta = float(ndf.tilt_quantile_rad(u))
        edges = np.append(0.0, theta * np.logspace(-9, 0, 19))
        integral = sum(
            integrate.quad(ndf.tilt_pdf_rad, a, b, epsabs=1e-13, epsrel=1e-10, limit=200)[0]
            for a, b in zip(edges[:-1], edges[1:])
        )
        assert ndf.cdf_theta_rad(theta) == pytest.approx(integral, abs=1e-6)
    assert ndf.cdf_theta_rad(0.0) == 0.0
    assert ndf.cdf_theta_rad(HALF_PI) == pytest.approx(1.0, abs=1e-12)


@pytest.mark.parametrize("ndf", CDF_CASES, ids=repr)
def test_quantile_inverts_cdf(ndf):
    u = np.concatenate([[0.0, 1e-12, 1e-6], np.linspace(0.001, 0.999, 999), [1 - 1e-9, 1.0]])
    theta = ndf.tilt_quantile_rad(u)
    assert np.all((theta >= 0) & (theta <= HALF_PI))
    assert np.all(np.diff(theta) >= 0)
    np.testing.assert_allclose(ndf.cdf_theta_rad(theta), u, rtol=0, atol=1e-12)
    assert theta[-1] == pytest.approx(HALF_PI, abs=1e-15)
    # θ round trip where the CDF is neither 0 nor 1 to double precision
    inner = theta[(u >= 1e-6) & (u <= 0.999)]
    np.testing.assert_allclose(ndf.tilt_quantile_rad(ndf.cdf_theta_rad(inner)), inner, rtol=1e-8)


# --- closed-form special values ------------------------------------------------------------
def test_closed_forms_at_the_normal():
    """D(n) from the formulas: Beckmann 1/(πm²), GGX 1/(πα²), Phong (e+2)/2π,
    vMF κ/(2π(1 − e^{−κ})), ABC M."""
    n = np.array([0.0, 0.0, 1.0])
    assert an.Beckmann(0.2).D(n) == pytest.approx(1 / (np.pi * 0.04), rel=1e-14)
    assert an.GGX(0.2).D(n) == pytest.approx(1 / (np.pi * 0.04), rel=1e-14)
    assert an.BlinnPhong(7).D(n) == pytest.approx(9 / (2 * np.pi), rel=1e-14)
    assert an.VonMisesFisher(3).D(n) == pytest.approx(3 / (2 * np.pi * (1 - np.exp(-3))), rel=1e-14)
    # ABC with C = 2: J(1) = ∫₀¹ (1 − t)/(1 + Bt)² dt = (B − ln(1 + B))/B² by hand (s = 1 + Bt)
    B = 3.0
    j1 = integrate.quad(lambda t: (1 - t) / (1 + B * t) ** 2, 0, 1, epsrel=1e-13)[0]
    assert j1 == pytest.approx((B - np.log1p(B)) / B**2, rel=1e-12)
    assert an.ABC(B, 2).D(n) == pytest.approx(1 / (2 * np.pi * j1), rel=1e-12)


def test_abc_c_near_one_is_continuous():
    """C → 1 passes smoothly through the logarithmic case (no special branch, no jump)."""
    base = an.ABC(1e8, 1.0)
    theta = np.radians([0.0, 0.01, 1.0, 30.0, 89.0])
    for dc in (1e-9, -1e-9, 1e-12):
        other = an.ABC(1e8, 1.0 + dc)
        assert other.M == pytest.approx(base.M, rel=1e-7)
        np.testing.assert_allclose(other.cdf_theta_rad(theta), base.cdf_theta_rad(theta), rtol=1e-7)


def test_abc_D_from_vector_is_accurate_near_the_peak():
    """For B = 1e8 a facet tilted by 1e-5 rad has 1 − h_z = 5e-11, which 1 − h_z computed in
    floating point gets wrong by ~1e-6 relative; D(h) must use the exact tangential form."""
    ndf = an.ABC(1e8, 3.0)
    theta = 1e-5
    h = np.array([np.sin(theta), 0.0, np.cos(theta)])
    exact = ndf.M * (1 + 1e8 * 2 * np.sin(theta / 2) ** 2) ** -3.0
    assert ndf.D(h) == pytest.approx(exact, rel=1e-13)
    assert ndf.pdf(h) == pytest.approx(exact * np.cos(theta), rel=1e-13)


def test_beckmann_phong_conversion():
    """Mikkelsen 2009, eq. 21: e = 2/m² − 2 equates the normalisation constants at h = n."""
    for m in (0.05, 0.3, 1.0):
        e = an.beckmann_to_phong(m)
        assert e == pytest.approx(2 / m**2 - 2, rel=1e-15)
        assert an.BlinnPhong(e).D_cos(1.0) == pytest.approx(an.Beckmann(m).D_cos(1.0), rel=1e-13)
        assert an.phong_to_beckmann(e) == pytest.approx(m, rel=1e-13)
    with pytest.raises(ValueError, match="m"):
        an.beckmann_to_phong(1.5)
    with pytest.raises(ValueError, match="e"):
        an.phong_to_beckmann(-1)


# --- Smith Λ -------------------------------------------------------------------------------
def mean_projected_area_over_cos(ndf, theta_o):
    """∫ (wo·h)⁺ D(h) dω / cos θo, as an expectation over h ~ D(h)(h·n) dω: the φ_h integral of
    (sinθo tanθ cosφ + cosθo)⁺ is done in closed form, the tilt integral by quad over
    v = √(1 − u) (u the tilt's cumulative probability), which tames the tan θ tail at u → 1.
    v < 1e-8 (where u = 1 − v² rounds to 1) is left out: its integrand is at most
    2 tanθ √(1 − u)/π → 2α/π (GGX tail), so it contributes < 1e-8."""
    b = np.cos(theta_o)

    def over_phi(v):
        a = np.sin(theta_o) * np.tan(ndf.tilt_quantile_rad(1.0 - v * v))
        mean = b if a <= b else (b * np.arccos(-b / a) + np.sqrt(a * a - b * b)) / np.pi
        return mean * 2.0 * v  # du = 2v dv

    v_kink = np.sqrt(1.0 - ndf.cdf_theta_rad(HALF_PI - theta_o))  # where a = b
    edges = np.unique(np.append(np.logspace(-8, 0, 17), max(v_kink, 1e-8)))
    # epsabs: for v ≲ 1e-7 the rounding of u = 1 − v² makes the integrand noisy
    total = sum(
        integrate.quad(over_phi, lo, hi, epsabs=1e-11, epsrel=1e-10, limit=200)[0]
        for lo, hi in zip(edges[:-1], edges[1:])
    )
    return total / b


@pytest.mark.parametrize(
    "ndf", [an.Beckmann(0.5), an.Beckmann(0.1), an.GGX(0.5), an.GGX(0.1)], ids=repr
)
def test_smith_lambda_satisfies_projected_area_identity(ndf):
    """∫ G1(wo,h)(wo·h)⁺ D dω = cos θo with G1 = 1/(1 + Λ(wo)) (docs/design.md): the integral over
    (wo·h)⁺ D must equal (1 + Λ) cos θo."""
    for deg in (0.0, 30.0, 70.0, 85.0):
        t = np.radians(deg)
        expected = 1.0 + ndf.smith_lambda_cos(np.cos(t))
        assert mean_projected_area_over_cos(ndf, t) == pytest.approx(expected, rel=1e-7)


def test_smith_lambda_matches_textbook_forms():
    c = np.linspace(0.05, 0.999, 200)
    tan = np.sqrt(1 - c * c) / c
    m = 0.4
    a = 1 / (m * tan)
    lam_b = (special.erf(a) - 1) / 2 + np.exp(-a * a) / (2 * a * np.sqrt(np.pi))
    ok = lam_b > 1e-6  # the textbook form cancels below that
    np.testing.assert_allclose(an.Beckmann(m).smith_lambda_cos(c)[ok], lam_b[ok], rtol=1e-9)
    alpha = 0.4
    np.testing.assert_allclose(
        an.GGX(alpha).smith_lambda_cos(c), (-1 + np.sqrt(1 + alpha**2 * tan**2)) / 2, rtol=1e-12
    )


@pytest.mark.parametrize("ndf", [an.Beckmann(0.3), an.GGX(0.3)], ids=repr)
def test_smith_lambda_limits(ndf):
    lam = ndf.smith_lambda_cos(np.array([1.0, 0.0]))
    assert lam[0] == 0.0 and lam[1] == np.inf
    assert 1.0 / (1.0 + lam[1]) == 0.0


# --- sampler χ² ------------------------------------------------------------------------------
SAMPLER_CASES = [
    an.Beckmann(0.3),
    an.Beckmann(0.02),
    an.GGX(0.3),
    an.GGX(0.05),
    an.BlinnPhong(20),
    an.BlinnPhong(1e4),
    an.VonMisesFisher(17),
    an.VonMisesFisher(1024),
    an.ABC(1e4, 1 + 1e-9),
    an.ABC(1e4, 1 - 1e-9),
    an.ABC(100, 3),
    an.ABC(1e8, 0.6),
]
N_SAMPLES = 1_000_000
# two tests per case (joint θ×φ cells, φ marginal); Šidák over the whole family of the file
ALPHA = sidak(0.01, 2 * len(SAMPLER_CASES))
U_EDGES = np.concatenate(
    [[0, 1e-4, 1e-3, 0.01, 0.03], np.linspace(0.05, 0.95, 19), [0.97, 0.99, 0.999, 0.9999, 1]]
)
N_PHI = 8


@pytest.mark.parametrize("case", range(len(SAMPLER_CASES)), ids=[repr(n) for n in SAMPLER_CASES])
def test_sampler_chi2(case):
    ndf = SAMPLER_CASES[case]
    rng = np.random.default_rng(20240 + case)
    h = ndf.sample(*rng.random((2, N_SAMPLES)))
    assert np.all(np.isfinite(h)) and np.all(h[:, 2] >= 0)
    np.testing.assert_allclose(np.linalg.norm(h, axis=-1), 1.0, atol=1e-14)
    theta = np.arctan2(np.hypot(h[:, 0], h[:, 1]), h[:, 2])
    phi = np.mod(np.arctan2(h[:, 1], h[:, 0]), 2 * np.pi)

    theta_edges = ndf.tilt_quantile_rad(U_EDGES)
    theta_edges[-1] = HALF_PI
    p_theta = np.diff(ndf.cdf_theta_rad(theta_edges))
    p_theta[-1] += 1.0 - ndf.cdf_theta_rad(HALF_PI)  # zero up to rounding
    phi_edges = np.linspace(0, 2 * np.pi, N_PHI + 1)
    observed, _, _ = np.histogram2d(theta, phi, bins=[theta_edges, phi_edges])
    assert observed.sum() == N_SAMPLES
    expected = N_SAMPLES * np.outer(p_theta, np.full(N_PHI, 1.0 / N_PHI))
    _, _, p = pearson_chi2(observed, expected)
    assert p > ALPHA, f"joint θ×φ χ² p = {p:.3g}"

    phi_counts, _ = np.histogram(phi, bins=np.linspace(0, 2 * np.pi, 33))
    _, _, p_phi = pearson_chi2(phi_counts, np.full(32, N_SAMPLES / 32))
    assert p_phi > ALPHA, f"φ uniformity χ² p = {p_phi:.3g}"


# --- finiteness on the closed hemisphere (hypothesis) --------------------------------------
def log_uniform(lo, hi):
    return st.floats(np.log10(lo), np.log10(hi)).map(lambda v: 10.0**v)


NDFS = st.one_of(
    log_uniform(1e-3, 10).map(an.Beckmann),
    log_uniform(1e-3, 10).map(an.GGX),
    st.one_of(st.just(0.0), log_uniform(1e-3, 1e6)).map(an.BlinnPhong),
    log_uniform(1e-6, 1e8).map(an.VonMisesFisher),
    st.builds(
        an.ABC,
        log_uniform(1e-2, 1e10),
        st.one_of(log_uniform(0.05, 10), st.floats(1 - 1e-8, 1 + 1e-8)),
    ),
)
ANGLES = st.floats(0.0, HALF_PI)
UNIT = st.floats(0.0, 1.0)


@settings(max_examples=300, deadline=None)
@given(ndf=NDFS, theta=ANGLES, phi=st.floats(0.0, 2 * np.pi))
@example(ndf=an.VonMisesFisher(1e-6), theta=HALF_PI, phi=0.0)
@example(ndf=an.ABC(1e10, 1 + 1e-9), theta=0.0, phi=0.0)
def test_densities_finite_on_closed_hemisphere(ndf, theta, phi):
    hs = np.stack([spherical(theta, phi), [0, 0, 1.0], [1.0, 0, 0], spherical(HALF_PI, phi)])
    for values in (
        ndf.D(hs),
        ndf.pdf(hs),
        ndf.D_cos(hs[:, 2]),
        ndf.tilt_pdf_rad(np.array([theta, 0.0, HALF_PI])),
        ndf.cdf_theta_rad(np.array([theta, 0.0, HALF_PI])),
    ):
        assert np.all(np.isfinite(values)) and np.all(values >= 0)
    assert ndf.D(hs[2]) == 0.0  # h exactly in the tangent plane
    assert 0.0 <= ndf.cdf_theta_rad(theta) <= 1.0
    if ndf.has_closed_smith:
        lam = ndf.smith_lambda_cos(np.array([np.cos(theta), 1.0, 0.0]))
        assert np.isfinite(lam[0]) or np.cos(theta) == 0.0
        assert lam[1] == 0.0 and lam[2] == np.inf and np.all(lam >= 0)


@settings(max_examples=300, deadline=None)
@given(ndf=NDFS, u1=UNIT, u2=UNIT)
@example(ndf=an.ABC(1e10, 0.05), u1=1.0, u2=1.0)
@example(ndf=an.VonMisesFisher(1e8), u1=1.0, u2=0.0)
@example(ndf=an.Beckmann(1e-3), u1=0.0, u2=0.5)
def test_quantile_and_samples_finite(ndf, u1, u2):
    theta = ndf.tilt_quantile_rad(np.array([u1, 0.0, 1.0]))
    assert np.all(np.isfinite(theta)) and np.all((theta >= 0) & (theta <= HALF_PI))
    assert theta[1] == 0.0 and theta[2] == pytest.approx(HALF_PI, abs=1e-15)
    assert abs(ndf.cdf_theta_rad(theta[0]) - u1) <= 1e-12
    h = ndf.sample(u1, u2)
    assert np.all(np.isfinite(h)) and h[2] >= 0 and np.linalg.norm(h) == pytest.approx(1, abs=1e-15)


# --- parameter validation ------------------------------------------------------------------
@pytest.mark.parametrize(
    "make, name",
    [
        (lambda: an.Beckmann(0), "m"),
        (lambda: an.Beckmann(-1), "m"),
        (lambda: an.Beckmann(np.nan), "m"),
        (lambda: an.Beckmann(np.inf), "m"),
        (lambda: an.GGX(0), "alpha"),
        (lambda: an.GGX(np.nan), "alpha"),
        (lambda: an.BlinnPhong(-1), "e"),
        (lambda: an.BlinnPhong(np.nan), "e"),
        (lambda: an.BlinnPhong(np.inf), "e"),
        (lambda: an.VonMisesFisher(0), "kappa"),
        (lambda: an.VonMisesFisher(np.nan), "kappa"),
        (lambda: an.ABC(0, 1), "B"),
        (lambda: an.ABC(1, 0), "C"),
        (lambda: an.ABC(1, -1), "C"),
        (lambda: an.ABC(np.nan, 1), "B"),
        (lambda: an.ABC(1, np.nan), "C"),
    ],
)
def test_invalid_parameters(make, name):
    with pytest.raises(ValueError, match=rf"^{name} must"):
        make()


def test_frozen_and_repr():
    ndf = an.ABC(100, 3)
    with pytest.raises(AttributeError):
        ndf.B = 5.0
    assert repr(ndf) == "ABC(B=100.0, C=3.0)"
    assert an.Beckmann(0.3) == an.Beckmann(0.3) and hash(an.GGX(0.1)) == hash(an.GGX(0.1))


@pytest.mark.parametrize("ndf", CDF_CASES, ids=repr)
def test_tilt_angles_in_degrees_are_refused(ndf):
    """Tilt angles are radians and say so: a value in degrees raises instead of being clipped
    (``Beckmann(0.3).cdf_theta(30)`` used to return 1.0)."""
    for method in (ndf.cdf_theta_rad, ndf.tilt_pdf_rad):
        with pytest.raises(ValueError, match="radians"):
            method(30.0)
        with pytest.raises(ValueError, match="radians"):
            method(np.array([0.1, -0.5]))
    assert ndf.cdf_theta_rad(0.5 * np.pi + 1e-12) == ndf.cdf_theta_rad(0.5 * np.pi)
