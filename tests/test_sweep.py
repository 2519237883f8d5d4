"""Sweeps (microsim.app.sweep): grid expansion, per-task atomic JSON results, resuming only the
missing tasks after an interruption, and the same table from a Dask LocalCluster as from the
local process pool."""

import csv
import json
import os
import re

import pytest

from microsim.app.cli import build_parser
from microsim.app.sweep import SweepSpec, expand_tasks, load_sweep, run_sweep
from microsim.atomic import write_json

TINY = {
    "rays": 12_000,
    "theta_bins": 10,
    "phi_bins": 7,
    "theta_i": [30, 70],
    "seed": 1,
    "models": ["vgroove", "smith"],
    "scenes": [
        {
            "name": "vg",
            "ior": ["aluminium"],
            "surface": {"kind": "vgrooves", "n_grooves": 100, "ndf": "beckmann", "m": [0.2, 0.6]},
        }
    ],
}


def tiny_spec() -> SweepSpec:
    return SweepSpec("tiny", "test sweep", tuple(expand_tasks(TINY)))


def table(out, drop=("seconds",)):
    with open(os.path.join(out, "summary.csv"), newline="") as fh:
        return [{k: v for k, v in row.items() if k not in drop} for row in csv.DictReader(fh)]


def test_grid_expands_every_axis():
    spec = tiny_spec()
    assert len(spec.tasks) == 2 * 1 * 2  # m × ior × θi
    assert len({t.id for t in spec.tasks}) == len(spec.tasks)
    assert {t.surface["m"] for t in spec.tasks} == {0.2, 0.6}
    for path, n in (
        ("sweeps/vgroove-roughness.toml", 7 * 2 * 4),
        ("sweeps/gaussian-roughness.toml", 5 * 4),
    ):
        assert len(load_sweep(path).tasks) == n


@pytest.mark.parametrize(
    "bad, key",
    [
        ({"raysx": 1}, "raysx"),
        ({"theta_i": [95]}, "theta_i"),
        ({"models": ["cook"]}, "models"),
        ({"scenes": []}, "scenes"),
    ],
)
def test_bad_sweeps_raise_naming_the_key(bad, key):
    with pytest.raises(ValueError, match=key):
        expand_tasks({**TINY, **bad})


def test_the_sweep_takes_every_incidence_a_scene_file_takes():
    from microsim.app.scene import MAX_THETA_I

    tasks = expand_tasks({**TINY, "theta_i": [0, MAX_THETA_I]})
    assert sorted({t.theta_i for t in tasks}) == [0, MAX_THETA_I]


def test_bad_surface_parameters_raise():
    sc = {**TINY["scenes"][0], "surface": {"kind": "vgrooves", "ndf": "beckmann", "m": [-1.0]}}
    with pytest.raises(ValueError, match="m"):
        expand_tasks({**TINY, "scenes": [sc]})


def test_interrupted_sweep_resumes_with_only_the_missing_tasks(tmp_path):
    spec = tiny_spec()
    out = tmp_path / "sweep"
    first = run_sweep(spec, out, workers=2, limit=2)  # "killed" after 2 results
    assert len(first.computed) == 2 and first.skipped == []
    assert len(table(out)) == 2 * 2  # partial table: 2 tasks × 2 models
    # a write interrupted mid-way leaves only a temporary file, never a truncated result
    (out / "tasks" / ".junk-abc.tmp").write_text("{")
    second = run_sweep(spec, out, workers=2)
    ids = [t.id for t in spec.tasks]
    assert sorted(second.skipped) == sorted(first.computed)
    assert sorted(second.computed) == sorted(set(ids) - set(first.computed))
    rows = table(out)
    assert len(rows) == len(ids) * 2 and {r["task"] for r in rows} == set(ids)
    third = run_sweep(spec, out, workers=1)
    assert third.computed == [] and len(third.skipped) == len(ids)
    # the resumed sweep equals one uninterrupted run
    run_sweep(spec, tmp_path / "fresh", workers=2)
    assert table(out) == table(tmp_path / "fresh")
    assert (out / "summary.md").read_text().count("| vg |") == len(ids) * 2
    assert (out / "error_vs_roughness.png").stat().st_size > 0


