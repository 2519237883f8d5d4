"""The full-wave rung on 1D gratings (``microsim.wave.gratings``, ``microsim.wave.fullwave``).

Facts checked:
* the Kirchhoff order integrals in closed form (Bessel for the sinusoid, linear pieces for the
  triangle) equal a brute-force quadrature of their definition, and the efficiencies equal
  microsim's tile solver (``wave.kirchhoff``) on the profile extruded along y to 1e-9;
* RCW (NIST SCATMECH, the ``fullwave`` extra; skipped with the reason without it):
  - a lossless dielectric grating conserves energy, R + T = 1 for s and p separately, once
    converged (order and levels raised until no efficiency moves by 10⁻³; the study is kept);
  - small sinusoids reproduce first-order perturbation theory (Rayleigh–Rice): at a = λ/50
    the orders ±1 fall below it by the next order's x²/4 (x = q_z a/2), in s and p on glass
    and in s on aluminium (aluminium's p does not converge well enough to resolve it);
  - long periods approach geometric optics: on a symmetric triangular glass grating (facets
    at α = 10°, normal incidence, no masking) the orders around a facet's mirror direction
    2α carry F(α)/2 in the ray limit — which the ray trace of the extruded profile
    (``surfaces.triangular_grating``) gives within its standard error; the shortfall falls
    with the period (edge diffraction, ∝ λ/Λ to leading order): at Λ = 8 λ it is below 60 %
    of the shortfall at 4 λ and below 20 %; and scalar Kirchhoff follows RCW there within
    3 % on that group and 2 % in total;
  - periodic random profiles (``wave.random_profiles``, SCATMECH's ``Generic_Grating``):
    a glass profile converges and conserves energy; RCW's orders follow Kirchhoff's order by
    order, sign included, on a non-symmetric profile (the x mirroring of the description);
    small amplitudes approach first-order perturbation theory at the rate its next order sets.
* the random profiles realise their spectrum exactly (exact-amplitude synthesis) and each
  spectrum integrates to σ².
"""

from __future__ import annotations

import numpy as np
import pytest

from microsim.analytic.fresnel import fresnel
from microsim.wave import fullwave
from microsim.wave.gratings import (
    Grating,
    SampledGrating,
    _phase_integral,
    fourier_coefficients,
    kirchhoff_efficiencies,
    order_directions,
    rayleigh_rice_efficiencies,
)
from microsim.wave.random_profiles import RandomProfile, random_grating

LAMBDA = 0.5  # µm
needs_rcw = pytest.mark.skipif(fullwave.available() is not None, reason=str(fullwave.available()))


@pytest.mark.parametrize("profile", ["sinusoidal", "triangular"])
def test_kirchhoff_order_integrals_equal_a_quadrature(profile):
    g = Grating(profile, 2.0, 0.4)
    x = np.linspace(0.0, g.period, 200_001)
    h = (
        0.5 * g.amplitude * np.cos(2 * np.pi * x / g.period)
        if profile == "sinusoidal"
        else np.where(x < g.period / 2, 2 * g.amplitude * x / g.period,
                      g.amplitude - 2 * g.amplitude * (x - g.period / 2) / g.period)
    )  # fmt: skip
    for m, qz in [(0, 3.0), (1, 7.5), (-3, 12.0), (5, 20.0)]:
        qx = 2 * np.pi * m / g.period
        brute = np.trapezoid(np.exp(1j * (qx * x + qz * h)), x) / g.period
        closed = _phase_integral(g, np.array([qx]), np.array([qz]))[0]
        assert abs(abs(closed) - abs(brute)) < 1e-8, (m, closed, brute)


def test_order_directions_follow_the_grating_equation():
    g = Grating("sinusoidal", 2.0, 0.01)
    m, wo = order_directions(g, LAMBDA, 30.0)
    assert np.allclose(wo[:, 0], -0.5 + m * LAMBDA / 2.0) and np.all(np.abs(wo[:, 0]) < 1)
    assert np.allclose(np.linalg.norm(wo, axis=1), 1.0) and 0 in m


@needs_rcw
@pytest.mark.parametrize("profile", ["sinusoidal", "triangular"])
def test_a_lossless_grating_conserves_energy_once_converged(profile):
    g = Grating(profile, 2.0, 0.3, 1.5)
    r = fullwave.converged_efficiencies(g, LAMBDA, 30.0)
    assert r.info["converged"] and len(r.info["study"]) >= 3
    t = fullwave.rcw_efficiencies(
        g, LAMBDA, 30.0, r.info["order"], r.info["levels"], "transmission"
    )
    for pol in ("s", "p"):
        assert abs(getattr(r, pol).sum() + getattr(t, pol).sum() - 1.0) < 1e-5, pol


