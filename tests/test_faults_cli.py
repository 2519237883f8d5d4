"""Fault suite of the application layer: bad scene files, options and heightfield
files fed to ``microsim.app.cli.main`` in-process, interrupts at every phase, concurrent runs,
disk full and read-only file systems.

For every bad input: the exit status (2 usage, 1 environment), exactly one stderr line naming
the file/key/path, no traceback, nothing written (the working directory unchanged) and
nothing lost (a finished result passed as ``--out … --force`` is intact). For every
interrupt (through ``checkpoints.interrupt_at``, deterministic): status 130, the main
simulation's complete tallies saved and resumable, no report from partial work, the previous
report intact. Runs are tiny (200 V-grooves, 2·10⁴ rays, one incidence) with a reduced
``--quick`` effort and stub charts, so the module takes well under a minute; the real charts
are covered by test_cli_run.py.
"""

from __future__ import annotations

import dataclasses
import errno
import hashlib
import json
import os
import signal
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from microsim import atomic
from microsim.analysis import charts
from microsim.app import runner
from microsim.app.cli import main
from microsim.app.runner import planning, tracing
from microsim.checkpoints import interrupt_at

TINY = """\
name = "{name}"
description = "tiny fault-test scene"
[surface]
kind = "vgrooves"
n_grooves = 200
ndf = "beckmann"
m = 0.3
[material]
ior = "aluminium"
[simulation]
theta_i = [30]
rays = 20000
theta_bins = 9
phi_bins = 10
seed = 3
"""
FAST = dataclasses.replace(
    runner.QUICK,
    sweep_theta=(0.0, 60.0),
    sweep_rays=4000,
    speed_rays=(2000, 4000),
    fig6_theta=(0.0, 60.0),
    fig6_rays=2000,
    albedo_nodes=(8, 8, 4),
    fit_names=("cook-torrance",),
)
CHARTS = (
    "inplane_curves",
    "hemisphere_maps",
    "energy_chart",
    "stability_chart",
    "speed_accuracy",
    "mikkelsen_fig6",
)


def _stub_chart(*args, **kwargs):
    path = next(a for a in args if isinstance(a, Path))
    atomic.write_text(path, "stub chart\n")
    return str(path)


def _fast(mp) -> None:
    mp.setattr(planning, "QUICK", FAST)
    for name in CHARTS:
        mp.setattr(charts, name, _stub_chart)


@pytest.fixture
def fast(monkeypatch):
    _fast(monkeypatch)


def run_cli(capsys, *args) -> tuple[int, list[str], str]:
    """(exit status, stderr lines, stderr) of ``microsim ARGS`` in-process."""
    capsys.readouterr()
    try:
        status = main([str(a) for a in args])
    except SystemExit as e:  # argparse's own errors
        status = e.code
    err = capsys.readouterr().err
    return status, err.strip().splitlines(), err


def tree(root: Path) -> dict:
    """path → (size, sha1) of every file and directory under ``root`` (hidden ones too)."""
    out = {}
    for p in sorted(root.rglob("*")):
        rel = str(p.relative_to(root))
        out[rel] = (
            ("dir",) if p.is_dir() else (p.stat().st_size, hashlib.sha1(p.read_bytes()).hexdigest())
        )
    return out


def scene(tmp: Path, name="tiny", text=None, file_name=None) -> Path:
    p = tmp / (file_name or f"{name}.toml")
    p.write_text(text if text is not None else TINY.format(name=name))
    return p


@pytest.fixture(scope="module")
def finished(tmp_path_factory):
    """A finished run (scene, out dir) to check that bad commands never touch it."""
    tmp = tmp_path_factory.mktemp("finished")
    with pytest.MonkeyPatch.context() as mp:
        _fast(mp)
        mp.chdir(tmp)
        sc = scene(tmp)
        assert main(["run", str(sc), "--quick", "--out", str(tmp / "done"), "--no-progress"]) == 0
    return sc, tmp / "done"


# --- the corpus of bad inputs -------------------------------------------------------------------
def _heightfield_scene(h_maker):
    def make(tmp):
        if h_maker is not None:
            h_maker(tmp / "h.npy")
        return scene(
            tmp,
            text='name = "hf"\n[surface]\nkind = "file"\npath = "h.npy"\ndx = 1.0\n',
            file_name="hf.toml",
        )

    return make


def _truncated_npy(p):
    np.save(p, np.zeros((16, 16)))
    p.write_bytes(p.read_bytes()[:150])


def _edit(edit):
    return lambda tmp: scene(tmp, text=edit(TINY.format(name="bad")), file_name="bad.toml")


