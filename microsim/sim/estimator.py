"""The estimator: its frozen description ``Estimator`` and ``estimate``, which runs it — the
ray-traced BRDF of Mikkelsen 2009, eq. 9 (``simulate``, its keyword form) — and ``ray_events``.

Parallel primary rays from wi fall on the periodic surface from origins spread uniformly over
one tile; each is followed to its first hit, Fresnel weight, mirror direction and masking
test, and tallied in the (θo, Δφ) bin of its outgoing direction. The bin average of eq. 9 is
f̄_B = Σ_rays w / (N Ω_B) in sr⁻¹, with a paired-strata standard error. The work is split
into modules with one job each:

- ``streams``  per-block random streams and ray origins (reproducibility, stratification);
- ``paths``    the trace paths (traced, facet table, exact and analytic V-groove masking), one
  interface chosen once per (surface, masking, incidence); the ledger classes;
- ``bounces``  the paths followed beyond the first bounce (``bounces`` = K > 1 or "all"):
  scattering orders, their tally slots and the paths' energy ledger;
- ``tallies``  running sums per block, the bin estimate and its standard error, the Result;
- ``schedule`` the thread pool, lazy in-order scheduling, deferred SIGINT;
- ``arguments`` checking every argument before any work;
- ``identity``  the run's identity (``RunDescription``), which a resumed run must share;
- this module: ``Estimator`` and the driver (``estimate``: memory check, realisations,
  resume, interrupt, progress, run meta) and ``ray_events`` (per-ray outcomes for diagnostics).

Reproducibility: the rays of (realisation r, incidence i) are cut into fixed blocks of
``BLOCK`` rays, each drawing from its own slot of the stream (seed, r, i) and tallied on its
own; block tallies are summed in block order. So results are bitwise identical for any
``threads``/``chunk``, and an interrupted run keeps its exact running sums and block counts
(``Result.tallies``): ``simulate(resume=...)`` continues with the next block.
"""

from __future__ import annotations

import platform
import time
from dataclasses import dataclass
from importlib.metadata import PackageNotFoundError, version
from typing import Callable, NamedTuple

import numpy as np

from microsim.analytic.fresnel import resolve_material
from microsim.bins import Bins
from microsim.checkpoints import checkpoint
from microsim.checks import check_memory, integer
from microsim.errors import UsageError
from microsim.vectors import spherical_deg

from .arguments import (
    CHUNK,
    MAX_CHUNK,
    MAX_RAYS,
    MAX_THREADS,
    check_choice,
    check_inputs,
    check_masking_bounces,
    is_surface,
    surface_error,
)
from .bounces import MAX_BOUNCES, WEIGHT_FLOOR, chain_task, ledger_classes, order_slots
from .cluster import ClusterPool, RemoteSurface, SchedulerLost, tracer_info
from .dielectric import interface_task
from .events import Events, trace_events
from .experiment import Execution, Experiment, normalise
from .identity import RunDescription, saved_identity
from .paths import LEDGER, MASKING, Incidence
from .progress import RaysDone
from .result import Result
from .schedule import (
    IN_FLIGHT,
    DeferredInterrupt,
    chunk_groups,
    run_in_order,
    set_up_pool,
    thread_pool,
)
from .spectral import (
    SpectralResult,
    SpectralTally,
    Spectrum,
    check_spectral_run,
    check_task_memory,
    spectral_task,
)
from .streams import BLOCK, DESIGN, ORIGINS, block_origins
from .tallies import TALLY_NAMES, Tally, simulation_result, tallies_from_arrays
from .tracer_cache import tracer_for

__all__ = [
    "Estimator",
    "estimate",
    "simulate",
    "estimate_spectral",
    "simulate_spectral",
    "ray_events",
    "Events",
    "BLOCK",
    "LEDGER",
    "MASKING",
    "ORIGINS",
    "MAX_RAYS",
    "MAX_THREADS",
    "MAX_CHUNK",
]

EVENT_BYTES = 65
"""Bytes per ray of ``Events``: status 1, weight 8, wo 24, normal 24, margin 8."""
BIN_BYTES_TALLY = 72
"""Bytes per bin per (realisation, incidence): the running sums Σw, Σw², Σpairs, counts
(32 B), their copies in ``Result.tallies`` (32 B) and the per-realisation BRDF (8 B)."""
BIN_BYTES_INCIDENCE = 96
"""Bytes per bin per incidence in the Result: brdf, stderr, counts, sums, pooled tally (≈12
float64 arrays)."""
BIN_BYTES_THREAD = 32
"""Bytes per bin per running thread task: its scratch sums and touched flags."""


