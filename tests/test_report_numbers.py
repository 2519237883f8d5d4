"""Numbers in the reports that must not mislead a reader.

- Percentages: one formatter (``analysis.markdown.percent``) for every output, plain decimals
  to the stated significant figures, never exponent notation ("1e+02%" reads as a typo for
  100 %), also in the builders of the index, the report and the run's table.
- Fits: a parameter on a physical bound of its box (kd ≥ 0) is a constrained minimum; one at a
  search limit (ks = 10) means the optimiser was stopped there (``fits.Param.physical``).
- Multiple scattering: a model's deviation from a simulated energy of orders ≥ 2 that is not
  resolved from 0 (below 2 standard errors) is an absolute difference in percentage points,
  never a relative one ("−706 %" from a share of 0.00045 % ± 0.00045 %).
"""

from __future__ import annotations

import re

import numpy as np
from hypothesis import given
from hypothesis import strategies as st
from support import flat_verdict
from test_fits import _synthetic

from microsim.analysis import charts, fits, report, report_cells, report_index, report_wave
from microsim.analysis import verdicts as V
from microsim.analysis.markdown import PERCENT_FLOOR, percent
from microsim.analysis.multiple_report import RESOLVED_SE, deviation_text, multiple_section
from microsim.app.runner.publishing import fit_record
from microsim.sim import Bins

EXPONENT_PERCENT = re.compile(r"\d[eE][+-]?\d+ ?%")
"""A percentage in exponent notation: "1e+02%", "-9.61e+03 %"."""


# --- one percentage formatter ---------------------------------------------------------------
@given(st.floats(min_value=-1e6, max_value=1e6, allow_nan=False, allow_infinity=False))
def test_percent_is_plain_decimal_to_two_significant_figures(fraction):
    text = percent(fraction)
    assert "e" not in text.lower() and text.endswith("%")
    v = 100.0 * fraction
    if v != 0 and abs(v) < PERCENT_FLOOR:
        assert text == "< 0.0001%"
    else:
        assert float(text[:-1]) == float(f"{v:.2g}")  # the value to 2 significant figures


def test_percent_examples():
    assert [percent(x) for x in (1.0, 1.4, 0.000123, -54.3, 0.0)] == [
        "100%",
        "140%",
        "0.012%",
        "-5400%",
        "0%",
    ]
    assert percent(0.25, 3, signed=True, unit=" pp") == "+25 pp"
    assert percent(None) == percent(float("nan")) == "–"


BINS = Bins(10, 6)


def _verdict(scale: float, name: str) -> dict:
    """One verdict of a model ``scale`` times as bright as a smooth lobe simulated with 0.2 %
    noise: deviates, with a relative RMS of about scale − 1."""
    t, p = BINS.theta_centers[:, None], BINS.phi_centers[None, :]
    truth = 0.2 + 5.0 * np.exp(-(((t - 40.0) / 12.0) ** 2) - ((p - 180.0) / 40.0) ** 2)
    return flat_verdict(truth, 0.002 * truth, np.full(truth.shape, 1000), scale * truth,
                        BINS.projected_solid_angle(), BINS.theta_edges, phi_edges=BINS.phi_edges,
                        theta_i=60.0, name=name)  # fmt: skip


def test_builders_write_no_exponent_percentages_for_large_deviations():
    """Models 2× and 2.4× as bright (rel RMS ≈ 100 % and 140 %, worst bin −140 %): the run's
    table, the report's verdict rows, the chart's table, the index (cells and summary lines)
    and a wave verdict's range outside its agreement region all write plain percentages."""
    vs = [_verdict(2.0, "twice"), _verdict(2.4, "brighter")]
    assert all(V.verdict_kind(v) == "deviates" for v in vs)
    doc = {"scene": "s", "verdicts": vs}
    texts = {
        "symbol": " ".join(V.verdict_symbol(v) for v in vs),
        "summary": " ".join(V.summary_row(vs).values()),
        "run table": report.run_summary(doc),
        "report rows": str(report._verdict_rows(vs)),
        "chart table": charts._verdict_table(vs),
        "index": report.index_report([doc], None, True),
        "wave outside": report_wave._outside_text({"forward": [-96.1, 1.0]}),
    }
    for where, text in texts.items():
        assert not EXPONENT_PERCENT.search(text), (where, text)
    assert V.verdict_symbol(vs[0]) == "✗ 100%" and V.verdict_symbol(vs[1]) == "✗ 140%"
    assert texts["wave outside"] == "forward -9610 … +100 %"


# --- fits: physical bounds and search limits ----------------------------------------------------
def test_a_fit_on_a_physical_bound_is_a_constrained_minimum():
    """Data without a diffuse term: Cook–Torrance's best kd is 0, its physical bound kd ≥ 0 —
    a constrained minimum, converged, and reported as such."""
    data = _synthetic("cook-torrance", {"ks": 0.8, "m": 0.25, "kd": 0.0})
    res = fits.fit_model("cook-torrance", data, "aluminium", n_starts=2)
    assert res.bounds_reached == (fits.BoundReached("kd", 0.0, "lower", True),)
    assert res.converged
    record = fit_record(res)
    assert record["converged"] is True
    assert report_cells.converged_text(record) == "yes: kd = 0, on its physical bound kd ≥ 0"
    assert report_index._index_fit_cell(record).endswith("(physical bound: kd = 0)")


