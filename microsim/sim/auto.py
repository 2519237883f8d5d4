"""Run a simulation until a requested precision is reached (``rays = "auto"``).

Precision measure (the one the verdicts report as ``rel_rms``, with the model replaced by the
simulation's own noise): over the energy set E — the fewest bins with ≥ ``min_events`` events,
taken by decreasing f̄Ω, carrying ``energy`` (90 %) of Σ f̄Ω (``microsim.stats.energy_set``) —

    rse = √( Σ_E f̄Ω (se/f̄)² / Σ_E f̄Ω ),

the energy-weighted relative standard error. If a model m equals the truth, the verdict's
rel_rms² = Σ_E f̄Ω ((m − f̄)/f̄)² / Σ_E f̄Ω has expectation ≈ rse² (each (m − f̄)/f̄ has variance
(se/f̄)²), so "rse ≤ target" is "rel_rms ≈ target at worst against an exact model".

The run is a sequence of independent batches (``simulate`` with seeds derived from ``seed`` and
the batch index), each itself stratified over the tile; their raw sums Σw, Σw², counts and
ledger tallies are added in batch order, which keeps the estimate unbiased. Batches are
independent and each is a whole number of blocks (an even number of rays, so no pair of the
paired-strata error straddles two batches): the variance of the pooled mean is the sum of
the batches' pair terms, (Σx² − 2 Σ pairs)/N², i.e. the same ``tallies.bin_estimate`` on the
pooled sums (``tallies.Tally``; per-ray formula for ``origins="independent"``). After each
batch the number of rays still needed is predicted from rse ∝ N^(-1/2); batches grow at most
4× per step.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, fields, replace
from functools import partial
from typing import Callable, Mapping

import numpy as np

from microsim.bins import Bins
from microsim.checks import in_range, integer
from microsim.errors import UsageError
from microsim.stats import ENERGY_FRACTION, MIN_EVENTS, energy_set

from .arguments import (
    MAX_RAYS,
    check_progress,
)
from .estimator import Estimator, estimate
from .experiment import Execution, Experiment
from .result import Result
from .streams import BLOCK
from .tallies import Tally, tallies_from_arrays, tally_result

__all__ = [
    "simulate_auto",
    "estimate_to_precision",
    "Precision",
    "AutoRecord",
    "AutoIncidence",
    "relative_standard_error",
    "ENERGY_FRACTION",
]


def relative_standard_error(
    brdf, stderr, counts, omega, energy: float = ENERGY_FRACTION, min_events: int = MIN_EVENTS
) -> float:
    """Energy-weighted relative standard error over the bins carrying ``energy`` of the
    reflected energy (module docstring), dimensionless; inf when no bin qualifies.
    ``brdf``/``stderr`` (Θ, Φ) sr⁻¹, ``counts`` (Θ, Φ) events, ``omega`` (Θ, Φ) sr."""
    f, se, c, om = (np.asarray(a, dtype=np.float64) for a in (brdf, stderr, counts, omega))
    used = (c >= min_events) & (f > 0) & np.isfinite(se)
    e = np.where(used, f * om, 0.0)
    E = energy_set(e, energy).reshape(f.shape)
    if not E.any():
        return float("inf")
    w = e[E]
    return float(np.sqrt(np.sum(w * (se[E] / f[E]) ** 2) / w.sum()))


def _batch_seed(seed: int, incidence: int, batch: int) -> int:
    """Independent 63-bit stream seed for batch ``batch`` of incidence ``incidence`` of a run
    seeded ``seed``."""
    state = np.random.SeedSequence([int(seed), int(incidence), int(batch)]).generate_state(
        1, np.uint64
    )
    return int(state[0] >> np.uint64(1))


class _Batches:
    """The pooled running sums (``tallies.Tally``) of one incidence's batches, added in batch
    order, with their rays and whether every batch used the paired-strata error."""

    def __init__(self, nbin: int):
        self.total, self.rays, self.pairs = Tally.empty(nbin), 0, True

    def add(self, res: Result) -> None:
        """Add a complete one-surface, one-incidence ``simulate`` result."""
        self.total.add_totals(tallies_from_arrays(res.tallies, 1, 1)[0][0])
        self.rays += int(res.rays[0])
        self.pairs &= res.meta["stderr_method"] == "pairs"

    def estimate(self, omega: np.ndarray):
        """BRDF and standard error (sr⁻¹), flat (``Tally.estimate``)."""
        return self.total.estimate(self.rays, omega, "pairs" if self.pairs else "per-ray")


BATCH_GROWTH = 16
"""A batch traces at most this many times the rays already done: the predicted shortfall is
trusted that far (on the V-groove bench scene the first 2¹⁸ rays predict the rays to 1 % within
a few per cent), so a run to 1 % takes 3 batches instead of 4 at a growth of 4."""
BATCH_MARGIN = 1.02
"""The predicted shortfall is traced with this many times the rays (2 % more rays; the
prediction from a batch of 6.5·10⁶ rays was within 0.1 % on the bench scene, and a run that
falls short adds a small batch)."""


def _next_batch(n_done: int, rse: float, target: float, first: int, max_rays: int) -> int:
    """Rays of the next batch: the predicted shortfall (rse ∝ N^-1/2, × ``BATCH_MARGIN``), at
    least one block, at most ``BATCH_GROWTH``× what was done, never beyond ``max_rays``;
    whole blocks."""
    growth = BATCH_GROWTH * n_done
    if np.isfinite(rse) and rse > 0:
        need = n_done * (rse / target) ** 2 * BATCH_MARGIN - n_done
    else:
        need = growth
    n = int(np.clip(need, BLOCK, max(growth, first)))
    n = -(-n // BLOCK) * BLOCK
    return int(min(n, max_rays - n_done))


def simulate_auto(
    surface,
    material,
    theta_i,
    *,
    target: float = 0.01,
    phi_i=0.0,
    bins: Bins = Bins(),
    seed: int = 0,
    threads: int | None = None,
    chunk: int = 2**16,
    masking: str = "traced",
    origins: str = "stratified",
    first: int = 2**18,
    max_rays: int = 10**9,
    energy: float = ENERGY_FRACTION,
    min_events: int = MIN_EVENTS,
    progress=None,
) -> Result:
    """``simulate`` with ``rays = "auto"``: trace each incidence until the energy-weighted
    relative standard error over the bins carrying ``energy`` of the reflected energy
    (``relative_standard_error``) is ≤ ``target`` (dimensionless, default 1 %), or until
    ``max_rays`` rays.

    ``theta_i``/``phi_i`` degrees (scalar or sequences); every option is keyword-only;
    ``first`` rays in the first batch; ``threads`` None means the machine's CPU count; the
    other arguments as in ``simulate`` (one surface; no realisations). Returns a ``Result``
    whose ``meta["auto"]`` lists per incidence the rays used, seconds, batches, the achieved
    rse and whether the target was met (``converged``). Every bad argument raises a
    UsageError naming it before any work. ``progress`` receives one text line per batch. An
    interrupt (SIGINT, or ``checkpoints.checkpoint("simulation")`` inside a batch) raises
    KeyboardInterrupt within one chunk of rays (there is no partial result to resume);
    memory does not depend on ``max_rays`` (each batch is scheduled lazily).
    """
    max_rays = integer("max_rays", max_rays, 2, MAX_RAYS, " (rays per incidence at most)")
    return estimate_to_precision(  # each description checks its own arguments
        Experiment(surface, material, theta_i, phi_i, bins),
        Estimator(max_rays, seed, masking, origins),
        Execution(threads, chunk),
        Precision(target, first, energy, min_events),
        log=progress,
    )


@dataclass(frozen=True)
class Precision:
    """The stopping rule of a ``rays = "auto"`` run: trace until the energy-weighted relative
    standard error over the bins carrying ``energy`` of Σ f̄Ω (bins with ≥ ``min_events``
    events) is ≤ ``target`` (dimensionless, in (0, 1)); ``first`` rays in the first batch."""

    target: float = 0.01
    first: int = 2**18
    energy: float = ENERGY_FRACTION
    min_events: int = MIN_EVENTS

    def __post_init__(self):
        check = partial(object.__setattr__, self)
        check("target", in_range("target", self.target, 0.0, 1.0, lo_open=True, hi_open=True))
        check("first", integer("first", self.first, 1, MAX_RAYS))
        check("energy", in_range("energy", self.energy, 0.0, 1.0, lo_open=True))
        check("min_events", integer("min_events", self.min_events, 0))


def estimate_to_precision(
    experiment: Experiment,
    estimator: Estimator,
    execution: Execution,
    precision: Precision,
    log: Callable[[str], None] | None = None,
) -> Result:
    """Each incidence of ``experiment`` traced in batches (``estimate`` with the batch's rays
    and seed, module docstring) until ``precision`` holds or ``estimator.rays`` rays were
    traced; one surface, single bounce, no azimuth randomisation. ``log`` receives one text
    line per batch. ``execution.progress`` is not called (a batch is not a run to report)."""
    ex, est = experiment, estimator
    if ex.surface_factory is not None or ex.realisations is not None:
        raise UsageError("an auto run traces one surface: realisations must be None")
    if ex.bounces != 1 or est.isotropic:
        raise UsageError("an auto run traces single bounces without isotropic rotation")
    check_progress(log, "one text line")
    bins, max_rays = ex.bins, est.rays
    omega = bins.projected_solid_angle()
    first = -(-int(min(precision.first, max_rays)) // BLOCK) * BLOCK
    batch_run = replace(execution, progress=None)
    runs, info, meta0 = [], [], None
    for i, (t_deg, p_deg) in enumerate(zip(ex.theta_i, ex.phi_i)):
        acc, t0, rse, batch = _Batches(omega.size), time.perf_counter(), float("inf"), 0
        incidence = replace(ex, theta_i=(t_deg,), phi_i=(p_deg,))
        n_next = int(min(first, max_rays))
        while n_next > 0:
            seed = _batch_seed(est.seed, i, batch)
            res = estimate(incidence, replace(est, rays=n_next, seed=seed), batch_run)
            if res.meta["interrupted"]:  # SIGINT, even after the last chunk: no resuming
                raise KeyboardInterrupt
            meta0 = meta0 or res.meta
            acc.add(res)
            batch += 1
            f, se = acc.estimate(omega.ravel())
            rse = relative_standard_error(
                f.reshape(bins.shape),
                se.reshape(bins.shape),
                acc.total.count.reshape(bins.shape),
                omega,
                precision.energy,
                precision.min_events,
            )
            if log is not None:
                log(
                    f"theta_i = {t_deg:g}°: {acc.rays} rays, rse = {rse:.4g} "
                    f"(target {precision.target:g})"
                )
            if rse <= precision.target:
                break
            n_next = _next_batch(acc.rays, rse, precision.target, first, max_rays)
        runs.append(acc)
        info.append(
            {
                "theta_i": float(t_deg),
                "rays": acc.rays,
                "batches": batch,
                "seconds": time.perf_counter() - t0,
                "rse": rse,
                "converged": bool(rse <= precision.target),
            }
        )
    th, ph = np.array(ex.theta_i), np.array(ex.phi_i)
    return _assemble(th, ph, bins, omega, runs, meta0, info, precision, est.seed)


@dataclass(frozen=True)
class AutoIncidence:
    """One incidence of an adaptive run's record (``Result.info.auto``): θi (degrees), the rays
    used, wall seconds, the achieved relative standard error, whether it met the target and
    the batches traced."""

    theta_i: float
    rays: int
    seconds: float
    rse: float
    converged: bool
    batches: int


@dataclass(frozen=True)
class AutoRecord:
    """An adaptive run's record (``Result.info.auto``), typed: the target, the energy share
    its error covers (None if not recorded) and one ``AutoIncidence`` per incidence."""

    target: float
    energy: float | None
    incidences: tuple[AutoIncidence, ...]

    @classmethod
    def of(cls, auto: Mapping | None) -> AutoRecord | None:
        """The typed reading of ``Result.info.auto`` (None for a run that was not adaptive)."""
        if not auto:
            return None
        names = [f.name for f in fields(AutoIncidence)]
        incidences = tuple(
            AutoIncidence(**{k: d.get(k) for k in names}) for d in auto.get("incidences")
        )
        return cls(auto.get("target"), auto.get("energy"), incidences)


def _assemble(th, ph, bins, omega, runs, meta0, info, precision, seed) -> Result:
    """The Result of all incidences from their pooled batches (``tallies.tally_result``;
    no raw tallies: an auto run is not resumable)."""
    est = [r.estimate(omega.ravel()) for r in runs]
    meta = {
        k: v
        for k, v in meta0.items()
        if k
        not in (
            "seconds",
            "rays_per_second",
            "rays_traced",
            "partial",
            "interrupted",
            "resumed",
            "seconds_per_realisation",
            "seconds_scene_build",
        )
    }
    meta.update(stderr_method="pairs" if all(r.pairs for r in runs) else "per-ray")
    meta.update(
        seed=int(seed),
        rays="auto",
        seconds=float(sum(d["seconds"] for d in info)),
        auto={
            "target": float(precision.target),
            "energy": float(precision.energy),
            "incidences": info,
        },
    )
    return tally_result(
        th,
        ph,
        bins,
        [r.total for r in runs],
        np.array([r.rays for r in runs], dtype=np.int64),
        np.array([e[0] for e in est]),
        np.array([e[1] for e in est]),
        meta,
    )
