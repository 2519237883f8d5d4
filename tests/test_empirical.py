"""Empirical (histogram) NDF: normalisation, agreement with the sampled NDF, sampler, checks."""

import numpy as np
import pytest
from support import pearson_chi2, sidak

from microsim import analytic as an
from microsim.vectors import spherical

N = 1_000_000
ALPHA = sidak(0.01, 3)  # sampler χ² family of this file: isotropic, anisotropic, φ marginal
Z = 5.0  # per-bin tolerance in standard deviations


@pytest.fixture(scope="module")
def beckmann_normals():
    rng = np.random.default_rng(20090101)
    ndf = an.Beckmann(0.3)
    return ndf, ndf.sample(rng.random(N), rng.random(N))


@pytest.fixture(scope="module")
def emp(beckmann_normals):
    return an.Empirical(beckmann_normals[1])


def test_exactly_normalised(emp):
    # ∫ D h_z dω over each bin = π D Δ(sin²θ); and independently by Gauss–Legendre per bin
    assert abs(np.sum(emp.bin_D * np.pi * np.diff(emp.q_edges)) - 1.0) < 1e-9
    gx, gw = np.polynomial.legendre.leggauss(4)
    a, b = emp.theta_edges[:-1, None], emp.theta_edges[1:, None]
    t = 0.5 * (a + b) + 0.5 * (b - a) * gx
    integral = np.sum(0.5 * (b - a) * gw * emp.tilt_pdf_rad(t))
    assert abs(integral - 1.0) < 1e-9
    assert emp.cdf_theta_rad(np.pi / 2) == 1.0 and emp.cdf_theta_rad(0.0) == 0.0


def test_matches_beckmann_per_bin(beckmann_normals, emp):
    """Each bin's weight vs the Beckmann probability between its (data-driven) edges.

    The probability content between order statistics is Beta-distributed with the binomial
    variance p(1 − p)/N, so |w − p| < 5σ per bin (≈ 200 bins: false alarm ≲ 1e-4)."""
    ndf = beckmann_normals[0]
    p = np.diff(ndf.cdf_theta_rad(emp.theta_edges))
    w = emp.bin_weights
    sigma = np.sqrt(np.maximum(p, w) * (1 - np.minimum(p, w)) / N) + 1e-12
    assert np.all(np.abs(w - p) < Z * sigma)
    # and the D values themselves: D_emp vs the bin average of D, same tolerance
    d_avg = p / (np.pi * np.diff(emp.q_edges))
    assert np.all(np.abs(emp.bin_D - d_avg) < Z * sigma / (np.pi * np.diff(emp.q_edges)))


def test_narrow_lobe_is_resolved():
    """Quantile bins resolve a κ = 1024 vMF lobe (width ≈ 0.03 rad): D(0) within 5σ."""
    rng = np.random.default_rng(7)
    ndf = an.VonMisesFisher(1024.0)
    emp = an.Empirical(ndf.sample(rng.random(200_000), rng.random(200_000)))
    p0 = ndf.cdf_theta_rad(emp.theta_edges[1])
    d0 = p0 / (np.pi * emp.q_edges[1])
    sigma = np.sqrt(p0 / 200_000) / (np.pi * emp.q_edges[1])
    assert abs(emp.D_cos(1.0) - d0) < Z * sigma
    assert emp.theta_edges[1] < 0.01  # first bin far narrower than the lobe


def test_quantile_inverts_cdf(emp):
    u = np.linspace(0.0, 1.0, 1001)
    assert np.allclose(emp.cdf_theta_rad(emp.tilt_quantile_rad(u)), u, atol=1e-12)
    th = np.linspace(0.0, emp.max_tilt, 777)
    assert np.allclose(emp.tilt_quantile_rad(emp.cdf_theta_rad(th)), th, atol=1e-9)


def test_default_bin_rule(emp):
    # 2 N^(1/3) = 200 equal-weight bins, plus splits of bins wider than 2°
    assert np.sum(emp.bin_weights > 0) >= 200
    assert np.max(np.diff(emp.theta_edges)) <= np.radians(2.0) + 1e-12
    assert emp.D_cos(np.cos(np.radians(89.0))) == 0.0  # no facet tilted that far
    assert emp.params()["n_facets"] == N