def _latin1(tmp):
    p = tmp / "latin.toml"
    p.write_bytes(TINY.format(name="caf\u00e9").encode("latin-1"))
    return p


def _big(tmp):
    return scene(
        tmp, text=TINY.format(name="big") + "#" + "x" * (2 << 20) + "\n", file_name="big.toml"
    )


def _dir(tmp):
    (tmp / "adir.toml").mkdir()
    return tmp / "adir.toml"


BAD_SCENES = [
    # (id, maker(tmp) → scene path, words the one line must contain)
    ("directory", _dir, ["adir.toml", "directory"]),
    ("dev-zero", lambda tmp: Path("/dev/zero"), ["/dev/zero", "regular file"]),
    ("missing", lambda tmp: tmp / "nope.toml", ["nope.toml", "no such"]),
    ("not-utf8", _latin1, ["latin.toml", "UTF-8"]),
    ("too-large", _big, ["big.toml", "MiB"]),
    (
        "not-toml",
        lambda tmp: scene(tmp, text="[surface\nkind=", file_name="bad.toml"),
        ["bad.toml", "TOML"],
    ),
    ("name-empty", _edit(lambda t: t.replace('name = "bad"', 'name = ""')), ["bad.toml", "name"]),
    (
        "name-escape",
        _edit(lambda t: t.replace('name = "bad"', 'name = "../../escape"')),
        ["bad.toml", "name"],
    ),
    ("name-dot", _edit(lambda t: t.replace('name = "bad"', 'name = "."')), ["bad.toml", "name"]),
    (
        "name-slash",
        _edit(lambda t: t.replace('name = "bad"', 'name = "a/b"')),
        ["bad.toml", "name"],
    ),
    (
        "theta-bins-1e6",
        _edit(lambda t: t.replace("theta_bins = 9", "theta_bins = 1e6")),
        ["bad.toml", "simulation.theta_bins"],
    ),
    (
        "theta-bins-huge",
        _edit(lambda t: t.replace("theta_bins = 9", "theta_bins = 1000000")),
        ["bad.toml", "simulation.theta_bins"],
    ),
    (
        "phi-bins-1",
        _edit(lambda t: t.replace("phi_bins = 10", "phi_bins = 1")),
        ["bad.toml", "simulation.phi_bins"],
    ),
    (
        "n-grooves-1e8",
        _edit(lambda t: t.replace("n_grooves = 200", "n_grooves = 100000000")),
        ["bad.toml", "surface.n_grooves"],
    ),
    (
        "theta-i-95",
        _edit(lambda t: t.replace("theta_i = [30]", "theta_i = [95]")),
        ["bad.toml", "simulation.theta_i"],
    ),
    (
        "rays-zero",
        _edit(lambda t: t.replace("rays = 20000", "rays = 0")),
        ["bad.toml", "simulation.rays"],
    ),
    ("unknown-key", _edit(lambda t: t + "colour = 1\n"), ["bad.toml", "simulation.colour"]),
    (
        "sigma-1e200",
        lambda tmp: scene(
            tmp,
            file_name="bad.toml",
            text=('[surface]\nkind = "gaussian"\nn = 16\nsigma = 1e200\ncorr_len = 8.0\n'),
        ),
        ["bad.toml", "surface.sigma"],
    ),
    (
        "corr-len-1e-9",
        lambda tmp: scene(
            tmp,
            file_name="bad.toml",
            text=('[surface]\nkind = "gaussian"\nn = 16\nsigma = 1.0\ncorr_len = 1e-9\n'),
        ),
        ["bad.toml", "surface.corr_len"],
    ),
    (
        "grid-100000",
        lambda tmp: scene(
            tmp,
            file_name="bad.toml",
            text=('[surface]\nkind = "gaussian"\nn = 100000\nsigma = 1.0\ncorr_len = 8.0\n'),
        ),
        ["bad.toml", "surface.n"],
    ),
    ("hf-missing", _heightfield_scene(None), ["hf.toml", "surface.path", "h.npy"]),
    (
        "hf-3d",
        _heightfield_scene(lambda p: np.save(p, np.zeros((8, 8, 8)))),
        ["hf.toml", "surface.path", "2D"],
    ),
    (
        "hf-tiny",
        _heightfield_scene(lambda p: np.save(p, np.zeros((4, 4)))),
        ["hf.toml", "surface.path", "8"],
    ),
    (
        "hf-nan",
        _heightfield_scene(lambda p: np.save(p, np.full((16, 16), np.nan))),
        ["hf.toml", "surface.path", "NaN"],
    ),
    (
        "hf-complex",
        _heightfield_scene(lambda p: np.save(p, np.zeros((16, 16), complex))),
        ["hf.toml", "surface.path", "real"],
    ),
    ("hf-truncated", _heightfield_scene(_truncated_npy), ["hf.toml", "surface.path", "h.npy"]),
    (
        "hf-garbage",
        _heightfield_scene(lambda p: p.write_bytes(b"\x00garbage" * 10)),
        ["hf.toml", "surface.path", "h.npy"],
    ),
    ("hf-directory", _heightfield_scene(lambda p: p.mkdir()), ["hf.toml", "surface.path"]),
]


