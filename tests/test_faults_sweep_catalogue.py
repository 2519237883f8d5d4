"""Faults of `microsim sweep` and `microsim report` from a new-user corpus: a worker process
killed, a SIGTERM to the sweep, a FIFO among the task results, duplicate tasks, errors only a
worker used to find, catalogue scene names that clash with the report's own files, and a
scene file edited before ``report --resume``.

Through ``microsim.app.cli.main`` in-process (a patched ``sweep.execution.run_task`` reaches the
worker processes, which a fork server starts, by reference: module-level functions only) except the
SIGTERM, which needs its own process.
"""

import functools
import json
import os
import re
import signal
import stat
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest
from test_faults_cli import TINY, _fast, run_cli, scene, tree
from test_faults_sweep import OK, _nothing_written, _one_error_line, edit

from microsim.app import sweep
from microsim.app.cli import main
from microsim.checkpoints import interrupt_at

THREE = OK.replace("m = 0.3", "m = [0.2, 0.3, 0.4]")
_REAL_RUN_TASK = sweep.run_task


@pytest.fixture
def fast(monkeypatch):
    _fast(monkeypatch)


def _killing_run_task(kill: dict, task, out_dir):
    """``sweep.run_task``, but the worker running the task with ``m == kill["m"]`` SIGKILLs
    itself (the first time only, unless ``kill["always"]``; ``kill["marker"]`` is the file
    that says it has)."""
    if task.surface["m"] == kill["m"]:
        try:
            os.close(os.open(kill["marker"], os.O_CREAT | os.O_EXCL | os.O_WRONLY))
            first = True
        except FileExistsError:
            first = False
        if first or kill["always"]:
            os.kill(os.getpid(), signal.SIGKILL)
    return _REAL_RUN_TASK(task, out_dir)


def _kill_in_task(monkeypatch, **kill) -> None:
    """Workers run ``_killing_run_task`` with ``kill`` instead of ``sweep.run_task``."""
    monkeypatch.setattr(sweep.execution, "run_task", functools.partial(_killing_run_task, kill))


def _task_records(out):
    return {p.stem: json.loads(p.read_text()) for p in (out / "tasks").glob("*.json")}


def test_killed_worker_task_is_rerun(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "s.toml").write_text(THREE)
    _kill_in_task(monkeypatch, m=0.2, always=False, marker=str(tmp_path / "killed"))
    rc = main(["sweep", "s.toml", "--out", "out", "--workers", "2"])
    err = capsys.readouterr().err
    assert (tmp_path / "killed").exists()
    assert rc == 0 and "Traceback" not in err, err
    recs = _task_records(tmp_path / "out")
    assert sorted(r["task"]["surface"]["m"] for r in recs.values()) == [0.2, 0.3, 0.4]
    assert len((tmp_path / "out" / "summary.csv").read_text().splitlines()) == 1 + 3


def test_worker_killed_every_time_fails_with_one_line_and_keeps_finished_tasks(
    tmp_path, monkeypatch, capsys
):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "s.toml").write_text(THREE)
    _kill_in_task(monkeypatch, m=0.4, always=True, marker=str(tmp_path / "killed"))
    rc = main(["sweep", "s.toml", "--out", "out", "--workers", "1"])
    err = capsys.readouterr().err
    assert rc == 1 and "Traceback" not in err, err
    last = err.strip().splitlines()[-1]
    assert last.startswith("microsim: error: ") and "worker" in last and "2/3" in last, err
    recs = _task_records(tmp_path / "out")
    assert sorted(r["task"]["surface"]["m"] for r in recs.values()) == [0.2, 0.3]
    assert all(r["rays"] == 20_000 for r in recs.values())
    assert not (tmp_path / "out" / "summary.csv").exists()


def test_fifo_in_place_of_a_task_file_is_refused_without_opening_it(tmp_path, monkeypatch, capsys):
    """The rerun names the FIFO and stops at once (it used to block reading it: a thread
    unblocks such a reader after a few seconds, so the old behaviour fails instead of hanging)."""
    monkeypatch.chdir(tmp_path)
    (tmp_path / "s.toml").write_text(THREE)
    assert main(["sweep", "s.toml", "--out", "out", "--workers", "1"]) == 0
    victim = sorted((tmp_path / "out" / "tasks").glob("*.json"))[1]
    victim.unlink()
    others = {p: p.read_bytes() for p in (tmp_path / "out" / "tasks").iterdir()}
    os.mkfifo(victim)
    capsys.readouterr()
    stop = threading.Event()

    def unblock():
        stop.wait(5)
        while not stop.is_set():
            try:
                os.close(os.open(victim, os.O_WRONLY | os.O_NONBLOCK))
            except OSError:  # no reader
                pass
            stop.wait(0.05)

    thread = threading.Thread(target=unblock, daemon=True)
    thread.start()
    t0 = time.monotonic()
    try:
        rc = main(["sweep", "s.toml", "--out", "out", "--workers", "1"])
    finally:
        stop.set()
        thread.join()
    line = _one_error_line(capsys)
    assert time.monotonic() - t0 < 5
    assert rc == 2 and str(victim) in line and "FIFO" in line, line
    assert stat.S_ISFIFO(victim.stat().st_mode)  # left in place, nothing computed
    assert {p: p.read_bytes() for p in (tmp_path / "out" / "tasks").iterdir() if p != victim} == (
        others
    )


