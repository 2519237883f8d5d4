"""Fault corpus of `microsim sweep`: bad sweep files and options through the CLI in-process.

For each case: the exit status (2 usage, 1 environment), exactly one line on stderr that names
the file, key, option or path at fault, no traceback, and nothing written (no output
directory, nothing under the working directory). Plus Ctrl-C through the in-process hook and a
real SIGINT to a CLI subprocess: exit 130, finished tasks kept complete, no summary."""

import json
import os
import re
import signal
import subprocess
import sys
import time

import pytest

from microsim.app.cli import main

OK = """
name = "ok"
rays = 20_000
theta_bins = 10
phi_bins = 7
theta_i = [30]
models = ["vgroove"]
[[scenes]]
name = "vg"
ior = "aluminium"
[scenes.surface]
kind = "vgrooves"
n_grooves = 100
ndf = "beckmann"
m = 0.3
"""


def edit(old, new):
    assert old in OK
    return OK.replace(old, new)


# (case id, sweep file content (str or bytes), words the error line must contain besides the file)
FILES = [
    ("unknown-top-key", OK + "\n", None),  # placeholder replaced below
    ("rays-zero", edit("rays = 20_000", "rays = 0"), ["rays"]),
    ("rays-float", edit("rays = 20_000", "rays = 2e4"), ["rays"]),
    ("rays-string", edit("rays = 20_000", 'rays = "many"'), ["rays"]),
    ("seed-float", edit("rays = 20_000", "rays = 20_000\nseed = 1.5"), ["seed"]),
    ("seed-negative", edit("rays = 20_000", "rays = 20_000\nseed = -1"), ["seed"]),
    ("theta-empty", edit("theta_i = [30]", "theta_i = []"), ["theta_i", "empty"]),
    ("theta-95", edit("theta_i = [30]", "theta_i = [95]"), ["theta_i"]),
    ("theta-89.995", edit("theta_i = [30]", "theta_i = [89.995]"), ["theta_i", "89.99"]),
    ("theta-bool", edit("theta_i = [30]", "theta_i = [true]"), ["theta_i"]),
    ("theta-nan", edit("theta_i = [30]", "theta_i = [nan]"), ["theta_i"]),
    ("models-empty", edit('models = ["vgroove"]', "models = []"), ["models"]),
    ("models-unknown", edit('models = ["vgroove"]', 'models = ["cook"]'), ["models"]),
    ("masking", edit("rays = 20_000", 'rays = 20_000\nmasking = "fast"'), ["masking"]),
    ("theta-bins-1", edit("theta_bins = 10", "theta_bins = 1"), ["theta_bins"]),
    ("phi-bins-1", edit("phi_bins = 7", "phi_bins = 1"), ["phi_bins"]),
    ("bins-huge", edit("theta_bins = 10", "theta_bins = 1_000_000"), ["theta_bins"]),
    ("scenes-empty", OK.split("[[scenes]]")[0] + "scenes = []\n", ["scenes"]),
    ("scenes-missing", OK.split("[[scenes]]")[0], ["scenes"]),
    ("scenes-not-tables", OK.split("[[scenes]]")[0] + "scenes = [1]\n", ["scenes[0]"]),
    (
        "scene-unknown-key",
        edit('name = "vg"', 'name = "vg"\ncolour = "red"'),
        ["scenes[0]", "colour"],
    ),
    ("scene-no-surface", OK.split("[scenes.surface]")[0], ["scenes[0]", "surface"]),
    ("surface-no-kind", edit('kind = "vgrooves"\n', ""), ["scenes[0]", "surface.kind"]),
    ("surface-kind", edit('kind = "vgrooves"', 'kind = "fractal"'), ["surface.kind"]),
    ("surface-unknown-key", edit("m = 0.3", "m = 0.3\nroughness = 2"), ["surface.roughness"]),
    ("m-empty", edit("m = 0.3", "m = []"), ["surface.m", "empty"]),
    ("m-negative", edit("m = 0.3", "m = [0.3, -1.0]"), ["surface.m"]),
    ("m-nested", edit("m = 0.3", "m = [[0.3]]"), ["surface.m"]),
    ("n-grooves-zero", edit("n_grooves = 100", "n_grooves = 0"), ["surface.n_grooves"]),
    ("ior-empty", edit('ior = "aluminium"', "ior = []"), ["scenes[0]", "ior", "empty"]),
    ("ior-unknown", edit('ior = "aluminium"', 'ior = ["unobtainium"]'), ["scenes[0]", "ior"]),
    ("ior-negative-k", edit('ior = "aluminium"', "ior = [[1.5, -1]]"), ["scenes[0]", "ior"]),
    ("ior-zero", edit('ior = "aluminium"', "ior = 0"), ["scenes[0]", "ior"]),
    ("scene-name-empty", edit('name = "vg"', 'name = ""'), ["scenes[0]", "name"]),
    ("scene-name-escape", edit('name = "vg"', 'name = "../../escape"'), ["scenes[0]", "name"]),
    ("scene-name-number", edit('name = "vg"', "name = 5"), ["scenes[0]", "name"]),
    ("sweep-name-escape", edit('name = "ok"', 'name = "../../escape"'), ["name"]),
    ("sweep-name-empty", edit('name = "ok"', 'name = ""'), ["name"]),
    ("sweep-name-dot", edit('name = "ok"', 'name = ".."'), ["name"]),
    ("description-number", edit('name = "ok"', 'name = "ok"\ndescription = 3'), ["description"]),
    (
        "heightfield-missing",
        edit(
            'kind = "vgrooves"\nn_grooves = 100\nndf = "beckmann"\nm = 0.3',
            'kind = "file"\npath = "nowhere.npy"\ndx = 1.0',
        ),
        ["surface.path"],
    ),
    (
        "grid-too-big",
        edit(
            "m = 0.3",
            "n_grooves = ["
            + ", ".join(map(str, range(100, 600)))
            + "]\nm = ["
            + ", ".join(f"0.{k:03d}" for k in range(1, 300))
            + "]",
        ).replace("n_grooves = 100\n", ""),
        ["scenes[0]", "tasks"],
    ),
    ("not-toml", "this is = not [toml\n", ["TOML"]),
    ("empty-file", "", ["scenes"]),
    ("non-utf8", OK.encode().replace(b'"vg"', b'"v\xe9g"'), ["UTF-8"]),
    ("binary", bytes(range(256)) * 4, []),
    ("utf16", OK.encode("utf-16"), []),
    ("nul-bytes", OK.replace('"vg"', '"v\x00g"'), ["NUL"]),
    ("nested-400000", "a = " + "[" * 400_000 + "]" * 400_000 + "\n", ["nested"]),
]
FILES[0] = ("unknown-top-key", edit("rays = 20_000", "rays = 20_000\nraysx = 1"), ["raysx"])