@dataclass(frozen=True)
class Estimator:
    """The estimator of one run: ``rays`` primary rays per incidence in [1, ``MAX_RAYS``]
    (spread over the realisations); ``seed`` ≥ 0, the random stream (results are a function
    of it alone); ``masking``: "traced" (Embree, the reference), "exact" or "analytic"
    (V-groove surfaces only, ``paths``); ``origins``: "stratified" or "independent"
    (``streams.chunk_origins``); ``isotropic``: rotate each block's incidence azimuth by its
    own uniform angle (statistically isotropic surfaces only, ``paths.RotatedIncidencePath``),
    each block a sweep of the whole tile by itself, so the blocks are independent replicates
    and the standard error comes from their scatter (``stderr_method``).
    """

    rays: int = 1_000_000
    seed: int = 0
    masking: str = "traced"
    origins: str = "stratified"
    isotropic: bool = False

    def __post_init__(self):
        normalise(
            self, "rays", integer("rays", self.rays, 1, MAX_RAYS, " (primary rays per incidence)")
        )
        normalise(self, "seed", integer("seed", self.seed, 0, None, " (the random stream)"))
        check_choice("masking", self.masking, MASKING)
        check_choice("origins", self.origins, ORIGINS)
        if not isinstance(self.isotropic, (bool, np.bool_)):
            raise UsageError(f"isotropic must be True or False, got {self.isotropic!r}")
        normalise(self, "isotropic", bool(self.isotropic))

    @property
    def stderr_method(self) -> str:
        """One of ``tallies.STDERR_METHODS``: "blocks" for ``isotropic`` runs (every block an
        independent replicate: its own sweep of the tile, its own incidence azimuth), else
        "pairs" (paired strata) for stratified origins, "per-ray" for independent ones."""
        if self.isotropic:
            return "blocks"
        return "pairs" if self.origins == "stratified" else "per-ray"