@pytest.mark.parametrize(
    "content, words",
    [
        (edit("theta_i = [30]", "theta_i = [30, 30.0]"), ["theta_i", "30"]),
        (edit("m = 0.3", "m = [0.3, 0.4, 0.3]"), ["scenes[0]", "surface.m", "0.3"]),
        (edit('ior = "aluminium"', 'ior = ["aluminium", 1.5, "aluminium"]'), ["scenes[0]", "ior"]),
        (OK + OK[OK.index("[[scenes]]") :], ["scenes[1]", "scenes[0]"]),
    ],
    ids=["theta_i", "surface-axis", "ior", "identical-scenes"],
)
def test_duplicate_tasks_are_refused(tmp_path, monkeypatch, capsys, content, words):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "dup.toml").write_text(content)
    rc = main(["sweep", "dup.toml", "--workers", "1"])
    line = _one_error_line(capsys)
    assert rc == 2 and "dup.toml" in line and "duplicate" in line, line
    for w in words:
        assert w in line, line
    _nothing_written(tmp_path, ["dup.toml"])


def _heightfield_sweep(tmp_path, heights):
    np.save(tmp_path / "h.npy", heights)
    return edit(
        'kind = "vgrooves"\nn_grooves = 100\nndf = "beckmann"\nm = 0.3',
        'kind = "file"\npath = "h.npy"\ndx = 1.0',
    )


def _nan_heights():
    h = np.zeros((16, 16))
    h[3, 4] = np.nan
    return h


@pytest.mark.parametrize(
    "make, words",
    [
        (lambda tmp: edit("rays = 20_000", "rays = 100_000_000_000_000_000_000"), ["rays"]),
        (lambda tmp: _heightfield_sweep(tmp, _nan_heights()), ["surface.path", "h.npy", "NaN"]),
        (lambda tmp: _heightfield_sweep(tmp, np.zeros((16, 16, 2))), ["surface.path", "2D"]),
    ],
    ids=["rays-1e20", "nan-heightfield", "3d-heightfield"],
)
def test_task_errors_are_found_before_any_output_exists(tmp_path, monkeypatch, capsys, make, words):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "bad.toml").write_text(make(tmp_path))
    inputs = sorted(p.name for p in tmp_path.iterdir())
    rc = main(["sweep", "bad.toml", "--workers", "1"])
    line = _one_error_line(capsys)
    assert rc == 2 and "bad.toml" in line, line
    for w in words:
        assert w in line, line
    _nothing_written(tmp_path, inputs)


def _group_ends(pgid: int, within: float) -> bool:
    """Whether process group ``pgid`` is empty within ``within`` seconds (the fork server
    that started the workers exits just after the sweep, once its last client is gone)."""
    t0 = time.monotonic()
    while time.monotonic() - t0 < within:
        try:
            os.killpg(pgid, 0)
        except ProcessLookupError:
            return True
        time.sleep(0.05)
    return False


def _sweep_with_a_task_done(tmp_path) -> tuple[subprocess.Popen, Path]:
    """A CLI sweep of six tasks of 10⁶ rays in its own process group, once its first task
    is done: (the process, the file its stderr goes to)."""
    (tmp_path / "s.toml").write_text(
        THREE.replace("m = [0.2, 0.3, 0.4]", "m = [0.2, 0.3, 0.4, 0.5, 0.6, 0.7]").replace(
            "rays = 20_000", "rays = 1_000_000"
        )
    )
    log = tmp_path / "stderr.txt"
    argv = [sys.executable, "-m", "microsim.app.cli", "sweep", "s.toml", "--out", "out"]
    with open(log, "w") as err:  # a file, not a pipe: orphaned workers would keep a pipe open
        proc = subprocess.Popen(argv, cwd=tmp_path, stderr=err, start_new_session=True)
    t0 = time.monotonic()
    while not re.search(r"\b1/6 done", log.read_text()) and proc.poll() is None:
        if time.monotonic() - t0 > 120:
            os.killpg(proc.pid, signal.SIGKILL)
            pytest.fail(f"no task done in 120 s: {log.read_text()}")
        time.sleep(0.05)
    return proc, log


