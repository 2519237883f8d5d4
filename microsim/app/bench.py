"""`microsim bench`: measured throughput, memory and time to accuracy (nothing asserted).

For a fixed mesh and ray set — a periodic Gaussian heightfield (the gaussian-m0.3 scene's
surface: 512², σ = 1.2, ℓ = 8, 524 288 triangles), aluminium, θi = 30°, 2° θ bins — it reports

* raw embreex rays/s on 1 and 2 threads for exactly the rays the pipeline casts: every
  primary ray (closest hit) and the masking ray (occlusion) of every lit facet hit that is
  not cleared without tracing (mirror directions steeper than the heightfield's steepest
  facet, ``Tracer.rise_bound``: 70 % of them here; then the coarse grid of cell maxima,
  ``Tracer.clears_horizon``), in batches
  of 65 536 (float32 arrays prepared beforehand, so only Embree is timed);
* the same rays traced in coherent Embree packets (``microsim.sim.embree_packets``: the
  Embree 4 library embreex bundles, called at its native packet width through ctypes), rays/s
  on 1 and 2 threads, measured alternately with the embreex figure, best of five each;
* the tracer's fixed cost: building the Embree scene and BVH of the mesh with embreex
  (``TriangleMesh`` + first query, which commits) and with ``PacketScene`` (one copy per
  buffer + ``rtcCommitScene``), best of three;
* the pipeline's samples/s (``simulate``: primary ray, Fresnel, reflection, masking ray,
  tally; scene build — mesh, Embree BVH — excluded, the per-incidence facet table included)
  on 1 and 2 threads and its ratio to the raw figure, both expressed per sample (a sample =
  one primary ray and, when lit and not surely escaping, its masking ray). Both figures are
  the best of five runs, raw and pipeline measured alternately (``throughput``): on a shared
  2-core machine single runs scatter by several per cent;
* the same estimator written with Mitsuba 3's LLVM backend (``bench_peer``, the peer the
  speed target is set against; ``pip install microsim[peer]``, skipped with a note without
  it), traced alternately with the others, best of the same runs, and the ratio;
* the marginal throughput of the pipeline and of the peer (``marginal_throughput``): the
  wall time of whole calls at ``rays``/4 and ``rays`` primary rays, alternating, best of
  ``MARGINAL_REPEAT`` each, on 1 and 2 threads; samples/s = the extra rays over the extra
  time, and the fixed cost per call = the time the line through both points gives at zero
  rays (the pipeline's: the per-call set-up with its tracer reused, the facet table; the
  peer's: its facet table in NumPy and its Dr.Jit launches). The speed target is set on this
  ratio, since the whole-run ratio above mixes each side's fixed cost into its rate; its
  spread comes from the same calls, the ratio of the two sides' margins within each round
  (median and range over the rounds, ``bench_report.RoundRatios``);
* the dielectric path (``interface_throughput``): ``simulate(..., transmission=True,
  bounces="all")`` with glass (η = ``GLASS``) at θi and at 180° − θi (the same angle from
  inside the glass) against its Mitsuba peer (``bench_peer.PeerScene.run_dielectric``: the
  same estimator), marginal paths/s and fixed cost per call as ``marginal_throughput``;
* the pipeline's samples/s with every scattering order traced (``bounces="all"``) beside
  ``bounces=1``, alternating, best of three;
* GGX surfaces (``ggx_surface_cost``): samples/s on a GGX heightfield of the same grid
  (the transform construction, α = 2σ/ℓ) beside the Gaussian one, alternating;
* the cost of full-azimuth bins (``azimuth_cost``): samples/s on folded and on full-azimuth
  bins of the same width, and the time of one model's bin averages on each;
* the fixed cost of a ``simulate`` call: the first call on a surface (scene + BVH built) and a
  repeated call on the same surface object (its tracer reused), one block of rays each;
* the peak resident memory of a ``simulate`` run in a fresh process at two ray counts (it
  does not grow with the ray count: tallies are per bin, rays live only per chunk; both
  counts exceed the facet count, so both runs take the per-facet-table path);
* the time ``simulate_auto`` needs to reach 1 % relative standard error on the V-groove
  Beckmann m = 0.3 scene (aluminium, θi = 30°, 2° bins) with the exact analytic V-groove path
  (``masking="analytic"``: primary hit and masking in float64, no Embree; the ray-traced paths
  stay the reference in the tests), its rays/s, and the relative RMS error it actually
  achieves against the exact closed form (Torrance–Sparrow with V-groove G, Mikkelsen 2009,
  eq. 25, bin-averaged); the same with the traced path (``masking="traced"``: Embree primary
  and masking rays, each ray in its own groove frame);
* the wave solver (``wave.bench.wave_bench``): wall time of ``kirchhoff_orders`` for one
  incidence (θi = 30°, aluminium, all propagating orders) on an n² ABC tile of side ``tile``
  wavelengths (1024² over 200 λ; ``--quick``: 128² over 25 λ), smooth (σ = λ/100) and σ = λ,
  with the Fourier upsampling the phase sampling needed; ``skip_wave`` omits it.
"""

