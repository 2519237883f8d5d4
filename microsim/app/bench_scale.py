"""How a run scales with the tile (``microsim bench --scale``): per grid size, in a fresh
process each, the surface build, the first ``simulate`` call, the fixed cost of a later call,
the marginal samples/s and the peak resident memory.

The surface is ``bench``'s (a Gaussian field, σ = ``BenchConfig.sigma``, ℓ = ``corr_len`` cells)
at n² points, n in ``SIZES``; the run is ``bench``'s (aluminium, θi = ``BenchConfig.theta_i``,
its bins, 1 thread). Each size runs in its own process (``_PROBE``): numba's kernels are loaded
(compiled once per machine) on a 64² tile first, then the surface is built (``build``), traced
once with one block of rays (``first``: the tracer, its tables and the first rays), and traced
at ``RAYS`` = (2²⁰, 2²²) rays, best of ``REPEAT`` calls each or more (``MIN_SECONDS``): the line
through the two gives
``samples_per_s`` (marginal) and ``fixed_seconds`` (the intercept: what a later call on the same
surface costs besides its rays). Both counts must take one path (``rays_for``: the facet table,
or per ray on tiles with more facets than rays), which each row names; a size measured through
the facet table is measured per ray too (``per_ray_rays``, when its smaller count is at least
``PER_RAY_MIN``), and one measured per ray whose tile can have a facet table
(``facet_tables.table_pays``) is measured through it too, at one and two rays per facet
(``tabled_rays``): each path compared with itself across sizes. ``rss_mb`` is the process's
peak resident set (VmHWM), ``build_rss_mb`` that peak right after the surface's build,
``base_mb`` its resident set before the surface (interpreter, libraries, kernels),
``bytes_per_point`` the difference over n². A size whose expected peak (``_does_not_fit``)
exceeds the memory the machine has available is skipped with that reason instead of run; a
size whose probe fails (a refusal by the surface's own memory check, a crash) is listed with its
failure, after the sizes measured before it. A row through the table expects
``TABLE_BYTES_PER_GRID_POINT`` more per point and the kept tables' bytes besides
(``surfaces.heightfields.traced_bytes``).
"""

from __future__ import annotations

import json
import subprocess
import sys
from dataclasses import asdict, dataclass

from microsim.sim.facet_tables import table_pays
from microsim.surfaces.heightfields import (
    BYTES_PER_GRID_POINT,
    TABLE_BYTES_PER_GRID_POINT,
    TABLES_KEPT_BYTES,
)

from .bench_report import BenchConfig

__all__ = [
    "SIZES",
    "RAYS",
    "QUICK_SIZES",
    "QUICK_RAYS",
    "ScaleRow",
    "scale_rows",
    "format_scale",
    "available_mb",
]

SIZES = (512, 1024, 2048, 4096, 8192)
RAYS = (2**20, 2**22)
QUICK_SIZES, QUICK_RAYS = (64, 128), (2**15, 2**17)
"""``--quick``: small tiles and ray counts, each called ``REPEAT`` times (seconds; for smoke
tests)."""
REPEAT = 2
MIN_SECONDS = 1.0
"""Each size's two counts are called alternately ``REPEAT`` times, and again until the calls
have taken ``MIN_SECONDS`` per count on average: short calls (a 512² tile per ray, 0.01–0.05 s)
are repeated dozens of times, so that their best is not one turn of a busy host."""
BYTES_PER_POINT_GUESS = float(BYTES_PER_GRID_POINT)
"""Peak bytes per grid point assumed for a size before two sizes have been measured: the
heightfields' own estimate (``surfaces.heightfields.BYTES_PER_GRID_POINT``)."""

