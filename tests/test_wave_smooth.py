"""Exact check 3 of the wave solver on a smooth random tile (4πσ cos θi/λ = 0.05): the specular
order carries F·exp(−(4πσ cos θi/λ)²) (Davies 1954; Debye–Waller) with σ the tile's realised rms
height, and the diffuse orders, summed over bins, match the first-order Kirchhoff expression
P = R·obliquity·q_z²|ĥ_mn|² built from the tile's own Fourier coefficients ĥ (its realised PSD,
no ensemble noise): equivalently BRDF = (16π²/λ⁴) cos θi cos θo Q_K PSD (module docstring)."""

import math
import warnings

import numpy as np
import pytest

from microsim.sim import Bins
from microsim.surfaces.heightfields import abc
from microsim.wave import kirchhoff_orders, obliquity
from microsim.wave.kirchhoff import incident_direction, reflectance

LAM = 1.0


@pytest.mark.parametrize("theta_i", [0.0, 30.0, 60.0])
def test_smooth_tile_davies_and_first_order(theta_i):
    """Specular: relative 1e-4 (the neglected cumulants of the realised heights are
    O((q_z σ)⁴ × excess kurtosis) ≈ 1e-7). Diffuse: within 1 % in total and 3 % per bin over
    the bins below θo = 80° holding ≥ 1 % of the largest bin; the second-order terms are
    O(q_z σ) ≤ 0.075 per order with random phase, and the Debye–Waller loss (q_z σ)² < 0.6 %."""
    ci = math.cos(math.radians(theta_i))
    sigma = 0.05 * LAM / (4 * math.pi * ci)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        surf = abc(256, 0.25, sigma, 20.0, 2.0, seed=4)
    h = surf.heights - surf.heights.mean()
    o = kirchhoff_orders(h, 0.25, LAM, theta_i, material="aluminium", upsample=2)
    wi, k = incident_direction(theta_i, 0.0), 2 * math.pi / LAM
    R = reflectance(wi, o.wo, "aluminium", "half")
    sp = o.specular_index()
    sigma_r = math.sqrt(np.mean(h**2))
    davies = R[sp] * math.exp(-((2 * k * ci * sigma_r) ** 2))
    assert abs(o.power[sp] / davies - 1) < 1e-4

    ny, nx = h.shape
    hm = np.fft.ifft2(h)[o.n % ny, o.m % nx]  # mean of h e^{i p·x}: |ĥ|² = PSD/A
    qz = k * (wi[2] + o.wo[:, 2])
    first = R * obliquity(wi, o.wo) * qz**2 * np.abs(hm) ** 2
    diffuse = np.ones(len(o.m), bool)
    diffuse[sp] = False
    bins = Bins(18, 10, True)
    idx = bins.locate(o.wo[diffuse], 0.0)
    size = bins.n_theta * bins.n_phi
    kir = np.bincount(idx, o.power[diffuse], size)
    fo = np.bincount(idx, first[diffuse], size)
    assert abs(kir.sum() / fo.sum() - 1) < 0.01
    kir, fo = kir[: 16 * bins.n_phi], fo[: 16 * bins.n_phi]  # θo < 80°
    sel = fo >= 0.01 * fo.max()
    assert sel.sum() >= 10
    assert np.max(np.abs(kir[sel] / fo[sel] - 1)) < 0.03