def test_unreadable_result_is_recomputed(tmp_path):
    spec = tiny_spec()
    run_sweep(spec, tmp_path, workers=2, limit=1)
    done = next((tmp_path / "tasks").glob("*.json"))
    done.write_text('{"id": ')  # corrupt
    res = run_sweep(spec, tmp_path, workers=2)
    assert done.stem in res.computed


def test_atomic_write_leaves_nothing_on_failure(tmp_path):
    with pytest.raises(TypeError):
        write_json(tmp_path / "x.json", {"a": object()})
    assert list(tmp_path.iterdir()) == []


@pytest.mark.integration
@pytest.mark.slow  # 13 s; tests/test_cluster_run.py keeps a cluster run bitwise the local one
def test_dask_local_cluster_gives_the_same_table(tmp_path):
    distributed = pytest.importorskip("distributed")
    spec = tiny_spec()
    run_sweep(spec, tmp_path / "local", workers=2)
    with distributed.LocalCluster(
        n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None
    ) as cluster:
        res = run_sweep(spec, tmp_path / "dask", scheduler=cluster.scheduler_address)
    assert len(res.computed) == len(spec.tasks)
    assert table(tmp_path / "dask") == table(tmp_path / "local")
    rec = json.loads(next((tmp_path / "dask" / "tasks").glob("*.json")).read_text())
    assert {v["model"] for v in rec["verdicts"]} == {"ts-vgroove", "ts-smith"}


def test_the_command_line_has_the_sweep_subcommand():
    args = build_parser(("sweep",)).parse_args(
        ["sweep", "s.toml", "--scheduler", "tcp://h:8786", "--workers", "3"]
    )
    assert args.scheduler == "tcp://h:8786" and args.workers == 3 and callable(args.func)


# --- hardening: interrupts, partial results, progress, empty axes, CSV, scheduler ----------------
def _json(path):
    return json.loads(path.read_text())


