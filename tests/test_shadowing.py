"""Shadowing–masking: projected-area identity, numerical Smith Λ, finiteness, argument checks."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from microsim import analytic as an
from microsim.vectors import half_vector, spherical


def _empirical_beckmann():
    rng = np.random.default_rng(42)
    ndf = an.Beckmann(0.3)
    return an.Empirical(ndf.sample(rng.random(1_000_000), rng.random(1_000_000)))


NDFS = {
    "beckmann0.1": lambda: an.Beckmann(0.1),
    "beckmann0.5": lambda: an.Beckmann(0.5),
    "beckmann1": lambda: an.Beckmann(1.0),
    "ggx0.3": lambda: an.GGX(0.3),
    "phong20": lambda: an.BlinnPhong(20.0),
    "vmf17": lambda: an.VonMisesFisher(17.0),
    "vmf1024": lambda: an.VonMisesFisher(1024.0),
    "abc": lambda: an.ABC(100.0, 1.5),
    "empirical": _empirical_beckmann,
}
_CACHE = {}


def ndf_named(name):
    if name not in _CACHE:
        _CACHE[name] = NDFS[name]()
    return _CACHE[name]


def _tilt_nodes(ndf, n_gl=8):
    """θ_h Gauss–Legendre nodes/weights on panels at the NDF's tilt quantiles (and bin edges)."""
    edges = [
        ndf.tilt_quantile_rad(np.linspace(0, 1, 129)),
        np.linspace(0, np.pi / 2, 65),
        ndf.tilt_quantile_rad(1 - np.logspace(-9, -3, 7)),
    ]
    if hasattr(ndf, "theta_edges"):
        edges.append(ndf.theta_edges)
    e = np.unique(np.concatenate(edges))
    gx, gw = np.polynomial.legendre.leggauss(n_gl)
    a, b = e[:-1, None], e[1:, None]
    return (0.5 * (a + b) + 0.5 * (b - a) * gx).ravel(), (0.5 * (b - a) * gw).ravel()


def projected_area(ndf, g1, theta_o_deg, n_phi=512):
    """∫ G1(wo, h)(wo·h)⁺ D(h) dω_h by θ_h panels × midpoint φ_h on [0, π] (wo in the xz-plane)."""
    th, wth = _tilt_nodes(ndf)
    ph = (np.arange(n_phi) + 0.5) * np.pi / n_phi
    h = spherical(th[:, None], ph[None, :])
    wo = spherical(np.radians(theta_o_deg), 0.0)
    woh = h @ wo
    f = g1(ndf, wo, h) * np.maximum(woh, 0.0) * ndf.D_cos(h[..., 2])
    return np.sum(f * (wth * np.sin(th))[:, None]) * 2 * np.pi / n_phi


@pytest.mark.parametrize("kind", ["vgroove", "smith"])
@pytest.mark.parametrize("name", list(NDFS))
def test_projected_area_identity(name, kind):
    """∫ G1 (wo·h)⁺ D dω = cos θo (docs/design.md); V-groove holds because D is isotropic."""
    ndf = ndf_named(name)
    g1 = (
        (lambda d, w, h: an.vgroove_g1(w, h))
        if kind == "vgroove"
        else (lambda d, w, h: an.smith_g1(w, h, d))
    )
    for theta in (0.0, 30.0, 60.0, 80.0, 85.0):
        got = projected_area(ndf, g1, theta)
        assert abs(got - np.cos(np.radians(theta))) < 1e-3, (theta, got)


def test_identity_fails_without_masking():
    """Control: with G1 = 1 the integral is (1 + Λ) cos θo, visibly above cos θo at 80°."""
    ndf = an.Beckmann(0.5)
    got = projected_area(ndf, lambda d, w, h: np.ones(h.shape[:-1]), 80.0)
    lam = ndf.smith_lambda_cos(np.cos(np.radians(80.0)))
    assert abs(got - (1 + lam) * np.cos(np.radians(80.0))) < 1e-4 and lam > 0.1