@pytest.mark.parametrize("make, words", [c[1:] for c in BAD_SCENES], ids=[c[0] for c in BAD_SCENES])
@pytest.mark.parametrize("command", ["run", "surface"])
def test_bad_scene_one_line_nothing_written_nothing_lost(
    tmp_path, capsys, monkeypatch, finished, make, words, command
):
    monkeypatch.chdir(tmp_path)
    path = make(tmp_path)
    before = tree(tmp_path)
    done = tree(finished[1])
    extra = ["--quick", "--out", finished[1], "--force"] if command == "run" else []
    status, lines, err = run_cli(capsys, command, path, *extra)
    assert status == 2, err
    assert len(lines) == 1 and "Traceback" not in err, err
    for w in words:
        assert w in lines[0], (w, lines[0])
    assert tree(tmp_path) == before  # nothing written (no runs/)
    assert tree(finished[1]) == done  # nothing lost


def _out_options(tmp: Path, sc: Path):
    (tmp / "afile").write_text("x")
    (tmp / "mine").mkdir()
    (tmp / "mine" / "thesis.tex").write_text("precious")
    return {
        "out-dot-force": (["--out", ".", "--force"], "."),
        "out-dotdot-force": (["--out", "..", "--force"], ".."),
        "out-cwd-abs-force": (["--out", tmp, "--force"], str(tmp)),
        "out-parent-of-cwd": (["--out", tmp.parent, "--force"], str(tmp.parent)),
        "out-parent-is-file": (["--out", tmp / "afile" / "run"], "afile"),
        "out-is-file": (["--out", tmp / "afile", "--force"], "afile"),
        "force-non-result": (["--out", tmp / "mine", "--force"], "mine"),
        "rays-zero": (["--rays", "0"], "--rays"),
        "rays-text": (["--rays", "many"], "--rays"),
        "rays-float": (["--rays", "1e12"], "--rays"),
        "threads-zero": (["--threads", "0"], "--threads"),
        "seed-negative": (["--seed", "-1"], "--seed"),
        "theta-95": (["--theta-i", "95"], "--theta-i"),
        "theta-text": (["--theta-i", "abc"], "--theta-i"),
        "resume-missing": (["--resume", tmp / "nothing"], "nothing"),
        "resume-and-force": (["--resume", tmp / "x", "--force"], "--force"),
    }


OUT_CASES = [
    "out-dot-force",
    "out-dotdot-force",
    "out-cwd-abs-force",
    "out-parent-of-cwd",
    "out-parent-is-file",
    "out-is-file",
    "force-non-result",
    "rays-zero",
    "rays-text",
    "rays-float",
    "threads-zero",
    "seed-negative",
    "theta-95",
    "theta-text",
    "resume-missing",
    "resume-and-force",
]


@pytest.mark.parametrize("case", OUT_CASES)
def test_bad_options_one_line_nothing_written(tmp_path, capsys, monkeypatch, case):
    work = tmp_path / "work"
    work.mkdir()
    monkeypatch.chdir(work)
    sc = scene(work)
    args, word = _out_options(work, sc)[case]
    before = tree(tmp_path)
    status, lines, err = run_cli(capsys, "run", sc, "--quick", *args)
    assert status == 2, err
    assert len(lines) == 1 and "Traceback" not in err and word in lines[0], err
    assert tree(tmp_path) == before


@pytest.mark.parametrize(
    "damage, name",
    [
        (lambda d: (d / "meta.json").write_text((d / "meta.json").read_text()[:50]), "meta.json"),
        (lambda d: (d / "brdf.npz").write_bytes((d / "brdf.npz").read_bytes()[:300]), "brdf.npz"),
        (lambda d: (d / "meta.json").write_text("[1, 2]"), "meta.json"),
        (lambda d: (d / "brdf.npz").unlink(), "brdf.npz"),
    ],
)
def test_truncated_saved_run_on_resume(tmp_path, capsys, monkeypatch, fast, damage, name):
    monkeypatch.chdir(tmp_path)
    sc = scene(tmp_path)
    out = tmp_path / "run"
    with interrupt_at("fits"):
        assert run_cli(capsys, "run", sc, "--quick", "--out", out, "--no-progress")[0] == 130
    damage(out)
    before = tree(tmp_path)
    status, lines, err = run_cli(capsys, "run", sc, "--quick", "--resume", out)
    assert status == 2 and len(lines) == 1 and "Traceback" not in err, err
    assert name in lines[0] and str(out) in lines[0]
    assert tree(tmp_path) == before


