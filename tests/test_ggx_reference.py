"""A renderer's GGX checked against the explicit GGX surface (the catalogue's ggx-transform-0.3,
``microsim.testing.PHYSICS_REFERENCES["ggx"]``): written here from its formulas — Trowbridge &
Reitz's D, Smith's height-correlated G2 with the GGX Λ (Heitz 2014) — not from microsim's code,
it agrees within 1 % (``rtol``, energy and every bin beyond the noise of 8 realisations) at
normal incidence, where Smith holds on that surface to that tolerance (its own error there is
+1.1 ± 0.1 % in energy: ``microsim.testing.physics_error``); the same BRDF 3 % too bright
fails there. (Where Smith itself deviates, at 60° on such a surface, the failure names the
physics' own error: tests/test_testing_physics_error.py.)"""

import numpy as np
import pytest

from microsim.testing import PHYSICS_REFERENCES, assert_brdf_agrees

ALPHA = 0.3
SCENE = "ggx-transform-0.3"
SETTINGS = dict(
    material=None, rays=1_000_000, realisations=8, bins=(30, 37), symmetric=True, rtol=0.01
)


@pytest.fixture(scope="module")
def cache(tmp_path_factory):
    return tmp_path_factory.mktemp("ggx-reference")


def _lambda(w):
    tan2 = (1.0 - w[:, 2] ** 2) / w[:, 2] ** 2
    return 0.5 * (np.sqrt(1.0 + ALPHA**2 * tan2) - 1.0)


def ggx(wi, wo):
    """Torrance–Sparrow with GGX D and height-correlated Smith G2, a mirror (F = 1)."""
    h = wi + wo
    h /= np.linalg.norm(h, axis=1, keepdims=True)
    cos2 = h[:, 2] ** 2
    d = ALPHA**2 / (np.pi * (ALPHA**2 * cos2 + (1.0 - cos2)) ** 2)
    g2 = 1.0 / (1.0 + _lambda(wi) + _lambda(wo))
    return d * g2 / (4.0 * wi[:, 2] * wo[:, 2])


def ggx_too_bright(wi, wo):
    return 1.03 * ggx(wi, wo)


def test_the_ggx_reference_is_the_transform_surface():
    assert SCENE in PHYSICS_REFERENCES["ggx"]


def test_a_correct_ggx_passes_where_smith_holds(cache):
    assert_brdf_agrees(ggx, SCENE, theta_i=[0.0], cache=cache, **SETTINGS)


def test_a_ggx_three_percent_too_bright_fails_there(cache):
    with pytest.raises(AssertionError, match=r"θi = 0°") as failure:
        assert_brdf_agrees(ggx_too_bright, SCENE, theta_i=[0.0], cache=cache, **SETTINGS)
    assert "Smith holds here" in str(failure.value)
