"""The wheel is a working microsim with its scene catalogue: built from a copy of the sources
(so no build folder lands in the clone), installed with ``pip install --no-deps --target``
into a folder of its own, and run from an empty working directory with only that folder on
``PYTHONPATH`` — the clone's editable install is never what gets imported.

From there: the README's quickstart command, ``microsim run NAME --quick``, on the cheapest
catalogue scene, ``flat-aluminium`` (the README's ``vgroove-beckmann-0.3`` adds ~15 s to the
kernels' first compilation into the installed copy, ~30 s), and the README's testing example,
``assert_brdf_agrees`` on the catalogue name ``vgroove-ggx-0.3`` with a catalogue model. The
build needs setuptools ≥ 77 (pyproject.toml's ``[build-system]``): taken from this interpreter
when it has it, else from the package registry (pip's build isolation).
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from importlib import metadata
from pathlib import Path

import pytest

from microsim.app.scene import catalogue_names

pytestmark = [pytest.mark.integration, pytest.mark.long]

ROOT = Path(__file__).resolve().parents[1]
SOURCES = ("pyproject.toml", "README.md", "LICENSE", "microsim")
"""What the build reads: the project's metadata, its readme and license, the package."""
TESTING_EXAMPLE = """\
import microsim
from microsim.testing import assert_brdf_agrees, find_scene

print("package", microsim.__file__)
print("scene", find_scene("vgroove-ggx-0.3"))
assert_brdf_agrees(
    "ts-vgroove", "vgroove-ggx-0.3", theta_i=[30], rays=200_000, bins=(9, 9), cache="cache"
)
print("agrees")
"""


def _setuptools_builds() -> bool:
    """Whether this interpreter's setuptools can build the project without isolation."""
    try:
        return int(metadata.version("setuptools").split(".")[0]) >= 77
    except (metadata.PackageNotFoundError, ValueError):
        return False


def _wheel(tmp: Path) -> Path:
    """The wheel built from a copy of the sources into ``tmp/dist``."""
    src = tmp / "src"
    src.mkdir()
    for name in SOURCES:
        if (ROOT / name).is_dir():
            ignore = shutil.ignore_patterns("__pycache__", "*.pyc", "*.nbi", "*.nbc")
            shutil.copytree(ROOT / name, src / name, ignore=ignore)
        else:
            shutil.copy2(ROOT / name, src / name)
    isolation = ["--no-build-isolation"] if _setuptools_builds() else []
    cmd = [sys.executable, "-m", "pip", "wheel", "--no-deps", *isolation, str(src)]
    r = subprocess.run(
        [*cmd, "-w", str(tmp / "dist")], capture_output=True, text=True, timeout=300, cwd=tmp
    )
    assert r.returncode == 0, r.stdout[-2000:] + r.stderr[-2000:]
    (wheel,) = (tmp / "dist").glob("microsim-*.whl")
    return wheel


def _run(args, cwd: Path, site: Path) -> subprocess.CompletedProcess:
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    env["PYTHONPATH"] = str(site)
    return subprocess.run(
        [sys.executable, *args],
        cwd=cwd,
        env=env,
        capture_output=True,
        text=True,
        encoding="utf-8",
        errors="replace",
        timeout=300,
    )


def test_the_installed_wheel_runs_the_readme_examples_from_an_empty_folder(tmp_path):
    wheel = _wheel(tmp_path)
    site = tmp_path / "site"
    r = subprocess.run(
        [sys.executable, "-m", "pip", "install", "--no-deps", "--target", str(site), str(wheel)],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert r.returncode == 0, r.stderr[-2000:]
    scenes = site / "microsim" / "scenes"
    assert sorted(p.stem for p in scenes.glob("*.toml")) == catalogue_names()
    assert (scenes / "heightfields" / "gaussian-64.npy").is_file()

    empty = tmp_path / "empty"
    empty.mkdir()
    run = ["run", "flat-aluminium", "--quick"]
    r = _run(["-m", "microsim.app.cli", *run, "--no-progress"], empty, site)
    assert r.returncode == 0, r.stderr[-3000:]
    summary = r.stdout.splitlines()
    assert summary[0].startswith("flat-aluminium:"), r.stdout
    assert any(s.startswith("agrees at every") and "mirror-fresnel" in s for s in summary), r.stdout
    verdicts = json.loads((empty / "runs" / "flat-aluminium" / "verdicts.json").read_text())
    scene = scenes / "flat-aluminium.toml"
    assert Path(verdicts["scene_file"]).resolve() == scene.resolve()

    r = _run(["-c", TESTING_EXAMPLE], empty, site)
    assert r.returncode == 0, r.stderr[-3000:]
    lines = dict(line.split(" ", 1) for line in r.stdout.splitlines() if " " in line)
    assert Path(lines["package"]).resolve().is_relative_to(site.resolve()), r.stdout
    assert Path(lines["scene"]).resolve() == (scenes / "vgroove-ggx-0.3.toml").resolve()
    assert r.stdout.splitlines()[-1] == "agrees", r.stdout
