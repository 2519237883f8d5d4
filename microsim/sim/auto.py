"""Run a simulation until a requested precision is reached (``rays = "auto"``).

Precision measure (the one the verdicts report as ``rel_rms``, with the model replaced by the
simulation's own noise): over the energy set E — the fewest bins with ≥ ``min_events`` events,
taken by decreasing f̄Ω, carrying ``energy`` (90 %) of Σ f̄Ω (``analysis.verdicts.energy_set``) —

    rse = √( Σ_E f̄Ω (se/f̄)² / Σ_E f̄Ω ),

the energy-weighted relative standard error. If a model m equals the truth, the verdict's
rel_rms² = Σ_E f̄Ω ((m − f̄)/f̄)² / Σ_E f̄Ω has expectation ≈ rse² (each (m − f̄)/f̄ has variance
(se/f̄)²), so "rse ≤ target" is "rel_rms ≈ target at worst against an exact model".

The run is a sequence of independent batches (``simulate`` with seeds derived from ``seed`` and
the batch index), each itself stratified over the tile; their raw sums Σw, Σw², counts and
ledger tallies are added in batch order, which keeps the estimate unbiased. Batches are
independent and each is a whole number of blocks (an even number of rays, so no pair of the
collapsed-strata error straddles two batches): the variance of the pooled mean is the sum of
the batches' pair terms, (Σx² − 2 Σ pairs)/N², i.e. the same ``estimator._estimate`` on the
pooled sums (per-ray formula for ``origins="independent"``). After each batch the number of rays
still needed is predicted from rse ∝ N^(-1/2); batches grow at most 4× per step.
"""
from __future__ import annotations

import time

import numpy as np

from microsim.analytic._checks import in_range, integer
from microsim.analytic.fresnel import resolve_material

from .bins import Bins
from .estimator import (BLOCK, LEDGER, MAX_RAYS, _check_inputs, _check_run_options, _estimate, _is_surface,
                        _surface_error, simulate)
from .result import Result

__all__ = ["simulate_auto", "relative_standard_error", "ENERGY_FRACTION"]

ENERGY_FRACTION = 0.9
MASKED, DOWNWARD = LEDGER.index("masked"), LEDGER.index("downward")


def _energy_set(energy: np.ndarray, fraction: float) -> np.ndarray:
    from microsim.analysis.verdicts import energy_set
    return energy_set(energy, fraction)


def relative_standard_error(brdf, stderr, counts, omega, energy: float = ENERGY_FRACTION,
                            min_events: int = 25) -> float:
    """Energy-weighted relative standard error over the bins carrying ``energy`` of the
    reflected energy (module docstring), dimensionless; inf when no bin qualifies.
    ``brdf``/``stderr`` (Θ, Φ) sr⁻¹, ``counts`` (Θ, Φ) events, ``omega`` (Θ, Φ) sr."""
    f, se, c, om = (np.asarray(a, dtype=np.float64) for a in (brdf, stderr, counts, omega))
    used = (c >= min_events) & (f > 0) & np.isfinite(se)
    e = np.where(used, f * om, 0.0)
    E = _energy_set(e, energy).reshape(f.shape)
    if not E.any():
        return float("inf")
    w = e[E]
    return float(np.sqrt(np.sum(w * (se[E] / f[E]) ** 2) / w.sum()))


def _batch_seed(seed: int, incidence: int, batch: int) -> int:
    """Independent 63-bit stream seed for batch ``batch`` of incidence ``incidence`` of a run
    seeded ``seed``."""
    state = np.random.SeedSequence([int(seed), int(incidence), int(batch)]).generate_state(1, np.uint64)
    return int(state[0] >> np.uint64(1))


