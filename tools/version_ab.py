"""Two versions of microsim side by side: the marginal samples/s of ``simulate`` on the bench
scene (``bench.marginal_throughput`` without the peer: the 512² Gaussian heightfield of
``microsim bench``, aluminium, θi = 30°, the line through the best of five calls at 2²⁰ and
2²² rays, on 1 and 2 threads) in alternating processes, one importing microsim from this
checkout and one from another (a ``git worktree`` of an older commit), so that a slow turn of a
shared host falls on both. Prints each round's rates and their medians. Set the
instruction-set pins in the environment to compare on that path (docs/performance.md).
docs/performance.md quotes it.

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
from microsim.app.bench import BenchConfig, marginal_throughput

m = marginal_throughput(BenchConfig(), peer=(None, "not compared"))
print(*(m.pipeline[t].samples_per_s for t in (1, 2)))
"""


def rates(source: Path) -> tuple:
    """Marginal samples/s on (1, 2) threads of the checkout at ``source``, in a fresh
    process."""
    env = {**os.environ, "PYTHONPATH": str(source)}
    out = subprocess.run(
        [sys.executable, "-c", PROBE], env=env, cwd=source, capture_output=True, text=True
    )
    if out.returncode != 0:
        raise SystemExit(out.stderr[-2000:])
    return tuple(float(r) / 1e6 for r in out.stdout.split()[-2:])


def main() -> None:
    other = Path(sys.argv[1]).resolve()
    rounds = int(sys.argv[2]) if len(sys.argv) > 2 else 3
    sources = {"other": other, "this": HERE}
    runs = {name: [] for name in sources}
    for r in range(rounds):
        for name in ("other", "this") if r % 2 == 0 else ("this", "other"):
            runs[name].append(rates(sources[name]))
        line = ", ".join(f"{n} {v[-1][0]:.1f} / {v[-1][1]:.1f} M" for n, v in runs.items())
        print(f"round {r + 1} (1 / 2 threads): {line}")
    for name, v in runs.items():
        medians = [statistics.median(x[k] for x in v) for k in (0, 1)]
        print(f"{name} ({sources[name]}): medians {medians[0]:.1f} / {medians[1]:.1f} M")


if __name__ == "__main__":
    main()
