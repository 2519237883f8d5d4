"""The dielectric estimator against an independent refraction tracer (``dielectric_reference``,
pure NumPy, no ``microsim.sim`` code).

Self-checks of the tracer: on a flat tile the reflected fraction is the Fresnel reflectance,
written here in Fresnel's sine and tangent form (Born & Wolf 1999, §1.5.2, eq. 21 —
not the amplitude form the tracer uses), every ray leaves after one interaction in the mirror
or Snell direction, and beyond the critical angle everything is reflected; with no index step
(η = 1) every ray crosses a rough tile unbent, an odd number of times.

The comparison: one Gaussian heightfield (16 × 16 cells, realised rms slope 0.47), η = 1.5,
light from above (θi = 40°) and from below (θi = 150°), on 9 × 6 folded bins. For each side
(reflected, transmitted) and for all orders, order 1 and orders 2+, the bins of the reference
(``REFERENCE_RAYS`` rays, per-ray binomial errors) and of ``microsim.sim.simulate``
(``ESTIMATOR_RAYS`` rays, its standard errors) agree by a χ² over bins, and the totals
within 4 combined standard errors.
"""

from __future__ import annotations

import dielectric_reference as ref
import numpy as np
import pytest
from scipy import stats
from support import sidak

from microsim.bins import Bins
from microsim.surfaces import flat, gaussian

ETA = 1.5
FLAT_RAYS = 20_000
REFERENCE_RAYS = 150_000
"""Reference rays per incidence (≈ 3 s for both): binomial standard errors of the totals
≈ 0.00055 from above (R ≈ 0.048) and ≈ 0.0012 from below (R ≈ 0.35)."""
ESTIMATOR_RAYS = 400_000
BINS = Bins(n_theta=9, n_phi=6, folded=True)
INCIDENCES = {"from above": 40.0, "from below": 150.0}
SIDES = ("reflected", "transmitted")
ORDERS = {"all orders": None, "order 1": (1,), "orders 2+": (2, 3, 4)}
"""Order slots compared (4 stands for ≥ 4): orders 2+ alone, as their light is a few per cent
of the whole, which the whole's errors would hide."""
CASES = [(i, s, o) for i in INCIDENCES for s in SIDES for o in ORDERS]
P_MIN = sidak(1e-3, len(CASES))
"""Smallest χ² p-value accepted: 1e-3 family-wise over the cases."""
MIN_EXPECTED = 10.0
"""Bins expecting fewer reference rays than this are pooled into one cell of the χ²."""


def fresnel_sine_form(theta_deg: float, n1: float, n2: float) -> float:
    """Unpolarised reflectance from n1 into n2 at θ: (sin²(θ−θt)/sin²(θ+θt) +
    tan²(θ−θt)/tan²(θ+θt))/2, ((n1 − n2)/(n1 + n2))² at normal incidence, 1 beyond the
    critical angle."""
    t = np.radians(theta_deg)
    s = n1 / n2 * np.sin(t)
    if s >= 1.0:
        return 1.0
    if t == 0.0:
        return ((n1 - n2) / (n1 + n2)) ** 2
    tt = np.arcsin(s)
    rs = np.sin(t - tt) ** 2 / np.sin(t + tt) ** 2
    rp = np.tan(t - tt) ** 2 / np.tan(t + tt) ** 2
    return 0.5 * (rs + rp)


