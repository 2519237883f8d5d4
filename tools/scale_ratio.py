"""The throughput of a large tile over a small one, each path compared with itself, both tiles
in one process and their calls alternating, so that a turn of the host slows both alike
(``microsim bench --scale`` runs each size in a process of its own, minutes apart, and its
ratios move with the host by ±30 %).

``bench``'s Gaussian field (σ = 1.2, ℓ = 8 cells) at ``small``² and ``large``² points,
aluminium at θi = 30°, 1 thread. Per round and per tile the marginal samples a second of a
path: the line through ``simulate`` calls on the same surface (its tracer and facet table
kept) at the two ray counts ``microsim.app.bench_scale`` takes for that path
(``per_ray_rays``: F/8 and F/2 rays on a tile of F facets; ``tabled_rays``: F and 2F), the
best call at each, the two called alternately until they have taken
``bench_scale.MIN_SECONDS`` per count; then the large tile's rate over the small one's. Also,
as the scale table's first rows compare, the large tile per ray at 2²⁰ and 2²² rays over the
small one through its table at the same counts (a fixed count: the path changes). Prints
every round's ratio and their median.

    .venv/bin/python tools/scale_ratio.py [small] [large] [rounds]   (defaults: 512 4096 5)
"""

import dataclasses
import statistics
import sys
import time

from microsim.app.bench import BenchConfig, _bins, _surface
from microsim.app.bench_scale import MIN_SECONDS, RAYS, per_ray_rays, tabled_rays
from microsim.sim import simulate

THETA = 30.0


def main(small: int = 512, large: int = 4096, rounds: int = 5) -> None:
    bins = _bins()
    tiles = {n: _surface(dataclasses.replace(BenchConfig(), n=n)) for n in (small, large)}
    comparisons = {  # name: (the small tile's ray counts, the large tile's)
        "per ray": (per_ray_rays(small), per_ray_rays(large)),
        "facet table": (tabled_rays(small), tabled_rays(large)),
        "fixed 2²⁰–2²² rays": (RAYS, RAYS),
    }
    comparisons = {k: v for k, v in comparisons.items() if None not in v}

    def call(n: int, rays: int) -> float:
        t0 = time.perf_counter()
        simulate(tiles[n], "aluminium", THETA, rays=rays, bins=bins, threads=1)
        return time.perf_counter() - t0

    def rate(n: int, counts: tuple) -> float:
        """Marginal samples a second of the n² tile between the two ray counts."""
        best, spent, calls = [float("inf")] * 2, 0.0, 0
        while calls < 2 or spent < MIN_SECONDS * 2:
            for k, rays in enumerate(counts):
                took = call(n, rays)
                best[k], spent = min(best[k], took), spent + took
            calls += 1
        return (counts[1] - counts[0]) / (best[1] - best[0])

    for counts in comparisons.values():  # tracers, facet tables, kernels: before any timing
        for n, rays in zip(tiles, counts):
            call(n, rays[0])
    print(f"{large}² over {small}², Gaussian field, θi = {THETA}°, 1 thread, {rounds} rounds")
    for name, (small_counts, large_counts) in comparisons.items():
        ratios = []
        for _ in range(rounds):
            a, b = rate(small, small_counts), rate(large, large_counts)
            ratios.append(b / a)
            print(f"  {name}: {a / 1e6:.1f} M and {b / 1e6:.1f} M a second: {b / a:.2f}")
        low, mid, high = min(ratios), statistics.median(ratios), max(ratios)
        print(f"  {name}: median {mid:.2f} (range {low:.2f}–{high:.2f})")


if __name__ == "__main__":
    main(*(int(a) for a in sys.argv[1:4]))