def test_sampler_chi2(emp):
    rng = np.random.default_rng(11)
    h = emp.sample(rng.random(N), rng.random(N))
    theta = np.arctan2(np.hypot(h[:, 0], h[:, 1]), h[:, 2])
    counts, _ = np.histogram(theta, emp.theta_edges)
    _, _, p = pearson_chi2(counts, emp.bin_weights * N)
    assert p > ALPHA


def _anisotropic_normals(n, mx, my, rng):
    """Normals of a Gaussian heightfield with per-axis rms slopes mx/√2, my/√2 (equal weights)."""
    sx = rng.normal(0, mx / np.sqrt(2), n)
    sy = rng.normal(0, my / np.sqrt(2), n)
    v = np.stack([-sx, -sy, np.ones(n)], axis=-1)
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def test_anisotropic_phi_marginal_and_sampler():
    rng = np.random.default_rng(3)
    mx, my = 0.2, 0.5
    emp = an.Empirical(_anisotropic_normals(N, mx, my, rng), isotropic=False)
    assert not emp.isotropic and emp.params()["n_phi_bins"] == 24
    # φ marginal vs the elliptical-Gaussian angle law: tan ψ = (my/mx) tan ψ', ψ' uniform
    e = emp.phi_edges
    cdf = np.unwrap(np.arctan2(mx * np.sin(e), my * np.cos(e))) / (2 * np.pi)
    p = np.diff(cdf)
    w = emp.cell_weights.sum(axis=0)
    assert np.all(np.abs(w - p) < Z * np.sqrt(p * (1 - p) / N))
    # D(h) follows the cells; D_cos is their azimuthal mean; normalised
    assert (
        abs(np.sum(emp.cell_D * 0.5 * np.diff(e)[None, :] * np.diff(emp.q_edges)[:, None]) - 1.0)
        < 1e-9
    )
    hx = spherical(np.radians(15.0), 0.0)
    hy = spherical(np.radians(15.0), np.pi / 2)
    assert emp.D(hy) > 3.0 * emp.D(hx)  # rougher along y: Beckmann ratio 4.5 here
    # sampler χ² over (θ, φ) cells against the cell weights
    h = emp.sample(rng.random(N), rng.random(N))
    theta = np.arctan2(np.hypot(h[:, 0], h[:, 1]), h[:, 2])
    phi = np.mod(np.arctan2(h[:, 1], h[:, 0]), 2 * np.pi)
    counts, _, _ = np.histogram2d(theta, phi, [emp.theta_edges, emp.phi_edges])
    _, _, pval = pearson_chi2(counts, emp.cell_weights * N)
    assert pval > ALPHA


def test_weights_are_projected_areas():
    """Weights reweight the histogram: two tilts, one with 3× the projected area."""
    n = np.array([[0.0, 0.0, 1.0], [np.sin(0.5), 0.0, np.cos(0.5)]])
    emp = an.Empirical(n, weights=[1.0, 3.0], n_theta=2)
    assert np.isclose(emp.cdf_theta_rad(0.25), 0.25)


def test_atom_is_smeared_over_one_bin():
    """A flat facet set (all θ = 0) is a delta: it fills the first 2° bin, exactly normalised."""
    emp = an.Empirical(np.tile([0.0, 0.0, 1.0], (1000, 1)))
    assert emp.cdf_theta_rad(np.radians(2.0)) == 1.0
    assert np.isclose(emp.D_cos(1.0) * np.pi * np.sin(np.radians(2.0)) ** 2, 1.0)


@pytest.mark.parametrize(
    "normals, weights, match",
    [
        (np.zeros((0, 3)), None, "normals"),
        ([[0.0, 0.0, 1.0], [1.0, 0.0, 0.0]], None, "upper hemisphere"),
        ([[0.0, 0.6, -0.8]], None, "upper hemisphere"),
        ([[0.0, 0.0, 1.1]], None, "unit"),
        ([[0.0, 0.0, 1.0]], [-1.0], "weights"),
        ([[0.0, 0.0, 1.0]], [0.0], "weights"),
        ([[0.0, 0.0, 1.0]], [1.0, 2.0], "weights"),
    ],
)
def test_invalid_input(normals, weights, match):
    with pytest.raises(ValueError, match=match):
        an.Empirical(normals, weights)