def test_sigterm_to_the_sweep_stops_its_workers(tmp_path):
    """SIGTERM to the main process only (as `kill PID` sends it): the workers stop too (no
    process of the sweep's group outlives it), finished tasks are kept complete, no summary,
    one line saying how to continue, status 143."""
    proc, log = _sweep_with_a_task_done(tmp_path)
    try:
        proc.send_signal(signal.SIGTERM)
        rc = proc.wait(timeout=60)
        assert _group_ends(proc.pid, within=10)  # no worker left in the sweep's process group
    finally:
        try:
            os.killpg(proc.pid, signal.SIGKILL)
        except ProcessLookupError:
            pass
    text = log.read_text()
    if rc == 0:
        pytest.skip("the sweep finished before the signal arrived")
    assert rc == 143 and "Traceback" not in text, text
    last = text.strip().splitlines()[-1]
    assert "terminated" in last and "rerun" in last, text
    recs = _task_records(tmp_path / "out")
    assert 1 <= len(recs) < 6 and all(r["rays"] == 1_000_000 for r in recs.values())
    assert not (tmp_path / "out" / "summary.csv").exists()


def test_a_sweep_killed_outright_leaves_no_worker_running(tmp_path):
    """SIGKILL to the main process (the out-of-memory killer, a batch system): it can stop
    nothing, yet its workers and the fork server that started them end within seconds
    instead of waiting for tasks forever, and the finished task stays complete."""
    proc, log = _sweep_with_a_task_done(tmp_path)
    try:
        proc.kill()
        assert proc.wait(timeout=60) == -signal.SIGKILL
        assert _group_ends(proc.pid, within=10), log.read_text()
    finally:
        try:
            os.killpg(proc.pid, signal.SIGKILL)
        except ProcessLookupError:
            pass
    recs = _task_records(tmp_path / "out")
    assert 1 <= len(recs) < 6 and all(r["rays"] == 1_000_000 for r in recs.values())


# --- microsim report ----------------------------------------------------------------------------
@pytest.mark.parametrize("name", ["index.md", "mikkelsen-fig6.png", "regimes.png"])
def test_catalogue_scene_named_like_a_report_file_is_refused_up_front(
    tmp_path, monkeypatch, capsys, fast, name
):
    monkeypatch.chdir(tmp_path)
    cat = tmp_path / "cat"
    cat.mkdir()
    scene(cat, "tiny")
    scene(cat, name, file_name="clash.toml")
    before = tree(tmp_path)
    status, lines, err = run_cli(capsys, "report", "--quick", "--catalogue", cat, "--out", "rep")
    assert status == 2 and len(lines) == 1 and "Traceback" not in err, err
    assert "clash.toml" in lines[0] and "name" in lines[0] and name in lines[0], err
    assert tree(tmp_path) == before


def test_report_resume_recomputes_scenes_whose_file_was_edited(tmp_path, monkeypatch, capsys, fast):
    """Both the finished scene and the interrupted one (its complete tallies saved) are run
    anew from their edited files: no report kept, no tallies of the old scene continued."""
    monkeypatch.chdir(tmp_path)
    cat = tmp_path / "cat"
    cat.mkdir()
    a = scene(cat, "tiny-a")
    b = scene(cat, "tiny-b", text=TINY.format(name="tiny-b").replace("seed = 3", "seed = 4"))
    opts = ["report", "--quick", "--catalogue", cat, "--out", "rep", "--no-progress"]
    with interrupt_at("fits", after=1) as hit:  # tiny-a finished, tiny-b's tallies saved
        assert run_cli(capsys, *opts)[0] == 130
    assert hit["fired"] and (tmp_path / "rep" / ".tiny-b.partial" / "meta.json").is_file()
    a.write_text(a.read_text().replace("seed = 3", "seed = 7"))
    b.write_text(b.read_text().replace("seed = 4", "seed = 8"))
    status, lines, err = run_cli(capsys, *opts, "--resume")
    assert status == 0, err
    assert not [line for line in lines if "finished earlier" in line], err
    for name, seed in (("tiny-a", 7), ("tiny-b", 8)):
        verdicts = json.loads((tmp_path / "rep" / name / "verdicts.json").read_text())
        assert verdicts["seed"] == seed
