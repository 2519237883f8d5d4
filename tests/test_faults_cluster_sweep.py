"""Faults of `microsim run --scheduler` and `microsim sweep`: a Dask scheduler killed mid-run is
an environment failure (status 1, one line naming it, no Dask log flood) that keeps the work
done for a `--resume` ending bitwise equal to the uninterrupted run."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time

import numpy as np
import pytest

from microsim.app.cli import main
from microsim.app.runner import plan_run, tracing
from microsim.checkpoints import set_hook

SCENE = """\
name = "tiny-cluster"
[surface]
kind = "vgrooves"
n_grooves = 400
ndf = "beckmann"
m = 0.3
[material]
ior = "aluminium"
[simulation]
theta_i = [20, 60]
rays = 200000
theta_bins = 9
phi_bins = 10
"""


def _spawn(*module_args) -> subprocess.Popen:
    """A Dask command-line process (``python -m MODULE ARGS``) in its own process group,
    silent."""
    return subprocess.Popen(
        [sys.executable, "-m", *module_args],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
        start_new_session=True,
    )


def _stop(proc: subprocess.Popen) -> None:
    """Kill ``proc``'s process group (a worker's nanny and its worker) and reap it."""
    if proc.poll() is None:
        os.killpg(proc.pid, signal.SIGKILL)
    proc.wait(timeout=30)


@pytest.fixture
def scheduler(tmp_path):
    """(scheduler process, its address) of a `dask scheduler` with one single-threaded
    `dask worker` connected; both killed afterwards."""
    distributed = pytest.importorskip("distributed", reason="needs the `cluster` extra")
    info = tmp_path / "scheduler.json"
    procs = [
        _spawn(
            "distributed.cli.dask_scheduler", "--host", "127.0.0.1", "--port", "0",
            "--no-dashboard", "--scheduler-file", str(info),
        )
    ]  # fmt: skip
    try:
        deadline = time.monotonic() + 60
        while not info.exists() or not info.read_text().strip():
            assert time.monotonic() < deadline and procs[0].poll() is None, "no scheduler"
            time.sleep(0.1)
        address = json.loads(info.read_text())["address"]
        procs.append(
            _spawn(
                "distributed.cli.dask_worker", address, "--nworkers", "1", "--nthreads", "1",
                "--no-dashboard",
            )
        )  # fmt: skip
        with distributed.Client(address, timeout=30) as client:
            client.wait_for_workers(1, timeout=60)
        yield procs[0], address
    finally:
        for proc in procs:
            _stop(proc)


@pytest.mark.integration
def test_a_killed_scheduler_keeps_the_tallies_for_a_resume(tmp_path, scheduler, capfd):
    """The scheduler process is killed (SIGKILL) after the second chunk of rays is tallied:
    status 1, one line on stderr naming the scheduler's address and the --resume to continue,
    none of Dask's log lines; the partial tallies are saved, and `--resume` (locally) ends
    with the tallies of the uninterrupted run bit for bit."""
    proc, address = scheduler
    scene = tmp_path / "tiny.toml"
    scene.write_text(SCENE)
    quick = ["--no-progress", "--quick"]
    remote = tmp_path / "remote"

    chunks = []

    def kill_scheduler(phase):
        if phase == "simulation" and len(chunks) < 2:
            chunks.append(phase)
            if len(chunks) == 2:
                os.kill(proc.pid, signal.SIGKILL)
                proc.wait(timeout=30)

    old = set_hook(kill_scheduler)
    try:
        rc = main(["run", str(scene), "--out", str(remote), *quick, "--scheduler", address])
    finally:
        set_hook(old)
    err = capfd.readouterr().err
    lines = err.strip().splitlines()
    assert rc == 1, err
    assert len(lines) == 1, err
    assert address in lines[0] and f"--resume {remote}" in lines[0], err
    meta = json.loads((remote / "meta.json").read_text())
    assert meta["partial"] and meta["scheduler_lost"] == address
    assert not (remote / "report.md").exists()

    assert main(["run", str(scene), "--resume", str(remote), *quick]) == 0
    plan = plan_run(scene, out=tmp_path / "unused", quick=True)
    theta_i, phi_i = plan.incidences
    whole = tracing.simulate_scene(plan, theta_i, plan.rays, plan.seed, plan.bins, phi_i=phi_i)
    with np.load(remote / "brdf.npz") as resumed:
        for k in ("brdf", "stderr", "rays", "counts", "sum_w", "sum_w2"):
            assert np.array_equal(getattr(whole, k), resumed[k], equal_nan=True), k
        for k, v in whole.tallies.items():
            assert np.array_equal(v, resumed[f"tally_{k}"]), k
