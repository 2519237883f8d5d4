"""The measurements of `microsim bench --methods` (``microsim.app.bench_methods``: what each
panel measures, and how): the settings, the three panels and ``methods_study``."""

from __future__ import annotations

import math
import os
import subprocess
import time
import warnings
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

__all__ = ["MethodsConfig", "QUICK", "SCHEMA", "methods_config", "methods_study"]

SCHEMA = "microsim.bench_methods/1"
REF_RTOL = 1e-6  # quadrature tolerance of the panel A reference
MODEL_RTOL = 1e-3  # the project's default bin-average tolerance (what a user pays for)


@dataclass(frozen=True)
class MethodsConfig:
    """What ``methods_study`` measures (module docstring). Lengths of the wave scene in
    micrometres (the unit of dx), angles in degrees."""

    theta_i: float = 30.0
    grooves: int = 4000
    m: float = 0.3
    rays: tuple = tuple(10_000 * 4**k for k in range(6))  # 1e4 … 1.02e7 (panel A)
    wave_rays: tuple = tuple(10_000 * 4**k for k in range(5))  # 1e4 … 2.6e6 (panel B)
    wave_ref_n: int = 1024
    wave_tiles: tuple = (64, 128, 256, 512)
    dx: float = 0.1
    sigma: float = 0.125
    B: float = 10.0
    C: float = 2.5
    band_limit: float = 4.0
    wavelength: float = 0.5
    upsample: int = 2
    repeat: int = 3
    cheap: float = 2.0  # a run longer than this (s) is not repeated
    threads: int = 2
    grating_slope: float = 0.2  # nominal rms slope of panel C's random profile


QUICK = dict(
    grooves=1000,
    rays=(10_000, 40_000, 160_000),
    wave_rays=(10_000, 160_000),
    wave_ref_n=256,
    wave_tiles=(64, 128),
)
"""``--quick``: 1000 grooves, three ray counts (16× apart end to end), a 256² reference tile."""


def methods_config(quick: bool = False, **overrides) -> MethodsConfig:
    """``QUICK`` or the defaults, with ``overrides`` (``MethodsConfig`` fields)."""
    from ..errors import UsageError

    conf = dict(QUICK) if quick else {}
    unknown = sorted(set(overrides) - set(MethodsConfig.__dataclass_fields__))
    if unknown:
        raise UsageError(
            f"unknown setting(s) {unknown}: allowed {sorted(MethodsConfig.__dataclass_fields__)}"
        )
    conf.update(overrides)
    return MethodsConfig(**conf)


def _best_of(fn, repeat: int, cheap: float):
    """(best wall seconds, [fn(k) for the runs]) over up to ``repeat`` runs k = 0, 1, …; a
    run longer than ``cheap`` seconds ends the repetition."""
    times, outs = [], []
    for k in range(repeat):
        t0 = time.perf_counter()
        outs.append(fn(k))
        times.append(time.perf_counter() - t0)
        if times[-1] > cheap:
            break
    return min(times), outs


def _commit() -> tuple[str | None, bool | None]:
    """(git HEAD of the package's checkout, whether its microsim/ has uncommitted changes),
    (None, None) when it is not a git checkout."""
    here = Path(__file__).resolve().parents[1]  # the microsim package

    def git(*a):
        return subprocess.run(["git", *a], cwd=here, capture_output=True, text=True, timeout=10)

    try:
        head = git("rev-parse", "HEAD")
        if head.returncode != 0:
            return None, None
        dirty = git("status", "--porcelain", "--untracked-files=no", "--", str(here))
    except (OSError, subprocess.SubprocessError):
        return None, None
    return head.stdout.strip() or None, bool(dirty.stdout.strip())


# --- panel A: geometric scene ------------------------------------------------------------------
@dataclass(frozen=True)
class _RelRms:
    """``verdict``'s rel_rms of a model against a run, and the run's ray-noise floor over the
    same energy set (None where there is none)."""

    rel_rms: float | None
    noise_floor: float | None


def _rel_rms(sim, se, counts, model, bins) -> _RelRms:
    """``verdict``'s rel_rms of ``model`` against ``sim`` and the ray-noise floor over the
    same energy set (used bins: ≥ MIN_EVENTS events, f̄ > 0)."""
    from microsim.analysis.verdicts import Measured, Prediction, verdict
    from microsim.stats import MIN_EVENTS, energy_set

    omega = bins.projected_solid_angle()
    measured = Measured(sim, se, counts, omega, bins.theta_edges, bins.phi_edges)
    v = verdict(measured, Prediction(model))
    used = (counts >= MIN_EVENTS) & np.isfinite(sim) & (sim > 0) & np.isfinite(se)
    w = np.where(used, sim * omega, 0.0)
    E = energy_set(w).reshape(w.shape)
    noise = float(np.sqrt(np.sum(w[E] * (se[E] / sim[E]) ** 2) / w[E].sum())) if E.any() else None
    return _RelRms(v["rel_rms"], noise)


