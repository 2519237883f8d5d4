"""Where the first ``simulate`` call on a large heightfield spends its time: the bench's
Gaussian field (``microsim bench --scale``'s surface) at n² points, aluminium, θi = 30°, one
block of rays, 1 thread, under cProfile (the kernels loaded beforehand on a 64² tile), then a
second call on the same surface (its tracer reused). docs/performance.md quotes it.

    .venv/bin/python tools/first_call_profile.py [n]     # n: grid points per side, 4096
"""

import cProfile
import pstats
import sys
import time
from dataclasses import replace

from microsim.app.bench import BenchConfig, _bins, _surface
from microsim.sim import BLOCK, simulate


def profiled(surface, cfg) -> float:
    """Seconds of one profiled ``simulate`` call; prints its 20 most expensive calls."""
    profile = cProfile.Profile()
    t0 = time.perf_counter()
    profile.enable()
    simulate(surface, "aluminium", cfg.theta_i, rays=BLOCK, bins=_bins(), threads=1)
    profile.disable()
    seconds = time.perf_counter() - t0
    pstats.Stats(profile).sort_stats("cumulative").print_stats(20)
    return seconds


def main(n: int) -> None:
    cfg = replace(BenchConfig(), n=n)
    small = _surface(replace(cfg, n=64))
    for rays in (BLOCK, 4 * BLOCK):  # the kernels of both single-scattering paths
        simulate(small, "aluminium", cfg.theta_i, rays=rays, bins=_bins(), threads=1)
    t0 = time.perf_counter()
    surface = _surface(cfg)
    build = time.perf_counter() - t0
    first = profiled(surface, cfg)
    second = profiled(surface, cfg)
    print(f"{n}²: build {build:.2f} s, first call {first:.2f} s, second call {second:.2f} s")


if __name__ == "__main__":
    main(int(sys.argv[1]) if len(sys.argv) > 1 else 4096)
