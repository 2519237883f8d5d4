"""Tests of the halfway-vector-disk models (Edwards et al. 2006).

Facts checked: the projections are bijections between the halfway disk and the unit disk centred
at wo_xy (eq. 15/21, 22/25); their Jacobians agree with finite differences and with the paper's
eq. 19/23; the framework BRDF (eq. 11, 20, 24, 33) has albedo exactly 1 for every wo; lumps
(eq. 26–27) have unit volume; the lump sampler (eq. 28–29) and ``sample_edwards`` draw from the
densities they report (Pearson χ², α = 0.01 with Šidák over the 9 sampler tests).
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st
from scipy import integrate
from support import pearson_chi2, sidak

from microsim.analytic import edwards as ed
from microsim.vectors import half_vector, spherical, spherical_deg

PI = np.pi
N_SAMPLER_TESTS = 9  # 3 lump-sampler + 6 sample_edwards χ² tests
ALPHA = sidak(0.01, N_SAMPLER_TESTS)
N_SAMPLES = 1_000_000


def direction(theta_deg, phi_deg):
    """Unit vector; θ = 90° gives z = 0 exactly (not cos(π/2) ≈ 6e-17)."""
    w = spherical_deg(theta_deg, phi_deg)
    return np.where(np.asarray(theta_deg)[..., None] == 90.0, w * [1, 1, 0], w)


# --------------------------------------------------------------------------------------------
# quadrature helpers
# --------------------------------------------------------------------------------------------
def graded_edges(lo, hi, centres, hmin=1e-5, n_uniform=16):
    """Panel edges: uniform on [lo, hi] plus geometric grading (ratio 2) towards each centre."""
    steps = hmin * 2.0 ** np.arange(60)
    steps = steps[steps < hi - lo]
    parts = [np.linspace(lo, hi, n_uniform + 1)]
    for c in centres:
        parts += [c + steps, c - steps, [c]]
    return np.unique(np.clip(np.concatenate(parts), lo, hi))


def gauss_nodes(edges, order):
    """Composite Gauss–Legendre nodes and weights on the panels given by ``edges``."""
    x, w = np.polynomial.legendre.leggauss(order)
    a, b = edges[:-1, None], edges[1:, None]
    return (0.5 * (b - a) * x + 0.5 * (a + b)).ravel(), (0.5 * (b - a) * w).ravel()


def hemisphere_integral(f, theta_centres, phi_centres, order=6):
    """∫ f(wi) dω_i over the upper hemisphere (θ, φ ∈ [−π/2, 3π/2]) on graded panels."""
    th, wt = gauss_nodes(graded_edges(0.0, PI / 2, theta_centres), order)
    ph, wp = gauss_nodes(graded_edges(-PI / 2, 1.5 * PI, phi_centres), order)
    T, P = np.meshgrid(th, ph, indexing="ij")
    return np.sum(f(spherical(T, P)) * np.sin(T) * wt[:, None] * wp[None, :])


def cell_integrals(f, x_edges, y_edges, order=6):
    """∫∫ f(x, y) over each cell of the tensor grid (shape (len(x)−1, len(y)−1))."""
    xg, wx = np.polynomial.legendre.leggauss(order)

    def nodes(e):
        a, b = e[:-1, None], e[1:, None]
        return 0.5 * (b - a) * xg + 0.5 * (a + b), 0.5 * (b - a) * wx

    X, WX = nodes(np.asarray(x_edges, float))
    Y, WY = nodes(np.asarray(y_edges, float))
    vals = f(X[:, None, :, None], Y[None, :, None, :])
    return np.einsum("ijab,ia,jb->ij", vals, WX, WY)


# --------------------------------------------------------------------------------------------
# projections
# --------------------------------------------------------------------------------------------
angles_o = st.floats(0.0, 89.9)
azimuths = st.floats(0.0, 360.0)


@settings(max_examples=200, deadline=None)
@given(angles_o, azimuths, st.floats(0.0, 90.0), azimuths)
@example(0.0, 0.0, 0.0, 0.0)
@example(89.9, 0.0, 90.0, 180.0)
@example(89.9, 10.0, 90.0, 10.0)
@example(45.0, 0.0, 90.0, 90.0)
@example(60.595649451866436, 131.98120147117726, 89.99999999999999, 89.9375)  # 5.5ε in |d|²
def test_projection_round_trip_and_image_in_unit_disk(theta_o, phi_o, theta_i, phi_i):
    """h → (u, v) → h to 1e-10. The orthogonal inverse recovers cos θi = √(1 − |uv − wo_xy|²);
    |uv − wo_xy|² carries a rounding error ≲ 8ε (each component of d = uv − wo_xy is ≈ unit
    on the rim and off by up to ~3 ulp from h's rounding, the forward projection and the
    subtraction, so 2(|δd_x| + |δd_y|) ≲ 6ε, plus ≲ 2ε from squaring and summing; 5.5ε
    measured in the example at θi = 90°), so cos θi is off by ≲ 8ε/cos θi (√(8ε) ≈ 4e-8 on the
    horizon) — intrinsic, as dA/dω = cos θi → 0 at the rim. It enters h divided by |wi + wo|,
    and that term is added to the tolerance."""
    wo, wi = direction(theta_o, phi_o), direction(theta_i, phi_i)
    h = half_vector(wi, wo)
    eps = np.finfo(float).eps
    rim = 8 * eps / max(wi[2], np.sqrt(8 * eps)) / np.linalg.norm(wi + wo)
    for proj in ed.DISK_PROJECTIONS:
        uv = ed.disk_projection(wo, h, proj)
        tol = 1e-10 + (rim if proj == "orthogonal" else 0.0)
        assert np.abs(ed.disk_projection_inverse(wo, uv, proj) - h).max() <= tol
        r = np.linalg.norm(uv - ed.disk_centre(wo))
        assert r <= 1.0 + 1e-12  # halfway disk → unit disk around wo_xy
        if theta_i == 90.0:  # horizon ↔ rim of the disk
            assert abs(r - 1.0) <= 1e-10


@settings(max_examples=200, deadline=None)
@given(angles_o, azimuths, st.floats(0.0, 1.0), st.floats(0.0, 2 * PI))
@example(0.0, 0.0, 1.0, 0.0)
@example(89.9, 0.0, 1.0, PI)
@example(89.9, 0.0, 0.0, 0.0)
def test_every_disk_point_is_a_halfway_vector(theta_o, phi_o, r, psi):
    """Surjectivity: each point of the unit disk around wo_xy comes from an upper-hemisphere wi."""
    wo = direction(theta_o, phi_o)
    uv = ed.disk_centre(wo) + r * np.array([np.cos(psi), np.sin(psi)])
    for proj in ed.DISK_PROJECTIONS:
        h = ed.disk_projection_inverse(wo, uv, proj)
        wi = ed.reflect_halfway(wo, h)
        assert abs(np.linalg.norm(wi) - 1.0) <= 1e-12
        assert wi[2] >= -1e-12
        if r == 1.0:
            assert wi[2] <= 1e-7  # rim → horizon (√ of a rounding error ≤ 1.5e-8)
        assert np.abs(ed.disk_projection(wo, h, proj) - uv).max() <= 1e-10
        assert np.abs(ed.disk_to_incident(wo, uv, proj) - wi).max() <= 1e-12


def test_special_points_of_the_disk():
    """(u, v) = 0 is mirror reflection in both projections; the disk centre is retro-reflection
    in the scaling projection (Edwards et al. 2006, §3.1) and wi = n in the orthogonal one, whose
    retro point
    is 2 wo_xy ((u, v) = wo_xy + wi_xy, eq. 22)."""
    wo = spherical_deg(np.array([0.0, 35.0, 80.0]), np.array([0.0, 120.0, 300.0]))
    mirror, normal = wo * [-1, -1, 1], np.array([0.0, 0.0, 1.0])
    c = ed.disk_centre(wo)
    for proj in ed.DISK_PROJECTIONS:
        assert np.allclose(ed.disk_to_incident(wo, np.zeros(2), proj), mirror, atol=1e-12)
    assert np.allclose(ed.disk_to_incident(wo, c, "scaling"), wo, atol=1e-12)
    assert np.allclose(ed.disk_to_incident(wo, c, "orthogonal"), normal, atol=1e-12)
    assert np.allclose(ed.disk_to_incident(wo, 2 * c, "orthogonal"), wo, atol=1e-12)


# --------------------------------------------------------------------------------------------
# Jacobians
# --------------------------------------------------------------------------------------------
def fd_jacobian(wo, theta, phi, proj, step):
    """|det ∂(u, v)/∂(θi, φi)| / sin θi by central differences: dA_disk/dω_i."""

    def uv(t, p):
        return ed.incident_to_disk(spherical(t, p), wo, proj)

    d_t = (uv(theta + step, phi) - uv(theta - step, phi)) / (2 * step)
    d_p = (uv(theta, phi + step) - uv(theta, phi - step)) / (2 * step)
    return np.abs(d_t[..., 0] * d_p[..., 1] - d_t[..., 1] * d_p[..., 0]) / np.sin(theta)


@pytest.mark.parametrize("proj", ed.DISK_PROJECTIONS)
def test_jacobian_matches_finite_differences(proj):
    """FD error of the step-δ estimate ≈ |FD(δ) − FD(2δ)|/3 (O(δ²)); allow that estimate itself
    plus rounding (ε|uv|/δ ≈ 1e-12) — i.e. a 3× margin on the truncation error."""
    to, ti, pi_ = np.meshgrid(
        np.radians([0.0, 30.0, 60.0, 85.0]),
        np.radians([5.0, 40.0, 70.0, 85.0]),
        np.radians([0.0, 60.0, 150.0, 200.0]),
        indexing="ij",
    )
    wo = spherical(to, np.radians(20.0))
    delta = 1e-4
    fd1 = fd_jacobian(wo, ti, pi_, proj, delta)
    fd2 = fd_jacobian(wo, ti, pi_, proj, 2 * delta)
    J = ed.disk_jacobian(spherical(ti, pi_), wo, proj)
    assert np.all(np.abs(fd1 - J) <= np.abs(fd1 - fd2) + 1e-9 * (1.0 + J))


def test_jacobians_equal_paper_forms():
    """J = (dμ/dΩ(Ĥ)) / (4 wi·Ĥ) with dμ/dΩ from Edwards et al. 2006, eq. 19 and eq. 23."""
    rng = np.random.default_rng(7)
    wo = spherical(np.arccos(rng.random(500)), 2 * PI * rng.random(500))
    wi = spherical(np.arccos(rng.random(500)), 2 * PI * rng.random(500))
    H = half_vector(wi, wo)
    wi_h = np.sum(wi * H, -1)
    eq19 = wo[:, 2] ** 2 / H[:, 2] ** 3
    eq23 = np.sum((wi + wo) ** 2, -1) * wi[:, 2] / wi_h
    assert np.allclose(ed.scaling_jacobian(wi, wo), eq19 / (4 * wi_h), rtol=1e-12)
    assert np.allclose(ed.orthogonal_jacobian(wi, wo), eq23 / (4 * wi_h), rtol=1e-12)


def test_brdfs_equal_paper_forms():
    """edwards_empirical reproduces eq. 20 (scaling) and eq. 24 (orthogonal) literally."""
    rng = np.random.default_rng(8)
    wo = spherical(np.arccos(rng.random(500)), 2 * PI * rng.random(500))
    wi = spherical(np.arccos(rng.random(500)), 2 * PI * rng.random(500))
    H = half_vector(wi, wo)
    wi_h = np.sum(wi * H, -1)

    def density(uv, wo_):
        return np.exp(-np.sum(uv * uv, -1))  # any function of (u, v)

    p_s = density(ed.scaling_projection(wo, H), wo)
    p_o = density(ed.orthogonal_projection(wo, H), wo)
    eq20 = p_s * wo[:, 2] ** 2 / (4 * wi[:, 2] * wi_h * H[:, 2] ** 3)
    eq24 = p_o * np.sum((wi + wo) ** 2, -1) / (4 * wi_h**2)
    assert np.allclose(ed.edwards_empirical(wi, wo, density, "scaling"), eq20, rtol=1e-12)
    assert np.allclose(ed.edwards_empirical(wi, wo, density, "orthogonal"), eq24, rtol=1e-12)


# --------------------------------------------------------------------------------------------
# white furnace (energy conservation, Edwards et al. 2006, eq. 4, 11)
# --------------------------------------------------------------------------------------------
def albedo(brdf, wo, theta_o):
    """∫ f cos θi dω_i by graded composite Gauss–Legendre (order 6) in (θi, φi), panels refined
    geometrically down to 1e-5 rad around θo, the horizon and the azimuths φ = 0 and π of the
    plane of incidence, where the lumps live. Its error on these integrands is < 1e-4 (checked
    against orders 8 and 12 during development), far below the 1e-3 asserted."""

    def f(wi):
        return brdf(wi, wo) * np.maximum(wi[..., 2], 0.0)

    return hemisphere_integral(f, [theta_o, PI / 2], [0.0, PI])


def uniform_disk(uv, wo):
    """p = 1/π on the unit disk around wo_xy: a callable disk density."""
    return np.where(np.sum((uv - wo[..., :2]) ** 2, -1) <= 1.0, 1.0 / PI, 0.0)


@pytest.mark.parametrize("proj", ed.DISK_PROJECTIONS)
@pytest.mark.parametrize(
    "density",
    [
        ed.empirical_lumps(k=0.3, n_s=3, n_r=4),
        ed.empirical_lumps(k=0.3, n_s=60, n_r=4),
        uniform_disk,
    ],
    ids=["wide", "narrow", "uniform-callable"],
)
def test_white_furnace(proj, density):
    for theta_o in (0.0, 30.0, 60.0, 80.0, 89.0):
        wo = spherical_deg(theta_o, 0.0)
        a = albedo(
            lambda wi, w: ed.edwards_empirical(wi, w, density, proj), wo, np.radians(theta_o)
        )
        assert abs(a - 1.0) < 1e-3, (proj, theta_o, a)


@pytest.mark.parametrize("proj", ed.DISK_PROJECTIONS)
def test_albedo_with_fresnel_and_diffuse(proj):
    """Eq. 33: albedo = (1 − F(θo)) C_d + F(θo) with Schlick F (eq. 30)."""
    lumps = ed.empirical_lumps(k=0.2, n_s=10, n_r=2)
    for theta_o in (20.0, 75.0):
        wo = spherical_deg(theta_o, 0.0)
        F = 0.04 + 0.96 * (1 - np.cos(np.radians(theta_o))) ** 5
        a = albedo(
            lambda wi, w: ed.edwards_empirical(wi, w, lumps, proj, fresnel=0.04, diffuse=0.5),
            wo,
            np.radians(theta_o),
        )
        assert abs(a - ((1 - F) * 0.5 + F)) < 1e-3


def lump_mass_on_disk(R, n, s):
    """Mass of the eq. 26 lump (radius R, exponent n, centred at the origin) inside the unit disk
    centred at distance s: ∫ (n+1)/(πR²)(1 − r²/R²)^n · 2r · α(r) dr, where α(r) ∈ [0, π] is the
    half-angle of the circle of radius r inside the disk, cos α = (r² + s² − 1)/(2rs)."""

    def integrand(r):
        alpha = np.arccos(np.clip((r * r + s * s - 1) / (2 * r * s), -1.0, 1.0))
        return (n + 1) / (PI * R * R) * (1 - r * r / R / R) ** n * 2 * r * alpha

    points = [1 - s] if 0 < 1 - s < R else None
    return integrate.quad(integrand, 0, R, points=points, epsabs=1e-12, epsrel=1e-12)[0]


def test_fit_brdf_loses_exactly_the_lump_mass_off_the_disk():
    """Eq. 36 (orthogonal): albedo = (1 − F) C_d + F · (mass of the eq. 35 lumps on the disk);
    = (1 − F) C_d + F when the lumps fit, less when they leave the disk (Edwards et al. 2006,
    §5)."""
    theta_o = 50.0
    wo = spherical_deg(theta_o, 0.0)
    for r1 in (0.2, 0.9):  # 1 − sin 50° = 0.234: fits, then leaves the disk
        params = ed.EdwardsParams(cd=0.3, f0=0.05, f90=0.8, k=0.4, r1=r1, n1=8, r2=0.1, n2=3)
        mass = sum(
            w * lump_mass_on_disk(r, n, np.sin(np.radians(theta_o)))
            for w, r, n in [(1 - params.k, params.r1, params.n1), (params.k, params.r2, params.n2)]
        )
        F = params.fresnel(wo[2])
        a = albedo(lambda wi, w: ed.edwards_fit_brdf(wi, w, params), wo, np.radians(theta_o))
        assert abs(a - ((1 - F) * params.cd + F * mass)) < 1e-3
        assert (mass > 0.999) == (r1 < 1 - np.sin(np.radians(theta_o)))


# --------------------------------------------------------------------------------------------
# lumps
# --------------------------------------------------------------------------------------------
LUMP_CASES = [  # (lump, θo): every lump lies on the disk of its wo
    (ed.Lump(0.0), 30.0),
    (ed.Lump(2.5, 0.4, aspect=0.5, anchor="centre", offset=(0.1, -0.2)), 60.0),
    (ed.Lump(40.0, 0.05, aspect=3.0, offset=(0.2, 0.1)), 10.0),
    (ed.Lump(7.0, anchor="centre"), 85.0),
]


@pytest.mark.parametrize("lump,theta_o", LUMP_CASES)
def test_lump_has_unit_volume_on_the_disk(lump, theta_o):
    wo = spherical_deg(theta_o, 40.0)
    assert lump.fits_on_disk(wo)
    (cu, cv), ru, rv = (np.asarray(g) for g in lump.geometry(wo))

    def half(u):
        return rv * np.sqrt(max(0.0, 1 - ((u - cu) / ru) ** 2))

    vol, _ = integrate.dblquad(
        lambda v, u: lump.pdf(wo, np.array([u, v])),
        cu - ru,
        cu + ru,
        lambda u: cv - half(u),
        lambda u: cv + half(u),
        epsabs=1e-10,
        epsrel=1e-10,
    )
    assert abs(vol - 1.0) < 1e-6


def test_mixture_is_the_weighted_sum_of_unit_lumps():
    """Σ w_j p_j with Σ w_j = 1 (eq. 32) — unit volume follows from the lump test above."""
    wo = spherical_deg(45.0, 0.0)
    mix = ed.empirical_lumps(k=0.3, n_s=5, n_r=2)
    uv = np.random.default_rng(3).uniform(-1, 1.7, (1000, 2))
    expect = 0.7 * ed.Lump(5).pdf(wo, uv) + 0.3 * ed.Lump(2, anchor="centre").pdf(wo, uv)
    assert np.allclose(mix.pdf(wo, uv), expect, rtol=1e-14)
    assert sum(mix.weights) == 1.0 and np.all(mix.fits_on_disk(wo))


@pytest.mark.parametrize("lump,theta_o", LUMP_CASES[1:3])
def test_lump_sampler_chi2(lump, theta_o):
    """Cells equal in area in the lump's own (ρ², ψ), ρ² = (Δu/R_u)² + (Δv/R_v)²; expected
    counts integrate ``Lump.pdf`` over each cell (area element R_u R_v/2 dρ² dψ)."""
    wo = spherical_deg(theta_o, 40.0)
    centre, ru, rv = lump.geometry(wo)
    rng = np.random.default_rng(11)
    uv = lump.sample(wo, rng.random(N_SAMPLES), rng.random(N_SAMPLES))
    d = (uv - centre) / [ru, rv]
    rho2, psi = np.sum(d * d, -1), np.mod(np.arctan2(d[:, 1], d[:, 0]), 2 * PI)
    e_r, e_p = np.linspace(0, 1, 21), np.linspace(0, 2 * PI, 17)
    obs, _, _ = np.histogram2d(rho2, psi, [e_r, e_p])

    def pdf(s, p):
        return lump.pdf(
            wo,
            centre
            + np.stack(
                np.broadcast_arrays(ru * np.sqrt(s) * np.cos(p), rv * np.sqrt(s) * np.sin(p)), -1
            ),
        )

    exp = N_SAMPLES * cell_integrals(pdf, e_r, e_p) * ru * rv / 2
    assert obs.sum() == N_SAMPLES
    _, _, p_value = pearson_chi2(obs, exp)
    assert p_value > ALPHA


def test_mixture_sampler_chi2():
    """Cells equal in area on the disk in (r², ψ) about its centre; mixture pdf per cell."""
    wo = spherical_deg(45.0, 0.0)
    mix = ed.empirical_lumps(k=0.3, n_s=5, n_r=2)
    rng = np.random.default_rng(12)
    uv, p = mix.sample(wo, rng.random(N_SAMPLES), rng.random(N_SAMPLES))
    assert np.allclose(p, mix.pdf(wo, uv))
    c = ed.disk_centre(wo)
    d = uv - c
    e_r, e_p = np.linspace(0, 1, 21), np.linspace(0, 2 * PI, 25)
    obs, _, _ = np.histogram2d(
        np.sum(d * d, -1), np.mod(np.arctan2(d[:, 1], d[:, 0]), 2 * PI), [e_r, e_p]
    )

    def pdf(s, q):
        return mix.pdf(
            wo,
            c + np.stack(np.broadcast_arrays(np.sqrt(s) * np.cos(q), np.sqrt(s) * np.sin(q)), -1),
        )

    exp = N_SAMPLES * cell_integrals(pdf, e_r, e_p, order=8) / 2
    _, _, p_value = pearson_chi2(obs, exp)
    assert p_value > ALPHA


# --------------------------------------------------------------------------------------------
# sample_edwards
# --------------------------------------------------------------------------------------------
def lobe_edges(wo, lump, proj, n=12):
    """θ, φ ranges of the lump's rim mapped to wi (to refine cells where the lobe is narrow)."""
    centre, ru, rv = lump.geometry(wo)
    t = np.linspace(0, 2 * PI, 721)
    wi = ed.disk_to_incident(wo, centre + np.stack([ru * np.cos(t), rv * np.sin(t)], -1), proj)
    th = np.arccos(np.clip(wi[:, 2], -1, 1))
    ph = np.mod(np.arctan2(wi[:, 1], wi[:, 0]) + PI / 2, 2 * PI) - PI / 2
    return np.linspace(th.min(), th.max(), n), np.linspace(ph.min(), ph.max(), n)


