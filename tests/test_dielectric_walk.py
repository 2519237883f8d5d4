"""Heitz et al. 2016's random walk on a dielectric interface (``smith_random_walk(...,
transmission=True)``, ``dielectric_walk_bin_averages``) and Kulla & Conty 2017's energy
compensation for rough dielectrics (``KullaContyDielectric``).

The single-scattering reference is Walter et al. 2007, eq. 20 and 21, with height-correlated
Smith masking (G2 = 1/(1 + Λi + Λo) reflecting, B(1 + Λi, 1 + Λo) refracting:
``WalterDielectric(..., crossing="height-correlated")``), integrated over each bin by
Gauss–Legendre quadrature here."""

import numpy as np
import pytest

from microsim import analytic as an
from microsim.analytic import random_walk as rw
from microsim.analytic.energy_compensation import DielectricAlbedoTable, KullaContyDielectric
from microsim.analytic.fresnel import fresnel
from microsim.bins import Bins
from microsim.errors import UsageError

ETA = 1.5
NDF = an.GGX(0.5)
WALTER = an.WalterDielectric(NDF, an.Smith(correlated=True), ETA, "height-correlated")


def _direction(theta_deg, phi_deg=0.0):
    t, p = np.radians(theta_deg), np.radians(phi_deg)
    return np.stack(
        np.broadcast_arrays(np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)), axis=-1
    )


def _walter_single(wi, wo):
    """Walter et al. 2007 eq. 20 (reflection) and 21 (transmission, radiance convention) with
    height-correlated Smith G across the interface as Heitz 2014 derives it, sr⁻¹, for one wi
    and an array of wo (``WalterDielectric(..., crossing="height-correlated")``)."""
    return WALTER.f(np.broadcast_to(wi, wo.shape), wo)


def _bin_averages(f, theta_i, bins, transmitted, n=8):
    """(1/Ω_B)∫_B f(wo)|cos θo| dωo for the bins of one hemisphere of light incident at θi
    (φi = 0): θo from the pole of that side, Δφ of the direction itself, folded bins counting
    ±Δφ. ``f``: wo (..., 3) → sr⁻¹. n × n Gauss–Legendre nodes per bin."""
    x, w = np.polynomial.legendre.leggauss(n)
    te, pe = np.radians(bins.theta_edges), np.radians(bins.phi_edges)
    t = 0.5 * (te[:-1, None] + te[1:, None]) + 0.5 * np.diff(te)[:, None] * x
    wt = 0.5 * np.diff(te)[:, None] * w
    p = 0.5 * (pe[:-1, None] + pe[1:, None]) + 0.5 * np.diff(pe)[:, None] * x
    wp = 0.5 * np.diff(pe)[:, None] * w
    incident_above = np.cos(np.radians(theta_i)) > 0
    z_sign = 1.0 if incident_above != transmitted else -1.0
    T, P = t[:, None, :, None], p[None, :, None, :]
    wo = np.stack(
        np.broadcast_arrays(np.sin(T) * np.cos(P), np.sin(T) * np.sin(P), z_sign * np.cos(T)),
        axis=-1,
    )
    vals = f(wo) * np.cos(T) * np.sin(T) * wt[:, None, :, None] * wp[None, :, None, :]
    fold = 2.0 if bins.folded else 1.0
    return fold * vals.sum(axis=(2, 3)) / bins.projected_solid_angle()


def test_the_dielectric_walk_loses_no_path_from_either_side():
    """Russian roulette keeps every weight 1: each path leaves up, leaves down or is cut,
    R + T + cut = 1 path by path, nothing absorbed, from both sides, grazing included; the
    binned energies add up to R and T (every exit lands in a bin of its own side)."""
    angles = [0.0, 45.0, 89.9, 90.1, 135.0, 180.0]
    for theta in angles:
        wi = np.broadcast_to(_direction(theta), (20_000, 3))
        p = rw.smith_random_walk(wi, NDF, ETA, 7, transmission=True)
        left = p.order > 0
        assert np.all(p.absorbed == 0.0)
        assert np.all(p.weight == np.where(left, 1.0, 0.0))
        assert np.all(p.weight + p.cut == 1.0)
        assert np.allclose(np.linalg.norm(p.wo[left], axis=1), 1.0, atol=1e-12)
        down = np.count_nonzero(p.wo[left, 2] < 0)
        assert 0 < down < np.count_nonzero(left), theta  # both hemispheres are reached
    bins = Bins(9, 7)
    r = rw.dielectric_walk_bin_averages(angles, bins, NDF, ETA, n_paths=20_000, seed=1)
    np.testing.assert_array_equal(r.cut, 0.0)
    np.testing.assert_allclose(r.R + r.T, 1.0, rtol=0, atol=1e-12)
    omega = bins.projected_solid_angle()
    for part, total in ((r.reflected, r.R), (r.transmitted, r.T)):
        np.testing.assert_allclose((part.values * omega).sum(axis=(1, 2, 3)), total, atol=1e-12)
        np.testing.assert_allclose(part.energy.sum(axis=1), total, atol=1e-12)


