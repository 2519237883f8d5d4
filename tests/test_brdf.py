"""Torrance–Sparrow, microfacet sampling, albedo (Mikkelsen 2009, eq. 27) and the eq. 28 mix."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from support import pearson_chi2, sidak

from microsim import analytic as an
from microsim.vectors import spherical

KINDS = ["vgroove", "smith", "smith-correlated", "none"]


def _random_dirs(rng, n, upper=True):
    v = rng.normal(size=(n, 3))
    v /= np.linalg.norm(v, axis=-1, keepdims=True)
    if upper:
        v[:, 2] = np.abs(v[:, 2])
    return v


@pytest.mark.parametrize("kind", KINDS)
@pytest.mark.parametrize("ior", [None, "aluminium", 1.329])
def test_torrance_sparrow_reciprocal(kind, ior):
    rng = np.random.default_rng(1)
    wi, wo = _random_dirs(rng, 100_000), _random_dirs(rng, 100_000)
    for ndf in (an.Beckmann(0.3), an.VonMisesFisher(17.0)):
        f = an.torrance_sparrow(wi, wo, ndf, kind, ior)
        g = an.torrance_sparrow(wo, wi, ndf, kind, ior)
        assert np.all(np.abs(f - g) <= 1e-12 * np.abs(f))
        assert np.all(f >= 0) and np.any(f > 0)


def test_torrance_sparrow_value_and_horizon():
    """Against eq. 13 written out by hand at one configuration; 0 below or at the horizon."""
    ndf = an.Beckmann(0.4)
    wi, wo = spherical(np.radians(40.0), 0.0), spherical(np.radians(25.0), 2.5)
    h = (wi + wo) / np.linalg.norm(wi + wo)
    g = min(1.0, 2 * h[2] * wo[2] / (wo @ h), 2 * h[2] * wi[2] / (wi @ h))
    expected = an.fresnel(wi @ h, 1.329) * ndf.D_cos(h[2]) * g / (4 * wi[2] * wo[2])
    assert np.isclose(an.torrance_sparrow(wi, wo, ndf, "vgroove", 1.329), expected, rtol=1e-12)
    below = np.array([wo[0], wo[1], -wo[2]])
    grazing = np.array([1.0, 0.0, 0.0])
    for kind in KINDS:
        assert an.torrance_sparrow(wi, below, ndf, kind) == 0.0
        assert an.torrance_sparrow(grazing, wo, ndf, kind) == 0.0
        assert an.torrance_sparrow(grazing, -grazing, ndf, kind) == 0.0  # h undefined


def _unit(theta_deg, phi_deg):
    v = spherical(np.radians(theta_deg), np.radians(phi_deg))
    if theta_deg == 90.0:
        v = np.array([v[0], v[1], 0.0]) / np.hypot(v[0], v[1])
    return v


_NDFS = [
    an.Beckmann(0.1),
    an.GGX(0.3),
    an.BlinnPhong(20.0),
    an.VonMisesFisher(1024.0),
    an.ABC(100.0, 1.5),
]


@settings(max_examples=200, deadline=None)
@given(
    ti=st.floats(0.0, 90.0) | st.sampled_from([0.0, 90.0]),
    pi=st.floats(0.0, 360.0),
    to=st.floats(0.0, 90.0) | st.sampled_from([0.0, 90.0]),
    po=st.floats(0.0, 360.0),
    mirror=st.booleans(),
    k=st.integers(0, len(_NDFS) - 1),
    kind=st.sampled_from(KINDS),
    ior=st.sampled_from([None, "aluminium", "methanol"]),
)
def test_torrance_sparrow_finite(ti, pi, to, po, mirror, k, kind, ior):
    wi = _unit(ti, pi)
    wo = np.array([-wi[0], -wi[1], wi[2]]) if mirror else _unit(to, po)  # mirror: h = n
    f = an.torrance_sparrow(wi, wo, _NDFS[k], kind, ior)
    assert np.isfinite(f) and f >= 0.0


def _albedo(ndf, kind, ior, theta, n=2**14):
    return an.directional_albedo(
        theta, lambda a, b: an.torrance_sparrow(a, b, ndf, kind, ior), n=n, ndf=ndf
    )


@pytest.mark.parametrize("ndf", [an.Beckmann(1.0), an.GGX(0.3), an.BlinnPhong(20.0)], ids=repr)
def test_albedo_without_masking_at_normal_incidence(ndf):
    """G = none, F = 1, wi = n: f cos θo dωo = D(h) h_z dω_h, so ρ(0°) = P(θ_h < 45°)
    (wo = 2h_z h − n is above the horizon iff θ_h < 45°): a known number, independent of G."""
    rho, se = _albedo(ndf, "none", None, 0.0)
    assert abs(rho - ndf.cdf_theta_rad(np.pi / 4)) < 1e-3
    table = an.AlbedoTable(ndf, "none", None, n_theta=3, n_grazing=0)
    assert abs(table.rho(1.0) - ndf.cdf_theta_rad(np.pi / 4)) < 1e-5


@pytest.mark.parametrize(
    "ndf, kind, ior",
    [
        (an.Beckmann(0.5), "smith", "methanol"),
        (an.VonMisesFisher(1024.0), "vgroove", "methanol"),
        (an.GGX(0.3), "smith-correlated", "aluminium"),
    ],
    ids=["beckmann-smith", "vmf1024-vgroove", "ggx-correlated"],
)
def test_albedo_table_matches_qmc(ndf, kind, ior):
    """Two independent methods (h-quadrature table, MIS randomised QMC) agree within the
    QMC standard error (5σ) plus the table's stated interpolation accuracy 2e-5."""
    table = an.AlbedoTable(ndf, kind, ior)
    theta = np.array([0.0, 30.0, 60.0, 77.7, 85.0, 88.6, 89.7])
    rho, se = _albedo(ndf, kind, ior, theta)
    assert np.all(np.abs(table.rho(np.cos(np.radians(theta))) - rho) < 5 * se + 2e-5)
    assert np.all((rho <= 1 + 5 * se) & (rho > 0))
    # ρ̄ = 2∫ρ cosθ sinθ dθ against a plain midpoint rule on the QMC-checked interpolant
    t = (np.arange(4000) + 0.5) * (np.pi / 2) / 4000
    assert abs(table.rho_bar - np.sum(table.rho(np.cos(t)) * np.sin(2 * t)) * np.pi / 8000) < 1e-6


