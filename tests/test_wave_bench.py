"""The wave solver's bench entry (microsim.app.wave_bench): one incidence per σ, the upsampling the
sampling check needs at σ = λ, and the smooth tile's total order power ≈ F(θi) (first-order
redistribution keeps the reflected power up to the Fresnel variation over the narrow lobe)."""

import math

import pytest

from microsim.analytic.fresnel import fresnel
from microsim.app.wave_bench import wave_bench


def test_wave_bench_small():
    rows = wave_bench(n=128, tile=25.0, theta_i=30.0)
    assert [r.sigma for r in rows] == [0.01, 1.0]
    smooth, rough = rows
    assert smooth.upsample == 1 and rough.upsample >= 1
    for r in rows:  # lattice points in the disk of radius L/λ (Gauss circle: error ≪ 3 %)
        assert r.seconds > 0 and r.orders == pytest.approx(math.pi * 25.0**2, rel=0.03)
    f = fresnel(math.cos(math.radians(30.0)), "aluminium")
    assert smooth.albedo == pytest.approx(f, rel=2e-3)
