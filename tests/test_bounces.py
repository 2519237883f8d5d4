"""Scattering orders: ``simulate(..., bounces=K)`` (``microsim.sim.bounces``).

What is established here:

* ``bounces=1`` is the default, bitwise (every array of the Result, on every trace path);
* single bounce is the chain's K = 1 case: order 1 of every K > 1 chain, on every trace path,
  is the single-bounce estimate of the same rays (classes and bin counts exactly);
* white furnace: with a mirror (F = 1) and ``bounces="all"`` every path leaves the periodic
  surface — escaped energy 1 to within 1e-6, nothing absorbed, cut, unresolved or missed —
  on V-grooves (Embree and the exact float64 chain) and a Gaussian heightfield, θi 0–89°;
* the V-groove chain against a direct enumeration of the two-plane geometry of one
  symmetric groove by unfolding (the walls' mirror images: a path's bounces are the wall
  images its straight unfolded line crosses): per ray exactly (order and direction, float64)
  for the analytic chain, and in the order energies for Embree and azimuth-averaged runs;
* order 2 of an isotropic Gaussian ensemble is reciprocal (slow);
* threads/chunks do not change a bit; save/load and interrupt/resume round-trip the orders;
* bounce limits: K = 2 ends exactly the paths K = "all" continues, and the ledger balances.
"""

from __future__ import annotations

import dataclasses
import functools

import numpy as np
import pytest
from scipy import stats
from support import heightfield_surface, random_heights, vgroove_surface

from microsim.checkpoints import interrupt_at
from microsim.errors import UsageError
from microsim.sim import BLOCK, Bins, Result, fresnel_kernels, simulate, vgroove_kernels
from microsim.sim.bounces import MAX_BOUNCES, TERMINAL
from microsim.sim.tracer import Tracer
from microsim.sim.vgroove_profile import VGrooveCaster
from microsim.surfaces import gaussian

BINS = Bins(9, 7)


def gauss(seed=1, n=64):
    """m = 2σ/ℓ = 0.5 Gaussian heightfield, ℓ = 8 dx (the issue's surface, smaller tile)."""
    return gaussian(n, 1.0, 2.0, 8.0, seed=seed)


def arrays(res: Result) -> dict:
    out = dict(res._arrays())
    out.update({f"tally_{k}": v for k, v in (res.tallies or {}).items()})
    return out


def assert_bitwise(a: Result, b: Result):
    x, y = arrays(a), arrays(b)
    assert sorted(x) == sorted(y)
    for k in x:
        assert x[k].dtype == y[k].dtype, k
        assert np.array_equal(x[k], y[k], equal_nan=True), k


# --- bounces=1 is the default, bitwise ------------------------------------------------------
@pytest.mark.parametrize(
    "case", ["facet-table", "isotropic", "realisations", "vg-traced", "vg-exact", "vg-analytic"]
)
def test_bounces_one_is_the_default_bitwise(case):
    s = heightfield_surface(random_heights(32, sigma=0.03, seed=2), 1 / 32)
    v = vgroove_surface([20, 35, 50, 65])
    kw = dict(rays=3 * BLOCK + 77, bins=BINS, seed=3, threads=2)
    args = {
        "facet-table": (s, {}),
        "isotropic": (s, {"isotropic": True}),
        "realisations": (None, {"realisations": [s, dataclasses.replace(s)]}),
        "vg-traced": (v, {}),
        "vg-exact": (v, {"masking": "exact"}),
        "vg-analytic": (v, {"masking": "analytic"}),
    }[case]
    a = simulate(args[0], "aluminium", [0, 50, 85], **kw, **args[1])
    b = simulate(args[0], "aluminium", [0, 50, 85], **kw, **args[1], bounces=1)
    assert_bitwise(a, b)
    assert "bounces" not in b.meta and b.brdf_orders is None and b.stderr_orders is None
    assert len(b.tallies["led_n"][0, 0]) == 5  # the single-bounce ledger only