def test_a_memoised_albedo_table_is_the_table_built_anew():
    """``AlbedoTable.of``: equal frozen distributions share one table, bitwise the table built
    anew; distributions hashed by identity (a tile's histogram) are told apart."""
    args = ("smith", "aluminium", 9, 4, 6)
    table = an.AlbedoTable.of(an.GGX(0.41), *args)
    assert an.AlbedoTable.of(an.GGX(0.41), *args) is table
    assert an.AlbedoTable.of(an.GGX(0.42), *args) is not table
    fresh = an.AlbedoTable(an.GGX(0.41), *args)
    assert np.array_equal(table.rho_nodes, fresh.rho_nodes) and table.rho_bar == fresh.rho_bar
    normals = spherical(np.full(500, 0.3), np.linspace(0.0, 2.0 * np.pi, 500, endpoint=False))
    histogram, other = an.Empirical(normals), an.Empirical(normals)
    assert an.AlbedoTable.of(histogram, *args) is an.AlbedoTable.of(histogram, *args)
    assert an.AlbedoTable.of(other, *args) is not an.AlbedoTable.of(histogram, *args)


def test_albedo_of_lambertian_is_exact():
    """Cosine-weighted samples make f cos θ / p constant for f = kd/π: ρ = kd to rounding."""
    rho, se = an.directional_albedo(
        np.array([0.0, 45.0, 90.0]), lambda a, b: np.full(b.shape[:-1], 0.7 / np.pi), n=2**10
    )
    assert np.allclose(rho, 0.7, atol=1e-12) and np.all(se < 1e-12)


