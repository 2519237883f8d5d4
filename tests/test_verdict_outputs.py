"""One verdict, one answer in every output: ``microsim run``'s table, report.md's verdict
table, the index cell, the hemisphere chart's table, the index summary line, the sweep rows
and ``microsim.testing`` all word a verdict by ``verdicts.verdict_kind``.

The three cases are built with ``verdicts.verdict`` itself: an ensemble model within ray noise
of one tile (agrees), one 20 % too bright beyond the tile's departure (deviates) and one whose
deviation the tile's departure explains (inconclusive)."""

import numpy as np
import pytest
from support import flat_verdict

from microsim.analysis import charts, report, report_index
from microsim.analysis import verdicts as V
from microsim.sim import Bins

BINS = Bins(10, 6)
OMEGA = BINS.projected_solid_angle()


def _lobe():
    t = BINS.theta_centers[:, None]
    p = BINS.phi_centers[None, :]
    return 0.2 + 5.0 * np.exp(-(((t - 40.0) / 12.0) ** 2) - ((p - 180.0) / 40.0) ** 2)


def _case(kind: str) -> dict:
    rng = np.random.default_rng(3)
    truth = _lobe()
    tile = truth * (1.0 + 0.03 * np.sign(rng.normal(size=truth.shape)))
    se = 0.002 * tile
    sim = tile + rng.normal(size=truth.shape) * se
    departure = np.abs(tile - truth)
    if kind == "agrees":
        sim = truth + rng.normal(size=truth.shape) * se
    scale = 1.2 if kind == "deviates" else 1.0
    v = flat_verdict(
        sim,
        se,
        np.full(sim.shape, 1000),
        scale * truth,
        OMEGA,
        BINS.theta_edges,
        phi_edges=BINS.phi_edges,
        theta_i=60.0,
        name=f"model-{kind}",
        ensemble=True,
        departure=scale * departure,
    )
    assert V.verdict_kind(v) == kind
    return v


KINDS = ["agrees", "deviates", "inconclusive"]
SYMBOL = {"agrees": "✓", "deviates": "✗", "inconclusive": "?"}
WORD = {"agrees": "**agrees**", "deviates": "deviates", "inconclusive": "inconclusive"}


@pytest.mark.parametrize("kind", KINDS)
def test_every_output_words_the_verdict_alike(kind):
    v = _case(kind)
    doc = {"scene": "s", "verdicts": [v]}
    # microsim run's stdout table: the row of the model
    row = next(r for r in report.run_summary(doc).splitlines() if r.startswith(v["model"]))
    assert row.split()[1] == SYMBOL[kind]
    # report.md's verdict table: the verdict column
    assert report._verdict_rows([v])[0][2] == WORD[kind]
    # the index cell and the index summary line
    summary = V.summary_row([v])
    assert report_index._index_cell(doc, v["model"], summary).startswith(SYMBOL[kind])
    assert summary[v["model"]].startswith(kind)
    # the hemisphere chart's table
    assert charts._verdict_table([v]).splitlines()[2].split()[4] == kind
    # the symbol function itself
    assert V.verdict_symbol(v).startswith(SYMBOL[kind])


def test_inconclusive_prints_both_sizes():
    """ "? x% (tile departs y%)": the deviation and the departure that explains it."""
    v = _case("inconclusive")
    text = V.verdict_symbol(v)
    assert text == f"? {100 * v['rel_rms']:.2g}% (tile departs {100 * v['tile_departure']:.2g}%)"
    assert "tile departs" in report_index._index_cell(
        {"verdicts": [v]}, v["model"], V.summary_row([v])
    )
    assert "departure" in V.summary_row([v])[v["model"]]


SWEEP_SCENE = {"kind": "vgrooves", "n_grooves": 2000, "ndf": "beckmann", "m": 0.5}


@pytest.mark.integration
def test_a_sweep_task_is_judged_as_microsim_run_judges_it(tmp_path):
    """One V-groove tile at θi = 60°: the sweep's verdicts of Torrance–Sparrow with V-groove G
    (exact for the ensemble) and Smith G equal those of the run's pipeline on the same
    simulation (``default_models`` → ``attach_models`` → ``verdicts_for_result``): the same
    rel RMS, the same tile departure and the same verdict word, also in the summary's
    ``verdict`` column. Smith's G (heights uncorrelated between facets) is not a V-groove's
    (Blinn's V-cavity G): its error is far beyond the tile's departure, so it deviates rather
    than being left inconclusive."""
    from microsim.app.scene import load_scene
    from microsim.app.sweep import expand_tasks, run_task, summary_table
    from microsim.sim import simulate
    from microsim.sim.compare import attach_models, default_models

    sweep = {
        "rays": 200_000,
        "theta_bins": 18,
        "phi_bins": 13,
        "theta_i": [60],
        "seed": 4,
        "models": ["vgroove", "smith"],
        "scenes": [{"name": "vg", "ior": ["aluminium"], "surface": SWEEP_SCENE}],
    }
    (task,) = expand_tasks(sweep)
    rec = run_task(task, tmp_path)
    swept = {v["model"]: v for v in rec["verdicts"]}

    toml = "\n".join(
        ["[surface]", *(f"{k} = {v!r}".replace("'", '"') for k, v in SWEEP_SCENE.items())]
        + ["[material]", 'ior = "aluminium"']
    )
    (tmp_path / "vg.toml").write_text(toml + "\n")
    scene = load_scene(tmp_path / "vg.toml")
    surface = scene.build_surface(seed=task.seed)
    res = simulate(
        surface,
        scene.ior,
        task.theta_i,
        rays=task.rays,
        bins=BINS.__class__(task.theta_bins, task.phi_bins),
        seed=task.seed,
        threads=1,
        masking=task.masking,
    )
    judged = attach_models(res, default_models(surface, scene.ior, scene.ndf()))
    ran = {v["model"]: v for v in V.verdicts_for_result(judged)}

    for name in ("ts-vgroove", "ts-smith"):
        assert swept[name]["rel_rms"] == ran[name]["rel_rms"]
        assert swept[name]["tile_departure"] == ran[name]["tile_departure"] is not None
        assert V.verdict_kind(swept[name]) == V.verdict_kind(ran[name])
    assert V.verdict_kind(swept["ts-smith"]) == "deviates"
    rows = {r["model"]: r["verdict"] for r in summary_table([rec])}
    assert rows == {n: V.verdict_kind(v) for n, v in swept.items()}


def test_the_testing_message_words_each_incidence_by_its_verdict(tmp_path):
    """``assert_brdf_agrees``' table: a model 20 % too bright on one V-groove tile deviates
    (beyond the tile's departure, far beyond ray noise), and the message's result column says
    "deviates" for the incidence, the word ``verdict_kind`` gives its verdict."""
    from microsim.analytic import GGX, torrance_sparrow
    from microsim.surfaces import vgrooves
    from microsim.testing import BRDFMismatch, assert_brdf_agrees

    ndf = GGX(0.3)
    surface = vgrooves(500, ndf)
    with pytest.raises(BRDFMismatch) as err:
        assert_brdf_agrees(
            lambda wi, wo: 1.2 * torrance_sparrow(wi, wo, ndf, "vgroove", "aluminium"),
            surface,
            "aluminium",
            [60],
            rays=50_000,
            bins=(10, 7),
            cache=tmp_path,
        )
    (v,) = err.value.agreement["verdicts"]
    row = next(r for r in str(err.value).splitlines() if r.strip().startswith("60°"))
    assert V.verdict_kind(v) == "deviates" == row.split()[1]
