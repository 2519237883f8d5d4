"""Verdicts on a measured surface (reference "this-tile", analysis/verdicts.py).

A surface read from a file is the object of study, not a draw of an ensemble: every model is
judged as a model of that tile, against its ray noise, and both agreement and deviation are
conclusive. Truth known exactly: a heightfield of symmetric V-grooves along y (every grid cell
planar, rims at one height) is a V-cavity surface, for which Torrance–Sparrow with the tile's
own facets and the V-groove G (Mikkelsen 2009, eq. 25) is exact. Facts checked: that model
agrees conclusively at every θi; the same model × 1.1 deviates conclusively by its known size;
the default models of a file surface are judged against the tile too; a generated (ensemble)
tile keeps the "one-tile" reference and its verdicts; the false-alarm rate of the exact model
stays within the binomial bound (``-s`` prints the measured rates).
"""

import numpy as np
import pytest
from scipy import stats

from microsim import surfaces as sf
from microsim.analysis.verdicts import (
    Measured,
    Prediction,
    judged_as_tile,
    validate_verdict,
    verdict,
    verdict_symbol,
    verdicts_for_result,
)
from microsim.sim import Bins, simulate
from microsim.sim.compare import attach_models, default_models
from microsim.sim.predict import Predictor

THETAS = [0.0, 30.0, 60.0]
BINS = Bins(18, 4)
# tilts whose specular directions at THETAS avoid the 5° bin edges (a facet's mirror
# direction on an edge would fall in either bin by rounding)
TILTS = [6.0, 12.0, 17.0, 23.0, 28.0, 34.0, 38.0]
EXACT = "ts-facets-vgroove"


def _groove_heights(tilts_deg, half=3, rows=8) -> np.ndarray:
    """Heights (rows, 2·half·len(tilts)) of symmetric V-grooves along y, one per tilt, ``half``
    cells per flank (dx = 1), rims at z = 0: every grid cell is planar."""
    flank = half - np.abs(np.arange(2 * half) - half)  # 0 at the rims, half at the bottom
    profile = np.concatenate([-np.tan(np.radians(t)) * flank for t in tilts_deg])
    return np.tile(profile, (rows, 1))


def _scanned_grooves(tmp_path):
    """The groove heightfield written to a file and read back (kind "file")."""
    path = tmp_path / "grooves.npy"
    np.save(path, _groove_heights(TILTS))
    return sf.from_file(path, 1.0, periodic=True)


def _exact_model(surface) -> Predictor:
    """Torrance–Sparrow with the tile's facets and V-groove G: exact for a V-cavity tile."""
    normals, areas = surface.facet_normals(), surface.projected_areas()
    return Predictor.facets(EXACT, normals, areas, "vgroove", "aluminium")


def _traced(surface, seed=0, rays=40_000):
    return simulate(surface, "aluminium", THETAS, rays=rays, bins=BINS, seed=seed)


@pytest.fixture(scope="module")
def scan_run(tmp_path_factory):
    """The scanned grooves traced, with the file surface's default models and the exact one."""
    surface = _scanned_grooves(tmp_path_factory.mktemp("scan"))
    res = attach_models(_traced(surface), default_models(surface, "aluminium"))
    res = attach_models(res, [_exact_model(surface)])
    return res.with_models({**res.models, "exact-x1.1": res.models[EXACT] * 1.1})


def _by_model(verdicts) -> dict:
    out = {}
    for v in verdicts:
        out.setdefault(v["model"], []).append(validate_verdict(v))
    return out


def test_a_file_surface_is_judged_as_this_tile(scan_run):
    """Every model of a file surface — the default models, built from the tile's own
    statistics, included — is judged against the tile: reference "this-tile", conclusive."""
    assert judged_as_tile(scan_run)
    verdicts = verdicts_for_result(scan_run)
    assert {v["reference"] for v in verdicts} == {"this-tile"}
    assert all(v["conclusive"] and v["realisations"] == 1 for v in verdicts)
    assert all(v["tile_departure"] is None and v["energy_p"] is None for v in verdicts)
    assert "?" not in {verdict_symbol(v) for v in verdicts}


def test_exact_model_of_a_scanned_tile_agrees_conclusively(scan_run):
    by = _by_model(verdicts_for_result(scan_run))
    assert all(v.kind == "agrees" and v["reference"] == "this-tile" for v in by[EXACT])
    assert all(v["n_bins"] > 5 for v in by[EXACT])