def test_albedo_tends_to_fresnel_for_narrow_lobes():
    """Mikkelsen 2009, §3: ρ(ω) → F(ω·n) as κ → ∞ (κ = 1024 already within 1e-3 at 30°)."""
    table = an.AlbedoTable(
        an.VonMisesFisher(1024.0), "vgroove", "aluminium", n_theta=7, n_grazing=0
    )
    c = np.cos(np.radians(30.0))
    assert abs(table.rho(c) - an.fresnel(c, an.resolve_material("aluminium"))) < 1e-3


# --- sampling ------------------------------------------------------------------------------
THETA_WO = (0.0, 45.0, 80.0)
ALPHA = sidak(0.01, len(THETA_WO))


def _cell_mass(ndf, wo, t_edges, p_edges, n_gl=6):
    """∫ pdf_microfacet over each (θ, φ) cell of the sphere by Gauss–Legendre in both."""
    gx, gw = np.polynomial.legendre.leggauss(n_gl)
    ta, tb = t_edges[:-1, None], t_edges[1:, None]
    th = 0.5 * (ta + tb) + 0.5 * (tb - ta) * gx
    wth = 0.5 * (tb - ta) * gw * np.sin(th)
    pa, pb = p_edges[:-1, None], p_edges[1:, None]
    ph = 0.5 * (pa + pb) + 0.5 * (pb - pa) * gx
    wph = 0.5 * (pb - pa) * gw
    wi = spherical(th[:, :, None, None], ph[None, None, :, :])
    pdf = an.pdf_microfacet(wi, wo, ndf)
    return np.einsum("atpq,at,pq->ap", pdf, wth, wph)


def _mass_below_horizon(ndf, wo, n_phi=1024):
    """P(wi_z < 0) = ∫ D(h) h_z [2(wo·h)h_z < wo_z] dω_h, integrated over h (in wi the pdf has an
    integrable 1/|wi + wo| singularity at wi = −wo, where every h ⟂ wo lands)."""
    u = np.linspace(0, 1, 257)
    e = np.unique(np.concatenate([ndf.tilt_quantile_rad(u), np.linspace(0, np.pi / 2, 91)]))
    gx, gw = np.polynomial.legendre.leggauss(8)
    a, b = e[:-1, None], e[1:, None]
    th = (0.5 * (a + b) + 0.5 * (b - a) * gx).ravel()
    wth = (0.5 * (b - a) * gw).ravel() * ndf.tilt_pdf_rad(th) / (2 * np.pi)
    ph = (np.arange(n_phi) + 0.5) * 2 * np.pi / n_phi
    h = spherical(th[:, None], ph[None, :])
    below = 2 * (h @ wo) * h[..., 2] < wo[2]
    return np.sum(below * wth[:, None]) * 2 * np.pi / n_phi


@pytest.mark.parametrize("theta_o", THETA_WO)
def test_sample_microfacet_chi2(theta_o):
    ndf = an.Beckmann(0.3)
    wo = spherical(np.radians(theta_o), 0.0)
    n = 1_000_000
    rng = np.random.default_rng(int(theta_o) + 17)
    wi, pdf = an.sample_microfacet(wo, rng.random(n), rng.random(n), ndf)
    assert np.allclose(pdf, an.pdf_microfacet(wi, wo, ndf), rtol=1e-9)
    t_up = np.linspace(0, np.pi / 2, 37)
    p_edges = np.linspace(0, 2 * np.pi, 49)
    upper = _cell_mass(ndf, wo, t_up, p_edges)
    lower = _mass_below_horizon(ndf, wo)
    assert abs(upper.sum() + lower - 1.0) < 1e-5  # the pdf is normalised on the sphere
    theta = np.arccos(np.clip(wi[:, 2], -1, 1))
    phi = np.mod(np.arctan2(wi[:, 1], wi[:, 0]), 2 * np.pi)
    up = wi[:, 2] >= 0
    counts, _, _ = np.histogram2d(theta[up], phi[up], [t_up, p_edges])
    observed = np.append(counts.ravel(), np.count_nonzero(~up))
    expected = np.append(upper.ravel(), lower) * n
    _, _, p = pearson_chi2(observed, expected)
    assert p > ALPHA