@pytest.mark.parametrize("theta_i", [0.0, 60.0, 150.0, 130.0])  # 130°: 50° > asin(1/η) ≈ 41.8°
def test_flat_tile_reflects_the_fresnel_fraction(theta_i):
    esc = ref.trace(ref.Mesh.of(flat(1.0)), ETA, theta_i, FLAT_RAYS, np.random.default_rng(1))
    wi = ref.incident_direction(theta_i)
    from_above = wi[2] > 0
    n1, n2 = (1.0, ETA) if from_above else (ETA, 1.0)
    theta_local = theta_i if from_above else 180.0 - theta_i
    r = fresnel_sine_form(theta_local, n1, n2)
    assert esc.cut == 0 and len(esc.wo) == FLAT_RAYS
    assert np.all(esc.order == 1)
    got = esc.reflected.mean()
    if r == 1.0:
        assert got == 1.0, "beyond the critical angle everything is reflected"
    else:
        assert abs(got - r) <= 4.0 * np.sqrt(r * (1 - r) / FLAT_RAYS), (got, r)
    mirror = np.array([-wi[0], -wi[1], wi[2]])
    np.testing.assert_allclose(
        esc.wo[esc.reflected], np.broadcast_to(mirror, (esc.reflected.sum(), 3)), atol=1e-12
    )
    ratio, sin_i = n1 / n2, np.hypot(wi[0], wi[1])
    if ratio * sin_i < 1.0:  # Snell: the tangential part scales by n1/n2, the ray goes on
        snell = np.array([-ratio * wi[0], -ratio * wi[1], -np.sign(wi[2])])
        snell[2] *= np.sqrt(1.0 - (ratio * sin_i) ** 2)
        through = esc.wo[~esc.reflected]
        np.testing.assert_allclose(through, np.broadcast_to(snell, through.shape), atol=1e-12)


