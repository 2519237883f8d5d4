"""Damaged files microsim saved and reads back: a result's ``brdf.npz`` cut in half or
replaced by other bytes, its ``meta.json`` not JSON, of another JSON type or with keys of the
wrong type; the reference cache's entries; ``microsim report --resume``'s state and the
verdicts of the scenes it finished; the index's ``methods.json`` and ``fullwave.json``.

The promise: each is one ``UsageError`` line naming the file and what is wrong (CLI: status
2, nothing written) — or, where the file is a cache or a record of finished work, the damage
is said in one line and the work done again — never a parser's traceback.
"""

from __future__ import annotations

import json
import shutil
import warnings

import numpy as np
import pytest
import test_faults_testing
from test_faults_cli import TINY, _fast, run_cli, scene, tree
from test_faults_testing import AL
from test_faults_testing import TINY as TINY_REFERENCE

from microsim.analysis import report
from microsim.app.cli import main
from microsim.checkpoints import interrupt_at
from microsim.errors import UsageError
from microsim.sim import Bins, Result
from microsim.testing import reference


def cut_in_half(path):
    data = path.read_bytes()
    path.write_bytes(data[: len(data) // 2])


def garbage(path):
    path.write_bytes(b"\x00not what microsim wrote \xff\xfe" * 8)


def single_array(path):
    with open(path, "wb") as fh:
        np.save(fh, np.zeros(3))


def json_of(value):
    return lambda path: path.write_text(json.dumps(value))


FILE_DAMAGE = {
    "npz cut in half": ("brdf.npz", cut_in_half),
    "npz garbage": ("brdf.npz", garbage),
    "npz a single array": ("brdf.npz", single_array),
    "meta cut in half": ("meta.json", cut_in_half),
    "meta garbage": ("meta.json", garbage),
    "meta an array": ("meta.json", json_of([])),
    "meta a number": ("meta.json", json_of(3)),
}


def one_line_naming(message: str, path) -> bool:
    return "\n" not in message and str(path) in message


# --- Result.load -------------------------------------------------------------------------------
@pytest.fixture
def saved_result(tmp_path):
    """A small saved Result (no ray tallies) in ``tmp_path / "r"``."""
    bins = Bins(n_theta=3, n_phi=4, folded=True)
    grid = (1,) + bins.shape
    meta = {"surface": {"kind": "vgrooves"}, "material": {"name": "aluminium"}}
    res = Result(np.array([30.0]), np.array([0.0]), bins, np.ones(grid), np.zeros(grid), meta=meta)
    res.save(tmp_path / "r")
    return tmp_path / "r"


@pytest.mark.parametrize("case", list(FILE_DAMAGE))
def test_result_load_of_a_damaged_file_is_one_usage_error_naming_it(case, saved_result):
    name, damage = FILE_DAMAGE[case]
    damage(saved_result / name)
    with pytest.raises(UsageError) as caught:
        Result.load(saved_result)
    assert one_line_naming(str(caught.value), saved_result / name), caught.value


META_KEYS = [
    ("bins", None),
    ("surface", "vgrooves"),
    ("material", ["aluminium"]),
    ("realisations", "3"),
    ("partial", "no"),
]


@pytest.mark.parametrize("key, value", META_KEYS, ids=[k for k, _ in META_KEYS])
def test_result_load_refuses_meta_keys_of_the_wrong_type(key, value, saved_result):
    """The keys a Result's own methods read (``repr``: surface, material, realisations) are
    checked on load, not found wrong later as an AttributeError."""
    path = saved_result / "meta.json"
    meta = json.loads(path.read_text())
    meta[key] = value
    path.write_text(json.dumps(meta))
    with pytest.raises(UsageError) as caught:
        repr(Result.load(saved_result))
    assert one_line_naming(str(caught.value), path) and key in str(caught.value), caught.value


@pytest.mark.parametrize("name", ["brdf.npz", "meta.json"])
def test_every_truncation_of_a_saved_result_is_refused(name, saved_result):
    """A write cut short at any byte (every length of the file) is a UsageError."""
    path = saved_result / name
    whole = path.read_bytes()
    for n in range(len(whole)):
        path.write_bytes(whole[:n])
        with pytest.raises(UsageError):
            Result.load(saved_result)


def test_a_damaged_member_of_the_npz_is_refused(saved_result):
    """A byte changed inside an array's data (np.load checks no CRC) is found."""
    path = saved_result / "brdf.npz"
    data = bytearray(path.read_bytes())
    data[data.index(b"\x93NUMPY") + 130] ^= 0xFF  # theta_i's value (after its 128-byte header)
    path.write_bytes(bytes(data))
    with pytest.raises(UsageError, match="CRC"):
        Result.load(saved_result)


# --- microsim run --resume ---------------------------------------------------------------------
QUICK = ["--quick", "--threads", "1", "--no-progress"]


@pytest.fixture(scope="module")
def finished_run(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("run")
    with pytest.MonkeyPatch.context() as mp:
        _fast(mp)
        mp.chdir(tmp)
        scene(tmp, "t")
        assert main(["run", "t.toml", *QUICK, "--out", str(tmp / "finished")]) == 0
    return tmp


@pytest.mark.parametrize("case", list(FILE_DAMAGE))
def test_resume_from_a_damaged_file_is_one_line_exit_2(
    case, finished_run, tmp_path, monkeypatch, capsys
):
    _fast(monkeypatch)
    monkeypatch.chdir(tmp_path)
    shutil.copy(finished_run / "t.toml", tmp_path / "t.toml")
    shutil.copytree(finished_run / "finished", tmp_path / "o")
    name, damage = FILE_DAMAGE[case]
    damage(tmp_path / "o" / name)
    before = tree(tmp_path)
    status, lines, err = run_cli(capsys, "run", "t.toml", *QUICK, "--resume", "o")
    assert status == 2 and len(lines) == 1 and "Traceback" not in err, err
    assert name in lines[0], err
    assert tree(tmp_path) == before


# --- the reference cache -----------------------------------------------------------------------
def without_ray_tallies(path):
    with np.load(path) as z:
        kept = {k: z[k] for k in ("theta_i", "phi_i", "theta_edges", "phi_edges", "brdf", "stderr")}
    with open(path, "wb") as fh:
        np.savez(fh, **kept)


surface, good, traces = (  # the reference cache's fixtures
    test_faults_testing.surface,
    test_faults_testing.good,
    test_faults_testing.traces,
)
CACHE_DAMAGE = {
    "npz garbage": ("brdf.npz", garbage),
    "npz a single array": ("brdf.npz", single_array),
    "npz without ray tallies": ("brdf.npz", without_ray_tallies),
    "meta an array": ("meta.json", json_of([])),
    "key.json garbage": ("key.json", garbage),
    "key.json an array": ("key.json", json_of([])),
}


@pytest.mark.parametrize("case", list(CACHE_DAMAGE))
def test_a_damaged_cache_entry_is_warned_once_and_traced_again(
    case, surface, good, tmp_path, traces
):
    root, name, brdf = good
    shutil.copytree(root / name, tmp_path / name)
    file, damage = CACHE_DAMAGE[case]
    damage(tmp_path / name / file)
    with pytest.warns(UserWarning) as caught:
        res = reference(surface, AL, [30], cache=tmp_path, **TINY_REFERENCE)
    (warning,) = caught
    assert one_line_naming(str(warning.message), tmp_path / name / file), warning.message
    assert traces == [name]
    np.testing.assert_array_equal(res.brdf, brdf)


# --- microsim report --resume ------------------------------------------------------------------
REPORT = ["report", "--quick", "--catalogue", "cat", "--out", "rep", "--no-progress"]


@pytest.fixture(scope="module")
def interrupted_report(tmp_path_factory):
    """A catalogue of two scenes and its report interrupted after the first one finished."""
    tmp = tmp_path_factory.mktemp("report")
    with pytest.MonkeyPatch.context() as mp:
        _fast(mp)
        mp.chdir(tmp)
        (tmp / "cat").mkdir()
        scene(tmp / "cat", "tiny-a")
        scene(
            tmp / "cat", "tiny-b", text=TINY.format(name="tiny-b").replace("seed = 3", "seed = 4")
        )
        with interrupt_at("fits", after=1) as hit:
            assert main(REPORT) == 130
        assert hit["fired"] and (tmp / "rep" / "tiny-a" / "verdicts.json").is_file()
    return tmp


@pytest.fixture
def report_copy(interrupted_report, tmp_path, monkeypatch):
    _fast(monkeypatch)
    monkeypatch.chdir(tmp_path)
    for name in ("cat", "rep"):
        shutil.copytree(interrupted_report / name, tmp_path / name)
    return tmp_path


STATE_DAMAGE = {
    "cut in half": cut_in_half,
    "garbage": garbage,
    "an array": json_of([]),
    "done not names": json_of({"done": [["tiny-a"]], "quick": True, "catalogue": "cat"}),
}


@pytest.mark.parametrize("case", list(STATE_DAMAGE))
def test_report_resume_with_a_damaged_state_is_one_line_exit_2(case, report_copy, capsys):
    state = report_copy / "rep" / ".report-state.json"
    STATE_DAMAGE[case](state)
    before = tree(report_copy)
    status, lines, err = run_cli(capsys, *REPORT, "--resume")
    assert status == 2 and len(lines) == 1 and "Traceback" not in err, err
    assert ".report-state.json" in lines[0] and "without --resume" in lines[0], err
    assert tree(report_copy) == before


@pytest.mark.parametrize(
    "damage",
    [
        pytest.param(cut_in_half, marks=pytest.mark.slow),
        garbage,
        pytest.param(json_of([]), marks=pytest.mark.slow),
    ],
    ids=["half", "garbage", "array"],
)
def test_report_resume_runs_again_a_finished_scene_whose_verdicts_are_damaged(
    damage, report_copy, capsys
):
    verdicts = report_copy / "rep" / "tiny-a" / "verdicts.json"
    damage(verdicts)
    status, lines, err = run_cli(capsys, *REPORT, "--resume")
    assert status == 0 and "Traceback" not in err, err
    said = [line for line in lines if "rep/tiny-a/verdicts.json" in line]
    assert len(said) == 1 and "tiny-a again" in said[0], err
    assert json.loads(verdicts.read_text())["seed"] == 3


# --- the index's methods.json and fullwave.json ------------------------------------------------
INDEX_DAMAGE = {
    "cut in half": cut_in_half,
    "garbage": garbage,
    "an array": json_of([]),
    "machine a number": json_of({"machine": 5, "panels": []}),
}


@pytest.mark.parametrize("case", list(INDEX_DAMAGE))
@pytest.mark.parametrize("name", ["methods.json", "fullwave.json"])
def test_a_damaged_index_input_is_one_line_of_the_index(case, name, tmp_path):
    """The index is still written, with one line naming the damaged file and the command
    that writes it again."""
    (tmp_path / name).write_text(json.dumps({"machine": {}, "panels": [], "settings": {}}))
    INDEX_DAMAGE[case](tmp_path / name)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        lines = report.regime_section(
            [], None, methods=tmp_path / "methods.json", fullwave=tmp_path / "fullwave.json"
        )
    said = [line for line in lines if name in line and "unreadable" in line]
    assert len(said) == 1, lines
