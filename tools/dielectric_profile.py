"""Where a path's time goes in the dielectric path on the bench scene (the 512² Gaussian
heightfield of ``microsim bench``, glass η = 1.5, ``bounces="all"``, 2²¹ paths, 1 thread):
each stage of ``simulate(..., transmission=True)`` timed by wrapping it, best of two runs, at
θi = 30° (from the air) and 150° (from inside the glass). docs/performance.md quotes it.

    .venv/bin/python tools/dielectric_profile.py [THETA ...]
"""

import collections
import sys
import time

from stage_profile import wrap_stages

from microsim.app.bench import GLASS, BenchConfig, _bins, _surface
from microsim.sim import dielectric, facet_tables, interface_grid, paths, simulate, tallies

PATHS = 2**21
STAGES = {
    "paths on the grid (one compiled loop: walks, interactions, bins, tallies)": (
        interface_grid,
        "grid_interface_paths",
    ),
    "  first interactions' facet table (built once per incidence)": (
        facet_tables,
        "interface_table",
    ),
    "paths step by step (primaries, Embree continuations)": (dielectric, "trace_dielectric"),
    "origins (stratified starts)": (paths.Incidence, "origins_of"),
    "tallies of the step-by-step paths (split_order_tallies)": (tallies, "split_order_tallies"),
    "a thread task (origins + the paths + their tallies)": (dielectric.DielectricPath, "tallies"),
}


def profile(surface, theta: float, spent: dict) -> tuple[float, dict]:
    """(ns per path of the whole call, {stage: ns per path}), best of two calls; ``spent``
    the stages' seconds (``stage_profile.wrap_stages``)."""
    kw = dict(bins=_bins(), threads=1, transmission=True, bounces="all")
    simulate(surface, GLASS, theta, rays=2**16, **kw)  # compilation, tracer
    best = None
    for _ in range(2):
        spent.clear()
        t0 = time.perf_counter()
        simulate(surface, GLASS, theta, rays=PATHS, **kw)
        total = time.perf_counter() - t0
        if best is None or total < best[0]:
            best = (total, dict(spent))
    total, stages = best
    return total / PATHS * 1e9, {k: v / PATHS * 1e9 for k, v in stages.items()}


def main(thetas) -> None:
    surface = _surface(BenchConfig())
    spent = collections.defaultdict(float)
    wrap_stages(STAGES, spent)
    for theta in thetas:
        total, stages = profile(surface, theta, spent)
        print(f"θi = {theta:g}°: {total:.0f} ns per path ({1e3 / total:.2f} M paths/s)")
        for label in STAGES:
            print(f"  {label:62s} {stages.get(label, 0.0):6.1f} ns")


if __name__ == "__main__":
    main([float(t) for t in sys.argv[1:]] or [30.0, 150.0])
