"""Faults around saved and published results: interrupts and kills while a result is being
replaced, ``--force`` over a folder holding the user's own files, ``--resume`` after the
scene changed or with damaged ``brdf.npz``/``meta.json``, unusable ``--out`` paths and a full
disk.

The promises: a finished result is never lost or replaced by partial work; files microsim did
not write are kept; ``--resume`` continues only tallies made with the same scene and options,
and only arrays that are consistent; every refusal is one stderr line naming the option, file
or key (status 2; 1 for the environment), with nothing written. Runs use the tiny scene and
the reduced ``--quick`` of test_faults_cli.py; the saved runs are made once per module and
copied into each test.
"""

from __future__ import annotations

import errno
import json
import os
import shutil
import signal
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from test_faults_cli import TINY, _fast, run_cli, scene, tree

from microsim import atomic
from microsim.app.cli import main
from microsim.checkpoints import interrupt_at

QUICK = ["--quick", "--threads", "1", "--no-progress"]
PARTIAL = ["--rays", "150000"]  # several chunks: an interrupt leaves partial tallies


@pytest.fixture(scope="module")
def saved(tmp_path_factory):
    """Scene files and saved runs to copy: ``finished`` (a complete run), ``complete`` (the
    complete tallies of a run interrupted in its fits), ``partial`` (tallies of a run
    interrupted in its simulation, ``PARTIAL`` rays) and ``hf`` (a finished run of a
    heightfield-file scene)."""
    tmp = tmp_path_factory.mktemp("saved")
    with pytest.MonkeyPatch.context() as mp:
        _fast(mp)
        mp.chdir(tmp)
        sc = scene(tmp, "t")
        np.save(tmp / "h.npy", 0.3 * np.random.default_rng(0).normal(size=(16, 16)))
        hf = scene(
            tmp,
            text='name = "hf"\n[surface]\nkind = "file"\npath = "h.npy"\ndx = 1.0\n'
            "[simulation]\ntheta_i = [30]\nrays = 20000\ntheta_bins = 9\nphi_bins = 10\n",
            file_name="hf.toml",
        )
        assert main(["run", str(sc), *QUICK, "--out", str(tmp / "finished")]) == 0
        for name, phase, opts in (("complete", "fits", []), ("partial", "simulation", PARTIAL)):
            with interrupt_at(phase):
                assert main(["run", str(sc), *QUICK, *opts, "--out", str(tmp / name)]) == 130
        assert main(["run", str(hf), *QUICK, "--out", str(tmp / "hf")]) == 0
    return tmp


@pytest.fixture
def work(tmp_path, monkeypatch, saved):
    """A working directory with the scene files (tmp_path); ``fast`` effort and charts."""
    _fast(monkeypatch)
    monkeypatch.chdir(tmp_path)
    for f in ("t.toml", "hf.toml", "h.npy"):
        shutil.copy(saved / f, tmp_path / f)
    return tmp_path


def copy_run(saved: Path, work: Path, name: str, out="o") -> Path:
    shutil.copytree(saved / name, work / out)
    return work / out


def listing(root: Path) -> list[str]:
    """Every path under ``root``, symbolic links not followed."""
    return sorted(str(Path(b, n).relative_to(root)) for b, ds, fs in os.walk(root) for n in ds + fs)


def leftovers(work: Path) -> list[str]:
    return sorted(p.name for p in work.iterdir() if p.name.startswith("."))


# --- a finished result is never lost or replaced by partial work -------------------------------
def test_interrupted_reanalysis_of_a_finished_run_keeps_its_report(work, saved, capsys):
    out = copy_run(saved, work, "finished")
    before = tree(out)
    with interrupt_at("charts"):
        status, lines, err = run_cli(capsys, "run", "t.toml", *QUICK, "--resume", out)
    assert status == 130 and len(lines) == 1 and str(out) in lines[0], err
    assert tree(out) == before
    assert leftovers(work) == []


@pytest.mark.parametrize("phase, opts", [("simulation", PARTIAL), ("fits", [])])
def test_interrupted_force_rerun_keeps_the_finished_result(work, saved, capsys, phase, opts):
    out = copy_run(saved, work, "finished")
    before = tree(out)
    with interrupt_at(phase) as hit:
        status, lines, err = run_cli(
            capsys, "run", "t.toml", *QUICK, *opts, "--out", out, "--force"
        )
    assert hit["fired"]
    assert status == 130 and len(lines) == 1 and str(out) in lines[0], err
    assert tree(out) == before
    assert leftovers(work) == []


