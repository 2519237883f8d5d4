"""Tests of microsim.analytic.low (Löw et al. 2012): ABC spectrum, Rayleigh–Rice, smooth-surface
and microfacet BRDFs, their samplers and the fit metrics.

Reference values are computed here from the formulas in the paper (or textbook Fresnel
amplitudes), by independent quadrature, or in 50-digit decimal arithmetic — never copied from
the module's output.
"""

from __future__ import annotations

from decimal import Decimal, getcontext

import numpy as np
import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st
from scipy import integrate
from support import pearson_chi2, sidak

from microsim import analytic as an
from microsim.vectors import half_vector, spherical, spherical_deg

RNG = np.random.default_rng(20120601)
LAMBDA = 0.5  # µm
AL, METHANOL = 0.769 + 6.08j, 1.329


def random_upper(n, rng, max_theta_deg=89.5):
    """n directions uniform in (cos θ, φ) over the cap θ ≤ max_theta_deg."""
    c = rng.uniform(np.cos(np.radians(max_theta_deg)), 1.0, n)
    return spherical(np.arccos(c), rng.uniform(0.0, 2 * np.pi, n))


# --- ABC spectrum --------------------------------------------------------------------------------
def test_condensed_abc_is_church_reparametrised():
    """Löw et al. 2012, eq. 11: S(f; A=a, B=b², C=(c+1)/2) equals Church's eq. 7."""
    f = np.concatenate([[0.0], np.geomspace(1e-4, 1e4, 50)])
    for a, b, c in [(2.0, 3.0, 1.5), (1e-3, 0.1, 0.2), (5.0, 40.0, 3.0)]:
        A, B, C = an.church_to_condensed(a, b, c)
        np.testing.assert_allclose(
            an.abc_psd(f, A, B, C), an.abc_psd_church(f, a, b, c), rtol=1e-13
        )
        assert an.abc_psd(0.0, A, B, C) == a


@pytest.mark.parametrize("a,b,c", [(2.0, 3.0, 1.5), (1.0, 0.1, 4.0), (0.3, 7.0, 1.1)])
def test_church_integral_matches_quadrature(a, b, c):
    """∫ PSD d²f = 2π ∫₀^∞ f PSD(f) df = 2πa/(b²(c−1)) (docs/design.md)."""

    # v = ln(1 + b²f²): f df = e^v dv/(2b²), so 2π f PSD df = π e^v PSD(f(v)) dv / b²
    def integrand(v):
        return np.pi * np.exp(v) * an.abc_psd_church(np.sqrt(np.expm1(v)) / b, a, b, c) / b**2

    v_max = 64.0 / (c - 1.0)  # the tail beyond holds a fraction e^-32 of the total
    val, _ = integrate.quad(integrand, 0.0, v_max, epsabs=0, epsrel=1e-12, limit=500)
    np.testing.assert_allclose(an.abc_psd_church_integral(a, b, c), val, rtol=1e-9)


def test_church_integral_needs_c_above_one():
    with pytest.raises(ValueError, match="C must be > 1"):
        an.abc_psd_church_integral(1.0, 1.0, 1.0)


# --- Rayleigh–Rice -------------------------------------------------------------------------------
def textbook_rs_rp(cos_t, ior):
    """|r_s|², |r_p|² from the textbook amplitudes (c ∓ g)/(c ± g), (ε c ∓ g)/(ε c ± g)."""
    eps = complex(ior) ** 2
    g = np.sqrt(eps - (1 - cos_t**2) + 0j)
    rs = (cos_t - g) / (cos_t + g)
    rp = (eps * cos_t - g) / (eps * cos_t + g)
    return np.abs(rs) ** 2, np.abs(rp) ** 2


@pytest.mark.parametrize("ior", [1.5, METHANOL, AL])
def test_rr_q_in_specular_direction_is_fresnel(ior):
    """Stover's Q reduces to the Fresnel reflectances in the specular direction (S(0) = A)."""
    theta = np.radians([0.0, 20.0, 45.0, 70.0, 85.0])
    wi, wo = spherical(theta, np.pi), spherical(theta, 0.0)
    scale = 16 * np.pi**2 / LAMBDA**4 * np.cos(theta) ** 2  # A = 1
    q = {
        p: an.rayleigh_rice(wi, wo, LAMBDA, 1.0, 2.0, 1.5, ior, p) / scale
        for p in an.RR_POLARISATIONS
    }
    rs, rp = textbook_rs_rp(np.cos(theta), ior)
    np.testing.assert_allclose(q["ss"], rs, rtol=1e-12)
    np.testing.assert_allclose(q["pp"], rp, rtol=1e-12, atol=1e-15)
    assert np.all(q["sp"] < 1e-25) and np.all(q["ps"] < 1e-25)  # sin φ = 0 up to rounding
    np.testing.assert_allclose(q["unpolarised"], an.fresnel(np.cos(theta), ior), rtol=1e-12)


