"""`microsim bench --methods`: wall time against error for the methods themselves — which
method a scene needs, and what it costs.

Two scenes, each judged against its own reference; every time is wall seconds on this machine
(``time.perf_counter``), the best of ``repeat`` (3) runs where one run takes less than
``cheap`` seconds, else one run; ``threads`` (2) worker threads / FFT workers throughout. What
is timed is the method's own work for one incidence: the closed forms' bin averages over the
bins, ``simulate`` (surface, Embree scene and BVH, and for the analytic V-groove path the numba
compilation excluded: a warm-up call on the same surface object does them, and its time is
recorded as ``setup_seconds``), ``kirchhoff_brdf`` (surface synthesis excluded).

Panel A, geometric scene: V-grooves with a Beckmann NDF, m = 0.3 (``surfaces.vgrooves(4000,
Beckmann(0.3), seed=0)``), aluminium, θi = 30°, ``Bins(45, 37)`` (2° × 5° folded, the bins of
``microsim bench``'s throughput runs: with the 2° × 2° bins of its time-to-accuracy run, 10⁴
rays leave no bin with the 25 events a verdict needs). Reference: the exact closed form of that
surface, Torrance–Sparrow with the V-groove G (Mikkelsen 2009, eq. 25), bin-averaged by
``sim.predict.predict`` to relative quadrature error 1e-6. Error: the energy-weighted relative
RMS error over the bins carrying 90 % of the energy,
``analysis.verdicts.verdict(...)["rel_rms"]``, √(Σ_E f̄Ω ((m − f̄)/f̄)²/Σ_E f̄Ω), with f̄ the
method's bins and m the reference's for the ray traces (so it *includes the ray noise*: it
falls as 1/√N until the model-error floor — here the finite sample of 4000 grooves against the
nominal NDF), and f̄ the reference, m the closed form for the closed forms. Methods:
Torrance–Sparrow with Smith G (a real model error on V-grooves) and with the V-groove G at the
project's default quadrature tolerance 1e-3 (its error is that quadrature error); the ray trace
(``simulate``, ``masking="traced"``: Embree) and the exact V-groove path
(``masking="analytic"``: float64, no Embree) at increasing ray counts. A ray-trace point's
error is the mean over the repeated runs (seeds 0, 1, 2), its uncertainty the standard
deviation of those errors / √runs (None after a single run), and ``noise_floor`` = √(Σ_E f̄Ω
(se/f̄)²/Σ_E f̄Ω) the part the ray noise alone contributes.

Panel B, wave scene: the catalogue scene surfaces/abc-transition-wave.toml (ABC PSD, σ = 0.125
µm = λ/4, B = 10 µm, C = 2.5, band limit 4, exact amplitudes, dx = 0.1 µm = λ/5, λ = 0.5 µm;
the transition regime), aluminium, θi = 30°, ``Bins(18, 13)`` (5° × 15° folded). Reference:
the Kirchhoff solver (``wave.kirchhoff_brdf``, the smooth interpolant upsampled 2×, as the
scene) on the largest tile afforded: ``wave_ref_n``² = 1024² samples, 102.4 µm = 204.8 λ
(``--quick``: 256², 51.2 λ). Error: |energy deviation| over the reference's 90 % diffuse
energy set, ``analysis.wave_verdicts.wave_verdict(...)["energy_dev"]`` = Σ_E Ω(f̄ − m)/Σ_E Ω f̄
(f̄ the reference's diffuse part, m the method's bins; bins beyond θo = 80° left out), the
measure of the regime map. Its uncertainty combines in quadrature the reference's speckle
part (``energy_dev_se``, common to every point of the panel; the reference's own relative
speckle error of its energy Σ_E Ω f̄ is the panel's ``reference_se``, drawn as a dotted line)
and the method's own noise, √(Σ_E (Ω se_m)²)/Σ_E Ω f̄ (ray noise; a smaller Kirchhoff tile's own
speckle). Methods: Kirchhoff on smaller tiles (``wave_tiles``: 64²–512² at the same dx, new
realisations of the same PSD: the error includes realisation scatter), Rayleigh–Rice (Löw et
al. 2012, eq. 3, nominal PSD, no fit), Löw's smooth-surface model (PSD's A, B, C), the
first-order Kirchhoff expression, Torrance–Sparrow with Smith G and Beckmann(m realised by the
reference tile), all four bin-averaged by ``sim.predict.bin_average`` (rtol 1e-3; the error
with the solver's own lattice averaging is kept as ``error_lattice``), and the ray trace of
the reference tile itself at increasing ray counts — its error stops falling at the
geometric-optics error of this σ/λ: more rays do not buy accuracy a wave scene needs.

Panel C, full-wave rung (only with the `fullwave` extra; without it the study's
``fullwave_skipped`` says why): a periodic Gaussian glass profile from the full-wave map
(``wave.random_profiles``: ℓ = λ, nominal rms slope ``grating_slope``, Λ = 4 ℓ, 32 samples,
seed 0), θi as above. Reference: RCW (``wave.fullwave.converged_efficiencies``, tolerance
10⁻³). Error: the share of the reflected power put in the wrong orders, Σ|η − η_RCW|/Σ η_RCW
over the orders with θo ≤ 80° (``analysis.fullwave_map.order_error``). Methods: RCW at each
truncation of its convergence study (its error against the converged solution; the converged
point's own error is its last change under a raise, the truncation it can vouch for), and
scalar Kirchhoff (``wave.gratings.kirchhoff_efficiencies``) against it.

Output (``methods_study``): a JSON-able dict — ``machine`` (cpus, load average at start and
end, threads, git commit when the package is a checkout and whether its microsim/ had
uncommitted changes), ``settings``, ``panels`` (each:
``key``, ``title``, ``scene``, ``reference``, ``error_measure``, ``points``: {method, kind
"closed-form" | "curve", setting, size, seconds, runs, error, error_se, ...}). Errors are
dimensionless fractions, times seconds.
"""

