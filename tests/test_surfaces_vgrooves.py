"""V-groove surfaces: facet tilts follow D(h)(h·n) for every NDF; exact geometry
(docs/design.md)."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy import integrate, stats
from support import pearson_chi2, sidak

from microsim import analytic as an
from microsim.surfaces import vgrooves

NDFS = {
    "beckmann-0.3": an.Beckmann(0.3),
    "ggx-0.3": an.GGX(0.3),
    "blinn-phong-20": an.BlinnPhong(20.0),
    "vmf-17": an.VonMisesFisher(17.0),
    "vmf-1024": an.VonMisesFisher(1024.0),
    "abc-200-2": an.ABC(200.0, 2.0),
}
ALPHA = sidak(0.01, len(NDFS))  # one χ² test per NDF in this family


def groove_tilts_from_mesh(surf):
    """Tilt of each groove's first triangle, from the mesh geometry alone (one per groove)."""
    v, f = surf.vertices, surf.faces[0::4]
    c = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])
    return np.arctan2(np.hypot(c[:, 0], c[:, 1]), c[:, 2])


@pytest.mark.parametrize("name", NDFS)
def test_random_groove_tilts_pass_chi2_against_projected_ndf(name):
    """10⁶ random grooves: tilt histogram vs ∫ 2π D(θ) cosθ sinθ dθ per cell (D from D_cos by
    quadrature, independent of the quantile that drew the tilts)."""
    ndf = NDFS[name]
    n = 1_000_000
    theta = groove_tilts_from_mesh(vgrooves(n, ndf, seed=7, sampling="random"))
    top = float(ndf.tilt_quantile_rad(1 - 1e-4))
    edges = np.append(np.linspace(0.0, top, 41), np.pi / 2)
    probs = np.array(
        [
            integrate.quad(ndf.tilt_pdf_rad, a, b, limit=200, epsabs=1e-13)[0]
            for a, b in zip(edges[:-1], edges[1:])
        ]
    )
    assert abs(probs.sum() - 1) < 1e-6  # D is normalised (Mikkelsen 2009, eq. 14)
    observed, _ = np.histogram(theta, edges)
    _, _, p = pearson_chi2(observed, probs / probs.sum() * n)
    assert p > ALPHA, f"{name}: p = {p:.3g}"


@pytest.mark.parametrize("name", NDFS)
def test_stratified_tilt_cdf_within_quantisation(name):
    """Stratified tilts: sup|F_n − cdf_theta| = 1/(2n) exactly (no sampling noise)."""
    n = 4000
    surf = vgrooves(n, NDFS[name], seed=3)
    theta = np.sort(groove_tilts_from_mesh(surf))
    F = NDFS[name].cdf_theta_rad(theta)
    i = np.arange(1, n + 1)
    d = max(np.max(i / n - F), np.max(F - (i - 1) / n))
    assert d <= 0.5 / n + 1e-9
    assert surf.stats()["cdf_max_dev"] <= 0.5 / n + 1e-9
    # nothing beyond the 1 − 1/(2n) quantile exists (docs/design.md)
    assert theta.max() <= NDFS[name].tilt_quantile_rad(1 - 0.5 / n) + 1e-12


def test_stratified_order_is_shuffled():
    """The seeded shuffle leaves no trend of tilt with x: Spearman |ρ| < 4/√n."""
    n = 4000
    theta = groove_tilts_from_mesh(vgrooves(n, NDFS["beckmann-0.3"], seed=1))
    rho = stats.spearmanr(np.arange(n), theta).statistic
    assert abs(rho) < 4 / np.sqrt(n)
    assert np.mean(np.diff(theta) > 0) < 0.6  # not monotone


def test_geometry_rims_depths_triangles():
    n, tile = 500, 2.0
    ndf = NDFS["ggx-0.3"]
    surf = vgrooves(n, ndf, seed=0, tile=tile)
    v = surf.vertices
    assert surf.faces.shape == (4 * n, 3) and surf.faces.dtype == np.int32
    assert np.all(v[:, 2] <= 0.0)
    w = tile / n
    x_rims = -tile / 2 + w * np.arange(n + 1)
    on_rim = np.isclose(v[:, 0][:, None], x_rims[None, :], rtol=0, atol=1e-12 * tile).any(axis=1)
    assert on_rim.sum() == 2 * (n + 1) and np.all(v[on_rim, 2] == 0.0)
    # bottoms at the groove centres, depth (w/2) tan θ, and both faces of a groove tilt by θ
    nrm = surf.facet_normals()
    assert np.all(nrm[:, 2] > 0)
    tilt = np.arctan2(np.hypot(nrm[:, 0], nrm[:, 1]), nrm[:, 2]).reshape(n, 4)
    assert np.allclose(tilt, tilt[:, :1], rtol=1e-10, atol=1e-12)
    sx = np.sign(nrm[:, 0]).reshape(n, 4)
    assert np.all(sx[:, :2] >= 0) and np.all(sx[:, 2:] <= 0)
    bottoms = v[~on_rim]
    k = np.floor((bottoms[:, 0] + tile / 2) / w).astype(int)
    assert np.allclose(bottoms[:, 0], -tile / 2 + (k + 0.5) * w)
    assert np.allclose(-bottoms[:, 2], 0.5 * w * np.tan(tilt[k, 0]), rtol=1e-9)
    # the tile is covered exactly once, periodic in x and y
    assert np.isclose(surf.projected_areas().sum(), tile * tile)
    assert surf.tile_size == (tile, tile) and surf.periodic and surf.azimuth_average
    assert np.allclose(v[:, :2].min(0), -tile / 2) and np.allclose(v[:, :2].max(0), tile / 2)


def test_seeds():
    ndf = NDFS["beckmann-0.3"]
    for sampling in ("stratified", "random"):
        a = vgrooves(300, ndf, seed=5, sampling=sampling)
        b = vgrooves(300, ndf, seed=5, sampling=sampling)
        c = vgrooves(300, ndf, seed=6, sampling=sampling)
        assert np.array_equal(a.vertices, b.vertices)
        assert not np.array_equal(a.vertices, c.vertices)


@pytest.mark.parametrize(
    "kwargs, key",
    [
        (dict(n_grooves=0), "n_grooves"),
        (dict(n_grooves=2.5), "n_grooves"),
        (dict(sampling="sobol"), "sampling"),
        (dict(ndf="beckmann"), "ndf"),
        (dict(tile=-1.0), "tile"),
        (dict(seed=-1), "seed"),
    ],
)
def test_bad_input(kwargs, key):
    args = dict(n_grooves=10, ndf=NDFS["beckmann-0.3"]) | kwargs
    with pytest.raises(ValueError, match=key):
        vgrooves(**args)


@settings(max_examples=40, deadline=None)
@given(
    n=st.integers(1, 60),
    m=st.floats(0.01, 3.0),
    tile=st.floats(1e-3, 1e3),
    sampling=st.sampled_from(["stratified", "random"]),
    seed=st.integers(0, 10),
)
def test_property_finite_and_below_rims(n, m, tile, sampling, seed):
    surf = vgrooves(n, an.Beckmann(m), seed=seed, sampling=sampling, tile=tile)
    assert np.all(np.isfinite(surf.vertices)) and np.all(surf.vertices[:, 2] <= 0)
    nrm = surf.facet_normals()
    assert np.all(np.isfinite(nrm)) and np.all(nrm[:, 2] > 0)
