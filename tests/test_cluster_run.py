"""One run over a Dask cluster (``Execution(cluster=client)``, ``microsim run --scheduler``):
the result is the local run's bit for bit, a worker killed mid-run is replaced without double
counting, an interrupt keeps the tallied chunks and a resume on the cluster completes them to
the local run exactly.

All on a ``LocalCluster`` of two single-threaded worker processes (this machine's two cores)."""

from __future__ import annotations

import json
import os
import signal

import numpy as np
import pytest
from support import TINY_CLUSTER_SCENE

from microsim.analytic import Beckmann
from microsim.checkpoints import interrupt_at
from microsim.errors import UsageError
from microsim.sim import Bins, Estimator, Execution, Experiment, estimate
from microsim.surfaces import gaussian, vgrooves

distributed = pytest.importorskip("distributed", reason="needs the `cluster` extra")
pytestmark = pytest.mark.integration

BINS = Bins(12, 10)
RAYS = 6 * 2**16  # 96 blocks of 4096 per incidence: many chunks of 2¹⁴ rays


@pytest.fixture(scope="module")
def client():
    with (
        distributed.LocalCluster(
            n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None
        ) as cluster,
        distributed.Client(cluster) as c,
    ):
        yield c


def _experiment(bounces=1):
    def build(seed):
        return gaussian(64, 1.0, sigma=0.8, corr_len=8.0, seed=seed)

    return Experiment(
        None, "aluminium", (20.0, 70.0), 0.0, bins=BINS, bounces=bounces,
        surface_factory=build, seeds=[3, 4],
    )  # fmt: skip


def _same(a, b):
    """Every array of two Results equal, NaN equal to NaN."""
    for name in ("brdf", "stderr", "counts"):
        assert np.array_equal(getattr(a, name), getattr(b, name), equal_nan=True), name
    assert set(a.tallies) == set(b.tallies)
    for k in a.tallies:
        assert np.array_equal(np.asarray(a.tallies[k]), np.asarray(b.tallies[k])), k


@pytest.mark.parametrize("bounces", [1, "all"])
def test_a_cluster_run_is_the_local_run_bitwise(client, bounces):
    est = Estimator(RAYS, seed=11)
    local = estimate(_experiment(bounces), est, Execution(2, chunk=2**14))
    remote = estimate(_experiment(bounces), est, Execution(chunk=2**14, cluster=client))
    _same(local, remote)
    assert not remote.is_partial and remote.meta["rays_traced"] == local.meta["rays_traced"]


def test_exact_vgroove_masking_runs_on_the_cluster(client):
    ex = Experiment(vgrooves(300, Beckmann(0.3)), "aluminium", (10.0, 60.0), 0.0, bins=BINS)
    est = Estimator(2**17, seed=2, masking="exact")
    _same(estimate(ex, est, Execution(1)), estimate(ex, est, Execution(cluster=client)))


def test_a_killed_worker_is_replaced_without_double_counting(client):
    """After the first chunk is tallied one worker process is killed (SIGKILL); its nanny
    starts another, Dask reruns the tasks it held, and the client — which tallies each block
    range once, in order — ends with the local run's sums."""
    est = Estimator(RAYS, seed=5)
    local = estimate(_experiment(), est, Execution(2, chunk=2**14))
    pids = list(client.run(os.getpid).values())
    killed = []

    def kill_once(event):
        if not killed:
            os.kill(pids[0], signal.SIGKILL)
            killed.append(pids[0])

    remote = estimate(
        _experiment(), est, Execution(chunk=2**14, progress=kill_once, cluster=client)
    )
    assert killed and pids[0] not in client.run(os.getpid).values()
    _same(local, remote)
    client.wait_for_workers(2, timeout=60)


