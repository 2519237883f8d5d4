"""`microsim run` / `microsim report` end to end, in subprocesses (tiny scenes, coarse bins).

Facts checked: a run writes every promised file and its verdicts follow the documented schema;
Ctrl-C keeps the tallies (partial, exit 130) and ``--resume`` completes them to exactly the
tallies of an uninterrupted run with the same seed (bitwise: blocks are seeded by index);
existing output is never overwritten; malformed scenes fail with one line and write nothing;
``report`` indexes every scene of a catalogue with working links.
"""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from microsim.analysis.verdicts import validate_verdict
from microsim.app.scene import CATALOGUE

pytestmark = pytest.mark.integration  # end to end: subprocesses, whole runs and reports

TINY = """\
name = "{name}"
description = "tiny test scene"
[surface]
kind = "vgrooves"
n_grooves = 800
ndf = "beckmann"
m = {m}
[material]
ior = "aluminium"
[simulation]
theta_i = [0, 45]
rays = 20000
theta_bins = 9
phi_bins = 10
seed = 3
"""
RESUME_RAYS = "1200000"  # per incidence: ~2 s of tracing, time to interrupt in between


def _env():
    env = dict(os.environ, PYTHONWARNINGS="ignore", MPLBACKEND="Agg")
    return env


def microsim(*args, cwd=None, timeout=120):
    return subprocess.run(
        [sys.executable, "-m", "microsim.app.cli", *map(str, args)],
        cwd=cwd,
        capture_output=True,
        text=True,
        timeout=timeout,
        env=_env(),
    )


def _scene(tmp: Path, name="tiny-vg", m=0.3, text=None) -> Path:
    p = tmp / f"{name}.toml"
    p.write_text(text if text is not None else TINY.format(name=name, m=m))
    return p


def _arrays(d: Path) -> dict:
    with np.load(d / "brdf.npz") as z:
        return {k: z[k] for k in z.files}


@pytest.fixture(scope="module")
def reference(tmp_path_factory):
    """One uninterrupted quick run with RESUME_RAYS rays: (scene path, output dir)."""
    tmp = tmp_path_factory.mktemp("ref")
    scene = _scene(tmp)
    out = tmp / "run"
    r = microsim("run", scene, "--quick", "--rays", RESUME_RAYS, "--out", out, "--no-progress")
    assert r.returncode == 0, r.stderr
    (tmp / "stdout.txt").write_text(r.stdout)
    return scene, out


def test_run_prints_the_verdicts_it_wrote(reference):
    """stdout: one table row per model, the cell of each (model, θi) saying what
    verdicts.json says (✓ agrees, ✗ deviates, ? inconclusive), and the conclusion line."""
    from microsim.analysis.report import run_summary

    scene, out = reference
    printed = (out.parent / "stdout.txt").read_text()
    doc = json.loads((out / "verdicts.json").read_text())
    assert printed == run_summary(doc) + "\n"
    lines = printed.splitlines()
    thetas = list(dict.fromkeys(v["theta_i"] for v in doc["verdicts"]))
    for v in doc["verdicts"]:
        row = next(line for line in lines[2:-1] if line.split()[0] == v["model"])
        cells = re.split(r"\s{2,}", row.strip())[1:]
        if v["model"] in (doc.get("outside_domain") or {}):
            assert cells == ["outside its domain"]
            continue
        cell = cells[thetas.index(v["theta_i"])]
        want = "✓" if v["agrees"] else ("✗" if v.get("conclusive", True) else "?")
        assert cell.startswith(want), (v["model"], v["theta_i"], cell)
    agree = [
        m
        for m in dict.fromkeys(v["model"] for v in doc["verdicts"])
        if all(w["agrees"] for w in doc["verdicts"] if w["model"] == m)
        and m not in (doc.get("outside_domain") or {})
    ]
    assert lines[-1].startswith(f"agrees at every θi: {', '.join(agree) or 'none'}")


@pytest.mark.slow  # 10 s (a resumed run); the default run checks the verdicts.json it writes
def test_run_json_prints_verdicts_json(reference, tmp_path, capsys):
    from microsim.app.cli import main

    scene, out = reference
    copy = tmp_path / "run"
    import shutil

    shutil.copytree(out, copy)
    capsys.readouterr()
    opts = ["--quick", "--rays", RESUME_RAYS, "--no-progress", "--json"]
    assert main(["run", str(scene), *opts, "--resume", str(copy)]) == 0
    printed = capsys.readouterr().out
    assert printed == (copy / "verdicts.json").read_text()
    assert json.loads(printed)["verdicts"]