def test_a_nearly_smooth_interface_gives_the_fresnel_reflectance_from_either_side():
    """Beckmann m = 0.02 (light tails): R is the smooth interface's F(cos θi) for the relative
    index η from the air and 1/η from inside (total internal reflection beyond 41.8° inside),
    within 4 standard errors plus the roughness's own effect (≲ 2e-3 here)."""
    angles = np.array([0.0, 40.0, 150.0, 130.0])
    r = rw.dielectric_walk_bin_averages(
        angles, Bins(2, 3), an.Beckmann(0.02), ETA, n_paths=50_000, seed=2
    )
    mu = np.cos(np.radians(angles))
    want = np.where(mu > 0, fresnel(np.abs(mu), ETA), fresnel(np.abs(mu), 1.0 / ETA))
    assert want[-1] > 1.0 - 1e-12  # 50° inside: beyond the critical angle
    assert np.all(np.abs(r.R - want) < 4 * r.R_stderr + 2e-3), (r.R, want)


@pytest.mark.parametrize("theta_i", [30.0, 70.0, 150.0, 130.0])
def test_order_one_of_the_walk_is_walters_bsdf_with_height_correlated_smith(theta_i):
    """Order 1 of the walk against Walter et al. 2007 (eq. 20/21, height-correlated Smith G:
    B(1 + Λi, 1 + Λo) for refraction) bin by bin in both hemispheres (within 5 standard errors
    over ~126 bins) and in total energy (4 standard errors: without the mirrored heights below
    the surface the walk's refraction would have G2 = 1/(1 + Λi + Λo), 2 % more T at 70°)."""
    bins = Bins(9, 7)
    r = rw.dielectric_walk_bin_averages(theta_i, bins, NDF, ETA, n_paths=200_000, orders=2, seed=3)
    wi = _direction(theta_i)
    omega = bins.projected_solid_angle()
    for part, transmitted in ((r.reflected, False), (r.transmitted, True)):
        want = _bin_averages(lambda wo: _walter_single(wi, wo), theta_i, bins, transmitted)
        got, se = part.values[0, 0], part.stderr[0, 0]
        seen = se > 0
        assert np.all(want[~seen] * omega[~seen] < 2e-5), "an empty bin the BSDF fills"
        z = (got[seen] - want[seen]) / se[seen]
        assert np.max(np.abs(z)) < 5, (transmitted, np.max(np.abs(z)))
        e, e_se = part.energy[0, 0], part.energy_stderr[0, 0]
        assert abs(e - np.sum(want * omega)) < 4 * e_se, (transmitted, e, np.sum(want * omega))