def test_rr_polarisation_sums():
    """s = ss + sp, p = ps + pp, unpolarised = (s + p)/2."""
    wi, wo = random_upper(200, RNG), random_upper(200, RNG)
    rr = {p: an.rayleigh_rice(wi, wo, LAMBDA, 1e-3, 2.0, 1.5, AL, p) for p in an.RR_POLARISATIONS}
    np.testing.assert_allclose(rr["s"], rr["ss"] + rr["sp"], rtol=1e-13)
    np.testing.assert_allclose(rr["p"], rr["ps"] + rr["pp"], rtol=1e-13)
    np.testing.assert_allclose(rr["unpolarised"], 0.5 * (rr["s"] + rr["p"]), rtol=1e-13)


@pytest.mark.parametrize("ior", [1.5, AL])
def test_rr_normal_incidence_is_azimuth_independent(ior):
    """At θi = 0 the plane of incidence is undefined: unpolarised RR must not depend on φo."""
    wo = spherical_deg(40.0, np.linspace(0, 360, 37))
    f = an.rayleigh_rice([0.0, 0.0, 1.0], wo, LAMBDA, 1e-3, 2.0, 1.5, ior)
    np.testing.assert_allclose(f, f[0], rtol=1e-13)


def test_rr_spatial_frequency_follows_eq_4_5():
    """f_x = (sinθo cosφo − sinθi)/λ, f_y = sinθo sinφo/λ for wi in the φ = π half-plane.

    Recovered from RR alone: with C = 1, RR(B1)/RR(B2) = (1 + B2 f²)/(1 + B1 f²), Q cancels."""
    n = 300
    ti, to, po = (RNG.uniform(0, 1.5, n), RNG.uniform(0, 1.5, n), RNG.uniform(0, 2 * np.pi, n))
    wi, wo = spherical(ti, np.pi), spherical(to, po)
    b1, b2 = 0.3, 5.0
    ratio = an.rayleigh_rice(wi, wo, LAMBDA, 1.0, b1, 1.0, 1.5) / an.rayleigh_rice(
        wi, wo, LAMBDA, 1.0, b2, 1.0, 1.5
    )
    f2 = (ratio - 1.0) / (b2 - ratio * b1)
    fx = (np.sin(to) * np.cos(po) - np.sin(ti)) / LAMBDA
    fy = np.sin(to) * np.sin(po) / LAMBDA
    np.testing.assert_allclose(f2, fx**2 + fy**2, rtol=1e-9, atol=1e-12)


# --- reciprocity ---------------------------------------------------------------------------------
BRDFS = {
    "smooth": lambda wi, wo: an.low_smooth(wi, wo, 3.0, 200.0, 1.3, kd=0.1, material=1.5),
    "smooth-cos-al": lambda wi, wo: an.low_smooth(
        wi, wo, 3.0, 50.0, 0.7, material=AL, obliquity="cos"
    ),
    "smooth-harvey": lambda wi, wo: an.low_smooth(wi, wo, 1.0, 1e4, 2.0, obliquity="harvey"),
    "microfacet": lambda wi, wo: an.low_microfacet(wi, wo, 2.0, 300.0, 1.7, kd=0.2, material=1.5),
    "microfacet-al": lambda wi, wo: an.low_microfacet(wi, wo, 2.0, 30.0, 1.0, material=AL),
    "microfacet-noG": lambda wi, wo: an.low_microfacet(wi, wo, 2.0, 30.0, 0.5, shadowing="none"),
    "rr": lambda wi, wo: an.rayleigh_rice(wi, wo, LAMBDA, 1e-3, 2.0, 1.5, AL),
    "rr-ss": lambda wi, wo: an.rayleigh_rice(wi, wo, LAMBDA, 1e-3, 2.0, 1.5, 1.5, "ss"),
    "rr-pp": lambda wi, wo: an.rayleigh_rice(wi, wo, LAMBDA, 1e-3, 2.0, 1.5, AL, "pp"),
}


@pytest.mark.parametrize("name", sorted(BRDFS))
def test_reciprocity(name):
    f = BRDFS[name]
    wi, wo = random_upper(2000, RNG), random_upper(2000, RNG)
    np.testing.assert_allclose(f(wi, wo), f(wo, wi), rtol=1e-12, atol=0)


