"""A Result's run description read typed: ``Result.info`` (a frozen ``RunInfo``) holds every
key of ``meta`` as an attribute (unknown keys in ``extra``), follows every derivation, and
``meta.json`` stays the JSON form written at save and read at load."""

import dataclasses
import json

import pytest

from microsim.sim import Bins, Result, simulate
from microsim.sim.result import RunInfo
from microsim.surfaces import flat


@pytest.fixture(scope="module")
def res():
    return simulate(flat(), "aluminium", [20.0, 50.0], rays=2000, bins=Bins(9, 5))


def test_every_meta_key_is_an_attribute_or_kept_in_extra(res):
    info = res.info
    fields = {f.name for f in dataclasses.fields(RunInfo)} - {"extra"}
    for key, value in res.meta.items():
        got = getattr(info, key) if key in fields else info.extra[key]
        assert got == value, key
    assert set(info.extra).isdisjoint(fields)
    assert info.seed == res.meta["seed"] and info.material["name"] == "aluminium"


def test_absent_keys_read_as_their_defaults():
    info = RunInfo.from_meta({"seed": 3, "tool_version": "x"})
    assert info.seed == 3 and info.extra == {"tool_version": "x"}
    assert info.bounces is None and info.realisation_models == () and info.partial is False
    assert info.n_realisations == 1 and info.material_text == "ior ?"


def test_info_is_frozen_and_follows_derivations(res):
    with pytest.raises(dataclasses.FrozenInstanceError):
        res.info.seed = 7
    derived = res.with_meta(partial=True, model_warnings=["w"])
    assert derived.info.partial and derived.is_partial and derived.info.model_warnings == ["w"]
    assert not res.info.partial and res.info.model_warnings == ()
    replaced = dataclasses.replace(res, meta={"seed": 11})
    assert replaced.info.seed == 11 and replaced.info.material is None


def test_meta_json_is_the_json_form_and_loads_back_to_the_same_info(res, tmp_path):
    res.save(tmp_path)
    on_disk = json.loads((tmp_path / "meta.json").read_text())
    assert "info" not in on_disk and on_disk["seed"] == res.meta["seed"]
    back = Result.load(tmp_path)
    assert back.info == res.info
