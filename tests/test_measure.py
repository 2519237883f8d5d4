"""`microsim measure` (``app.measure``): a dense table of the single-bounce BRDF, each incidence
to its error target, resumable.

Facts checked: the table holds every θi of the grid on the scene's bins, each incidence met its
target or says it did not, and the table agrees with the scene's exact closed form (V-grooves:
Torrance–Sparrow with V-groove G) within its own standard errors (χ² per bin near 1); an
interrupt keeps the finished incidences and ``--resume`` completes the table to exactly the
uninterrupted one (each incidence seeded by its index); a resume with other settings, an
anisotropic scene and bad options are one-line errors naming the option; a table round-trips
through ``BRDFTable.save``/``load``."""

from __future__ import annotations

import json

import numpy as np
import pytest

from microsim.analytic import Beckmann
from microsim.analytic.models import TorranceSparrow
from microsim.app.cli import main
from microsim.app.measure import measure, plan_measure
from microsim.checkpoints import interrupt_at
from microsim.errors import UsageError
from microsim.measured import BRDFTable
from microsim.sim.predict import Predictor, predict

SCENE = """\
name = "tiny-measure"
[surface]
kind = "vgrooves"
n_grooves = 2000
ndf = "beckmann"
m = 0.3
[material]
ior = "aluminium"
[simulation]
theta_bins = 18
phi_bins = 19
"""


@pytest.fixture
def scene(tmp_path):
    p = tmp_path / "tiny-measure.toml"
    p.write_text(SCENE)
    return p


def _plan(scene, out, exports=(), **kw):
    return plan_measure(
        scene, out=out, theta_step=20.0, theta_max=80.0, target=0.03, exports=exports, **kw
    )


@pytest.mark.slow  # 10 s; tests/test_merl.py and tests/test_rgl.py keep the round trips
def test_the_exports_read_back_to_the_table_within_its_noise(scene, tmp_path):
    """The MERL and RGL files of the table, read back and bin-averaged, differ from the table by
    about the table's own noise (MERL stores a reciprocal average, both interpolate, which
    smooths the noise; the bins' second-order smoothing adds a little): at most twice it plus
    1 %."""
    fine = tmp_path / "fine.toml"  # 2° × 5° bins: coarser ones add their own smoothing
    fine.write_text(SCENE.replace("theta_bins = 18", "theta_bins = 45").replace("19", "37"))
    out = tmp_path / "m"
    measure(_plan(fine, out, exports=None), log=None)
    exports = json.loads((out / "measure.json").read_text())["exports"]
    assert sorted(exports) == ["merl", "rgl"]
    assert exports["merl"]["bytes"] == 34_992_012
    for fmt, e in exports.items():
        assert (out / e["file"]).stat().st_size == e["bytes"]
        # θi ≤ 60°: at 80° the reciprocal partner (MERL) or the file's incidences between 80°
        # and 88° (RGL) lie beyond the table's last θi, where it is clamped
        for err, se in list(zip(e["interpolation_rel_rms"], e["table_rel_se"]))[:-1]:
            assert err <= 2 * se + 0.01, (fmt, err, se)


def test_the_table_is_the_exact_form_within_its_errors(scene, tmp_path):
    out = tmp_path / "m"
    table = measure(_plan(scene, out), log=None)
    assert table.theta_i.tolist() == [0.0, 20.0, 40.0, 60.0, 80.0]
    doc = json.loads((out / "measure.json").read_text())
    assert all(d["converged"] and d["rse"] <= 0.03 for d in doc["incidences"].values())
    assert doc["totals"]["rays"] == sum(d["rays"] for d in doc["incidences"].values())
    spec = Predictor("ts", TorranceSparrow(Beckmann(0.3), "vgroove", "aluminium"))
    model = predict([spec], table.theta_i, table.bins)["ts"]
    ok = table.stderr > 0
    chi2 = np.mean(((table.brdf - model)[ok] / table.stderr[ok]) ** 2)
    assert 0.5 < chi2 < 2.0  # the one tile departs from its ensemble by far less than noise
    back = BRDFTable.load(out / "table.npz")
    assert np.array_equal(back.brdf, table.brdf) and back.bins == table.bins


def test_an_interrupt_keeps_finished_incidences_and_resume_completes_them(scene, tmp_path):
    whole = measure(_plan(scene, tmp_path / "whole"), log=None)
    out = tmp_path / "cut"
    with interrupt_at("simulation", after=30) as state, pytest.raises(KeyboardInterrupt):
        measure(_plan(scene, out), log=None)
    assert state["fired"]
    kept = json.loads((out / "measure.json").read_text())["incidences"]
    assert 0 < len(kept) < 5 and not (out / "table.npz").exists()
    again = measure(_plan(scene, out, resume=True), log=None)
    assert np.array_equal(again.brdf, whole.brdf) and np.array_equal(again.stderr, whole.stderr)


def test_bad_input_names_the_option(scene, tmp_path, capsys):
    out = tmp_path / "m"
    measure(_plan(scene, out), log=None)
    with pytest.raises(UsageError, match="already exists"):
        _plan(scene, out)
    with pytest.raises(UsageError, match="target is 0.03 there but 0.05 now"):
        plan_measure(scene, out=out, theta_step=20.0, theta_max=80.0, target=0.05, resume=True)
    with pytest.raises(UsageError, match="--export"):
        _plan(scene, tmp_path / "e", exports=("obj",))
    for kw, name in (({"theta_step": 0}, "--theta-step"), ({"target": 2.0}, "--target")):
        with pytest.raises(UsageError, match=name):
            plan_measure(scene, out=tmp_path / "x", **kw)
    np.save(tmp_path / "h.npy", np.random.default_rng(0).normal(size=(16, 16)))
    hf = tmp_path / "hf.toml"
    hf.write_text('name = "hf"\n[surface]\nkind = "file"\npath = "h.npy"\ndx = 1.0\n')
    with pytest.raises(UsageError, match="--export rgl: .* no ensemble NDF"):
        plan_measure(hf, out=tmp_path / "h", exports=("rgl",))
    assert plan_measure(hf, out=tmp_path / "h").exports == ("merl",)  # the RGL file left out
    aniso = tmp_path / "aniso.toml"
    aniso.write_text(SCENE.replace("m = 0.3", "m = 0.3\noriented = true").replace("19", "20"))
    with pytest.raises(UsageError, match="anisotropic"):
        plan_measure(aniso, out=tmp_path / "y")
    assert main(["measure", str(scene), "--out", str(tmp_path / "z"), "--target", "7"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "--target" in err