def test_rr_cross_polarisations_swap_under_reciprocity():
    """Q_sp(wi, wo) = Q_ps(wo, wi): the polarised cross terms are reciprocal as a pair."""
    wi, wo = random_upper(500, RNG), random_upper(500, RNG)

    def rr(a, b, p):
        return an.rayleigh_rice(a, b, LAMBDA, 1e-3, 2.0, 1.5, AL, p)

    np.testing.assert_allclose(rr(wi, wo, "sp"), rr(wo, wi, "ps"), rtol=1e-12)


# --- smooth-surface BRDF -------------------------------------------------------------------------
@pytest.mark.parametrize("ior", [1.5, AL, None])
def test_smooth_specular_value(ior):
    """In the specular direction Dp = 0 and θd = θi (Löw et al. 2012, eq. 13–14): f = kd/π + G' A
    F(θi; Re η)."""
    theta = np.radians([0.0, 30.0, 60.0, 80.0, 89.0])
    wi, wo = spherical(theta, 0.3), spherical(theta, 0.3 + np.pi)
    F = an.fresnel(np.cos(theta), None if ior is None else complex(ior).real)
    A, kd = 2.5, 0.3
    for obl, g in [("one", 1.0), ("cos", np.cos(theta) ** 2), ("harvey", np.cos(theta) ** 2)]:
        f = an.low_smooth(wi, wo, A, 1e3, 1.2, kd=kd, material=ior, obliquity=obl)
        np.testing.assert_allclose(f, kd / np.pi + g * A * F, rtol=1e-12)


def test_smooth_fresnel_angle_exact_for_equal_elevations():
    """|wi − wo| = 2 sin θd exactly; its projection equals it when θi = θo, so there
    Q' = F(wi·ĥ) exactly (this fails if the sign inside eq. 13 is taken as |Lp + Vp|)."""
    n = 500
    theta, pi_, po = RNG.uniform(0, 1.5, n), RNG.uniform(0, 6.3, n), RNG.uniform(0, 6.3, n)
    wi, wo = spherical(theta, pi_), spherical(theta, po)
    h = half_vector(wi, wo)
    A, B, C = 1.0, 40.0, 1.3
    s = A / (1 + B * np.sum((wi + wo)[..., :2] ** 2, axis=-1)) ** C
    expect = s * an.fresnel(np.sum(wi * h, axis=-1), 1.5)
    np.testing.assert_allclose(an.low_smooth(wi, wo, A, B, C, material=1.5), expect, rtol=1e-12)


def test_smooth_argument_is_lows_polar_form():
    """|Dp|² = r_i² + 2 r_i r_o cos(φi − φo) + r_o² with r = sin θ (Löw §4, eq. before 18)."""
    n = 500
    ti, to = RNG.uniform(0, 1.57, n), RNG.uniform(0, 1.57, n)
    pi_, po = RNG.uniform(0, 6.3, n), RNG.uniform(0, 6.3, n)
    ri, ro = np.sin(ti), np.sin(to)
    d2 = ri**2 + 2 * ri * ro * np.cos(pi_ - po) + ro**2
    A, B, C = 2.0, 500.0, 0.8
    f = an.low_smooth(spherical(ti, pi_), spherical(to, po), A, B, C)
    np.testing.assert_allclose(f, A / (1 + B * d2) ** C, rtol=1e-10)


# --- microfacet BRDF -----------------------------------------------------------------------------
def abc_ndf_norm_by_quadrature(B, C):
    """M with 2π M ∫₀¹ (1 − x)(1 + Bx)^−C dx = 1, integrated in w = ln(1 + Bx)."""
    L = np.log1p(B)

    def g(w):
        return (1 - np.expm1(w) / B) * np.exp((1 - C) * w) / B

    val, _ = integrate.quad(g, 0.0, L, epsabs=0, epsrel=1e-13, limit=200)
    return 1.0 / (2 * np.pi * val)