@pytest.mark.parametrize("bounces", [2, "all"])
@pytest.mark.parametrize(
    "case", ["traced", "facet-table", "isotropic", "independent", "vg-traced", "vg-analytic"]
)
def test_order_one_of_every_chain_is_the_single_bounce_estimate(case, bounces):
    """The same rays (streams), the same first bounce: identical first-bounce classes and bin
    counts; BRDF to rounding (the facet table and the chain evaluate the same Fresnel factor
    in different compiled loops)."""
    s = heightfield_surface(random_heights(32, sigma=0.03, seed=2), 1 / 32)
    v = vgroove_surface([20, 35, 50, 65])
    rays = 3 * BLOCK + 77
    surface, extra = {
        "traced": (s, {"rays": 200}),  # fewer rays than facets: no facet table
        "facet-table": (s, {}),
        "isotropic": (s, {"isotropic": True}),
        "independent": (s, {"origins": "independent"}),
        "vg-traced": (v, {}),
        "vg-analytic": (v, {"masking": "analytic"}),
    }[case]
    kw = {"rays": rays, "bins": BINS, "seed": 4, "threads": 2, **extra}
    one = simulate(surface, "aluminium", [0, 50, 85], **kw)
    chain = simulate(surface, "aluminium", [0, 50, 85], bounces=bounces, **kw)
    for name in one.ledger_counts:
        np.testing.assert_array_equal(chain.ledger_counts[name], one.ledger_counts[name])
    np.testing.assert_array_equal(chain.counts, one.counts)
    np.testing.assert_allclose(chain.brdf_orders[0], one.brdf, rtol=1e-12, atol=0)
    np.testing.assert_allclose(chain.stderr, one.stderr, rtol=1e-9, atol=0)


@pytest.mark.parametrize(
    "bad", [0, -1, MAX_BOUNCES + 1, 2.5, True, "All", "2", None, np.float64(2)]
)
def test_bad_bounces_are_refused(bad):
    with pytest.raises(UsageError, match="bounces"):
        simulate(vgroove_surface([30]), None, 10, rays=100, bounces=bad)


def test_exact_masking_has_no_bounce_chain():
    with pytest.raises(UsageError, match="masking='exact'.*analytic"):
        simulate(vgroove_surface([30]), None, 10, rays=100, masking="exact", bounces=2)


# --- white furnace ---------------------------------------------------------------------------
def furnace(surface, theta, masking, rays, ties=0.0):
    """White furnace (F = 1, all bounces). ``ties``: the fraction of primary rays allowed to
    end 'unresolved' on Embree's edge ties at the groove rims (traced V-grooves near grazing,
    ``test_white_furnace_traced_grooves_lose_only_the_primary_edge_ties``)."""
    res = simulate(
        surface, None, theta, rays=rays, bins=BINS, bounces="all", masking=masking, threads=2
    )
    led = res.ledger
    # every path leaves: escaped energy 1 to within 1e-6 (less the primary edge ties),
    # nothing else takes energy
    lost = led["unresolved_path_energy"]
    assert np.all(lost <= max(ties, 1e-6)), lost
    assert np.all(np.abs(led["escaped_energy"] + lost - 1.0) <= 1e-6), led["escaped_energy"]
    for name in ("cut_bounces", "cut_weight", "missed_path"):
        assert np.all(led[f"{name}_energy"] <= 1e-6), (name, led[f"{name}_energy"])
    assert np.all(led["absorbed_energy"] == 0.0)  # F = 1: no Fresnel loss
    # the order-resolved BRDF holds exactly what the ledger says escaped at each order
    omega = res.bins.projected_solid_angle()
    per_order = (res.brdf_orders * omega).sum(axis=(2, 3))
    for o, name in enumerate(TERMINAL[:4]):
        np.testing.assert_allclose(per_order[o], led[f"{name}_energy"], rtol=1e-12, atol=1e-15)
    # and order 1 is the single-bounce ledger's escaping part
    np.testing.assert_array_equal(res.ledger_counts["escaped_1"], res.ledger_counts["single"])
    return res


