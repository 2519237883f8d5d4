"""Sweeps (microsim.sweep): grid expansion, per-task atomic JSON results, resuming only the
missing tasks after an interruption, and the same table from a Dask LocalCluster as from the
local process pool."""
import argparse
import csv
import json
import os

import pytest

from microsim.atomic import write_json
from microsim.sweep import (SweepSpec, add_sweep_command, expand_tasks,
                            load_sweep, run_sweep)

TINY = {"rays": 12_000, "theta_bins": 10, "phi_bins": 7, "theta_i": [30, 70], "seed": 1,
        "models": ["vgroove", "smith"],
        "scenes": [{"name": "vg", "ior": ["aluminium"],
                    "surface": {"kind": "vgrooves", "n_grooves": 100, "ndf": "beckmann",
                                "m": [0.2, 0.6]}}]}


def tiny_spec() -> SweepSpec:
    return SweepSpec("tiny", "test sweep", tuple(expand_tasks(TINY)))


def table(out, drop=("seconds",)):
    with open(os.path.join(out, "summary.csv"), newline="") as fh:
        return [{k: v for k, v in row.items() if k not in drop} for row in csv.DictReader(fh)]


def test_grid_expands_every_axis():
    spec = tiny_spec()
    assert len(spec.tasks) == 2 * 1 * 2                      # m × ior × θi
    assert len({t.id for t in spec.tasks}) == len(spec.tasks)
    assert {t.surface["m"] for t in spec.tasks} == {0.2, 0.6}
    for path, n in (("sweeps/vgroove-roughness.toml", 7 * 2 * 4),
                    ("sweeps/gaussian-roughness.toml", 5 * 4)):
        assert len(load_sweep(path).tasks) == n


@pytest.mark.parametrize("bad, key", [({"raysx": 1}, "raysx"), ({"theta_i": [95]}, "theta_i"),
                                      ({"models": ["cook"]}, "models"), ({"scenes": []}, "scenes")])
def test_bad_sweeps_raise_naming_the_key(bad, key):
    with pytest.raises(ValueError, match=key):
        expand_tasks({**TINY, **bad})


def test_bad_surface_parameters_raise():
    sc = {**TINY["scenes"][0], "surface": {"kind": "vgrooves", "ndf": "beckmann", "m": [-1.0]}}
    with pytest.raises(ValueError, match="m"):
        expand_tasks({**TINY, "scenes": [sc]})


def test_interrupted_sweep_resumes_with_only_the_missing_tasks(tmp_path):
    spec = tiny_spec()
    out = tmp_path / "sweep"
    first = run_sweep(spec, out, workers=2, limit=2)          # "killed" after 2 results
    assert len(first["computed"]) == 2 and first["skipped"] == []
    assert len(table(out)) == 2 * 2                           # partial table: 2 tasks × 2 models
    # a write interrupted mid-way leaves only a temporary file, never a truncated result
    (out / "tasks" / ".junk-abc.tmp").write_text("{")
    second = run_sweep(spec, out, workers=2)
    ids = [t.id for t in spec.tasks]
    assert sorted(second["skipped"]) == sorted(first["computed"])
    assert sorted(second["computed"]) == sorted(set(ids) - set(first["computed"]))
    rows = table(out)
    assert len(rows) == len(ids) * 2 and {r["task"] for r in rows} == set(ids)
    third = run_sweep(spec, out, workers=1)
    assert third["computed"] == [] and len(third["skipped"]) == len(ids)
    # the resumed sweep equals one uninterrupted run
    run_sweep(spec, tmp_path / "fresh", workers=2)
    assert table(out) == table(tmp_path / "fresh")
    assert (out / "summary.md").read_text().count("| vg |") == len(ids) * 2
    assert (out / "error_vs_roughness.png").stat().st_size > 0


def test_unreadable_result_is_recomputed(tmp_path):
    spec = tiny_spec()
    run_sweep(spec, tmp_path, workers=2, limit=1)
    done = next((tmp_path / "tasks").glob("*.json"))
    done.write_text('{"id": ')                                 # corrupt
    res = run_sweep(spec, tmp_path, workers=2)
    assert done.stem in res["computed"]


def test_atomic_write_leaves_nothing_on_failure(tmp_path):
    with pytest.raises(TypeError):
        write_json(tmp_path / "x.json", {"a": object()})
    assert list(tmp_path.iterdir()) == []


def test_dask_local_cluster_gives_the_same_table(tmp_path):
    distributed = pytest.importorskip("distributed")
    spec = tiny_spec()
    run_sweep(spec, tmp_path / "local", workers=2)
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                  dashboard_address=None) as cluster:
        res = run_sweep(spec, tmp_path / "dask", scheduler=cluster.scheduler_address)
    assert len(res["computed"]) == len(spec.tasks)
    assert table(tmp_path / "dask") == table(tmp_path / "local")
    rec = json.loads(next((tmp_path / "dask" / "tasks").glob("*.json")).read_text())
    assert {v["model"] for v in rec["verdicts"]} == {"ts-vgroove", "ts-smith"}


def test_sweep_subcommand_registers():
    p = argparse.ArgumentParser()
    add_sweep_command(p.add_subparsers())
    args = p.parse_args(["sweep", "s.toml", "--scheduler", "tcp://h:8786", "--workers", "3"])
    assert args.scheduler == "tcp://h:8786" and args.workers == 3 and callable(args.func)