@pytest.mark.parametrize(
    "B,C,ior", [(10.0, 1.0, 1.5), (300.0, 2.5, AL), (1e4, 0.6, METHANOL), (50.0, 1 + 1e-9, None)]
)
def test_microfacet_with_ndf_amplitude_is_torrance_sparrow(B, C, ior):
    """With A = low_microfacet_A_from_ndf(B, C), Löw et al. 2012, eq. 15 equals D F G/(4 cosθi
    cosθo) with
    the normalised ABC NDF and the V-groove G, all computed here from their formulas."""
    wi, wo = random_upper(3000, RNG, 89.0), random_upper(3000, RNG, 89.0)
    H = wi + wo
    h = H / np.linalg.norm(H, axis=-1, keepdims=True)
    x = np.sum(H[..., :2] ** 2, -1) / (
        np.linalg.norm(H, axis=-1) * (np.linalg.norm(H, axis=-1) + H[..., 2])
    )
    D = abc_ndf_norm_by_quadrature(B, C) / (1 + B * x) ** C
    ci, co, hz, vh = wi[..., 2], wo[..., 2], h[..., 2], np.sum(wo * h, -1)
    G = np.minimum(1.0, np.minimum(2 * hz * co / vh, 2 * hz * ci / vh))
    ts = D * an.fresnel(vh, ior) * G / (4 * ci * co)
    A = an.low_microfacet_A_from_ndf(B, C)
    np.testing.assert_allclose(an.low_microfacet(wi, wo, A, B, C, material=ior), ts, rtol=1e-10)


def test_microfacet_at_h_equal_n():
    """ĥ = n: S = A, G = 1, so f = kd/π + A F(θ)/(π cos²θ) (Löw et al. 2012, eq. 15)."""
    theta = np.radians([0.0, 10.0, 45.0, 75.0])
    wi, wo = spherical(theta, 1.0), spherical(theta, 1.0 + np.pi)
    f = an.low_microfacet(wi, wo, 0.7, 1e8, 1 - 1e-9, kd=0.05, material=1.5)
    expect = 0.05 / np.pi + 0.7 * an.fresnel(np.cos(theta), 1.5) / (np.pi * np.cos(theta) ** 2)
    np.testing.assert_allclose(f, expect, rtol=1e-12)


# --- samplers: χ² against the integrated pdf -----------------------------------------------------
N_SAMPLES = 1_000_000
SMOOTH_CASES = [(B, t) for B in (10.0, 1e3) for t in (0.0, 45.0, 80.0)]
FACET_CASES = [
    (B, C, t) for B in (10.0, 1e3) for C in (1.0, 1 - 1e-9, 2.5) for t in (0.0, 45.0, 80.0)
]
ALPHA = sidak(0.01, len(SMOOTH_CASES) + len(FACET_CASES))
GL_N = 8


def cell_integrals(density, a_edges, b_edges, n):
    """∫∫ density(a, b) da db over every cell of the grid, n×n Gauss–Legendre per cell."""
    x, w = np.polynomial.legendre.leggauss(n)

    def nodes(edges):
        lo, hi = edges[:-1, None], edges[1:, None]
        return 0.5 * (lo + hi) + 0.5 * (hi - lo) * x, 0.5 * (hi - lo) * w

    a, wa = nodes(a_edges)
    b, wb = nodes(b_edges)
    vals = density(a[:, :, None, None], b[None, None, :, :])
    return np.einsum("injm,in,jm->ij", vals, wa, wb)


def cell_edges(pilot, lo, hi, k=10):
    """Edges between lo and hi: k uniform cells merged with k cells at the quantiles of an
    independent pilot sample (fine where the mass is, bounded width in the tails). Few cells
    keep the power against smooth distortions: 20 × 20 cells reject samples drawn with B·1.05
    against the pdf of B (p ≈ 1e-5 at B = 1e3, θo = 45°), 47 × 47 cells did not (p ≈ 0.08)."""
    e = np.quantile(pilot, np.linspace(0, 1, k + 1))
    e[0], e[-1] = lo, hi
    return np.unique(np.concatenate([e, np.linspace(lo, hi, k + 1)]))


def chi2_against_pdf(coords, density, pilot, ranges):
    """Pearson χ² of the samples' cell counts against the quadrature of ``density``.

    Asserts first that the pdf integrates to 1 over the domain and that the quadrature error
    (n vs 2n Gauss points) is far below the statistical one. Returns the p-value."""
    (a_lo, a_hi), (b_lo, b_hi) = ranges
    a_edges = cell_edges(pilot[0], a_lo, a_hi)
    b_edges = cell_edges(pilot[1], b_lo, b_hi)
    p_n = cell_integrals(density, a_edges, b_edges, GL_N)
    p_2n = cell_integrals(density, a_edges, b_edges, 2 * GL_N)
    n = coords[0].size
    assert abs(p_2n.sum() - 1.0) < 1e-6, f"pdf integrates to {p_2n.sum()}"
    # the quadrature error may add at most 1 to χ² (whose own s.d. is √(2 dof) ≈ 28)
    assert np.sum(n * (p_n - p_2n) ** 2 / np.maximum(p_2n, 1.0 / n)) < 1.0
    counts, _, _ = np.histogram2d(coords[0], coords[1], bins=[a_edges, b_edges])
    assert counts.sum() == n
    _, _, p = pearson_chi2(counts, n * p_2n)
    return p


