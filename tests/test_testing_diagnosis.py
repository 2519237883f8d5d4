"""``assert_brdf_agrees``' failure message points at the cause: the energy ratio per θi, a
constant factor flagged as a normalisation error, a lobe wider than the reference's as a
roughness error. The reference is exact for the model (V-groove G on V-grooves), so the only
deviations are the seeded bugs."""

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
    assert "normalisation error" in msg and "roughness" not in msg


def test_a_wider_lobe_is_called_a_roughness_error(tmp_path, surface):
    ndf = GGX(0.36)  # 20 % rougher than the surface
    msg = _message(tmp_path, surface, lambda wi, wo: torrance_sparrow(wi, wo, ndf, "vgroove", AL))
    assert re.search(r"lobe \d+% wider than the reference's .*: roughness\?", msg), msg
    assert "normalisation" not in msg