from __future__ import annotations

import math
import os
import subprocess
import time
import warnings
from dataclasses import asdict, dataclass, fields
from pathlib import Path

import numpy as np

__all__ = [
    "MethodsConfig",
    "MethodsStudy",
    "QUICK",
    "methods_config",
    "methods_study",
    "methods_chart",
    "format_methods",
    "write_methods",
    "run_methods_command",
    "METHODS_JSON",
    "METHODS_PNG",
]

METHODS_JSON = "methods.json"
METHODS_PNG = "methods.png"
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
def _rel_rms(sim, se, counts, model, bins) -> dict:
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
    return {"rel_rms": v["rel_rms"], "noise_floor": noise}


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
        e = np.array([np.nan if x["rel_rms"] is None else x["rel_rms"] for x in errs])
        nf = [x["noise_floor"] for x in errs if x["noise_floor"] is not None]
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
        e = _rel_rms(ref, exact, many, outs[0], bins)["rel_rms"]
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


def _energy_point(ref, model_bins, model_se, name: str) -> dict:
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
    return {
        "deviation": d,
        "error": None if d is None else abs(d),
        "error_se": None if d is None else math.hypot(v["energy_dev_se"], own or 0.0),
        "own_se": own,
        "reference_se": ref_se,
        "rel_error": v["rel_error"],
    }


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
                **p,
                "orders": int(r.meta["orders"][0]),
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
        dev = float(np.mean([q["deviation"] for q in ps]))
        own = math.sqrt(np.mean([q["own_se"] ** 2 for q in ps]) / len(ps))
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
                    float(np.mean([q["error_se"] ** 2 - q["own_se"] ** 2 for q in ps])) ** 0.5,
                    own,
                ),
                "own_se": own,
                "reference_se": ps[0]["reference_se"],
                "rel_error": float(np.mean([q["rel_error"] for q in ps])),
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
                **p,
                "error_lattice": None if lat is None else abs(lat),
                "converged": bool(np.all(outs[0].converged)),
            }
        )
    points += _kirchhoff_points(cfg, ref, solve)
    points += _wave_trace_points(cfg, ref, ref_surface, bins)
    return {
        "key": "wave",
        "title": f"ABC tile, σ = λ/{lam / cfg.sigma:g} (transition), aluminium, θi = {th:g}°",
        "scene": f"surfaces/abc-transition-wave.toml: ABC σ = {cfg.sigma:g} µm, B = {cfg.B:g} "
        f"µm, C = {cfg.C:g}, dx = {cfg.dx:g} µm, λ = {lam:g} µm, aluminium, θi = {th:g}°, "
        "Bins(18, 13)",
        "reference": f"Kirchhoff on {cfg.wave_ref_n}² ({side:g} µm = {side / lam:g} λ), "
        f"upsample {cfg.upsample}",
        "reference_seconds": ref_seconds,
        "reference_se": float(points[0]["reference_se"]),
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


# --- output -----------------------------------------------------------------------------------
def _fields_of(cls, doc: dict) -> dict:
    """``cls``'s fields read from the JSON object ``doc`` (absent ones None)."""
    return {f.name: doc.get(f.name) for f in fields(cls)}


@dataclass(frozen=True)
class MethodPoint:
    """What the chart and the table read of one point of a panel (the JSON holds more)."""

    method: str
    key: str
    kind: str  # "curve" (one of a series over a size) or "closed-form"
    setting: str
    seconds: float
    error: float | None
    error_se: float | None


@dataclass(frozen=True)
class Panel:
    """What the chart and the table read of one panel: its title, reference, error measure,
    the reference's own uncertainty (the wave panel's) and its points."""

    key: str
    title: str
    reference: str
    error_measure: str
    reference_se: float | None
    points: tuple


@dataclass(frozen=True)
class StudyMachine:
    """Where and when the study ran (``methods.json``'s ``machine``)."""

    cpus: int
    load_average_start: list
    load_average_end: list
    threads: int
    commit: str | None
    worktree_modified: bool | None


@dataclass(frozen=True)
class MethodsStudy:
    """The study as the chart and the table read it: ``MethodsStudy.from_json`` of
    ``methods_study``'s JSON object."""

    quick: bool
    seconds: float
    machine: StudyMachine
    panels: tuple

    @classmethod
    def from_json(cls, doc: dict) -> MethodsStudy:
        def panel(d):
            points = tuple(MethodPoint(**_fields_of(MethodPoint, p)) for p in d.get("points"))
            return Panel(**{**_fields_of(Panel, d), "points": points})

        return cls(
            quick=doc.get("quick"),
            seconds=doc.get("seconds"),
            machine=StudyMachine(**_fields_of(StudyMachine, doc.get("machine"))),
            panels=tuple(panel(d) for d in doc.get("panels")),
        )


_MARKERS = {
    "ts-smith": ("C2", "^"),
    "ts-vgroove": ("C3", "v"),
    "rayleigh-rice": ("C0", "o"),
    "low-smooth": ("C1", "s"),
    "kirchhoff-first-order": ("C5", "D"),
    "ray-traced": ("C4", "o"),
    "ray-analytic": ("C6", "s"),
    "kirchhoff": ("C9", "h"),
    "rcw": ("C7", "P"),
    "kirchhoff-1d": ("C9", "*"),
}


def methods_chart(study: dict, path) -> None:
    """Two log–log panels (geometric, wave) of error against wall seconds, written to ``path``
    (PNG, atomically): curves for the methods with a size (rays, tile), single markers for
    the closed forms, error bars where a point has an uncertainty; the wave panel's reference
    uncertainty as a dotted line."""
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    from ..atomic import atomic_open

    study = MethodsStudy.from_json(study)
    panels = study.panels
    fig, axes = plt.subplots(1, len(panels), figsize=(6.2 * len(panels), 4.8), squeeze=False)
    for ax, panel in zip(axes[0], panels):
        by: dict[str, list] = {}
        for p in panel.points:
            by.setdefault(p.key, []).append(p)
        for key, pts in by.items():
            pts = [p for p in pts if p.error is not None and p.error > 0]
            if not pts:
                continue
            colour, marker = _MARKERS.get(key, ("k", "x"))
            x = [p.seconds for p in pts]
            y = [p.error for p in pts]
            yerr = [p.error_se or 0.0 for p in pts]
            # an error bar below zero is drawn down to 1/10 of the point on the log axis
            lo = [min(e, 0.9 * v) for e, v in zip(yerr, y)]
            curve = pts[0].kind == "curve"
            ax.errorbar(
                x,
                y,
                yerr=[lo, yerr],
                color=colour,
                marker=marker,
                ls="-" if curve else "none",
                ms=6 if curve else 9,
                capsize=2,
                label=pts[0].method,
            )
            if curve:
                ax.annotate(pts[0].setting, (x[0], y[0]), fontsize=7, xytext=(3, 3),
                            textcoords="offset points")  # fmt: skip
                ax.annotate(pts[-1].setting, (x[-1], y[-1]), fontsize=7, xytext=(3, 3),
                            textcoords="offset points")  # fmt: skip
        if panel.key == "wave" and panel.reference_se:
            ax.axhline(panel.reference_se, color="grey", ls=":", lw=1)
            ax.annotate("reference speckle (1 se)", (0.02, panel.reference_se),
                        xycoords=("axes fraction", "data"), fontsize=7, color="grey",
                        xytext=(0, 2), textcoords="offset points")  # fmt: skip
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel("wall time for one incidence (s)")
        ax.set_ylabel({"geometric": "energy-weighted rel. RMS error",
                       "fullwave": "share of power in the wrong orders"}.get(
                           panel.key, "|energy deviation|"))  # fmt: skip
        ax.set_title(f"{panel.title}\nreference: {panel.reference}", fontsize=8)
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=7, loc="best")
    m = study.machine
    fig.suptitle(
        f"What each method costs: wall time for one incidence on {m.cpus} cores, "
        f"{m.threads} threads, load {m.load_average_start[0]:.2f}, commit "
        f"{(m.commit or '?')[:7]}{' (quick)' if study.quick else ''}",
        fontsize=9,
    )
    fig.tight_layout()
    try:
        with atomic_open(path, "wb") as fh:
            fig.savefig(fh, format="png", dpi=100)
    finally:
        plt.close(fig)