def smooth_coords(wi):
    return np.sqrt(np.sum(wi[..., :2] ** 2, -1)), np.arctan2(wi[..., 1], wi[..., 0])


@pytest.mark.parametrize("B,theta_o", SMOOTH_CASES)
def test_sample_low_smooth_chi2(B, theta_o):
    """Samples of Löw et al. 2012, eq. 20–22 follow pdf_low_smooth (eq. 17–19), in (r, φ) disk
    coordinates."""
    rng = np.random.default_rng(int(B) * 100 + int(theta_o))
    wo = spherical_deg(theta_o, 180.0)  # lobe centred at φ = 0, away from the seam
    pilot = an.sample_low_smooth(wo, rng.random(100_000), rng.random(100_000), B)
    s = an.sample_low_smooth(wo, rng.random(N_SAMPLES), rng.random(N_SAMPLES), B)
    assert np.all(s.wi[..., 2] >= 0)  # the disk maps onto the upper hemisphere only
    np.testing.assert_array_equal(s.above, s.wi[..., 2] > 0)
    np.testing.assert_allclose(s.pdf[:100_000], an.pdf_low_smooth(s.wi[:100_000], wo, B), rtol=1e-9)

    def density(r, phi):  # area density on the disk × r
        wi = spherical(np.arcsin(r), phi)
        return an.pdf_low_smooth(wi, wo, B) / wi[..., 2] * r

    p = chi2_against_pdf(
        smooth_coords(s.wi), density, smooth_coords(pilot.wi), ((0.0, 1.0), (-np.pi, np.pi))
    )
    assert p > ALPHA


def facet_frame(wo):
    """Unit e1, e2 ⊥ wo with the mirror direction of wo at β = 0 (polar angles about −wo)."""
    t, phi = np.arccos(wo[2]), np.arctan2(wo[1], wo[0])
    e1 = np.array([-np.cos(t) * np.cos(phi), -np.cos(t) * np.sin(phi), np.sin(t)])
    e2 = np.array([np.sin(phi), -np.cos(phi), 0.0])
    return e1, e2


def facet_coords(wi, wo, e1, e2):
    """(α, β): α = angle from −wo (where the wi-density has its 1/|H| singularity), β azimuth."""
    a = np.arctan2(np.linalg.norm(np.cross(wi, -wo), axis=-1), np.sum(wi * -wo, -1))
    return a, np.arctan2(np.sum(wi * e2, -1), np.sum(wi * e1, -1))


@pytest.mark.parametrize("B,C,theta_o", FACET_CASES)
def test_sample_low_microfacet_chi2(B, C, theta_o):
    """Samples of Löw et al. 2012, eq. 25–27 follow pdf_low_microfacet (eq. 28) over the whole
    sphere of wi
    (below-horizon samples counted). Cells are polar about −wo, where pdf·sin α stays finite."""
    rng = np.random.default_rng(int(B) * 1000 + int(C * 10) + int(theta_o))
    wo = spherical_deg(theta_o, 30.0)
    e1, e2 = facet_frame(wo)
    pilot = an.sample_low_microfacet(wo, rng.random(100_000), rng.random(100_000), B, C)
    s = an.sample_low_microfacet(wo, rng.random(N_SAMPLES), rng.random(N_SAMPLES), B, C)
    np.testing.assert_array_equal(s.above, s.wi[..., 2] > 0)
    np.testing.assert_allclose(
        s.pdf[:100_000], an.pdf_low_microfacet(s.wi[:100_000], wo, B, C), rtol=1e-8
    )

    def density(a, b):
        wi = -np.cos(a)[..., None] * wo + np.sin(a)[..., None] * (
            np.cos(b)[..., None] * e1 + np.sin(b)[..., None] * e2
        )
        return an.pdf_low_microfacet(wi, wo, B, C) * np.sin(a)

    p = chi2_against_pdf(
        facet_coords(s.wi, wo, e1, e2),
        density,
        facet_coords(pilot.wi, wo, e1, e2),
        ((0.0, np.pi), (-np.pi, np.pi)),
    )
    assert p > ALPHA


