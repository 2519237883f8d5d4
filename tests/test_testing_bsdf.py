"""BSDFs with transmission through microsim.testing (``testing.bsdf``): a correct Walter et
al. 2007 BSDF passes the implementation check on both lobes from both sides, in either
convention; deliberately broken ones fail and the message names their bug (the BTDF's η²,
the other convention, Fresnel from the wrong side, the Smith form, across the interface too,
a cosine left in, a constant factor); against a traced rough interface the correct model
passes and a scaled one fails."""

import numpy as np
import pytest
from support import refused

from microsim.analysis.multiple import realised_ndf
from microsim.analytic import GGX, WalterDielectric
from microsim.analytic.dielectric import dielectric_fresnel
from microsim.analytic.masking import Smith
from microsim.surfaces import gaussian
from microsim.testing.agreement import BRDFMismatch
from microsim.testing.bsdf import assert_bsdf_agrees, assert_bsdf_matches_model

ETA = 1.5
MODEL = WalterDielectric(GGX(0.3), Smith(correlated=True), ETA)
FAST = dict(theta_i=(60, 150), bins=(9, 8))
"""One incidence from each side, coarse bins: each check well under a second."""


def _through(wi, wo):
    return wi[:, 2] * wo[:, 2] < 0.0


def _eta_rel(wi):
    """η_o/η_i: the other side's index over the incidence's."""
    return np.where(wi[:, 2] > 0.0, ETA, 1.0 / ETA)


def eta2_dropped(wi, wo):
    """Walter's f_t without its η_o²/η_i² (pbrt-v4's issue: the BTDF without η²)."""
    return MODEL.f(wi, wo) * np.where(_through(wi, wo), _eta_rel(wi) ** -2.0, 1.0)


def importance_form(wi, wo):
    """The adjoint BSDF a renderer transports importance with: f(wo, wi)."""
    return MODEL.f(wo, wi)


def with_cos_o(wi, wo):
    """A renderer's eval, f·|cos θo|, handed over as f."""
    return MODEL.f(wi, wo) * np.abs(wo[:, 2])


def fresnel_not_flipped(wi, wo):
    """Light from inside with the air side's F(|i·h|, η) instead of F(|i·h|, 1/η), on both
    lobes (1 − F on the transmitted one)."""
    rel = _eta_rel(wi)
    through = _through(wi, wo)
    h = np.where(through[:, None], -(wi + rel[:, None] * wo), wi + wo)
    h /= np.linalg.norm(h, axis=1, keepdims=True)
    c = np.clip(np.abs(np.einsum("ij,ij->i", wi, h)), 0.0, 1.0)
    right, wrong = dielectric_fresnel(c, 1.0 / ETA), dielectric_fresnel(c, ETA)
    ratio = np.where(
        through, (1.0 - wrong) / np.maximum(1.0 - right, 1e-300), wrong / np.maximum(right, 1e-300)
    )
    return MODEL.f(wi, wo) * np.where(wi[:, 2] < 0.0, ratio, 1.0)


def _failure(bsdf, model=MODEL, **kw) -> str:
    with pytest.raises(BRDFMismatch) as err:
        assert_bsdf_matches_model(bsdf, model, **{**FAST, **kw})
    return str(err.value)


def _cause(message: str) -> str:
    return next(line for line in message.splitlines() if line.startswith("likely cause"))


def test_a_correct_bsdf_passes_on_both_lobes_from_both_sides():
    out = assert_bsdf_matches_model(MODEL.f, MODEL, bins=(9, 8))
    assert out["rows"][:2] == ["0° reflected", "0° transmitted"]
    assert "180° transmitted" in out["rows"] and out["reciprocity"] < 1e-12
    assert max(out["max_rel_dev"]) < 1e-9  # the same function, the same quadrature


def eta2_twice(wi, wo):
    return MODEL.f(wi, wo) * np.where(_through(wi, wo), _eta_rel(wi) ** 2.0, 1.0)


SEPARABLE = WalterDielectric(GGX(0.3), Smith(correlated=False), ETA)
SLOW = pytest.mark.slow  # the mirror image of a case the default run keeps, or a generic one
BETA = WalterDielectric(GGX(0.3), Smith(correlated=True), ETA, "height-correlated")


