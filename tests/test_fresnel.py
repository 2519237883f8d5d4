"""Fresnel reflectance: reference values, limits, physical identities, stability, validation."""

import numpy as np
import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st

from microsim import analytic as an

ALUMINIUM, METHANOL = 0.769 + 6.08j, 1.329


def cosd(deg):
    return np.cos(np.radians(deg))


def textbook_fresnel(c, eta):
    """(R_s + R_p)/2 as printed in Mally's slides, with the complex root of Snell's law."""
    eta = complex(eta)
    g = np.sqrt(eta**2 - (1.0 - c**2) + 0j)  # η cos θ_t
    rs = (c - g) / (c + g)
    rp = (eta**2 * c - g) / (eta**2 * c + g)
    return 0.5 * (np.abs(rs) ** 2 + np.abs(rp) ** 2)


# docs/design.md "Facts to build on": exact unpolarised reflectance, checked independently
@pytest.mark.parametrize(
    "deg, r_al, r_meoh",
    [
        (0, 0.923284, 0.019955),
        (60, 0.909966, 0.058937),
        (80, 0.879388, 0.346580),
        (89, 0.973137, 0.895969),
    ],
)
def test_reference_values(deg, r_al, r_meoh):
    assert an.fresnel(cosd(deg), ALUMINIUM) == pytest.approx(r_al, abs=1e-5)
    assert an.fresnel(cosd(deg), METHANOL) == pytest.approx(r_meoh, abs=1e-5)


@pytest.mark.parametrize(
    "ior", [ALUMINIUM, METHANOL, 1 / METHANOL, 1.5 + 0j, 1.0, 1 + 1e-12, 0.2 + 3j, 40.0, None]
)
def test_grazing_incidence_reflects_everything(ior):
    r = an.fresnel(np.array([0.0, -1e-7]), ior)  # cos < 0 by rounding is clipped to grazing
    assert np.all(np.isfinite(r))
    np.testing.assert_allclose(r, 1.0, rtol=0, atol=1e-12)
    with pytest.raises(ValueError, match="cos_theta"):  # further out it is not a cosine
        an.fresnel(np.array([0.0, -0.3]), ior)


@pytest.mark.parametrize("n", [1.0001, 1.329, 1.5, 2.4, 4.0])
def test_dielectric_normal_incidence(n):
    expected = ((n - 1) / (n + 1)) ** 2
    assert an.fresnel(1.0, n) == pytest.approx(expected, rel=1e-13)
    assert an.f0_from_material(n) == pytest.approx(expected, rel=1e-13)


def test_conductor_normal_incidence():
    n, k = ALUMINIUM.real, ALUMINIUM.imag
    expected = ((n - 1) ** 2 + k**2) / ((n + 1) ** 2 + k**2)
    assert an.fresnel(1.0, ALUMINIUM) == pytest.approx(expected, rel=1e-13)
    assert an.f0_from_material(ALUMINIUM) == pytest.approx(expected, rel=1e-13)


@pytest.mark.parametrize("n", [0.5, 1.329, 3.0])
def test_conductor_with_zero_extinction_is_the_dielectric(n):
    c = np.linspace(0, 1, 1001)
    np.testing.assert_allclose(an.fresnel(c, complex(n, 0.0)), an.fresnel(c, n), rtol=1e-14, atol=0)


def test_matches_textbook_form_where_that_is_well_conditioned():
    c = np.linspace(0.01, 1, 500)
    for eta in [ALUMINIUM, METHANOL, 2.5, 0.3 + 0.1j, 0.05 + 4j]:
        np.testing.assert_allclose(an.fresnel(c, eta), textbook_fresnel(c, eta), rtol=1e-12)


def test_no_cancellation_for_index_close_to_one():
    # r_s = r_p = −δ/(2+δ) at normal incidence for η = 1 + δ; the textbook form loses all digits
    for delta in [1e-6, 1e-9, 1e-12]:
        expected = (delta / (2 + delta)) ** 2
        assert an.fresnel(1.0, 1 + delta) == pytest.approx(expected, rel=1e-9)
    # and at 60°: series in δ, R ≈ δ² (r_s² + r_p²)/2 with the δ → 0 limits of r/δ
    c = 0.5
    rs_over_d = -1 / (2 * c * c)  # r_s = (1 − η²)/(c + g)² → −2δ/(4c²)
    rp_over_d = (2 * c * c - 1) / (2 * c * c)  # r_p = (η² − 1)(c²(η² + 1) − 1)/(η²c + g)²
    delta = 1e-9
    assert an.fresnel(c, 1 + delta) == pytest.approx(
        0.5 * delta**2 * (rs_over_d**2 + rp_over_d**2), rel=1e-6
    )