_PROBE = """
import sys
sys.path.pop(0)  # "" (the working directory): a microsim/ folder there must not shadow ours
import json, time
from dataclasses import replace
from microsim.app.bench import BenchConfig, _bins, _surface
from microsim.sim import BLOCK, simulate

def status_mb(key):
    with open("/proc/self/status") as fh:
        return next(int(line.split()[1]) for line in fh if line.startswith(key)) / 1024.0

cfg, rays = BenchConfig(**json.loads(sys.argv[1])), json.loads(sys.argv[2])
repeat, min_seconds = int(sys.argv[3]), float(sys.argv[4])
run = dict(bins=_bins(), threads=1)
small = _surface(replace(cfg, n=64))  # the kernels of the traced path and the facet table's,
for warm in (BLOCK, 4 * BLOCK):  # rays < and > its 8192 facets (masking rays traced too)
    simulate(small, "aluminium", cfg.theta_i, rays=warm, **run)
base = status_mb("VmRSS:")
t0 = time.perf_counter()
surface = _surface(cfg)
build = time.perf_counter() - t0
built = status_mb("VmHWM:")
t0 = time.perf_counter()
simulate(surface, "aluminium", cfg.theta_i, rays=BLOCK, **run)
first = time.perf_counter() - t0
best, once, calls = {}, [], 0
while calls < repeat or sum(once) < min_seconds * len(rays):  # the counts alternating
    for n in rays:
        t0 = time.perf_counter()
        simulate(surface, "aluminium", cfg.theta_i, rays=n, **run)
        once.append(time.perf_counter() - t0)
        best[n] = min(best.get(n, float("inf")), once[-1])
    calls += 1
times = {"build": build, "first": first, "seconds": [best[n] for n in rays], "once": once[0]}
peaks = {"rss_mb": status_mb("VmHWM:"), "build_rss_mb": built, "base_mb": base}
print(json.dumps({**times, **peaks}))
"""


@dataclass(frozen=True)
class ScaleRow:
    """One grid size: ``n``; the times (s) and rates of the module docstring, None with a
    ``skipped`` reason when the size was not run; ``set_up_seconds``: what the first call at
    the smaller ray count took beyond the best one (through the table: the incidence's facet
    table, built by that call and kept for the later ones)."""

    n: int
    build_seconds: float | None = None
    first_seconds: float | None = None
    fixed_seconds: float | None = None
    samples_per_s: float | None = None
    rss_mb: float | None = None
    base_mb: float | None = None
    build_rss_mb: float | None = None
    rays: tuple | None = None
    path: str | None = None
    skipped: str | None = None
    set_up_seconds: float | None = None

    @property
    def bytes_per_point(self) -> float | None:
        """Peak memory above the process's own (interpreter, libraries, kernels) per point."""
        return None if self.rss_mb is None else (self.rss_mb - self.base_mb) * 2**20 / self.n**2

    @property
    def build_bytes_per_point(self) -> float | None:
        """``bytes_per_point`` of the peak reached by the surface's build alone."""
        if self.build_rss_mb is None:
            return None
        return (self.build_rss_mb - self.base_mb) * 2**20 / self.n**2


def available_mb() -> float:
    """The memory the machine has available now (MemAvailable, MB)."""
    with open("/proc/meminfo") as fh:
        return next(int(line.split()[1]) for line in fh if line.startswith("MemAvailable:")) / 1024


PATHS = ("facet table", "per ray")
"""The single-scattering paths a marginal rate can measure (``facet_tables.uses_facet_table``:
the facet table where it pays, ``facet_tables.table_pays``, else per ray)."""


def rays_for(n: int, rays: tuple) -> tuple[tuple, str]:
    """The two ray counts of an n² tile and the path both take (``PATHS``): ``rays``, unless
    they straddle its 2n² facets — the smaller traced per ray, the larger through the facet
    table, a line through two paths — then ``per_ray_rays``."""
    tabled = {table_pays(2 * n * n, r) for r in rays}
    if len(tabled) == 1:
        return tuple(rays), PATHS[0] if tabled.pop() else PATHS[1]
    return per_ray_rays(n), PATHS[1]


PER_RAY_MIN = 2**16
"""The fewest rays a per-ray call of a table-path size is timed with (fewer: not measured)."""


def per_ray_rays(n: int) -> tuple:
    """F/8 and F/2 rays on an n² tile of F = 2n² facets: both per ray."""
    facets = 2 * n * n
    return facets // 8, facets // 2


def tabled_rays(n: int) -> tuple | None:
    """F and 2F rays on an n² tile of F = 2n² facets, both through the facet table; None
    where the tile is too large for one (``facet_tables.table_pays``)."""
    facets = 2 * n * n
    return (facets, 2 * facets) if table_pays(facets, facets) else None