@pytest.mark.parametrize("B", [1e-3, 10.0, 1e3, 1e8])
@pytest.mark.parametrize("C", [0.3, 1 - 1e-9, 1.0, 1 + 1e-9, 2.5])
def test_halfvector_pdf_integrates_to_one(B, C):
    """∫ P_h dω = 2π ∫₀¹ P_h dx over the upper hemisphere (Löw et al. 2012, eq. 23–24), in w = ln(1
    + Bx)."""

    def integrand(w):
        x = np.expm1(w) / B
        h = np.stack([np.sqrt(x * (2 - x)), 0 * x, 1 - x], -1)
        return 2 * np.pi * an.pdf_low_halfvector(h, B, C) * np.exp(w) / B

    val, _ = integrate.quad(integrand, 0.0, np.log1p(B), epsabs=0, epsrel=1e-12, limit=200)
    assert abs(val - 1.0) < 1e-10


def decimal_tilt_quantile(u, B, C):
    """Löw et al. 2012, eq. 25 in 60-digit decimal arithmetic: x = 1 − cos θh at tilt CDF value
    u."""
    getcontext().prec = 60
    u = u if isinstance(u, Decimal) else Decimal(repr(float(u)))
    B, C = Decimal(repr(float(B))), Decimal(repr(float(C)))
    if C == 1:
        return ((u * (1 + B).ln()).exp() - 1) / B
    a = 1 - C
    inner = 1 + u * ((a * (1 + B).ln()).exp() - 1)
    return ((inner.ln() / a).exp() - 1) / B


@pytest.mark.parametrize("B", [10.0, 1e3, 1e8])
@pytest.mark.parametrize("C", [0.3, 1 - 1e-9, 1.0, 1 + 1e-9, 2.5])
def test_tilt_quantile_precision(B, C):
    """The half-vector tilt quantile matches eq. 25 evaluated in 60-digit arithmetic, also for
    C = 1 ± 1e-9 and B = 1e8 (docs/design.md numerical hazard), to a few ulps plus the quantile's
    own
    conditioning (the change of x when u moves by one ulp; large in the C > 1 tail).
    The private quantile is tested directly: reconstructing 1 − ĥ·n from a sampled wi is itself
    ill-conditioned near ĥ ⊥ wo."""
    u = np.array([0.0, 1e-12, 1e-6, 0.1, 0.5, 0.9, 0.999999, 1 - 1e-12, 1.0])
    ref = [decimal_tilt_quantile(ui, B, C) for ui in u]
    ulp = 1 + Decimal(2) ** -52
    one_ulp = [
        abs(decimal_tilt_quantile(Decimal(repr(float(ui))) * ulp, B, C) - r)
        for ui, r in zip(u, ref)
    ]
    ref, one_ulp = np.array(ref, dtype=float), np.array(one_ulp, dtype=float)
    err = np.abs(an.low._tilt_quantile(u, B, C) - ref)
    assert np.all(err <= 1e-13 * ref + 4 * one_ulp), (err, ref, one_ulp)


def test_sampled_tilts_use_the_quantile():
    """sample_low_microfacet draws ĥ at the quantile of u1 (wo = n, where wi = 2h_z ĥ − n)."""
    u = np.linspace(0.0, 0.99, 12)
    s = an.sample_low_microfacet([0.0, 0.0, 1.0], u, 0.3, 1e8, 1 + 1e-9)
    H = s.wi + np.array([0.0, 0.0, 1.0])
    nH = np.linalg.norm(H, axis=-1)
    x = np.sum(H[..., :2] ** 2, -1) / (nH * (nH + H[..., 2]))
    # the reconstruction loses ~1e-16/(1 − x) absolutely in H_z; u ≤ 0.99 keeps 1 − x ≳ 0.7
    ref = [float(decimal_tilt_quantile(ui, 1e8, 1 + 1e-9)) for ui in u]
    np.testing.assert_allclose(x, ref, rtol=1e-12, atol=1e-30)


# --- stability: no NaN/inf on the closed hemisphere ----------------------------------------------
angle = st.floats(0.0, 90.0)
azimuth = st.floats(0.0, 360.0)
B_values = st.sampled_from([1e-3, 10.0, 1e3, 1e8])
C_values = st.sampled_from([0.3, 1 - 1e-9, 1.0, 1 + 1e-9, 2.5])
unit = st.floats(0.0, 1.0)


def exact_dir(theta_deg, phi_deg):
    """spherical_deg, but exactly on the horizon at 90° and exactly n at 0°."""
    w = spherical_deg(theta_deg, phi_deg)
    if theta_deg == 90.0:
        w = np.array([w[0], w[1], 0.0]) / np.hypot(w[0], w[1])
    return w