@pytest.mark.parametrize(
    "ndf",
    [an.Beckmann(0.1), an.Beckmann(0.5), an.Beckmann(1.0), an.GGX(0.05), an.GGX(0.3), an.GGX(1.0)],
    ids=repr,
)
def test_numerical_lambda_matches_closed_form(ndf):
    theta = np.radians(np.linspace(0.0, 85.0, 1701))
    w = spherical(theta, 0.7)
    num = an.smith_lambda(w, ndf, method="numerical")
    ref = an.smith_lambda(w, ndf, method="closed")
    big = ref > 1e-30
    assert np.all(np.abs(num - ref)[big] <= 1e-4 * ref[big])
    assert np.all(np.abs(num - ref)[~big] <= 1e-30)
    # beyond 85° (Λ → ∞) the masking G1 = 1/(1 + Λ) still agrees to 1e-4 relative
    theta = np.radians(np.linspace(85.0, 89.999, 500))
    w = spherical(theta, 0.0)
    g_num = 1 / (1 + an.smith_lambda(w, ndf, method="numerical"))
    g_ref = 1 / (1 + an.smith_lambda(w, ndf, method="closed"))
    assert np.all(np.abs(g_num - g_ref) <= 1e-4 * g_ref)


def test_lambda_methods_and_grazing():
    ndf = an.VonMisesFisher(17.0)
    with pytest.raises(ValueError, match="method"):
        an.smith_lambda([0.0, 0.0, 1.0], ndf, method="closed")
    with pytest.raises(ValueError, match="method"):
        an.smith_lambda([0.0, 0.0, 1.0], an.Beckmann(0.3), method="exact")
    lam = an.smith_lambda(np.array([[0.0, 0.0, 1.0], [1.0, 0.0, 0.0]]), ndf)
    assert lam[0] == 0.0  # no facet is tilted beyond 90°
    assert np.isinf(lam[1])


def _cell_lambda_reference(emp, w, n_t=12, n_p=24):
    """Λ(w) of an anisotropic Empirical by a finer per-cell midpoint rule than the module's,
    using ∫(w·h)⁺D = ∫(w·h)D + ∫(w·h)⁻D with the first integral done on a much finer grid."""
    ta, tb = emp.theta_edges[:-1, None], emp.theta_edges[1:, None]
    th = ta + (tb - ta) * (np.arange(n_t) + 0.5) / n_t
    wt = (tb - ta) / n_t * np.sin(th)
    pa, pb = emp.phi_edges[:-1, None], emp.phi_edges[1:, None]
    ph = pa + (pb - pa) * (np.arange(n_p) + 0.5) / n_p
    wp = (pb - pa) / n_p * np.ones(n_p)
    h = spherical(th[:, :, None, None], ph[None, None, :, :])
    dw = emp.cell_D[:, None, :, None] * wt[:, :, None, None] * wp[None, None, :, :]
    m = np.sum(h * dw[..., None], axis=(0, 1, 2, 3))
    m = m / m[2]  # ∫ h_z D dω = 1 exactly
    return np.array([(np.sum(np.maximum(-(h @ wk), 0) * dw) + m @ wk) / wk[2] - 1 for wk in w])


def test_anisotropic_empirical_lambda():
    """The tabulated 2D Λ of an anisotropic Empirical matches a finer reference quadrature
    (stated accuracy 1e-4 on G1), is close to the isotropic Empirical of the same isotropic
    normals (different binning: 2e-3), and sees anisotropy when the slopes are stretched."""
    rng = np.random.default_rng(5)
    normals = an.Beckmann(0.4).sample(rng.random(400_000), rng.random(400_000))
    iso = an.Empirical(normals)
    aniso = an.Empirical(normals, isotropic=False)
    theta = np.radians(np.array([20.0, 45.0, 60.0, 70.0, 75.0, 80.0, 83.0, 85.0, 87.3, 89.1]))
    for phi in (0.0, 0.9, 2.0):
        w = spherical(theta, phi)
        g_tab = 1 / (1 + an.smith_lambda(w, aniso))
        g_ref = 1 / (1 + np.maximum(_cell_lambda_reference(aniso, w), 0.0))
        assert np.max(np.abs(g_tab - g_ref)) < 1e-4
        g_iso = 1 / (1 + an.smith_lambda(w, iso))
        assert np.max(np.abs(g_iso - g_tab)) < 2e-3
    s = np.stack([rng.normal(0, 0.1, 400_000), rng.normal(0, 0.4, 400_000), np.ones(400_000)], -1)
    stretched = an.Empirical(s / np.linalg.norm(s, axis=-1, keepdims=True), isotropic=False)
    w = spherical(np.radians(80.0), np.array([0.0, np.pi / 2]))
    lam = an.smith_lambda(w, stretched)
    assert lam[1] > 2 * lam[0]  # masking is stronger along the rough axis


