"""Walter et al. 2007's rough dielectric BSDF (``analytic.dielectric``): generalised
reciprocity in the radiance convention, its reflection is Torrance–Sparrow's, energy (R + T)
by quadrature — never above 1, → 1 and → Fresnel as the surface gets smooth — and bad
parameters refused naming the parameter."""

import dataclasses

import numpy as np
import pytest
from support import refused

from microsim import analytic as an
from microsim import vectors
from microsim.analytic.dielectric import WalterDielectric, dielectric_albedo, dielectric_fresnel
from microsim.errors import UsageError

ETA = 1.5
QUADRATURE = 1e-5  # dielectric_albedo's stated accuracy


def _sphere(rng, n):
    """Uniform unit directions on the whole sphere."""
    return vectors.spherical(np.arccos(rng.uniform(-1.0, 1.0, n)), rng.uniform(0, 2 * np.pi, n))


@pytest.mark.parametrize("ndf", [an.Beckmann(0.3), an.GGX(0.4)], ids=["beckmann", "ggx"])
@pytest.mark.parametrize("correlated", [False, True], ids=["separable", "correlated"])
def test_generalised_reciprocity(ndf, correlated):
    """f(i, o)/η_o² = f(o, i)/η_i² (Walter et al. 2007, eq. 21) on both sides, both G."""
    model = WalterDielectric(ndf, an.Smith(correlated=correlated), ETA)
    rng = np.random.default_rng(7)
    wi, wo = _sphere(rng, 20000), _sphere(rng, 20000)
    eta2_i = np.where(wi[:, 2] > 0, 1.0, ETA**2)
    eta2_o = np.where(wo[:, 2] > 0, 1.0, ETA**2)
    forward, backward = model.f(wi, wo) / eta2_o, model.f(wo, wi) / eta2_i
    transmitted = (wi[:, 2] * wo[:, 2] < 0) & (forward > 0)
    assert transmitted.sum() > 1000  # the relation is exercised where it is not trivial
    # atol: below 1e-100 Beckmann's D = exp(−tan²θh/m²)/… amplifies the rounding of h by
    # its exponent (≳ 230), so only there the agreement is absolute
    np.testing.assert_allclose(forward, backward, rtol=1e-12, atol=1e-100)


@pytest.mark.parametrize(
    "ndf",
    [an.Beckmann(0.3), an.GGX(0.4), an.AnisotropicGGX(0.2, 0.5, 30.0)],
    ids=["beckmann", "ggx", "anisotropic-ggx"],
)
@pytest.mark.parametrize("correlated", [False, True], ids=["separable", "correlated"])
def test_reflection_above_is_torrance_sparrow(ndf, correlated):
    rng = np.random.default_rng(8)
    wi, wo = _sphere(rng, 2000), _sphere(rng, 2000)
    wi[:, 2], wo[:, 2] = np.abs(wi[:, 2]), np.abs(wo[:, 2])
    walter = WalterDielectric(ndf, an.Smith(correlated=correlated), ETA)
    ts = an.TorranceSparrow(ndf, an.Smith(correlated=correlated), material=ETA)
    np.testing.assert_allclose(walter.f(wi, wo), ts.f(wi, wo), rtol=1e-14, atol=0)


def test_f_vanishes_where_no_facet_refracts():
    """Opposite sides but i·h_t against i·n (eq. 15/16 sign conditions): f = 0; the normal
    pair in the radiance convention: f(n, −n) = η² f(−n, n)."""
    model = WalterDielectric(an.GGX(0.3), an.Smith(), ETA)
    # o nearly the mirror image of i through the surface plane: h_t ∝ −(i + η o) would need
    # a facet facing away from i
    wi, wo = vectors.spherical_deg(60.0, 0.0), vectors.spherical_deg(120.0, 0.0)
    assert model.f(wi, wo) == 0.0 and model.f(wo, wi) == 0.0
    up, down = np.array([0.0, 0.0, 1.0]), np.array([0.0, 0.0, -1.0])
    assert model.f(up, down) == pytest.approx(ETA**2 * model.f(down, up), rel=1e-14)
    assert model.f(up, np.array([1.0, 0.0, 0.0])) == 0.0