@pytest.mark.parametrize(
    "args, word",
    [
        (["report", "--catalogue", "nowhere"], "nowhere"),
        (["report", "--catalogue", "empty"], "empty"),
        (["report", "--catalogue", "dups"], "unique"),
        (["report", "--catalogue", "cat", "--out", "."], "--out"),
        (["report", "--catalogue", "cat", "--out", "cat"], "--out"),
        (["report", "--catalogue", "cat", "--resume"], "--resume"),
        (["report", "--catalogue", "badcat"], "name"),
        (["bench", "--rays", "0"], "--rays"),
        (["sweep-not-a-command"], "invalid choice"),
    ],
)
def test_bad_report_and_bench_options(tmp_path, capsys, monkeypatch, args, word):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "empty").mkdir()
    for d in ("dups", "cat", "badcat"):
        (tmp_path / d).mkdir()
    scene(tmp_path / "dups", "same", file_name="a.toml")
    scene(tmp_path / "dups", "same", file_name="b.toml")
    scene(tmp_path / "cat", "tiny")
    scene(tmp_path / "badcat", text=TINY.format(name="../up"), file_name="up.toml")
    before = tree(tmp_path)
    status, lines, err = run_cli(capsys, *args)
    assert status == 2, err
    assert len(lines) == 1 and "Traceback" not in err and word in lines[0], err
    assert tree(tmp_path) == before


PARSED_WITH = """
import sys
from microsim.app.cli import main
try:
    main(sys.argv[1:])
except SystemExit:  # --help, argparse's errors
    pass
print(" ".join(sorted(m for m in sys.modules if m.startswith(("microsim.", "numpy")))))
"""


@pytest.mark.parametrize(
    "args, loaded",
    [
        (["--help"], set()),
        (["not-a-command"], set()),
        (["bench", "--rays", "x"], {"microsim.app.bench"}),
        (["view", "--what", "x", "s.toml"], {"microsim.app.view"}),
    ],
)
def test_the_parser_loads_only_the_chosen_commands_module(tmp_path, args, loaded):
    """``microsim --help`` and a usage error need no simulator: the subcommands defined in
    their own modules (``cli.COMMANDS``) are loaded only when chosen."""
    proc = subprocess.run(
        [sys.executable, "-c", PARSED_WITH, *args], cwd=tmp_path, capture_output=True, text=True
    )
    modules = set(proc.stdout.split("\n")[-2].split())
    commands = {"microsim.app.measure", "microsim.app.view", "microsim.app.bench"}
    commands |= {"microsim.app.sweep"}
    assert modules & commands == loaded, proc.stderr
    assert ("numpy" in modules) == bool(loaded), proc.stderr


SWEEP_FILE = """\
rays = 1000
models = ["vgroove"]
theta_i = [30]
[[scenes]]
name = "vg"
ior = "aluminium"
[scenes.surface]
kind = "vgrooves"
n_grooves = 10
ndf = "beckmann"
m = [0.3]
"""


@pytest.mark.parametrize("command", ["run", "sweep"])
def test_permission_denied_on_scene_is_an_environment_error(tmp_path, capsys, monkeypatch, command):
    """Root reads any file, so the denial is injected: exit 1, one line naming the path — the
    same for a scene file (``microsim run``) and a sweep file (``microsim sweep``)."""
    monkeypatch.chdir(tmp_path)
    if command == "run":
        sc, args = scene(tmp_path), ["--quick"]
    else:
        sc, args = tmp_path / "s.toml", ["--out", str(tmp_path / "out")]
        sc.write_text(SWEEP_FILE)
    real_open = os.open

    def deny(path, *a, **k):
        if str(path) == str(sc):
            raise PermissionError(errno.EACCES, os.strerror(errno.EACCES), str(path))
        return real_open(path, *a, **k)

    monkeypatch.setattr(os, "open", deny)
    status, lines, err = run_cli(capsys, command, sc, *args)
    assert status == 1 and len(lines) == 1 and "Traceback" not in err, err
    assert str(sc) in lines[0] and "Permission denied" in lines[0]
    assert sorted(p.name for p in tmp_path.iterdir()) == [sc.name]