class _Sums:
    """Raw tallies of one incidence, added batch by batch (in batch order)."""

    def __init__(self, nbin: int):
        self.n = 0
        self.sum_w, self.sum_w2, self.sum_pair = np.zeros(nbin), np.zeros(nbin), np.zeros(nbin)
        self.pairs = True                      # every batch used the pair estimate
        self.count = np.zeros(nbin, np.int64)
        self.led_n, self.led_f = np.zeros(len(LEDGER), np.int64), np.zeros(len(LEDGER))

    def add(self, res: Result) -> None:
        n = int(res.rays[0])
        self.n += n
        self.sum_w += res.sum_w[0].ravel()
        self.sum_w2 += res.sum_w2[0].ravel()
        self.count += res.counts[0].ravel()
        self.pairs &= (res.meta.get("stderr_method") == "pairs" and res.tallies is not None
                       and "sum_pair" in res.tallies)
        if self.pairs:
            self.sum_pair += res.tallies["sum_pair"][:, 0].sum(axis=0)
        self.led_n += np.array([res.ledger_counts[k][0] for k in LEDGER], dtype=np.int64)
        if res.tallies is not None and "led_f" in res.tallies:
            self.led_f += res.tallies["led_f"][:, 0].sum(axis=0)
        else:                                  # fractions × rays: exact up to rounding
            self.led_f += np.array([res.ledger.get(f"{k}_fresnel", np.zeros(1))[0] * n
                                    for k in LEDGER])

    def estimate(self, omega: np.ndarray):
        """BRDF and standard error (sr⁻¹), flat: collapsed-strata pairs when every batch had
        them, else per-ray (``estimator._estimate``)."""
        return _estimate(self.sum_w, self.sum_w2, self.n, omega,
                         self.sum_pair if self.pairs else None)