FURNACE_SURFACES = {
    "gaussian": (lambda: gauss(), "traced"),
    "vgrooves-traced": (lambda: vgroove_surface(np.linspace(5, 75, 40)), "traced"),
    "vgrooves-analytic": (lambda: vgroove_surface(np.linspace(5, 75, 40)), "analytic"),
}


@pytest.mark.parametrize("name", sorted(FURNACE_SURFACES))
def test_white_furnace(name):
    make, masking = FURNACE_SURFACES[name]
    res = furnace(make(), [0.0, 45.0, 80.0, 89.0], masking, 20_000)
    assert np.all(res.ledger["escaped_2_energy"] > 0)  # the chain did go beyond order 1


@pytest.mark.slow
@pytest.mark.parametrize("name", sorted(FURNACE_SURFACES))
def test_white_furnace_every_angle(name):
    make, masking = FURNACE_SURFACES[name]
    theta = [0, 10, 20, 30, 40, 50, 60, 65, 70, 75, 80, 83, 85, 86, 87, 88, 88.5]
    # traced grooves: Embree's rim ties (~1e-5 of the rays at 89°, 1 of 2·10⁵ at 88.5°)
    furnace(make(), theta, masking, 200_000, ties=1e-4 if name == "vgrooves-traced" else 0.0)


@pytest.mark.slow
def test_white_furnace_traced_grooves_lose_only_the_primary_edge_ties():
    """At θi = 89° Embree's float32 primary hit of a ray skimming the groove rims (z = 0)
    sometimes lands on the back of the neighbouring wall (an edge tie at the rim; measured
    2 of 2·10⁵ rays here): the single-bounce path counts those rays 'unresolved' too. The
    bounce chain loses nothing else: escaped + those rays = 1 to within 1e-6, and they are
    exactly the rays bounces=1 leaves unresolved (the same rays)."""
    surf, theta = vgroove_surface(np.linspace(5, 75, 40)), [88.5, 89.0, 89.0]
    kw = dict(rays=200_000, bins=BINS, threads=2)
    res = simulate(surf, None, theta, bounces="all", **kw)
    one = simulate(surf, None, theta, **kw)
    led = res.ledger
    np.testing.assert_array_equal(
        res.ledger_counts["unresolved_path"], one.ledger_counts["unresolved"]
    )
    np.testing.assert_array_equal(res.ledger_counts["unresolved"], one.ledger_counts["unresolved"])
    assert np.all(np.abs(led["escaped_energy"] + led["unresolved_path_energy"] - 1) <= 1e-6)
    assert np.all(led["unresolved_path_energy"] <= 1e-4)


# --- V-grooves against the unfolded two-plane geometry ---------------------------------------
def unfolded_orders(tilt_deg: float, theta_deg: float, width=1.0):
    """Direct enumeration for one symmetric groove (rims (0, 0) and (W, 0), walls tilted
    ``tilt_deg`` from horizontal) lit in its cross-section plane by rays falling along
    −(sin θ, cos θ) (θ signed, towards +x positive), entering uniformly over (0, W).

    Unfolding: the walls lie on rays from the apex A at ±β from the vertical, β = 90° − tilt;
    reflecting the groove across its walls again and again gives wedges j of angle 2β whose
    mirror images of the rims lie at A + L(sin, cos)((2j + 1)β), L the wall length. A path
    is a straight line in this picture; it bounces once per wall image it crosses within L
    of A and leaves through the first rim chord it meets, j. Wedge j maps back to the
    groove by the rotation φ → φ − 2jβ (j even) or the reflection φ → 2jβ − φ (j odd), which
    gives the outgoing direction. Returns [(u0, u1, bounces |j|, θo signed)] over the
    entry positions, cut where the line passes through a rim image or the apex."""
    beta = np.radians(90.0 - tilt_deg)
    depth = width / 2 * np.tan(np.radians(tilt_deg))
    wall = np.hypot(width / 2, depth)
    apex = np.array([width / 2, -depth])
    th = np.radians(theta_deg)
    d = np.array([-np.sin(th), -np.cos(th)])
    jmax = int(np.ceil(np.pi / (2 * beta))) + 2
    cuts = [0.0, width, apex[0] - apex[1] / d[1] * d[0]]
    for j in range(-jmax, jmax + 1):
        v = apex + wall * np.array([np.sin((2 * j + 1) * beta), np.cos((2 * j + 1) * beta)])
        cuts.append(v[0] - v[1] / d[1] * d[0])
    cuts = np.sort([c for c in cuts if 0.0 <= c <= width])
    cuts = cuts[np.r_[True, np.diff(cuts) > 1e-12 * width]]
    out = []
    for a, b in zip(cuts[:-1], cuts[1:]):
        r0 = np.array([0.5 * (a + b), 0.0]) - apex
        turn = 1 if r0[1] * d[0] - r0[0] * d[1] > 0 else -1  # sense of the polar angle
        j = 0
        for _ in range(4 * jmax):
            ang = (2 * j + turn) * beta  # the next wall image
            e = np.array([np.sin(ang), np.cos(ang)])
            t, r = np.linalg.solve(np.array([d, -e]).T, -r0)
            if not (t > 0 and 0 <= r <= wall):
                break
            j += turn
        phi_d = np.arctan2(d[0], d[1])
        phi = phi_d - 2 * j * beta if j % 2 == 0 else 2 * j * beta - phi_d
        out.append((a, b, abs(j), np.degrees((phi + np.pi) % (2 * np.pi) - np.pi)))
    return out