def test_vgroove_values():
    n = np.array([0.0, 0.0, 1.0])
    w = spherical(np.radians(60.0), 0.0)
    assert an.vgroove_g1(w, n) == 1.0  # h = n: never masked
    h = spherical(np.radians(20.0), np.pi)  # facet tilted away from w
    expected = 2 * h[2] * w[2] / (w @ h)
    assert np.isclose(an.vgroove_g1(w, h), min(1.0, expected))
    assert an.vgroove_g1(spherical(np.pi / 2, 0.0), h) == 0.0  # grazing
    assert an.vgroove_g(w, n, h) == min(an.vgroove_g1(w, h), an.vgroove_g1(n, h))


def test_smith_g2_forms():
    ndf = an.Beckmann(0.5)
    wi, wo = spherical(np.radians(70.0), 0.0), spherical(np.radians(50.0), 2.0)
    h = half_vector(wi, wo)
    li, lo = an.smith_lambda(wi, ndf), an.smith_lambda(wo, ndf)
    assert np.isclose(an.smith_g2(wi, wo, h, ndf), 1 / ((1 + li) * (1 + lo)))
    assert np.isclose(an.smith_g2(wi, wo, h, ndf, correlated=True), 1 / (1 + li + lo))
    assert np.isclose(an.shadowing_g(wi, wo, h, ndf, "smith-correlated"), 1 / (1 + li + lo))
    assert an.shadowing_g(wi, wo, h, ndf, "none") == 1.0


def _unit(theta_deg, phi_deg):
    """Unit vector with z exactly 0 at θ = 90°."""
    v = spherical(np.radians(theta_deg), np.radians(phi_deg))
    if theta_deg == 90.0:
        v = np.array([v[0], v[1], 0.0]) / np.hypot(v[0], v[1])
    return v


angle = st.floats(0.0, 90.0) | st.sampled_from([0.0, 90.0, 89.999999])
azimuth = st.floats(0.0, 360.0)


@settings(max_examples=150, deadline=None)
@given(
    ti=angle,
    pi=azimuth,
    to=angle,
    po=azimuth,
    th=angle,
    ph=azimuth,
    which=st.sampled_from(["half", "normal", "free"]),
    name=st.sampled_from(list(NDFS)),
)
def test_finite_everywhere(ti, pi, to, po, th, ph, which, name):
    wi, wo = _unit(ti, pi), _unit(to, po)
    h = {
        "half": half_vector(wi, wo),
        "normal": np.array([0.0, 0.0, 1.0]),
        "free": _unit(th, ph),
    }[which]
    if not np.any(h):
        h = np.array([0.0, 0.0, 1.0])
    ndf = ndf_named(name)
    for g in (
        an.vgroove_g(wi, wo, h),
        an.smith_g1(wi, h, ndf),
        an.smith_g1(wo, h, ndf),
        an.shadowing_g(wi, wo, h, ndf, "smith-correlated"),
    ):
        assert np.isfinite(g) and 0.0 <= g <= 1.0


def test_argument_checks():
    ndf = an.Beckmann(0.3)
    n = np.array([0.0, 0.0, 1.0])
    with pytest.raises(ValueError, match="shadowing.*vgroove.*smith"):
        an.shadowing_g(n, n, n, ndf, "cook")
    with pytest.raises(ValueError, match="unit"):
        an.vgroove_g([0.0, 0.0, 2.0], n, n)
    with pytest.raises(ValueError, match="upper hemisphere"):
        an.smith_lambda([0.0, 0.6, -0.8], ndf)
    with pytest.raises(ValueError, match="shape"):
        an.smith_g1([0.0, 1.0], n, ndf)