def _one_error_line(capsys):
    cap = capsys.readouterr()
    lines = cap.err.strip().splitlines()
    assert "Traceback" not in cap.err, cap.err  # the whole stderr: the traceback shows the cause
    assert len(lines) == 1, cap.err
    return lines[0]


def _nothing_written(tmp_path, keep):
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(keep)


@pytest.mark.parametrize("case, content, words", FILES, ids=[c[0] for c in FILES])
def test_bad_sweep_file(tmp_path, monkeypatch, capsys, case, content, words):
    monkeypatch.chdir(tmp_path)  # the default output would be sweeps/out
    sweep = tmp_path / "bad.toml"
    (sweep.write_bytes if isinstance(content, bytes) else sweep.write_text)(content)
    rc = main(["sweep", str(sweep), "--workers", "1"])
    line = _one_error_line(capsys)
    assert rc == 2
    assert line.startswith("microsim: error: ") and str(sweep) in line
    for w in words:
        assert w in line, line
    _nothing_written(tmp_path, ["bad.toml"])


def test_a_byte_order_mark_is_accepted(tmp_path):
    from microsim.app.sweep import load_sweep

    (tmp_path / "bom.toml").write_bytes(b"\xef\xbb\xbf" + OK.encode())
    (tmp_path / "ok.toml").write_text(OK)
    assert load_sweep(tmp_path / "bom.toml").tasks == load_sweep(tmp_path / "ok.toml").tasks


