"""What the heightfield grid walk costs per ray (``heightfield_caster.cast_falling``) on the
bench surface (512² Gaussian, σ = 1.2, ℓ = 8 cells), for falling rays from the top of the
relief at several incidences: ns per ray (process time, best of three, 2²¹ starts on a
jittered row-major grid, as stratified origins are ordered) without and with the table of
cells surely stepped over (``heightfield_caster.steps_over``, as the facet-table path walks),
the mean number of cells a ray steps over above the relief before the cell it meets (counted
in NumPy on 4096 of the starts) and how many of them the table lets it step over untested
(on 4096 starts spread over the tile: the table counts no step across a tile wall), and the
table's build time (wall clock).
With ``--embree``: instead, ns per primary ray of the grid walk and of Embree (the tracer's
packets) for the same rays at grazing incidences, where the walk crosses the most
cells.
With ``--orders``: instead, what bounds the walk at the bench's incidence (θi = 30°, with the
table): ns per ray of 2²¹ walks with the starts in four orders, in ``ROUNDS`` rounds of all
four (median and range over the rounds, process time) — as stratified origins come; one
start repeated (every branch predicted, its cells in L1: what is left is the ray's own chain
of dependent steps); starts drawn at random within 8 × 8 cells (the cells in L1, the
branches as unpredictable as the relief makes them); the same as the first, shuffled over the
whole tile (each ray's cells fetched from further out in the memory hierarchy).
With ``--lanes``: instead, ns per ray of the walk one ray at a time and ``LANES`` rays side by
side (``heightfield_caster.cast_lanes``; ``HeightfieldGrid.geometry``'s ``lanes``) at the
``INCIDENCES``, with the table, ``ROUNDS`` rounds alternating (median and range, process
time), after checking that both give the same bits. The default and ``--orders`` walk as
``cast_falling`` does on this machine (``LANE_WALK``; ``MICROSIM_LANE_WALK=0``: one at a time).
docs/performance.md and docs/design.md quote it.

    .venv/bin/python tools/walk_cost.py [--embree | --orders | --lanes]
"""

import sys
import time

import numpy as np

from microsim.app.bench import BenchConfig, _surface
from microsim.sim.heightfield_caster import LANE_WALK, LANES, NO_STEPS, cast_falling, steps_over
from microsim.sim.tracer import Tracer
from microsim.sim.tracer_cache import TRACER_BACKEND, tracer_for

INCIDENCES = ((0.0, 0.0), (30.0, 0.0), (30.0, 30.0), (60.0, 0.0), (60.0, 30.0))
GRAZING = (60.0, 75.0, 80.0, 85.0, 88.0, 89.5)  # θi of the comparison with Embree (φi = 0)
STARTS = 2**21
COUNTED = 4096
ROUNDS = 7  # rounds of ``--orders`` and ``--lanes``


def skipped_cells(grid, x, y, z, d) -> float:
    """Mean number of cells the rays (x, y, z) + t·d cross wholly above their highest vertex
    before the first cell they do not (steps of 1/64 cell along the ray's footprint)."""
    cell_max = grid.cell_max
    ny, nx = cell_max.shape
    u, v = (x - grid.x0) / grid.cell, (y - grid.y0) / grid.cell
    dh = np.hypot(d[0], d[1])
    if dh == 0.0:
        return 0.0
    step = 1.0 / 64.0  # in cells along the footprint
    count = np.zeros(len(x))
    live = np.ones(len(x), dtype=bool)
    last = np.stack([np.floor(u), np.floor(v)], axis=1)
    s = 0.0
    while live.any():
        s += step
        uu, vv = u + s * d[0] / dh, v + s * d[1] / dh
        zz = z + s * grid.cell * d[2] / dh
        i, j = np.floor(uu), np.floor(vv)
        above = zz > cell_max[j.astype(int) % ny, i.astype(int) % nx]
        moved = (i != last[:, 0]) | (j != last[:, 1])
        count += live & moved  # left a cell the ray stayed above
        last = np.stack([i, j], axis=1)
        live &= above
    return float(count.mean())


def _best_seconds(trace, repeat: int = 3) -> float:
    trace()  # compiled, scene built
    best = np.inf
    for _ in range(repeat):
        t0 = time.process_time()
        trace()
        best = min(best, time.process_time() - t0)
    return best


