"""On heightfield tiles whose realised Beckmann m differs from the nominal one (the triangulated
grid's own slopes: ``Surface.stats``), a failure message states the realised m and how
height-correlated Smith at that m fares at the failing incidences, so a BRDF of the nominal m
is not blamed for the difference alone."""

import re

import numpy as np
import pytest

from microsim.analytic import Beckmann, torrance_sparrow
from microsim.sim.compare import realised_m
from microsim.surfaces import gaussian
from microsim.testing import assert_brdf_agrees


def test_the_message_states_the_realised_m_of_the_tiles(tmp_path):
    # σ = 1, ℓ = 3 dx: the triangulated grid realises a smaller slope variance than the
    # continuum's 2σ²/ℓ² (heightfields.gaussian_mesh_slope_var): m ≈ 0.649 for the nominal 0.667
    tiles = [gaussian(96, 1.0, 1.0, 3.0, seed=s) for s in range(4)]
    nominal = tiles[0].ensemble_ndf
    assert isinstance(nominal, Beckmann)
    m = realised_m(tiles)
    assert abs(m / nominal.m - 1.0) > 0.01

    def brdf(wi, wo):  # the nominal Beckmann with Smith's G, 10 % too dark
        return 0.9 * torrance_sparrow(wi, wo, nominal, "smith-correlated", None)

    with pytest.raises(AssertionError) as e:
        assert_brdf_agrees(
            brdf, tiles, None, [0], rays=100_000, bins=(18, 12), rtol=0.01, cache=tmp_path
        )
    line = next(x for x in str(e.value).splitlines() if "tiles realise" in x)
    printed = float(re.search(r"realise m = ([0-9.]+)", line).group(1))
    assert printed == pytest.approx(m, rel=1e-3)
    assert f"not the nominal {nominal.m:g}" in line
    assert re.search(r"ts-smith-corr at the realised m (passes|fails) at θi = 0°", line), line
    assert np.isfinite(printed)
