"""Kirchhoff order powers as the bin-averaged BRDF (microsim.wave.brdf): the flat tile's mirror
bin, the albedo as the sum of order powers, the Result schema round trip, and the calibration
of the realisation standard error (z-scores between independent groups of seeds ~ N(0, 1))."""

import warnings

import numpy as np
import pytest

from microsim.analytic.fresnel import fresnel
from microsim.errors import UsageError
from microsim.sim import Bins, Result
from microsim.surfaces import flat
from microsim.surfaces.heightfields import gaussian
from microsim.wave import kirchhoff_orders
from microsim.wave.brdf import kirchhoff_brdf


def _gauss(n, dx, sigma, corr, seed):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return gaussian(n, dx, sigma, corr, seed=seed)


def test_flat_tile_mirror_bin(tmp_path):
    """Flat tile: f̄ = F(θi)/Ω_B in the mirror bin, 0 elsewhere, albedo F(θi) to 1e-12, no
    speckle; Result.save/load keeps it."""
    s = _gauss(64, 0.2, 1e-3, 1.0, 0)
    s = s.replaced(heights=np.zeros_like(s.heights))
    bins = Bins(30, 13, True)
    th = [0.0, 20.0, 50.0]
    r = kirchhoff_brdf(s, "aluminium", th, wavelength=1.0, bins=bins)
    assert r.meta["method"] == "kirchhoff"
    f = fresnel(np.cos(np.radians(th)), "aluminium")
    assert np.allclose(r.albedo(), f, rtol=0, atol=1e-12)
    assert np.all(r.stderr == 0.0)
    omega = bins.projected_solid_angle()
    for t, theta in enumerate(th):
        i = min(int(theta * bins.n_theta / 90.0), bins.n_theta - 1)
        j = bins.forward_index if theta > 0 else int(np.argmax(r.brdf[t, i]))
        assert r.brdf[t, i, j] == pytest.approx(f[t] / omega[i, j], rel=1e-12)
        assert np.count_nonzero(r.brdf[t]) == 1
    r.save(tmp_path)
    back = Result.load(tmp_path)
    assert np.array_equal(back.brdf, r.brdf) and back.meta["method"] == "kirchhoff"


def test_albedo_is_total_order_power():
    s = _gauss(128, 0.2, 0.02, 2.0, 1)
    r = kirchhoff_brdf(s, 1.5, 35.0, wavelength=1.0, bins=Bins(20, 9, True))
    o = kirchhoff_orders(s.heights, s.dx, 1.0, 35.0, material=1.5)
    assert r.albedo()[0] == pytest.approx(o.power.sum(), rel=1e-12)
    assert r.meta["order_power"][0] == pytest.approx(o.power.sum(), rel=1e-12)
    assert r.meta["orders"][0] == len(o.m) == r.counts.sum()
    # no fake ray ledger: the solver traces no rays
    assert r.rays is None and r.ledger is None and r.ledger_counts is None
    assert not r.has_ray_tallies and "rays=" not in repr(r)


def test_realisation_stderr_is_calibrated():
    """Two independent groups of 6 tiles (σ = 0.3 λ, ℓ = 3 λ, 32 λ): z = (A − B)/√(se_A² + se_B²)
    over the bins holding ≥ 1 % of the peak. With se from 6 tiles z is ~ Student t (≈ 10 dof),
    median |z| ≈ 0.70 (0.674 for N(0, 1)); with ≥ 100 bins the median's sd is ≈ 0.08, so
    [0.45, 0.95] is a > 3-sd band."""
    lam, bins, th = 1.0, Bins(12, 7, True), [0.0, 30.0, 45.0]
    groups = [[_gauss(200, 0.16, 0.3, 3.0, seed) for seed in range(g, g + 6)] for g in (0, 6)]
    a, b = (kirchhoff_brdf(g, "aluminium", th, wavelength=lam, bins=bins) for g in groups)
    assert a.stderr_realisation is not None and a.meta["realisations"] == 6
    mean = 0.5 * (a.brdf + b.brdf)
    sel = mean >= 0.01 * mean.max(axis=(1, 2), keepdims=True)
    z = (a.brdf - b.brdf)[sel] / np.sqrt(a.stderr**2 + b.stderr**2)[sel]
    assert sel.sum() >= 100
    assert 0.45 < float(np.median(np.abs(z))) < 0.95


def test_needs_a_heightfield():
    with pytest.raises(UsageError, match="heightfield"):
        kirchhoff_brdf(flat(), None, 0.0, wavelength=1.0)
    with pytest.raises(UsageError, match="non-empty"):
        kirchhoff_brdf([], None, 0.0, wavelength=1.0)