def simulate(
    surface,
    material,
    theta_i,
    *,
    phi_i=0.0,
    rays: int = 1_000_000,
    bins: Bins = Bins(),
    seed: int = 0,
    threads: int | None = None,
    chunk: int = CHUNK,
    masking: str = "traced",
    realisations=None,
    surface_factory: Callable[[int], object] | None = None,
    seeds=None,
    origins: str = "stratified",
    isotropic: bool = False,
    progress: Callable[[RaysDone], None] | None = None,
    resume: Result | None = None,
    bounces: int | str = 1,
    transmission: bool = False,
) -> Result:
    """Bin-averaged single-bounce BRDF of ``surface`` by ray tracing (Mikkelsen 2009, eq. 9).

    ``surface``: a ``microsim.surfaces.Surface`` (None when ``realisations`` lists the
    surfaces or ``surface_factory`` builds them). ``material``: name, index n / n+ik or None
    (mirror), see ``resolve_material``. ``theta_i``: incidence polar angle(s) in degrees, each
    in [0, 90). Every other argument is keyword-only: ``phi_i`` azimuth(s) in degrees (scalar
    or one per θi). ``rays``: primary rays per incidence (spread over the realisations).
    ``bins``: outgoing (θo, Δφ) grid. ``seed``: random stream; results are bitwise identical
    for any ``threads`` (worker threads; None: the machine's CPU count) and ``chunk`` (rays
    per thread task, rounded to whole ``BLOCK``s, at most ``MAX_CHUNK``; smaller when needed
    to give every thread a task). ``progress``: optional callback, called in the calling
    thread after every chunk is tallied with a ``RaysDone`` event (the rays that chunk added
    to its (realisation, incidence); the events of a pair sum to its rays and the last has
    ``finished=True``). Integers: ``rays`` in [1, ``MAX_RAYS``], ``threads`` in
    [1, ``MAX_THREADS``], ``seed`` ≥ 0; every bad argument raises a ``UsageError`` naming it,
    before any work. Memory does not grow with ``rays``: chunks are scheduled lazily, at most
    ``IN_FLIGHT``·threads at a time; the per-bin tallies are checked against the memory limit
    up front (``BIN_BYTES_*``, ``microsim.checks.check_memory``).

    ``masking``: "traced" (Embree, the reference), "exact" (Embree primary hit, float64
    V-groove masking test) or "analytic" (primary hit and masking both exact in float64, no
    Embree: ``VGrooveCaster``; the fast path) — the last two only for ``azimuth_average``
    V-groove surfaces (``paths``).

    Realisations (independent random surfaces; the BRDF pools them and ``stderr`` combines
    ray noise with realisation-to-realisation scatter; realisation r traces its share of
    ``rays`` with the stream (seed, r, i)):
    ``realisations`` = a list of surfaces (``surface`` None or the list's first), or a count
    n with ``surface_factory``. ``surface_factory``: a callable(seed) -> Surface (``surface``
    None), called lazily for one realisation at a time with each of ``seeds`` (a sequence of
    integers ≥ 0), or, without ``seeds``, with ``seed``, ``seed`` + 1, …, ``seed`` + n − 1
    (n = ``realisations``, default 1).

    ``origins``: "stratified" (jittered strata over the tile, the default) or "independent"
    (i.i.d. uniform origins, sorted spatially per block) — see ``streams.chunk_origins``.
    ``isotropic``: rotate the incidence azimuth of every block by its own uniform ψ_b (bins
    taken relative to φi + ψ_b; ``paths.RotatedIncidencePath``). Valid only for statistically
    isotropic surfaces (e.g. Gaussian or ABC heightfields with isotropic spectra): the expected
    BRDF is then unchanged and one tile is averaged over incident azimuths; it has no effect
    on ``azimuth_average`` surfaces (V-grooves, already azimuth-averaged per ray). Refused
    (``UsageError``) on an anisotropic surface (``Surface.anisotropy``: oriented V-grooves,
    two correlation lengths, gratings), whose BRDF depends on the incidence azimuth. Off by
    default.

    Standard error (``tallies.bin_estimate``): stratified origins use the paired-strata
    estimate (rays 2k, 2k+1 are two independent samples of one stratum: unbiased);
    ``origins="independent"`` uses the per-ray formula; ``isotropic=True`` makes every block
    an independent replicate (a stratified sweep of the whole tile by itself, with its own
    azimuth ψ_b) and takes the error from the scatter between the blocks, which includes the
    azimuth-to-azimuth scatter of the one surface (NaN below two blocks).
    ``meta["stderr_method"]`` records which ("pairs", "per-ray" or "blocks").

    Interrupt and resume. A KeyboardInterrupt (SIGINT, or raised by ``progress``, by
    ``microsim.checkpoints.checkpoint("simulation")`` — called after every chunk, after
    ``progress`` — or by ``surface_factory``) stops the run after the chunk in flight (within
    one thread task, well under a second at the default ``chunk``, whatever ``rays``) and
    *returns* a Result with ``meta["partial"] = True`` holding every complete block
    (``Result.rays`` counts them; incidences not started have 0 rays and NaN estimates).
    ``meta["interrupted"]`` says that a SIGINT came, also one that came after the last chunk
    was tallied (the Result then complete): a caller that must stop checks it.
    ``resume=<that Result>`` (same surface(s), material, θi, φi, bins, seed, rays, masking,
    origins, isotropic; else a UsageError naming what differs) continues from the first block
    not yet done; the final tallies are bitwise identical to an uninterrupted run, because
    blocks are seeded by index and the raw running sums (``Result.tallies``) are stored
    exactly. ``resume`` may also be a run of the first k < R of this run's realisations
    with the same rays per realisation (and everything else the same): its k realisations
    are kept, the others traced — bitwise the run of R realisations (how the runner extends
    the pilot of ``realisations = "auto"`` without tracing it again). Returns a ``Result``
    (BRDF in sr⁻¹).

    ``bounces``: 1 (the default: single scattering, the paths above, results as before) or
    an int K in [2, ``bounces.MAX_BOUNCES``] or "all": each path goes on after a facet hit
    whose reflected ray meets the surface again (masked or downward), with the Fresnel
    weight of every bounce, up to K bounces ("all": until it escapes or its weight falls
    below ``bounces.WEIGHT_FLOOR``, at most ``MAX_BOUNCES`` bounces); module ``bounces``.
    The Result then holds the BRDF per scattering order (1, 2, 3, ≥ 4:
    ``Result.brdf_orders``/``stderr_orders``), the paths' energy ledger (escaped per order,
    absorbed, cut off) and ``meta["bounces"]``; ``brdf`` stays the order-1 BRDF. Traced
    masking (Embree) or ``masking="analytic"`` (V-grooves, exact float64 chain);
    ``masking="exact"`` is refused with K > 1. ``resume`` must match ``bounces`` too.

    ``transmission``: False (the default: the medium keeps what it refracts, results as
    before) or True: ``material`` is a dielectric medium below the surface (a real index n;
    n + ik, k > 0, an absorbing one) and every hit reflects or refracts (module
    ``dielectric``: Russian roulette on the exact Fresnel factor, total internal reflection
    included); θi may then also lie in (90, 180] (light from inside the medium). The Result
    adds ``btdf_orders``/``stderr_btdf_orders`` (the light leaving on the other side),
    ``brdf_orders`` holding the light leaving on the incidence's side, O = ``order_slots``
    slots also for ``bounces=1``, and the ledger's transmitted and total-internal-reflection
    columns; ``meta["transmission"]`` is True. Traced masking only; not on a cluster.
    """
    return estimate(
        Experiment(
            surface,
            material,
            theta_i,
            phi_i,
            bins,
            bounces,
            realisations=realisations,
            surface_factory=surface_factory,
            seeds=seeds,
            transmission=transmission,
        ),
        Estimator(rays, seed, masking, origins, isotropic),
        Execution(threads, chunk, progress),
        resume=resume,
    )