def test_partial_simulation_writes_no_task_file(tmp_path, monkeypatch):
    """A task whose simulate comes back partial (SIGINT in the worker) is not stored as done."""
    import microsim.sim as sim
    from microsim.app.sweep import run_task

    real = sim.simulate

    def interrupted(surface, material, theta_i, *, rays, **kw):
        res = real(surface, material, theta_i, rays=rays // 2, **kw)  # fewer rays tallied …
        return res.with_meta(partial=True)  # … as after a Ctrl-C

    monkeypatch.setattr(sim, "simulate", interrupted)
    task = tiny_spec().tasks[0]
    rec = run_task(task, tmp_path)
    assert rec["id"] == task.id and rec.get("partial") is True
    assert not (tmp_path / "tasks" / f"{task.id}.json").exists()


def test_simulation_checkpoint_interrupt_writes_no_task_file(tmp_path):
    """The same through the in-process hook: simulate marks every chunk with a checkpoint."""
    from microsim.app.sweep import run_task
    from microsim.checkpoints import interrupt_at

    task = expand_tasks({**TINY, "rays": 400_000, "theta_i": [30]})[0]
    with interrupt_at("simulation") as state:
        rec = run_task(task, tmp_path)
    assert state["fired"], "simulate() no longer calls checkpoint('simulation') after a chunk"
    assert rec.get("partial") is True
    assert not (tmp_path / "tasks" / f"{task.id}.json").exists()


@pytest.mark.parametrize(
    "damage",
    [
        "short",
        pytest.param("partial", marks=pytest.mark.slow),
        pytest.param("truncated", marks=pytest.mark.slow),
        pytest.param("other-task", marks=pytest.mark.slow),
        "no-verdicts",
    ],
)
def test_incomplete_task_files_are_recomputed_and_never_summarised(tmp_path, damage):
    """Task JSONs left by an older interrupted sweep (fewer rays than requested, a partial flag,
    cut short, another task's record, no verdicts) count as missing: not in the summary, and
    the rerun computes them again."""
    from microsim.app.sweep import gather, write_summary

    spec = tiny_spec()
    run_sweep(spec, tmp_path, workers=2)
    victim = tmp_path / "tasks" / f"{spec.tasks[0].id}.json"
    rec = _json(victim)
    if damage == "short":
        rec["rays"] = rec["rays"] * 1_769_472 // 2_000_000
    elif damage == "partial":
        rec["partial"] = True
    elif damage == "other-task":
        rec["task"] = _json(tmp_path / "tasks" / f"{spec.tasks[1].id}.json")["task"]
    elif damage == "no-verdicts":
        del rec["verdicts"]
    victim.write_text(json.dumps(rec)[: -5 if damage == "truncated" else None])
    assert spec.tasks[0].id not in {r["id"] for r in gather(spec, tmp_path)}
    write_summary(spec, tmp_path)
    assert spec.tasks[0].id not in {r["task"] for r in table(tmp_path)}
    res = run_sweep(spec, tmp_path, workers=1)
    assert res.computed == [spec.tasks[0].id]
    back = _json(victim)
    assert back["rays"] == spec.tasks[0].rays and not back.get("partial")
    assert len(table(tmp_path)) == 2 * len(spec.tasks)


@pytest.mark.slow  # 8 s; the default run keeps the resume of an interrupted sweep
def test_interrupted_sweep_keeps_finished_tasks_and_writes_no_summary(tmp_path):
    """Ctrl-C after the 2nd finished task: the finished tasks stay (complete), no summary is
    written, and the rerun computes only the rest and equals an uninterrupted sweep."""
    from microsim.checkpoints import interrupt_at

    spec = tiny_spec()
    out = tmp_path / "sweep"
    with interrupt_at("sweep-task", after=1) as state, pytest.raises(KeyboardInterrupt):
        run_sweep(spec, out, workers=1)
    assert state["fired"]
    kept = sorted((out / "tasks").glob("*.json"))
    assert 2 <= len(kept) < len(spec.tasks)
    for p in kept:
        rec = _json(p)
        assert rec["rays"] == spec.tasks[0].rays and not rec.get("partial")
    assert not (out / "summary.csv").exists() and not (out / "summary.md").exists()
    again = run_sweep(spec, out, workers=2)
    assert sorted(again.skipped) == sorted(p.stem for p in kept)
    assert len(again.computed) == len(spec.tasks) - len(kept)
    run_sweep(spec, tmp_path / "fresh", workers=2)
    assert table(out) == table(tmp_path / "fresh")


def test_cli_interrupt_exits_130_with_one_line_telling_how_to_continue(tmp_path, capsys):
    from microsim.app.cli import main
    from microsim.checkpoints import interrupt_at

    sweep = tmp_path / "tiny.toml"
    sweep.write_text(TINY_TOML)
    out = tmp_path / "out"
    with interrupt_at("sweep-task", after=0):
        rc = main(["sweep", str(sweep), "--out", str(out), "--workers", "1"])
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 130
    assert "Traceback" not in "\n".join(err)
    last = err[-1]
    assert "interrupted" in last and "rerun" in last and str(sweep) in last
    assert not (out / "summary.csv").exists()
    assert len(list((out / "tasks").glob("*.json"))) >= 1


TINY_TOML = """
name = "tiny"
rays = 12_000
theta_bins = 10
phi_bins = 7
seed = 1
theta_i = [30, 70]
[[scenes]]
name = "vg"
ior = ["aluminium", [1.5, 0.25], 1.33]
[scenes.surface]
kind = "vgrooves"
n_grooves = 100
ndf = "beckmann"
m = [0.2, 0.6]
"""


@pytest.mark.slow  # 11 s; tests/test_progress_lines.py keeps the progress output's checks
def test_progress_lines_show_parameter_values_not_task_ids(tmp_path):
    spec = load_sweep_text(tmp_path, TINY_TOML)
    lines = []
    run_sweep(spec, tmp_path / "out", workers=2, progress=lines.append)
    done = [ln for ln in lines if "/12" in ln]
    assert len(done) == len(spec.tasks) == 12
    for t in spec.tasks:
        assert t.id not in "\n".join(lines)  # no hashed ids …
    for k in range(1, 13):
        assert sum(bool(re.search(rf"\b{k}/12\b", ln)) for ln in done) == 1  # … but k/N
    for ln in done:  # and the task's parameters
        assert "vg" in ln and ("m=0.2" in ln or "m=0.6" in ln)
        assert ("aluminium" in ln) + ("1.5+0.25i" in ln) + ("1.33" in ln) == 1
        assert "θi=30°" in ln or "θi=70°" in ln


def load_sweep_text(tmp_path, text, name="s.toml"):
    p = tmp_path / name
    p.write_text(text)
    return load_sweep(p)


@pytest.mark.parametrize(
    "where, key",
    [("surface", "m"), ("scene", "ior"), ("top", "theta_i"), ("top", "scenes"), ("top", "models")],
)
def test_empty_axis_is_a_usage_error(where, key):
    from microsim.errors import UsageError

    data = json.loads(json.dumps(TINY))
    if where == "surface":
        data["scenes"][0]["surface"][key] = []
    elif where == "scene":
        data["scenes"][0][key] = []
    else:
        data[key] = []
    with pytest.raises(UsageError, match=rf"\b{key}\b.*empty|empty.*\b{key}\b"):
        expand_tasks(data, "sweeps/x.toml")


def test_csv_material_column_is_plain_text(tmp_path):
    spec = load_sweep_text(
        tmp_path,
        TINY_TOML.replace("m = [0.2, 0.6]", "m = 0.3").replace(
            "theta_i = [30, 70]", "theta_i = [30]"
        ),
    )
    run_sweep(spec, tmp_path / "out", workers=2)
    with open(tmp_path / "out" / "summary.csv", newline="") as fh:
        rows = list(csv.reader(fh))
    col = rows[0].index("material")
    assert all(len(r) == len(rows[0]) for r in rows)
    assert {r[col] for r in rows[1:]} == {"aluminium", "1.5+0.25i", "1.33"}
    assert '"' not in (tmp_path / "out" / "summary.csv").read_text()


def _free_port():
    import socket

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_unreachable_scheduler_fails_fast_naming_the_address(tmp_path):
    pytest.importorskip("distributed")
    import time

    from microsim.errors import EnvironmentFailure

    addr = f"tcp://127.0.0.1:{_free_port()}"  # loopback, nothing listens
    t0 = time.monotonic()
    with pytest.raises(EnvironmentFailure, match=addr):
        run_sweep(tiny_spec(), tmp_path / "out", scheduler=addr, connect_timeout=1.0)
    assert time.monotonic() - t0 < 20
    assert not (tmp_path / "out").exists()


# --- effort options and the noise floor ------------------------------------------------------
def test_rays_and_quick_give_new_tasks_and_the_exact_model_sits_on_its_noise_floor(tmp_path):
    """``--rays``/``--quick`` change every task (new ids: a quick result never stands in for a
    full one); each record carries the ray-noise floor, and the exact model (TS with V-groove G
    on V-grooves) shows a relative RMS error at that floor: rel_rms² ≈ floor²·χ²_k/k over the
    k ≥ 20 energy bins, so their ratio lies in [0.5, 1.6] far beyond any plausible draw."""
    from microsim.app.runner.planning import QUICK
    from microsim.app.sweep.grid import with_effort

    spec = load_sweep("sweeps/quickstart.toml")
    quick = with_effort(spec, rays=30_000, quick=True)
    assert {t.id for t in quick.tasks}.isdisjoint({t.id for t in spec.tasks})
    assert all(t.rays == 30_000 for t in quick.tasks)
    assert all(t.theta_bins <= QUICK.max_bins[0] for t in quick.tasks)
    assert all(t.rays == min(s.rays, QUICK.max_rays) for t, s in
               zip(with_effort(spec, quick=True).tasks, spec.tasks))  # fmt: skip
    run_sweep(with_effort(spec, rays=200_000), tmp_path / "out", workers=2)
    rows = list(csv.DictReader(open(tmp_path / "out" / "summary.csv")))
    exact = [r for r in rows if r["model"] == "ts-vgroove"]
    assert exact and all(r["noise_floor"] for r in rows)
    for r in exact:
        assert 0.5 < float(r["rel_rms"]) / float(r["noise_floor"]) < 1.6, r