def test_interrupted_force_rerun_replaces_partial_tallies(work, saved, capsys):
    """Partial tallies are no finished result: an interrupted ``--force`` replaces them."""
    out = copy_run(saved, work, "partial")
    with interrupt_at("fits"):
        status, lines, err = run_cli(capsys, "run", "t.toml", *QUICK, "--out", out, "--force")
    assert status == 130 and f"--resume {out}" in lines[0], err
    assert json.loads((out / "meta.json").read_text())["partial"] is False


KILL_IN_PUBLISH = """
import os, shutil, signal, sys
from microsim import atomic
out, new, window = sys.argv[1:4]
stage = atomic.make_staging(out)
shutil.copytree(new, stage, dirs_exist_ok=True)
real = os.rename
def rename(src, dst):
    if window == "before":
        os.kill(os.getpid(), signal.SIGKILL)
    real(src, dst)
    os.kill(os.getpid(), signal.SIGKILL)
os.rename = rename
atomic.publish_dir(stage, out)
"""


def _killed_while_publishing(work: Path, saved: Path, window: str):
    """A process SIGKILLed in ``publish_dir`` (``window`` "before" the first rename or
    "between" the two) while replacing ``o`` (the finished run) by a new result."""
    out = copy_run(saved, work, "finished")
    new = copy_run(saved, work, "finished", out="new")
    (new / "report.md").write_text("the new report\n")
    old_tree, new_tree = tree(out), tree(new)
    p = subprocess.run([sys.executable, "-c", KILL_IN_PUBLISH, out, new, window], timeout=60)
    assert p.returncode == -signal.SIGKILL
    shutil.rmtree(new)
    return out, old_tree, new_tree


def test_kill_between_the_renames_of_a_publication_loses_neither_result(work, saved, capsys):
    out, old_tree, new_tree = _killed_while_publishing(work, saved, "between")
    assert not out.exists()
    status, lines, err = run_cli(capsys, "run", "t.toml", *QUICK, "--out", out)
    assert status == 2 and len(lines) == 1 and "Traceback" not in err, err
    kept = [q for q in work.iterdir() if q.name.startswith("o.unpublished-")]
    assert len(kept) == 1 and kept[0].name in lines[0] and str(out) in lines[0], err
    assert tree(out) == old_tree
    assert tree(kept[0]) == new_tree
    assert leftovers(work) == []


def test_kill_before_the_first_rename_keeps_the_unpublished_result(work, saved):
    out, old_tree, new_tree = _killed_while_publishing(work, saved, "before")
    atomic.clean_stale(out)
    kept = [q for q in work.iterdir() if q.name.startswith("o.unpublished-")]
    assert tree(out) == old_tree
    assert len(kept) == 1 and tree(kept[0]) == new_tree
    assert leftovers(work) == []


@pytest.mark.parametrize("where", ["between-renames", "after-publishing"])
def test_sigint_while_publishing_completes_the_result_and_exits_130(
    work, saved, capsys, monkeypatch, where
):
    """A real SIGINT while the finished directory replaces the old one: the publication
    completes (never the old result half moved aside, never tallies over a report), 130."""
    out = copy_run(saved, work, "finished")
    (out / "report.md").write_text("the old report\n")
    if where == "between-renames":
        real_rename = os.rename

        def rename(src, dst):
            real_rename(src, dst)
            if Path(dst).name == "d":
                os.kill(os.getpid(), signal.SIGINT)

        monkeypatch.setattr(os, "rename", rename)
    else:
        real_publish = atomic.publish_dir

        def publish(*a, **k):
            real_publish(*a, **k)
            os.kill(os.getpid(), signal.SIGINT)

        monkeypatch.setattr(atomic, "publish_dir", publish)
    status, lines, err = run_cli(capsys, "run", "t.toml", *QUICK, "--out", out, "--force")
    assert status == 130 and "Traceback" not in err and "Exception ignored" not in err, err
    assert lines and str(out) in lines[-1], err
    assert (out / "report.md").read_text() != "the old report\n"
    assert (out / "verdicts.json").is_file()
    assert json.loads((out / "meta.json").read_text())["partial"] is False
    assert leftovers(work) == []


