"""Paths through a dielectric interface (``simulate(..., transmission=True)``, module
``microsim.sim.dielectric``): the flat interface gives Fresnel's R and Snell's directions, a
lossless rough interface loses nothing (R + T = 1, path by path), an absorbing one keeps its
refracted light, and the estimated BTDF obeys Walter et al. 2007's generalised reciprocity
f_t(i, o)/η_o² = f_t(o, i)/η_i² (eq. 21) within its standard errors."""

from __future__ import annotations

import numpy as np
import pytest

from microsim.analytic.fresnel import fresnel
from microsim.bins import Bins
from microsim.errors import UsageError
from microsim.sim import simulate
from microsim.surfaces import flat, gaussian

ETA = 1.5


@pytest.fixture(scope="module")
def rough():
    """A Gaussian heightfield of rms slope m = 0.5 (multiple scattering and total internal
    reflection both matter)."""
    return gaussian(64, 1.0, 2.0, 8.0, seed=0)


def _binomial_sigma(p: float, n: int) -> float:
    return float(np.sqrt(max(p * (1 - p), 1.0 / n) / n))


@pytest.mark.parametrize("theta_i", [0.0, 60.0, 150.0])
def test_a_flat_interface_reflects_fresnels_fraction_and_refracts_by_snells_law(theta_i):
    rays = 40_000
    bins = Bins(30, 7)
    r = simulate(flat(1.0), ETA, theta_i, transmission=True, rays=rays, bins=bins, seed=1)
    below = theta_i > 90
    t_in = np.radians(180 - theta_i if below else theta_i)
    eta_rel = 1 / ETA if below else ETA
    F = float(fresnel(np.cos(t_in), eta_rel))
    R = r.ledger["escaped_energy"][0]
    assert abs(R - F) <= 4 * _binomial_sigma(F, rays)
    assert R + r.ledger["transmitted_energy"][0] == 1.0
    # every reflected ray in the mirror bin, every transmitted one in Snell's bin (Δφ = 180°)
    t_out = np.degrees(np.arcsin(np.sin(t_in) / eta_rel))
    for f, theta_o in ((r.brdf_total()[0], np.degrees(t_in)), (r.btdf_total()[0], t_out)):
        rows, cols = np.nonzero(f)
        assert set(rows) == {int(theta_o // 3)}  # 3° bins
        if theta_i != 0:  # (at θo = 0 every Δφ is the same direction)
            assert set(cols) == {bins.shape[1] - 1}
    assert r.ledger["escaped_1"][0] + r.ledger["transmitted_1"][0] == 1.0


def test_beyond_the_critical_angle_a_flat_interface_reflects_everything():
    r = simulate(flat(1.0), ETA, 130.0, transmission=True, rays=8192, bins=Bins(9, 7))
    assert r.ledger["escaped_energy"][0] == 1.0
    assert r.ledger["transmitted_energy"][0] == 0.0
    assert r.ledger["tir_1"][0] == 1.0


@pytest.mark.parametrize("theta_i", [0.0, 60.0, 85.0, 130.0, 175.0])
def test_a_lossless_rough_interface_loses_nothing(rough, theta_i):
    """Every path ends reflected or transmitted (the ledger closes path by path: R + T = 1),
    and the bins, which cover both hemispheres, see exactly that energy."""
    rays = 3 * 4096
    r = simulate(rough, ETA, theta_i, transmission=True, bounces="all", rays=rays, bins=Bins(9, 7))
    L = r.ledger
    R, T = L["escaped_energy"][0], L["transmitted_energy"][0]
    lost = L["cut_energy"][0] + L["unresolved_path"][0] + L["missed_path"][0]
    assert lost * rays <= 1  # at most one path of the run unresolved (grazing wrap cap)
    assert R + T + lost == pytest.approx(1.0, abs=1e-12)
    assert L["absorbed_energy"][0] == pytest.approx(0.0, abs=1e-12)
    assert r.reflectance()[0] == pytest.approx(R, rel=1e-12)
    assert r.transmittance()[0] == pytest.approx(T, rel=1e-12)
    assert 0 < R < 1 and 0 < T < 1


def test_an_absorbing_medium_keeps_what_it_refracts(rough):
    """With a complex index the medium's bulk keeps the refracted light: nothing is
    transmitted, R + absorbed = 1, and the reflected light is the opaque surface's (the same
    paths with the same Fresnel weights)."""
    kw = dict(rays=4096, bins=Bins(9, 7), bounces="all")
    eta = 0.769 + 6.08j
    r = simulate(rough, eta, 40.0, transmission=True, **kw)
    opaque = simulate(rough, eta, 40.0, **kw)
    assert r.ledger["transmitted_energy"][0] == 0.0
    assert r.ledger["escaped_energy"][0] + r.ledger["absorbed_energy"][0] == pytest.approx(1.0)
    np.testing.assert_allclose(r.brdf_orders, opaque.brdf_orders, rtol=1e-12, atol=0)


def test_the_btdf_obeys_the_generalised_reciprocity(rough):
    """f_t(i, o)/η_o² = f_t(o, i)/η_i² (Walter et al. 2007, eq. 21): light from the air at θa
    seen transmitted at θb inside (the 2° bin centred on θb, Δφ = 180°) against light from
    inside at θb seen transmitted at θa, for θa in {11°, 31°, 51°} and θb in {13°, 21°}, inside
    the transmitted lobe (bin averages differ from point values by ~1e-4 of f here). Each
    pair must agree within 4 combined standard errors; without the η² factor the ratio would
    be off by 125 %."""
    bins = Bins(45, 7)
    air, medium = [11.0, 31.0, 51.0], [13.0, 21.0]
    kw = dict(transmission=True, bounces="all", rays=200_000, bins=bins, isotropic=True)
    down = simulate(rough, ETA, air, **kw)
    up = simulate(rough, ETA, [180.0 - t for t in medium], **kw)
    through = bins.shape[1] - 1  # Δφ = 180°: light going on through the surface
    z = []
    for a, ta in enumerate(air):
        for b, tb in enumerate(medium):
            ka, kb = int(ta // 2), int(tb // 2)
            f_down, s_down = down.btdf_total()[a, kb, through], _btdf_stderr(down, a, kb, through)
            f_up, s_up = up.btdf_total()[b, ka, through], _btdf_stderr(up, b, ka, through)
            assert f_down > 0 and f_up > 0
            z.append((f_down / ETA**2 - f_up) / np.hypot(s_down / ETA**2, s_up))
    assert np.max(np.abs(z)) < 4, z


def _btdf_stderr(r, t, k, p):
    """The standard error of the BTDF summed over orders in one bin (orders are tallied from
    the same paths, each path in one order: their variances add)."""
    return float(np.sqrt(np.sum(r.stderr_btdf_orders[:, t, k, p] ** 2)))


def test_transmission_is_refused_where_it_has_no_meaning(rough):
    with pytest.raises(UsageError, match="transmission=True needs a material"):
        simulate(rough, None, 30.0, transmission=True, rays=64)
    with pytest.raises(UsageError, match=r"theta_i must lie in \[0, 90\)"):
        simulate(rough, ETA, 120.0, rays=64)
    with pytest.raises(UsageError, match="absorbing medium"):
        simulate(rough, 0.7 + 6j, 120.0, transmission=True, rays=64)
    with pytest.raises(UsageError, match="transmission must be True or False"):
        simulate(rough, ETA, 30.0, transmission="yes", rays=64)


def test_paths_are_bitwise_independent_of_threads_and_chunks(rough):
    """The roulette draws from a hash of each path's number, so the chunking that groups
    paths changes no number."""
    kw = dict(transmission=True, bounces="all", rays=5 * 4096 + 17, bins=Bins(9, 7))
    a = simulate(rough, ETA, [30.0, 150.0], threads=1, chunk=4096, **kw)
    b = simulate(rough, ETA, [30.0, 150.0], threads=2, chunk=3 * 4096, **kw)
    for name in ("brdf_orders", "btdf_orders", "stderr_btdf_orders"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name))
    assert a.ledger_counts.keys() == b.ledger_counts.keys()
    for k in a.ledger_counts:
        np.testing.assert_array_equal(a.ledger_counts[k], b.ledger_counts[k])
