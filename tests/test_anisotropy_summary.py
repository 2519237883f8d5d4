"""The anisotropy section: the summary an anisotropic scene's verdict document carries and
the index table built from it (``analysis.anisotropy``, ``report._anisotropy_index``)."""

import pytest

from microsim.analysis.anisotropy import VARIANTS, anisotropy_summary
from microsim.analysis.report import index_report
from microsim.analysis.verdicts import verdicts_for_result
from microsim.sim import Bins, simulate
from microsim.sim.compare import attach_models, default_models
from microsim.surfaces import gaussian


@pytest.fixture(scope="module")
def judged():
    fac = lambda s: gaussian(128, 1.0, 1.2, 8.0, corr_len_y=32.0, seed=s)  # noqa: E731
    surfaces = [fac(s) for s in range(4)]
    res = simulate(None, "aluminium", [30.0, 80.0], rays=400_000, bins=Bins(18, 24, folded=False),
                   realisations=surfaces, threads=2)  # fmt: skip
    return attach_models(res, default_models(surfaces, "aluminium"))


def test_the_summary_compares_the_stand_in_with_the_exact_lambda(judged):
    verdicts = verdicts_for_result(judged)
    s = anisotropy_summary(judged, verdicts)
    assert [r["theta_i"] for r in s["incidences"]] == [30.0, 80.0]
    grazing = s["incidences"][1]
    # model against model: the stand-in's G sees α = 0.15 across the rough axis (αx = 0.3):
    # too little masking, a brighter model, by far more at 80° than at 30°
    assert grazing["stand_in_vs_exact"]["energy_dev"] > 0.05
    assert s["incidences"][0]["stand_in_vs_exact"]["energy_dev"] < 0.02
    assert set(grazing["against_simulation"]) == set(VARIANTS)
    label = "exact Λ, height-correlated"
    by = {v["model"]: v for v in verdicts if v["theta_i"] == 80.0}
    assert grazing["against_simulation"][label]["rel_rms"] == by[VARIANTS[label]]["rel_rms"]
    assert 0 < grazing["stand_in_vs_exact"]["rel_rms"] < 1


def test_isotropic_results_have_no_summary_and_the_index_a_section(judged):
    iso = judged.with_models({k: v for k, v in judged.models.items() if "geomean" not in k})
    assert anisotropy_summary(iso, verdicts_for_result(iso)) is None
    doc = {"scene": "aniso", "verdicts": [], "anisotropy": anisotropy_summary(
        judged, verdicts_for_result(judged))}  # fmt: skip
    text = index_report([doc], None, True)
    section = text[text.index("## Anisotropy") :]
    assert "| [aniso](aniso/report.md) | 80° | 0° |" in section
    assert "e-0" not in section and "e+0" not in section  # no exponent notation