def test_run_writes_every_file_and_valid_verdicts(reference):
    scene, out = reference
    for f in ("brdf.npz", "meta.json", "verdicts.json", "report.md"):
        assert (out / f).is_file(), f
    assert not [p for p in out.parent.iterdir() if p.name.startswith(".")]  # no leftovers
    doc = json.loads((out / "verdicts.json").read_text())
    assert doc["scene"] == "tiny-vg" and doc["theta_i"] == [0.0, 45.0]
    assert doc["verdicts"], "no verdicts"
    for v in doc["verdicts"]:
        validate_verdict(v)
    models = {v["model"] for v in doc["verdicts"]}
    assert "ts-facets" in models and any(m.startswith("ts-") and m != "ts-facets" for m in models)
    # every incidence has a verdict for every model
    assert len(doc["verdicts"]) == 2 * len(models)
    for f in doc["fits"]:
        assert f["model"] in models
        assert f["sqrt_e2"] is None or abs(f["sqrt_e2"] ** 2 - f["e2"]) <= 1e-12 + 1e-9 * f["e2"]
    meta = json.loads((out / "meta.json").read_text())
    assert meta["partial"] is False and meta["run"]["quick"] is True
    timings = json.loads((out / "timings.json").read_text())
    stages = timings["analysis_stage_seconds"]  # in order, up to the writing stage
    assert list(stages) == ["models", "fits", "stability sweep", "speed runs", "charts"]
    assert all(t > 0 for t in stages.values())
    assert sum(stages.values()) <= timings["analysis_seconds"]
    report = (out / "report.md").read_text()
    links = re.findall(r"!\[[^\]]*\]\(([^)]+)\)", report)
    assert len(links) >= 4
    for link in links:
        assert (out / link).is_file(), link


@pytest.mark.slow  # 10 s; test_faults_cli checks an interrupted run resumes bitwise at each phase
def test_interrupt_then_resume_matches_uninterrupted(reference, tmp_path, capsys):
    """Ctrl-C (the in-process interrupt hook, deterministic) during the second incidence: exit
    130, partial tallies saved, no report; --resume completes them bitwise."""
    from microsim.app.cli import main
    from microsim.checkpoints import interrupt_at

    scene, ref = reference
    out = tmp_path / "run"
    args = ["run", str(scene), "--quick", "--rays", RESUME_RAYS, "--out", str(out)]
    # the first incidence takes ~26 chunks (16 blocks each, shrinking at the end): stop in the
    # second one
    with interrupt_at("simulation", after=32) as hook:
        assert main([*args, "--no-progress"]) == 130
    assert hook["fired"]
    meta = json.loads((out / "meta.json").read_text())
    assert meta["partial"] is True
    assert not (out / "verdicts.json").exists()
    partial = _arrays(out)
    assert partial["rays"][0] == int(RESUME_RAYS) and 0 < partial["rays"][1] < int(RESUME_RAYS)

    r = microsim("run", scene, "--quick", "--rays", RESUME_RAYS, "--resume", out, "--no-progress")
    assert r.returncode == 0, r.stderr
    got, want = _arrays(out), _arrays(ref)
    for key in ("rays", "counts", "sum_w", "sum_w2", "brdf", "stderr"):
        assert np.array_equal(got[key], want[key], equal_nan=True), key
    assert json.loads((out / "meta.json").read_text())["partial"] is False
    assert (out / "verdicts.json").is_file() and (out / "report.md").is_file()


def test_existing_directory_is_refused(tmp_path):
    scene = _scene(tmp_path)
    out = tmp_path / "taken"
    out.mkdir()
    (out / "keep.txt").write_text("mine")
    r = microsim("run", scene, "--quick", "--out", out)
    assert r.returncode == 2
    assert len(r.stderr.strip().splitlines()) == 1 and str(out) in r.stderr
    assert sorted(p.name for p in out.iterdir()) == ["keep.txt"]
    assert (out / "keep.txt").read_text() == "mine"