@needs_rcw
@pytest.mark.parametrize(
    "material, pols", [(1.5, ("s", "p")), ("aluminium", ("s",))], ids=["glass", "aluminium"]
)
def test_small_sinusoids_are_first_order_perturbation_theory(material, pols):
    """Orders ±1 of h = (a/2) cos(2πx/Λ), a = λ/50, against Rayleigh–Rice. The leading
    correction to first order is that of the Bessel amplitude J₁(x) ≈ (x/2)(1 − x²/8),
    x = q_z a/2, q_z = k(cos θi + cos θ±1): the power falls by x²/4 relative. RCW must show
    that deviation within 25 % of it, plus its own truncation error (the change from 60 to
    120 levels, the staircase's first-order error). Aluminium in p (TM) is left out: there
    RCW's order convergence is slow and erratic (at 53 orders × 68 levels a first order still
    moves by 0.5 %: docs/wave.md)."""
    k, a = 2 * np.pi / LAMBDA, LAMBDA / 50
    g = Grating("sinusoidal", 2.0, a, material)
    fine = fullwave.rcw_efficiencies(g, LAMBDA, 30.0, order=15, levels=120)
    coarse = fullwave.rcw_efficiencies(g, LAMBDA, 30.0, order=15, levels=60)
    rr = rayleigh_rice_efficiencies(g, LAMBDA, 30.0)
    wi_z = np.cos(np.radians(30.0))
    for m in (-1, 1):
        i, j = (np.flatnonzero(e.orders == m)[0] for e in (fine, rr))
        x = k * (wi_z + rr.wo[j, 2]) * a / 2
        for pol in pols:
            got, first = getattr(fine, pol)[i], getattr(rr, pol)[j]
            truncation = abs(got - getattr(coarse, pol)[i]) / first
            deviation = got / first - 1
            assert abs(deviation + x * x / 4) < 0.25 * x * x / 4 + truncation, (m, pol, deviation)


@needs_rcw
def test_long_periods_approach_geometric_optics_and_kirchhoff_follows():
    alpha = np.radians(10.0)
    geometric = 0.5 * fresnel(np.array([np.cos(alpha)]), 1.5)[0]  # one facet's share, G = 1
    # the ray trace of the extruded profile: the same share, within its standard error
    from microsim.sim import Bins, simulate
    from microsim.surfaces import triangular_grating

    bins = Bins(90, 2)
    traced = simulate(triangular_grating(128, 4.0 / 64, 4.0 * np.tan(alpha) / 2, 4.0, ny=8),
                      1.5, 0.0, rays=2**18, bins=bins)  # fmt: skip
    omega = bins.projected_solid_angle()
    centres = 0.5 * (bins.theta_edges[1:] + bins.theta_edges[:-1])
    window = np.abs(centres - 20.0) < 10.0
    side = (traced.brdf[0] * omega)[window, 0].sum()
    side_se = np.sqrt(((traced.stderr[0] * omega)[window, 0] ** 2).sum())
    assert abs(side - geometric) < 4 * side_se + 1e-6, (side, geometric, side_se)
    shortfall = {}
    for period in (2.0, 4.0):
        g = Grating("triangular", period, period * np.tan(alpha) / 2, 1.5)
        r = fullwave.converged_efficiencies(
            g, LAMBDA, 0.0, start=(int(2 * period / LAMBDA) + 5, 20)
        )
        kir = kirchhoff_efficiencies(g, LAMBDA, 0.0)
        group = [np.abs(np.degrees(np.arcsin(e.wo[:, 0])) - 20.0) < 10.0 for e in (r, kir)]
        rcw_group, kir_group = r.unpolarised[group[0]].sum(), kir.unpolarised[group[1]].sum()
        shortfall[period] = 1 - rcw_group / geometric
        assert r.info["converged"]
        assert abs(kir_group / rcw_group - 1) < 0.03 and abs(kir.total() / r.total() - 1) < 0.02
    assert 0 < shortfall[4.0] < min(0.6 * shortfall[2.0], 0.2), shortfall