def _write_ok(tmp_path):
    sweep = tmp_path / "ok.toml"
    sweep.write_text(OK)
    return sweep


def _free_port():
    import socket

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _setup_option(case, tmp_path):
    """(argv after the sweep file, expected status, words in the error line, files kept)."""
    if case == "no-such-file":
        return None, 2, ["missing.toml", "no such"], []
    if case == "directory":
        (tmp_path / "dir.toml").mkdir()
        return None, 2, ["dir.toml", "directory"], ["dir.toml"]
    if case == "dev-zero":
        return None, 2, ["/dev/zero", "regular"], []
    if case == "symlink-loop":
        (tmp_path / "loop.toml").symlink_to(tmp_path / "loop.toml")
        return None, 2, ["loop.toml", "symbolic links"], ["loop.toml"]
    if case == "workers-0":
        return ["--workers", "0"], 2, ["--workers"], []
    if case == "workers-negative":
        return ["--workers", "-3"], 2, ["--workers"], []
    if case == "out-is-file":
        (tmp_path / "taken").write_text("mine")
        return ["--out", str(tmp_path / "taken")], 2, [str(tmp_path / "taken")], ["taken"]
    if case == "out-parent-is-file":
        (tmp_path / "taken").write_text("mine")
        return ["--out", str(tmp_path / "taken" / "sub")], 2, [str(tmp_path / "taken")], ["taken"]
    if case == "out-foreign-dir":
        (tmp_path / "mine").mkdir()
        (tmp_path / "mine" / "summary.csv").write_text("my own table")
        return ["--out", str(tmp_path / "mine")], 2, [str(tmp_path / "mine"), "tasks"], ["mine"]
    if case == "out-tasks-is-file":
        (tmp_path / "o").mkdir()
        (tmp_path / "o" / "tasks").write_text("x")
        return ["--out", str(tmp_path / "o")], 2, [str(tmp_path / "o" / "tasks")], ["o"]
    if case == "out-is-cwd":  # the checks every output path gets, as for microsim run
        return ["--out", "."], 2, ["--out", "current directory"], []
    if case == "out-name-too-long":
        return ["--out", str(tmp_path / ("n" * 250))], 2, ["--out", "bytes long"], []
    if case == "scheduler-timeout-0":
        return (
            ["--scheduler", "tcp://127.0.0.1:1", "--scheduler-timeout", "0"],
            2,
            ["--scheduler-timeout"],
            [],
        )
    if case == "scheduler-bad-address":
        pytest.importorskip("distributed")
        return ["--scheduler", "not an address"], 2, ["--scheduler", "not an address"], []
    if case == "scheduler-bad-scheme":
        pytest.importorskip("distributed")
        return ["--scheduler", "foo://127.0.0.1:1"], 2, ["--scheduler", "foo://127.0.0.1:1"], []
    if case == "scheduler-unreachable":
        pytest.importorskip("distributed")
        addr = f"tcp://127.0.0.1:{_free_port()}"  # loopback, nothing listens there
        return ["--scheduler", addr, "--scheduler-timeout", "1"], 1, [addr], []
    raise AssertionError(case)


OPTIONS = [
    "no-such-file",
    "directory",
    "dev-zero",
    "symlink-loop",
    "workers-0",
    "workers-negative",
    "out-is-file",
    "out-parent-is-file",
    "out-foreign-dir",
    "out-tasks-is-file",
    "out-is-cwd",
    "out-name-too-long",
    "scheduler-timeout-0",
    "scheduler-bad-address",
    "scheduler-bad-scheme",
    "scheduler-unreachable",
]