def test_an_interrupt_keeps_the_tallied_chunks_and_a_resume_completes_them(client):
    est = Estimator(RAYS, seed=8)
    local = estimate(_experiment(), est, Execution(2, chunk=2**14))
    with interrupt_at("simulation", after=5) as hit:
        partial = estimate(_experiment(), est, Execution(chunk=2**14, cluster=client))
    assert hit["fired"] and partial.is_partial
    done = int(np.asarray(partial.tallies["rays"]).sum())
    assert 0 < done < local.meta["rays_traced"]
    resumed = estimate(_experiment(), est, Execution(chunk=2**14, cluster=client), resume=partial)
    _same(local, resumed)


def test_a_bad_cluster_names_the_parameter():
    with pytest.raises(UsageError, match="cluster must be a dask.distributed.Client"):
        Execution(cluster="tcp://localhost:8786")


SCENE = TINY_CLUSTER_SCENE


@pytest.mark.slow  # 17–22 s; the default run keeps `measure --scheduler` and the API check
def test_microsim_run_with_a_scheduler_writes_the_local_result(tmp_path):
    """``microsim run SCENE --scheduler ADDRESS``: the same brdf.npz arrays as the local run,
    and meta.json records the cluster; a bad address is a one-line error (exit 2)."""
    from microsim.app.cli import main

    scene = tmp_path / "tiny.toml"
    scene.write_text(SCENE)
    assert (
        main(["run", str(scene), "--out", str(tmp_path / "local"), "--no-progress", "--quick"]) == 0
    )
    with distributed.LocalCluster(
        n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None
    ) as cluster:
        args = ["run", str(scene), "--out", str(tmp_path / "dask"), "--no-progress", "--quick"]
        assert main(args + ["--scheduler", cluster.scheduler_address]) == 0
    with (
        np.load(tmp_path / "local" / "brdf.npz") as a,
        np.load(tmp_path / "dask" / "brdf.npz") as b,
    ):
        assert sorted(a.files) == sorted(b.files)
        for k in a.files:
            assert np.array_equal(a[k], b[k], equal_nan=True), k
    meta = json.loads((tmp_path / "dask" / "meta.json").read_text())
    assert meta["cluster"] == {"workers": 2, "threads": 2}
    assert main(["run", str(scene), "--out", str(tmp_path / "x"), "--scheduler", "nope://"]) == 2


@pytest.mark.slow  # 23 s; the default run keeps `run --scheduler` end to end
def test_microsim_report_with_a_scheduler_traces_each_scene_there(tmp_path):
    from microsim.app.runner import run_report

    cat = tmp_path / "cat"
    cat.mkdir()
    (cat / "tiny.toml").write_text(SCENE)
    kw = {"quick": True, "progress": False, "log": lambda s: None, "regimes": False}
    assert run_report(cat, tmp_path / "local", **kw) == 0
    with distributed.LocalCluster(
        n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None
    ) as cluster:
        assert run_report(cat, tmp_path / "dask", scheduler=cluster.scheduler_address, **kw) == 0
    local, dask = (np.load(tmp_path / d / "tiny-cluster" / "brdf.npz") for d in ("local", "dask"))
    with local, dask:
        for k in local.files:
            assert np.array_equal(local[k], dask[k], equal_nan=True), k
    meta = json.loads((tmp_path / "dask" / "tiny-cluster" / "meta.json").read_text())
    assert meta["cluster"]["workers"] == 2


def test_microsim_measure_with_a_scheduler_writes_the_local_table(tmp_path):
    from microsim.app.measure import measure, plan_measure
    from microsim.measured import BRDFTable

    scene = tmp_path / "tiny.toml"
    scene.write_text(SCENE)
    kw = {"theta_step": 30.0, "theta_max": 60.0, "target": 0.05, "exports": ()}
    local = measure(plan_measure(scene, out=tmp_path / "local", **kw), log=None)
    with distributed.LocalCluster(
        n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None
    ) as cluster:
        acq = plan_measure(scene, out=tmp_path / "dask", scheduler=cluster.scheduler_address, **kw)
        remote = measure(acq, log=None)
    assert np.array_equal(local.brdf, remote.brdf) and np.array_equal(local.stderr, remote.stderr)
    saved = BRDFTable.load(tmp_path / "dask" / "table.npz")
    assert np.array_equal(saved.brdf, local.brdf)
