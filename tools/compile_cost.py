"""What compiling microsim's kernels costs, kernel by kernel: the kernels ``make test``'s
warm-up compiles (``tests/dispatch_probe.py``, in this process's own dispatch) on an empty
numba cache (a fresh temporary ``NUMBA_CACHE_DIR``), each compilation timed through numba's
``numba:compile`` events. A kernel's own time excludes the compiled callees it triggers;
inlined helpers count in their caller's. Prints the total and the most expensive kernels with
how many specialisations (argument-type tuples) each got. docs/performance.md quotes it.

    .venv/bin/python tools/compile_cost.py [N]     # N: kernels listed, 15
"""

import collections
import os
import sys
import tempfile
import time
from pathlib import Path

os.environ["NUMBA_CACHE_DIR"] = tempfile.mkdtemp(prefix="microsim-compile-cost-")
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))

import numpy as np  # noqa: E402
from numba.core import event  # noqa: E402


class CompileTimes(event.Listener):
    """Per kernel: its own compile seconds (callees' compilations subtracted) and count."""

    def __init__(self):
        self.open = []  # [name, start, callees' seconds] of the compilations under way
        self.own = collections.Counter()
        self.count = collections.Counter()

    def on_start(self, ev):
        dispatcher = ev.data.get("dispatcher")
        name = dispatcher.py_func.__qualname__ if dispatcher is not None else "?"
        self.open.append([name, time.perf_counter(), 0.0])

    def on_end(self, ev):
        name, start, callees = self.open.pop()
        seconds = time.perf_counter() - start
        self.own[name] += seconds - callees
        self.count[name] += 1
        if self.open:
            self.open[-1][2] += seconds


def main(listed: int = 15) -> None:
    import dispatch_probe

    times = CompileTimes()
    event.register("numba:compile", times)
    with tempfile.TemporaryDirectory() as folder:
        inputs = dict(np.load(dispatch_probe.write_inputs(Path(folder)), allow_pickle=True))
        t0 = time.perf_counter()
        dispatch_probe.probe(inputs)
        whole = time.perf_counter() - t0
    total = sum(times.own.values())
    print(f"dispatch probe: {whole:.1f} s, of which compiling {total:.1f} s")
    print("  own s  count  kernel")
    for name, seconds in times.own.most_common(listed):
        print(f"{seconds:7.2f}  {times.count[name]:5d}  {name}")


if __name__ == "__main__":
    main(*(int(a) for a in sys.argv[1:2]))