def against_embree() -> None:
    """Grid walk and Embree per primary ray (``Tracer.trace_columns`` with and without the
    grid) at the ``GRAZING`` incidences, 2¹⁸ stratified starts, and the cells the relief's
    height range spans along the ray."""
    surface = _surface(BenchConfig())
    walk = Tracer(surface, backend=TRACER_BACKEND, grid=True)
    embree = Tracer(surface, backend=TRACER_BACKEND, grid=False)
    n = 2**18
    rng = np.random.default_rng(1)
    hx, hy = walk.half
    x = [rng.uniform(-hx, hx, n), rng.uniform(-hy, hy, n), np.full(n, walk.zmax + walk.top_margin)]
    order = np.lexsort((x[0], np.floor(x[1])))  # row by row, as stratified origins come
    x = [np.ascontiguousarray(c[order]) for c in x]
    print("θi    cells   grid walk ns   Embree ns")
    for theta in GRAZING:
        t = np.radians(theta)
        down = [-np.sin(t), 0.0, -np.cos(t)]
        d32 = np.array([down], dtype=np.float32)
        ns = [
            _best_seconds(lambda: tr.trace_columns(x, down, d32)) / n * 1e9 for tr in (walk, embree)
        ]
        cells = (walk.zmax - walk.zmin) * np.tan(t) / walk.grid.cell
        print(f"{theta:4.1f}  {cells:6.0f}   {ns[0]:12.0f}   {ns[1]:9.0f}")


def bench_grid() -> tuple:
    """(tracer, its heightfield grid, the grid walk's geometry) of the bench surface."""
    tracer = tracer_for(_surface(BenchConfig()), "traced").tracer
    grid = tracer.grid
    return tracer, grid, grid.geometry(tracer.zmin, tracer.zmax, tracer.max_wraps)


