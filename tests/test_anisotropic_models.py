"""The answer the anisotropy work exists for, as a fact the tests hold: on an explicit
anisotropic Gaussian surface (αx/αy = 4) at grazing incidence across its rough axis,
Torrance–Sparrow with MaterialX's isotropic stand-in for the Smith G (α = √(αx αy)) is much
further from the simulation than with the exact anisotropic Λ, and along the smooth axis at
moderate incidence the two coincide (Λ ≈ 0 there for both)."""

import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "examples"))

import anisotropic_smith as ex  # noqa: E402

from microsim.analytic import AnisotropicGGX, Smith, TorranceSparrow  # noqa: E402
from microsim.sim import Bins  # noqa: E402
from microsim.testing import BRDFMismatch, assert_brdf_matches_model  # noqa: E402


def _by_model(verdicts, theta):
    return {v["model"]: v for v in verdicts if v["theta_i"] == theta}


def test_the_isotropic_stand_in_misses_grazing_light_across_the_rough_axis():
    """φi = 0°, θi = 80°, 8 tiles, 4·10⁶ rays: the stand-in's Λ uses α = √(αx αy) = 0.15
    where the direction sees αx = 0.3 — too little masking, so the model is too bright: its
    energy deviation is beyond 5 % (the exact Λ's within it) and its energy-weighted error
    more than twice the exact Λ's; the run's ray noise and tile scatter are about 1 %."""
    v = _by_model(ex.compare(0.0, 8, 4_000_000, theta_i=(80.0,)), 80.0)
    exact, stand_in = v["exact Λ, correlated"], v["MaterialX α = √(αx αy)"]
    assert abs(stand_in["energy_dev"]) > 0.05 > abs(exact["energy_dev"])
    assert stand_in["rel_rms"] > 2 * exact["rel_rms"]


def test_along_the_smooth_axis_at_60_degrees_the_two_coincide():
    v = _by_model(ex.compare(90.0, 4, 1_000_000, theta_i=(60.0,)), 60.0)
    exact, stand_in = v["exact Λ, correlated"], v["MaterialX α = √(αx αy)"]
    assert abs(stand_in["energy_dev"] - exact["energy_dev"]) < 1e-3


def test_an_anisotropic_implementation_is_checked_at_its_azimuth():
    """``assert_brdf_matches_model`` at an incidence azimuth between the axes, on full-azimuth
    bins: the exact anisotropic model's own f passes; the same D with the α = √(αx αy) Smith
    G (a renderer's stand-in, a different BRDF) fails at grazing incidence and the message
    names θi and φi."""
    ndf = AnisotropicGGX(0.4, 0.1, 20.0)
    exact = TorranceSparrow(ndf, Smith(correlated=True), "aluminium")
    bins = Bins(12, 16, folded=False)
    assert_brdf_matches_model(exact.f, exact, [30, 75], phi_i=35.0, bins=bins)
    stand_in = TorranceSparrow(ndf, Smith(ndf.isotropic_equivalent(), correlated=True), "aluminium")
    with pytest.raises(BRDFMismatch, match="φi 35°"):
        assert_brdf_matches_model(stand_in.f, exact, [30, 75], phi_i=35.0, bins=bins)