def test_wrong_model_of_a_scanned_tile_deviates_by_its_size(scan_run):
    """The exact model × 1.1 deviates conclusively, and its rel_rms is 10 % up to the exact
    model's own: the relative errors are r' = 1.1 r − 0.1 on the same energy set (chosen from
    the simulation), so |rel_rms' − 0.1| ≤ 1.1 rel_rms (triangle inequality of that norm).
    Beckmann at the tile's realised rms slope (a smooth lobe for a tile of seven facet pairs)
    deviates conclusively at every θi too."""
    by = _by_model(verdicts_for_result(scan_run))
    for exact, wrong in zip(by[EXACT], by["exact-x1.1"]):
        assert wrong.kind == "deviates" and wrong["max_rel_dev"] < 0
        assert abs(wrong["rel_rms"] - 0.1) <= 1.1 * exact["rel_rms"] + 1e-12
    assert all(v.kind == "deviates" for v in by["ts-beckmann-realised-smith-corr"])


def test_every_verdict_on_a_scanned_tile_is_judged_as_this_tile(scan_run):
    """A verdict built directly from the run (``Measured.of``, as the glass and order-by-order
    studies and ``microsim.testing`` build theirs) is judged as this tile even for a model
    flagged as an ensemble's."""
    for t in range(len(THETAS)):
        v = verdict(
            Measured.of(scan_run, t),
            Prediction(scan_run.models["exact-x1.1"][t], "x1.1", ensemble=True),
        )
        assert v.reference == "this-tile" and v.kind == "deviates"


def test_an_ensemble_tile_keeps_its_one_tile_verdicts(tmp_path):
    """A generated Gaussian tile (one realisation) keeps the "one-tile" reference: its
    ensemble models are never "deviates". The same result recorded as a file surface is
    judged as this tile with the very same statistics: only the reference and, for a
    rejection, the conclusiveness change."""
    surface = sf.gaussian(32, 0.5, 0.5, 4.0, seed=3)
    res = attach_models(_traced(surface, rays=20_000), default_models(surface, "aluminium"))
    ensemble = verdicts_for_result(res)
    own = set(res.info.realisation_models)
    assert not judged_as_tile(res)
    for v in ensemble:
        assert v["reference"] == ("ray-noise" if v["model"] in own else "one-tile")
        assert v["model"] in own or v["conclusive"] == v["agrees"]
    assert any(v["reference"] == "one-tile" and not v["conclusive"] for v in ensemble)
    as_file = res.with_meta(surface={**res.meta["surface"], "kind": "file"})
    measured = verdicts_for_result(as_file)
    changed = {"reference", "conclusive"}
    for e, m in zip(ensemble, measured):
        assert m["reference"] == "this-tile" and m["conclusive"]
        assert {k: v for k, v in e.items() if k not in changed} == {
            k: v for k, v in m.items() if k not in changed
        }


def _deviates(verdicts) -> bool:
    return any(v.kind == "deviates" for v in verdicts)


def _max_false_alarms(seeds, alpha, level=1e-3):
    """Largest count of deviating seeds a calibrated test exceeds with probability < level."""
    return int(stats.binom.isf(level, seeds, alpha))


def test_this_tile_false_alarms_within_binomial_bound(tmp_path, capsys):
    """Calibration of the "this-tile" reference on a traced heightfield file: over 40 seeds
    the exact model's family (3 incidences) deviates at most as often as Binomial(40, α)
    allows, at α = 0.01 and 0.05; the model × 1.03 is flagged in ≥ 90 % of the seeds."""
    surface = _scanned_grooves(tmp_path)
    exact = _exact_model(surface)
    seeds, counts = 40, {0.01: 0, 0.05: 0, "x1.03": 0}
    model = None
    for seed in range(seeds):
        res = _traced(surface, seed=seed)
        if model is None:
            model = attach_models(res, [exact]).models[EXACT]
        res = res.with_models({EXACT: model})
        for alpha in (0.01, 0.05):
            counts[alpha] += _deviates(verdicts_for_result(res, alpha=alpha))
        counts["x1.03"] += _deviates(verdicts_for_result(res.with_models({"x": model * 1.03})))
    with capsys.disabled():
        print(f"\nthis-tile, {seeds} seeds: deviating families {counts}")
    assert counts[0.01] <= _max_false_alarms(seeds, 0.01)
    assert counts[0.05] <= _max_false_alarms(seeds, 0.05)
    assert counts["x1.03"] >= 0.9 * seeds