def _geometric_trace_points(cfg: MethodsConfig, surface, bins, ref, mask: str, label: str):
    """Panel A's curve of one trace path (``masking=mask``): per ray count of ``cfg.rays``, the
    best wall time and the mean rel_rms of the runs against ``ref`` with its standard error,
    beside the runs' ray-noise floor and the path's one-off set-up time."""
    from microsim.sim import simulate

    th = float(cfg.theta_i)

    def run(n, k):
        return simulate(
            surface,
            "aluminium",
            th,
            rays=int(n),
            bins=bins,
            masking=mask,
            seed=k,
            threads=cfg.threads,
        )

    t0 = time.perf_counter()
    run(cfg.rays[0], 99)  # scene + BVH (traced) or numba compilation (analytic)
    setup = time.perf_counter() - t0
    points = []
    for n in cfg.rays:
        sec, outs = _best_of(lambda k, n=n: run(n, k), cfg.repeat, cfg.cheap)
        errs = [_rel_rms(r.brdf[0], r.stderr[0], r.counts[0], ref, bins) for r in outs]
        e = np.array([np.nan if x.rel_rms is None else x.rel_rms for x in errs])
        nf = [x.noise_floor for x in errs if x.noise_floor is not None]
        points.append(
            {
                "method": label,
                "key": f"ray-{mask}",
                "kind": "curve",
                "setting": f"{n:,} rays",
                "size": int(n),
                "seconds": sec,
                "runs": len(outs),
                "error": float(e.mean()),
                "error_se": float(e.std(ddof=1) / math.sqrt(len(e))) if len(e) > 1 else None,
                "errors": e.tolist(),
                "noise_floor": float(np.mean(nf)) if nf else None,
                "setup_seconds": setup,
                "rays_per_s": n / sec,
            }
        )
    return points


def _panel_geometric(cfg: MethodsConfig) -> dict:
    from microsim import analytic as an
    from microsim.sim import Bins
    from microsim.sim.predict import Predictor, predict
    from microsim.surfaces import vgrooves

    bins = Bins(45, 37)  # bench's throughput bins: 2° θo × 5° Δφ, folded
    ndf = an.Beckmann(cfg.m)
    th = float(cfg.theta_i)
    surface = vgrooves(cfg.grooves, ndf, seed=0)
    vg = Predictor("ts-vgroove", an.TorranceSparrow(ndf, an.VGroove(), "aluminium"))
    sm = Predictor("ts-smith", an.TorranceSparrow(ndf, an.Smith(), "aluminium"))
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        t0 = time.perf_counter()
        ref = predict([vg], [th], bins, rtol=REF_RTOL)["ts-vgroove"][0]
        ref_seconds = time.perf_counter() - t0
    exact = np.zeros(bins.shape)
    many = np.full(bins.shape, 10**9)
    points = []
    for spec, label in (
        (sm, "Torrance–Sparrow, Smith G"),
        (vg, "Torrance–Sparrow, V-groove G (exact: quadrature error)"),
    ):
        sec, outs = _best_of(
            lambda k, s=spec: predict([s], [th], bins, rtol=MODEL_RTOL)[s.name][0],
            cfg.repeat,
            cfg.cheap,
        )
        e = _rel_rms(ref, exact, many, outs[0], bins).rel_rms
        points.append(
            {
                "method": label,
                "key": spec.name,
                "kind": "closed-form",
                "setting": f"bin average, rtol {MODEL_RTOL:g}",
                "size": None,
                "seconds": sec,
                "runs": len(outs),
                "error": e,
                "error_se": None,
            }
        )
    for mask, label in (("traced", "ray trace (Embree)"), ("analytic", "exact V-groove path")):
        points += _geometric_trace_points(cfg, surface, bins, ref, mask, label)
    return {
        "key": "geometric",
        "title": f"V-grooves, Beckmann m = {cfg.m:g}, aluminium, θi = {th:g}°",
        "scene": f"vgrooves({cfg.grooves}, Beckmann({cfg.m:g})), aluminium, θi = {th:g}°, "
        f"Bins(45, 37)",
        "reference": "Torrance–Sparrow with V-groove G (Mikkelsen 2009, eq. 25), bin-averaged "
        f"to rtol {REF_RTOL:g}",
        "reference_seconds": ref_seconds,
        "reference_warnings": len(caught),
        "error_measure": "energy-weighted relative RMS over the 90 % energy set (verdict "
        "rel_rms); ray traces include their noise",
        "points": points,
    }