# --- Mikkelsen 2009, eq. 28 mix ------------------------------------------------------------------
@pytest.fixture(scope="module")
def vmf_table():
    return an.AlbedoTable(an.VonMisesFisher(17.0), "vgroove", "methanol")


def test_mix_reciprocal(vmf_table):
    rng = np.random.default_rng(2)
    wi, wo = _random_dirs(rng, 100_000), _random_dirs(rng, 100_000)
    for renorm in (False, True):
        f = an.mikkelsen_mix(wi, wo, vmf_table, kd=[0.08, 0.172, 1.0], renormalise=renorm)
        g = an.mikkelsen_mix(wo, wi, vmf_table, kd=[0.08, 0.172, 1.0], renormalise=renorm)
        assert f.shape == (100_000, 3)
        assert np.all(np.abs(f - g) <= 1e-12 * np.abs(f))


@pytest.mark.parametrize("renormalise", [False, True])
def test_mix_albedo(vmf_table, renormalise):
    """Albedo of eq. 28 (kd = ks = 1) is ≤ 1 and equals the predicted
    ρ + (1 − ρ)(1 − ρ̄) — or exactly 1 when renormalised — within 5σ + table accuracy."""
    t = vmf_table
    theta = np.array([0.0, 30.0, 60.0, 85.0])
    brdf = lambda a, b: an.mikkelsen_mix(a, b, t, kd=1.0, renormalise=renormalise)  # noqa: E731
    alb, se = an.directional_albedo(theta, brdf, ndf=t.ndf)
    rho = t.rho(np.cos(np.radians(theta)))
    predicted = 1.0 if renormalise else rho + (1 - rho) * (1 - t.rho_bar)
    tol = 5 * se + 2e-5
    assert np.all(alb <= 1 + tol)
    assert np.all(np.abs(alb - predicted) < tol)
    if not renormalise:
        assert np.all(alb < 1 - 0.01)  # eq. 28 as printed loses ρ̄(1 − ρ) here


def test_mix_rejects_bad_arguments(vmf_table):
    n = np.array([0.0, 0.0, 1.0])
    with pytest.raises(ValueError, match="kd"):
        an.mikkelsen_mix(n, n, vmf_table, kd=1.5)
    with pytest.raises(ValueError, match="ks"):
        an.mikkelsen_mix(n, n, vmf_table, kd=0.5, ks=-0.1)
    unmasked = an.AlbedoTable(an.Beckmann(1.0), "none", None, n_theta=10, n_grazing=4)
    with pytest.raises(ValueError, match="specular_table"):
        an.mikkelsen_mix(n, n, unmasked, kd=0.5)


def test_argument_checks():
    ndf = an.Beckmann(0.3)
    n = np.array([0.0, 0.0, 1.0])
    with pytest.raises(ValueError, match="shadowing"):
        an.torrance_sparrow(n, n, ndf, "blinn")
    with pytest.raises(ValueError, match="unit"):
        an.torrance_sparrow([0.0, 0.0, 0.5], n, ndf)
    with pytest.raises(ValueError, match="material|ior"):
        an.torrance_sparrow(n, n, ndf, material="unobtainium")
    with pytest.raises(ValueError, match="upper hemisphere"):
        an.sample_microfacet([0.0, 0.0, -1.0], 0.5, 0.5, ndf)
    with pytest.raises(ValueError, match="power of 2"):
        an.directional_albedo(0.0, lambda a, b: 0 * a[..., 0], n=1000)
    with pytest.raises(ValueError, match="theta_deg"):
        an.directional_albedo(95.0, lambda a, b: 0 * a[..., 0])