@pytest.mark.parametrize("case", OPTIONS)
def test_bad_option_or_path(tmp_path, monkeypatch, capsys, case):
    monkeypatch.chdir(tmp_path)
    argv, status, words, keep = _setup_option(case, tmp_path)
    before = {p: p.read_bytes() for p in tmp_path.rglob("*") if p.is_file()}
    if argv is None:
        sweep = {
            "no-such-file": str(tmp_path / "missing.toml"),
            "directory": str(tmp_path / "dir.toml"),
            "dev-zero": "/dev/zero",
            "symlink-loop": str(tmp_path / "loop.toml"),
        }[case]
        argv = []
    else:
        sweep = str(_write_ok(tmp_path))
        keep = keep + ["ok.toml"]
        before = {p: p.read_bytes() for p in tmp_path.rglob("*") if p.is_file()}
    t0 = time.monotonic()
    rc = main(["sweep", sweep, *argv])
    line = _one_error_line(capsys)
    assert time.monotonic() - t0 < 15
    assert rc == status, line
    for w in words:
        assert w in line, line
    _nothing_written(tmp_path, keep)
    assert {p: p.read_bytes() for p in tmp_path.rglob("*") if p.is_file()} == before


@pytest.mark.skipif(
    not hasattr(os, "geteuid") or os.geteuid() == 0,
    reason="root writes through any permission bits",
)
def test_unwritable_out_parent_is_an_environment_failure(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    sweep = _write_ok(tmp_path)
    ro = tmp_path / "ro"
    ro.mkdir(mode=0o555)
    try:
        rc = main(["sweep", str(sweep), "--out", str(ro / "out")])
        line = _one_error_line(capsys)
    finally:
        ro.chmod(0o755)
    assert rc == 1 and str(ro / "out") in line
    assert list(ro.iterdir()) == []


def test_a_temporary_folder_too_deep_for_the_fork_server_is_an_environment_failure(tmp_path):
    """The fork server's socket lives in TMPDIR, and a socket path has at most ~107 bytes:
    one line naming the folder and the fix, status 1, nothing written. In its own process:
    a fork server already running (an earlier test's) would not start again."""
    sweep = _write_ok(tmp_path)
    deep = tmp_path / ("t" * 120)
    deep.mkdir()
    before = sorted(p.name for p in tmp_path.iterdir())
    r = subprocess.run(
        [sys.executable, "-m", "microsim.app.cli", "sweep", str(sweep), "--out", "out"],
        cwd=tmp_path,
        env={**os.environ, "TMPDIR": str(deep)},
        capture_output=True,
        text=True,
        timeout=120,
    )
    lines = r.stderr.strip().splitlines()
    assert r.returncode == 1 and len(lines) == 1 and "Traceback" not in r.stderr, r.stderr
    assert lines[0].startswith("microsim: error: ") and "fork server" in lines[0], r.stderr
    assert str(deep) in lines[0] and "TMPDIR" in lines[0], r.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == before


def test_concurrent_sweep_to_the_same_out_is_refused(tmp_path, monkeypatch, capsys):
    """While one sweep holds OUT, a second one to the same OUT stops with one line."""
    from microsim import atomic
    from microsim.app.sweep import LOCK_FILE

    monkeypatch.chdir(tmp_path)
    sweep = _write_ok(tmp_path)
    out = tmp_path / "out"
    (out / "tasks").mkdir(parents=True)
    with atomic.output_lock(out, out / LOCK_FILE, holder="sweep"):
        rc = main(["sweep", str(sweep), "--out", str(out)])
        line = _one_error_line(capsys)
    assert rc == 2 and str(out) in line and "another" in line
    assert list((out / "tasks").iterdir()) == []


def test_stale_temporary_files_are_cleaned_and_results_kept(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    sweep = _write_ok(tmp_path)
    out = tmp_path / "out"
    assert main(["sweep", str(sweep), "--out", str(out), "--workers", "1"]) == 0
    done = sorted((out / "tasks").glob("*.json"))
    assert len(done) == 1
    (out / "tasks" / ".vg-0123.json-xyz.tmp").write_text('{"id": ')  # a SIGKILLed write
    assert main(["sweep", str(sweep), "--out", str(out), "--workers", "1"]) == 0
    assert "1 already done" in capsys.readouterr().out
    assert sorted(p.name for p in (out / "tasks").iterdir()) == [p.name for p in done]


MULTI = edit("m = 0.3", "m = [0.2, 0.3, 0.4, 0.5]").replace("theta_i = [30]", "theta_i = [30, 60]")


def _complete_tasks(out, rays):
    recs = [json.loads(p.read_text()) for p in sorted((out / "tasks").glob("*.json"))]
    assert all(r["rays"] == rays and not r.get("partial") for r in recs)
    return recs


@pytest.mark.parametrize("after", [0, pytest.param(3, marks=pytest.mark.slow)])
def test_interrupt_via_hook(tmp_path, monkeypatch, capsys, after):
    from microsim.checkpoints import interrupt_at

    monkeypatch.chdir(tmp_path)
    sweep = tmp_path / "multi.toml"
    sweep.write_text(MULTI)
    out = tmp_path / "out"
    with interrupt_at("sweep-task", after=after) as state:
        rc = main(["sweep", str(sweep), "--out", str(out), "--workers", "2"])
    err = capsys.readouterr().err
    assert state["fired"] and rc == 130 and "Traceback" not in err
    last = err.strip().splitlines()[-1]
    assert re.search(r"interrupted: \d+/8 tasks done", last) and "rerun" in last
    recs = _complete_tasks(out, 20_000)
    assert after + 1 <= len(recs) < 8
    assert not list(out.glob("summary*")) and not list(out.glob("*.png"))
    assert not list(out.rglob(".*.tmp"))
    # rerun: only the rest, then the summary holds every task once
    assert main(["sweep", str(sweep), "--out", str(out), "--workers", "2"]) == 0
    assert f"{8 - len(recs)} tasks computed, {len(recs)} already done" in capsys.readouterr().out
    lines = (out / "summary.csv").read_text().strip().splitlines()
    assert len(lines) == 1 + 8


def test_real_sigint_to_the_cli_process_group(tmp_path):
    """Ctrl-C in a terminal: SIGINT to the whole process group (the CLI and its workers) once
    the first task is done. Exit 130 within seconds, every kept task complete, no summary."""
    sweep = tmp_path / "slow.toml"
    sweep.write_text(MULTI.replace("rays = 20_000", "rays = 2_000_000"))
    out = tmp_path / "out"
    proc = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "microsim.app.cli",
            "sweep",
            str(sweep),
            "--out",
            str(out),
            "--workers",
            "2",
        ],
        stderr=subprocess.PIPE,
        text=True,
        start_new_session=True,
    )
    try:
        err = []
        for line in proc.stderr:  # wait for the first finished task
            err.append(line)
            if re.search(r"\b1/8 done", line):
                break
        os.killpg(proc.pid, signal.SIGINT)
        t0 = time.monotonic()
        err.append(proc.stderr.read())
        rc = proc.wait(timeout=60)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
    text = "".join(err)
    if rc == 0:
        pytest.skip("the sweep finished before the signal arrived")
    assert rc == 130, text
    assert time.monotonic() - t0 < 30
    assert "Traceback" not in text and "rerun" in text.strip().splitlines()[-1]
    recs = _complete_tasks(out, 2_000_000)
    assert 1 <= len(recs) < 8
    assert not (out / "summary.csv").exists()