# --- --force keeps the user's own files ----------------------------------------------------------
def test_force_keeps_files_microsim_did_not_write(work, saved, capsys):
    out = copy_run(saved, work, "finished")
    (out / "my-notes.txt").write_text("precious notes\n")
    (out / "my-notes.txt").chmod(0o600)
    (out / "analysis").mkdir()
    (out / "analysis" / "fit.py").write_text("print(1)\n")
    (out / "hemisphere.png").write_text("an old chart\n")  # one of microsim's own names
    status, lines, err = run_cli(capsys, "run", "t.toml", *QUICK, "--out", out, "--force")
    assert status == 0, err
    assert (out / "my-notes.txt").read_text() == "precious notes\n"
    assert (out / "my-notes.txt").stat().st_mode & 0o777 == 0o600
    assert (out / "analysis" / "fit.py").read_text() == "print(1)\n"
    assert (out / "hemisphere.png").read_text() != "an old chart\n"
    assert (out / "report.md").is_file()
    assert leftovers(work) == []


# --- --resume refuses what the tallies were not made with --------------------------------------
EDITS = [
    ("material", lambda t: t.replace('ior = "aluminium"', 'ior = "methanol"')),
    ("bounces", lambda t: t.replace("seed = 3", 'seed = 3\nbounces = "all"')),
    ("surface", lambda t: t.replace("m = 0.3", "m = 0.5")),
    ("surface", lambda t: t.replace("n_grooves = 200", "n_grooves = 400")),
    ("realisations", lambda t: t.replace("seed = 3", "seed = 3\nrealisations = 2")),
]


@pytest.mark.parametrize("saved_run", ["finished", "complete", "partial"])
@pytest.mark.parametrize("key, edit", EDITS, ids=[f"{k}-{i}" for i, (k, _) in enumerate(EDITS)])
def test_resume_refuses_a_changed_scene(work, saved, capsys, saved_run, key, edit):
    out = copy_run(saved, work, saved_run)
    (work / "t.toml").write_text(edit(TINY.format(name="t")))
    before = tree(work)
    opts = PARTIAL if saved_run == "partial" else []
    status, lines, err = run_cli(capsys, "run", "t.toml", *QUICK, *opts, "--resume", out)
    assert status == 2 and len(lines) == 1 and "Traceback" not in err, err
    assert "--resume" in lines[0] and str(out) in lines[0] and key in lines[0], err
    assert tree(work) == before


def test_resume_refuses_a_changed_heightfield_file(work, saved, capsys):
    out = copy_run(saved, work, "hf")
    np.save(work / "h.npy", 0.5 * np.random.default_rng(1).normal(size=(16, 16)))
    before = tree(work)
    status, lines, err = run_cli(capsys, "run", "hf.toml", *QUICK, "--resume", out)
    assert status == 2 and len(lines) == 1 and "surface" in lines[0], err
    assert tree(work) == before


# --- --resume validates every array it reads back ------------------------------------------------
def _edit_npz(d: Path, change) -> None:
    with np.load(d / "brdf.npz") as z:
        a = {k: z[k] for k in z.files}
    change(a)
    with open(d / "brdf.npz", "wb") as fh:
        np.savez(fh, **a)


def _edit_meta(d: Path, change) -> None:
    meta = json.loads((d / "meta.json").read_text())
    change(meta)
    (d / "meta.json").write_text(json.dumps(meta))


def _set(key, value):
    def change(a):
        a[key] = value(a[key]) if callable(value) else value

    return change


def _bins_8(meta):
    meta["bins"]["n_theta"] = 8
    meta["run"]["bins"] = [8, 10]


DAMAGE = [
    ("blocks-negative", "complete", "npz", _set("tally_blocks", lambda v: -v), "tally_blocks"),
    ("blocks-negative-partial", "partial", "npz", _set("tally_blocks", lambda v: -v), "tally"),
    ("tally-rays", "complete", "npz", _set("tally_rays", lambda v: v + 1), "tally_rays"),
    ("tally-count", "partial", "npz", _set("tally_count", lambda v: v - 10**6), "tally_count"),
    ("counts-negative", "complete", "npz", _set("counts", lambda v: -v), "counts"),
    ("sum-w-nan", "complete", "npz", _set("sum_w", lambda v: v * np.nan), "sum_w"),
    ("brdf-shape", "complete", "npz", _set("brdf", lambda v: v[:, :, :5]), "brdf"),
    ("ledger", "complete", "npz", _set("count_single", lambda v: v + 7), "ledger"),
    ("theta-i-inf", "complete", "npz", _set("theta_i", lambda v: v * np.inf), "theta_i"),
    ("rays-float", "complete", "npz", _set("rays", lambda v: v + 0.5), "rays"),
    ("run-null", "complete", "meta", _set("run", None), "run"),
    ("partial-text", "complete", "meta", _set("partial", "no"), "partial"),
    ("bins-8", "complete", "meta", _bins_8, "bins"),
    ("bins-list", "complete", "meta", _set("bins", [9, 10]), "bins"),
]


