"""``assert_brdf_agrees``' failure message points at the cause: the energy ratio per θi, a
constant factor named a normalisation error, a rougher distribution with its roughness, and a
correct model that is not exact on the surface named as that model itself (the physics' error,
not the implementation's). The reference is exact for Torrance–Sparrow with the V-groove G on
V-grooves, so the only deviations are the seeded ones."""

import re

import pytest

from microsim.analytic import GGX, torrance_sparrow
from microsim.surfaces import vgrooves
from microsim.testing import assert_brdf_agrees

AL = "aluminium"
KW = dict(rays=200_000, bins=(18, 12))


@pytest.fixture(scope="module")
def surface():
    return vgrooves(400, GGX(0.3))


def _message(tmp_path, surface, f) -> str:
    with pytest.raises(AssertionError) as e:
        assert_brdf_agrees(f, surface, AL, [30], cache=tmp_path, **KW)
    return str(e.value)


def test_a_constant_factor_is_called_a_normalisation_error(tmp_path, surface):
    ndf = GGX(0.3)
    msg = _message(
        tmp_path, surface, lambda wi, wo: 4 * torrance_sparrow(wi, wo, ndf, "vgroove", AL)
    )
    ratio = float(re.search(r"deviates .*?([0-9.]+)×", msg).group(1))
    assert ratio == pytest.approx(4.0, rel=0.03)  # the hemisphere's energy, ray noise ≪ 3 %
    assert "likely cause (against ts-vgroove): a constant factor: brdf ≈ 4 × the model" in msg
    assert "roughness" not in msg


def test_a_wider_lobe_is_called_a_roughness_error(tmp_path, surface):
    ndf = GGX(0.36)  # 20 % rougher than the surface
    msg = _message(tmp_path, surface, lambda wi, wo: torrance_sparrow(wi, wo, ndf, "vgroove", AL))
    assert "likely cause (against ts-vgroove): a rougher distribution: alpha ≈ 0.36 for 0.3" in msg
    assert "normalisation" not in msg


def test_a_correct_smith_ggx_is_named_as_that_model_not_as_a_bug(tmp_path, surface):
    # Smith's G is not the V-grooves' exact G: at 80° a correct Smith-GGX deviates
    ndf = GGX(0.3)
    with pytest.raises(AssertionError) as e:
        assert_brdf_agrees(
            lambda wi, wo: torrance_sparrow(wi, wo, ndf, "smith-correlated", AL),
            surface,
            AL,
            [80],
            cache=tmp_path,
            **KW,
        )
    msg = str(e.value)
    assert (
        "the brdf is ts-smith-corr itself" in msg and "the physics, not your implementation" in msg
    )
    assert "likely cause" not in msg