def test_stokes_reciprocity_and_total_internal_reflection():
    """R is the same from either side of a dielectric interface at Snell-related angles,
    and beyond the critical angle the light coming from the denser side is all reflected."""
    n = METHANOL
    theta_i = np.radians(np.linspace(0, 89.9, 300))
    theta_t = np.arcsin(np.sin(theta_i) / n)
    np.testing.assert_allclose(
        an.fresnel(np.cos(theta_t), 1 / n), an.fresnel(np.cos(theta_i), n), rtol=1e-11
    )
    critical = np.arcsin(1 / n)
    beyond = np.linspace(critical + 1e-9, np.pi / 2, 200)
    np.testing.assert_allclose(an.fresnel(np.cos(beyond), 1 / n), 1.0, rtol=0, atol=1e-12)
    below = np.linspace(0, critical - 1e-3, 200)
    assert np.all(an.fresnel(np.cos(below), 1 / n) < 1.0)


def test_transmittance_is_complement():
    c = np.linspace(0, 1, 101)
    np.testing.assert_allclose(
        an.fresnel_transmittance(c, METHANOL) + an.fresnel(c, METHANOL), 1.0, rtol=0, atol=1e-15
    )


def test_mirror_is_one_everywhere():
    np.testing.assert_array_equal(an.fresnel(np.linspace(0, 1, 11), None), 1.0)


@settings(max_examples=300, deadline=None)
@given(c=st.floats(0.0, 1.0), n=st.floats(1e-3, 1e3), k=st.floats(0.0, 1e3))
@example(c=0.0, n=1.0, k=0.0)
@example(c=1.0, n=1.0, k=0.0)
@example(c=5e-324, n=1.0, k=0.0)
def test_reflectance_is_a_finite_fraction(c, n, k):
    for ior in (n, complex(n, k)):
        r = an.fresnel(c, ior)
        assert np.isfinite(r) and 0.0 <= r <= 1.0


def test_schlick_is_separate_and_matches_at_the_ends():
    """Schlick (Edwards et al. 2006, eq. 30–31) equals the exact value at 0° and 90° only; for
    aluminium it
    misses the dip before grazing by ~0.078 near 83° (docs/design.md)."""
    for ior in (ALUMINIUM, METHANOL):
        f0 = an.f0_from_material(ior)
        assert an.schlick(1.0, f0) == pytest.approx(an.fresnel(1.0, ior), rel=1e-14)
        assert an.schlick(0.0, f0) == pytest.approx(1.0, abs=1e-15)
    deg = np.linspace(0, 90, 9001)
    err = an.schlick(cosd(deg), an.f0_from_material(ALUMINIUM)) - an.fresnel(cosd(deg), ALUMINIUM)
    assert 80 < deg[np.argmax(np.abs(err))] < 86
    assert np.max(np.abs(err)) == pytest.approx(0.078, abs=0.002)


def test_schlick_rejects_bad_f0():
    with pytest.raises(ValueError, match="f0"):
        an.schlick(0.5, 1.5)


@pytest.mark.parametrize(
    "ior", [-1.0, 0.0, 0j, -1 + 2j, 1.5 - 0.1j, np.nan, complex(np.nan, 1), np.inf, "glass", True]
)
def test_invalid_ior(ior):
    with pytest.raises(ValueError, match="ior"):
        an.fresnel(0.5, ior)
    with pytest.raises(ValueError, match="ior"):
        an.f0_from_material(ior)


def test_nan_cosine_rejected():
    with pytest.raises(ValueError, match="cos_theta"):
        an.fresnel(np.nan, METHANOL)


def test_resolve_material():
    assert an.resolve_material("Aluminium") == ALUMINIUM
    assert an.resolve_material("ALUMINUM") == ALUMINIUM
    assert an.resolve_material("methanol") == METHANOL
    assert an.resolve_material("mirror") is None
    assert an.resolve_material(None) is None
    assert an.resolve_material(1.5) == 1.5 and isinstance(an.resolve_material(1.5), float)
    assert an.resolve_material(1.5 + 2j) == 1.5 + 2j
    assert isinstance(an.resolve_material(np.float64(2.0)), float)
    with pytest.raises(ValueError, match="aluminium.*methanol.*mirror"):
        an.resolve_material("gold")
    with pytest.raises(ValueError, match="ior"):
        an.resolve_material(-2.0)