@pytest.mark.parametrize(
    "bsdf, model, named, reciprocal",
    [
        (eta2_dropped, MODEL, "η² missing", False),
        pytest.param(eta2_twice, MODEL, "η² applied twice", False, marks=SLOW),
        pytest.param(with_cos_o, MODEL, "× cos θo", False, marks=SLOW),
        pytest.param(
            lambda wi, wo: 0.8 * MODEL.f(wi, wo), MODEL, "constant factor: brdf ≈ 0.8 ×", True,
            marks=SLOW,
        ),
        (fresnel_not_flipped, MODEL, "relative index not inverted", False),
        (SEPARABLE.f, MODEL, "separable Smith G1(wi)·G1(wo) for the height-correlated", True),
        pytest.param(MODEL.f, SEPARABLE,
         "height-correlated Smith 1/(1 + Λ(wi) + Λ(wo)) on both lobes for the separable", True,
         marks=SLOW),
        (BETA.f, MODEL,
         "B(1 + Λ(wi), 1 + Λ(wo)) across the interface for the height-correlated", True),
        pytest.param(MODEL.f, BETA,
         "1/(1 + Λ(wi) + Λ(wo)) on both lobes for the height-correlated Smith with Heitz", True,
         marks=SLOW),
    ],
)  # fmt: skip
def test_a_broken_bsdf_fails_and_the_message_names_its_bug(bsdf, model, named, reciprocal):
    """Each bug is named; those that break Walter et al. 2007's generalised reciprocity
    (eq. 21) are reported as such too, the Smith forms and a constant factor keep it."""
    message = _failure(bsdf, model, theta_i=(75, 165))
    assert named in _cause(message), message
    assert ("f(a, b)/η_b² = f(b, a)/η_a²" not in message) == reciprocal, message


def test_the_adjoint_passes_as_the_importance_convention():
    assert_bsdf_matches_model(importance_form, MODEL, convention="importance", **FAST)
    refused(lambda: assert_bsdf_matches_model(MODEL.f, MODEL, convention="adjoint"), "convention")


@pytest.mark.parametrize(
    "bsdf, convention",
    [(importance_form, "radiance"), pytest.param(MODEL.f, "importance", marks=SLOW)],
)
def test_a_bsdf_in_the_other_convention_fails_as_the_eta2_question(bsdf, convention):
    """The adjoint f(wo, wi) read as radiance (the default), or the radiance BSDF read as
    importance: the transmitted lobes are off by η_i²/η_o², named so."""
    message = _failure(bsdf, convention=convention)
    assert "the other convention than convention= says" in _cause(message), message


def test_bad_input_is_refused():
    refused(lambda: assert_bsdf_matches_model(MODEL.f, MODEL, theta_i=[90]), "theta_i")
    refused(lambda: assert_bsdf_matches_model(MODEL.f, MODEL, theta_i=[181]), "theta_i")
    refused(lambda: assert_bsdf_matches_model(MODEL.f, MODEL.f), "model", "WalterDielectric")
    refused(lambda: assert_bsdf_matches_model("glass", MODEL), "bsdf")
    tile = gaussian(32, 1.0, 1.2, 8.0, seed=0)
    refused(lambda: assert_bsdf_agrees(MODEL.f, tile, 1.5, [30], rays="auto"), "rays")
    refused(lambda: assert_bsdf_agrees(MODEL.f, tile, None, [30], rays=10_000), "transmission")


@pytest.fixture(scope="module")
def glass_tiles():
    return [gaussian(128, 1.0, 1.2, 8.0, seed=k) for k in range(4)]


def test_walters_bsdf_agrees_with_a_traced_rough_interface_and_a_scaled_one_does_not(
    glass_tiles, tmp_path_factory
):
    """Four Gaussian tiles (m = 0.3, where Smith holds away from grazing), lit from the air and
    from inside: Walter et al. 2007's BSDF with the tiles' realised Beckmann roughness agrees
    with their order 1 on both lobes; the same × 0.9 fails, named a constant factor."""
    ndf = realised_ndf(glass_tiles)
    model = WalterDielectric(ndf, Smith(correlated=True), ETA)
    kw = dict(theta_i=[30, 150], rays=400_000, bins=(15, 13), cache=tmp_path_factory.mktemp("c"))
    out = assert_bsdf_agrees(model.f, glass_tiles, ETA, **kw)
    assert len(out["verdicts"]) == 4
    with pytest.raises(BRDFMismatch) as err:
        assert_bsdf_agrees(lambda wi, wo: 0.9 * model.f(wi, wo), glass_tiles, ETA, **kw)
    message = str(err.value)
    assert "transmitted" in message.splitlines()[0]
    assert "constant factor: brdf ≈ 0.9" in message, message