def test_the_index_section_states_the_crossovers():
    """``fullwave_section`` on a hand-made map: the first slope (and a/λ) whose error passes
    5 % is named per period and θi, 'beyond the grid' where none does."""
    from microsim.analysis.fullwave_map import crossovers, fullwave_section

    tri = [
        {"period_over_lambda": 8.0, "theta_i": t, "slope": a, "kirchhoff_order_error": e,
         "kirchhoff_energy_ratio": 1.0, "rcw_converged": True, "geometric_group_ratio": 0.9,
         "kirchhoff_order_error_s": 0.5 * e, "kirchhoff_order_error_p": 1.5 * e}
        for t, errs in ((0.0, (0.01, 0.04, 0.08)), (30.0, (0.01, 0.02, 0.03)))
        for a, e in zip((10.0, 20.0, 30.0), errs)
    ]  # fmt: skip
    sin = [
        {"theta_i": 0.0, "amplitude_over_lambda": a, "rayleigh_rice_error": e,
         "rcw_converged": True}
        for a, e in ((0.01, 0.001), (0.1, 0.07))
    ]  # fmt: skip
    doc = {
        "settings": {"wavelength_um": 0.5, "material": "glass n = 1.5", "criterion": 0.05,
                     "rcw_tol": 1e-3, "sinusoid_period_over_lambda": 4.0},
        "triangular": tri, "sinusoidal": sin, "seconds": 1.0,
    }  # fmt: skip
    cross = crossovers(doc)
    assert cross["kirchhoff"] == {(8.0, 0.0): 30.0} and cross["rayleigh_rice"] == {0.0: 0.1}
    text = "\n".join(fullwave_section(doc))
    assert "Λ = 8 λ, θi 0°: 30°" in text and "Λ = 8 λ, θi 30°: beyond the grid" in text
    assert "θi 0°: a/λ = 0.1" in text and "| 8 | 0° | 1.0 % | 4.0 % | 8.0 % |" in text


@pytest.mark.parametrize("profile, surface", [("sinusoidal", "smooth"), ("triangular", "mesh")])
def test_the_1d_kirchhoff_orders_are_the_tile_solvers_on_the_extruded_profile(profile, surface):
    """The grating's Kirchhoff efficiencies equal ``wave.kirchhoff.kirchhoff_orders`` on the
    profile extruded along y (one period, 128 samples; the sinusoid on the band-limited
    interpolant, which it is; the triangle on the mesh, which holds it exactly)."""
    from microsim.wave.kirchhoff import kirchhoff_orders

    g = Grating(profile, 2.0, 0.3, "aluminium")
    nx, ny = 128, 4
    x = np.arange(nx) * g.period / nx
    h = (
        0.5 * g.amplitude * np.cos(2 * np.pi * x / g.period)
        if profile == "sinusoidal"
        else np.where(x <= g.period / 2, 2 * g.amplitude * x / g.period,
                      2 * g.amplitude * (1 - x / g.period))
    )  # fmt: skip
    tile = kirchhoff_orders(
        np.tile(h, (ny, 1)), g.period / nx, LAMBDA, 30.0, material="aluminium", surface=surface
    )
    mine = kirchhoff_efficiencies(g, LAMBDA, 30.0)
    in_plane = tile.n == 0
    assert np.allclose(tile.power[~in_plane], 0.0, atol=1e-12)
    by_m = dict(zip(tile.m[in_plane].tolist(), tile.power[in_plane]))
    for m, eta in zip(mine.orders.tolist(), mine.unpolarised):
        assert abs(by_m[m] - eta) < 1e-9, (m, by_m[m], eta)


def test_the_triangular_grating_surface_holds_the_profile():
    from microsim.errors import UsageError
    from microsim.surfaces import triangular_grating

    s = triangular_grating(64, 0.0625, 0.2, 1.0, ny=4)  # 4 periods of 16 steps
    row = s.heights[0]
    assert row.min() == 0.0 and np.isclose(row.max(), 0.2) and s.tile_size == (4.0, 0.25)
    slopes = np.abs(np.diff(row)) / 0.0625
    assert np.allclose(slopes, 0.4)  # tan α = 2a/Λ on every step: apex and valley on vertices
    with pytest.raises(UsageError, match="even number of grid steps"):
        triangular_grating(64, 0.0625, 0.2, 0.9)
    with pytest.raises(UsageError, match="whole number of times"):
        triangular_grating(60, 0.0625, 0.2, 1.0)