def order_fractions(intervals, orders=4, width=1.0):
    """Fractions of entry positions leaving after 1, 2, 3, ≥ 4 bounces."""
    f = np.zeros(orders)
    for a, b, k, _ in intervals:
        f[min(k, orders) - 1] += (b - a) / width
    return f


GROOVES = [(60.0, 20.0), (70.0, 35.0), (45.0, 30.0), (75.0, 0.0), (80.0, 50.0)]


@pytest.mark.parametrize("tilt,theta", GROOVES)
def test_analytic_chain_is_the_unfolded_geometry_ray_by_ray(tilt, theta):
    """The exact float64 chain (``vgroove_kernels.analytic_vgroove_bounces``) on one groove in its
    cross-section plane (ψ = 0) gives every ray the order and outgoing direction of the
    unfolding, to float64 rounding."""
    caster = VGrooveCaster(Tracer(vgroove_surface([tilt])))
    n = 20_000
    rng = np.random.default_rng(7)
    x = rng.uniform(-0.5, 0.5, n)
    th = np.radians(theta)
    wi = np.array([np.sin(th), 0.0, np.cos(th)])
    status1, weight1, wterm = np.empty(n, np.int8), np.empty(n), np.empty(n)
    term, order = np.empty(n, np.int8), np.empty(n, np.int64)
    wo = [np.empty(n) for _ in range(3)]
    mirror = fresnel_kernels.FresnelMaterial(0.0, 0.0, fresnel_kernels.FRESNEL_MIRROR)
    vgroove_kernels.analytic_vgroove_bounces(
        x, 0.0, np.zeros(n), wi, caster.profile, mirror,
        MAX_BOUNCES, 0.0,
        vgroove_kernels.GrooveChainLedger(status1, weight1, term, wterm, order, *wo),
    )  # fmt: skip
    iv = unfolded_orders(tilt, theta)
    u = x + 0.5
    k = np.searchsorted([b for _, b, _, _ in iv], u)
    cuts = np.array([a for a, _, _, _ in iv] + [1.0])
    clear = np.min(np.abs(u[:, None] - cuts[None, :]), axis=1) > 1e-9  # not on a cut
    assert clear.sum() > 0.999 * n
    want_order = np.array([iv[i][2] for i in k])
    want_theta = np.radians([iv[i][3] for i in k])
    assert np.array_equal(order[clear], want_order[clear])
    assert np.all(term[clear] == np.minimum(want_order[clear], 4) - 1)  # all escape
    np.testing.assert_allclose(wo[0][clear], np.sin(want_theta[clear]), atol=1e-12)
    np.testing.assert_allclose(wo[2][clear], np.cos(want_theta[clear]), atol=1e-12)
    np.testing.assert_array_equal(wterm, 1.0)


