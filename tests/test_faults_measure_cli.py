"""Fault suite of ``microsim measure`` (and ``report --scheduler``) through the command line,
in-process.

Facts checked: ``--force`` replaces the result with the one the new settings give — the same
files as a fresh measure with them, no incidence of the old one left — and an interrupted or
refused ``--force`` leaves the old result as it was; ``--resume`` over a damaged measure
traces a damaged incidence again (to the same table) or, when ``measure.json`` itself is
damaged, is a one-line usage error naming it, with nothing changed; bad options and bad or
unreachable scheduler addresses are refused before anything is written, naming the option or
the address; a Ctrl-C while connecting exits 130 with nothing written. Measures are tiny (400
V-grooves, 9 × 10 bins, θi every 40°, 2.6·10⁵ rays per incidence) so each test takes seconds.
"""

from __future__ import annotations

import functools
import gc
import json
import signal
import socket

import numpy as np
import pytest
from test_faults_cli import tree

from microsim.app import cluster, measure
from microsim.app.cli import main
from microsim.app.runner import catalogue
from microsim.checkpoints import interrupt_at
from microsim.errors import EnvironmentFailure, UsageError
from microsim.sim import estimator

SCENE = """\
name = "tiny"
[surface]
kind = "vgrooves"
n_grooves = 400
ndf = "beckmann"
m = 0.3
[material]
ior = "{ior}"
[simulation]
theta_bins = 9
phi_bins = 10
seed = 3
"""
FAST = ("--target", "0.05", "--theta-max", "80", "--export", "rgl")


@pytest.fixture
def scene(tmp_path):
    path = tmp_path / "tiny.toml"
    path.write_text(SCENE.format(ior="aluminium"))
    return path


def _cli(capsys, *args) -> tuple[int, str, str]:
    """(exit status, stdout, stderr) of ``microsim ARGS`` in-process."""
    capsys.readouterr()
    try:
        status = main([str(a) for a in args])
    except SystemExit as e:  # argparse's own errors
        status = e.code
    cap = capsys.readouterr()
    return status, cap.out, cap.err


def _measure(capsys, scene, out, *options):
    """``_cli`` of ``microsim measure SCENE --out OUT`` at the tiny settings (θi every 40°
    unless ``options`` say otherwise)."""
    return _cli(capsys, "measure", scene, "--out", out, "--theta-step", "40", *FAST, *options)


def _one_line_error(status, out, err, code, *words):
    lines = err.strip().splitlines()
    assert status == code and len(lines) == 1 and "Traceback" not in err, err
    assert all(w in lines[0] for w in words), lines[0]


def _same_table(a, b):
    with np.load(a / "table.npz") as x, np.load(b / "table.npz") as y:
        assert sorted(x.files) == sorted(y.files)
        for k in x.files:
            assert np.array_equal(x[k], y[k], equal_nan=x[k].dtype.kind == "f"), k


# --- --force ------------------------------------------------------------------------------------
def test_force_replaces_the_result_with_the_one_of_the_new_settings(tmp_path, capsys, scene):
    """Another material, seed and θi step over a finished measure: every file is the one a
    fresh measure with the new settings writes; no incidence of the old one is left; the
    user's own file in the directory stays."""
    out, fresh = tmp_path / "m", tmp_path / "fresh"
    assert _measure(capsys, scene, out)[0] == 0
    (out / "notes.txt").write_text("mine")
    scene.write_text(SCENE.format(ior="methanol"))
    new = ("--theta-step", "80", "--seed", "7")
    assert _cli(capsys, "measure", scene, "--out", out, *FAST, *new, "--force")[0] == 0
    assert _cli(capsys, "measure", scene, "--out", fresh, *FAST, *new)[0] == 0
    _same_table(out, fresh)
    assert (out / "table.bsdf").read_bytes() == (fresh / "table.bsdf").read_bytes()
    doc = json.loads((out / "measure.json").read_text())
    assert doc["settings"]["seed"] == 7 and doc["settings"]["theta_i"] == [0.0, 80.0]
    assert sorted(doc["incidences"]) == ["0", "80"]
    assert doc["totals"]["incidences"] == 2
    assert doc["totals"]["rays"] == sum(d["rays"] for d in doc["incidences"].values())
    assert sorted(p.name for p in (out / "incidences").iterdir()) == ["theta-00.00", "theta-80.00"]
    assert (out / "notes.txt").read_text() == "mine"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["fresh", "m", "tiny.toml"]


