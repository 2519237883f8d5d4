"""The parts of a verdict document the reports read (fits, scattering orders, stability,
speed, anisotropy) and the methods document are frozen records read by attribute, each read
by one loader and also the read-only dict of its JSON object: written back, a committed file
is unchanged."""

import dataclasses
import json
import pickle
from pathlib import Path

import pytest

from microsim.analysis.json_record import JsonRecord
from microsim.analysis.report_methods import MethodsDocument, load_methods
from microsim.analysis.study_records import (
    AnisotropyStudy,
    Fit,
    FitBound,
    OrdersStudy,
    RunDocument,
    Speed,
    Stability,
)
from microsim.app.sweep.summary import COLUMNS, SummaryRow

REPORTS = Path(__file__).resolve().parent.parent / "reports"
DOCUMENTS = sorted(REPORTS.glob("*/verdicts.json"))
STUDIES = {
    "orders": OrdersStudy,
    "stability": Stability,
    "speed": Speed,
    "anisotropy": AnisotropyStudy,
}


def _records(value):
    """Every JsonRecord in ``value`` and the records nested in its fields."""
    if isinstance(value, JsonRecord):
        yield value
        for f in dataclasses.fields(value):
            yield from _records(getattr(value, f.name))
    elif isinstance(value, (list, tuple)):
        for v in value:
            yield from _records(v)
    elif isinstance(value, dict):
        for v in value.values():
            yield from _records(v)


@pytest.mark.parametrize("path", DOCUMENTS, ids=lambda p: p.parent.name)
def test_a_committed_document_reads_as_records_and_writes_back_unchanged(path):
    raw = json.loads(path.read_text())
    doc = RunDocument.from_json(raw)
    assert all(isinstance(f, Fit) for f in doc.fits)
    assert json.dumps(list(doc.fits)) == json.dumps(raw["fits"])
    for name, kind in STUDIES.items():
        study = getattr(doc, name)
        if raw.get(name) is None:
            continue
        assert isinstance(study, kind)
        assert json.dumps(study) == json.dumps(raw[name])
        assert pickle.loads(pickle.dumps(study)) == study == raw[name]
    for rec in _records([doc.fits, doc.orders, doc.stability, doc.speed, doc.anisotropy]):
        present = [f.name for f in dataclasses.fields(rec) if f.name in rec]
        assert all(
            getattr(rec, k) == rec[k] or isinstance(getattr(rec, k), (tuple, dict)) for k in present
        )


def test_the_nested_parts_are_records_too():
    """Bounds of a fit, the speed runs, the scattering orders' incidences and the anisotropy
    variants are read by attribute."""
    fit = Fit.from_json(
        {
            "model": "m",
            "at_bounds": [{"param": "kd", "bound": 0.0, "side": "lower", "physical": True}],
            "cost": 1.0,
        }
    )
    assert fit.at_bounds == [FitBound(param="kd", bound=0.0, side="lower", physical=True)]
    assert fit["cost"] == 1.0  # a key of no field stays in the dict
    with pytest.raises((TypeError, dataclasses.FrozenInstanceError)):
        fit["model"] = "other"
    with pytest.raises(dataclasses.FrozenInstanceError):
        fit.model = "other"
    docs = [RunDocument.from_json(json.loads(p.read_text())) for p in DOCUMENTS]
    assert any(d.speed.runs for d in docs)
    for d in docs:
        for run in d.speed.runs.values():
            assert len(run.rays) == len(run.rel_rms)
        for n in d.orders.needs if d.orders else ():
            assert isinstance(n.needs, bool) and n.multiple_fraction >= 0
        for inc in d.anisotropy.incidences if d.anisotropy else ():
            assert all(v.verdict in ("agrees", "deviates", "inconclusive")
                       for v in inc.against_simulation.values())  # fmt: skip


def test_the_methods_document_reads_as_records():
    path = REPORTS / "methods.json"
    methods = load_methods(path)
    assert isinstance(methods, MethodsDocument)
    assert json.dumps(methods) == json.dumps(json.loads(path.read_text()))
    assert methods.panels and all(p.points for p in methods.panels)
    assert methods.machine.cpus == methods["machine"]["cpus"]


def test_a_summary_row_has_the_columns_as_fields():
    assert COLUMNS == tuple(f.name for f in dataclasses.fields(SummaryRow))
    row = SummaryRow.from_json(dict.fromkeys(COLUMNS, 1))
    assert list(row) == list(COLUMNS) and all(getattr(row, c) == row[c] for c in COLUMNS)