def simulate_spectral(
    surface,
    material,
    theta_i,
    *,
    wavelengths_nm=None,
    phi_i=0.0,
    rays: int = 1_000_000,
    bins: Bins = Bins(),
    seed: int = 0,
    threads: int | None = None,
    chunk: int = CHUNK,
    masking: str = "traced",
    realisations=None,
    surface_factory: Callable[[int], object] | None = None,
    seeds=None,
    origins: str = "stratified",
    isotropic: bool = False,
    progress: Callable[[RaysDone], None] | None = None,
    bounces: int | str = 1,
    transmission: bool = False,
) -> SpectralResult:
    """``simulate`` for W materials at once: every path's geometry traced once, each
    material's Fresnel factors applied to it (module ``spectral``). Returns a
    ``SpectralResult``: one ``Result`` per material, each bitwise the Result of ``simulate``
    with that material and the same arguments, and the wavelengths.

    ``material`` with ``wavelengths_nm``: a material of ``materials.TABLE`` (e.g. "gold") at
    each of the wavelengths (nm, inside its dataset's range; ``Result.meta["material"]``
    holds the name, index and ``wavelength_nm``). Without ``wavelengths_nm``: a list of
    materials, each as ``simulate`` takes one (a name, n / n+ik, ("gold", 550), None).
    Every other argument is ``simulate``'s. ``bounces``: 1, K or "all" — with "all" each
    material's path is cut where its own weight falls below ``bounces.WEIGHT_FLOOR`` (the
    geometry goes on while any material's weight is above it). Refused (a UsageError naming
    the argument, before any work): an empty list or a wavelength outside the table's range,
    ``transmission=True``, ``masking="analytic"`` with ``bounces`` > 1. There is no
    ``resume``: an interrupted spectral run returns its complete blocks (every Result
    ``meta["partial"]``), and each Result can resume a ``simulate`` run of its material."""
    spectrum = Spectrum.of(material, wavelengths_nm)
    return estimate_spectral(
        Experiment(
            surface,
            spectrum.materials[0],
            theta_i,
            phi_i,
            bins,
            bounces,
            realisations=realisations,
            surface_factory=surface_factory,
            seeds=seeds,
            transmission=transmission,
        ),
        spectrum,
        Estimator(rays, seed, masking, origins, isotropic),
        Execution(threads, chunk, progress),
    )


def estimate_spectral(
    experiment: Experiment,
    spectrum: Spectrum,
    estimator: Estimator = Estimator(),
    execution: Execution = Execution(),
) -> SpectralResult:
    """``estimate`` of ``experiment`` for each material of ``spectrum`` (its own material is
    not used), the geometry traced once (module ``spectral``; ``simulate_spectral`` is the
    keyword form and documents the rest)."""
    _check_descriptions(experiment=experiment, estimator=estimator, execution=execution)
    if not isinstance(spectrum, Spectrum):
        raise UsageError(
            f"spectrum must be a microsim.sim.spectral.Spectrum (Spectrum.of(material, "
            f"wavelengths_nm)), got {type(spectrum).__name__}"
        )
    ex, est, run = experiment, estimator, execution
    check_spectral_run(ex.transmission, est.masking, ex.bounces, run.cluster)
    check_task_memory(len(spectrum.iors), run.chunk, run.threads)
    results = _run(ex, est, run, None, spectrum)
    return SpectralResult(results, spectrum.wavelengths_nm)


class _Plan(NamedTuple):
    """What ``estimate`` derives from its descriptions before any work: realisations (count,
    lazy getter, rays of each), bins and tally slots, blocks per realisation, blocks per
    thread task, and the description a resumed run must share."""

    n_real: int
    get_surface: Callable[[int], object]
    per_real: list
    nbin: int
    slots: int | None
    nblk: np.ndarray
    chunk_blocks: int
    description: RunDescription
    material: dict | list
    spectrum: Spectrum | None


class _State(NamedTuple):
    """The run's running state, updated in place in the calling thread: ``tallies[r][i]``,
    blocks ``done`` (R, T), each realisation's surface meta."""

    tallies: list
    done: np.ndarray
    surfaces: list