@pytest.mark.parametrize("proj", ed.DISK_PROJECTIONS)
@pytest.mark.parametrize("theta_o", [0.0, 45.0, 80.0])
def test_sample_edwards_chi2_in_wi(proj, theta_o):
    """wi samples against ∫ pdf_edwards dω over (θi, φi) cells: uniform cells plus cells refined
    over the specular lobe; reported pdf equals pdf_edwards and f cos θi (F = 1)."""
    wo = spherical_deg(theta_o, 0.0)
    mix = ed.empirical_lumps(k=0.3, n_s=4, n_r=3)
    rng = np.random.default_rng(int(13 + theta_o))
    wi, pdf = ed.sample_edwards(wo, rng.random(N_SAMPLES), rng.random(N_SAMPLES), mix, proj)
    assert np.all(pdf > 0) and np.all(wi[:, 2] >= 0)
    sub = slice(0, 2000)
    assert np.allclose(pdf[sub], ed.pdf_edwards(wi[sub], wo, mix, proj), rtol=1e-9)
    assert np.allclose(
        pdf[sub], ed.edwards_empirical(wi[sub], wo, mix, proj) * wi[sub, 2], rtol=1e-9
    )
    lt, lp = lobe_edges(wo, mix.lumps[0], proj)
    e_t = np.unique(np.concatenate([np.linspace(0, PI / 2, 19), lt]))
    e_p = np.unique(np.concatenate([np.linspace(-PI / 2, 1.5 * PI, 25), lp]))
    th = np.arccos(np.clip(wi[:, 2], -1, 1))
    ph = np.mod(np.arctan2(wi[:, 1], wi[:, 0]) + PI / 2, 2 * PI) - PI / 2
    obs, _, _ = np.histogram2d(th, ph, [e_t, e_p])
    mass = cell_integrals(
        lambda t, p: ed.pdf_edwards(spherical(t, p), wo, mix, proj) * np.sin(t), e_t, e_p, order=8
    )
    assert abs(mass.sum() - 1.0) < 1e-3  # quadrature sanity (furnace identity)
    _, _, p_value = pearson_chi2(obs, N_SAMPLES * mass / mass.sum())
    assert p_value > ALPHA


