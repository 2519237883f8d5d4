"""A verdict is a frozen record read by attribute (``analysis.verdicts.Verdict``) that is also
the read-only dict verdicts.json holds: the two forms agree field by field, a file's dict
reads back (older files' missing fields defaulted, a damaged one refused), and the reports
read the record."""

import copy
import dataclasses
import json
import pickle

import numpy as np
import pytest
from support import flat_verdict

from microsim.analysis import report
from microsim.analysis.study_records import RunDocument
from microsim.analysis.verdicts import VERDICT_SCHEMA, Verdict, as_verdicts
from microsim.errors import UsageError
from microsim.sim import Bins

BINS = Bins(12, 9)


@pytest.fixture(scope="module")
def deviating():
    t = BINS.theta_centers[:, None] + 0 * BINS.phi_centers[None, :]
    sim = 0.2 + np.exp(-(((t - 30.0) / 10.0) ** 2))
    counts = np.full(sim.shape, 1000)
    omega = BINS.projected_solid_angle()
    return flat_verdict(
        sim, 0.01 * sim, counts, 1.3 * sim, omega, BINS.theta_edges, phi_edges=BINS.phi_edges
    )


def test_the_record_and_its_dict_agree_field_by_field(deviating):
    v = deviating
    assert isinstance(v, Verdict) and set(v) == set(VERDICT_SCHEMA)
    assert all(getattr(v, k) == v[k] for k in v)
    assert v.kind == "deviates" and not v.agrees and v.rel_rms > 0.2


def test_it_is_read_only_and_derived_by_replace(deviating):
    with pytest.raises(dataclasses.FrozenInstanceError):
        deviating.agrees = True
    with pytest.raises(TypeError):
        deviating["agrees"] = True
    agreeing = dataclasses.replace(deviating, agrees=True)
    assert agreeing.kind == "agrees" and agreeing["agrees"] and not deviating["agrees"]


def test_json_pickle_and_copy_give_the_same_verdict(deviating):
    text = json.dumps(deviating, allow_nan=False)
    back = Verdict.from_json(json.loads(text))
    assert back == deviating and back.worst_bin == deviating.worst_bin
    assert pickle.loads(pickle.dumps(deviating)) == deviating
    assert copy.deepcopy(deviating).model == deviating.model


def test_an_older_file_reads_with_the_fields_it_lacked_and_a_damaged_one_is_refused(deviating):
    older = {
        k: v
        for k, v in deviating.items()
        if k not in ("reference", "conclusive", "realisations", "energy_dev_se", "tile_departure")
    }
    v = Verdict.from_json(older)
    assert v.reference == "ray-noise" and v.conclusive and v.realisations == 1
    assert v.energy_dev_se is None and v.tile_departure is None
    with pytest.raises(UsageError, match="n_bins"):
        Verdict.from_json({**deviating, "n_bins": "many"})


def test_the_report_reads_a_files_dicts_as_it_reads_the_records(deviating):
    as_file = json.loads(json.dumps([deviating]))
    assert as_verdicts(as_file) == [deviating]
    assert report._verdict_rows(as_file) == report._verdict_rows([deviating])
    doc = {"scene": "s", "verdicts": as_file}
    assert report.run_summary(doc) == report.run_summary({**doc, "verdicts": [deviating]})


def test_a_run_document_reads_its_verdicts_as_records_and_a_null_study_as_none(deviating):
    doc = {"scene": "s", "verdicts": [dict(deviating)], "fits": None, "tool": "x"}
    rec = RunDocument.from_json(doc)
    assert rec.scene == "s" and rec.verdicts == [deviating]
    assert isinstance(rec.verdicts[0], Verdict) and rec.verdicts[0].kind == "deviates"
    assert rec.fits == () and rec.outside_domain == {} and rec.wave is None
    assert RunDocument.from_json(rec) is rec