def test_a_bug_is_not_disguised_as_a_usage_error(tmp_path, capsys, monkeypatch):
    """A plain ValueError from inside the package is a bug: traceback and status 1."""
    monkeypatch.chdir(tmp_path)
    sc = scene(tmp_path)

    def broken(*a, **k):
        raise ValueError("internal inconsistency")

    monkeypatch.setattr(runner, "plan_run", broken)
    status, lines, err = run_cli(capsys, "run", sc, "--quick")
    assert status == 1 and "Traceback" in err and "internal inconsistency" in err


# --- environment failures during a run ----------------------------------------------------------
def _enospc(path):
    raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC), str(path))


def test_disk_full_while_writing_keeps_the_previous_result(tmp_path, capsys, monkeypatch, fast):
    """ENOSPC while writing the report: one line naming the file, exit 1, the old result of
    ``--force`` intact, no staging directory left behind."""
    monkeypatch.chdir(tmp_path)
    sc = scene(tmp_path)
    out = tmp_path / "run"
    assert run_cli(capsys, "run", sc, "--quick", "--out", out, "--no-progress")[0] == 0
    before = tree(tmp_path)
    real = atomic.write_text
    monkeypatch.setattr(
        atomic,
        "write_text",
        lambda path, text: _enospc(path) if path.name == "report.md" else real(path, text),
    )
    status, lines, err = run_cli(
        capsys, "run", sc, "--quick", "--out", out, "--force", "--no-progress"
    )
    assert status == 1 and len(lines) == 1 and "Traceback" not in err, err
    assert "report.md" in lines[0] and "No space left" in lines[0]
    assert tree(tmp_path) == before


@pytest.mark.parametrize("where", ["staging", "rename"])
def test_read_only_file_system(tmp_path, capsys, monkeypatch, fast, where):
    """EROFS when the output is created (or published): exit 1, one line, nothing written."""
    monkeypatch.chdir(tmp_path)
    sc = scene(tmp_path)
    out = tmp_path / "run"
    before = tree(tmp_path)

    def erofs(*a, **k):
        raise OSError(errno.EROFS, os.strerror(errno.EROFS), str(a[0]))

    if where == "staging":
        monkeypatch.setattr(atomic, "make_staging", erofs)
    else:
        monkeypatch.setattr(os, "rename", erofs)
    status, lines, err = run_cli(capsys, "run", sc, "--quick", "--out", out, "--no-progress")
    assert status == 1 and len(lines) == 1 and "Traceback" not in err, err
    assert "Read-only file system" in lines[0] and str(tmp_path) in lines[0]
    assert tree(tmp_path) == before


def test_failed_publish_puts_the_old_result_back(tmp_path, monkeypatch):
    """If the new directory cannot be renamed in, the old one is restored (never lost)."""
    old, stage = tmp_path / "out", tmp_path / "stage"
    old.mkdir()
    (old / "report.md").write_text("old")
    stage.mkdir()
    (stage / "report.md").write_text("new")
    real = os.rename

    def fail_second(src, dst):
        if Path(src) == stage:
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC), str(src))
        return real(src, dst)

    monkeypatch.setattr(os, "rename", fail_second)
    with pytest.raises(OSError):
        atomic.publish_dir(stage, old)
    assert (old / "report.md").read_text() == "old"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out", "stage"]


# --- interrupts at every phase ------------------------------------------------------------------
def _arrays(d: Path) -> dict:
    with np.load(d / "brdf.npz") as z:
        return {k: z[k] for k in z.files}


@pytest.fixture(scope="module")
def reference(tmp_path_factory):
    """An uninterrupted run of the tiny scene: its brdf.npz arrays."""
    tmp = tmp_path_factory.mktemp("reference")
    with pytest.MonkeyPatch.context() as mp:
        _fast(mp)
        mp.chdir(tmp)
        sc = scene(tmp)
        assert (
            main(
                [
                    "run",
                    str(sc),
                    "--quick",
                    "--rays",
                    "150000",
                    "--out",
                    str(tmp / "ref"),
                    "--no-progress",
                ]
            )
            == 0
        )
    return _arrays(tmp / "ref")