def _random_glass(sigma=0.04, seed=1):
    """A non-symmetric Gaussian glass profile: Λ = 4 λ, ℓ = λ, 32 samples."""
    return random_grating(RandomProfile("gaussian", 4 * LAMBDA, sigma, corr_len=LAMBDA, n=32,
                                        seed=seed), 1.5)  # fmt: skip


def test_random_profiles_realise_their_spectrum():
    """Exact amplitude: every mode k/Λ carries S(k/Λ)/Λ (the samples' periodogram), so the
    samples' variance is Σ_k S(f_k)/Λ; each spectrum integrates to σ² over the real line."""
    from scipy import integrate

    for prof in (RandomProfile("gaussian", 8.0, 0.1, corr_len=0.7, n=64, seed=4),
                 RandomProfile("abc", 8.0, 0.1, B=2.0, C=2.5, n=64, seed=4)):  # fmt: skip
        total = integrate.quad(prof.psd, -np.inf, np.inf)[0]
        assert abs(total / prof.sigma**2 - 1) < 1e-8, prof.spectrum
        h = random_grating(prof).h
        f = np.fft.fftfreq(h.size, prof.period / h.size)
        expected = np.where(f != 0, prof.psd(f), 0.0) / prof.period
        assert np.allclose(np.abs(np.fft.fft(h) / h.size) ** 2, expected, rtol=1e-9, atol=1e-18)
        assert abs(h.var() / expected.sum() - 1) < 1e-9 and abs(h.mean()) < 1e-12


def test_sampled_profile_integrals_equal_a_quadrature():
    """The piecewise-linear phase integral and Fourier coefficients of a random profile
    against the trapezoidal rule on its linear interpolant."""
    g = _random_glass()
    n = g.h.size
    x = np.linspace(0.0, g.period, 320_001)
    h = np.interp(x, np.arange(n + 1) * g.period / n, np.append(g.h, g.h[0]))
    m = np.array([-5, -2, -1, 1, 3, 7])
    qx, qz = 2 * np.pi * m / g.period, np.array([3.0, 7.5, 12.0, 20.0, 9.0, 1.0])
    brute = [np.trapezoid(np.exp(1j * (a * x + b * h)), x) / g.period for a, b in zip(qx, qz)]
    assert np.allclose(_phase_integral(g, qx, qz), brute, atol=1e-9)
    coef = [np.trapezoid(h * np.exp(-1j * a * x), x) / g.period for a in qx]
    assert np.allclose(fourier_coefficients(g, m), coef, atol=1e-11)


@needs_rcw
def test_a_random_glass_profile_converges_and_conserves_energy():
    g = _random_glass()
    r = fullwave.converged_efficiencies(g, LAMBDA, 30.0)
    assert r.info["converged"] and len(r.info["study"]) >= 3
    slices = [step[2] for step in r.info["study"]]
    assert min(slices) >= g.h.size - 1 and slices[-1] > slices[0]  # the raises add slices
    t = fullwave.rcw_efficiencies(
        g, LAMBDA, 30.0, r.info["order"], r.info["levels"], "transmission"
    )
    for pol in ("s", "p"):
        assert abs(getattr(r, pol).sum() + getattr(t, pol).sum() - 1.0) < r.info["tol"], pol


@needs_rcw
@pytest.mark.parametrize("theta", [0.0, 30.0])
def test_rcw_orders_of_a_random_profile_follow_kirchhoff_sign_included(theta):
    """On a gentle non-symmetric profile (σ = 0.03 µm, rms slope 0.11, ℓ = λ: Kirchhoff holds)
    Kirchhoff's orders m and −m differ (its power leans to one side); RCW's must lean the
    same way: matched order by order its difference from Kirchhoff is under a quarter of the
    difference with the orders swapped (a mirrored description would invert the two)."""
    g = _random_glass()
    kir = kirchhoff_efficiencies(g, LAMBDA, theta)
    rcw = fullwave.rcw_efficiencies(g, LAMBDA, theta, order=20, levels=64)
    both = [m for m in kir.orders.tolist() if -m in kir.orders and m in rcw.orders]
    same = sum(abs(rcw.at(m) - kir.at(m)) for m in both)
    swapped = sum(abs(rcw.at(m) - kir.at(-m)) for m in both)
    assert same < 0.25 * swapped, (same, swapped)