@pytest.mark.parametrize(
    "alpha",
    [pytest.param(0.1, marks=pytest.mark.slow), 0.5, pytest.param(1.0, marks=pytest.mark.slow)],
)
def test_single_scattering_never_creates_energy(alpha):
    """R + T ≤ 1 (masking only removes flux) from above and from inside the medium."""
    for model in (
        WalterDielectric(an.GGX(alpha), an.Smith(correlated=True), ETA),
        WalterDielectric(an.Beckmann(alpha), an.Smith(), ETA),
    ):
        theta = np.array([0.0, 80.0, 100.0, 150.0])
        reflected, transmitted = dielectric_albedo(model, theta)
        assert np.all(reflected > 0) and np.all(transmitted >= 0)
        assert np.all(reflected + transmitted <= 1.0 + QUADRATURE), (theta, reflected + transmitted)


def test_albedo_meets_its_stated_accuracy_at_the_critical_angle():
    """From inside, F has a square-root edge at the critical angle: the default azimuth
    quadrature agrees with four times its nodes to the stated accuracy (plain Gauss–Legendre
    between the kinks misses it by ~6e-5 here)."""
    model = WalterDielectric(an.Beckmann(0.5), an.Smith(), ETA)
    coarse = np.array(dielectric_albedo(model, [135.0, 150.0]))
    fine = np.array(dielectric_albedo(model, [135.0, 150.0], n_gl_phi=64))
    np.testing.assert_allclose(coarse, fine, rtol=0, atol=QUADRATURE)


def _smith_loss_bound(ndf, theta_i_deg, eta_rel):
    """What single scattering can lose at θi (Smith G, a smooth surface): the masking of the
    specular reflected and refracted rays, Λ(θr) + Λ(θt) (G1 = 1/(1 + Λ) ≥ 1 − Λ), plus the
    rays a facet sends across the horizon — only facets tilted by ≥ (90° − θi)/2 do, with
    probability 1 − P(θh < (90° − θi)/2) — both doubled for the spread of the lobe."""
    theta_t = np.degrees(np.arcsin(np.sin(np.radians(theta_i_deg)) / eta_rel))
    lam = ndf.smith_lambda(vectors.spherical_deg(np.array([theta_i_deg, theta_t]), 0.0)).sum()
    tail = 1.0 - ndf.cdf_theta_rad(np.radians(0.5 * (90.0 - theta_i_deg)))
    return 2.0 * (lam + tail) + QUADRATURE


@pytest.mark.parametrize("ndf", [an.Beckmann(0.02), an.GGX(0.02)], ids=["beckmann", "ggx"])
def test_energy_is_conserved_in_the_smooth_limit(ndf):
    """At α = 0.02, θi = 30° from either side, 1 − (R + T) is at most what Smith's single
    scattering loses (``_smith_loss_bound``): ~1e-5 for Beckmann, whose slopes have no tail
    at 30°, ~2.5e-3 for GGX's heavy tail. Fails for a wrong Jacobian or η² factor (O(1))."""
    model = WalterDielectric(ndf, an.Smith(), ETA)
    for theta, eta_rel in ((30.0, ETA), (150.0, 1.0 / ETA)):
        reflected, transmitted = dielectric_albedo(model, theta)
        loss = 1.0 - (reflected + transmitted)
        assert -QUADRATURE <= loss <= _smith_loss_bound(ndf, 30.0, eta_rel), (theta, loss)


def test_smooth_limit_is_the_flat_interface():
    """α = 0.02 (Beckmann): R → the flat interface's Fresnel reflectance from above and from
    inside below the critical angle (41.8°), R → 1 beyond it (total internal reflection,
    ≥ 8° = 7α away, where no facet of the lobe transmits). The tolerance covers the O(α²)
    spread of incidence angles over the lobe."""
    model = WalterDielectric(an.Beckmann(0.02), an.Smith(), ETA)
    theta = np.array([0.0, 30.0, 60.0, 150.0, 180.0])
    reflected, transmitted = dielectric_albedo(model, theta)
    cos = np.abs(np.cos(np.radians(theta)))
    flat = np.where(theta < 90, an.fresnel(cos, ETA), an.fresnel(cos, 1.0 / ETA))
    np.testing.assert_allclose(reflected, flat, atol=1e-3)
    np.testing.assert_allclose(transmitted, 1.0 - flat, atol=1e-3)
    reflected, transmitted = dielectric_albedo(model, [120.0, 130.0])
    assert np.all(reflected >= 1.0 - 1e-3) and np.all(transmitted <= 1e-3)


