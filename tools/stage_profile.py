"""Where a sample's time goes in the single-bounce pipeline on the bench scene (the 512²
Gaussian heightfield of ``microsim bench``, aluminium, θi = 30°, 2²² rays, 1 thread): each
stage of ``simulate`` timed by wrapping it (best of three runs), how much faster it runs with
the origins drawn in the walk's pass than drawn as columns first, the one pass of origins,
walk and look-ups split by timing its parts alone on one chunk, the origins' uniform numbers (the
compiled PCG64 against NumPy's generator), what the per-facet beam test clears
and costs (``engine.beam``), and what the masking rays still walked do (how many escape, how
far they run). docs/performance.md quotes it.

    .venv/bin/python tools/stage_profile.py
"""

import collections
import dataclasses
import time

import numpy as np

from microsim.analytic.fresnel import resolve_material
from microsim.app.bench import BenchConfig, _bins, _surface, warm_up
from microsim.sim import (
    facet_tables,
    paths,
    pcg64,
    ray_columns,
    simulate,
    tallies,
    tracer_cache,
)
from microsim.sim.engine import primary, segments
from microsim.sim.masking_rays import MaskingRays, segment_geometry
from microsim.sim.streams import chunk_origins, stratified_draw
from microsim.vectors import spherical_deg

THETA = 30.0
STAGES = {
    "ray origins, primary walk, look-ups, masking starts, horizon test (one pass)": (
        paths,
        "drawn_masking_rays",
    ),
    "masking rays walked (grid or Embree)": (MaskingRays, "trace"),
    "tallies": (tallies, "split_tallies"),
}


def wrap_stages(stages: dict, spent: dict) -> None:
    """Replace every stage of ``stages`` (label → (owner, attribute name)) by a wrapper adding
    its wall time to ``spent[label]``."""
    for label, (owner, name) in stages.items():
        inner = getattr(owner, name)

        def timed(*a, _inner=inner, _label=label, **k):
            t0 = time.perf_counter()
            out = _inner(*a, **k)
            spent[_label] += time.perf_counter() - t0
            return out

        setattr(owner, name, timed)


def stage_times(surface, rays: int) -> tuple[float, dict]:
    """(ns per sample of the whole call, {stage: ns per sample}), best of three calls."""
    spent = collections.defaultdict(float)
    wrap_stages(STAGES, spent)
    best = None
    for _ in range(3):
        spent.clear()
        t0 = time.perf_counter()
        simulate(surface, "aluminium", THETA, rays=rays, bins=_bins(), threads=1)
        total = time.perf_counter() - t0
        if best is None or total < best[0]:
            best = (total, dict(spent))
    total, spent = best
    per = {label: spent[label] / rays * 1e9 for label in STAGES}
    return total / rays * 1e9, per


def drawn_against_columns(surface, rounds: int = 40) -> dict:
    """How much faster ``simulate`` runs (1 thread, 2²² rays) with the origins drawn in the
    walk's pass, as it does, than with ``paths.drawn_masking_rays`` declined, so that every
    chunk's origins are drawn as columns first (the same bits): per round one call each way,
    in alternating order, the ratio of their times; the median and quartiles over
    ``rounds`` (paired rounds see the same turn of a shared host)."""
    drawn = paths.drawn_masking_rays
    ways = {"drawn": drawn, "columns": lambda *a: None}
    ratios = []
    try:
        for r in range(rounds):
            took = {}
            for label in ("drawn", "columns") if r % 2 else ("columns", "drawn"):
                paths.drawn_masking_rays = ways[label]
                t0 = time.perf_counter()
                simulate(surface, "aluminium", THETA, rays=2**22, bins=_bins(), threads=1)
                took[label] = time.perf_counter() - t0
            ratios.append(took["columns"] / took["drawn"])
    finally:
        paths.drawn_masking_rays = drawn
    q1, median, q3 = np.quantile(ratios, [0.25, 0.5, 0.75])
    return {"median": median, "lower quartile": q1, "upper quartile": q3, "rounds": rounds}


