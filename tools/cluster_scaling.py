"""One run over a Dask LocalCluster against local threads: wall time and M rays/s of the same
estimate (a 256² Gaussian heightfield, aluminium, θi 30° and 60°, 4·10⁶ rays each, 30 × 37
bins) on 1 and 2 local threads and on 1 and 2 single-threaded worker processes, after a
warm-up of each; the cluster results are checked to equal the local one bitwise, and the
Dask cost per task is estimated from a run with small tasks.

    .venv/bin/python tools/cluster_scaling.py
"""

import os
import time

import numpy as np
from distributed import Client, LocalCluster

import microsim.sim.cluster as cl
from microsim.sim import Bins, Estimator, Execution, Experiment, estimate
from microsim.sim.streams import BLOCK
from microsim.surfaces import gaussian

RAYS = 4_000_000


def timed(ex, est, run):
    t = time.perf_counter()
    result = estimate(ex, est, run)
    return result, time.perf_counter() - t


def main() -> None:
    surface = gaussian(256, 1.0, sigma=2.0, corr_len=10.0, seed=1)
    ex = Experiment(surface, "aluminium", (30.0, 60.0), 0.0, bins=Bins(30, 37))
    est = Estimator(RAYS, seed=3)
    rays = RAYS * len(ex.theta_i)
    rows = {}
    estimate(ex, Estimator(200_000, seed=1), Execution(2))  # JIT and BVH
    for threads in (1, 2):
        ref, rows[f"local, {threads} thread(s)"] = timed(ex, est, Execution(threads))
    for workers in (1, 2):
        with (
            LocalCluster(
                n_workers=workers, threads_per_worker=1, processes=True, dashboard_address=None
            ) as cluster,
            Client(cluster) as client,
        ):
            estimate(ex, Estimator(200_000, seed=1), Execution(cluster=client))  # warm-up
            res, rows[f"cluster, {workers} worker(s)"] = timed(ex, est, Execution(cluster=client))
            assert np.array_equal(res.brdf, ref.brdf, equal_nan=True), "not bitwise equal"
            if workers == 1:  # the cost per task: the same run in tasks of one block
                small = Estimator(RAYS // 8, seed=3)
                _, local = timed(ex, small, Execution(1, chunk=BLOCK))
                n_tasks = len(ex.theta_i) * -(-RAYS // 8 // BLOCK)
                old, cl.MIN_TASK_BLOCKS = cl.MIN_TASK_BLOCKS, 1
                try:
                    _, remote = timed(ex, small, Execution(chunk=BLOCK, cluster=client))
                finally:
                    cl.MIN_TASK_BLOCKS = old
                per_task = (remote - local) / n_tasks
    for name, seconds in rows.items():
        print(f"{name:24s} {seconds:6.2f} s  {rays / seconds / 1e6:6.2f} M rays/s")
    print(
        f"Dask cost per task (1 worker, tasks of {BLOCK} rays): {1e3 * per_task:.1f} ms; "
        f"cluster tasks carry at least {cl.MIN_TASK_BLOCKS * BLOCK:,} rays"
    )
    print(f"load average {os.getloadavg()[0]:.2f}, {os.cpu_count()} CPUs")


if __name__ == "__main__":
    main()