def test_dielectric_fresnel_from_either_side():
    cos = np.linspace(0.0, 1.0, 11)
    np.testing.assert_array_equal(dielectric_fresnel(cos, ETA), an.fresnel(cos, ETA))
    critical = np.sqrt(1.0 - 1.0 / ETA**2)  # cos of the critical angle inside
    inside = dielectric_fresnel(cos, 1.0 / ETA)
    assert np.all(inside[cos < critical] == pytest.approx(1.0, abs=1e-15))
    assert np.all(inside[cos > critical] < 1.0)


def test_model_protocol_frozen_hashable():
    model = WalterDielectric(an.GGX(0.3))
    assert isinstance(model, an.BRDFModel) and not isinstance(model, an.SampleableBRDF)
    assert model.params() == {
        "ndf": an.GGX(0.3),
        "masking": an.Smith(an.GGX(0.3)),
        "eta": 1.5,
        "crossing": "as-reflection",
    }
    with pytest.raises(dataclasses.FrozenInstanceError):
        model.eta = 2.0
    assert hash(model) == hash(dataclasses.replace(model)) and model == dataclasses.replace(model)


@pytest.mark.parametrize(
    "call, word",
    [
        (lambda: WalterDielectric(an.GGX(0.3), an.Smith(), 0.0), "eta"),
        (lambda: WalterDielectric(an.GGX(0.3), an.Smith(), -1.5), "eta"),
        (lambda: WalterDielectric(an.GGX(0.3), an.Smith(), 1.0), "eta"),
        (lambda: WalterDielectric(an.GGX(0.3), an.Smith(), 1.5 + 0.1j), "eta"),
        # NumPy's complex would pass float() with a warning, its imaginary part dropped
        (lambda: WalterDielectric(an.GGX(0.3), an.Smith(), np.complex128(1.5 + 0.1j)), "eta"),
        (lambda: WalterDielectric(an.GGX(0.3), an.Smith(), "glass"), "eta"),
        (lambda: WalterDielectric(an.GGX(0.3), an.VGroove(), 1.5), "masking"),
        (lambda: WalterDielectric(an.GGX(0.3), an.NoMasking(), 1.5), "masking"),
        (lambda: WalterDielectric(an.GGX(0.3), "smith", 1.5), "masking"),
        (lambda: dielectric_fresnel(0.5, np.complex128(0.769 + 6.08j)), "eta"),
        (lambda: dielectric_albedo(WalterDielectric(an.GGX(0.3)), 90.0), "theta_i_deg"),
        (lambda: dielectric_albedo(WalterDielectric(an.GGX(0.3)), -5.0), "theta_i_deg"),
        (lambda: dielectric_albedo(an.TorranceSparrow(an.GGX(0.3)), 30.0), "model"),
    ],
)
def test_bad_parameters_are_refused_naming_them(call, word):
    refused(call, word)


def test_the_crossing_g_is_chosen_and_checked():
    """``crossing="height-correlated"`` replaces G of refraction only (reflection unchanged),
    by Heitz 2014's B(1 + Λi, 1 + Λo) ≤ 1/(1 + Λi + Λo) (equal where either Λ is 0), and needs
    the height-correlated Smith G; other values are refused naming the parameter."""
    ndf = an.GGX(0.5)
    shared = an.WalterDielectric(ndf, an.Smith(correlated=True), 1.5)
    beta = an.WalterDielectric(ndf, an.Smith(correlated=True), 1.5, "height-correlated")
    rng = np.random.default_rng(7)
    wi = _random_upper(rng, 200)
    wo_up, wo_down = _random_upper(rng, 200), -_random_upper(rng, 200)
    np.testing.assert_array_equal(beta.f(wi, wo_up), shared.f(wi, wo_up))
    ft_beta, ft_shared = beta.f(wi, wo_down), shared.f(wi, wo_down)
    assert np.all(ft_beta <= ft_shared * (1 + 1e-12)) and np.any(ft_beta < 0.99 * ft_shared)
    with pytest.raises(UsageError, match="crossing must be one of"):
        an.WalterDielectric(ndf, an.Smith(correlated=True), 1.5, "beta")
    with pytest.raises(UsageError, match="needs masking=Smith"):
        an.WalterDielectric(ndf, an.Smith(correlated=False), 1.5, "height-correlated")


def _random_upper(rng, n):
    v = rng.normal(size=(n, 3))
    v[:, 2] = np.abs(v[:, 2]) + 0.05
    return v / np.linalg.norm(v, axis=1, keepdims=True)