# --- panel B: wave scene -----------------------------------------------------------------------
def _wave_surface(cfg: MethodsConfig, n: int):
    from microsim.surfaces import abc

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # C ≤ 3: the slope variance depends on dx (known)
        return abc(n, cfg.dx, cfg.sigma, cfg.B, cfg.C, seed=0, band_limit=cfg.band_limit)


@dataclass(frozen=True)
class _EnergyError:
    """A method's energy deviation from the Kirchhoff reference (``_energy_point``); its
    fields go into the panel's JSON point as they are."""

    deviation: float | None
    error: float | None
    error_se: float | None
    own_se: float | None
    reference_se: float
    rel_error: float | None


def _energy_point(ref, model_bins, model_se, name: str) -> _EnergyError:
    """|energy_dev| of ``model_bins`` against the Kirchhoff ``ref`` (incidence 0) and its
    uncertainty: ``wave_verdict``'s ``energy_dev_se`` (the reference's speckle) and the
    model's own (``model_se``, or None) over the same energy set, in quadrature; also
    ``reference_se``, the reference's relative speckle error of Σ_E Ω f̄ itself."""
    from microsim.analysis.wave_verdicts import THETA_O_MAX, diffuse_brdf, wave_verdict
    from microsim.stats import energy_set

    v = wave_verdict(ref, 0, model_bins, model=name)
    bins = ref.bins
    omega = bins.projected_solid_angle().reshape(-1)
    f = diffuse_brdf(ref, 0).reshape(-1)
    se_r = np.asarray(ref.stderr[0], dtype=float).reshape(-1)
    m = np.asarray(model_bins, dtype=float).reshape(-1)
    inside = np.repeat(bins.theta_edges[1:] <= THETA_O_MAX + 1e-9, bins.n_phi)
    good = np.isfinite(m) & np.isfinite(f) & np.isfinite(se_r) & (f > 0) & inside
    E = energy_set(np.where(good, f * omega, 0.0)) & good
    norm = np.sum(omega[E] * f[E])
    ref_se = float(np.sqrt(np.sum((omega[E] * se_r[E]) ** 2)) / norm)
    own = None
    if model_se is not None:
        se_m = np.asarray(model_se, dtype=float).reshape(-1)
        own = float(np.sqrt(np.sum((omega[E] * se_m[E]) ** 2)) / norm)
    d = v["energy_dev"]
    return _EnergyError(
        deviation=d,
        error=None if d is None else abs(d),
        error_se=None if d is None else math.hypot(v["energy_dev_se"], own or 0.0),
        own_se=own,
        reference_se=ref_se,
        rel_error=v["rel_error"],
    )


def _kirchhoff_points(cfg: MethodsConfig, ref, solve) -> list[dict]:
    """Panel B's Kirchhoff curve: ``solve`` (the reference's solver) on each smaller tile of
    ``cfg.wave_tiles``, its |energy deviation| from ``ref``."""
    from microsim.analysis.wave_verdicts import diffuse_brdf

    points = []
    for n in cfg.wave_tiles:
        surface = _wave_surface(cfg, n)
        sec, outs = _best_of(lambda k, s=surface: solve(s), cfg.repeat, cfg.cheap)
        r = outs[0]
        p = _energy_point(ref, diffuse_brdf(r, 0), r.stderr[0], f"kirchhoff-{n}")
        points.append(
            {
                "method": "Kirchhoff, smaller tile",
                "key": "kirchhoff",
                "kind": "curve",
                "setting": f"{n}² ({n * cfg.dx / float(cfg.wavelength):g} λ)",
                "size": int(n),
                "seconds": sec,
                "runs": len(outs),
                **asdict(p),
                "orders": int(r.info.orders[0]),
            }
        )
    return points