@pytest.mark.parametrize(
    "phase, after",
    [
        ("simulation", 0),
        ("side-studies", 0),
        pytest.param("side-studies", 2, marks=pytest.mark.slow),
        ("fits", 0),
        ("charts", 0),
        ("publish", 0),
    ],
)
def test_interrupt_at_each_phase_saves_tallies_and_resumes(
    tmp_path, capsys, monkeypatch, fast, reference, phase, after
):
    """Ctrl-C at ``phase``: exit 130, one line naming the directory and --resume, the tallies
    saved (complete ones after the simulation), no report; --resume finishes bitwise equal to
    an uninterrupted run."""
    monkeypatch.chdir(tmp_path)
    sc = scene(tmp_path)
    out = tmp_path / "run"
    opts = ["--quick", "--rays", "150000"]
    with interrupt_at(phase, after=after) as hit:
        status, lines, err = run_cli(capsys, "run", sc, *opts, "--out", out, "--no-progress")
    assert hit["fired"], f"no checkpoint({phase!r}) reached: a phase lost its checkpoint"
    assert status == 130 and len(lines) == 1 and "Traceback" not in err, err
    assert f"--resume {out}" in lines[0]
    meta = json.loads((out / "meta.json").read_text())
    assert meta["partial"] is (phase == "simulation")
    assert sorted(p.name for p in out.iterdir()) == ["brdf.npz", "meta.json"]  # no report
    assert sorted(p.name for p in tmp_path.iterdir()) == ["run", sc.name]  # no leftovers
    status, lines, err = run_cli(capsys, "run", sc, *opts, "--resume", out, "--no-progress")
    assert status == 0, err
    got = _arrays(out)
    for key in ("rays", "counts", "sum_w", "sum_w2", "brdf", "stderr"):
        assert np.array_equal(got[key], reference[key], equal_nan=True), key
    assert (out / "report.md").is_file() and (out / "verdicts.json").is_file()


def test_partial_side_study_is_an_interrupt(tmp_path, capsys, monkeypatch, fast):
    """``simulate`` returns a partial Result on SIGINT; a side study that got one must not
    feed the report: exit 130, complete tallies saved, no report."""
    monkeypatch.chdir(tmp_path)
    sc = scene(tmp_path)
    out = tmp_path / "run"
    real = tracing.simulate_scene

    def cut_short(plan, theta_i, rays, seed, bins, progress=None, resume=None, **kw):
        r = real(plan, theta_i, rays, seed, bins, progress=progress, resume=resume, **kw)
        if seed != plan.seed:  # a side study (own seed offset)
            r = r.with_meta(partial=True)
        return r

    monkeypatch.setattr(tracing, "simulate_scene", cut_short)
    status, lines, err = run_cli(capsys, "run", sc, "--quick", "--out", out, "--no-progress")
    assert status == 130 and len(lines) == 1, err
    assert not (out / "report.md").exists() and not (out / "verdicts.json").exists()
    assert json.loads((out / "meta.json").read_text())["partial"] is False


# --- microsim report: interrupts and --resume ---------------------------------------------------
@pytest.fixture
def catalogue(tmp_path, monkeypatch, fast, capsys):
    """Two tiny scenes and a finished report of them: (catalogue dir, report dir)."""
    monkeypatch.chdir(tmp_path)
    cat = tmp_path / "cat"
    cat.mkdir()
    scene(cat, "tiny-a")
    scene(cat, "tiny-b", text=TINY.format(name="tiny-b").replace("seed = 3", "seed = 4"))
    rep = tmp_path / "rep"
    assert (
        run_cli(capsys, "report", "--quick", "--catalogue", cat, "--out", rep, "--no-progress")[0]
        == 0
    )
    return cat, rep


