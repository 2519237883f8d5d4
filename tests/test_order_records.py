"""The studies of verdicts.json as typed records (``microsim.analysis.study_records``): what a
builder returns reads by attribute, is the dict verdicts.json holds (same keys, same order,
read-only), and a dict read back from JSON becomes the same record, with its nested records."""

from __future__ import annotations

import dataclasses
import json
import pickle

import pytest

from microsim.analysis.multiple import needs_more_bounces, order_comparison, realised_ndf
from microsim.analysis.multiple_report import deviation_text, multiple_section
from microsim.analysis.study_records import (
    BounceNeed,
    ModelEnergy,
    OrderComparison,
    OrderIncidence,
    OrdersStudy,
    WaveVerdict,
)
from microsim.analysis.verdict_record import Verdict
from microsim.errors import UsageError
from microsim.sim import Bins, simulate
from microsim.surfaces import gaussian


@pytest.fixture(scope="module")
def comparison():
    tiles = [gaussian(64, 1.0, 2.0, 8.0, seed=s) for s in range(3)]
    res = simulate(None, None, [0.0, 60.0], realisations=tiles, rays=30_000, bins=Bins(6, 4),
                   bounces=3, seed=2, threads=2)  # fmt: skip
    return res, order_comparison(res, None, realised_ndf(tiles), walk_paths=10_000, seed=1)


def test_the_order_comparison_reads_by_attribute_as_its_dict(comparison):
    _, c = comparison
    assert isinstance(c, OrderComparison) and list(c) == [
        f.name for f in dataclasses.fields(OrderComparison)
    ]
    inc = c.incidences[1]
    assert isinstance(inc, OrderIncidence) and inc["sim"] is inc.sim
    assert inc.sim.multiple == c["incidences"][1]["sim"]["multiple"]
    assert isinstance(inc.walk_verdicts["2+"], Verdict)
    walk, kc = inc.models["random-walk"], inc.models["kulla-conty"]
    assert isinstance(walk, ModelEnergy) and len(walk.orders) == 3
    assert "orders" in walk and "orders" not in kc and kc.orders is None


def test_a_record_is_read_only(comparison):
    c = comparison[1]
    with pytest.raises(dataclasses.FrozenInstanceError):
        c.kd = 1.0
    with pytest.raises(TypeError):
        c["kd"] = 1.0
    with pytest.raises(TypeError):
        c.incidences[0].models["random-walk"]["energy"] = 0.0


def test_json_round_trip_gives_the_same_records(comparison):
    c = comparison[1]
    back = OrderComparison.from_json(json.loads(json.dumps(c)))
    assert back == c and json.dumps(back) == json.dumps(c)
    assert isinstance(back.incidences[0].walk_verdicts["2"], Verdict)
    assert isinstance(back.incidences[0].models["mikkelsen-eq28"], ModelEnergy)
    assert pickle.loads(pickle.dumps(c)) == c
    assert multiple_section(json.loads(json.dumps(c))) == multiple_section(c)
    inc = json.loads(json.dumps(c.incidences[0]))
    assert deviation_text(inc, "kulla-conty") == deviation_text(c.incidences[0], "kulla-conty")


def test_per_incidence_rows_are_records(comparison):
    res, _ = comparison
    needs = needs_more_bounces(res)
    assert all(isinstance(n, BounceNeed) for n in needs)
    assert needs[0].needs == needs[0]["needs"] and needs[0].threshold == 0.01


def test_the_orders_study_read_back_holds_its_records(comparison):
    res, c = comparison
    study = OrdersStudy(bounces=3, needs=needs_more_bounces(res), comparison=c, note=None)
    back = OrdersStudy.from_json(json.loads(json.dumps(study)))
    assert back == study and isinstance(back.comparison, OrderComparison)
    assert all(isinstance(n, BounceNeed) for n in back.needs)
    none = OrdersStudy.from_json({"bounces": 2, "needs": [], "comparison": None, "note": "x"})
    assert none.comparison is None and none.note == "x"


def test_a_wave_verdict_read_back_is_checked():
    with pytest.raises(UsageError, match="missing"):
        WaveVerdict.from_json({"status": "agrees"})