def _wave_trace_points(cfg: MethodsConfig, ref, ref_surface, bins) -> list[dict]:
    """Panel B's ray-trace curve on the reference tile itself: per ray count of
    ``cfg.wave_rays``, the mean energy deviation of the runs from ``ref``, its uncertainty
    (the reference's speckle and the runs' own noise in quadrature) and the one-off set-up."""
    from microsim.sim import simulate

    def trace(n, k):
        return simulate(
            ref_surface,
            "aluminium",
            float(cfg.theta_i),
            rays=int(n),
            bins=bins,
            seed=k,
            threads=cfg.threads,
        )

    t0 = time.perf_counter()
    trace(cfg.wave_rays[0], 99)  # Embree scene + BVH of the reference tile
    setup = time.perf_counter() - t0
    points = []
    for n in cfg.wave_rays:
        sec, outs = _best_of(lambda k, n=n: trace(n, k), cfg.repeat, cfg.cheap)
        ps = [_energy_point(ref, r.brdf[0], r.stderr[0], "ray-trace") for r in outs]
        dev = float(np.mean([q.deviation for q in ps]))
        own = math.sqrt(np.mean([q.own_se**2 for q in ps]) / len(ps))
        points.append(
            {
                "method": "ray trace (Embree)",
                "key": "ray-traced",
                "kind": "curve",
                "setting": f"{n:,} rays",
                "size": int(n),
                "seconds": sec,
                "runs": len(outs),
                "deviation": dev,
                "error": abs(dev),
                "error_se": math.hypot(
                    float(np.mean([q.error_se**2 - q.own_se**2 for q in ps])) ** 0.5,
                    own,
                ),
                "own_se": own,
                "reference_se": ps[0].reference_se,
                "rel_error": float(np.mean([q.rel_error for q in ps])),
                "setup_seconds": setup,
            }
        )
    return points


def _panel_wave(cfg: MethodsConfig) -> dict:
    from microsim.analysis.wave_verdicts import (
        closed_form,
        lattice_average,
        surface_spectrum,
        wave_verdict,
    )
    from microsim.analytic import Beckmann
    from microsim.analytic.brdf import torrance_sparrow
    from microsim.sim import Bins
    from microsim.sim.predict import bin_average
    from microsim.vectors import spherical_deg
    from microsim.wave import kirchhoff_brdf

    bins = Bins(18, 13)
    th, lam = float(cfg.theta_i), float(cfg.wavelength)

    def solve(surface):
        return kirchhoff_brdf(
            surface,
            "aluminium",
            th,
            wavelength=lam,
            bins=bins,
            upsample=cfg.upsample,
            workers=cfg.threads,
        )

    ref_surface = _wave_surface(cfg, cfg.wave_ref_n)
    t0 = time.perf_counter()
    ref = solve(ref_surface)
    ref_seconds = time.perf_counter() - t0
    side = cfg.wave_ref_n * cfg.dx
    points = []
    spec = surface_spectrum(ref_surface)
    m_real = float(ref_surface.stats()["m_realised"])
    wi = spherical_deg(th, 0.0)
    fns = {name: closed_form(name, spec, lam, "aluminium") for name in _WAVE_CLOSED}
    ndf = Beckmann(m_real)
    fns["ts-smith"] = lambda a, b: torrance_sparrow(a, b, ndf, "smith", "aluminium")
    for key, fn in fns.items():
        sec, outs = _best_of(
            lambda k, fn=fn: bin_average(wi, bins, fn, 0.0, rtol=MODEL_RTOL),
            cfg.repeat,
            cfg.cheap,
        )
        p = _energy_point(ref, outs[0].values, None, key)
        reference_se = p.reference_se  # the reference's speckle: the same for every method
        lat = wave_verdict(ref, 0, lattice_average(ref, 0, fn), model=key)["energy_dev"]
        points.append(
            {
                "method": _LABELS[key],
                "key": key,
                "kind": "closed-form",
                "setting": f"bin average, rtol {MODEL_RTOL:g}",
                "size": None,
                "seconds": sec,
                "runs": len(outs),
                **asdict(p),
                "error_lattice": None if lat is None else abs(lat),
                "converged": bool(np.all(outs[0].converged)),
            }
        )
    points += _kirchhoff_points(cfg, ref, solve)
    points += _wave_trace_points(cfg, ref, ref_surface, bins)
    return {
        "key": "wave",
        "title": f"ABC tile, σ = λ/{lam / cfg.sigma:g} (transition), aluminium, θi = {th:g}°",
        "scene": f"catalogue scene abc-transition-wave: ABC σ = {cfg.sigma:g} µm, B = {cfg.B:g} "
        f"µm, C = {cfg.C:g}, dx = {cfg.dx:g} µm, λ = {lam:g} µm, aluminium, θi = {th:g}°, "
        "Bins(18, 13)",
        "reference": f"Kirchhoff on {cfg.wave_ref_n}² ({side:g} µm = {side / lam:g} λ), "
        f"upsample {cfg.upsample}",
        "reference_seconds": ref_seconds,
        "reference_se": float(reference_se),
        "m_realised": m_real,
        "error_measure": "|energy deviation| over the reference's 90 % diffuse energy set "
        "(wave_verdict energy_dev); uncertainty: reference speckle (common) and the "
        "method's own noise in quadrature",
        "points": points,
    }