@pytest.mark.parametrize(
    "edit, key",
    [
        pytest.param(
            lambda t: t.replace("seed = 3", "seed = 3\nspeed = 1"),
            "simulation.speed",
            marks=pytest.mark.slow,
        ),
        pytest.param(
            lambda t: t.replace("rays = 20000", 'rays = "many"'),
            "simulation.rays",
            marks=pytest.mark.slow,
        ),
        (lambda t: t.replace('ndf = "beckmann"', 'ndf = "gauss"'), "surface.ndf"),
    ],
)
def test_malformed_scene_one_line_nothing_written(tmp_path, edit, key):
    scene = _scene(tmp_path, text=edit(TINY.format(name="bad", m=0.3)))
    out = tmp_path / "out"
    r = microsim("run", scene, "--out", out, cwd=tmp_path)
    assert r.returncode == 2
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1, r.stderr
    assert str(scene) in lines[0] and key in lines[0] and "Traceback" not in r.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == [scene.name]  # no out/, no runs/


@pytest.mark.slow
def test_catalogue_file_heightfield_scene_runs(tmp_path):
    """A fault once found: every ``kind = "file"`` scene crashed after its simulation (the
    report formatted the grid shape as a number). The catalogue's file scene runs end to end.
    Slow (11 s in a subprocess): the default run covers a file scene end to end in
    ``test_report_indexes_catalogue_with_working_links`` (its "tiny-file" scene)."""
    out = tmp_path / "run"
    r = microsim(
        "run",
        CATALOGUE / "file-gaussian-64.toml",
        "--quick",
        "--rays",
        "20000",
        "--theta-i",
        "30",
        "--out",
        out,
        "--no-progress",
        cwd=tmp_path,
    )
    assert r.returncode == 0, r.stderr
    assert "Traceback" not in r.stderr
    report = (out / "report.md").read_text()
    assert "input_shape = 64 × 64" in report and "heightfields/gaussian-64.npy" in report
    doc = json.loads((out / "verdicts.json").read_text())
    assert doc["scene"] == "file-gaussian-64" and doc["verdicts"]


@pytest.mark.long
def test_report_indexes_catalogue_with_working_links(tmp_path):
    cat = tmp_path / "cat"
    cat.mkdir()
    _scene(cat, "tiny-a", 0.2)  # a V-groove and a file heightfield scene: both kinds of link
    np.save(cat / "h.npy", 0.5 * np.random.default_rng(0).normal(size=(16, 16)))
    _scene(
        cat,
        "tiny-file",
        text=TINY.format(name="tiny-file", m=0).replace(
            'kind = "vgrooves"\nn_grooves = 800\nndf = "beckmann"\nm = 0\n',
            'kind = "file"\npath = "h.npy"\ndx = 1.0\n',
        ),
    )
    out = tmp_path / "reports"
    r = microsim(
        "report", "--quick", "--catalogue", cat, "--out", out, "--no-progress", timeout=400
    )
    assert r.returncode == 0, r.stderr
    index = (out / "index.md").read_text()
    links = re.findall(r"\]\(([^)]+)\)", index)
    for name in ("tiny-a", "tiny-file"):
        assert f"{name}/report.md" in links
    for link in links:
        assert (out / link).is_file(), link
    for name in ("tiny-a", "tiny-file"):
        report = (out / name / "report.md").read_text()
        for link in re.findall(r"!\[[^\]]*\]\(([^)]+)\)", report):
            assert (out / name / link).is_file(), link
    assert not [p for p in out.iterdir() if p.name.startswith(".")]


@pytest.mark.slow
def test_report_regenerated_in_place_replaces_the_scene_folders(tmp_path):
    cat = tmp_path / "cat"
    cat.mkdir()
    _scene(cat, "tiny-a", 0.2)
    out = tmp_path / "reports"
    r = microsim("report", "--quick", "--catalogue", cat, "--out", out, "--no-progress")
    assert r.returncode == 0, r.stderr
    before = (out / "tiny-a" / "verdicts.json").stat().st_ino
    r = microsim("report", "--quick", "--catalogue", cat, "--out", out, "--no-progress")
    assert r.returncode == 0, r.stderr
    assert (out / "tiny-a" / "verdicts.json").stat().st_ino != before
    assert not [p for p in out.iterdir() if p.name.startswith(".")]