def jittered_starts(tracer, rng) -> tuple:
    """``STARTS`` starts (x, y, z) at the top of the relief on a jittered row-major grid over
    the tile, as stratified origins are ordered."""
    m = int(np.sqrt(STARTS))
    k = np.arange(STARTS)
    hx, hy = tracer.half
    x = -hx + (k % m + rng.uniform(size=STARTS)) * (2 * hx / m)
    y = -hy + (k // m + rng.uniform(size=STARTS)) * (2 * hy / m)
    return x, y, np.full(STARTS, tracer.zmax + tracer.top_margin)


def walk_outputs() -> tuple:
    """``cast_falling``'s output columns for ``STARTS`` rays."""
    return (np.empty(STARTS, np.int8), np.empty(STARTS, np.int64)) + tuple(
        np.empty(STARTS) for _ in range(3)
    )


def orders() -> None:
    """ns per ray of the walk at θi = 30° (φi = 0, with the table) for the starts in the
    four orders of the module docstring, ``ROUNDS`` rounds of all four."""
    tracer, grid, geometry = bench_grid()
    rng = np.random.default_rng(1)
    x, y, z = jittered_starts(tracer, rng)
    shuffled = rng.permutation(STARTS)
    corner = 100 * grid.cell  # a block of 8 × 8 cells away from the tile's walls
    starts = {
        "as stratified origins come": (x, y),
        "one start repeated": (np.full(STARTS, x[STARTS // 3]), np.full(STARTS, y[STARTS // 3])),
        "at random within 8 × 8 cells": (
            grid.x0 + corner + 8 * grid.cell * rng.random(STARTS),
            grid.y0 + corner + 8 * grid.cell * rng.random(STARTS),
        ),
        "shuffled over the whole tile": (x[shuffled], y[shuffled]),
    }
    t = np.radians(30.0)
    d = (-np.sin(t), 0.0, -np.cos(t))
    ahead = steps_over(grid, d, tracer.zmax)
    out = walk_outputs()
    cast_falling(x, y, z, *d, geometry, ahead, *out)  # compiled, the output pages faulted in
    ns = {label: [] for label in starts}
    for _ in range(ROUNDS):
        for label, (sx, sy) in starts.items():
            t0 = time.process_time()
            cast_falling(sx, sy, z, *d, geometry, ahead, *out)
            ns[label].append((time.process_time() - t0) / STARTS * 1e9)
    print(f"θi = 30°, {STARTS} walks a round, {ROUNDS} rounds: ns per ray, median (range)")
    for label, values in ns.items():
        print(f"  {label}: {np.median(values):.1f} ({min(values):.1f}–{max(values):.1f})")


def lanes() -> None:
    """ns per ray of the walk one at a time and ``LANES`` side by side (module docstring)."""
    tracer, grid, _ = bench_grid()
    x, y, z = jittered_starts(tracer, np.random.default_rng(1))
    ways = {
        label: grid.geometry(tracer.zmin, tracer.zmax, tracer.max_wraps, lanes=lanes)
        for label, lanes in (("one at a time", False), (f"{LANES} side by side", True))
    }
    print(f"walk schedule of cast_falling here: {'lanes' if LANE_WALK else 'one at a time'}")
    print(f"θi    φi   ns per ray, median (range) over {ROUNDS} rounds: " + " | ".join(ways))
    for theta, phi in INCIDENCES:
        t, p = np.radians(theta), np.radians(phi)
        d = (-np.sin(t) * np.cos(p), -np.sin(t) * np.sin(p), -np.cos(t))
        ahead = steps_over(grid, d, tracer.zmax)
        outs = {}
        for label, g in ways.items():
            outs[label] = walk_outputs()
            cast_falling(x, y, z, *d, g, ahead, *outs[label])
        for a, b in zip(*outs.values()):
            np.testing.assert_array_equal(a, b)  # the same bits
        ns = {label: [] for label in ways}
        for _ in range(ROUNDS):
            for label, g in ways.items():
                t0 = time.process_time()
                cast_falling(x, y, z, *d, g, ahead, *outs[label])
                ns[label].append((time.process_time() - t0) / STARTS * 1e9)
        cols = [f"{np.median(v):.1f} ({min(v):.1f}–{max(v):.1f})" for v in ns.values()]
        print(f"{theta:4.0f}  {phi:4.0f}   " + " | ".join(cols))


def main() -> None:
    if "--lanes" in sys.argv[1:]:
        lanes()
        return
    if "--embree" in sys.argv[1:]:
        against_embree()
        return
    if "--orders" in sys.argv[1:]:
        orders()
        return
    tracer, grid, geometry = bench_grid()
    rng = np.random.default_rng(1)
    x, y, z = jittered_starts(tracer, rng)
    out = walk_outputs()
    print(
        "θi    φi   ns per ray   with the table   cells stepped over   of them, surely   table ms"
    )
    for theta, phi in INCIDENCES:
        t, p = np.radians(theta), np.radians(phi)
        d = (-np.sin(t) * np.cos(p), -np.sin(t) * np.sin(p), -np.cos(t))
        t0 = time.perf_counter()
        ahead = steps_over(grid, d, tracer.zmax)
        built = (time.perf_counter() - t0) * 1e3
        times = []
        for table in (NO_STEPS, ahead):
            cast_falling(x[:8], y[:8], z[:8], *d, geometry, table, *(o[:8] for o in out))
            best = np.inf
            for _ in range(3):
                t0 = time.process_time()
                cast_falling(x, y, z, *d, geometry, table, *out)
                best = min(best, time.process_time() - t0)
            times.append(best / STARTS * 1e9)
        cells = skipped_cells(grid, x[:COUNTED], y[:COUNTED], z[0], d)
        every = slice(None, None, STARTS // COUNTED)  # spread over the tile
        sure = _start_cells(grid, ahead, x[every], y[every], z[0], d, tracer.zmax)
        print(
            f"{theta:4.0f}  {phi:4.0f}   {times[0]:10.1f}   {times[1]:14.1f}   {cells:18.2f}"
            f"   {sure:15.2f}   {built:8.1f}"
        )


def _start_cells(grid, ahead, x, y, z0, d, zmax) -> float:
    """Mean of ``ahead`` over the cells where the rays (x, y, z0) + t·d cross the level
    zmax: the cells the walk steps over without testing them."""
    t = (zmax - z0) / d[2]
    i = np.floor((x + t * d[0] - grid.x0) / grid.cell).astype(int) % grid.nx
    j = np.floor((y + t * d[1] - grid.y0) / grid.cell).astype(int) % grid.ny
    return float(ahead[j, i].mean())


if __name__ == "__main__":
    main()
