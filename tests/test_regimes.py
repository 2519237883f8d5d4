"""The regime map (microsim.analysis.regimes): where Rayleigh–Rice and geometric optics each
stop holding against the Kirchhoff solver as σ/λ grows, checked against first-order theory.

With g = (4πσ cos θi/λ)², Kirchhoff's diffuse power is F(1 − e^{−g}) (Davies 1954) and
Rayleigh–Rice's ≈ F g, so RR overestimates by ≈ g/2 and crosses 5 % at g ≈ 0.1, i.e.
σ/λ ≈ 0.0252/cos θi; geometric optics puts all of F in its lobe, an excess e^{−g}/(1 − e^{−g})
over the diffuse power: > 50 % for g ≤ 1, while for g ≥ 10 the coherent part is < 5e-5 and
Kirchhoff tends to the facet model of the same mesh (ℓ = 10 λ ≫ λ)."""

import math

import matplotlib
import numpy as np
import pytest

from microsim.analysis.regimes import RegimeMap, crossover, regime_chart, regime_map
from microsim.errors import UsageError

matplotlib.use("Agg")


def _g(sigma, theta):
    return (4 * math.pi * sigma * math.cos(math.radians(theta))) ** 2


@pytest.fixture(scope="module")
def small():
    sig = [0.01, 0.016, 0.024, 0.037, 0.058, 0.4]
    return regime_map(
        "gaussian", sig, (0.0,), tile_over_lambda=32.0, models=("rayleigh-rice", "geometric-facets")
    )


def test_rayleigh_rice_stops_holding_where_debye_waller_says(small):
    x = small.crossovers()["rayleigh-rice"][0.0]
    assert x is not None and 0.8 < x / 0.0252 < 1.25
    i = small.models.index("rayleigh-rice")
    assert np.all(small.energy_dev[i, :3, 0] < 0)  # RR overestimates the diffuse power


def test_geometric_optics_fails_when_smooth_and_holds_when_rough(small):
    i = small.models.index("geometric-facets")
    for j, s in enumerate(small.sigma):
        if _g(s, 0.0) <= 1.0:
            assert small.energy_dev[i, j, 0] < -0.5  # −e^{-g}/(1 − e^{-g}) ≤ −0.58
        if _g(s, 0.0) >= 10.0:
            assert abs(small.energy_dev[i, j, 0]) <= 0.05
    d = small.to_dict()
    assert d["family"] == "gaussian" and len(d["energy_dev"]) == 2


def test_chart_returns_a_figure(small):
    fig = regime_chart(small)
    assert fig.axes and fig.axes[0].get_xscale() == "log"
    import matplotlib.pyplot as plt

    f2, ax = plt.subplots()
    assert regime_chart([small], ax=ax) is f2
    plt.close("all")


def test_crossover_interpolates_in_log_sigma():
    s = [0.01, 0.1, 1.0, 10.0]
    assert crossover(s, [0.01, 0.03, 0.2, 1.0]) == pytest.approx(10 ** (-1 + 0.02 / 0.17))
    assert crossover(s, [1.0, 0.5, 0.01, 0.3], side="above") == pytest.approx(
        10 ** (-1 + 0.45 / 0.49)
    )
    assert crossover(s, [0.01] * 4) is None and crossover(s, [1.0] * 4, side="above") is None
    with pytest.raises(UsageError, match="side"):
        crossover(s, s, side="left")


def test_bad_input():
    with pytest.raises(UsageError, match="family"):
        regime_map("fractal", [0.1])
    with pytest.raises(UsageError, match="corr_over_lambda"):
        regime_map("gaussian", [0.1], corr_over_lambda=3.0)


@pytest.mark.slow
@pytest.mark.parametrize("family", ["gaussian", "abc"])
def test_full_regime_map_crossovers(family):
    """σ/λ from 0.01 to 3 (14 values), θi = 0, 30, 60°, tile 64 λ (several minutes)."""
    rm = regime_map(family)
    assert isinstance(rm, RegimeMap)
    x = rm.crossovers()
    for th in (0.0, 30.0, 60.0):
        rr = x["rayleigh-rice"][th]
        assert rr is not None and 0.75 < rr * math.cos(math.radians(th)) / 0.0252 < 1.33
        geo = x["geometric-facets"][th]
        lo, hi = 0.08 / math.cos(math.radians(th)), 0.25 / math.cos(math.radians(th))
        assert geo is not None and lo < geo < hi
