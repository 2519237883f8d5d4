"""Mitsuba 3's roughdielectric through microsim.testing's BSDF checks (``testing.mitsuba``,
``testing.bsdf``): evaluated on both hemispheres in either transport mode, it implements
Walter et al. 2007's BSDF with Mitsuba's separable Smith G — its Radiance mode in microsim's
radiance convention, its Importance mode the adjoint — and the checks name the η² and
G-form differences. Skipped where Mitsuba or its LLVM backend is unusable."""

import re
from pathlib import Path

import numpy as np
import pytest
from support import refused

from microsim.analytic import WalterDielectric
from microsim.analytic.masking import Smith
from microsim.testing.agreement import BRDFMismatch
from microsim.testing.bsdf import assert_bsdf_matches_model
from microsim.testing.mitsuba import mitsuba_brdf, mitsuba_model


def _glass(distribution="ggx", alpha=0.3, **more):
    return {"type": "roughdielectric", "distribution": distribution, "alpha": alpha, **more}


FAST = dict(theta_i=(45, 150), bins=(9, 8))
DOCS = Path(__file__).resolve().parents[1] / "docs" / "testing.md"


@pytest.mark.parametrize("distribution", ["ggx", "beckmann"])
def test_roughdielectric_implements_walters_bsdf_with_separable_smith(mitsuba, distribution):
    """The closed form: the plugin's float32 α, separable G (the rational G1 for Beckmann),
    η = int_ior/ext_ior; Mitsuba's float32 BSDF matches it in every bin from both sides."""
    bsdf = _glass(distribution, int_ior=1.5, ext_ior=1.0)
    model = mitsuba_model(bsdf)
    assert isinstance(model, WalterDielectric) and not model.masking.correlated
    assert model.eta == pytest.approx(1.5, rel=1e-7)
    assert (model.masking.lambda_method == "walter2007") == (distribution == "beckmann")
    assert_bsdf_matches_model(mitsuba_brdf(bsdf), model, **FAST)


def test_the_default_exterior_is_air_not_vacuum(mitsuba):
    """Mitsuba's default ext_ior is air (1.000277): η = 1.5046/1.000277 (BK7 in air)."""
    assert mitsuba_model(_glass()).eta == pytest.approx(1.5046 / 1.000277, rel=1e-6)


def test_the_transport_mode_is_the_convention(mitsuba):
    """TransportMode.Importance is the importance convention (its BTDF without the radiance
    scale 1/η²); read as radiance it fails as the η² question."""
    bsdf = _glass()
    importance = mitsuba_brdf(bsdf, mode="importance")
    assert_bsdf_matches_model(importance, mitsuba_model(bsdf), convention="importance", **FAST)
    with pytest.raises(BRDFMismatch, match="the other convention than convention= says"):
        assert_bsdf_matches_model(importance, mitsuba_model(bsdf), **FAST)
    refused(lambda: mitsuba_brdf(bsdf, mode="adjoint"), "mode", "radiance, importance")


def test_its_g_is_named_against_the_height_correlated_model(mitsuba):
    """Against Walter's BSDF with height-correlated Smith (pbrt-v4's choice), Mitsuba's
    separable G is named."""
    mine = mitsuba_model(_glass(int_ior=1.5, ext_ior=1.0))
    correlated = WalterDielectric(mine.ndf, Smith(correlated=True), mine.eta)
    with pytest.raises(BRDFMismatch) as err:
        assert_bsdf_matches_model(
            mitsuba_brdf(_glass(int_ior=1.5, ext_ior=1.0)), correlated, theta_i=(75, 165),
            bins=(9, 8),
        )  # fmt: skip
    assert "separable Smith G1(wi)·G1(wo) for the height-correlated" in str(err.value)


def test_mitsuba_is_zero_on_the_horizon_and_evaluates_below_it(mitsuba):
    f = mitsuba_brdf(_glass(int_ior=1.5, ext_ior=1.0))
    wi = np.array([[0.0, 0.0, 1.0], [0.0, 0.0, -1.0], [1.0, 0.0, 0.0]])
    wo = np.array([[0.0, 0.0, -1.0], [0.0, 0.0, -1.0], [0.0, 0.0, 1.0]])
    value = f(wi, wo)
    assert value[0] > 0 and value[1] > 0 and value[2] == 0.0


def test_refused_plugins_and_factors(mitsuba):
    refused(lambda: mitsuba_model({"type": "dielectric"}), "roughdielectric")
    refused(lambda: mitsuba_model(_glass(specular_transmittance=0.5)), "specular_transmittance")


@pytest.mark.slow
def test_the_docs_example_runs_as_printed(mitsuba):
    """docs/testing.md's roughdielectric example (after its marker) is this module's checks."""
    text = DOCS.read_text(encoding="utf-8")
    block = re.search(r"<!-- mitsuba-dielectric-example -->\s*```python\n(.*?)```", text, re.S)
    assert block, "docs/testing.md has no block after <!-- mitsuba-dielectric-example -->"
    namespace = {}
    exec(compile(block.group(1), str(DOCS), "exec"), namespace)
    for name, fn in namespace.items():
        if name.startswith("test_"):
            fn()