@needs_rcw
def test_small_random_profiles_approach_first_order_perturbation_theory():
    """Scaled to rms height σ = λ/100 and λ/200 (same shape), each order carrying ≥ 1 % of the
    first-order diffuse power (s and p, glass): RCW's deviation from Rayleigh–Rice,
    D = η_RCW/η_RR − 1, is the perturbation series' next term, O(q_z σ) on a random profile
    (the interference of the first- and second-order amplitudes, which a sinusoid lacks):
    halving σ must at least halve it, up to the term after, (q_z σ)², and each run's
    truncation error (the change from 64 to 128 levels)."""
    shape = _random_glass()
    dev, trunc, qz = {}, {}, {}
    for sigma in (LAMBDA / 100, LAMBDA / 200):
        g = SampledGrating(shape.period, tuple(shape.h * sigma / shape.rms_height), 1.5)
        rr = rayleigh_rice_efficiencies(g, LAMBDA, 30.0)
        fine = fullwave.rcw_efficiencies(g, LAMBDA, 30.0, order=15, levels=128)
        coarse = fullwave.rcw_efficiencies(g, LAMBDA, 30.0, order=15, levels=64)
        for pol in ("s", "p"):
            first = getattr(rr, pol)
            keep = first > 0.01 * first.sum()
            assert np.array_equal(fine.orders, rr.orders)
            dev[sigma, pol] = getattr(fine, pol)[keep] / first[keep] - 1
            trunc[sigma, pol] = (
                np.abs(getattr(fine, pol) - getattr(coarse, pol))[keep] / first[keep]
            )
            qz[pol] = 2 * np.pi / LAMBDA * (np.cos(np.radians(30.0)) + rr.wo[keep, 2])
    big, small = LAMBDA / 100, LAMBDA / 200
    for pol in ("s", "p"):
        bound = (
            np.abs(dev[big, pol]) / 2 + (qz[pol] * big) ** 2 + trunc[small, pol] + trunc[big, pol]
        )
        assert np.all(np.abs(dev[small, pol]) <= bound), (pol, dev[small, pol], bound)


def test_kirchhoff_s_and_p_split_the_unpolarised_and_p_vanishes_at_brewster():
    """R_s, R_p average to the unpolarised Fresnel reflectance; on glass R_p = 0 at Brewster's
    angle tan θB = n, so a 1D Kirchhoff order whose half-vector angle is θB carries no p."""
    from microsim.analytic.fresnel import fresnel
    from microsim.wave.gratings import fresnel_sp

    c = np.linspace(0.0, 1.0, 11)
    for n in (1.5, complex(0.769, 6.08)):
        rs, rp = fresnel_sp(c, n)
        assert np.allclose(0.5 * (rs + rp), fresnel(c, n), atol=1e-15)
    assert fresnel_sp(np.cos(np.arctan(1.5)), 1.5)[1] < 1e-30
    k = kirchhoff_efficiencies(_random_glass(), LAMBDA, 30.0)
    assert np.allclose(0.5 * (k.s + k.p), k.unpolarised, rtol=1e-14)


def _section_doc():
    """A hand-made map with every part: glass triangles, aluminium TE, its TM study, sinusoids
    and random profiles, one unconverged random row."""
    tri = [
        {"period_over_lambda": 4.0, "theta_i": 0.0, "slope": a, "kirchhoff_order_error": e,
         "kirchhoff_energy_ratio": 1.0, "rcw_converged": True, "geometric_group_ratio": 0.9,
         "kirchhoff_order_error_s": 0.5 * e, "kirchhoff_order_error_p": 1.5 * e}
        for a, e in ((10.0, 0.01), (20.0, 0.08))
    ]  # fmt: skip
    al = [dict(r, kirchhoff_order_error=e) for r, e in zip(tri, (0.06, 0.09))]
    sin = [{"theta_i": 0.0, "amplitude_over_lambda": 0.1, "rayleigh_rice_error": 0.01,
            "rcw_converged": True}]  # fmt: skip
    rnd = [
        {"corr_over_lambda": 1.0, "theta_i": 0.0, "rms_slope_nominal": a, "rms_slope": a,
         "sigma_over_lambda": s, "kirchhoff_order_error": k, "rayleigh_rice_error": r,
         "rcw_converged": ok}
        for a, s, k, r, ok in ((0.1, 0.02, 0.09, 0.02, False), (0.2, 0.04, 0.07, 0.3, True))
    ]  # fmt: skip
    return {
        "settings": {"wavelength_um": 0.5, "material": "glass n = 1.5", "criterion": 0.05,
                     "rcw_tol": 1e-3, "sinusoid_period_over_lambda": 4.0, "random": "Gaussian"},
        "triangular": tri, "triangular_aluminium_te": al, "sinusoidal": sin, "random": rnd,
        "aluminium_tm_study": {"grating": "triangle", "limit": [70, 110], "converged": False,
                               "study": [[13, 20, None], [20, 20, 0.024]]},
        "seconds": 1.0,
    }  # fmt: skip


