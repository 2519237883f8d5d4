"""Rough glass answers (``analysis.glass``, ``runner.glass``): Walter et al. 2007's BSDF
judged against the traced first order from both sides, a scene with ``[material]
transmission`` run end to end (the inside run saved, verdicts.json "glass", the report's and
the index's "Rough glass"), and the scene key's errors."""

from __future__ import annotations

import json

import numpy as np
import pytest

from microsim import analytic as an
from microsim.analysis.glass import glass_models, glass_study, lobe_measured, lobe_values
from microsim.analysis.glass_report import glass_chart, glass_index, glass_section
from microsim.analysis.multiple import realised_ndf
from microsim.analysis.study_records import RunDocument
from microsim.analysis.verdicts import Prediction, verdict
from microsim.analytic.dielectric import WalterDielectric
from microsim.analytic.masking import Smith
from microsim.app.cli import main
from microsim.app.scene import SceneError, load_scene
from microsim.bins import Bins
from microsim.sim import simulate
from microsim.surfaces import gaussian


def test_walters_bsdf_agrees_with_the_first_order_where_smiths_assumptions_hold():
    """On Gaussian heightfields (m = 0.3: Smith's uncorrelated masking holds away from
    grazing), Walter et al. 2007's BRDF and BTDF with the tiles' realised Beckmann roughness
    agree with the traced order 1, lit from the air and from inside, by the verdicts' own
    statistics (realisation scatter); the same model with a wrong index (1.4 for 1.5) is
    found to deviate, so the comparison has the power to see a wrong BSDF."""
    tiles = [gaussian(256, 1.0, 1.2, 8.0, seed=k) for k in range(4)]
    kw = dict(transmission=True, rays=1_000_000, bins=Bins(30, 25), realisations=tiles)
    r = simulate(None, 1.5, [30.0, 150.0], **kw)
    ndf = realised_ndf(tiles)
    wrong = WalterDielectric(ndf, Smith(correlated=True), 1.4)
    for t in range(2):
        for lobe in ("reflected", "transmitted"):
            m = lobe_measured(r, t, lobe)
            for name, model in glass_models(ndf, 1.5).items():
                v = verdict(m, Prediction(lobe_values(model, r, t, lobe), name, ensemble=True))
                assert v.agrees, (name, lobe, r.theta_i[t], v.rel_rms)
                assert abs(v.energy_dev) < 4 * v.energy_dev_se
            bad = verdict(m, Prediction(lobe_values(wrong, r, t, lobe), "wrong", ensemble=True))
            assert not bad.agrees


SCENE = """\
name = "glass-small"
[surface]
kind = "gaussian"
n = 64
dx = 1.0
sigma = 1.2
corr_len = 8.0
[material]
ior = 1.5
transmission = true
[simulation]
theta_i = [20, 70]
rays = 20000
theta_bins = 9
phi_bins = 7
bounces = "all"
seed = 1
"""


def test_the_glass_study_reports_both_sides(tmp_path):
    """The study of a run from the air and one from inside (``glass_study``): one row per
    incidence and side, R + T = 1 (every path reflected or transmitted), the three Walter
    variants' single-scattering energies below 1, the random walk's R and T summing to 1; the
    report section, the index rows and the chart from it."""
    tile = gaussian(64, 1.0, 1.2, 8.0, seed=3)
    kw = dict(transmission=True, bounces="all", rays=20_000, bins=Bins(9, 7))
    above, inside = simulate(tile, 1.5, [20.0], **kw), simulate(tile, 1.5, [160.0], **kw)
    predictions = {}
    study = glass_study(
        above, inside, an.Beckmann(0.3), 1.5, "inside", walk_paths=4000, predictions=predictions
    )
    assert [(g.side, g.theta) for g in study.incidences] == [("air", 20.0), ("medium", 20.0)]
    for g in study.incidences:
        assert g.reflected + g.transmitted == pytest.approx(1.0, abs=1e-12)
        assert all(0.9 < sum(rt) < 1.0 for rt in g.models.values())
        assert sum(g.multiple["random-walk"][:2]) == pytest.approx(1.0, abs=1e-12)
    assert (20.0, "transmitted", "walter-smith-corr-beta") in predictions
    section = "\n".join(glass_section(study))
    assert "## Rough glass" in section and "air → medium" in section and "medium → air" in section
    doc = RunDocument(scene="glass-tiny", glass=study)
    assert "glass-tiny" in "\n".join(glass_index([doc]))
    glass_chart(above, inside, predictions, tmp_path / "glass.png", "glass-tiny")
    assert (tmp_path / "glass.png").stat().st_size > 0


# slow (15 s end to end, most of it the run's regular analysis): the default run covers the
# study, its report, index and chart above, and the dielectric paths in test_dielectric
@pytest.mark.integration
@pytest.mark.slow
def test_a_glass_scene_is_traced_from_both_sides_and_reported(tmp_path):
    scene = tmp_path / "glass.toml"
    scene.write_text(SCENE)
    out = tmp_path / "run"
    assert main(["run", str(scene), "--quick", "--out", str(out), "--no-progress"]) == 0
    doc = json.loads((out / "verdicts.json").read_text())
    glass = doc["glass"]
    assert glass["eta"] == 1.5 and glass["inside"] == "inside"
    sides = [(g["side"], g["theta"], g["theta_i"]) for g in glass["incidences"]]
    assert sides == [
        ("air", 20.0, 20.0),
        ("air", 70.0, 70.0),
        ("medium", 20.0, 160.0),
        ("medium", 70.0, 110.0),
    ]
    for g in glass["incidences"]:  # a lossless interface: every path reflected or transmitted
        assert g["reflected"] + g["transmitted"] == pytest.approx(1.0, abs=1e-12)
        assert 0.0 < g["single"] <= 1.0
        assert set(g["models"]) == {"walter-smith", "walter-smith-corr", "walter-smith-corr-beta"}
        walk = g["multiple"]["random-walk"]  # [R, T, se R, se T]: every path R or T
        assert walk[0] + walk[1] == pytest.approx(1.0, abs=1e-12) and walk[2] > 0
    with np.load(out / "inside" / "brdf.npz") as z:
        assert z["theta_i"].tolist() == [160.0, 110.0] and "btdf_orders" in z
    report = (out / "report.md").read_text()
    assert "## Rough glass" in report and "medium → air" in report and "glass.png" in report
    assert (out / "glass.png").is_file()
    index = "\n".join(glass_index([RunDocument.from_json(doc)]))
    assert "## Rough glass" in index and "glass-small" in index


@pytest.mark.parametrize(
    "material, message",
    [
        ("ior = [1.5, 0.1]\ntransmission = true", "true needs a real index"),
        ('ior = "mirror"\ntransmission = true', "true needs a real index"),
        ('ior = 1.5\ntransmission = "yes"', "material.transmission"),
    ],
)
def test_transmission_needs_a_clear_dielectric(tmp_path, material, message):
    path = tmp_path / "s.toml"
    path.write_text(
        f'[surface]\nkind = "flat"\n[material]\n{material}\n[simulation]\nrays = 1000\n'
    )
    with pytest.raises(SceneError, match=message):
        load_scene(path)


def test_transmission_needs_a_fixed_ray_count(tmp_path):
    path = tmp_path / "s.toml"
    path.write_text(
        '[surface]\nkind = "gaussian"\nn = 64\nsigma = 1.0\ncorr_len = 8.0\n'
        '[material]\nior = 1.5\ntransmission = true\n[simulation]\nrays = "auto"\n'
    )
    with pytest.raises(SceneError, match="simulation.rays"):
        load_scene(path)