def test_an_interrupted_force_leaves_the_old_result(tmp_path, capsys, scene):
    out = tmp_path / "m"
    assert _measure(capsys, scene, out)[0] == 0
    before = tree(tmp_path)
    scene.write_text(SCENE.format(ior="methanol"))
    with interrupt_at("simulation", after=20) as hit:
        status, said, err = _measure(capsys, scene, out, "--force")
    assert hit["fired"] and status == 130 and "Traceback" not in err
    assert "keeps its finished table" in said
    after = tree(tmp_path)
    assert after.pop("tiny.toml") != before.pop("tiny.toml")
    assert after == before  # the old result intact, no staging left beside it


def test_force_replaces_only_a_measure_directory(tmp_path, capsys, scene):
    out = tmp_path / "papers"
    out.mkdir()
    (out / "draft.tex").write_text("mine")
    before = tree(tmp_path)
    _one_line_error(*_measure(capsys, scene, out, "--force"), 2, "--force", "measure.json")
    assert tree(tmp_path) == before


# --- --resume over a damaged measure ------------------------------------------------------------
def _truncate_npz(out):
    path = out / "incidences" / "theta-40.00" / "brdf.npz"
    path.write_bytes(path.read_bytes()[:100])


def _garble_meta(out):
    (out / "incidences" / "theta-40.00" / "meta.json").write_text("{not json")


def _drop_rays(out):
    path = out / "measure.json"
    doc = json.loads(path.read_text())
    del doc["incidences"]["40"]["rays"]
    path.write_text(json.dumps(doc))


@pytest.mark.parametrize(
    "damage",
    [
        _truncate_npz,
        pytest.param(_garble_meta, marks=pytest.mark.slow),
        pytest.param(_drop_rays, marks=pytest.mark.slow),
    ],
)
def test_resume_traces_a_damaged_incidence_again(tmp_path, capsys, scene, damage):
    """The damaged incidence is named and traced again — to the same table, as each incidence
    has its own seed; the others are read back."""
    out, whole = tmp_path / "m", tmp_path / "whole"
    assert _measure(capsys, scene, whole)[0] == 0
    assert _measure(capsys, scene, out)[0] == 0
    damage(out)
    status, said, err = _measure(capsys, scene, out, "--resume")
    assert status == 0 and "Traceback" not in err
    assert "θi = 40°: the saved incidence is damaged" in said
    assert "θi = 0°" not in said and "θi = 80°" not in said
    _same_table(out, whole)
    doc = json.loads((out / "measure.json").read_text())
    assert doc["totals"]["rays"] == sum(d["rays"] for d in doc["incidences"].values())


@pytest.mark.parametrize("text", ["[]", "{not json", '{"settings": {}, "incidences": []}'])
def test_resume_over_a_damaged_measure_json_is_one_line_naming_it(tmp_path, capsys, scene, text):
    out = tmp_path / "m"
    assert _measure(capsys, scene, out)[0] == 0
    (out / "measure.json").write_text(text)
    before = tree(tmp_path)
    _one_line_error(*_measure(capsys, scene, out, "--resume"), 2, "measure.json", "--force")
    assert tree(tmp_path) == before