@pytest.mark.parametrize("tilt,theta", GROOVES[:3])
def test_embree_chain_orders_match_the_unfolded_geometry(tilt, theta):
    """Embree's chain on one groove without azimuth averaging, lit in its cross-section
    plane: the energy leaving at each order is the unfolding's fraction of entry positions
    (within 4 binomial standard errors, conservative for stratified origins), and order 2
    leaves in the direction the unfolding gives (its bin holds all order-2 energy)."""
    surf = dataclasses.replace(vgroove_surface([tilt]), azimuth_average=False)
    n = 40_000
    bins = Bins(37, 2)  # 2.43° in θo (no edge on a whole degree); Δφ 0° or 180° halves
    res = simulate(surf, None, theta, rays=n, bins=bins, bounces="all", threads=2)
    iv = unfolded_orders(tilt, theta)
    want = order_fractions(iv)
    got = np.array([res.ledger[f"{t}_energy"][0] for t in TERMINAL[:4]])
    se = np.sqrt(want * (1 - want) / n) + 1 / n
    assert np.all(np.abs(got - want) <= 4 * se), (got, want)
    two = [(b - a, th_o) for a, b, k, th_o in iv if k == 2]
    if two:
        omega = bins.projected_solid_angle()
        e2 = res.brdf_orders[1, 0] * omega
        expected = np.zeros(e2.size)  # the unfolding's order-2 share per bin
        for share, th_o in two:
            w = np.array([np.sin(np.radians(th_o)), 0.0, np.cos(np.radians(th_o))])
            expected[bins.locate(w[None], 0.0)[0]] += share
        sd = np.sqrt(expected * (1 - expected) / n) + 1 / n
        assert np.all(np.abs(e2.ravel() - expected) <= 4 * sd)
        assert abs(e2.sum() - sum(s for s, _ in two)) <= 4 * se[1]


@functools.lru_cache
def azimuth_averaged_fractions(tilt, theta, n_psi=1000):
    """Order fractions averaged over a uniform groove azimuth ψ (midpoint rule): the path
    in the groove's cross-section depends on ψ only through the projected incidence
    tan θ' = cos ψ tan θ (the y component of every direction is a passive constant)."""
    psi = (np.arange(n_psi) + 0.5) * (2 * np.pi / n_psi)
    th = np.degrees(np.arctan(np.cos(psi) * np.tan(np.radians(theta))))
    return np.mean([order_fractions(unfolded_orders(tilt, t)) for t in th], axis=0)


@pytest.mark.parametrize("masking", ["analytic", "traced"])
def test_azimuth_averaged_groove_orders_match_the_unfolded_geometry(masking):
    tilt, theta, n = 65.0, 40.0, 40_000
    want = azimuth_averaged_fractions(tilt, theta)
    res = simulate(
        vgroove_surface([tilt] * 3), None, theta, rays=n, bins=BINS, bounces="all",
        masking=masking, threads=2,
    )  # fmt: skip
    got = np.array([res.ledger[f"{t}_energy"][0] for t in TERMINAL[:4]])
    se = np.sqrt(want * (1 - want) / n) + 1 / n
    assert np.all(np.abs(got - want) <= 4 * se), (got, want)
    assert want[1] > 0.1 and want[2] > 0.01  # a real test of orders 2 and 3


def test_analytic_and_traced_vgroove_chains_agree():
    """Same rays, two implementations: per-order energies (metal: with Fresnel weights) and
    the first-bounce ledger agree within the binomial error of a few edge-tie rays."""
    v = vgroove_surface(np.linspace(10, 75, 30))
    kw = dict(rays=30_000, bins=BINS, bounces="all", threads=2)
    a = simulate(v, "aluminium", [0, 40, 80], masking="analytic", **kw)
    t = simulate(v, "aluminium", [0, 40, 80], masking="traced", **kw)
    for name in [f"{x}_energy" for x in TERMINAL[:4]] + ["absorbed_energy"]:
        se = np.sqrt(np.maximum(a.ledger[name], 1 / 30_000) / 30_000)
        assert np.all(np.abs(a.ledger[name] - t.ledger[name]) <= 4 * se), name
    assert np.all(a.ledger["absorbed_energy"] > 0.01)  # aluminium absorbs


