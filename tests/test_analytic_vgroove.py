"""The exact analytic V-groove path (``masking="analytic"``, ``VGrooveCaster``) against the
ray-traced reference (``masking="exact"``: Embree primary hit, same float64 masking test).

Ray by ray on the same ray stream the two paths must agree in ledger class, Fresnel weight and
bin, except where Embree's float32 answer is itself ambiguous: Embree intersects the
float32-rounded ray (origin rounded to ≤ ½ ulp32(L/2) per coordinate) with float32-rounded
vertices (same bound), so its hit can be off by a few ulp32(L/2) in x, amplified by
1 + |a| (a = horizontal advance per unit depth of the ray) along the ray. We allow
δ0 = 16 ulp32(L/2) (≈ 1e-6 on a unit tile) at the rim crossing x0, which decides the groove,
and δ = δ0 (1 + |a|) at the hit, which decides the wall (bottom vertex) and the masking
margin; every disagreement must fall in one of these ambiguity zones, and there must be fewer
than 0.1 % of them.
"""

import numpy as np
import pytest
from scipy import stats

from microsim import analytic as an
from microsim import surfaces as sf
from microsim.analytic.fresnel import fresnel_real_arithmetic, resolve_material
from microsim.sim import (
    BLOCK,
    Bins,
    paths,
    ray_columns,
    ray_events,
    simulate,
    streams,
    tracer_cache,
)
from microsim.sim.vgroove_profile import VGrooveCaster
from microsim.vectors import spherical_deg

AL = resolve_material("aluminium")
BINS = Bins(45, 37)


@pytest.fixture(scope="module")
def grooves():
    return sf.vgrooves(1000, an.Beckmann(0.3))


def _distance_to(points, edges):
    """Distance from each point to the nearest of the sorted ``edges``."""
    k = np.clip(np.searchsorted(edges, points), 1, len(edges) - 1)
    return np.minimum(np.abs(points - edges[k - 1]), np.abs(points - edges[k]))


def _ambiguous(caster, lx, origins, psi, wi):
    """Rays whose traced (float32) outcome may legitimately differ from the exact one."""
    cp, sp = np.cos(psi), np.sin(psi)
    wx, wz = cp * wi[0] + sp * wi[1], np.full(len(psi), wi[2])
    a = np.abs(wx / wz)
    d0 = 16 * float(np.spacing(np.float32(lx / 2)))
    d = d0 * (1 + a)
    x0 = origins[:, 0] - origins[:, 2] / wz * wx
    x0 = np.mod(x0 + lx / 2, lx) - lx / 2
    rims = np.concatenate([caster.x_left, caster.x_right[-1:]])
    near_rim = _distance_to(x0, rims) <= d0
    f, s = caster.groove_hits(origins[:, 0], origins[:, 2], wx, wz)
    x = caster.facet_rim[f] + np.where(f % 2, -s, s)
    bottoms = caster.x_left + caster.w_left
    near_bottom = _distance_to(x, bottoms) <= d
    nx, nz = caster.facet_nx[f], caster.facet_nz[f]
    c = wx * nx + wz * nz
    wo_x, wo_z = 2 * c * nx - wx, 2 * c * nz - wz
    prim = caster.facet_prim[f]
    lo = caster.margin_columns(prim, x - d, wo_x, wo_z)
    hi = caster.margin_columns(prim, x + d, wo_x, wo_z)
    near_mask = (np.sign(lo) != np.sign(hi)) & (wo_z > 0)
    return near_rim | near_bottom | near_mask