def estimate(
    experiment: Experiment,
    estimator: Estimator = Estimator(),
    execution: Execution = Execution(),
    *,
    resume: Result | None = None,
) -> Result:
    """Bin-averaged BRDF of ``experiment`` by ``estimator`` (Mikkelsen 2009, eq. 9), run as
    ``execution`` says; ``resume``: a partial Result of the same experiment and estimator to
    continue (``simulate`` documents every field, the interrupt and the resume). Returns a
    ``Result`` (BRDF in sr⁻¹). Each description must be of its class (a ``UsageError``
    names the argument otherwise, e.g. when they are passed in another order). On a cluster
    whose scheduler is lost mid-run it raises ``SchedulerLost`` (an ``EnvironmentFailure``)
    holding the partial Result to resume."""
    _check_descriptions(experiment=experiment, estimator=estimator, execution=execution)
    return _run(experiment, estimator, execution, resume)[0]


def _run(
    ex: Experiment,
    est: Estimator,
    run: Execution,
    resume: Result | None,
    spectrum: Spectrum | None = None,
) -> list:
    """``estimate``'s work for checked descriptions: its Result, in a list; with a
    ``spectrum``, one Result per material (``spectral``)."""
    check_masking_bounces(est.masking, ex.bounces)
    _check_transmission_run(ex, est, run)
    plan = _plan(ex, est, run, spectrum)
    state = _start(plan, ex, resume)
    done_before = state.done.copy()
    cluster = _cluster_meta(run.cluster) if run.cluster is not None else None
    t_all = time.perf_counter()
    timings, build, interrupted, lost = _trace(plan, state, ex, est, run)
    elapsed = time.perf_counter() - t_all
    per_real = np.array(plan.per_real)[:, None]
    n_done = np.minimum(state.done * BLOCK, per_real)
    traced = int(n_done.sum() - np.minimum(done_before * BLOCK, per_real).sum())
    meta = {
        "surface": state.surfaces[0],
        "realisations": state.surfaces if plan.n_real > 1 else None,
        "material": plan.material,
        "seed": est.seed,
        "rays": est.rays,
        "masking": est.masking,
        "origins": est.origins,
        "isotropic": est.isotropic,
        "stderr_method": est.stderr_method,
        "partial": bool(np.any(state.done < plan.nblk[:, None])),
        "interrupted": interrupted,
        "resumed": resume is not None,
        "threads": run.threads,
        "chunk_blocks": plan.chunk_blocks,
        "block": BLOCK,
        "design": DESIGN,
        "versions": _versions(),
        "seconds": elapsed,
        "seconds_scene_build": build,
        "seconds_per_realisation": timings,
        "rays_traced": traced,
        "rays_per_second": traced / (elapsed - build) if elapsed > build and traced else None,
    }
    if cluster is not None:  # absent: local threads (``threads``)
        meta["cluster"] = cluster
    if lost is not None:  # absent: the scheduler stayed
        meta["scheduler_lost"] = lost.address
    if ex.bounces != 1:  # absent: 1 (single-bounce results keep their meta)
        meta["bounces"] = ex.bounces
        meta["max_bounces"] = MAX_BOUNCES
        meta["weight_floor"] = WEIGHT_FLOOR if ex.bounces == "all" else 0.0
    if ex.transmission:  # absent: False (results without transmission keep their meta)
        meta["transmission"] = True
    th, ph = np.array(ex.theta_i), np.array(ex.phi_i)
    results = [
        simulation_result(
            th, ph, ex.bins, tallies, n_done, plan.per_real, state.done, meta_j, plan.slots
        )
        for tallies, meta_j in _by_material(plan, state, meta)
    ]
    if lost is not None:
        lost.partial = results[0]
        raise lost
    return results


def _by_material(plan: _Plan, state: _State, meta: dict) -> list:
    """(running sums [r][i], meta) of each Result: the run's own, or one per material of a
    spectral run (its material record, and ``spectral``: how many materials were traced
    together)."""
    spectrum = plan.spectrum
    if spectrum is None:
        return [(state.tallies, meta)]
    return [
        (
            [[t.tallies[j] for t in row] for row in state.tallies],
            {**meta, "material": spectrum.material_meta(j, record), "spectral": len(plan.material)},
        )
        for j, record in enumerate(plan.material)
    ]


def _check_descriptions(**given) -> None:
    """A UsageError naming the first of ``estimate``'s descriptions (experiment, estimator,
    execution) that is not of its class, with the class it got and the order expected."""
    for (name, value), kind in zip(given.items(), (Experiment, Estimator, Execution)):
        if not isinstance(value, kind):
            raise UsageError(
                f"{name} must be a microsim.sim.{kind.__name__}, got "
                f"{type(value).__module__}.{type(value).__qualname__} (the arguments are "
                f"estimate(Experiment, Estimator, Execution), in this order)"
            )