from __future__ import annotations

import json
import os
import platform
import subprocess
import sys
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import asdict

import numpy as np

from ..checks import check_memory
from ..errors import EnvironmentFailure, UsageError
from ..jit import numba_target
from .bench_report import (
    THREADS,
    Accuracy,
    AzimuthCost,
    Bench,
    BenchConfig,
    BounceThroughput,
    BuildTimes,
    FixedCost,
    FoldedFull,
    GGXSurfaceCost,
    InterfaceLine,
    InterfaceThroughput,
    Machine,
    Marginal,
    PeerSetup,
    RawThroughput,
    format_bench,
)
from .options import rays_option

__all__ = [
    "BenchConfig",
    "bench_config",
    "throughput",
    "marginal_throughput",
    "interface_throughput",
    "azimuth_cost",
    "build_times",
    "peak_rss_mb",
    "time_to_accuracy",
    "warm_up",
    "run_bench",
    "format_bench",
    "wave_rows",
    "configure_bench",
]

BATCH = 2**16
ACCURACY_MASKING = "analytic"  # the V-groove path timed by ``time_to_accuracy``
ACCURACY_CHUNK = 2**18  # rays per thread task there (fewer per-task overheads)


def _surface(cfg: BenchConfig):
    from microsim.surfaces import gaussian

    return gaussian(cfg.n, 1.0, cfg.sigma, cfg.corr_len, seed=0)


def _bins():
    from microsim.sim import Bins

    return Bins(45, 37)  # 2° θo bins, 5° Δφ bins (folded)


RAY_SET_BYTES = 320
"""Bytes per primary ray while ``_ray_set`` prepares the throughput runs' rays (their
origins, the pipeline's per-ray arrays and the masking rays; measured 274 at its peak): a
``--rays`` above ``checks.memory_limit()`` / this is refused before anything runs."""