def _probe(cfg: BenchConfig, n: int, rays: tuple, min_seconds: float) -> ScaleRow:
    conf = {k: list(v) if isinstance(v, tuple) else v for k, v in asdict(cfg).items()}
    conf["n"] = n
    rays, path = rays_for(n, rays)
    out = subprocess.run(
        [
            sys.executable,
            "-c",
            _PROBE,
            json.dumps(conf),
            json.dumps(list(rays)),
            str(REPEAT),
            str(min_seconds),
        ],
        capture_output=True,
        text=True,
    )
    if out.returncode != 0:  # said in the table: the sizes measured before it are kept
        lines = (out.stderr or "").strip().splitlines() or ["(no output)"]
        return ScaleRow(n, skipped=f"the probe failed with status {out.returncode}: {lines[-1]}")
    got = json.loads(out.stdout.strip().splitlines()[-1])
    (t1, t2), (n1, n2) = got["seconds"], rays
    rate = (n2 - n1) / (t2 - t1) if t2 > t1 else None
    fixed = None if rate is None else t1 - n1 / rate
    peaks = got["rss_mb"], got["base_mb"], got["build_rss_mb"]
    set_up = got["once"] - t1
    return ScaleRow(n, got["build"], got["first"], fixed, rate, *peaks, rays, path, None, set_up)


def scale_rows(
    cfg: BenchConfig = BenchConfig(), sizes=SIZES, rays=RAYS, min_seconds: float = MIN_SECONDS
) -> list[ScaleRow]:
    """``ScaleRow`` of each of ``sizes`` (module docstring), smallest first, the marginal rate
    between the two ray counts ``rays``, each called until ``min_seconds`` (``MIN_SECONDS``)."""
    rows = []
    for n in sorted(sizes):
        reason = _does_not_fit(rows, n, tabled=rays_for(n, rays)[1] == PATHS[0])
        if reason:
            rows.append(ScaleRow(n, skipped=reason))
            continue
        rows.append(_probe(cfg, n, rays, min_seconds))
        if rows[-1].path == PATHS[0] and min(per_ray_rays(n)) >= PER_RAY_MIN:
            rows.append(_probe(cfg, n, per_ray_rays(n), min_seconds))  # like with like
        elif rows[-1].path == PATHS[1] and tabled_rays(n) is not None:
            reason = _does_not_fit(rows, n, tabled=True)
            table = tabled_rays(n)
            rows.append(
                ScaleRow(n, skipped=reason) if reason else _probe(cfg, n, table, min_seconds)
            )
    return rows


def _does_not_fit(rows: list[ScaleRow], n: int, tabled: bool) -> str | None:
    """Why an n² tile is not run (None: it fits): its expected peak above 90 % of the memory
    available. The peak: ``BYTES_PER_POINT_GUESS`` per point, or once two tiles have been
    measured per ray the larger of their bytes per point (fixed costs amortised); through the
    table ``TABLE_BYTES_PER_GRID_POINT`` more per point and the kept tables' bytes."""
    per_ray = [r for r in rows if r.rss_mb is not None and r.path == PATHS[1]]
    measured = [r for r in rows if r.rss_mb is not None]
    per_point = BYTES_PER_POINT_GUESS
    if len(per_ray) >= 2:
        per_point = max(r.bytes_per_point for r in per_ray[-2:])
    base = measured[-1].base_mb if measured else 0.0
    extra = TABLE_BYTES_PER_GRID_POINT * n * n + TABLES_KEPT_BYTES if tabled else 0.0
    need, have = base + (per_point * n * n + extra) / 2**20, available_mb()
    if need <= 0.9 * have:
        return None
    path = "through the facet table " if tabled else ""
    return (
        f"needs ~{need / 1024:.1f} GB {path}at {per_point:.0f} B/point, "
        f"{have / 1024:.1f} GB available"
    )


def format_scale(rows: list[ScaleRow]) -> str:
    """The rows as the table of docs/performance.md."""

    def fmt(v, f):
        return "–" if v is None else f.format(v)

    lines = [
        "| grid | build | first call | fixed cost per later call | marginal samples/s "
        "(path, rays) | peak RSS | bytes per point above the process's own "
        "| of them, the build's peak |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        if r.skipped:
            lines.append(f"| {r.n}² | skipped: {r.skipped} | | | | | | |")
            continue
        built = f" built in {r.set_up_seconds:.1f} s" if r.path == PATHS[0] else ""
        lines.append(
            f"| {r.n}² | {fmt(r.build_seconds, '{:.2f} s')} | {fmt(r.first_seconds, '{:.2f} s')} "
            f"| {fmt(r.fixed_seconds, '{:.2f} s')} "
            f"| {fmt(r.samples_per_s and r.samples_per_s / 1e6, '{:.1f} M')} "
            f"({r.path}{built}, {r.rays[0]:,} and {r.rays[1]:,}) "
            f"| {fmt(r.rss_mb, '{:.0f} MB')} | {fmt(r.bytes_per_point, '{:.0f}')} "
            f"| {fmt(r.build_bytes_per_point, '{:.0f}')} |"
        )
    return "\n".join(lines)
