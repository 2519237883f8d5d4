"""Each common bug of a GGX implementation, injected into a GGX written from scratch in numpy,
fails ``assert_brdf_matches_model`` against microsim's closed form with a message naming that
bug (``microsim.testing.diagnosis``: the variant of the model that fits the brdf best); the
correct implementation, in float64 and in float32, passes with the default settings."""

import numpy as np
import pytest

from microsim.analytic import GGX
from microsim.analytic.masking import Smith
from microsim.analytic.models import TorranceSparrow
from microsim.testing import assert_brdf_matches_model

N, K = 0.769, 6.08  # aluminium, n + ik
THETA_I = (0, 30, 60, 80)


def fresnel_conductor(c, n=N, k=K):
    eta = n + 1j * k
    et = np.sqrt(eta * eta - (1.0 - c * c) + 0j)
    rs = (c - et) / (c + et)
    rp = (eta * eta * c - et) / (eta * eta * c + et)
    return 0.5 * (np.abs(rs) ** 2 + np.abs(rp) ** 2)


def ggx(alpha=0.3, bug=None, dtype=np.float64):
    """f(wi, wo) of GGX with height-correlated Smith G (Heitz 2014) on aluminium, with ``bug``
    injected: "alpha-squared", "g1", "separable", "swapped-fresnel", "cosine", "half"."""
    a = alpha * alpha if bug == "alpha-squared" else alpha

    def lam(c):
        return 0.5 * (np.sqrt(1 + a * a * (1 - c * c) / (c * c)) - 1)

    def f(wi, wo):
        wi, wo = wi.astype(dtype), wo.astype(dtype)
        ci, co = wi[:, 2], wo[:, 2]
        h = wi + wo
        h /= np.linalg.norm(h, axis=1, keepdims=True)
        ch, cd = h[:, 2], np.clip(np.sum(wi * h, 1), 0, 1)
        d = a * a / (np.pi * (ch * ch * (a * a - 1) + 1) ** 2)
        with np.errstate(divide="ignore", invalid="ignore"):
            if bug == "g1":
                g = 1 / (1 + lam(co))
            elif bug == "separable":
                g = 1 / ((1 + lam(ci)) * (1 + lam(co)))
            else:
                g = 1 / (1 + lam(ci) + lam(co))
            fr = fresnel_conductor(cd, K, N) if bug == "swapped-fresnel" else fresnel_conductor(cd)
            out = fr * d * g / (4 * ci * co)
            if bug == "cosine":
                out = out * co
            if bug == "half":
                out = out * 0.5
        return np.where((ci > 0) & (co > 0), out, 0.0).astype(dtype)

    return f


MODEL = TorranceSparrow(GGX(0.3), Smith(correlated=True), N + 1j * K)


@pytest.mark.parametrize("dtype", [np.float64, np.float32])
def test_the_correct_ggx_passes_in_double_and_single_precision(dtype):
    out = assert_brdf_matches_model(ggx(dtype=dtype), MODEL, THETA_I)
    assert out["reciprocity"] < 1e-4


@pytest.mark.parametrize(
    "bug, named",
    [
        ("half", "a constant factor: brdf ≈ 0.5 ×"),
        ("alpha-squared", "alpha = 0.09 = 0.3²"),
        ("g1", "G1(wo) for G2"),
        ("separable", "separable G1(wi)·G1(wo) Smith G for the height-correlated"),
        ("swapped-fresnel", "Fresnel with η and k swapped"),
        ("cosine", "a cosine left in: brdf ≈ model × cos θo"),
    ],
)
def test_each_bug_is_named(bug, named):
    with pytest.raises(AssertionError) as e:
        assert_brdf_matches_model(ggx(bug=bug), MODEL, THETA_I)
    msg = str(e.value)
    assert "likely cause: " + named in msg, msg


def test_a_deviation_no_common_bug_explains_is_not_given_a_cause():
    correct = ggx()

    def wavy(wi, wo):  # a ripple over θo: no variant of the model has that shape
        return correct(wi, wo) * (1.0 + 0.05 * np.sin(9.0 * np.arccos(wo[:, 2])))

    with pytest.raises(AssertionError) as e:
        assert_brdf_matches_model(wavy, MODEL, THETA_I)
    assert "likely cause" not in str(e.value)
    assert "no single common bug" in str(e.value)
