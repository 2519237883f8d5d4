"""Two versions of microsim side by side: the marginal samples/s of ``simulate`` on the bench
scene (the 512² Gaussian heightfield of ``microsim bench``, aluminium, θi = 30°, 1 thread; the
line through the best of five calls at 2²⁰ and 2²² rays, as ``bench.marginal_throughput``)
in alternating processes, one importing microsim from this checkout and one from another
(a ``git worktree`` of an older commit), so that a slow turn of a shared host falls on both.
Prints each round's two rates and their medians. Set the instruction-set pins in the
environment to compare on that path (docs/performance.md). docs/performance.md quotes it.

    git worktree add /tmp/older COMMIT
    .venv/bin/python tools/version_ab.py /tmp/older [ROUNDS]     # ROUNDS: 3
"""

import os
import statistics
import subprocess
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parents[1]
PROBE = """
import time
from microsim.app.bench import BenchConfig, _bins, _surface
from microsim.sim import simulate

surface = _surface(BenchConfig())
sizes = (2**20, 2**22)


def call(n):
    t0 = time.perf_counter()
    simulate(surface, "aluminium", 30.0, rays=n, bins=_bins(), threads=1)
    return time.perf_counter() - t0


call(2**16)  # compiles or loads the kernels, builds the tracer and the facet table
best = {n: min(call(n) for _ in range(5)) for n in sizes}
print((sizes[1] - sizes[0]) / (best[sizes[1]] - best[sizes[0]]))
"""


def rate(source: Path) -> float:
    """Marginal samples/s of the checkout at ``source``, in a fresh process."""
    env = {**os.environ, "PYTHONPATH": str(source)}
    out = subprocess.run(
        [sys.executable, "-c", PROBE], env=env, cwd=source, capture_output=True, text=True
    )
    if out.returncode != 0:
        raise SystemExit(out.stderr[-2000:])
    return float(out.stdout.split()[-1])


def main() -> None:
    other = Path(sys.argv[1]).resolve()
    rounds = int(sys.argv[2]) if len(sys.argv) > 2 else 3
    runs = {"other": [], "this": []}
    for r in range(rounds):
        for name in ("other", "this") if r % 2 == 0 else ("this", "other"):
            runs[name].append(rate(other if name == "other" else HERE) / 1e6)
        print(f"round {r + 1}: other {runs['other'][-1]:.1f} M, this {runs['this'][-1]:.1f} M")
    for name, v in runs.items():
        print(f"{name} ({other if name == 'other' else HERE}): median {statistics.median(v):.1f} M")


if __name__ == "__main__":
    main()