@pytest.mark.parametrize(
    "phase, after, cut, saved",
    [
        pytest.param("report-scene", 1, "tiny-b", None, marks=pytest.mark.slow),  # between scenes
        pytest.param("fits", 1, "tiny-b", "complete", marks=pytest.mark.slow),  # after tiny-b's run
        # the same saved state as "fits", one phase later: slow (keeps the default run short)
        pytest.param("charts", 1, "tiny-b", "complete", marks=pytest.mark.slow),
        ("simulation", 0, "tiny-a", "partial"),  # inside tiny-a's simulation
        ("report-index", 0, None, None),  # every scene done
    ],
)
def test_report_interrupt_keeps_previous_report_and_resumes(
    capsys, catalogue, phase, after, cut, saved
):
    """Ctrl-C in ``microsim report``: exit 130, one line saying how to continue (``report
    --resume``, which exists), the interrupted scene's previous report intact and its tallies
    kept aside; ``report --resume`` skips the finished scenes and completes the rest."""
    cat, rep = catalogue
    before = {n: tree(rep / n) for n in ("tiny-a", "tiny-b")}
    opts = ["report", "--quick", "--catalogue", cat, "--out", rep, "--no-progress"]
    with interrupt_at(phase, after=after) as hit:
        status, lines, err = run_cli(capsys, *opts)
    assert hit["fired"], f"no checkpoint({phase!r}) reached"
    assert status == 130 and "Traceback" not in err, err
    last = [line for line in lines if "interrupted" in line]
    assert len(last) == 1 and "report --resume" in last[0], err
    if cut is not None:
        assert tree(rep / cut) == before[cut]  # previous report intact
        partial = rep / f".{cut}.partial"
        if saved is None:
            assert not partial.exists()
        else:
            meta = json.loads((partial / "meta.json").read_text())
            assert meta["partial"] is (saved == "partial")
    status, lines, err = run_cli(capsys, *opts, "--resume")
    assert status == 0, err
    finished = {line.split("] ")[1].split(":")[0] for line in lines if "finished earlier" in line}
    order = ["tiny-a", "tiny-b"]
    assert finished == set(order[: order.index(cut)] if cut else order), err
    index = (rep / "index.md").read_text()
    assert "tiny-a/report.md" in index and "tiny-b/report.md" in index
    assert (rep / "tiny-b" / "report.md").is_file()
    assert not [p.name for p in rep.iterdir() if p.name.startswith(".")]  # state cleaned


def test_report_without_resume_state_refuses_resume(capsys, catalogue):
    cat, rep = catalogue
    status, lines, err = run_cli(
        capsys, "report", "--quick", "--catalogue", cat, "--out", rep, "--resume"
    )
    assert status == 2 and len(lines) == 1 and "--resume" in lines[0], err


# --- concurrency, stale temporaries, permissions ------------------------------------------------
def test_concurrent_run_on_the_same_output_is_refused(tmp_path, capsys, monkeypatch, fast):
    """A second run while the first holds the output: one line, exit 2, the first's output
    untouched."""
    monkeypatch.chdir(tmp_path)
    sc = scene(tmp_path)
    out = tmp_path / "run"
    with atomic.output_lock(out):
        before = tree(tmp_path)
        status, lines, err = run_cli(capsys, "run", sc, "--quick", "--out", out)
        assert status == 2 and len(lines) == 1 and str(out) in lines[0], err
        assert "another microsim run" in lines[0]
        assert tree(tmp_path) == before
    assert not atomic.lock_path(out).exists()
    assert run_cli(capsys, "run", sc, "--quick", "--out", out, "--no-progress")[0] == 0


def test_two_in_process_plans_cannot_both_publish(tmp_path, capsys, monkeypatch, fast):
    """Both plans pass planning (the output does not exist yet); the second one to reach the
    output while the first is running is refused, and the first result is the one kept."""
    monkeypatch.chdir(tmp_path)
    sc = scene(tmp_path)
    out = tmp_path / "run"
    first = runner.plan_run(sc, out=out, quick=True)
    second = runner.plan_run(sc, out=out, quick=True, seed=9)
    outcome = {}

    def race(*a, **k):  # the second run starts while the first simulates
        if "second" not in outcome:
            outcome["second"] = None
            try:
                outcome["second"] = runner.execute(second, progress=False)
            except Exception as e:
                outcome["second"] = e
        return real(*a, **k)

    real = tracing.simulate_scene
    monkeypatch.setattr(tracing, "simulate_scene", race)
    assert runner.execute(first, progress=False).status == 0
    assert isinstance(outcome["second"], ValueError) and "another microsim run" in str(
        outcome["second"]
    )
    assert json.loads((out / "verdicts.json").read_text())["seed"] == first.seed


def test_lock_of_a_killed_process_does_not_block(tmp_path, capsys, monkeypatch, fast):
    """A process holding the lock blocks a run; once it is SIGKILLed (lock file left behind)
    the next run proceeds."""
    monkeypatch.chdir(tmp_path)
    sc = scene(tmp_path)
    out = tmp_path / "run"
    holder = subprocess.Popen(
        [
            sys.executable,
            "-c",
            (
                "import sys, time\nfrom microsim.atomic import output_lock\n"
                f"with output_lock({str(out)!r}):\n"
                "    print('held', flush=True)\n    time.sleep(60)\n"
            ),
        ],
        stdout=subprocess.PIPE,
        text=True,
    )
    try:
        assert holder.stdout.readline().strip() == "held"
        status, lines, err = run_cli(capsys, "run", sc, "--quick", "--out", out)
        assert status == 2 and f"pid {holder.pid}" in lines[0], err
    finally:
        holder.send_signal(signal.SIGKILL)
        holder.wait(timeout=10)
    assert atomic.lock_path(out).exists()  # stale file left by the kill
    assert run_cli(capsys, "run", sc, "--quick", "--out", out, "--no-progress")[0] == 0