@pytest.mark.parametrize("theta", [0.0, 30.0, 60.0, 80.0, 89.0])
def test_analytic_path_matches_the_traced_one_ray_by_ray(grooves, theta):
    exact = tracer_cache.tracer_for(grooves, "exact")
    tracer, caster, _ = tracer_cache.tracer_for(grooves, "analytic")
    wi, n = spherical_deg(theta, 20.0), 64 * BLOCK
    drawn = [streams.block_origins(tracer, n, b, (7, 0, 0), True) for b in range(n // BLOCK)]
    origins, psi = (np.concatenate(x) for x in zip(*drawn))
    ref = ray_columns.trace_columns(exact[0], exact[1], wi, 20.0, BINS, origins, psi, AL)
    got = ray_columns.analytic_columns(
        caster, wi, 20.0, BINS, origins[:, 0], origins[0, 2], psi, AL
    )
    assert np.all(got[0] != paths.RAY_MISSED) and np.any(got[0] == paths.SINGLE)
    differ = (got[0] != ref[0]) | ~np.isclose(got[1], ref[1], rtol=0, atol=1e-9)
    same_bin = got[2] == ref[2]
    assert np.mean(differ | ~same_bin) <= 1e-3
    ambiguous = _ambiguous(caster, tracer.tile[0], origins, psi, wi)
    assert not np.any(differ & ~ambiguous)
    assert np.mean(ambiguous) < 0.02  # the zones are narrow (measured ≤ 0.7 %)
    assert np.mean(~same_bin & ~differ) <= 1e-4  # both bin the same wo: edges to rounding
    # the per-ray diagnostics (ray_events, analytic) take the same decisions
    ev = ray_events(grooves, "aluminium", theta, phi_i=20.0, rays=n, seed=7, masking="analytic")
    assert np.mean(ev.status != got[0]) <= 1e-4
    same = ev.status == got[0]
    assert np.allclose(ev.weight[same], got[1][same], rtol=0, atol=1e-12)


def _two_sample_chi2(a, b, min_count=25):
    """Σ (f_a − f_b)² / (se_a² + se_b²) over bins with ≥ ``min_count`` events in both runs."""
    use = (a.counts[0] >= min_count) & (b.counts[0] >= min_count)
    z2 = (a.brdf[0] - b.brdf[0])[use] ** 2 / (a.stderr[0] ** 2 + b.stderr[0] ** 2)[use]
    return float(z2.sum()), int(use.sum())


THETAS = (30.0, 80.0)


@pytest.mark.parametrize("theta", THETAS)
def test_independent_runs_of_both_paths_agree(grooves, theta):
    """Independent origins (per-ray standard errors, unbiased) from different seeds: the
    two-sample χ² over the populated bins is χ²(dof) under equal expectations; two-sided
    α = 0.01, Šidák-corrected over the incidences."""
    kw = dict(rays=10**6, bins=BINS, origins="independent")
    a = simulate(grooves, "aluminium", theta, seed=11, masking="exact", **kw)
    b = simulate(grooves, "aluminium", theta, seed=12, masking="analytic", **kw)
    chi2, dof = _two_sample_chi2(a, b)
    alpha = 1 - (1 - 0.01) ** (1 / len(THETAS))
    assert dof > 50
    assert stats.chi2.ppf(alpha / 2, dof) < chi2 < stats.chi2.ppf(1 - alpha / 2, dof)
    for key in ("single", "masked", "downward"):  # ledger fractions within 5σ (binomial)
        p = 0.5 * (a.ledger[key][0] + b.ledger[key][0])
        assert (
            abs(a.ledger[key][0] - b.ledger[key][0]) <= 5 * np.sqrt(2 * p * (1 - p) / 1e6) + 1e-12
        )


def test_analytic_results_do_not_depend_on_threads_or_chunks(grooves):
    kw = dict(rays=5 * BLOCK + 123, bins=BINS, masking="analytic", seed=3)
    a = simulate(grooves, "aluminium", [30.0, 70.0], threads=1, chunk=BLOCK, **kw)
    b = simulate(grooves, "aluminium", [30.0, 70.0], threads=2, chunk=2**20, **kw)
    for key in ("sum_w", "sum_w2", "count", "led_n", "led_f", "sum_pair"):
        assert np.array_equal(a.tallies[key], b.tallies[key])
    assert a.meta["masking"] == "analytic"


def test_unfolded_bins_use_the_generic_locator(grooves):
    """Unfolded bins go through ``Bins.locate``; folding them by hand gives the folded run."""
    kw = dict(rays=4 * BLOCK, masking="analytic", seed=5)
    u = simulate(grooves, "aluminium", 40.0, bins=Bins(9, 8, folded=False), **kw)
    f = simulate(grooves, "aluminium", 40.0, bins=Bins(9, 5), **kw)
    cu, cf = u.counts[0], f.counts[0]
    # unfolded edges (k − ½)·45°; folded edges 0, 22.5, 67.5, …, 180: bin j of the folded
    # grid collects unfolded bins j and 8 − j (the same |Δφ| ranges)
    folded = np.stack(
        [cu[:, 0], cu[:, 1] + cu[:, 7], cu[:, 2] + cu[:, 6], cu[:, 3] + cu[:, 5], cu[:, 4]], axis=1
    )
    assert abs(int(folded.sum()) - int(cf.sum())) <= 2
    assert np.abs(folded - cf).sum() <= 4  # Δφ exactly on an edge: rounding


def test_bad_use_raises(grooves):
    hf = sf.gaussian(32, 1.0, 0.05, 8.0, seed=0)
    with pytest.raises(ValueError, match="masking"):
        simulate(hf, "aluminium", 30.0, rays=10, masking="analytic")
    with pytest.raises(ValueError, match="masking"):
        ray_events(hf, "aluminium", 30.0, rays=10, masking="analytic")
    with pytest.raises(ValueError, match="masking"):
        simulate(grooves, "aluminium", 30.0, rays=10, masking="analytical")
    assert "analytic" in paths.MASKING


def test_caster_geometry(grooves):
    """Facet columns reproduce the mesh: rims, normals of the reported triangles, depth."""
    tracer, caster, _ = tracer_cache.tracer_for(grooves, "analytic")
    assert isinstance(caster, VGrooveCaster)
    w = 1.0 / 1000
    assert np.allclose(np.diff(caster.x_left), w, rtol=0, atol=1e-12)
    nrm = tracer.normals[caster.facet_prim]
    assert np.array_equal(nrm[:, 0], caster.facet_nx) and np.all(nrm[0::2, 0] > 0)
    assert np.all(nrm[1::2, 0] < 0)
    assert np.allclose(caster.depth, -tracer.vertices[:, 2].reshape(2, -1)[0, 1::2], atol=1e-15)


@pytest.mark.parametrize("ior", ["aluminium", "methanol", "mirror", 20 + 3j, 0.7 + 0.01j, 0.7])
def test_real_arithmetic_fresnel_equals_fresnel(ior):
    """``fresnel_real_arithmetic`` (position-independent rounding) is ``fresnel`` to rounding,
    grazing (c = 0: R = 1) and normal incidence included."""
    from microsim.analytic.fresnel import fresnel

    eta = resolve_material(ior)
    c = np.concatenate([[0.0, 1e-300, 1e-8, 0.5, 1.0], np.random.default_rng(0).random(100_000)])
    got, ref = fresnel_real_arithmetic(c, eta), fresnel(c, eta)
    assert got[0] == 1.0 and np.all(np.isfinite(got))
    np.testing.assert_allclose(got, ref, rtol=1e-12, atol=1e-14)