@pytest.mark.parametrize(
    "saved_run, kind, damage, word", [d[1:] for d in DAMAGE], ids=[d[0] for d in DAMAGE]
)
def test_resume_refuses_damaged_saved_arrays(work, saved, capsys, saved_run, kind, damage, word):
    out = copy_run(saved, work, saved_run)
    (_edit_npz if kind == "npz" else _edit_meta)(out, damage)
    if word == "bins" and damage is _bins_8:
        (work / "t.toml").write_text(
            TINY.format(name="t").replace("theta_bins = 9", "theta_bins = 8")
        )
    before = tree(work)
    opts = PARTIAL if saved_run == "partial" else []
    status, lines, err = run_cli(capsys, "run", "t.toml", *QUICK, *opts, "--resume", out)
    assert status == 2 and len(lines) == 1 and "Traceback" not in err, err
    name = "brdf.npz" if kind == "npz" else "meta.json"
    assert name in lines[0] and word in lines[0] and str(out) in lines[0], err
    assert tree(work) == before


def test_resume_of_a_run_saved_without_a_setting_asks_for_force(work, saved, capsys):
    """A run whose meta.json lacks a setting the tallies depend on (an older microsim's)."""
    out = copy_run(saved, work, "complete")
    _edit_meta(out, lambda meta: meta["run"].pop("surface"))
    before = tree(work)
    status, lines, err = run_cli(capsys, "run", "t.toml", *QUICK, "--resume", out)
    assert status == 2 and len(lines) == 1 and "Traceback" not in err, err
    assert "surface" in lines[0] and "--force" in lines[0] and str(out) in lines[0], err
    assert tree(work) == before


# --- unusable --out paths are refused before anything runs --------------------------------------
@pytest.mark.parametrize("option", ["--out", "--resume"])
@pytest.mark.parametrize("case", ["dangling-symlink", "symlink-loop", "name-300", "component-300"])
def test_unusable_out_path_is_one_line_exit_2(work, capsys, option, case):
    if case == "dangling-symlink":
        out = work / "o"
        out.symlink_to(work / "nowhere" / "o")
    elif case == "symlink-loop":
        out = work / "o"
        out.symlink_to(out)
    elif case == "name-300":
        out = work / ("a" * 300)
    else:
        out = work / ("b" * 300) / "o"
    before = listing(work)
    status, lines, err = run_cli(capsys, "run", "t.toml", *QUICK, option, out)
    assert status == 2 and len(lines) == 1 and "Traceback" not in err, err
    assert option in lines[0], err
    assert listing(work) == before


# --- a full disk names the path -----------------------------------------------------------------
def _disk_full(*a, **k):
    raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))  # as write(2) raises it: no path


@pytest.mark.parametrize("command", ["new", "force", "interrupt-save", "report"])
def test_disk_full_names_the_path(work, saved, capsys, monkeypatch, command):
    out = work / "o"
    args = ["run", "t.toml", *QUICK, "--out", out]
    if command == "force":
        copy_run(saved, work, "finished")
        args.append("--force")
    elif command == "report":
        (work / "cat").mkdir()
        shutil.copy(work / "t.toml", work / "cat" / "t.toml")
        args = ["report", "--quick", "--no-progress", "--catalogue", "cat", "--out", out]
    before = tree(out) if out.exists() else None
    monkeypatch.setattr(np, "savez", _disk_full)
    with interrupt_at("fits" if command == "interrupt-save" else "report-index"):
        status, lines, err = run_cli(capsys, *args)
    errors = [line for line in lines if line.startswith("microsim: error")]
    assert status == 1 and errors == lines[-1:] and "Traceback" not in err, err
    assert len(lines) == 1 or command == "report", err  # report: a line per scene
    assert "No space left on device" in errors[0] and "brdf.npz" in errors[0], err
    assert str(work) in errors[0], err
    if before is not None:
        assert tree(out) == before
    assert not [n for n in leftovers(work) if ".tmp-" in n or ".old-" in n]