def test_stale_staging_of_dead_processes_is_cleaned(tmp_path, capsys, monkeypatch, fast):
    """``.DIR.tmp-<pid>-*`` of a dead process is removed by the next run on DIR; a live
    process's and anything not named like microsim's own are left alone."""
    monkeypatch.chdir(tmp_path)
    sc = scene(tmp_path)
    dead = subprocess.Popen([sys.executable, "-c", "pass"])
    dead.wait()
    stale = [tmp_path / f".run.tmp-{dead.pid}-abc123", tmp_path / f".run.old-{dead.pid}-x_y"]
    keep = [
        tmp_path / f".run.tmp-{os.getppid()}-live",
        tmp_path / ".run.tmp-nopid",
        tmp_path / f".other.tmp-{dead.pid}-abc",
    ]
    for d in stale + keep:
        d.mkdir()
        (d / "brdf.npz").write_text("x")
    assert run_cli(capsys, "run", sc, "--quick", "--out", tmp_path / "run", "--no-progress")[0] == 0
    assert not any(d.exists() for d in stale)
    assert all(d.exists() for d in keep)


def test_outputs_get_the_users_normal_permissions(tmp_path, capsys, monkeypatch, fast):
    monkeypatch.chdir(tmp_path)
    sc = scene(tmp_path)
    old = os.umask(0o027)
    try:
        assert (
            run_cli(capsys, "run", sc, "--quick", "--out", tmp_path / "run", "--no-progress")[0]
            == 0
        )
    finally:
        os.umask(old)
    out = tmp_path / "run"
    assert out.stat().st_mode & 0o777 == 0o750
    modes = {p.name: p.stat().st_mode & 0o777 for p in out.iterdir()}
    assert set(modes.values()) == {0o640}, modes


def test_file_heightfield_scene_runs_end_to_end(tmp_path, capsys, monkeypatch, fast):
    """Bug 1: a ``kind = "file"`` scene used to crash after its simulation (report fmt())."""
    monkeypatch.chdir(tmp_path)
    np.save(tmp_path / "h.npy", 0.5 * np.random.default_rng(0).normal(size=(16, 16)))
    sc = scene(
        tmp_path,
        text='name = "hf"\n[surface]\nkind = "file"\npath = "h.npy"\n'
        "dx = 1.0\n[simulation]\ntheta_i = [30]\nrays = 20000\n"
        "theta_bins = 9\nphi_bins = 10\n",
    )
    status, lines, err = run_cli(
        capsys, "run", sc, "--quick", "--out", tmp_path / "run", "--no-progress"
    )
    assert status == 0, err
    report = (tmp_path / "run" / "report.md").read_text()
    assert "input_shape = 16 × 16" in report


def test_surface_prints_each_warning_once(tmp_path, capsys):
    np.save(tmp_path / "h.npy", np.random.default_rng(0).normal(size=(16, 16)))
    sc = scene(tmp_path, text='[surface]\nkind = "file"\npath = "h.npy"\ndx = 1.0\n')
    capsys.readouterr()
    assert main(["surface", str(sc)]) == 0
    cap = capsys.readouterr()
    text = cap.out + cap.err
    assert text.count("made periodic by mirroring") == 1, text


def test_a_missing_optional_extra_is_one_line_naming_the_extra(tmp_path, capsys, monkeypatch):
    """Without pyvista (the 'view' extra) `microsim view` says what to install, exit 1, no
    traceback; likewise Surface.mesh without trimesh."""
    monkeypatch.setitem(sys.modules, "pyvista", None)  # makes `import pyvista` fail
    monkeypatch.setitem(sys.modules, "trimesh", None)
    path = scene(tmp_path)
    status, lines, err = run_cli(
        capsys, "view", path, "--what", "surface", "--screenshot", tmp_path / "v.png"
    )
    assert status == 1 and len(lines) == 1 and "Traceback" not in err
    assert "microsim[view]" in lines[0]
    from microsim.errors import EnvironmentFailure
    from microsim.surfaces import flat

    with pytest.raises(EnvironmentFailure, match=r"microsim\[view\]"):
        flat().mesh()


def test_a_closed_stdout_stops_quietly():
    """`microsim models | head -1`: no 'Broken pipe' error line, no traceback."""
    r = subprocess.run(
        f"{sys.executable} -m microsim.app.cli models | head -1",
        shell=True,
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert r.stdout.startswith("Models as") and r.stderr == ""