# --- structure of the chain ------------------------------------------------------------------
def test_bounce_limit_cuts_what_all_continues():
    """K = 2 follows the same paths as K = "all" up to the second bounce: the same paths
    escape at orders 1 and 2, and the ones K = 2 cuts are those "all" continues."""
    s = gauss(seed=2, n=48)
    kw = dict(rays=20_000, bins=BINS, threads=2)
    k2 = simulate(s, None, [0, 60, 85], bounces=2, **kw)
    ka = simulate(s, None, [0, 60, 85], bounces="all", **kw)
    c2, ca = k2.ledger_counts, ka.ledger_counts
    for name in ("escaped_1", "escaped_2", "single", "masked", "downward"):
        np.testing.assert_array_equal(c2[name], ca[name], err_msg=name)
    later = sum(ca[n] for n in TERMINAL[2:])
    np.testing.assert_array_equal(c2["cut_bounces"], later)
    assert np.all(c2["cut_bounces"] > 0)
    assert k2.brdf_orders.shape == (2, 3) + BINS.shape
    assert ka.brdf_orders.shape == (4, 3) + BINS.shape
    np.testing.assert_array_equal(k2.brdf_orders, ka.brdf_orders[:2])
    np.testing.assert_array_equal(k2.brdf, ka.brdf)


def test_metal_ledger_balances_and_order_one_is_the_single_bounce_brdf():
    s = gauss(seed=3, n=48)
    kw = dict(rays=20_000, bins=BINS, threads=2)
    one = simulate(s, "aluminium", [0, 60, 85], **kw)
    res = simulate(s, "aluminium", [0, 60, 85], bounces=3, **kw)
    led = res.ledger
    total = sum(led[f"{t}_energy"] for t in TERMINAL) + led["absorbed_energy"]
    np.testing.assert_allclose(total, 1.0, rtol=0, atol=1e-12)
    assert np.all(led["absorbed_energy"] > 0.03)  # aluminium: F ≈ 0.9
    # order 1 = the single-bounce estimate of the same rays: identical classification
    # (the chain's reflected ray is the masking ray) and Fresnel weights to rounding
    for name in ("single", "masked", "downward", "unresolved", "missed"):
        np.testing.assert_array_equal(res.ledger_counts[name], one.ledger_counts[name])
    np.testing.assert_array_equal(res.counts, one.counts)
    np.testing.assert_allclose(res.brdf, one.brdf, rtol=1e-12)
    np.testing.assert_allclose(res.brdf_total(), res.brdf_orders.sum(0))


def test_order_standard_errors_cover_the_seed_to_seed_scatter():
    """Two independent ray streams on one tile: per (order ≥ 2, incidence, bin) the
    difference of the estimates over their combined standard error has mean square ≤ 1 +
    3·√(2/k) for k bins (the paired-strata error is unbiased, so 1 in expectation;
    χ²₁ terms have variance 2): the order-resolved errors are not too small."""
    s = gauss(seed=6, n=48)
    kw = dict(rays=40_000, bins=BINS, bounces="all", threads=2)
    a = simulate(s, None, [30, 60, 80], seed=1, **kw)
    b = simulate(s, None, [30, 60, 80], seed=2, **kw)
    fa, fb = a.brdf_orders[1:], b.brdf_orders[1:]
    sa, sb = a.stderr_orders[1:], b.stderr_orders[1:]
    use = (sa > 0) & (sb > 0)
    z2 = ((fa - fb)[use] / np.hypot(sa, sb)[use]) ** 2
    assert use.sum() > 100
    assert z2.mean() <= 1 + 3 * np.sqrt(2 / use.sum()), z2.mean()


