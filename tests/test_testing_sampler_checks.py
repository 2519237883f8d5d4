"""The sampler check as a renderer developer meets it (``assert_sampler_matches``): a float32
sampler that returns (direction, pdf, weight) like Mitsuba 3's ``bsdf.sample`` — directions
below the horizon with weight 0 — passes with the defaults; its weights are checked against
brdf(w)·|cos θ|/pdf(w); and each classic bug fails with a message that names it (a pdf off by a
constant, the half-vector Jacobian or the factor h·n left out, a cosine too many or too few in
the weight, samples below the horizon returned as if valid).

The sampler is microsim's GGX visible-normal sampler (Heitz 2018) reflected about the fixed
direction WI; its pdf in float32 is written out as a renderer computes it, and the harness
compares it with microsim's float64 ``GGX.pdf_visible``. 10⁵ samples per check (< 1 s each)."""

import re

import numpy as np
import pytest
from support import refused

from microsim.analytic import GGX, pdf_microfacet, sample_microfacet
from microsim.testing import assert_sampler_matches

ALPHA = 0.3
NDF = GGX(ALPHA)
WI = np.array([np.sin(np.radians(40.0)), 0.0, np.cos(np.radians(40.0))])
N = 100_000
f32 = np.float32


def half_vector(wo):
    """h = (WI + wo)/|WI + wo| for each row of wo (float64)."""
    h = wo + WI
    return h / np.linalg.norm(h, axis=1, keepdims=True)


def reflected_visible_normals(u1, u2):
    """wo = 2(WI·m)m − WI with m ~ D_WI(m), microsim's float64 sampler."""
    m = NDF.sample_visible(np.tile(WI, (len(u1), 1)), u1, u2)
    return 2.0 * (m @ WI)[:, None] * m - WI


def pdf(wo):
    """The reference density (float64): D_WI(h)/(4|wo·h|) above the horizon, 0 below."""
    h = half_vector(wo)
    dv = NDF.pdf_visible(h, np.broadcast_to(WI, h.shape))
    return np.where(wo[:, 2] > 0, dv / (4.0 * np.abs(np.einsum("ij,ij->i", wo, h))), 0.0)


def brdf(wo):
    """GGX Torrance–Sparrow with the separable Smith G and F = 1 (float64, no cosine)."""
    h = half_vector(wo)
    g1 = 1.0 / (1.0 + NDF.smith_lambda_cos(np.clip(wo[:, 2], 1e-12, 1.0)))
    g1_i = 1.0 / (1.0 + NDF.smith_lambda_cos(WI[2]))
    f = NDF.D_cos(h[:, 2]) * g1_i * g1 / (4.0 * WI[2] * np.maximum(wo[:, 2], 1e-300))
    return np.where(wo[:, 2] > 0, f, 0.0)


def g1_f32(c):
    """Smith G1 of GGX in float32 from cos θ: 2c/(c + √(α² + (1 − α²)c²))."""
    a2 = f32(ALPHA * ALPHA)
    return f32(2) * c / (c + np.sqrt(a2 + (f32(1) - a2) * c * c))


def renderer_sample(u1, u2):
    """What a float32 renderer returns: wo, its pdf D_WI(h)/(4|wo·h|) and its weight G1(wo)
    (= f·cos θ/pdf for visible-normal sampling with F = 1), all computed in float32 from the
    float32 direction, as Mitsuba 3 does; a direction below the horizon gets weight 0."""
    wo = reflected_visible_normals(u1, u2).astype(f32)
    wi = WI.astype(f32)
    h = wo + wi
    h /= np.sqrt(np.sum(h * h, axis=1, keepdims=True))
    c, a2 = h[:, 2], f32(ALPHA * ALPHA)
    d = a2 / (f32(np.pi) * (a2 * c * c + (f32(1) - c * c)) ** 2)  # 1 − c² cancels near c = 1
    ci = wi[2]
    d_visible = g1_f32(ci) * np.maximum(h @ wi, f32(0)) * d / ci
    pdf32 = d_visible / (f32(4) * np.abs(np.sum(wo * h, axis=1)))
    up = wo[:, 2] > 0
    weight = np.where(up, g1_f32(np.maximum(wo[:, 2], f32(0))), f32(0))
    return wo, pdf32, weight