def fused_split(tracer, table, wi) -> dict:
    """ns per ray on 16 blocks of the stratified rays: the pass ``simulate`` takes (origins
    drawn block by block in the walk's pass, ``ray_columns.drawn_masking_rays``), the origins
    drawn as columns (``chunk_origins``) then the fused walk and look-ups
    (``primary.cast_tabled_primary``) on them, each of those two alone, the grid walk alone and
    the look-ups alone on its results."""
    key, blocks = (0, 0, 0), range(16)
    draw = stratified_draw(tracer, 2**22, blocks, key)
    x, _ = chunk_origins(tracer, 2**22, blocks, key, False)
    x = [c.copy() for c in x]
    n = len(x[0])
    down = [float(-c) for c in wi]
    facets = primary.FacetColumns(
        table.code, table.weight, table.facets, table.wo32, table.bin, table.clear,
    )  # fmt: skip
    out = primary.PrimaryLedger(np.empty(n, np.int8), np.empty(n), np.empty(n, np.int64))
    mask = MaskingRays.work(n)
    geo, grid = segment_geometry(tracer), tracer.grid_walk(x, down)
    hs, prim, p = tracer.cast_falling(x, down)
    hs, prim, p = hs.copy(), prim.copy(), [c.copy() for c in p]
    walk = segments.WalkResult(hs, prim, *p)

    def columns():
        return chunk_origins(tracer, 2**22, blocks, key, False)

    calls = {
        "origins drawn in the pass, walk, look-ups": lambda: ray_columns.drawn_masking_rays(
            tracer, table, wi, draw
        ),
        "origin columns, then walk and look-ups": lambda: ray_columns.tabled_masking_rays(
            tracer, table, wi, columns()[0]
        ),
        "origin columns alone": columns,
        "walk and look-ups on the columns alone": lambda: primary.cast_tabled_primary(
            tuple(x),
            tuple(down),
            grid,
            table.ahead,
            facets,
            tracer.horizon,
            geo,
            out,
            mask.kernel_args(),
        ),  # fmt: skip
        "grid walk alone": lambda: tracer.cast_falling(x, down),
        "look-ups, starts, horizon alone": lambda: primary.tabled_primary(
            walk, facets, tracer.horizon, geo, out, mask.kernel_args()
        ),
    }
    times = {}
    for label, call in calls.items():
        call()
        times[label] = min(_timed(call) for _ in range(20)) / n * 1e9
    candidates = (table.code[prim] == paths.SINGLE) & ~table.clear[prim]
    return times, float(candidates.mean())


def _timed(call) -> float:
    t0 = time.perf_counter()
    call()
    return time.perf_counter() - t0


def uniform_numbers(n: int = 2**17, repeat: int = 5) -> dict:
    """ns per uniform number (a chunk's ξ and η: 2 per ray) of the compiled PCG64 the origins
    use (``pcg64.fill_uniforms``) and of NumPy's ``Generator(PCG64).random`` on the same
    stream position, best of ``repeat`` each, alternating (the same bits: tests/test_pcg64.py)."""
    state = np.random.PCG64(np.random.SeedSequence([0, 0, 0])).state
    stream, out = pcg64.stream_of(state), np.empty(n)
    rng = np.random.Generator(np.random.PCG64())
    ways = {
        "compiled PCG64 (sim.pcg64)": lambda: pcg64.fill_uniforms(stream, 0, out),
        "NumPy Generator.random": lambda: rng.random(out=out),
    }
    best = dict.fromkeys(ways, np.inf)
    for _ in range(repeat):
        for label, way in ways.items():
            rng.bit_generator.state = state
            best[label] = min(best[label], _timed(way))
    return {label: t / n * 1e9 for label, t in best.items()}