def _check_transmission_run(ex: Experiment, est: Estimator, run: Execution) -> None:
    """UsageError for transmission with a masking other than "traced" or on a cluster."""
    if not ex.transmission:
        return
    if est.masking != "traced":
        raise UsageError(
            f"transmission=True traces every path through the interface with Embree: "
            f"masking must be 'traced', got {est.masking!r}"
        )
    if run.cluster is not None:
        raise UsageError("transmission=True runs on local threads only: pass cluster=None")


def _plan(ex: Experiment, est: Estimator, run: Execution, spectrum: Spectrum | None) -> _Plan:
    """The run's realisations, tally slots and blocks; the tallies' memory (one set per
    material of a ``spectrum``) checked up front (``BIN_BYTES_*``); the material records
    (one per material of a ``spectrum``)."""
    n_real, get_surface = ex.surfaces(est.seed)
    per_real = [est.rays // n_real + (r < est.rays % n_real) for r in range(n_real)]
    if min(per_real) < 1:
        raise UsageError(f"rays must be >= the number of realisations ({n_real}), got {est.rays}")
    slots = None if ex.bounces == 1 else order_slots(ex.bounces)
    if ex.transmission:  # reflected and transmitted order slots
        slots = 2 * order_slots(ex.bounces)
    nbin = ex.bins.shape[0] * ex.bins.shape[1]
    nslot, n_th = nbin * (slots or 1), len(ex.theta_i)  # tally slots: bins, or orders × bins
    n_mat = 1 if spectrum is None else len(spectrum.iors)
    check_memory(
        "bins",
        n_mat
        * nslot
        * (
            BIN_BYTES_TALLY * n_real * n_th
            + BIN_BYTES_INCIDENCE * n_th
            + BIN_BYTES_THREAD * run.threads
        ),
        f"the tallies of {nbin:,} bins × {slots or 1} orders × {n_th} incidences × "
        f"{n_real} realisations" + ("" if spectrum is None else f" × {n_mat} materials"),
    )
    if spectrum is None:
        material = _json_material(ex.material, ex.ior)
    else:
        material = [_json_material(m, i) for m, i in zip(spectrum.materials, spectrum.iors)]
    description = RunDescription.of(ex, est, n_real)
    nblk = np.array([-(-n // BLOCK) for n in per_real], dtype=np.int64)
    chunk_blocks = max(1, int(round(run.chunk / BLOCK)))
    return _Plan(
        n_real, get_surface, per_real, nbin, slots, nblk, chunk_blocks, description, material,
        spectrum,
    )  # fmt: skip


def _start(plan: _Plan, ex: Experiment, resume: Result | None) -> _State:
    """Empty tallies, or those of ``resume`` (plus empty ones for realisations it lacks)."""
    n_th, nslot = len(ex.theta_i), plan.nbin * (plan.slots or 1)
    classes = ledger_classes(ex.bounces, ex.transmission)
    if resume is None:
        tallies, done, metas = [], np.zeros((0, n_th), dtype=np.int64), []
    else:
        tallies, done, metas = _resume_state(resume, plan.description, n_th)
    extra = plan.n_real - len(tallies)  # realisations not started
    if plan.spectrum is None:
        empty = lambda: Tally.empty(nslot, classes)  # noqa: E731
    else:
        empty = lambda: SpectralTally(len(plan.spectrum.iors), nslot, classes)  # noqa: E731
    tallies += [[empty() for _ in range(n_th)] for _ in range(extra)]
    done = np.vstack([done, np.zeros((extra, n_th), dtype=np.int64)])
    return _State(tallies, done, metas + [None] * extra)


def _trace(plan: _Plan, state: _State, ex: Experiment, est: Estimator, run: Execution):
    """Trace every block not yet done, realisation by realisation, incidence by incidence;
    (seconds per realisation, seconds building surfaces and tracers, interrupted, the
    ``SchedulerLost`` that stopped a cluster run or None)."""
    timings, build, interrupted, lost = [], 0.0, False, None
    pool = ClusterPool(run.cluster) if run.cluster is not None else thread_pool(run.threads)
    with DeferredInterrupt() as stop:
        try:
            for r in range(plan.n_real):
                if np.all(state.done[r] >= plan.nblk[r]):
                    continue
                t0 = time.perf_counter()
                surf = plan.get_surface(r)
                _check_azimuth_average(surf, est)
                smeta = _surface_meta(surf)
                _check_same_surface(state.surfaces[r], smeta, r)
                prepared, info = _prepare(surf, smeta["fingerprint"], plan, est, run)
                build += time.perf_counter() - t0
                state.surfaces[r] = {**smeta, **info}
                try:
                    for i in range(len(ex.theta_i)):
                        if stop.is_set():  # SIGINT while building the surface
                            raise KeyboardInterrupt
                        _trace_incidence(plan, state, ex, est, run, prepared, r, i, pool, stop)
                finally:
                    if isinstance(prepared, RemoteSurface):
                        prepared.release()
                timings.append(time.perf_counter() - t0)
                del prepared
        except KeyboardInterrupt:
            interrupted = True
        except SchedulerLost as e:  # stops the run as an interrupt does; ``estimate`` raises it
            lost = e
        interrupted = interrupted or stop.is_set()  # SIGINT after the last chunk's check
    return timings, build, interrupted, lost


def _check_azimuth_average(surface, est: Estimator) -> None:
    """``isotropic=True`` averages over the incidence azimuth: a UsageError on an anisotropic
    surface (``Surface.anisotropy``), whose BRDF depends on that azimuth."""
    what = getattr(surface, "anisotropy", None) if est.isotropic else None
    if what is not None:
        raise UsageError(
            f"isotropic=True averages the BRDF over the incidence azimuth, but the surface is "
            f"anisotropic ({what}): its BRDF depends on that azimuth, so the average answers "
            f"another question; pass isotropic=False and choose the azimuths with phi_i"
        )


def _prepare(surf, fingerprint: str, plan: _Plan, est: Estimator, run: Execution):
    """(prepared tracer, its meta) of one realisation: ``tracer_for``'s triple, or the
    ``RemoteSurface`` scattered to ``run.cluster``."""
    if run.cluster is not None:
        remote = RemoteSurface(run.cluster, surf, est.masking, fingerprint)
        return remote, remote.info
    # one surface: keep its tracer for the next call (``tracer_for``); several: each
    # realisation's tracer is released once it is traced
    prepared = tracer_for(surf, est.masking, fingerprint if plan.n_real == 1 else None)
    return prepared, tracer_info(prepared[0])


def _trace_incidence(plan, state, ex, est, run, prepared, r, i, pool, stop) -> None:
    """Trace the blocks of (realisation ``r``, incidence ``i``) not yet done on ``pool`` and
    tally them in block order in the calling thread, reporting each chunk to ``progress``."""
    start, end = int(state.done[r, i]), int(plan.nblk[r])
    if start >= end:
        return
    t_deg, p_deg = ex.theta_i[i], ex.phi_i[i]
    key = (est.seed, r, i)
    if isinstance(prepared, RemoteSurface):
        task = prepared.chunks(
            t_deg, p_deg, ex.bins, ex.ior, plan.per_real[r], key, est.origins,
            est.isotropic, ex.bounces,
        )  # fmt: skip
        threads, depth, blocks = pool.threads, pool.depth, max(plan.chunk_blocks, pool.min_blocks)
    else:
        tracer, profile, azimuth = prepared
        incidence = Incidence(
            tracer,
            spherical_deg(t_deg, p_deg),
            p_deg,
            ex.bins,
            ex.ior,
            plan.per_real[r],
            key,
            est.origins,
            est.isotropic,
        )
        if plan.spectrum is not None:  # the geometry once, weighted per material
            task = spectral_task(
                incidence, profile, azimuth, est.isotropic, ex.bounces, plan.spectrum,
                *set_up_pool(),
            )  # fmt: skip
        elif ex.transmission:  # paths through a dielectric interface
            task = interface_task(incidence, azimuth, est.isotropic, ex.bounces)
        else:  # one chain, cut after ex.bounces bounces (single bounce: its first)
            task = chain_task(
                incidence, profile, azimuth, est.isotropic, ex.bounces, *set_up_pool()
            )
        threads, depth, blocks = run.threads, IN_FLIGHT * run.threads, plan.chunk_blocks
    rays, done, tally_ri = plan.per_real[r], state.done, state.tallies[r][i]

    def tally(chunk):
        """Add one chunk (calling thread, block order), then report it."""
        before = min(int(done[r, i]) * BLOCK, rays)
        done[r, i] += tally_ri.add_chunk(chunk)
        after = min(int(done[r, i]) * BLOCK, rays)
        if run.progress is not None:
            run.progress(
                RaysDone(
                    realisation=r,
                    realisations=plan.n_real,
                    incidence=i,
                    theta_i=float(t_deg),
                    rays=after - before,
                    finished=bool(done[r, i] >= plan.nblk[r]),
                )
            )
        checkpoint("simulation")

    run_in_order(
        pool,
        task,
        chunk_groups(start, end, blocks, threads),
        depth,
        stop,
        tally,
    )


def ray_events(
    surface,
    material,
    theta_i: float,
    *,
    phi_i: float = 0.0,
    rays: int = 100_000,
    seed: int = 0,
    masking: str = "traced",
) -> Events:
    """Per-ray outcomes of ``rays`` primary rays at one incidence (degrees), global frame.

    Same ray stream as ``simulate(surface, material, theta_i, ...)`` (realisation 0,
    incidence 0, stratified origins); for diagnostics and tests (paired comparisons of
    masking modes). Options are keyword-only; one thread. The output is per ray
    (``EVENT_BYTES`` each): ray counts whose events exceed the memory limit are refused
    (``microsim.checks.check_memory``).
    """
    th, ph = check_inputs(theta_i, phi_i, rays, 1, masking, seed)
    if th.size != 1:
        raise UsageError(f"theta_i must be a single incidence in degrees, got {theta_i!r}")
    if not is_surface(surface):
        raise surface_error("surface", surface)
    check_memory(
        "rays",
        2 * EVENT_BYTES * int(rays),
        f"ray_events of {int(rays):,} rays "
        f"({EVENT_BYTES} bytes per ray, twice while concatenating)",
    )
    ior = resolve_material(material)
    tracer, profile, azimuth = tracer_for(surface, masking)
    wi = spherical_deg(th[0], ph[0])
    blocks = []
    for b in range(-(-int(rays) // BLOCK)):  # block by block, as in simulate
        origins, psi = block_origins(tracer, int(rays), b, (int(seed), 0, 0), azimuth)
        blocks.append(trace_events(tracer, profile, wi, origins, psi, ior, azimuth))
    return Events(
        *(
            np.concatenate([getattr(e, f) for e in blocks])
            for f in ("status", "weight", "wo", "normal", "margin")
        )
    )


# --- run description and resume ------------------------------------------------------------
def _cluster_meta(client) -> dict:
    """Workers and threads of the cluster that traces (asked before the run: a lost
    scheduler cannot say afterwards)."""
    nthreads = client.nthreads()
    return {"workers": len(nthreads), "threads": int(sum(nthreads.values()))}


def _surface_meta(surface) -> dict:
    """JSON-able description of a traced surface (its own warnings plus the tracer's)."""
    warnings = list(getattr(surface, "warnings", ()))
    if not surface.periodic:
        warnings.append(
            "the tile was traced as periodic although surface.periodic is False: "
            "its seams act as steps"
        )
    zmin, zmax = surface.z_range
    return {
        "kind": surface.kind,
        "fingerprint": surface.fingerprint(),
        "nominal": dict(surface.nominal),
        "tile_size": [float(t) for t in surface.tile_size],
        "triangles": int(surface.facet_count),
        "z_range": [zmin, zmax],
        "periodic": bool(surface.periodic),
        "warnings": warnings,
    }


def _json_material(material, ior) -> dict:
    """The material as meta records it: its name (if given by name) and ior [n, k] (None for
    a mirror)."""
    name = material if isinstance(material, str) else None
    if ior is None:
        return {"name": name or "mirror", "ior": None}
    c = complex(ior)
    return {"name": name, "ior": [c.real, c.imag]}


def _versions() -> dict:
    """Versions of what the numbers depend on: NumPy, Python, embreex."""
    try:
        embree = version("embreex")
    except PackageNotFoundError:
        embree = None
    return {"numpy": np.__version__, "python": platform.python_version(), "embreex": embree}


def _resume_state(resume, description: RunDescription, n_th: int):
    """Running sums, blocks done (R, T) and surface metas restored from a partial ``Result``
    of the run ``description`` (its identity read by ``identity.saved_identity``)."""
    if not isinstance(resume, Result):
        raise UsageError(f"resume must be a microsim.sim.Result (a partial run), got {resume!r}")
    if resume.tallies is None:
        raise UsageError("resume holds no raw tallies (Result.tallies): it cannot be continued")
    diff = description.mismatches(saved_identity(resume))
    if diff:
        raise UsageError(
            "resume does not match this run's configuration: "
            + "; ".join(f"{k} (partial run: {old!r}, now: {now!r})" for k, old, now in diff)
        )
    t = resume.tallies
    if any(name not in t for name in TALLY_NAMES):
        missing = [name for name in TALLY_NAMES if name not in t]
        raise UsageError(
            f"resume holds no {', '.join(missing)} tallies (Result.tallies, written by an "
            "older microsim): it cannot be continued"
        )
    k = int(t["blocks"].shape[0])
    tallies = tallies_from_arrays(t, k, n_th)
    metas = resume.meta.get("realisations") if k > 1 else [resume.meta.get("surface")]
    return tallies, np.array(t["blocks"], dtype=np.int64), list(metas or [None] * k)


def _check_same_surface(old: dict | None, new: dict, r: int) -> None:
    """UsageError when realisation ``r`` of a resumed run is not the partial run's surface."""
    if old is not None and old.get("fingerprint") != new["fingerprint"]:
        raise UsageError(
            f"resume does not match this run's configuration: surface of realisation "
            f"{r} (partial run: {old.get('kind')} {old.get('fingerprint')}, now: "
            f"{new['kind']} {new['fingerprint']})"
        )