@pytest.mark.parametrize("theta_i", [65.0, 145.0])
def test_flat_tile_bins_the_mirror_and_snell_directions(theta_i):
    """Reflected rays fall in the bin of θo = θi, transmitted ones in that of Snell's θt, both
    at Δφ = 180° (the exit direction's own azimuth), and Σ f Ω_B is each side's fraction."""
    esc = ref.trace(ref.Mesh.of(flat(1.0)), ETA, theta_i, 2_000, np.random.default_rng(5))
    theta_local = min(theta_i, 180.0 - theta_i)
    ratio = 1.0 / ETA if theta_i < 90.0 else ETA
    theta_t = np.degrees(np.arcsin(ratio * np.sin(np.radians(theta_local))))
    for reflected, theta_o in ((True, theta_local), (False, theta_t)):
        side = ref.bin_averages(esc, BINS, 0.0, reflected=reflected)
        expected = np.zeros(BINS.shape, dtype=bool)
        expected[int(theta_o // (90.0 / BINS.n_theta)), BINS.forward_index] = True
        assert np.array_equal(side.f > 0, expected), (reflected, theta_o)
        assert np.sum(side.f * BINS.projected_solid_angle()) == pytest.approx(side.total)
        assert side.total == np.mean(esc.reflected == reflected)


@pytest.mark.parametrize("theta_i", [40.0, 85.0, 150.0, 95.0])
def test_without_an_index_step_rays_cross_unbent(theta_i, tile):
    """At 85° and 95° a ray runs ~50 cells sideways across the slab: several tile-long steps."""
    esc = ref.trace(ref.Mesh.of(tile), 1.0, theta_i, 5_000, np.random.default_rng(2))
    assert esc.cut == 0 and not esc.reflected.any()
    wi = ref.incident_direction(theta_i)
    np.testing.assert_allclose(esc.wo, np.broadcast_to(-wi, esc.wo.shape), atol=1e-12)
    assert np.all(esc.order % 2 == 1), "a straight line crosses a closed heightfield oddly often"


@pytest.fixture(scope="module")
def tile():
    """The heightfield of the comparison: 16 × 16 cells, σ = 1.75, ℓ = 7 (m = 0.5 nominal)."""
    return gaussian(16, 1.0, 1.75, 7.0, seed=1)


@pytest.fixture(scope="module")
def reference(tile):
    """The reference tracer's escapes per incidence name."""
    rng = np.random.default_rng(3)
    mesh = ref.Mesh.of(tile)
    return {name: ref.trace(mesh, ETA, t, REFERENCE_RAYS, rng) for name, t in INCIDENCES.items()}


@pytest.fixture(scope="module")
def estimate(tile):
    """``microsim.sim.simulate``'s dielectric result at the incidences."""
    from microsim.sim import simulate

    return simulate(
        tile,
        material=ETA,
        theta_i=list(INCIDENCES.values()),
        transmission=True,
        bounces="all",
        rays=ESTIMATOR_RAYS,
        bins=BINS,
        seed=4,
    )


def estimator_side(result, t: int, side: str, orders):
    """(fractions per bin (Θ, Φ), their standard errors, total fraction, its standard error)
    of the estimator's ``side`` at incidence ``t``, over ``orders`` (None: all) — the bins
    as f Ω_B, the total from the ledger (a fraction of the primary rays, binomial error)."""
    f_orders = result.brdf_orders if side == "reflected" else result.btdf_orders
    se_orders = result.stderr_orders if side == "reflected" else result.stderr_btdf_orders
    slots = slice(None) if orders is None else [k - 1 for k in orders]
    omega = BINS.projected_solid_angle()
    x = f_orders[slots, t].sum(axis=0) * omega
    se = np.sqrt(np.sum(se_orders[slots, t] ** 2, axis=0)) * omega
    prefix = "escaped" if side == "reflected" else "transmitted"
    names = [("1", "2", "3", "4plus")[k - 1] for k in (orders or (1, 2, 3, 4))]
    total = float(sum(result.ledger[f"{prefix}_{k}"][t] for k in names))
    n = float(result.rays[t])
    return x, se, total, np.sqrt(total * (1.0 - total) / n)


def chi2_of_bins(x_ref, n_ref: int, x_est, se_est):
    """(χ², cells) of the reference's bin fractions ``x_ref`` (``n_ref`` rays) against the
    estimator's ``x_est`` ± ``se_est``: each cell's variance is the reference's binomial one
    at the pooled fraction plus the estimator's; bins expecting fewer than ``MIN_EXPECTED``
    reference rays are pooled into one cell."""
    x_ref, x_est, var_est = (np.ravel(a) for a in (x_ref, x_est, se_est**2))
    pooled = 0.5 * (x_ref + x_est)
    small = pooled * n_ref < MIN_EXPECTED
    cells = [(x_ref[~small], x_est[~small], var_est[~small])]
    if small.any():
        cells.append(([x_ref[small].sum()], [x_est[small].sum()], [var_est[small].sum()]))
    xr, xe, ve = (np.concatenate(c) for c in zip(*cells))
    p = 0.5 * (xr + xe)
    var = p * (1.0 - p) / n_ref + ve
    keep = var > 0
    return float(np.sum((xr - xe)[keep] ** 2 / var[keep])), int(keep.sum())


@pytest.mark.parametrize("incidence, side, orders", CASES)
def test_estimator_agrees_with_the_reference_tracer(reference, estimate, incidence, side, orders):
    t = list(INCIDENCES).index(incidence)
    esc = reference[incidence]
    assert esc.cut <= 1e-4 * esc.n, "paths given up by the reference must be rare"
    mine = ref.bin_averages(esc, BINS, 0.0, reflected=side == "reflected", orders=ORDERS[orders])
    omega = BINS.projected_solid_angle()
    x_est, se_est, total_est, total_se = estimator_side(estimate, t, side, ORDERS[orders])

    chi2, cells = chi2_of_bins(mine.f * omega, esc.n, x_est, se_est)
    p = stats.chi2.sf(chi2, cells)
    assert p > P_MIN, (
        f"{incidence} {side} {orders}: χ² = {chi2:.1f} over {cells} cells, p = {p:.2g}"
    )
    combined = np.hypot(mine.total_stderr, total_se)
    assert abs(mine.total - total_est) <= 4.0 * combined, (
        f"{incidence} {side} {orders}: total {total_est:.5f} (estimator) vs {mine.total:.5f} "
        f"(reference), 4 combined standard errors = {4 * combined:.5f}"
    )