def beams(tracer, table, steep) -> dict:
    """The lit facets the steepness test (``steep``) leaves (candidates), the share of them
    whose beam ``engine.beam.beam_clear`` clears, and its time on 1 thread (best of five)."""
    from microsim.sim.engine import beam

    cand = (table.code == paths.SINGLE) & ~steep
    out = np.empty(len(cand), dtype=np.bool_)
    best = min(
        _timed(lambda: beam.beam_clear(0, cand, table.wo32, tracer.beam, out)) for _ in range(5)
    )
    return {
        "lit facets left by the steepness test": int(cand.sum()),
        "share of them cleared": round(float(out.sum() / cand.sum()), 4),
        "time per incidence (ms)": round(best * 1e3, 1),
    }


def masking_rays(tracer, table, steep, wi, n: int = 2**20) -> dict:
    """The masking rays walked for n uniform primary rays: their share (and what it
    would be with the per-ray tests alone: ``clear`` = ``steep``, no beam cleared), the share
    of them that escape, and quantiles of their polar angle and of their run (cells crossed
    on the climb to zmax) for the escaping ones."""
    rng = np.random.default_rng(0)
    lx, ly = tracer.tile
    x = [rng.uniform(-lx / 2, lx / 2, n), rng.uniform(-ly / 2, ly / 2, n)]
    x.append(np.full(n, tracer.zmax + tracer.top_margin))
    per_ray = dataclasses.replace(table, clear=steep)
    without_beams = ray_columns.tabled_masking_rays(tracer, per_ray, wi, x).m / n
    (status, _, _), mask, m = ray_columns.tabled_masking_rays(tracer, table, wi, x)
    d = np.stack([c[:m] for c in mask.d], 1)
    start_z = mask.start[2][:m].copy()
    mask.trace(tracer, m, status)
    escaped = status[mask.ray[:m]] == paths.SINGLE
    run = (tracer.zmax - start_z) * np.hypot(d[:, 0], d[:, 1]) / d[:, 2] / tracer.grid.cell
    theta = np.degrees(np.arccos(d[:, 2]))
    q = [0.05, 0.5, 0.95]
    return {
        "share of samples": m / n,
        "share of samples with the per-ray tests alone": without_beams,
        "escaping share": float(escaped.mean()),
        "theta_o quantiles 5/50/95 % (deg)": np.round(np.quantile(theta, q), 1).tolist(),
        "run of escaping ones, quantiles 5/50/95 % (cells)": np.round(
            np.quantile(run[escaped], q), 1
        ).tolist(),
    }


def main() -> None:
    warm_up()
    cfg = BenchConfig()
    surface = _surface(cfg)
    total, per = stage_times(surface, cfg.rays)
    print(f"simulate, 1 thread, θi {THETA:g}°, {cfg.rays:,} rays: {total:.1f} ns per sample")
    for label, ns in per.items():
        print(f"  {label}: {ns:.1f} ns")
    print(f"  the rest (thread pool, per-call set-up): {total - sum(per.values()):.1f} ns")
    print("speed-up of drawing the origins in the walk's pass (time as columns / drawn):")
    for label, value in drawn_against_columns(surface).items():
        print(f"  {label}: {value:.3f}" if label != "rounds" else f"  {label}: {value}")
    print("the origins' uniform numbers (2 per ray), ns each:")
    for label, ns in uniform_numbers().items():
        print(f"  {label}: {ns:.2f}")
    tracer, _, _ = tracer_cache.tracer_for(surface, "traced", surface.fingerprint())
    wi = spherical_deg(THETA, 0.0)
    table = facet_tables.facet_table(tracer, wi, resolve_material("aluminium"), _bins(), 0.0)
    times, candidates = fused_split(tracer, table, wi)
    print("the fused primary kernel on one chunk, ns per ray:")
    for label, ns in times.items():
        print(f"  {label}: {ns:.1f}")
    print(f"  share of rays that need the horizon test: {candidates:.3f}")
    print("beams cleared per facet:")
    steep = facet_tables.steep_facets(
        tracer, table.code, table.wo32
    )  # the clear flags before beams
    for label, value in beams(tracer, table, steep).items():
        print(f"  {label}: {value}")
    print("masking rays walked:")
    for label, value in masking_rays(tracer, table, steep, wi).items():
        print(f"  {label}: {value}")


if __name__ == "__main__":
    main()