def failure(call) -> str:
    with pytest.raises(AssertionError) as info:
        call()
    return str(info.value)


def test_a_correct_float32_sampler_passes_with_the_default_tolerances():
    """Its pdf values differ from the float64 pdf by float32 rounding (~10⁻⁶, more where
    1 − cos² cancels): more than the old default 10⁻⁶, well within FLOAT32_RTOL."""
    wo, pdf32, weight = renderer_sample(*np.random.default_rng(5).random((2, 20_000)))
    up = weight > 0
    rel = np.abs(pdf32[up] / pdf(wo[up].astype(float)) - 1.0)
    assert rel.max() > 1e-6  # float32 rounding shows
    check = assert_sampler_matches(renderer_sample, pdf, n=N, brdf=brdf, wi=WI)
    assert check["p_value"] >= check["p_threshold"]
    assert check["weights_checked"] + check["outside"] == N and check["weights_checked"] > 0


def test_zero_weight_samples_below_the_horizon_count_as_rejected():
    drawn = {}

    def sample(u1, u2):
        out = renderer_sample(u1, u2)
        drawn[len(u1)] = int(np.count_nonzero(out[2] == 0))
        return out

    check = assert_sampler_matches(sample, pdf, n=N)
    assert check["outside"] == drawn[N] > 0  # the rejections: 1 − ∫ pdf of them expected


def test_pdf_values_off_by_a_factor_or_a_jacobian_fail_the_pdf_comparison():
    """The float32-aware default still sees a pdf × 0.5 or one without 1/(4|wo·h|)."""
    assert "pdf values disagree" in failure(
        lambda: assert_sampler_matches(renderer_sample, lambda w: 0.5 * pdf(w), n=N)
    )

    def without_jacobian(w):
        return pdf(w) * 4.0 * np.abs(np.einsum("ij,ij->i", w, half_vector(w)))

    assert "pdf values disagree" in failure(
        lambda: assert_sampler_matches(renderer_sample, without_jacobian, n=N)
    )


def test_a_pdf_too_small_by_a_constant_is_named_with_its_factor():
    def sample(u1, u2):
        wo, p, weight = renderer_sample(u1, u2)
        return wo, 0.5 * p, weight  # the sampler uses the same (wrong) pdf

    msg = failure(lambda: assert_sampler_matches(sample, lambda w: 0.5 * pdf(w), n=N, wi=WI))
    factor = re.search(r"pdf off by a constant factor ([\d.]+) \(normalisation\)", msg)
    assert factor and abs(float(factor.group(1)) - 0.5) < 0.02, msg
    assert "too small by that factor" in msg and "integrates to 0.45" in msg, msg


def test_a_pdf_without_the_half_vector_jacobian_is_named():
    def sample(u1, u2):
        wo = reflected_visible_normals(u1, u2)
        wo[wo[:, 2] <= 0] = np.nan
        return wo

    def without_jacobian(w):
        return pdf(w) * 4.0 * np.abs(np.einsum("ij,ij->i", w, half_vector(w)))

    msg = failure(lambda: assert_sampler_matches(sample, without_jacobian, n=N, wi=WI))
    assert "the pdf lacks the Jacobian 1/(4|wo·h|)" in msg, msg
    # without wi the half vector is unknown: nothing is named, and the message says why
    msg = failure(lambda: assert_sampler_matches(sample, without_jacobian, n=N))
    assert "no single factor" in msg and "pass wi=" in msg, msg