def _num(x, fmt="{:.3g}") -> str:
    return "–" if x is None else fmt.format(x)


def format_methods(study: dict) -> str:
    """A short table: per panel, method, setting, seconds, error ± uncertainty."""
    study = MethodsStudy.from_json(study)
    m = study.machine
    lines = [
        f"methods study{' (quick)' if study.quick else ''}: {m.cpus} CPUs, "
        f"{m.threads} threads, load average {m.load_average_start[0]:.2f} → "
        f"{m.load_average_end[0]:.2f}, commit {(m.commit or '?')[:10]}, "
        f"{study.seconds:.1f} s"
    ]
    for panel in study.panels:
        lines += [
            "",
            f"{panel.title} — reference: {panel.reference}",
            f"error: {panel.error_measure}",
            f"{'method':30s}{'setting':26s}{'seconds':>10s}{'error':>10s}{'± se':>10s}",
        ]
        for p in panel.points:
            lines.append(
                f"{p.method[:29]:30s}{p.setting[:25]:26s}{p.seconds:10.3g}"
                f"{_num(p.error):>10s}{_num(p.error_se):>10s}"
            )
    return "\n".join(lines)


def write_methods(study: dict, out) -> tuple[Path, Path]:
    """Write ``out/methods.json`` and ``out/methods.png``, each atomically (``atomic``)."""
    from ..atomic import write_json

    out = Path(out)
    if out.exists() and not out.is_dir():
        from ..errors import UsageError

        raise UsageError(f"--methods {out}: exists and is not a directory")
    png, js = out / METHODS_PNG, out / METHODS_JSON
    methods_chart(study, png)
    write_json(js, study)
    return js, png


def run_methods_command(args) -> int:
    """``microsim bench --methods [DIR] [--quick] [--json]``: the study, written to
    DIR/methods.json and DIR/methods.png (nothing written if it fails), the table (or the JSON
    with ``--json``) printed. ``--rays`` and ``--skip-accuracy`` belong to the throughput bench
    and are refused here."""
    import json

    from ..errors import UsageError

    if getattr(args, "rays", None) is not None or getattr(args, "skip_accuracy", False):
        raise UsageError(
            "--methods: --rays and --skip-accuracy apply to the throughput bench only; "
            "allowed with --methods: --quick, --json"
        )
    out = Path(args.methods)
    if out.exists() and not out.is_dir():
        raise UsageError(f"--methods {out}: exists and is not a directory")
    study = methods_study(quick=bool(args.quick))
    js, png = write_methods(study, out)
    print(json.dumps(study, indent=1) if args.json else format_methods(study))
    print(f"microsim: wrote {js} and {png}")
    return 0