# --- determinism, persistence, resume -------------------------------------------------------
def test_bitwise_identical_for_threads_and_chunks():
    s, v = gauss(seed=4, n=48), vgroove_surface(np.linspace(10, 70, 20))
    for surf, extra in ((s, {}), (s, {"isotropic": True}), (v, {})):
        kw = dict(rays=5 * BLOCK + 99, bins=BINS, bounces="all", seed=5, **extra)
        ref = simulate(surf, "aluminium", [0, 70, 88], threads=1, chunk=BLOCK, **kw)
        for threads, chunk in ((2, BLOCK), (2, 2**16), (1, 2**16)):
            assert_bitwise(ref, simulate(surf, "aluminium", [0, 70, 88], threads=threads,
                                         chunk=chunk, **kw))  # fmt: skip


def test_save_load_and_resume_round_trip(tmp_path):
    s = gauss(seed=5, n=32)
    kw = dict(rays=7 * BLOCK + 321, bins=BINS, seed=4, bounces="all", chunk=BLOCK, threads=2)
    full = simulate(s, "aluminium", [20, 70], **kw)
    with interrupt_at("simulation", after=3):
        part = simulate(s, "aluminium", [20, 70], **kw)
    assert part.is_partial
    part.save(tmp_path / "part")
    done = simulate(s, "aluminium", [20, 70], resume=Result.load(tmp_path / "part"), **kw)
    for k in ("brdf", "stderr", "brdf_orders", "stderr_orders", "counts", "rays"):
        assert np.array_equal(getattr(full, k), getattr(done, k)), k
    for k in full.tallies:
        assert np.array_equal(full.tallies[k], done.tallies[k]), k
    for k in full.ledger:
        assert np.array_equal(full.ledger[k], done.ledger[k]), k
    full.save(tmp_path / "full")
    back = Result.load(tmp_path / "full")
    assert_bitwise(full, back)
    assert back.meta["bounces"] == "all"
    with pytest.raises(UsageError, match="bounces"):
        simulate(s, "aluminium", [20, 70], **{**kw, "bounces": 2}, resume=part)


def test_realisations_give_order_resolved_scatter():
    s = [gauss(seed=k, n=32) for k in range(3)]
    res = simulate(None, None, [30, 70], realisations=s, rays=12_000, bins=BINS,
                   bounces="all", threads=2)  # fmt: skip
    assert res.brdf_realisations_orders.shape == (4, 3, 2) + BINS.shape
    np.testing.assert_array_equal(res.brdf_realisations_orders[0], res.brdf_realisations)
    assert np.all(res.stderr_orders[1] >= 0)


# --- reciprocity of order 2 for an isotropic Gaussian ensemble -------------------------------
@pytest.mark.slow
def test_order_two_is_reciprocal_for_the_ensemble():
    """f₂(θa → θb, Δφ) = f₂(θb → θa, Δφ) for the ensemble of m = 0.5 Gaussian tiles
    (32 realisations, incidence azimuth rotated per block): in the 5°-wide θ bins centred on
    θa = 32.5° and θb = 57.5°, every 30° Δφ bin that holds order-2 light both ways (together
    ≥ 95 % of it: the light is on the specular side) passes a χ² test at the 0.1 % level,
    with the realisation scatter in the standard error (a single tile is not reciprocal bin
    by bin). Bin averaging over θo (5°) biases each side by O(Δθ² f″) only. Resolution: the
    combined standard error is 6–10 % of f₂ in the three forward bins that hold most of it."""
    bins = Bins(18, 7)
    res = simulate(
        None, None, [32.5, 57.5], surface_factory=lambda seed: gauss(seed, 64),
        realisations=32, seed=11, rays=4_000_000, bins=bins, bounces="all", isotropic=True,
    )  # fmt: skip
    f, se = res.brdf_orders[1], res.stderr_orders[1]
    ia, ib = 6, 11  # θ bins centred on 32.5° and 57.5°
    ab, ba = f[0, ib], f[1, ia]
    sab, sba = se[0, ib], se[1, ia]
    use = (ab > 0) & (ba > 0) & (sab > 0) & (sba > 0)
    assert ab[use].sum() >= 0.95 * ab.sum() and ba[use].sum() >= 0.95 * ba.sum()
    z = (ab - ba)[use] / np.hypot(sab, sba)[use]
    assert np.sum(z**2) < stats.chi2.ppf(0.999, len(z)), z