@settings(max_examples=300, deadline=None)
@given(angle, azimuth, angle, azimuth, B_values, C_values)
@example(90.0, 0.0, 90.0, 180.0, 1e8, 1 + 1e-9)  # both on the horizon, wi = −wo
@example(90.0, 0.0, 90.0, 0.0, 1e8, 1 - 1e-9)  # wi = wo on the horizon
@example(35.0, 10.0, 35.0, 190.0, 1e8, 1.0)  # ĥ = n
@example(0.0, 0.0, 0.0, 0.0, 1e8, 2.5)
def test_models_and_pdfs_finite(ti, pi_, to, po, B, C):
    wi, wo = exact_dir(ti, pi_), exact_dir(to, po)
    vals = [
        an.low_smooth(wi, wo, 1.0, B, C, kd=0.1, material=AL, obliquity=o)
        for o in an.LOW_OBLIQUITIES
    ]
    vals += [an.low_microfacet(wi, wo, 1.0, B, C, kd=0.1, material=ior) for ior in (1.5, AL, None)]
    vals += [
        an.rayleigh_rice(wi, wo, LAMBDA, 1e-3, B, C, ior, p)
        for ior in (1.5, AL)
        for p in ("unpolarised", "ss", "pp")
    ]
    vals += [
        an.pdf_low_smooth(wi, wo, B),
        an.pdf_low_microfacet(wi, wo, B, C),
        an.pdf_low_halfvector(half_vector(wi, wo), B, C),
    ]
    for v in vals:
        assert np.isfinite(v) and v >= 0.0


@settings(max_examples=300, deadline=None)
@given(angle, azimuth, unit, unit, B_values, C_values)
@example(90.0, 0.0, 0.0, 0.0, 1e8, 1.0)  # wo on the horizon, ĥ = n: wi = −wo
@example(90.0, 0.0, 1.0, 1.0, 1e8, 1 + 1e-9)
@example(0.0, 0.0, 1.0, 0.5, 1e8, 1 - 1e-9)
@example(2.2250738585e-313, 0.0, 1.0, 0.0, 1e-3, 0.3)  # ĥ on the horizon, wo·ĥ denormal
def test_samplers_finite(to, po, u1, u2, B, C):
    wo = exact_dir(to, po)
    for s in (an.sample_low_smooth(wo, u1, u2, B), an.sample_low_microfacet(wo, u1, u2, B, C)):
        assert np.all(np.isfinite(s.wi)) and np.isfinite(s.pdf) and s.pdf >= 0.0
        assert abs(np.linalg.norm(s.wi) - 1.0) < 1e-12


def test_smooth_sampler_stays_in_upper_hemisphere_for_sharp_lobes():
    wo = spherical_deg(89.0, 0.0)
    s = an.sample_low_smooth(wo, RNG.random(100_000), RNG.random(100_000), 1e8)
    assert np.all(s.wi[..., 2] >= 0.0) and np.all(np.isfinite(s.pdf)) and np.all(s.pdf > 0)
    np.testing.assert_allclose(s.pdf, an.pdf_low_smooth(s.wi, wo, 1e8), rtol=1e-9)


# --- fit metrics ---------------------------------------------------------------------------------
def hemisphere_grid(step=1.0):
    """Bin centres and widths (degrees) of a θo × φo grid over the hemisphere."""
    t = np.arange(step / 2, 90.0, step)
    p = np.arange(step / 2, 360.0, step)
    return np.meshgrid(t, p, indexing="ij"), step


def test_e1_is_the_riemann_sum_of_eq_33():
    """With cosθi(f_meas − f_model) = δ everywhere, E1 → δ² Δθi ∫ sinθo dθo dφo = 2π δ² Δθi."""
    (to, _), step = hemisphere_grid()
    ti, delta, d_ti = 30.0, 0.2, 10.0
    model = np.full(to.shape, 1.0)
    measured = model + delta / np.cos(np.radians(ti))
    e1 = an.low_e1(measured, model, ti, to, d_ti, step, step)
    # midpoint rule on sinθ: relative error ≈ (Δθ)²/24 ≈ 1.3e-5 for 1° bins
    np.testing.assert_allclose(e1, 2 * np.pi * delta**2 * np.radians(d_ti), rtol=1e-4)
    assert an.low_e1(model, model, ti, to, d_ti, step, step) == 0.0


