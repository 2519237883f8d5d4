"""Check your own BRDF with microsim.testing — examples that are also tests (docs/testing.md).

(a) a correct GGX written in plain NumPy against the GGX V-groove scene: passes;
(b) the same with the roughness 3 % too large: fails, and the message says where;
(c) Schlick's Fresnel instead of the exact one on aluminium: fails at grazing incidence and
    passes where Schlick's error is far below the reference's precision;
(d) a user's importance sampler against its pdf: passes, and a wrong pdf fails.

The catalogue scene ``vgroove-ggx-0.3`` is 4000 stratified V-grooves with GGX(α = 0.3)
tilts on aluminium; azimuth-averaged, its single-bounce BRDF is Torrance–Sparrow with the GGX
D, the V-groove G and exact Fresnel (Mikkelsen 2009, eq. 13, 25), which is what ``ggx_brdf``
below implements without microsim. All checks share one reference simulation (traced once,
then read from the cache: ``--microsim-cache DIR`` or ``$MICROSIM_CACHE``).
"""

import numpy as np
import pytest

from microsim.testing import BRDFMismatch, assert_brdf_agrees, assert_sampler_matches

SCENE = "vgroove-ggx-0.3"
ALUMINIUM = 0.769 + 6.08j  # the scene's n + ik (Mikkelsen 2009, Fig. 5, 500 nm)
THETA_I = [0, 30, 60, 80]
RAYS = 1_000_000  # per incidence: ~5 s to trace all four on 2 cores, then cached
BINS = (30, 37)
pytestmark = pytest.mark.microsim


# --- the "external" implementation: plain NumPy, nothing from microsim -----------------------
def fresnel_conductor(cos_i, eta):
    """Exact unpolarised Fresnel reflectance (R_s + R_p)/2 from air onto n + ik, with
    η cos θt = √(η² − sin²θi) (Mikkelsen 2009, §2.1; Mally 2015)."""
    cos_i = np.clip(cos_i, 0.0, 1.0)
    sin2 = 1.0 - cos_i**2
    eta_cos_t = np.sqrt(eta * eta - sin2 + 0j)  # η cos θt
    rs = (cos_i - eta_cos_t) / (cos_i + eta_cos_t)
    rp = (eta * eta * cos_i - eta_cos_t) / (eta * eta * cos_i + eta_cos_t)
    return 0.5 * (np.abs(rs) ** 2 + np.abs(rp) ** 2)


def fresnel_schlick(cos_i, eta):
    f0 = abs((eta - 1) / (eta + 1)) ** 2
    return f0 + (1.0 - f0) * (1.0 - np.clip(cos_i, 0.0, 1.0)) ** 5


def ggx_brdf(alpha, fresnel=fresnel_conductor, eta=ALUMINIUM):
    """Torrance–Sparrow f = F(wi·h) D(h) G(wi, wo, h) / (4 cos θi cos θo) with the GGX D and
    the V-groove G = min(1, 2 (n·h)(n·wo)/(wo·h), 2 (n·h)(n·wi)/(wi·h)) (Blinn 1977)."""

    def f(wi, wo):  # wi, wo: (N, 3) unit vectors, z = macro normal; returns (N,) in sr⁻¹
        ci, co = wi[:, 2], wo[:, 2]
        h = wi + wo
        h /= np.linalg.norm(h, axis=1, keepdims=True)
        ch, cd = h[:, 2], np.sum(wi * h, axis=1)
        d = alpha**2 / (np.pi * (ch**2 * (alpha**2 - 1.0) + 1.0) ** 2)
        g = np.minimum(1.0, 2.0 * ch * np.minimum(ci, co) / cd)
        out = fresnel(cd, eta) * d * g / (4.0 * ci * co)
        return np.where((ci > 0) & (co > 0) & (ch > 0), out, 0.0)

    return f