def _ray_set(tracer, wi: np.ndarray, rays: int):
    """float32 (origins, directions) of the primary rays (one shared direction) and of the
    masking rays the pipeline casts for them: set up by the pipeline's own compiled pass
    (``ray_columns.tabled_masking_rays``: its starts, offsets and directions, none for the rays it
    clears without tracing)."""
    from microsim.analytic.fresnel import resolve_material
    from microsim.sim.facet_tables import facet_table
    from microsim.sim.ray_columns import tabled_masking_rays
    from microsim.sim.streams import BLOCK, block_origins

    nblk = -(-rays // BLOCK)
    o = np.concatenate([block_origins(tracer, rays, b, (0, 0, 0), False)[0] for b in range(nblk)])
    table = facet_table(tracer, wi, resolve_material("aluminium"), _bins(), 0.0)
    *_, mask, m = tabled_masking_rays(tracer, table, wi, o)
    return (
        (o.astype(np.float32), (-wi).astype(np.float32)[None]),
        (mask.o32[:m].copy(), mask.d32[:m].copy()),
    )


def _time_raw(tracer, primary, masking, threads: int) -> float:
    """Wall seconds Embree needs for both ray sets in BATCH-sized calls on ``threads``."""
    (po, pd), (mo, md) = primary, masking
    scene = tracer.scene.embree

    def prim_batch(a):
        scene.run(po[a : a + BATCH], pd, output=1)

    def mask_batch(a):
        scene.run(mo[a : a + BATCH], md[a : a + BATCH], query="OCCLUDED")

    with ThreadPoolExecutor(threads) as pool:
        t0 = time.perf_counter()
        list(pool.map(prim_batch, range(0, len(po), BATCH)))
        list(pool.map(mask_batch, range(0, len(mo), BATCH)))
        return time.perf_counter() - t0


def _time_packets(scene, primary, masking, threads: int) -> float:
    """Wall seconds the packet scene needs for both ray sets in BATCH-sized calls."""
    (po, pd), (mo, md) = primary, masking
    far = np.full(BATCH, 1e37, dtype=np.float32)  # embreex's default tfar

    def prim_batch(a):
        o = po[a : a + BATCH]
        scene.run(o, pd, far[: len(o)])

    def mask_batch(a):
        o = mo[a : a + BATCH]
        scene.run(o, md[a : a + BATCH], far[: len(o)], occlusion=True)

    with ThreadPoolExecutor(threads) as pool:
        t0 = time.perf_counter()
        list(pool.map(prim_batch, range(0, len(po), BATCH)))
        list(pool.map(mask_batch, range(0, len(mo), BATCH)))
        return time.perf_counter() - t0


def build_times(surface, repeat: int = 3) -> BuildTimes:
    """Seconds to build the Embree scene + BVH of ``surface``'s mesh, best of ``repeat``."""
    from embreex import mesh_construction as mc
    from embreex import rtcore_scene as rs

    from microsim.sim import embree_packets as ep

    v = np.asarray(surface.vertices, dtype=np.float64)
    f = np.asarray(surface.faces)
    reason = ep.binding_error()
    embreex, packets = np.inf, np.inf if reason is None else None
    for _ in range(repeat):
        t0 = time.perf_counter()
        scene = rs.EmbreeScene(robust=True)
        mc.TriangleMesh(scene, v.astype(np.float32), f.astype(np.int32))
        one = np.zeros((1, 3), dtype=np.float32)
        scene.run(one, np.array([[0.0, 0.0, -1.0]], dtype=np.float32), dists=0.0)
        embreex = min(embreex, time.perf_counter() - t0)
        del scene
        if reason is None:
            t0 = time.perf_counter()
            ep.PacketScene(v, f)
            packets = min(packets, time.perf_counter() - t0)
    return BuildTimes(embreex, packets, reason)


def throughput(cfg: BenchConfig = BenchConfig(), surface=None, repeat: int = 5, peer=None) -> tuple:
    """Raw embreex throughput for the pipeline's own rays and the pipeline's (``simulate``,
    scene build excluded), on 1 and 2 threads, best of ``repeat`` each. The two are measured
    alternately (raw, pipeline, raw, …), so that a transient slowdown of the shared machine
    hits both rather than one. Returns (raw, pipeline): a ``RawThroughput`` (rays/s counts
    both kinds; samples/s = primary rays/s) and {1: samples/s, 2: samples/s}. ``peer``: the
    (scene, reason) of ``_peer``, built here when not given."""
    from microsim.sim import Tracer, simulate
    from microsim.sim import embree_packets as ep
    from microsim.vectors import spherical_deg

    surface = surface if surface is not None else _surface(cfg)
    tracer = Tracer(surface, backend="embreex")  # the reference: embreex's single rays
    primary, masking = _ray_set(tracer, spherical_deg(cfg.theta_i, 0.0), cfg.rays)
    n_p, n_m = len(primary[0]), len(masking[0])
    reason = ep.binding_error()
    packets = None if reason else ep.PacketScene(tracer.vertices, tracer.faces)
    peer, peer_reason = _peer(surface, cfg) if peer is None else peer
    best_raw, pipe = {1: np.inf, 2: np.inf}, {1: 0.0, 2: 0.0}
    best_pk, best_peer = {1: np.inf, 2: np.inf}, {1: np.inf, 2: np.inf}
    for rep in range(repeat):
        for threads in (1, 2):
            best_raw[threads] = min(best_raw[threads], _time_raw(tracer, primary, masking, threads))
            if packets is not None:
                dt = _time_packets(packets, primary, masking, threads)
                best_pk[threads] = min(best_pk[threads], dt)
            if peer is not None:
                r = peer.run(
                    "aluminium", cfg.theta_i, cfg.rays, _bins(), seed=1 + rep, threads=threads
                )
                best_peer[threads] = min(best_peer[threads], r.seconds)
            res = simulate(
                surface, "aluminium", cfg.theta_i, rays=cfg.rays, bins=_bins(), threads=threads
            )
            pipe[threads] = max(pipe[threads], res.info.rays_per_second)
    raw = RawThroughput(
        rays=n_p + n_m,
        primary_rays=n_p,
        masking_rays=n_m,
        rays_per_s={t: (n_p + n_m) / best_raw[t] for t in THREADS},
        samples_per_s={t: n_p / best_raw[t] for t in THREADS},
        packet_rays_per_s=None
        if packets is None
        else {t: (n_p + n_m) / best_pk[t] for t in THREADS},
        packet_width=None if packets is None else packets.width,
        packets_unavailable=reason,
        peer_samples_per_s=None if peer is None else {t: cfg.rays / best_peer[t] for t in THREADS},
        peer=None if peer is None else _peer_setup(peer),
        peer_unavailable=peer_reason,
    )
    return raw, pipe


def _peer_setup(peer) -> PeerSetup:
    """What ``raw`` records of a built peer scene."""
    return PeerSetup(
        variant=peer.variant,
        mitsuba_version=peer.mi.__version__,
        copies=2 * peer.m + 1,
        build_seconds=peer.build_seconds,
        llvm_target=peer.llvm_target,
    )


def _peer(surface, cfg: BenchConfig):
    """(the Mitsuba 3 peer scene of ``surface`` after a JIT warm-up run, None) or (None, the
    reason it is unavailable: ``pip install microsim[peer]``)."""
    from microsim.app.bench_peer import PeerScene, PeerUnavailable

    try:
        peer = PeerScene(surface, cfg.theta_i)  # (2m+1)² copies; build + BVH excluded
        peer.run("aluminium", cfg.theta_i, min(cfg.rays, 2**16), _bins(), threads=1)
        return peer, None
    except PeerUnavailable as exc:
        return None, str(exc)


MARGINAL_REPEAT = 5
"""Calls per size, side and thread count of the marginal rates, the best kept: a rate comes
from the difference of two short calls (0.04–0.6 s), which a slow turn of a shared host moves
most on 2 threads; the best of five gives each side its rate in the host's quiet turns, and
the ratio within each of the five rounds its spread."""


def marginal_throughput(
    cfg: BenchConfig = BenchConfig(), surface=None, repeat: int = MARGINAL_REPEAT, peer=None
) -> Marginal:
    """Marginal samples/s and fixed cost per call of the pipeline (``simulate``, the surface's
    tracer reused) and of the Mitsuba peer (``PeerScene.run``, its scene built once) on 1 and
    2 threads: wall times of whole calls at n1 = ``rays``/4 and n2 = ``rays`` primary rays,
    the pipeline and the peer alternating, best of ``repeat`` each; rate = (n2 − n1)/(T2 − T1),
    fixed = T1 − n1/rate (both None when T2 ≤ T1: too few rays to resolve the margin); and
    the ratio of the two rates round by round (``Marginal.ratio_rounds``). ``peer``: as
    ``throughput``'s."""
    from microsim.sim import simulate

    surface = surface if surface is not None else _surface(cfg)
    scene, reason = _peer(surface, cfg) if peer is None else peer
    sizes = (max(1, cfg.rays // 4), cfg.rays)
    pipe, peer = _round_times(sizes), _round_times(sizes)
    for rep in range(repeat):
        for threads in (1, 2):
            for n in sizes:
                t0 = time.perf_counter()
                simulate(surface, "aluminium", cfg.theta_i, rays=n, bins=_bins(), threads=threads)
                pipe[threads][n].append(time.perf_counter() - t0)
                if scene is not None:
                    r = scene.run(
                        "aluminium", cfg.theta_i, n, _bins(), seed=1 + rep, threads=threads
                    )
                    peer[threads][n].append(r.seconds)
    return Marginal.of(list(sizes), pipe, None if scene is None else peer, reason)


def _round_times(sizes) -> dict:
    """{threads: {rays: []}}: the wall time of each round's call, per thread count and size."""
    return {t: {n: [] for n in sizes} for t in THREADS}


GLASS = 1.5
"""The index of the medium of ``interface_throughput``'s dielectric path (air → glass)."""


def interface_throughput(
    cfg: BenchConfig = BenchConfig(), surface=None, repeat: int = MARGINAL_REPEAT, peer=None
) -> InterfaceThroughput:
    """The dielectric path against its Mitsuba peer: marginal paths/s and fixed cost per call
    of ``simulate(surface, GLASS, θi, transmission=True, bounces="all")`` (its tracer reused)
    and of ``PeerScene.run_dielectric`` (the same estimator, its scene built once) at θi =
    ``cfg.theta_i`` (air → glass) and 180° − θi (the same angle from inside the glass), on 1
    and 2 threads: whole calls at ``rays``/4 and ``rays`` paths, alternating, best of
    ``repeat`` each, as ``marginal_throughput``. ``peer``: as ``throughput``'s."""
    from microsim.sim import simulate

    surface = surface if surface is not None else _surface(cfg)
    scene, reason = _peer(surface, cfg) if peer is None else peer
    sizes = (max(2, cfg.rays // 4), max(2, cfg.rays))
    lines = []
    for theta in (cfg.theta_i, 180.0 - cfg.theta_i):
        if scene is not None:  # compiles the peer's kernel (once per process)
            scene.run_dielectric(GLASS, theta, min(cfg.rays, 2**16), _bins(), threads=1)
        pipe, peer = _round_times(sizes), _round_times(sizes)
        per_path = None
        for rep in range(repeat):
            for threads in THREADS:
                for n in sizes:
                    t0 = time.perf_counter()
                    simulate(
                        surface,
                        GLASS,
                        theta,
                        rays=n,
                        bins=_bins(),
                        threads=threads,
                        transmission=True,
                        bounces="all",
                    )
                    pipe[threads][n].append(time.perf_counter() - t0)
                    if scene is not None:
                        r = scene.run_dielectric(
                            GLASS, theta, n, _bins(), seed=1 + rep, threads=threads
                        )
                        peer[threads][n].append(r.seconds)
                        per_path = r.segments
        marginal = Marginal.of(list(sizes), pipe, None if scene is None else peer, reason)
        lines.append(InterfaceLine(theta, marginal, per_path))
    return InterfaceThroughput(GLASS, "all", lines)


def bounce_throughput(
    cfg: BenchConfig = BenchConfig(), surface=None, repeat: int = 3
) -> BounceThroughput:
    """Pipeline samples/s (primary rays/s, scene build excluded) with ``bounces=1`` and
    ``bounces="all"`` (every scattering order, ``sim.bounces``) on 1 and 2 threads, best of
    ``repeat``, alternating."""
    from microsim.sim import simulate

    surface = surface if surface is not None else _surface(cfg)
    one, every = {1: 0.0, 2: 0.0}, {1: 0.0, 2: 0.0}
    for _ in range(repeat):
        for threads in (1, 2):
            for b, best in ((1, one), ("all", every)):
                res = simulate(
                    surface,
                    "aluminium",
                    cfg.theta_i,
                    rays=cfg.rays,
                    bins=_bins(),
                    threads=threads,
                    bounces=b,
                )
                best[threads] = max(best[threads], res.info.rays_per_second)
    return BounceThroughput(one=one, every=every)


def ggx_surface_cost(
    cfg: BenchConfig = BenchConfig(), surface=None, repeat: int = 3
) -> GGXSurfaceCost:
    """Pipeline samples/s (``simulate``, scene build excluded) on the Gaussian bench surface and
    on a GGX heightfield of the same grid, roughness and correlation length (the transform
    construction, ``surfaces.student_t_transform``: α = 2σ/ℓ, γ = 2), 1 and 2 threads,
    alternating, best of ``repeat``."""
    from microsim.sim import simulate
    from microsim.surfaces import student_t_transform

    surfaces = {
        "gaussian": surface if surface is not None else _surface(cfg),
        "ggx": student_t_transform(cfg.n, 1.0, 2.0 * cfg.sigma / cfg.corr_len, 2.0, cfg.corr_len),
    }
    best = {k: {1: 0.0, 2: 0.0} for k in surfaces}
    for _ in range(repeat):
        for threads in THREADS:
            for key, s in surfaces.items():
                res = simulate(
                    s, "aluminium", cfg.theta_i, rays=cfg.rays, bins=_bins(), threads=threads
                )
                best[key][threads] = max(best[key][threads], res.info.rays_per_second)
    return GGXSurfaceCost(**best)


def azimuth_cost(cfg: BenchConfig = BenchConfig(), surface=None, repeat: int = 3) -> AzimuthCost:
    """What full-azimuth bins cost: pipeline samples/s on folded bins (Δφ ∈ [0°, 180°], 37
    bins of 5°) and on full-azimuth bins over the whole circle (72 bins of 5°), 2 threads,
    alternating, best of ``repeat``; and the wall time of one model's bin averages on each at
    θi = ``cfg.theta_i`` (``predict``, best of ``repeat``): Torrance–Sparrow with the isotropic
    Beckmann m = 0.3 and Smith G on the folded bins (integrated over Δφ ≥ 0 only, by
    symmetry), and with the anisotropic Beckmann αx = 0.3, αy = 0.075 and its exact Smith G on
    the full bins (no symmetry to use)."""
    from microsim.analytic import AnisotropicBeckmann, Beckmann, Smith, TorranceSparrow
    from microsim.sim import Bins, simulate
    from microsim.sim.predict import predict

    surface = surface if surface is not None else _surface(cfg)
    bins = {"folded": _bins(), "full": Bins(45, 72, folded=False)}
    ndfs = {"folded": Beckmann(0.3), "full": AnisotropicBeckmann(0.3, 0.075)}
    rate = {k: 0.0 for k in bins}
    seconds = {k: np.inf for k in bins}
    for _ in range(repeat):
        for key, b in bins.items():
            res = simulate(surface, "aluminium", cfg.theta_i, rays=cfg.rays, bins=b, threads=2)
            rate[key] = max(rate[key], res.info.rays_per_second)
            model = TorranceSparrow(ndfs[key], Smith(ndfs[key]), "aluminium")
            t0 = time.perf_counter()
            predict({"ts": model}, [cfg.theta_i], b)
            seconds[key] = min(seconds[key], time.perf_counter() - t0)
    return AzimuthCost(FoldedFull(**rate), FoldedFull(**seconds))


def fixed_cost(cfg: BenchConfig = BenchConfig(), repeat: int = 3) -> FixedCost:
    """Wall time of a ``simulate`` call of one block of rays on the bench surface: the first
    call (Embree scene + BVH built) and the best of ``repeat`` further calls on the same
    surface object, whose prepared tracer is reused (``tracer_cache.tracer_for``), in seconds."""
    from microsim.sim import BLOCK, simulate

    fresh = _surface(cfg)  # a new object: nothing to reuse yet

    def call(s):
        t0 = time.perf_counter()
        simulate(s, "aluminium", cfg.theta_i, rays=BLOCK, bins=_bins(), threads=2)
        return time.perf_counter() - t0

    first = call(fresh)
    return FixedCost(first_call=first, reused=min(call(fresh) for _ in range(repeat)))


_PROBE = """
import sys
sys.path.pop(0)  # "" (the working directory): a microsim/ folder there must not shadow ours
import json, resource
from microsim.app.bench import BenchConfig, _bins, _surface
from microsim.sim import simulate
cfg = BenchConfig(**json.loads(sys.argv[1]))
simulate(_surface(cfg), "aluminium", cfg.theta_i, rays=int(sys.argv[2]), bins=_bins(), threads=2)
try:        # this process's own high-water mark (ru_maxrss may carry the parent's over exec)
    with open("/proc/self/status") as fh:
        print(next(int(l.split()[1]) for l in fh if l.startswith("VmHWM:")) / 1024.0)
except OSError:
    print(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0)
"""


def peak_rss_mb(cfg: BenchConfig = BenchConfig(), rays: int | None = None) -> float:
    """Peak resident memory (MB) of building the surface and one ``simulate`` run of ``rays``
    rays (2 threads) in a fresh Python process."""
    conf = {k: list(v) if isinstance(v, tuple) else v for k, v in asdict(cfg).items()}
    out = subprocess.run(
        [sys.executable, "-c", _PROBE, json.dumps(conf), str(int(rays or cfg.rays))],
        capture_output=True,
        text=True,
    )
    if out.returncode != 0:
        lines = (out.stderr or "").strip().splitlines() or ["(no output)"]
        raise EnvironmentFailure(
            f"the memory probe ({sys.executable} -c …) failed with status {out.returncode}: "
            f"{lines[-1]}"
        )
    return float(out.stdout.split()[-1])


def time_to_accuracy(
    cfg: BenchConfig = BenchConfig(), threads: int = 2, masking: str = ACCURACY_MASKING
) -> Accuracy:
    """Seconds and rays ``simulate_auto`` needs on the V-groove Beckmann m = 0.3 scene
    (aluminium, θi = 30°, Bins(45, 91): 2° bins; ``masking``: "analytic", the exact analytic
    V-groove path with no Embree, or "traced") to reach ``cfg.target`` relative standard
    error, and its rays/s
    (scene builds included); also the achieved rel. RMS error against the exact closed form
    (bin-averaged Torrance–Sparrow with V-groove G) and its χ²/dof."""
    from microsim import analytic as an
    from microsim.analysis.verdicts import Measured, Prediction, verdict
    from microsim.sim import Bins
    from microsim.sim.auto import AutoRecord, simulate_auto
    from microsim.sim.predict import predict
    from microsim.surfaces import vgrooves

    bins = Bins(45, 91)
    surface = vgrooves(cfg.vgrooves, an.Beckmann(0.3), seed=0)
    t0 = time.perf_counter()
    res = simulate_auto(
        surface,
        "aluminium",
        30.0,
        target=cfg.target,
        bins=bins,
        masking=masking,
        threads=threads,
        chunk=ACCURACY_CHUNK,
        max_rays=cfg.max_rays,
    )
    seconds = time.perf_counter() - t0
    ts = an.TorranceSparrow(an.Beckmann(0.3), an.VGroove(), "aluminium")
    model = predict({"ts": ts}, [30.0], bins)["ts"][0]
    v = verdict(Measured.of(res, 0), Prediction(model))
    incidence = AutoRecord.of(res.info.auto).incidences[0]
    return Accuracy(
        seconds=seconds,
        rays=int(res.rays[0]),
        rays_per_s=res.rays[0] / seconds,
        masking=masking,
        rse=incidence.rse,
        converged=incidence.converged,
        rel_rms_vs_closed_form=v["rel_rms"],
        chi2_dof=v["chi2_dof"],
        threads=threads,
    )


def warm_up() -> None:
    """Run every trace path the bench times once, on small surfaces of their own (tabled and
    traced heightfield paths, the traced and the exact V-groove paths, one bounce and all, the
    dielectric path from the air and from inside),
    so that no timed figure includes a numba compilation: a process compiles each kernel once
    (seconds after an edit of the sources; docs/performance.md, "First-run compilation") and
    then loads it from its cache, a per-process cost, not a per-call one."""
    from microsim import analytic as an
    from microsim.sim import BLOCK, Bins, simulate
    from microsim.surfaces import gaussian, vgrooves

    hf, grooves = gaussian(16, 1.0, 0.3, 8.0, seed=0), vgrooves(8, an.Beckmann(0.3), seed=0)
    for surface, masking, rays, bounces in (
        (hf, "traced", BLOCK, 1),  # 512 facets < rays: the facet table
        (gaussian(64, 1.0, 0.3, 8.0, seed=0), "traced", BLOCK, 1),  # traced, shared direction
        (hf, "traced", BLOCK, "all"),
        (grooves, "traced", BLOCK, 1),
        (grooves, "analytic", BLOCK, 1),
    ):
        for threads in (1, 2):
            simulate(
                surface,
                "aluminium",
                30.0,
                rays=rays,
                bins=Bins(45, 37),
                threads=threads,
                masking=masking,
                bounces=bounces,
            )
    for threads in (1, 2):  # the dielectric path, from the air and from inside
        simulate(hf, GLASS, [30.0, 150.0], rays=BLOCK, bins=Bins(45, 37), threads=threads,
                 transmission=True, bounces="all")  # fmt: skip


def machine() -> Machine:
    """What the figures were measured on: the CPU model, its widest x86 vector extension
    ("AVX-512", "AVX2" or the machine's architecture), NumPy's dispatch targets in use (its
    AVX-512 kernels change ulps of some functions), numba's target (``jit.numba_target``) and
    how the grid walk runs (``heightfield_caster.LANE_WALK``)."""
    flags, model = set(), platform.processor() or platform.machine()
    try:
        with open("/proc/cpuinfo", encoding="utf-8") as fh:
            for line in fh:
                key, _, value = line.partition(":")
                if key.strip() == "flags" and not flags:
                    flags = set(value.split())
                elif key.strip() == "model name":
                    model = value.strip()
    except OSError:
        pass
    isa = "AVX-512" if "avx512f" in flags else "AVX2" if "avx2" in flags else platform.machine()
    try:
        from numpy._core import _multiarray_umath as umath
    except ImportError:  # NumPy < 2
        from numpy.core import _multiarray_umath as umath
    dispatch = [k for k in umath.__cpu_dispatch__ if umath.__cpu_features__.get(k)]
    from ..sim.heightfield_caster import LANE_WALK, LANES

    walk = f"{LANES} rays side by side" if LANE_WALK else "one ray at a time"
    return Machine(
        cpu=model, isa=isa, numpy_dispatch=dispatch, numba_cpu=numba_target(), grid_walk=walk
    )


def run_bench(cfg: BenchConfig = BenchConfig()) -> Bench:
    """Every figure of the module docstring (after ``warm_up``); ``Bench.to_json`` is its JSON."""
    warm_up()
    surface = _surface(cfg)
    peer = _peer(surface, cfg)
    raw, pipe = throughput(cfg, surface, peer=peer)
    return Bench(
        config=cfg,
        machine=machine(),
        load_average=list(os.getloadavg()),
        cpus=os.cpu_count(),
        mesh_triangles=int(len(surface.faces)),
        raw=raw,
        pipeline_samples_per_s=pipe,
        ratio={t: pipe[t] / raw.samples_per_s[t] for t in THREADS},
        marginal=marginal_throughput(cfg, surface, peer=peer),
        build_seconds=build_times(surface),
        fixed_cost=fixed_cost(cfg),
        bounces=bounce_throughput(cfg, surface),
        full_azimuth=azimuth_cost(cfg, surface),
        ggx_surface=ggx_surface_cost(cfg, surface),
        dielectric=interface_throughput(cfg, surface, peer=peer),
        peak_rss_mb={int(r): peak_rss_mb(cfg, r) for r in cfg.memory_rays},
        time_to_accuracy=None if cfg.skip_accuracy else time_to_accuracy(cfg),
        time_to_accuracy_traced=None
        if cfg.skip_accuracy
        else time_to_accuracy(cfg, masking="traced"),
        wave=None if cfg.skip_wave else wave_rows(cfg),
    )


def wave_rows(cfg: BenchConfig = BenchConfig(), threads: int = 2) -> list:
    """``wave.bench.wave_bench`` on a ``cfg.wave_n``² tile of ``cfg.wave_tile`` λ: one row per
    roughness (σ = λ/100 and σ = λ), smooth-interpolant solver, ``threads`` FFT workers."""
    from microsim.app.wave_bench import wave_bench

    return wave_bench(n=cfg.wave_n, tile=cfg.wave_tile, workers=threads)


QUICK = dict(
    n=128,
    rays=2**17,
    memory_rays=(2**16, 2**18),
    target=0.05,
    vgrooves=1000,
    wave_n=128,
    wave_tile=25.0,
)
"""``bench --quick``: a 128² mesh, 2**17 rays (an explicit ``--rays`` wins), small memory
probes, the wave solver on a 128² tile of 25 λ."""


def bench_config(
    rays: int | None = None, quick: bool = False, skip_accuracy: bool = False
) -> BenchConfig:
    """The configuration of ``microsim bench``: ``QUICK`` or the defaults, ``rays`` (primary
    rays of the throughput runs, an integer >= 1) overriding either. Rays whose prepared
    arrays would not fit in memory (``RAY_SET_BYTES`` each) are refused, naming ``--rays``
    and the limit (``checks.check_memory``)."""
    if rays is not None and (isinstance(rays, bool) or int(rays) != rays or rays < 1):
        from ..errors import UsageError

        raise UsageError(f"--rays must be an integer >= 1, got {rays!r}")
    conf = dict(QUICK) if quick else {}
    if rays is not None:
        rays = int(rays)
        conf = {**conf, "rays": rays}
        check_memory(
            "--rays",
            RAY_SET_BYTES * rays,
            f"preparing {rays:,} primary rays and their masking rays for the "
            f"throughput runs ({RAY_SET_BYTES} bytes per ray)",
        )
    return BenchConfig(skip_accuracy=skip_accuracy, **conf)


def _cmd_bench(args) -> int:
    if args.methods is not None:
        from .bench_methods import run_methods_command

        return run_methods_command(args)
    if args.scale:
        return _cmd_scale(args)
    cfg = bench_config(args.rays, args.quick, args.skip_accuracy)
    b = run_bench(cfg)
    print(json.dumps(b.to_json(), indent=1) if args.json else format_bench(b))
    return 0


def _cmd_scale(args) -> int:
    """``microsim bench --scale``: ``bench_scale``'s table (or its rows as JSON)."""
    from . import bench_scale as bs

    if args.rays is not None or args.skip_accuracy:
        given = "--rays" if args.rays is not None else "--skip-accuracy"
        raise UsageError(f"{given}: not with --scale (its ray counts are fixed: {bs.RAYS})")
    sizes, rays = (bs.QUICK_SIZES, bs.QUICK_RAYS) if args.quick else (bs.SIZES, bs.RAYS)
    rows = bs.scale_rows(BenchConfig(), sizes, rays, 0.0 if args.quick else bs.MIN_SECONDS)
    if args.json:
        record = {"machine": asdict(machine()), "rays": list(rays)}
        print(json.dumps({**record, "rows": [asdict(r) for r in rows]}, indent=1))
    else:
        m = machine()
        print(f"{m.cpu} ({m.isa}, numba {m.numba_cpu}, grid walk {m.grid_walk}); 1 thread")
        print(bs.format_scale(rows))
    return 0


def configure_bench(p) -> None:
    """The arguments of ``microsim bench [--json] [--quick] [--rays N] [--skip-accuracy]
    [--methods [DIR]] [--scale]`` on its parser ``p`` (``cli.COMMANDS``)."""
    p.add_argument("--json", action="store_true", help="print the figures as JSON")
    p.add_argument(
        "--rays",
        type=rays_option,
        default=None,
        help=f"primary rays of the throughput runs (default {BenchConfig.rays}; "
        f"with --quick {QUICK['rays']})",
    )
    p.add_argument(
        "--quick", action="store_true", help="small mesh and ray counts (seconds; for smoke tests)"
    )
    p.add_argument("--skip-accuracy", action="store_true", help="omit the time-to-1%% run")
    p.add_argument(
        "--scale",
        action="store_true",
        help="instead: build, first call, fixed cost, marginal samples/s and peak memory per "
        "tile size (512² … 8192², the largest that fits; microsim.app.bench_scale)",
    )
    p.add_argument(
        "--methods",
        nargs="?",
        const="reports",
        default=None,
        metavar="DIR",
        help="instead: wall time against error of each method (closed forms, ray trace, exact "
        "V-groove path, wave solver; with the fullwave extra, rigorous coupled-wave "
        "solutions of a 1D grating); writes DIR/methods.json and DIR/methods.png "
        "(default DIR: reports; microsim.app.bench_methods)",
    )
    p.set_defaults(func=_cmd_bench)
