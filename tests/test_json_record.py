"""``JsonRecord``, the one base of the records of a JSON object: a record made by a builder
and one read from a file hold their nested objects as records alike, a file's object is
written back unchanged (its order, keys of no field, fields it lacks), and a record is
read-only and survives pickle and copy."""

import copy
import dataclasses
import json
import pickle

import pytest

from microsim.analysis.study_records import (
    AnisotropyIncidence,
    MissedEnergy,
    OrderIncidence,
    StandIn,
    VariantVerdict,
)


def _incidence(**extra):
    return AnisotropyIncidence(
        theta_i=30.0,
        phi_i=0.0,
        stand_in_vs_exact={"energy_dev": 0.01, "rel_rms": 0.02},
        against_simulation={"a": {"rel_rms": 0.1, "energy_dev": 0.0, "verdict": "deviates"}},
        **extra,
    )


def test_a_built_record_holds_its_nested_objects_as_records():
    inc = _incidence()
    assert isinstance(inc.stand_in_vs_exact, StandIn) and inc.stand_in_vs_exact.rel_rms == 0.02
    assert isinstance(inc.against_simulation["a"], VariantVerdict)
    assert inc.against_simulation["a"].verdict == "deviates"
    assert inc["stand_in_vs_exact"] is inc.stand_in_vs_exact
    assert "missed" not in inc and inc.missed is None  # None and named in OMITTED_IF_NONE
    assert list(inc) == ["theta_i", "phi_i", "stand_in_vs_exact", "against_simulation"]


def test_an_object_read_back_is_written_back_unchanged():
    raw = {
        "against_simulation": {"a": {"verdict": "agrees", "rel_rms": 0.1}},
        "theta_i": 30.0,
        "stand_in_vs_exact": {"rel_rms": 0.02},
        "added_later": [1, 2],
    }
    inc = AnisotropyIncidence.from_json(raw)
    assert json.dumps(inc) == json.dumps(raw)
    assert inc.phi_i == 0.0 and "phi_i" not in inc  # OLDER_DEFAULTS, not written back
    assert inc.stand_in_vs_exact.energy_dev is None and inc["added_later"] == [1, 2]
    assert inc.against_simulation["a"].energy_dev_se is None


def test_a_record_is_read_only_and_survives_pickle_and_copy():
    inc = _incidence(
        missed={
            "reflected": 0.9,
            "reflected_se": 0.01,
            "multiple": 0.1,
            "multiple_se": 0.01,
            "models": {"a": {"energy": 0.8, "missed": 0.1, "missed_se": 0.01}},
        }
    )
    assert isinstance(inc.missed, MissedEnergy) and inc.missed.models["a"].missed == 0.1
    for back in (pickle.loads(pickle.dumps(inc)), copy.copy(inc), copy.deepcopy(inc)):
        assert type(back) is AnisotropyIncidence and back == inc
        assert json.dumps(back) == json.dumps(inc) and back.missed.models["a"].energy == 0.8
    with pytest.raises(dataclasses.FrozenInstanceError):
        inc.theta_i = 0.0
    with pytest.raises(TypeError):
        inc.against_simulation["b"] = {}
    with pytest.raises(TypeError):
        inc["theta_i"] = 0.0


def test_a_field_an_older_object_lacks_reads_as_its_older_default():
    old = {"theta_i": 0.0, "sim": {}, "models": {}, "walk_verdicts": {}}
    inc = OrderIncidence.from_json(old)
    assert inc.phi_i == 0.0 and list(inc) == list(old)
