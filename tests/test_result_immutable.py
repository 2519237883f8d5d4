"""A Result never changes: attributes, arrays, meta and models are read-only, derivations
(``with_meta``, ``with_models``, ``attach_models``) return new Results and leave their input
untouched, and a result without ray tallies (the Kirchhoff solver's) saves and loads."""

import dataclasses
import json
import pickle

import numpy as np
import pytest

from microsim.sim import Bins, Result, simulate
from microsim.sim.compare import attach_models, default_models
from microsim.surfaces import flat


@pytest.fixture(scope="module")
def res():
    return simulate(flat(), "aluminium", [20.0, 50.0], rays=2000, bins=Bins(9, 5))


def test_attributes_cannot_be_assigned(res):
    with pytest.raises(dataclasses.FrozenInstanceError):
        res.brdf = res.brdf * 2
    with pytest.raises(dataclasses.FrozenInstanceError):
        res.meta = {}


@pytest.mark.parametrize("name", ["brdf", "stderr", "rays", "counts", "sum_w", "theta_i"])
def test_arrays_are_read_only(res, name):
    with pytest.raises(ValueError, match="read-only"):
        getattr(res, name)[0] = 0
    with pytest.raises(ValueError, match="read-only"):
        res.ledger["single"][0] = 0
    with pytest.raises(ValueError, match="read-only"):
        res.tallies["sum_w"][...] = 0


def test_meta_models_and_ledger_are_read_only(res):
    with pytest.raises(TypeError):
        res.meta["partial"] = True
    with pytest.raises(TypeError):
        res.meta["material"]["name"] = "gold"  # nested dicts too
    with pytest.raises(TypeError):
        res.meta.update(seed=3)
    with pytest.raises(TypeError):
        res.meta["seconds_per_realisation"].append(1.0)  # and lists
    with pytest.raises(TypeError):
        res.models["x"] = res.brdf
    with pytest.raises(TypeError):
        res.ledger["single"] = res.rays
    assert not res.is_partial and "x" not in res.models


def test_meta_is_a_copy_of_what_was_given(res):
    meta = {"partial": False, "run": {"bins": [9, 5]}}
    r = dataclasses.replace(res, meta=meta)
    meta["run"]["bins"].append(1)
    meta["partial"] = True
    assert r.meta["run"]["bins"] == [9, 5] and not r.is_partial
    assert isinstance(r.meta["run"], dict) and json.loads(json.dumps(r.meta)) == r.meta
    back = pickle.loads(pickle.dumps(r))
    assert back.meta == r.meta
    with pytest.raises(TypeError):
        back.meta["partial"] = True


def test_derivations_return_new_results(res):
    before = dict(res.meta)
    part = res.with_meta(partial=True, run={"a": 1})
    assert part.is_partial and part.meta["run"] == {"a": 1}
    assert not res.is_partial and "run" not in res.meta and dict(res.meta) == before
    m = res.with_models({"double": res.brdf * 2})
    assert list(m.models) == ["double"] and not res.models


def test_attach_models_leaves_its_input_untouched(res):
    meta = json.dumps(res.meta, sort_keys=True, default=repr)
    brdf = res.brdf.copy()
    out = attach_models(res, default_models(flat(), "aluminium"))
    assert out is not res and list(out.models) == ["mirror-fresnel"]
    assert out.meta["realisation_models"] == ["mirror-fresnel"]
    assert not res.models and "realisation_models" not in res.meta
    assert json.dumps(res.meta, sort_keys=True, default=repr) == meta
    assert np.array_equal(res.brdf, brdf) and out.brdf is not res.brdf
    assert np.shares_memory(out.brdf, res.brdf)  # derivations share the (read-only) arrays


def test_result_without_ray_tallies_round_trips(res, tmp_path):
    bare = Result(
        theta_i=res.theta_i,
        phi_i=res.phi_i,
        bins=res.bins,
        brdf=res.brdf,
        stderr=res.stderr,
        meta={"method": "test", "partial": False},
    )
    assert not bare.has_ray_tallies and res.has_ray_tallies
    assert "rays" not in repr(bare)
    bare.save(tmp_path / "bare")
    back = Result.load(tmp_path / "bare")
    assert back.rays is None and back.ledger is None and back.counts is None
    assert np.array_equal(back.brdf, res.brdf) and back.meta["method"] == "test"
