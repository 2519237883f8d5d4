"""Several incidence azimuths in one run (``[simulation] phi_i = [...]``): the runner traces
every θi at each φi, and every output — verdicts.json, report.md, the printed summary,
``microsim.testing`` — keys its verdicts by (θi, φi).

Facts checked, on oriented V-grooves (where ``ts-facets`` is exact for single scattering and
the BRDF depends on φi): ts-facets agrees at every (θi, φi) of the run; the incidences at
different φi are different measurements (their bin averages differ far beyond noise), so the
azimuth really reached the tracer; the incidences' order and labels are the documented ones;
``microsim.testing`` judges a BRDF at (θi, φi) pairs and names the failing pair; bad
``phi_i`` values fail at load time naming the key."""

from __future__ import annotations

import json
import tempfile
from pathlib import Path

import numpy as np
import pytest
from test_cli_run import microsim

from microsim.analysis.verdicts import verdict_kind
from microsim.analytic import Beckmann, TorranceSparrow, VGroove
from microsim.app.scene import incidence_pairs, load_scene
from microsim.errors import UsageError
from microsim.testing import assert_brdf_agrees
from microsim.testing.agreement import BRDFMismatch

pytestmark = pytest.mark.integration

SCENE = """\
name = "oriented-azimuths"
description = "oriented V-grooves at three incidence azimuths"
[surface]
kind = "vgrooves"
n_grooves = 1000
ndf = "beckmann"
m = 0.3
oriented = true
[material]
ior = "aluminium"
[simulation]
theta_i = [30, 70]
rays = 200000
theta_bins = 18
phi_bins = 24
phi_i = {phi_i}
seed = 5
"""
PHIS = [0.0, 45.0, 120.0]


def _scene(tmp, phi_i) -> str:
    p = tmp / "oriented-azimuths.toml"
    p.write_text(SCENE.format(phi_i=phi_i))
    return p


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("azimuths")
    scene = _scene(tmp, json.dumps(PHIS))
    out = tmp / "run"
    r = microsim("run", scene, "--out", out, "--no-progress", "--quick", timeout=300)
    assert r.returncode == 0, r.stderr
    return scene, out, r.stdout


def test_every_theta_at_every_phi_in_the_documented_order(run):
    _, out, _ = run
    with np.load(out / "brdf.npz") as z:
        theta, phi = z["theta_i"], z["phi_i"]
    want_t, want_p = incidence_pairs([30.0, 70.0], PHIS)
    assert theta.tolist() == list(want_t) == [30.0, 70.0] * 3
    assert phi.tolist() == list(want_p) == [0.0, 0.0, 45.0, 45.0, 120.0, 120.0]
    doc = json.loads((out / "verdicts.json").read_text())
    assert doc["phi_i"] == PHIS and doc["theta_i"] == [30.0, 70.0]
    keys = {(v["theta_i"], v["phi_i"]) for v in doc["verdicts"]}
    assert keys == set(zip(want_t, want_p))


def test_the_exact_form_agrees_at_every_incidence_and_the_azimuths_differ(run):
    """ts-facets is exact on oriented grooves: it must agree at each of the six (θi, φi),
    judged at the run's family level. The φi blocks are distinct measurements: at θi = 70°
    the energy-weighted χ²/bin between φi = 0° and 45° of the simulated BRDFs is ≫ 1."""
    _, out, _ = run
    doc = json.loads((out / "verdicts.json").read_text())
    facets = [v for v in doc["verdicts"] if v["model"] == "ts-facets"]
    assert len(facets) == 6
    assert all(verdict_kind(v) == "agrees" for v in facets), [
        (v["theta_i"], v["phi_i"], v["chi2_dof"]) for v in facets
    ]
    with np.load(out / "brdf.npz") as z:
        f, se, n = z["brdf"], z["stderr"], z["counts"]
    a, b = 1, 3  # θi 70° at φi 0° and 45°
    used = (n[a] >= 100) & (n[b] >= 100)
    chi2 = np.mean((f[a][used] - f[b][used]) ** 2 / (se[a][used] ** 2 + se[b][used] ** 2))
    assert chi2 > 10.0


def test_outputs_name_each_incidence_by_theta_and_phi(run):
    _, out, stdout = run
    assert "θi 30°, φi 45°" in stdout and "θi 70°, φi 120°" in stdout
    report = (out / "report.md").read_text()
    assert "| incidence azimuths φi | 0°, 45°, 120°" in report
    assert "| θi | φi | model | verdict |" in report
    assert "| θi | φi | rays |" in report  # the energy ledger
    assert "at φi = 0°" in report  # the side studies trace the first azimuth


def test_resume_records_the_azimuths(run, tmp_path):
    scene, out, _ = run
    meta = json.loads((out / "meta.json").read_text())
    assert meta["run"]["phi_i"] == PHIS
    other = _scene(tmp_path, "[0, 45]")
    r = microsim("run", other, "--resume", out, "--no-progress", "--quick")
    assert r.returncode == 2 and "simulation.phi_i" in r.stderr, r.stderr


def test_testing_judges_pairs_and_names_the_failing_one():
    """A scene's (θi, φi) pairs reach ``microsim.testing``: the exact form passes at every
    pair; the azimuth-averaged V-cavity form (the isotropic surface's model) fails, and the
    message names θi and φi."""
    scene = load_scene_text(SCENE.format(phi_i="[0, 90]"))
    ok = assert_brdf_agrees("ts-facets", scene, rays=100_000, cache=False, seed=1)
    assert [tuple(v) for v in zip(ok["reference"].theta_i, ok["reference"].phi_i)] == [
        (30.0, 0.0),
        (70.0, 0.0),
        (30.0, 90.0),
        (70.0, 90.0),
    ]
    iso = TorranceSparrow(Beckmann(0.3), VGroove(), material="aluminium")
    with pytest.raises(BRDFMismatch) as e:
        assert_brdf_agrees(iso.f, scene, rays=100_000, cache=False, seed=1, name="v-cavity")
    assert "φi = 90°" in str(e.value) and e.value.agreement["failing_incidences"]


def load_scene_text(text):
    d = Path(tempfile.mkdtemp())
    p = d / "scene.toml"
    p.write_text(text)
    return load_scene(p)


@pytest.mark.parametrize(
    "value, message",
    [
        ("[0, 360]", "twice"),
        ("[]", "non-empty list"),
        ("[0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12]", "at most 12"),
        ('"x"', "degrees in [-360, 360]"),
        ("[0, 400]", "degrees in [-360, 360]"),
    ],
)
def test_bad_azimuth_lists_name_the_key(value, message):
    with pytest.raises(UsageError, match="simulation.phi_i") as e:
        load_scene_text(SCENE.format(phi_i=value))
    assert message in str(e.value)


def test_grouped_incidence_lists_name_every_azimuth():
    from microsim.analysis.incidence import grouped

    def vs(*pairs):
        return [{"theta_i": t, "phi_i": p} for t, p in pairs]

    assert grouped(vs((80, 0))) == "80° at φi 0°"
    assert grouped(vs((0, 0), (80, 0), (0, 90), (80, 90)), ",") == "0,80° at φi 0,90°"
    assert grouped(vs((60, 0), (80, 0), (80, 90))) == "60, 80° at φi 0° and 80° at φi 90°"