def test_the_walks_btdf_obeys_the_generalised_reciprocity():
    """f_t(i, o)/η_o² = f_t(o, i)/η_i² (Walter et al. 2007, eq. 21) on all orders, as
    tests/test_dielectric.py checks the simulation: light from the air at θa seen transmitted
    at θb inside (2° bin, Δφ = 180°) against light from inside at θb seen at θa. Each pair
    within 4 combined standard errors; without the η² the ratio would be off by 125 %."""
    bins = Bins(45, 7)
    air, medium = [11.0, 31.0, 51.0], [13.0, 21.0]
    kw = dict(n_paths=200_000, seed=4)
    down = rw.dielectric_walk_bin_averages(air, bins, NDF, ETA, **kw).transmitted
    up = rw.dielectric_walk_bin_averages([180.0 - t for t in medium], bins, NDF, ETA, **kw)
    up = up.transmitted
    through = bins.forward_index
    z = []
    for a, ta in enumerate(air):
        for b, tb in enumerate(medium):
            ka, kb = int(ta // 2), int(tb // 2)
            f_down = down.values[a, :, kb, through].sum()
            s_down = np.sqrt(np.sum(down.stderr[a, :, kb, through] ** 2))
            f_up = up.values[b, :, ka, through].sum()
            s_up = np.sqrt(np.sum(up.stderr[b, :, ka, through] ** 2))
            assert f_down > 0 and f_up > 0
            z.append((f_down / ETA**2 - f_up) / np.hypot(s_down / ETA**2, s_up))
    assert np.max(np.abs(z)) < 4, z


def test_the_dielectric_walk_refuses_what_has_no_meaning():
    wi = np.array([[0.0, 0.0, 1.0]])
    for material in (None, 0.2 + 3j, 1.0):
        with pytest.raises(UsageError, match="real index of refraction"):
            rw.smith_random_walk(wi, NDF, material, 0, transmission=True)
    with pytest.raises(UsageError, match="above the horizon"):
        rw.smith_random_walk(-wi, NDF, ETA, 0)
    with pytest.raises(UsageError, match="transmission must be True or False"):
        rw.smith_random_walk(wi, NDF, ETA, 0, transmission="yes")
    with pytest.raises(UsageError, match=r"\(90, 180\]"):
        rw.dielectric_walk_bin_averages(90.0, Bins(2, 3), NDF, ETA, n_paths=10)


# --- Kulla & Conty 2017, dielectric ------------------------------------------------------------
@pytest.fixture(scope="module")
def compensation():
    table = DielectricAlbedoTable.from_walk(NDF, ETA, n_paths=20_000, seed=5)
    return KullaContyDielectric(eta=ETA, table=table)


def _albedos(f, theta_i, bins=Bins(30, 31)):
    """(R, T) of a BSDF f(wo) for light at θi, by ``_bin_averages`` over both hemispheres."""
    omega = bins.projected_solid_angle()
    return tuple(
        float(np.sum(_bin_averages(f, theta_i, bins, transmitted, n=6) * omega))
        for transmitted in (False, True)
    )


@pytest.mark.parametrize("theta_i", [0.0, 48.0, 72.0, 84.0, 180.0, 132.0, 108.0, 96.0])
def test_the_compensation_closes_the_white_furnace_of_the_lossless_dielectric(
    compensation, theta_i
):
    """Single scattering (Walter et al. 2007 with height-correlated Smith, by quadrature) plus
    the compensation's R and T (f_ms integrated by quadrature over both hemispheres) = 1 at
    the table's nodes, within 4 of the table's standard errors (its Monte Carlo accuracy) and
    the quadrature's 2e-4. The compensation alone restores exactly the table's loss."""
    wi = _direction(theta_i)
    side = "outside" if wi[2] > 0 else "inside"
    single = sum(_albedos(lambda wo: _walter_single(wi, wo), theta_i))
    r_ms, t_ms = _albedos(lambda wo: compensation.bsdf(wi, wo), theta_i)
    mu = abs(wi[2])
    table = compensation.table
    k = np.argmin(np.abs(table.mu - mu))
    assert abs(table.mu[k] - mu) < 1e-12  # a node
    se = (table.stderr_outside if side == "outside" else table.stderr_inside)[k]
    assert abs(table.E(mu, side) + r_ms + t_ms - 1.0) < 2e-4
    assert abs(single + r_ms + t_ms - 1.0) < 4 * se + 2e-4, (single, r_ms, t_ms, se)
    np.testing.assert_allclose((r_ms, t_ms), compensation.albedo(theta_i), atol=2e-4)


def test_the_compensation_is_reciprocal_in_its_own_sense(compensation):
    """Reflection lobes symmetric on either side; transmission lobes in the radiance
    convention, f_t(i, o)/η_o² = f_t(o, i)/η_i² (the constraint that fixes x₋ from x₊);
    and x₊ is the smooth interface's mean Fresnel transmittance from the air."""
    rng = np.random.default_rng(6)
    a = rng.normal(size=(200, 3))
    b = rng.normal(size=(200, 3))
    a /= np.linalg.norm(a, axis=1, keepdims=True)
    b /= np.linalg.norm(b, axis=1, keepdims=True)
    f, g = compensation.bsdf(a, b), compensation.bsdf(b, a)
    assert np.all(f > 0)
    index = lambda w: np.where(w[:, 2] > 0, 1.0, ETA)  # noqa: E731
    np.testing.assert_allclose(f / index(b) ** 2, g / index(a) ** 2, rtol=1e-12)
    same = np.sign(a[:, 2]) == np.sign(b[:, 2])
    assert 0 < np.count_nonzero(same) < len(same)
    x = compensation.transmitted
    assert x["outside"] == pytest.approx(1.0 - an.energy_compensation.fresnel_average(ETA))
    assert 0 < x["inside"] < x["outside"]


def test_the_compensation_refuses_a_split_reciprocity_cannot_keep():
    mu = np.array([0.1, 1.0])
    table = DielectricAlbedoTable(mu, [0.2, 0.3], [0.9, 0.99], [0.0, 0.0], [0.0, 0.0])
    with pytest.raises(UsageError, match="reciprocity"):
        KullaContyDielectric(eta=1.01, table=table, transmitted_fraction=1.0)
    with pytest.raises(UsageError, match="real index"):
        KullaContyDielectric(eta=1.0, table=table)


@pytest.mark.slow  # 20 s: 24 quadratures of the closed form and a 480 000-path walk
def test_the_albedo_table_from_the_closed_form_is_the_walks_first_order():
    """``DielectricAlbedoTable.from_model`` (Walter's BSDF with Heitz's G across, by
    quadrature) and ``from_walk`` (the walk's order 1, Monte Carlo) tabulate the same E± at
    every node, within 4 of the walk's standard errors and the quadrature's 1e-5."""
    exact = DielectricAlbedoTable.from_model(WALTER)
    walk = DielectricAlbedoTable.from_walk(NDF, ETA, n_paths=20_000, seed=11)
    np.testing.assert_array_equal(exact.mu, walk.mu)
    for side in ("outside", "inside"):
        diff = np.abs(exact.E(exact.mu, side) - walk.E(walk.mu, side))
        se = getattr(walk, f"stderr_{side}")
        assert np.all(diff <= 4 * se + 1e-5), (side, diff / np.maximum(se, 1e-12))