_WAVE_CLOSED = ("rayleigh-rice", "low-smooth", "kirchhoff-first-order")
_LABELS = {
    "rayleigh-rice": "Rayleigh–Rice",
    "low-smooth": "Löw smooth",
    "kirchhoff-first-order": "Kirchhoff, first order",
    "ts-smith": "Torrance–Sparrow, Smith G",
}


# --- panel C: the full-wave rung -------------------------------------------------------------
def _panel_fullwave(cfg: MethodsConfig) -> dict:
    """Panel C of the module docstring (needs the `fullwave` extra)."""
    from microsim.analysis.fullwave_map import order_error
    from microsim.wave import fullwave
    from microsim.wave.gratings import kirchhoff_efficiencies
    from microsim.wave.random_profiles import RandomProfile, random_grating

    lam, th = cfg.wavelength, float(cfg.theta_i)
    ell = lam
    prof = RandomProfile("gaussian", 4 * ell, cfg.grating_slope * ell / math.sqrt(2),
                         corr_len=ell, n=32, seed=0)  # fmt: skip
    g = random_grating(prof, 1.5)
    t0 = time.perf_counter()
    ref = fullwave.converged_efficiencies(g, lam, th, start=(int(2 * g.period / lam) + 5, 20))
    ref_seconds = time.perf_counter() - t0
    steps = ref.info["study"]
    points = []
    for k, (order, levels, slices, _, seconds) in enumerate(steps):
        if k == len(steps) - 1:  # the converged one: its last change under a raise
            before = fullwave.rcw_efficiencies(g, lam, th, *steps[k - 1][:2])
            error = order_error(before, ref)[0]
        else:
            error = order_error(fullwave.rcw_efficiencies(g, lam, th, order, levels), ref)[0]
        points.append({"key": "rcw", "method": "RCW (SCATMECH)", "kind": "curve",
                       "setting": f"{order} orders × {slices} slices", "size": order,
                       "seconds": seconds, "runs": 1, "error": error, "error_se": None,
                       "converged_point": k == len(steps) - 1})  # fmt: skip
    seconds, outs = _best_of(lambda _: kirchhoff_efficiencies(g, lam, th), cfg.repeat, cfg.cheap)
    points.append({"key": "kirchhoff-1d", "method": "Kirchhoff (1D, per order)",
                   "kind": "closed-form", "setting": "closed form per linear piece",
                   "seconds": seconds, "runs": len(outs), "error": order_error(outs[0], ref)[0],
                   "error_se": None})  # fmt: skip
    return {
        "key": "fullwave",
        "title": f"Periodic Gaussian glass profile, rms slope {cfg.grating_slope:g}, θi = {th:g}°",
        "scene": f"random_grating(RandomProfile('gaussian', {4 * ell:g}, "
        f"{prof.sigma:.4g}, corr_len={ell:g}, n=32, seed=0), 1.5), λ = {lam:g} µm",
        "reference": f"RCW converged to 1e-3 ({ref.info['order']} orders × "
        f"{ref.info['slices']} slices)",
        "reference_seconds": ref_seconds,
        "error_measure": "share of the reflected power in the wrong orders (θo ≤ 80°); the "
        "converged RCW point's error is its last change",
        "points": points,
    }


def methods_study(quick: bool = False, cfg: MethodsConfig | None = None) -> dict:
    """Both panels of the module docstring as a JSON-able dict (``cfg`` overrides ``quick``)."""
    cfg = cfg if cfg is not None else methods_config(quick)
    load0 = list(os.getloadavg())
    commit, dirty = _commit()
    t0 = time.perf_counter()
    panels = [_panel_geometric(cfg), _panel_wave(cfg)]
    from microsim.wave import fullwave

    skipped = fullwave.available()
    if skipped is None:
        panels.append(_panel_fullwave(cfg))
    settings = {k: list(v) if isinstance(v, tuple) else v for k, v in asdict(cfg).items()}
    return {
        "fullwave_skipped": skipped,
        "schema": SCHEMA,
        "quick": bool(quick),
        "machine": {
            "cpus": os.cpu_count(),
            "load_average_start": load0,
            "load_average_end": list(os.getloadavg()),
            "threads": cfg.threads,
            "commit": commit,
            "worktree_modified": dirty,
        },
        "settings": settings,
        "seconds": time.perf_counter() - t0,
        "panels": panels,
    }