def test_the_section_never_counts_an_unconverged_row_and_states_non_convergence():
    from microsim.analysis.fullwave_map import crossovers, fullwave_section

    doc = _section_doc()
    cross = crossovers(doc)
    assert cross["kirchhoff_aluminium_te"] == {(4.0, 0.0): 10.0}
    assert cross["kirchhoff_p"] == {(4.0, 0.0): 20.0} and cross["kirchhoff_s"] == {}
    # the unconverged row at slope 0.1 exceeds 5 % but is not the crossing; 0.2 is
    assert cross["kirchhoff_random"] == {(1.0, 0.0): 0.2}
    assert cross["rayleigh_rice_random"] == {(1.0, 0.0): 0.04}
    text = "\n".join(fullwave_section(doc, chart="fullwave-map.png"))
    assert "(RCW not converged)" in text and "did **not** converge" in text
    assert "![Kirchhoff and Rayleigh–Rice against RCW](fullwave-map.png)" in text
    assert "ℓ = 1 λ, θi 0°: 0.2" in text and "σ/λ = 0.04" in text
    assert "Kirchhoff in s departs by more than 5 % from slope: Λ = 4 λ, θi 0°: beyond" in text
    # the summary: smallest crossing per θi, or the grid named as holding throughout
    assert "on aluminium in TE from 10° at θi 0°" in text
    assert "Rayleigh–Rice from σ/λ (within 5 % on the whole grid at θi 0°) on sinusoids" in text


def test_the_map_chart_has_a_panel_per_incidence_and_method(tmp_path):
    from microsim.analysis.fullwave_map import fullwave_chart

    fig = fullwave_chart(_section_doc())
    axes = fig.get_axes()
    assert len(axes) == 3  # one incidence: Kirchhoff on triangles, on random profiles; RR
    assert axes[0].get_xlabel() == "facet slope α (°)" and "θi = 0°" in axes[0].get_title()
    assert all(ax.get_yscale() == "log" for ax in axes)
    fig.savefig(tmp_path / "map.png")
    assert (tmp_path / "map.png").stat().st_size > 10_000


@needs_rcw
def test_the_methods_panel_places_rcw_and_kirchhoff_on_one_grating():
    """``microsim bench --methods``' full-wave panel: every point has the keys the index reads;
    the converged RCW point's error (its last change) is bounded by the tolerance per order,
    K·tol/Σ η over the K orders with θo ≤ 80°; Kirchhoff is cheaper than any RCW solve."""
    from microsim.analysis.report_methods import _METHODS_KEYS
    from microsim.app.bench_methods_study import _panel_fullwave, methods_config

    panel = _panel_fullwave(methods_config(quick=True))
    assert all(k in panel for k in _METHODS_KEYS["panel"])
    assert all(k in p for p in panel["points"] for k in _METHODS_KEYS["point"])
    rcw = [p for p in panel["points"] if p["key"] == "rcw"]
    last = rcw[-1]
    assert last["converged_point"] and len(rcw) >= 3
    g = random_grating(RandomProfile("gaussian", 4 * LAMBDA, 0.2 * LAMBDA / np.sqrt(2),
                                     corr_len=LAMBDA, n=32, seed=0), 1.5)  # fmt: skip
    ref = fullwave.converged_efficiencies(
        g, LAMBDA, 30.0, start=(int(2 * g.period / LAMBDA) + 5, 20)
    )
    inside = np.abs(ref.wo[:, 0]) < np.sin(np.radians(80.0))
    assert last["error"] <= inside.sum() * ref.info["tol"] / ref.unpolarised[inside].sum()
    kir = [p for p in panel["points"] if p["key"] == "kirchhoff-1d"]
    assert len(kir) == 1 and kir[0]["error"] > 0
    assert kir[0]["seconds"] < min(p["seconds"] for p in rcw)