def test_e2_uses_log_of_one_plus_cosine_weighted_brdf():
    (to, _), step = hemisphere_grid()
    ti, f1, f2 = 60.0, 3.0, 0.5
    c = np.cos(np.radians(ti))
    e2 = an.low_e2(np.full(to.shape, f1), f2, ti, to, 10.0, step, step)
    expect = 2 * np.pi * np.radians(10.0) * (np.log1p(c * f1) - np.log1p(c * f2)) ** 2
    np.testing.assert_allclose(e2, expect, rtol=1e-4)


def test_fit_metric_errors():
    with pytest.raises(ValueError, match="d_theta_o"):
        an.low_e1(1.0, 1.0, 10.0, 10.0, 1.0, 0.0, 1.0)
    with pytest.raises(ValueError, match="theta_o"):
        an.low_e1(1.0, 1.0, 10.0, 95.0, 1.0, 1.0, 1.0)
    with pytest.raises(ValueError, match="measured"):
        an.low_e2(-3.0, 1.0, 0.0, 10.0, 1.0, 1.0, 1.0)


# --- argument validation -------------------------------------------------------------------------
Z = np.array([0.0, 0.0, 1.0])
W = spherical_deg(30.0, 0.0)


@pytest.mark.parametrize(
    "call,name",
    [
        (lambda: an.abc_psd(1.0, 1.0, 0.0, 1.0), "B"),
        (lambda: an.abc_psd(1.0, 1.0, 1.0, -1.0), "C"),
        (lambda: an.abc_psd(1.0, -1.0, 1.0, 1.0), "A"),
        (lambda: an.low_smooth(Z, W, 1.0, -2.0, 1.0), "B"),
        (lambda: an.low_smooth(Z, W, 1.0, 2.0, 0.0), "C"),
        (lambda: an.low_smooth(Z, W, -1.0, 2.0, 1.0), "A"),
        (lambda: an.low_smooth(Z, W, 1.0, 2.0, 1.0, kd=-0.1), "kd"),
        (lambda: an.low_smooth(Z, W, 1.0, 2.0, 1.0, obliquity="bad"), "obliquity"),
        (lambda: an.low_microfacet(Z, W, 1.0, 0.0, 1.0), "B"),
        (lambda: an.low_microfacet(Z, W, 1.0, 2.0, -1.0), "C"),
        (lambda: an.low_microfacet(Z, W, -1.0, 2.0, 1.0), "A"),
        (lambda: an.low_microfacet(Z, W, 1.0, 2.0, 1.0, kd=-1.0), "kd"),
        (lambda: an.low_microfacet(Z, W, 1.0, 2.0, 1.0, shadowing="smith"), "shadowing"),
        (lambda: an.rayleigh_rice(Z, W, 0.0, 1.0, 2.0, 1.0, 1.5), "wavelength"),
        (lambda: an.rayleigh_rice(Z, W, -0.5, 1.0, 2.0, 1.0, 1.5), "wavelength"),
        (lambda: an.rayleigh_rice(Z, W, 0.5, -1.0, 2.0, 1.0, 1.5), "A"),
        (lambda: an.rayleigh_rice(Z, W, 0.5, 1.0, 0.0, 1.0, 1.5), "B"),
        (lambda: an.rayleigh_rice(Z, W, 0.5, 1.0, 2.0, 0.0, 1.5), "C"),
        (lambda: an.rayleigh_rice(Z, W, 0.5, 1.0, 2.0, 1.0, None), "ior"),
        (lambda: an.rayleigh_rice(Z, W, 0.5, 1.0, 2.0, 1.0, 1.5, "x"), "polarisation"),
        (lambda: an.sample_low_smooth(Z, 0.5, 0.5, 0.0), "B"),
        (lambda: an.sample_low_smooth(Z, 1.5, 0.5, 1.0), "u1"),
        (lambda: an.sample_low_microfacet(Z, 0.5, 0.5, -1.0, 1.0), "B"),
        (lambda: an.sample_low_microfacet(Z, 0.5, 0.5, 1.0, 0.0), "C"),
        (lambda: an.pdf_low_microfacet(W, Z, 1.0, -1.0), "C"),
        (lambda: an.pdf_low_smooth(W, Z, -1.0), "B"),
        (lambda: an.pdf_low_halfvector(Z, 0.0, 1.0), "B"),
        (lambda: an.low_microfacet_A_from_ndf(1.0, 0.0), "C"),
        (lambda: an.sample_low_smooth(-Z, 0.5, 0.5, 1.0), "wo"),
    ],
)
def test_invalid_parameters_are_named(call, name):
    with pytest.raises(ValueError, match=rf"\b{name}\b"):
        call()