def test_a_pdf_without_the_factor_h_n_is_named():
    """microsim's h ~ D(h)(h·n) sampler judged by a pdf D(h)/(4|wo·h|) (h·n left out)."""

    def sample(u1, u2):
        wo, _ = sample_microfacet(WI, u1, u2, NDF)
        wo[wo[:, 2] <= 0] = np.nan
        return wo

    def without_h_n(w):
        return pdf_microfacet(w, WI, NDF) / half_vector(w)[:, 2] * (w[:, 2] > 0)

    msg = failure(lambda: assert_sampler_matches(sample, without_h_n, n=N, wi=WI))
    assert "the pdf lacks the factor h·n" in msg, msg


def test_a_slightly_wrong_pdf_is_not_blamed_on_a_named_cause():
    """A 3 % rougher pdf fails the χ² test but fits none of the causes."""
    rougher = GGX(ALPHA * 1.03)

    def sample(u1, u2):
        wo = reflected_visible_normals(u1, u2)
        wo[wo[:, 2] <= 0] = np.nan
        return wo

    def pdf_rougher(w):
        h = half_vector(w)
        dv = rougher.pdf_visible(h, np.broadcast_to(WI, h.shape))
        return np.where(w[:, 2] > 0, dv / (4.0 * np.abs(np.einsum("ij,ij->i", w, h))), 0.0)

    msg = failure(lambda: assert_sampler_matches(sample, pdf_rougher, n=N, wi=WI))
    assert "sampler does not match its pdf" in msg and "no single factor" in msg, msg


@pytest.mark.parametrize(
    "factor, cause",
    [
        (lambda wo: np.abs(wo[:, 2]), "the cosine cos θ is included twice"),
        (lambda wo: 1.0 / np.maximum(np.abs(wo[:, 2]), 1e-6), "the cosine cos θ is left out"),
        (lambda wo: np.full(len(wo), np.pi), "f and pdf are normalised differently"),
    ],
    ids=["cos-twice", "cos-left-out", "constant"],
)
def test_a_wrong_weight_is_named(factor, cause):
    """Directions and pdf right, only the weight wrong: the χ² test cannot see it."""

    def sample(u1, u2):
        wo, p, weight = renderer_sample(u1, u2)
        return wo, p, weight * factor(wo.astype(float))

    assert_sampler_matches(sample, pdf, n=N)  # without brdf= the weights are not judged
    msg = failure(lambda: assert_sampler_matches(sample, pdf, n=N, brdf=brdf, wi=WI))
    assert "sample weights disagree with brdf(w)·|cos θ|/pdf(w)" in msg and cause in msg, msg


def test_samples_below_the_horizon_without_weights_are_told_what_to_return():
    def sample(u1, u2):
        return renderer_sample(u1, u2)[0]  # directions only: the rejections look valid

    msg = failure(lambda: assert_sampler_matches(sample, pdf, n=N))
    assert "landed where pdf(w) is 0" in msg, msg
    assert "return NaN for a rejected sample, or (directions, pdf, weight) with weight 0" in msg


def test_weights_must_be_finite_and_brdf_needs_them():
    def nan_weight(u1, u2):
        wo, p, weight = renderer_sample(u1, u2)
        weight[weight > 0.5] = np.nan
        return wo, p, weight

    assert "finite and >= 0" in failure(lambda: assert_sampler_matches(nan_weight, pdf, n=N))

    def two(u1, u2):
        return renderer_sample(u1, u2)[:2]

    refused(lambda: assert_sampler_matches(two, pdf, n=N, brdf=brdf), "brdf=", "weight")
    refused(lambda: assert_sampler_matches(renderer_sample, pdf, brdf=3.0), "brdf")
    refused(lambda: assert_sampler_matches(renderer_sample, pdf, weight_rtol=-1), "weight_rtol")
    refused(lambda: assert_sampler_matches(renderer_sample, pdf, wi=[0, 0, 2]), "wi")
    refused(lambda: assert_sampler_matches(renderer_sample, pdf, wi=[[0, 0, 1]] * 2), "wi")
    refused(
        lambda: assert_sampler_matches(lambda a, b: (*renderer_sample(a, b), 1), pdf),
        "tuple of 4",
    )
