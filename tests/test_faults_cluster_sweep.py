"""Faults of `microsim run --scheduler` and `microsim sweep`: a Dask scheduler killed mid-run is
an environment failure (status 1, one line naming it, no Dask log flood) that keeps the work
done for a `--resume` ending bitwise equal to the uninterrupted run; a sweep of oriented
V-grooves judges them by the model `microsim run` judges them by, and a sweep that would leave
them without a verdict is refused up front."""

from __future__ import annotations

import csv
import json
import os
import signal
import subprocess
import sys
import time

import numpy as np
import pytest
from support import TINY_CLUSTER_SCENE

from microsim.app.cli import main
from microsim.app.runner import plan_run, tracing
from microsim.app.sweep import load_sweep, run_task
from microsim.app.sweep.task import load_result
from microsim.checkpoints import set_hook

SCENE = TINY_CLUSTER_SCENE


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
@pytest.mark.slow  # 15 s; the default run keeps the cluster sweep's other fault checks
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


ORIENTED_SWEEP = """\
name = "oriented"
rays = 20_000
theta_bins = 10
phi_bins = 8
theta_i = [20, 50]
models = MODELS
[[scenes]]
name = "og"
[scenes.surface]
kind = "vgrooves"
n_grooves = 100
ndf = "beckmann"
m = 0.3
oriented = true
"""


def _sweep_cli(tmp_path, models: str) -> subprocess.CompletedProcess:
    (tmp_path / "oriented.toml").write_text(ORIENTED_SWEEP.replace("MODELS", models))
    args = ["sweep", "oriented.toml", "--out", "out", "--workers", "1"]
    return subprocess.run(
        [sys.executable, "-m", "microsim.app.cli", *args],
        cwd=tmp_path, capture_output=True, text=True, timeout=300,
    )  # fmt: skip


def test_an_oriented_sweep_judges_every_task_by_the_oriented_vgroove_model(tmp_path):
    """Oriented grooves have no ensemble NDF: each task gets the verdict of
    ts-vgroove-oriented (the model `microsim run` judges them by, with the tile's departure),
    and the isotropic-NDF smith variant asked beside it is not judged on them."""
    proc = _sweep_cli(tmp_path, '["vgroove", "smith"]')
    assert proc.returncode == 0, proc.stderr
    with open(tmp_path / "out" / "summary.csv", newline="") as fh:
        rows = list(csv.DictReader(fh))
    assert len(rows) == 2, rows
    for row in rows:
        assert row["model"] == "ts-vgroove-oriented", row
        assert row["verdict"] in ("agrees", "deviates", "inconclusive"), row
        assert float(row["rel_rms"]) >= 0 and float(row["tile_departure"]) > 0, row
    assert {float(r["theta_i"]) for r in rows} == {20.0, 50.0}


def test_an_oriented_sweep_without_the_vgroove_model_is_refused(tmp_path):
    proc = _sweep_cli(tmp_path, '["smith", "none"]')
    lines = proc.stderr.strip().splitlines()
    assert proc.returncode == 2 and len(lines) == 1, proc.stderr
    assert "oriented" in lines[0] and '"vgroove"' in lines[0] and "models" in lines[0], lines
    assert "Traceback" not in proc.stderr and not (tmp_path / "out").exists()


def test_an_oriented_task_record_without_its_verdict_is_not_complete(tmp_path):
    """A task file of oriented grooves holding no verdict is computed again by a rerun."""
    (tmp_path / "oriented.toml").write_text(ORIENTED_SWEEP.replace("MODELS", '["vgroove"]'))
    task = load_sweep(tmp_path / "oriented.toml").tasks[0]
    (tmp_path / "tasks").mkdir()
    record = run_task(task, tmp_path)
    assert [v["model"] for v in record["verdicts"]] == ["ts-vgroove-oriented"]
    assert load_result(task, tmp_path) is not None
    path = tmp_path / "tasks" / f"{task.id}.json"
    path.write_text(json.dumps({**record, "verdicts": []}))
    assert load_result(task, tmp_path) is None
