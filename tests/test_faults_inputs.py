"""Fault suite of scene files, heightfield files and command-line options: each bad input is
refused before anything is built or written, with one stderr line naming the file or option,
the key and the allowed values (exit status 2); interrupts during start-up exit with 130;
a closed stderr runs without progress bars; the charts draw the schema's smallest bin grid;
``microsim --version``. In-process ``microsim.app.cli.main`` on the tiny scene of
test_faults_cli.py, except the start-up interrupt, which needs a real process.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from types import SimpleNamespace

import numpy as np
import pytest
from test_faults_cli import TINY, _fast, run_cli, scene, tree

import microsim
from microsim import analytic
from microsim.app import runner, sweep
from microsim.app.cli import main

HF_SCENE = 'name = "hf"\n[surface]\nkind = "file"\npath = "{path}"\ndx = 1.0\n'


@pytest.fixture
def fast(monkeypatch):
    _fast(monkeypatch)


def _edit(old, new):
    return lambda tmp: scene(
        tmp, text=TINY.format(name="bad").replace(old, new), file_name="bad.toml"
    )


def _deep(tmp):
    return scene(tmp, text="a = " + "[" * 400_000 + "]" * 400_000 + "\n", file_name="deep.toml")


def _loop(tmp):
    (tmp / "loop.toml").symlink_to(tmp / "loop.toml")
    return tmp / "loop.toml"


def _heightfield(name, write):
    def make(tmp):
        write(tmp / name)
        return scene(tmp, text=HF_SCENE.format(path=name), file_name="hf.toml")

    return make


def _npy(array):
    return lambda p: np.save(p, array)


_NOISE = np.random.default_rng(0).normal(size=(16, 16))
BAD_SCENES = [
    # (id, maker(tmp) → scene path, words the one line must contain)
    ("nested-400000", _deep, ["deep.toml", "nested"]),
    ("symlink-loop", _loop, ["loop.toml", "symbolic links"]),
    ("scene-path-5000", lambda tmp: tmp / ("s" * 5000 + ".toml"), ["name too long"]),
    ("rays-1e30", _edit("rays = 20000", "rays = " + "1" + "0" * 30), ["simulation.rays", "2"]),
    ("ior-1e308", _edit('ior = "aluminium"', "ior = 1e308"), ["material.ior", "1000"]),
    ("ior-k-1e200", _edit('ior = "aluminium"', "ior = [1.5, 1e200]"), ["material.ior", "1000"]),
    ("ior-1", _edit('ior = "aluminium"', "ior = 1.0"), ["material.ior", "reflects nothing"]),
    ("ior-1-0", _edit('ior = "aluminium"', "ior = [1.0, 0.0]"), ["material.ior", "reflects"]),
    (
        "theta-i-repeated",
        _edit("theta_i = [30]", "theta_i = [30, 60, 30]"),
        ["simulation.theta_i", "30"],
    ),
    (
        "theta-i-grazing",
        _edit("theta_i = [30]", "theta_i = [89.9999999]"),
        ["simulation.theta_i", "89.99"],
    ),
    ("m-1e-300", _edit("m = 0.3", "m = 1e-300"), ["surface.m", "1e-06"]),
    ("hf-8x5000", _heightfield("h.npy", _npy(np.zeros((8, 5000)))), ["surface.path", "4096"]),
    ("hf-all-zero", _heightfield("h.npy", _npy(np.zeros((16, 16)))), ["surface.path", "flat"]),
    (
        "hf-1e300",
        _heightfield("h.npy", _npy(1e300 * _NOISE)),
        ["hf.toml", "surface.path", "h.npy", "1e+30"],
    ),
    (
        "hf-int64-2^62",
        _heightfield("h.npy", _npy(np.random.default_rng(0).integers(0, 2**62, (16, 16)))),
        ["hf.toml", "surface.path", "h.npy", "tile"],
    ),
    (
        "hf-text-empty",
        _heightfield("h.txt", lambda p: p.write_text("")),
        ["surface.path", "h.txt", "no heights"],
    ),
    (
        "hf-path-5000",
        lambda tmp: scene(tmp, text=HF_SCENE.format(path="h" * 5000 + ".npy"), file_name="hf.toml"),
        ["hf.toml", "surface.path", "name too long"],
    ),
]


@pytest.mark.parametrize("make, words", [c[1:] for c in BAD_SCENES], ids=[c[0] for c in BAD_SCENES])
def test_bad_scene_one_line_before_anything_is_built(
    tmp_path, capsys, monkeypatch, recwarn, make, words
):
    monkeypatch.chdir(tmp_path)
    path = make(tmp_path)
    before = tree(tmp_path) if path.name != "loop.toml" else None
    status, lines, err = run_cli(capsys, "run", path, "--quick", "--threads", "1")
    assert status == 2, err
    assert len(lines) == 1 and "Traceback" not in err, err
    for w in words:
        assert w in lines[0], (w, lines[0])
    assert not [w for w in recwarn if issubclass(w.category, UserWarning)]  # no extra lines
    if before is not None:
        assert tree(tmp_path) == before


def test_a_byte_order_mark_is_accepted(tmp_path, capsys):
    plain = scene(tmp_path)
    bom = tmp_path / "bom.toml"
    bom.write_bytes(b"\xef\xbb\xbf" + plain.read_bytes())
    from microsim.app.scene import load_scene

    assert load_scene(bom).simulation == load_scene(plain).simulation


BAD_OPTIONS = [
    (["--rays", "1e30"], ["--rays", "281,474,976,710,656"]),
    (["--rays", "1" + "0" * 30], ["--rays", "281,474,976,710,656"]),
    (["--rays", str(2**49)], ["--rays", "281,474,976,710,656"]),
    (["--theta-i", "30", "--theta-i", "30"], ["--theta-i", "30", "twice"]),
    (["--theta-i", "30,60,30"], ["--theta-i", "twice"]),
    (["--theta-i", "89.9999999"], ["--theta-i", "89.99"]),
]


@pytest.mark.parametrize("args, words", BAD_OPTIONS, ids=lambda a: " ".join(a)[:30])
def test_bad_run_options_one_line_nothing_written(tmp_path, capsys, monkeypatch, args, words):
    monkeypatch.chdir(tmp_path)
    sc = scene(tmp_path)
    before = tree(tmp_path)
    status, lines, err = run_cli(capsys, "run", sc, "--quick", *args)
    assert status == 2, err
    assert len(lines) == 1 and "Traceback" not in err, err
    for w in words:
        assert w in lines[0], (w, lines[0])
    assert tree(tmp_path) == before


def test_repeated_theta_i_options_add_up(tmp_path, capsys, monkeypatch):
    """``--theta-i 30 --theta-i 60`` means ``--theta-i 30 60`` (and says so in --help)."""
    monkeypatch.chdir(tmp_path)
    sc = scene(tmp_path)
    planned = []
    monkeypatch.setattr(
        runner,
        "execute",
        lambda plan, progress: planned.append(plan) or SimpleNamespace(status=0, document=None),
    )
    status, lines, err = run_cli(capsys, "run", sc, "--theta-i", "30", "--theta-i", "60,70")
    assert status == 0, err
    assert planned[0].theta_i == (30.0, 60.0, 70.0)
    capsys.readouterr()
    with pytest.raises(SystemExit):
        main(["run", "--help"])
    assert "repeat" in " ".join(capsys.readouterr().out.split())


def test_charts_of_the_smallest_bin_grid(tmp_path):
    """theta_bins = 1, phi_bins = 2 (the schema's minima), with a model off by |z| >> 5: the
    hemisphere maps (whose |z| = 5 contour needs two θo bins) and the in-plane curves draw."""
    from microsim.analysis import charts
    from microsim.sim import Bins, simulate
    from microsim.surfaces import vgrooves

    surface = vgrooves(200, analytic.Beckmann(0.3), seed=3)
    res = simulate(surface, "aluminium", [30.0], rays=20_000, bins=Bins(1, 2), seed=3)
    models = {"ts-vgroove": 2.0 * np.asarray(res.brdf)}
    verdicts = [{"theta_i": 30.0, "model": "ts-vgroove", "rel_rms": 1.0}]
    charts.hemisphere_maps(res, models, verdicts, tmp_path / "hemisphere.png")
    charts.inplane_curves(res, models, tmp_path / "inplane.png")
    assert {p.name for p in tmp_path.iterdir()} == {"hemisphere.png", "inplane.png"}


def test_interrupt_while_the_parser_loads_is_one_line(capsys, monkeypatch):
    def interrupted(*a, **k):
        raise KeyboardInterrupt

    monkeypatch.setattr(sweep, "configure_sweep", interrupted)
    status, lines, err = run_cli(capsys, "sweep", "s.toml")
    assert status == 130 and lines == ["microsim: interrupted"], err


def test_an_import_cut_short_by_ctrl_c_is_an_interrupt(capsys, monkeypatch):
    """An extension module whose initialisation SIGINT interrupts raises ImportError (numba's
    "failed to import", pybind11's "initialization failed"): still an interrupt, not a bug."""

    def extension_init(*a, **k):
        try:
            signal.raise_signal(signal.SIGINT)
        except KeyboardInterrupt:
            raise ImportError("initialization failed") from None

    monkeypatch.setattr(sweep, "configure_sweep", extension_init)
    status, lines, err = run_cli(capsys, "sweep", "s.toml")
    assert status == 130 and lines == ["microsim: interrupted"], err
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler


# The console script's way in (`python -m` dies by SIGINT after a KeyboardInterrupt that
# passed through an eval() of a string, even a caught one: a CPython quirk).
ENTRY = "import sys; from microsim.app.cli import main; sys.exit(main())"


def _wait_until_mapped(pid: int, name: str, timeout: float = 60.0) -> None:
    """Wait until process ``pid`` has a shared library whose path contains ``name`` mapped."""
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        with open(f"/proc/{pid}/maps") as f:
            if name in f.read():
                return
        time.sleep(0.005)
    raise AssertionError(f"{name} was not loaded within {timeout:g} s")


@pytest.mark.skipif(not os.path.isdir("/proc/self"), reason="needs /proc to follow the child")
@pytest.mark.parametrize("delay", [0.0, 0.4])
def test_sigint_during_start_up_exits_130_without_traceback(tmp_path, delay):
    """SIGINT while the command loads its modules — as soon as NumPy's extension is mapped,
    which only ``main`` imports (the command line's own modules do not) — or 0.4 s later. A
    signal before ``main`` runs (while the interpreter itself starts, ~50 ms) is Python's
    default KeyboardInterrupt: no program can catch it, so the test waits for ``main``."""
    sc = scene(tmp_path)
    proc = subprocess.Popen(
        [sys.executable, "-c", ENTRY, "run", str(sc), "--quick", "--no-progress"],
        cwd=tmp_path,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        _wait_until_mapped(proc.pid, "_multiarray_umath")
        time.sleep(delay)
        proc.send_signal(signal.SIGINT)
        err = proc.communicate(timeout=60)[1]
    finally:
        proc.kill()
    assert proc.returncode == 130, err
    assert "Traceback" not in err and len(err.strip().splitlines()) == 1, err


SWALLOWED = """
import gc, os, signal, sys, time, weakref
from microsim.app.cli import _CtrlC

class Thing:
    pass

def callback(_):  # SIGINT handled inside a weakref callback: Python only reports it
    os.kill(os.getpid(), signal.SIGINT)
    t = time.time()
    while time.time() - t < 5:
        pass

with _CtrlC() as ctrl_c:
    thing = Thing()
    ref = weakref.ref(thing, callback)
    del thing
    gc.collect()
    try:
        ctrl_c.check()
    except KeyboardInterrupt:
        sys.exit(130)
sys.exit(0)
"""


def test_an_interrupt_swallowed_by_a_callback_is_raised_again_silently():
    """A SIGINT whose KeyboardInterrupt a callback swallowed (as a module lock's weakref
    callback does during an import) is not lost: ``check`` raises it again, and nothing is
    printed for the swallowed one."""
    proc = subprocess.run([sys.executable, "-c", SWALLOWED], capture_output=True, text=True)
    assert proc.returncode == 130 and proc.stderr == "", proc.stderr


def test_sigint_after_the_command_finished_keeps_its_status():
    """A Ctrl-C between the command's end and the interpreter's exit changes nothing."""
    entry = ENTRY.replace("sys.exit(main())", "s = main(); os.kill(os.getpid(), 2); sys.exit(s)")
    proc = subprocess.run(
        [sys.executable, "-c", "import os; " + entry, "models"], capture_output=True, text=True
    )
    assert proc.returncode == 0 and proc.stderr == "", proc.stderr


def test_closed_stderr_runs_without_progress(tmp_path, capsys, monkeypatch, fast):
    """With file descriptor 2 closed Python sets ``sys.stderr = None``: the run still happens."""
    monkeypatch.chdir(tmp_path)
    sc = scene(tmp_path)
    capsys.readouterr()
    stderr, sys.stderr = sys.stderr, None
    try:
        status = main(["run", str(sc), "--quick", "--threads", "1", "--out", "run"])
    finally:
        sys.stderr = stderr
    assert status == 0, capsys.readouterr()
    assert (tmp_path / "run" / "report.md").is_file()


@pytest.mark.parametrize("shot", ["adir", "view.gif"])
def test_view_screenshot_must_be_an_image_file(tmp_path, capsys, monkeypatch, shot):
    monkeypatch.chdir(tmp_path)
    sc = scene(tmp_path)
    (tmp_path / "adir").mkdir()
    before = tree(tmp_path)
    status, lines, err = run_cli(capsys, "view", sc, "--screenshot", shot)
    assert status == 2 and len(lines) == 1 and "Traceback" not in err, err
    assert "--screenshot" in lines[0] and shot in lines[0]
    assert tree(tmp_path) == before


def test_version(capsys):
    capsys.readouterr()
    with pytest.raises(SystemExit) as exit_:
        main(["--version"])
    assert exit_.value.code == 0
    assert capsys.readouterr().out == f"microsim {microsim.__version__}\n"