def test_a_fit_at_a_search_limit_is_stopped_there():
    """Data 12× as bright as a unit-ks lobe: the best ks lies beyond the search limit ks = 10,
    where the optimiser is stopped — not converged, and the report says the best fit may lie
    beyond."""
    data = _synthetic("cook-torrance", {"ks": 12.0, "m": 0.25, "kd": 0.0})
    res = fits.fit_model("cook-torrance", data, "aluminium", n_starts=2)
    reached = {b.param: b for b in res.bounds_reached}
    assert reached["ks"] == fits.BoundReached("ks", 10.0, "upper", False)
    assert not res.converged
    record = fit_record(res)
    assert record["converged"] is False
    assert report_cells.converged_text(record).startswith(
        "no: stopped at the search limit ks = 10: the best fit may lie beyond"
    )
    assert "(search limit: ks = 10" in report_index._index_fit_cell(record)


def test_every_bound_declares_its_kind():
    """kd and the fractions are physical at both ends; Löw's C and ior and Cook–Torrance's m
    are search limits (their physical limits, C > 0, ior > 1, m > 0, lie outside the box)."""
    kinds = {(m, p.name): p.physical for m, fm in fits.FIT_MODELS.items() for p in fm.params}
    assert kinds["cook-torrance", "kd"] == kinds["low-microfacet", "kd"] == (True, True)
    assert kinds["edwards", "f0"] == (True, True)
    assert kinds["low-microfacet", "C"] == kinds["low-microfacet", "ior"] == (False, False)
    assert kinds["cook-torrance", "m"] == (False, False)


# --- multiple scattering: deviations below the noise ------------------------------------------
def _incidence(sim: float, sim_se: float, model: float, model_se: float = 1e-6) -> dict:
    """One incidence of an ``order_comparison`` with the random walk's energy of orders ≥ 2
    (relative deviation and its delta-method error as ``_energy_verdict`` computes them)."""
    rel = None if sim == 0 else 1.0 - model / sim
    rel_se = None if sim == 0 else (model / sim) * np.hypot(model_se / model, sim_se / sim)
    walk = {"energy": model, "energy_se": model_se, "rel_dev": rel, "rel_dev_se": rel_se,
            "t": (sim - model) / np.hypot(sim_se, model_se), "agrees": True, "fitted": False,
            "rel_rms": 0.5, "shape_rel_rms": 0.2, "noise_floor": 0.1, "specular_share": 0.5,
            "orders": [0.9, model, 0.0], "order_se": [1e-4, model_se, 0.0], "cut": 0.0}  # fmt: skip
    return {
        "theta_i": 0.0,
        "phi_i": 0.0,
        "sim": {
            "orders": [0.9, sim, 0.0],
            "order_se": [1e-4, sim_se, 0.0],
            "multiple": sim,
            "multiple_se": sim_se,
            "absorbed": 0.1,
            "absorbed_se": 1e-4,
            "cut": 0.0,
            "cut_se": 0.0,
            "specular_share": 1.0,
        },  # fmt: skip
        "models": {"random-walk": walk},
        "walk_verdicts": {},
    }


UNRESOLVED = _incidence(4.5e-6, 4.5e-6, 3.6e-5)  # a share of 0.00045 % ± 0.00045 %
RESOLVED = _incidence(0.05, 0.001, 0.052)


def test_unresolved_shares_get_an_absolute_difference():
    """Below RESOLVED_SE standard errors the deviation is sim − model in percentage points of
    the incident power (± the errors in quadrature); above, the relative deviation."""
    assert 4.5e-6 < RESOLVED_SE * 4.5e-6 and 0.05 > RESOLVED_SE * 0.001
    assert deviation_text(UNRESOLVED, "random-walk", with_se=False) == "-0.00315 pp"
    assert deviation_text(UNRESOLVED, "random-walk") == "-0.00315 ± 0.00046 pp"
    assert deviation_text(RESOLVED, "random-walk", with_se=False) == "-4 %"
    assert deviation_text(RESOLVED, "random-walk").startswith("-4 ± ")
    nothing = _incidence(0.0, 0.0, 2e-5)  # no multiply scattered light simulated at all
    assert deviation_text(nothing, "random-walk", with_se=False) == "-0.002 pp"


def test_the_index_and_the_section_print_no_relative_deviation_below_noise():
    comparison = {
        "order_labels": ["1", "2", "3"],
        "models": ["random-walk"],
        "ndf": {"kind": "Beckmann", "alpha": 0.3},
        "closed_forms_note": "left out",
        "bounces": "all",
        "realisations": 8,
        "walk_paths": 1000,
        "alpha": 0.01,
        "incidences": [UNRESOLVED, {**RESOLVED, "theta_i": 60.0}],
    }
    needs = [{"theta_i": t, "phi_i": 0.0, "multiple_fraction": q, "multiple_fraction_se": q,
              "cut": 0.0, "needs": q > 0.01} for t, q in ((0.0, 5e-6), (60.0, 0.05))]  # fmt: skip
    doc = {"scene": "s", "verdicts": [], "orders": {"needs": needs, "comparison": comparison}}
    index = report.index_report([doc], None, True)
    orders = index[index.index("## How much light single scattering misses") :]
    row = next(line for line in orders.splitlines() if line.startswith("| [s]"))
    assert "| -0.00315 pp, -4 % |" in row
    section = "\n".join(multiple_section(comparison))
    assert "| -0.00315 ± 0.00046 pp |" in section
    assert "-706" not in section and "-700" not in section