# --- options and schedulers: refused before anything is written --------------------------------
@pytest.mark.parametrize(
    "option, value, words",
    [
        ("--max-rays", "1152921504606846976", ("--max-rays", "65536", "281,474,976,710,656")),
        ("--seed", "-1", ("--seed", ">= 0")),
    ],
)
def test_bad_options_are_refused_up_front(tmp_path, capsys, scene, option, value, words):
    before = tree(tmp_path)
    _one_line_error(*_measure(capsys, scene, tmp_path / "m", option, value), 2, *words)
    assert tree(tmp_path) == before


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_an_unreachable_scheduler_writes_nothing(tmp_path, capsys, monkeypatch, scene):
    pytest.importorskip("distributed", reason="needs the `cluster` extra")
    monkeypatch.setattr(measure, "connect", functools.partial(cluster.connect, timeout=1.0))
    address = f"tcp://127.0.0.1:{_free_port()}"
    before = tree(tmp_path)
    _one_line_error(*_measure(capsys, scene, tmp_path / "m", "--scheduler", address), 1, address)
    assert tree(tmp_path) == before


def test_a_bad_scheduler_address_writes_nothing(tmp_path, capsys, scene):
    pytest.importorskip("distributed", reason="needs the `cluster` extra")
    cat = tmp_path / "cat"
    cat.mkdir()
    (cat / "tiny.toml").write_text(scene.read_text())
    before = tree(tmp_path)
    bad = ("--scheduler", "notanaddress")
    _one_line_error(*_measure(capsys, scene, tmp_path / "m", *bad), 2, "notanaddress")
    args = ("report", "--quick", "--catalogue", cat, "--out", tmp_path / "rep", "--no-progress")
    _one_line_error(*_cli(capsys, *args, *bad), 2, "notanaddress")
    assert tree(tmp_path) == before


@pytest.mark.parametrize("address", ["notanaddress", "unreachable"])
def test_a_client_that_failed_to_start_is_finalised_at_once(address):
    """A Client that failed to start is garbage in a reference cycle; left to a later
    collection, its finaliser can run inside the next Client's start, where both wait on dask's
    one loop-runner lock and the process hangs (as a bad address followed by another did). So
    ``connect`` finalises it before it reports the error: with automatic collection off, no
    Client more is alive (other tests of the process may hold theirs)."""
    distributed = pytest.importorskip("distributed", reason="needs the `cluster` extra")
    if address == "unreachable":
        address = f"tcp://127.0.0.1:{_free_port()}"

    def clients() -> int:
        return sum(isinstance(o, distributed.Client) for o in gc.get_objects())

    gc.collect()
    gc.disable()
    try:
        before = clients()
        with pytest.raises((UsageError, EnvironmentFailure)):
            with cluster.connect(address, timeout=1.0):
                pass
        after = clients()
    finally:
        gc.enable()
    assert after == before


def test_ctrl_c_while_connecting_exits_130_and_writes_nothing(tmp_path, capsys, monkeypatch, scene):
    def interrupted(address, *args, **kwargs):
        raise KeyboardInterrupt  # what Ctrl-C raises while Client(address) waits

    monkeypatch.setattr(measure, "connect", interrupted)
    monkeypatch.setattr(catalogue, "connect", interrupted)
    before = tree(tmp_path)
    status, _, err = _measure(capsys, scene, tmp_path / "m", "--scheduler", "tcp://host:8786")
    assert status == 130 and "Traceback" not in err
    assert tree(tmp_path) == before


def test_ctrl_c_after_an_incidences_last_chunk_is_not_lost(tmp_path, capsys, monkeypatch, scene):
    """A SIGINT that comes once an incidence's last chunk was tallied (on a cluster: while its
    surface is released there) still stops the measure: status 130, not a finished table."""
    real = estimator._trace_incidence
    sent = []

    def then_ctrl_c(*args, **kwargs):
        real(*args, **kwargs)
        if not sent:
            sent.append(True)
            signal.raise_signal(signal.SIGINT)

    monkeypatch.setattr(estimator, "_trace_incidence", then_ctrl_c)
    status, said, err = _measure(capsys, scene, tmp_path / "m")
    assert sent and status == 130 and "Traceback" not in err
    assert "interrupted" in said and not (tmp_path / "m" / "table.npz").exists()