# --------------------------------------------------------------------------------------------
# robustness and validation
# --------------------------------------------------------------------------------------------
angles = st.floats(0.0, 90.0)


@settings(max_examples=150, deadline=None)
@given(angles, azimuths, angles, azimuths, st.floats(0.0, 1.0), st.floats(0.0, 1.0))
@example(0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
@example(90.0, 0.0, 90.0, 180.0, 1.0, 1.0)
@example(90.0, 0.0, 90.0, 0.0, 0.5, 0.5)
@example(90.0, 30.0, 0.0, 0.0, 0.0, 1.0)
@example(0.0, 0.0, 90.0, 10.0, 1.0, 0.0)
@example(89.9999, 0.0, 89.9999, 180.0, 0.999, 0.5)
def test_finite_everywhere(theta_o, phi_o, theta_i, phi_i, u1, u2):
    wo, wi = direction(theta_o, phi_o), direction(theta_i, phi_i)
    h = half_vector(wi, wo)
    lumps = ed.empirical_lumps(k=0.4, n_s=5, n_r=0)
    params = ed.EdwardsParams(cd=0.2, k=0.5, r1=0.3, n1=20, r2=2.0, n2=1)
    for proj in ed.DISK_PROJECTIONS:
        uv = ed.disk_projection(wo, h, proj)
        values = [
            uv,
            ed.disk_projection_inverse(wo, uv, proj),
            ed.disk_jacobian(wi, wo, proj),
            ed.incident_to_disk(wi, wo, proj),
            ed.edwards_empirical(wi, wo, lumps, proj),
            ed.edwards_empirical(wi, wo, lumps, proj, fresnel=0.04, diffuse=0.5),
            ed.edwards_fit_brdf(wi, wo, params, proj),
            ed.pdf_edwards(wi, wo, lumps, proj),
            ed.brdf_to_disk_density(wi, wo, 1.0, proj),
            *ed.sample_edwards(wo, u1, u2, lumps, proj),
            *ed.sample_edwards(wo, u1, u2, params.lumps(), proj),
        ]
        for v in values:
            assert np.all(np.isfinite(v))
        assert ed.edwards_empirical(wi, wo, lumps, proj) >= 0


def test_broadcasting():
    wo = spherical_deg(np.array([10.0, 50.0, 80.0])[:, None], 0.0)  # (3, 1, 3)
    wi = spherical_deg(np.array([0.0, 20.0, 40.0, 60.0]), 170.0)  # (4, 3)
    lumps = ed.empirical_lumps(k=0.2, n_s=8, n_r=2)
    for proj in ed.DISK_PROJECTIONS:
        f = ed.edwards_empirical(wi, wo, lumps, proj)
        assert f.shape == (3, 4)
        assert np.allclose(f[1, 2], ed.edwards_empirical(wi[2], wo[1, 0], lumps, proj))
        wi_s, pdf = ed.sample_edwards(wo, np.full((3, 4), 0.3), np.full((3, 4), 0.7), lumps, proj)
        assert wi_s.shape == (3, 4, 3) and pdf.shape == (3, 4)


def test_edwards_params_vector_and_bounds():
    p = ed.EdwardsParams(cd=0.1, f0=0.2, f90=0.9, k=0.3, r1=0.5, n1=12, r2=1.5, n2=2)
    assert ed.EdwardsParams.from_vector(p.to_vector()) == p
    lo, hi = ed.EdwardsParams.bounds()
    assert lo.shape == hi.shape == (len(ed.EdwardsParams.names()),) and np.all(lo < hi)
    assert np.all((lo <= p.to_vector()) & (p.to_vector() <= hi))
    assert np.all((lo <= ed.EdwardsParams().to_vector()) & (ed.EdwardsParams().to_vector() <= hi))
    F = p.fresnel(np.array([1.0, 0.0]))
    assert np.allclose(F, [p.f0, p.f90])  # eq. 34 end points


@pytest.mark.parametrize(
    "make,match",
    [
        (lambda: ed.Lump(n=-1.0), "Lump.n"),
        (lambda: ed.Lump(radius=0.0), "Lump.radius"),
        (lambda: ed.Lump(radius=-0.2), "Lump.radius"),
        (lambda: ed.Lump(aspect=0.0), "Lump.aspect"),
        (lambda: ed.Lump(anchor="side"), "Lump.anchor"),
        (lambda: ed.Lump(offset=(0.1,)), "Lump.offset"),
        (lambda: ed.LumpMixture((ed.Lump(),), (0.5,)), "weights"),
        (lambda: ed.LumpMixture((ed.Lump(), ed.Lump()), (1.5, -0.5)), "weights"),
        (lambda: ed.empirical_lumps(k=1.5), "k"),
        (lambda: ed.EdwardsParams(r1=0.0), "EdwardsParams.r1"),
        (lambda: ed.EdwardsParams(f0=1.2), "EdwardsParams.f0"),
        (lambda: ed.EdwardsParams(n2=-1.0), "EdwardsParams.n2"),
        (lambda: ed.EdwardsParams.from_vector(np.ones(3)), "x must have shape"),
        (lambda: ed.disk_projection([0, 0, 1.0], [0, 0, 1.0], "stereographic"), "projection"),
        (lambda: ed.edwards_empirical([0, 0, 1.0], [0, 0, 1.0], ed.Lump(), "polar"), "projection"),
        (lambda: ed.sample_edwards([0, 0, 1.0], 0.5, 0.5, ed.Lump(), "x"), "projection"),
        (lambda: ed.sample_edwards([0, 0, 1.0], 0.5, 0.5, uniform_disk), "lumps"),
        (lambda: ed.edwards_empirical([0, 0, 1.0], spherical_deg(60, 0), ed.Lump(2, 0.5)), "lumps"),
        (lambda: ed.edwards_empirical([0, 0, 1.0], [0, 0, 1.0], ed.Lump(), diffuse=2.0), "diffuse"),
        (lambda: ed.edwards_empirical([0, 0, 1.0], [0, 0, 1.0], ed.Lump(), fresnel=-0.1), "f0"),
        (lambda: ed.edwards_empirical([0, 0, 1.0], [0, 0, 1.0], "lump"), "lumps"),
        (lambda: ed.edwards_fit_brdf([0, 0, 1.0], [0, 0, 1.0], {"k": 0}), "params"),
        (lambda: ed.edwards_empirical([0, 0, 1.0], [0, 0, -1.0], ed.Lump()), "wo"),
    ],
)
def test_invalid_arguments_raise(make, match):
    with pytest.raises(ValueError, match=match):
        make()
