"""The scene catalogue ships in the package and every command and API takes its names.

From an empty working directory (nothing named like a scene there): ``microsim run``,
``surface``, ``measure`` (its plan: validated, nothing traced), ``view`` and ``report``'s default
catalogue, and the testing API's ``find_scene``, all read the packaged file; a relative
heightfield path of a catalogue scene resolves beside its file; an existing path wins over a
catalogue name; a name that is neither is one line naming the argument and listing the
catalogue's names (CLI status 2, nothing written); the catalogue is the set docs/scenes.md
lists.
"""

from __future__ import annotations

import re
from pathlib import Path

import pytest
from support import refused
from test_view import _run, opengl  # noqa: F401  (the off-screen OpenGL probe fixture)

from microsim.app.cli import main
from microsim.app.measure import plan_measure
from microsim.app.runner import catalogue as report_catalogue
from microsim.app.scene import CATALOGUE, catalogue_names, load_scene, resolve_scene
from microsim.errors import EXIT_USAGE, UsageError
from microsim.testing import find_scene

DOCS = Path(__file__).resolve().parents[1] / "docs" / "scenes.md"
CHEAPEST = "flat-aluminium"


@pytest.fixture
def empty_cwd(tmp_path, monkeypatch):
    """An empty working directory outside the clone."""
    work = tmp_path / "work"
    work.mkdir()
    monkeypatch.chdir(work)
    return work


def _status(capsys, *args):
    """(exit status, stdout, stderr lines) of ``microsim ARGS`` in-process."""
    capsys.readouterr()
    status = main([str(a) for a in args])
    out, err = capsys.readouterr()
    return status, out, err.strip().splitlines()


def test_the_packaged_catalogue_is_the_set_the_docs_list():
    """docs/scenes.md, "The catalogue": one table row per packaged scene, no more, no less."""
    text = DOCS.read_text(encoding="utf-8")
    section = text.split("## The catalogue", 1)[1].split("\n## ", 1)[0]
    documented = re.findall(r"^\| `([^`]+)` \|", section, flags=re.M)
    assert sorted(documented) == catalogue_names()
    assert len(documented) == len(set(documented))
    assert CATALOGUE.is_relative_to(Path(__file__).resolve().parents[1] / "microsim")


def test_a_name_with_or_without_toml_is_the_packaged_file(empty_cwd):
    for given in (CHEAPEST, f"{CHEAPEST}.toml"):
        path = resolve_scene(given)
        assert path.resolve() == CATALOGUE / f"{CHEAPEST}.toml"
    assert find_scene("vgroove-ggx-0.3").resolve() == CATALOGUE / "vgroove-ggx-0.3.toml"
    assert load_scene("vgroove-ggx-0.3").name == "vgroove-ggx-0.3"


def test_a_catalogue_heightfield_resolves_beside_its_scene_file(empty_cwd):
    scene = load_scene("file-gaussian-64")
    surface = scene.build_surface()
    assert Path(surface.nominal["path"]).resolve() == (
        CATALOGUE / "heightfields" / "gaussian-64.npy"
    )


def test_an_existing_path_wins_over_the_catalogue_name(empty_cwd):
    mine = (
        (CATALOGUE / f"{CHEAPEST}.toml")
        .read_text()
        .replace(f'name = "{CHEAPEST}"', 'name = "my-own"')
    )
    (empty_cwd / f"{CHEAPEST}.toml").write_text(mine)
    assert load_scene(f"{CHEAPEST}.toml").name == "my-own"  # the local file, as given
    assert load_scene(CHEAPEST).name == CHEAPEST  # no such local path: the catalogue's


@pytest.mark.parametrize("given", ["no-such-scene", "surfaces/vgroove-ggx-0.3.toml", "x/flat"])
def test_a_bad_name_names_the_argument_and_every_catalogue_scene(empty_cwd, given):
    msg = refused(lambda: resolve_scene(given), "scene:", given, *catalogue_names())
    assert msg.startswith("scene: ")
    refused(lambda: find_scene(given), "surface_or_scene:", *catalogue_names())


@pytest.mark.parametrize(
    "command",
    [
        ["run", "--quick"],
        ["surface"],
        ["measure", "--quick"],
        ["view", "--screenshot", "v.png"],
    ],
)
def test_every_command_refuses_a_bad_name_in_one_line(empty_cwd, capsys, command):
    status, out, err = _status(capsys, command[0], "no-such-scene", *command[1:])
    assert status == EXIT_USAGE and len(err) == 1, err
    assert err[0].startswith("microsim: error: scene: no such scene file 'no-such-scene'")
    assert all(name in err[0] for name in catalogue_names()), err[0]
    assert list(empty_cwd.iterdir()) == []


def test_run_and_surface_take_a_catalogue_name_from_an_empty_folder(empty_cwd, capsys):
    status, out, err = _status(capsys, "surface", "vgroove-beckmann-0.3")
    assert status == 0 and "vgrooves" in out, err
    args = ["run", CHEAPEST, "--quick", "--rays", "20000", "--theta-i", "30", "--no-progress"]
    status, out, err = _status(capsys, *args, "--out", "out")
    assert status == 0, err
    assert "mirror-fresnel" in out and (empty_cwd / "out" / "verdicts.json").is_file()


def test_measure_plans_a_catalogue_name_from_an_empty_folder(empty_cwd):
    acq = plan_measure(CHEAPEST, out="m", theta_step=45.0, theta_max=45.0, quick=True)
    assert acq.scene.path.resolve() == CATALOGUE / f"{CHEAPEST}.toml"
    assert list(empty_cwd.iterdir()) == []  # planned, nothing written


@pytest.mark.slow
def test_view_renders_a_catalogue_name_from_an_empty_folder(empty_cwd, opengl):  # noqa: F811
    r = _run([CHEAPEST, "--what", "surface", "--screenshot", "v.png"], cwd=empty_cwd)
    assert r.returncode == 0, r.stderr
    assert (empty_cwd / "v.png").stat().st_size > 0


def test_report_runs_the_packaged_catalogue_by_default(empty_cwd, capsys, monkeypatch):
    """``microsim report`` without ``--catalogue`` loads every packaged scene (stopped right
    after loading them: running the catalogue is make demo's job)."""
    loaded, load = {}, report_catalogue._load_catalogue

    def load_then_stop(catalogue, out):
        loaded["paths"] = load(catalogue, out)[0]
        raise UsageError("stopped after loading the catalogue")

    monkeypatch.setattr(report_catalogue, "_load_catalogue", load_then_stop)
    status, out, err = _status(capsys, "report", "--quick", "--out", "rep")
    assert status == EXIT_USAGE and err == ["microsim: error: stopped after loading the catalogue"]
    assert sorted(p.stem for p in loaded["paths"]) == catalogue_names()
    assert all(p.resolve().parent == CATALOGUE for p in loaded["paths"])


def test_the_catalogue_scan_is_read_as_a_measured_surface(empty_cwd):
    """The X3P beside its scene: read in micrometres with its own spacing, its plane removed,
    its missing points filled and, not being periodic, mirrored into a periodic tile."""
    surface = load_scene("scan-gaussian-96").build_surface()
    assert Path(surface.nominal["path"]).resolve() == (
        CATALOGUE / "heightfields" / "gaussian-window-96.x3p"
    )
    assert surface.nominal["unit"] == "µm" and surface.nominal["form"] == "plane"
    assert 0.0 < surface.nominal["filled_fraction"] < 0.02
    assert surface.periodic and not surface.nominal["periodic_input"]