def _next_batch(n_done: int, rse: float, target: float, first: int, max_rays: int) -> int:
    """Rays of the next batch: the predicted shortfall (rse ∝ N^-1/2, +5 %), at least one
    block, at most 4× what was done, never beyond ``max_rays``; whole blocks."""
    if np.isfinite(rse) and rse > 0:
        need = n_done * (rse / target) ** 2 * 1.05 - n_done
    else:
        need = 4 * n_done
    n = int(np.clip(need, BLOCK, max(4 * n_done, first)))
    n = -(-n // BLOCK) * BLOCK
    return int(min(n, max_rays - n_done))


def simulate_auto(surface, material, theta_i, target: float = 0.01, *, phi_i=0.0,
                  bins: Bins = Bins(), seed: int = 0, threads: int = 2, chunk: int = 2 ** 16,
                  masking: str = "traced", origins: str = "stratified", first: int = 2 ** 18,
                  max_rays: int = 10 ** 9, energy: float = ENERGY_FRACTION, min_events: int = 25,
                  progress=None) -> Result:
    """``simulate`` with ``rays = "auto"``: trace each incidence until the energy-weighted
    relative standard error over the bins carrying ``energy`` of the reflected energy
    (``relative_standard_error``) is ≤ ``target`` (dimensionless, default 1 %), or until
    ``max_rays`` rays.

    ``theta_i``/``phi_i`` degrees (scalar or sequences), ``first`` rays in the first batch;
    the other arguments as in ``simulate`` (one surface; no realisations). Returns a
    ``Result`` whose ``meta["auto"]`` lists per incidence the rays used, seconds, batches,
    the achieved rse and whether the target was met (``converged``). Every bad argument
    raises a UsageError naming it before any work. ``progress`` receives one text line per
    batch. An interrupt (SIGINT, or ``checkpoints.checkpoint("simulation")`` inside a batch)
    raises KeyboardInterrupt within one chunk of rays (there is no partial result to
    resume); memory does not depend on ``max_rays`` (each batch is scheduled lazily).
    """
    th, ph = _check_inputs(theta_i, phi_i, 1, threads, chunk, masking, seed)
    target = in_range("target", target, 0.0, 1.0, lo_open=True, hi_open=True)
    first = integer("first", first, 1, MAX_RAYS)
    max_rays = integer("max_rays", max_rays, 2, MAX_RAYS, " (rays per incidence at most)")
    energy = in_range("energy", energy, 0.0, 1.0, lo_open=True)
    min_events = integer("min_events", min_events, 0)
    _check_run_options(bins, origins, progress, "one text line")
    if not _is_surface(surface):
        raise _surface_error("surface", surface)
    resolve_material(material)
    omega = bins.projected_solid_angle()
    nbin = omega.size
    first = -(-int(min(first, max_rays)) // BLOCK) * BLOCK
    sums, info, meta0 = [], [], None
    for i, (t_deg, p_deg) in enumerate(zip(th, ph)):
        acc, t0, rse, batch = _Sums(nbin), time.perf_counter(), float("inf"), 0
        n_next = int(min(first, max_rays))
        while n_next > 0:
            res = simulate(surface, material, float(t_deg), phi_i=float(p_deg), rays=n_next,
                           bins=bins, seed=_batch_seed(seed, i, batch), threads=threads,
                           chunk=chunk, masking=masking, origins=origins)
            if res.is_partial:                 # interrupted (SIGINT): batches cannot resume
                raise KeyboardInterrupt
            meta0 = meta0 or res.meta
            acc.add(res)
            batch += 1
            f, se = acc.estimate(omega.ravel())
            rse = relative_standard_error(f.reshape(bins.shape), se.reshape(bins.shape),
                                          acc.count.reshape(bins.shape), omega, energy, min_events)
            if progress is not None:
                progress(f"theta_i = {t_deg:g}°: {acc.n} rays, rse = {rse:.4g} (target {target:g})")
            if rse <= target:
                break
            n_next = _next_batch(acc.n, rse, target, first, int(max_rays))
        sums.append(acc)
        info.append({"theta_i": float(t_deg), "rays": acc.n, "batches": batch,
                     "seconds": time.perf_counter() - t0, "rse": rse,
                     "converged": bool(rse <= target)})
    return _assemble(th, ph, bins, omega, sums, meta0, info, target, energy, seed)


def _assemble(th, ph, bins, omega, sums, meta0, info, target, energy, seed) -> Result:
    shape = (len(th),) + bins.shape
    est = [s.estimate(omega.ravel()) for s in sums]
    n = np.array([s.n for s in sums], dtype=np.int64)
    led_n = np.array([s.led_n for s in sums])
    led_f = np.array([s.led_f for s in sums])
    ledger = {name: led_n[:, k] / n for k, name in enumerate(LEDGER)}
    for k, name in enumerate(LEDGER[:3]):
        ledger[f"{name}_fresnel"] = led_f[:, k] / n
    ledger["lost"] = (led_n[:, MASKED] + led_n[:, DOWNWARD]) / n
    ledger["lost_fresnel"] = (led_f[:, MASKED] + led_f[:, DOWNWARD]) / n
    meta = {k: v for k, v in meta0.items()
            if k not in ("seconds", "rays_per_second", "rays_traced", "partial", "interrupted",
                         "resumed", "seconds_per_realisation", "seconds_scene_build")}
    meta.update(stderr_method="pairs" if all(s.pairs for s in sums) else "per-ray")
    meta.update(seed=int(seed), rays="auto", seconds=float(sum(d["seconds"] for d in info)),
                auto={"target": float(target), "energy": float(energy), "incidences": info})
    return Result(theta_i=th, phi_i=np.array(ph, dtype=np.float64), bins=bins,
                  brdf=np.array([e[0] for e in est]).reshape(shape),
                  stderr=np.array([e[1] for e in est]).reshape(shape), rays=n,
                  ledger=ledger, ledger_counts={name: led_n[:, k] for k, name in enumerate(LEDGER)},
                  counts=np.array([s.count for s in sums]).reshape(shape),
                  sum_w=np.array([s.sum_w for s in sums]).reshape(shape),
                  sum_w2=np.array([s.sum_w2 for s in sums]).reshape(shape), meta=meta)