# --- (a) a correct GGX passes ------------------------------------------------------------------
def test_a_correct_ggx_agrees():
    result = assert_brdf_agrees(
        ggx_brdf(0.3), SCENE, theta_i=THETA_I, rays=RAYS, bins=BINS, symmetric=True
    )
    assert result["passed"] and result["failing"] == []


# --- (b) 3 % too rough fails, and says where ---------------------------------------------------
def test_b_three_percent_rougher_fails_with_a_message_that_says_where():
    with pytest.raises(AssertionError) as err:
        assert_brdf_agrees(
            ggx_brdf(0.3 * 1.03), SCENE, theta_i=THETA_I, rays=RAYS, bins=BINS, symmetric=True
        )
    msg = str(err.value)
    assert "θi = 0°, 30°, 60°, 80°" in msg  # every incidence fails
    assert "worst bins at θi = 80°" in msg and "hemisphere chart: /" in msg
    assert "χ²/dof" in msg and "deviating θo" in msg


# --- (c) Schlick instead of exact Fresnel on aluminium -------------------------------------------
def test_c_schlick_fails_at_grazing_and_passes_near_normal_incidence():
    """Schlick's error on aluminium grows with the angle on the facet: its energy excess is
    +0.01 % (θi 0°), +0.14 % (30°), +1.4 % (60°), +4.8 % (80°) (bin averages, no noise). At
    ~2 % reference precision it cannot be seen at 0° and 30°; it is seen at 80°. At 60° its
    1.4 % (up to 5.7 % in single bins) is real and usually resolved by 10⁶ rays beyond the
    tile's 0.45 % departure from its ensemble, but not always (19 of 20 and 29 of 32 reference
    traces in docs/testing.md), so this test asserts only what holds for every trace."""
    schlick = ggx_brdf(0.3, fresnel_schlick)
    with pytest.raises(BRDFMismatch) as err:
        assert_brdf_agrees(schlick, SCENE, theta_i=THETA_I, rays=RAYS, bins=BINS, symmetric=True)
    failing = err.value.agreement["failing"]
    assert 80.0 in failing and not {0.0, 30.0} & set(failing), str(err.value)


# --- (d) a user's importance sampler against its pdf ---------------------------------------------
def ggx_reflection_sampler(alpha, wo):
    """Sample wi by reflecting wo about h ~ D(h) cos θh (GGX); returns sample(u1, u2), pdf(wi)."""

    def sample(u1, u2):
        tan2 = alpha**2 * u1 / (1.0 - u1)
        ch = 1.0 / np.sqrt(1.0 + tan2)
        sh, phi = np.sqrt(1.0 - ch**2), 2.0 * np.pi * u2
        h = np.stack([sh * np.cos(phi), sh * np.sin(phi), ch], axis=1)
        return 2.0 * (h @ wo)[:, None] * h - wo

    def pdf(wi):  # D(h) cos θh / (4 |wo·h|), h the half vector (upper hemisphere)
        h = wi + wo
        h /= np.linalg.norm(h, axis=1, keepdims=True)
        h *= np.sign(h[:, 2:3])
        ch = h[:, 2]
        d = alpha**2 / (np.pi * (ch**2 * (alpha**2 - 1.0) + 1.0) ** 2)
        return d * ch / (4.0 * np.abs(h @ wo))

    return sample, pdf


WO = np.array([np.sin(np.radians(40.0)), 0.0, np.cos(np.radians(40.0))])


def test_d_sampler_matches_its_pdf():
    sample, pdf = ggx_reflection_sampler(0.3, WO)
    check = assert_sampler_matches(sample, pdf, n=200_000, seed=1)
    assert check["p_value"] >= check["p_threshold"]


def test_d_sampler_with_the_wrong_pdf_fails():
    sample, _ = ggx_reflection_sampler(0.3, WO)
    _, pdf_rougher = ggx_reflection_sampler(0.3 * 1.03, WO)
    with pytest.raises(AssertionError, match="sampler does not match its pdf"):
        assert_sampler_matches(sample, pdf_rougher, n=200_000, seed=1)
