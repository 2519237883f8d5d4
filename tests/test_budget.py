"""The error budget of an ensemble BRDF and ``realisations = "auto"``.

Facts checked: ``error_budget`` recovers a known ray noise and a known tile scatter from
synthetic realisations; ``realisations_needed`` follows its documented rule; a scene with
``realisations = "auto"`` traces a pilot, then exactly ``simulate`` with the chosen count (its
first realisations are the pilot's, bitwise), records the choice in ``meta.json`` and resumes
bitwise after an interrupt in either stage; the precision ``auto`` claims is honest: its mean
BRDF differs from an independent 32-realisation reference by what the two budgets predict.
"""

from __future__ import annotations

import dataclasses
import json
from types import SimpleNamespace

import numpy as np
import pytest

from microsim.analysis.budget import (
    MAX_AUTO,
    MIN_AUTO,
    error_budget,
    realisations_needed,
)
from microsim.errors import UsageError
from microsim.sim import Bins, Result

BINS = Bins(12, 9)


class _FakeResult(SimpleNamespace):
    """The fields of a ``Result`` the budget reads, with its own ``realisations_traced``."""

    realisations_traced = Result.realisations_traced


def _fake_result(R, ray_rel, tile_rel, seed=0):
    """R tile BRDFs around a smooth lobe: per-bin independent tile scatter of relative σ
    ``tile_rel`` and ray noise of relative σ ``ray_rel`` per tile (stderr_ray = the mean's)."""
    rng = np.random.default_rng(seed)
    th = BINS.theta_centers[:, None]
    truth = np.broadcast_to(np.exp(-(((th - 30.0) / 15.0) ** 2)) + 0.01, BINS.shape)[None]
    F = truth * (1.0 + rng.normal(0, tile_rel, (R, *BINS.shape)))
    F = F * (1.0 + rng.normal(0, ray_rel, F.shape))
    mean = F.mean(axis=0)[None]
    return _FakeResult(
        theta_i=np.array([30.0]),
        phi_i=np.array([0.0]),
        bins=BINS,
        brdf=mean,
        stderr=np.abs(mean) * 0.0,
        stderr_ray=truth * ray_rel / np.sqrt(R),
        brdf_realisations=F[:, None],
    )


def test_budget_separates_ray_noise_from_tile_scatter():
    R, ray, tile = 400, 0.03, 0.05
    (b,) = error_budget(_fake_result(R, ray, tile))
    assert b["realisations"] == R
    # estimates of the mean's standard errors; 400 tiles: the sample variances are good to
    # √(2/399) = 7 % per bin, far better averaged over the energy set
    assert b["ray"] == pytest.approx(ray / np.sqrt(R), rel=0.05)
    assert b["tile"] == pytest.approx(tile / np.sqrt(R), rel=0.1)
    assert b["total"] == pytest.approx(np.hypot(ray, tile) / np.sqrt(R), rel=0.1)
    assert 0 < b["energy"] < b["total"]  # independent bins average out in the energy


def test_budget_without_realisations_has_only_ray_noise():
    res = _fake_result(4, 0.02, 0.0)
    res.brdf_realisations = None
    (b,) = error_budget(res)
    assert b["tile"] is None and b["energy"] is None and b["total"] == b["ray"] > 0


def test_realisations_needed_rule():
    row = {"realisations": 8, "tile": 0.02}
    assert realisations_needed([row], 0.01) == 32  # 8 · (2 %/1 %)² · MARGIN, capped
    assert realisations_needed([{"realisations": 8, "tile": 0.015}], 0.01) == 23  # 22.5↑
    assert realisations_needed([{"realisations": 8, "tile": 0.001}], 0.01) == MIN_AUTO
    assert realisations_needed([{"realisations": 8, "tile": 0.5}], 0.01) == MAX_AUTO
    assert realisations_needed([{"realisations": 1, "tile": None}], 0.01) == MIN_AUTO
    for bad in (0, 1.0, -0.1, "1%"):
        with pytest.raises(UsageError, match="target"):
            realisations_needed([row], bad)


# --- realisations = "auto" through the runner --------------------------------------------------
AUTO_SCENE = """\
name = "auto-gauss"
[surface]
kind = "gaussian"
n = 48
dx = 1.0
sigma = 1.0
corr_len = 8.0
[material]
ior = "aluminium"
[simulation]
theta_i = [0, 60]
rays = 16000
theta_bins = 6
phi_bins = 5
realisations = "auto"
realisation_target = 0.02
seed = 5
"""


@pytest.fixture
def auto_scene(tmp_path, monkeypatch):
    """A tiny auto scene, and ``--quick`` allowed up to 32 realisations (quick stops at the
    pilot otherwise), so that the pilot chooses more than its own 8."""
    from microsim.app.runner import planning

    monkeypatch.setattr(
        planning,
        "QUICK",
        dataclasses.replace(planning.QUICK, max_realisations=32, realisation_target_floor=0.0),
    )
    p = tmp_path / "auto.toml"
    p.write_text(AUTO_SCENE)
    return p


def test_auto_pilot_then_exactly_simulate_with_the_chosen_count(auto_scene):
    from microsim.app.runner import tracing
    from microsim.app.runner.planning import plan_run

    plan = plan_run(auto_scene, quick=True, out=auto_scene.parent / "o")
    assert plan.realisations == MIN_AUTO and plan.auto_realisations
    pilot = tracing.simulate_scene(plan, plan.theta_i, plan.rays, plan.seed, plan.bins)
    chosen = tracing.choose_realisations(plan, pilot)
    need = realisations_needed(error_budget(pilot), 0.02)
    assert chosen.realisations == max(MIN_AUTO, min(need, 32)) > MIN_AUTO
    assert chosen.rays == plan.rays // MIN_AUTO * chosen.realisations
    final = tracing.simulate_scene(chosen, chosen.theta_i, chosen.rays, chosen.seed, chosen.bins)
    assert final.brdf_realisations.shape[0] == chosen.realisations
    # same surfaces, same streams: the pilot's realisations reappear bitwise
    assert np.array_equal(
        final.brdf_realisations[:MIN_AUTO], pilot.brdf_realisations, equal_nan=True
    )


def _run(args):
    from microsim.app.cli import main

    return main([*map(str, args), "--quick", "--no-progress"])


def _arrays(d):
    with np.load(d / "brdf.npz") as z:
        return {k: z[k] for k in z.files}


def _save_only(plan, stage, result, log, progress):
    from microsim.app.runner.publishing import publish_dir
    from microsim.app.runner.run import RunOutcome

    result.save(stage)
    publish_dir(stage, plan.out)
    return RunOutcome(0, plan.out)


@pytest.mark.integration
@pytest.mark.slow  # 10 s; tests/test_auto.py and tests/test_resume.py keep auto runs and resumes
def test_auto_run_records_its_choice_and_resumes_bitwise_from_either_stage(auto_scene, monkeypatch):
    from microsim.app.runner import run
    from microsim.checkpoints import interrupt_at, set_hook

    tmp = auto_scene.parent
    assert _run(["run", auto_scene, "--out", tmp / "ref"]) == 0
    meta = json.loads((tmp / "ref" / "meta.json").read_text())
    auto = meta["run"]["realisations_auto"]
    assert auto["stage"] == "final" and auto["pilot_realisations"] == MIN_AUTO
    assert auto["realisations"] == meta["run"]["realisations"] > MIN_AUTO
    assert auto["pilot_continued"] and meta["rays_traced"] == (  # the pilot is not retraced
        (auto["rays"] - auto["pilot_rays"]) * len(meta["error_budget"])
    )
    assert [b["realisations"] for b in meta["error_budget"]] == [auto["realisations"]] * 2
    assert "## Error budget" in (tmp / "ref" / "report.md").read_text()
    want = _arrays(tmp / "ref")
    # the tallies are the point from here on: the analysis only saves them
    monkeypatch.setattr(run, "_analyse", _save_only)
    count = {"n": 0}

    def counter(phase):
        count["n"] += phase == "simulation"

    old = set_hook(counter)
    try:  # how many chunks the pilot and the final run tally
        assert _run(["run", auto_scene, "--out", tmp / "count"]) == 0
    finally:
        set_hook(old)
    # interrupt in the pilot (first chunk) and in the final run (its last chunks)
    for k, after in enumerate((0, count["n"] - 2)):
        out = tmp / f"run{k}"
        with interrupt_at("simulation", after=after) as hook:
            assert _run(["run", auto_scene, "--out", out]) == 130
        assert hook["fired"]
        stage = json.loads((out / "meta.json").read_text())["run"]["realisations_auto"]
        assert stage["stage"] == ("pilot" if k == 0 else "final")
        assert _run(["run", auto_scene, "--resume", out]) == 0
        got = _arrays(out)
        for key in ("rays", "counts", "sum_w", "sum_w2", "brdf", "stderr"):
            assert np.array_equal(got[key], want[key], equal_nan=True), (k, key)


@pytest.mark.slow
def test_auto_meets_its_target_against_a_32_realisation_reference():
    """The precision ``auto`` reports is honest: on a Gaussian scene (128² tiles, ℓ = 8 dx),
    its mean BRDF and that of 32 independent realisations differ per bin by what the two
    budgets' total standard errors predict (energy-weighted RMS of the relative difference
    ≈ √(total_auto² + total_ref²); asserted within a factor 1.5, far outside the sampling
    scatter of an RMS over the energy set's bins)."""
    from microsim.sim import simulate
    from microsim.stats import energy_set
    from microsim.surfaces import gaussian

    bins, theta = Bins(15, 13), [0.0, 60.0]

    def run(seeds, rays_per):
        surfs = [gaussian(n=128, dx=1.0, sigma=1.0, corr_len=8.0, seed=s) for s in seeds]
        return simulate(
            None, "aluminium", theta, rays=rays_per * len(seeds), bins=bins, realisations=surfs
        )

    pilot = run(range(MIN_AUTO), 20_000)
    R = realisations_needed(error_budget(pilot), 0.03)
    auto = run(range(R), 20_000)
    ref = run(range(1000, 1032), 20_000)
    b_auto, b_ref = error_budget(auto), error_budget(ref)
    omega = bins.projected_solid_angle()
    for t in range(len(theta)):
        assert b_auto[t]["tile"] <= 0.03 or R == MAX_AUTO
        f = ref.brdf[t]
        E = energy_set(f * omega).reshape(f.shape)
        w = (f * omega)[E]
        rel = ((auto.brdf[t] - f) / f)[E]
        rms = np.sqrt(np.sum(w * rel**2) / np.sum(w))
        predicted = np.hypot(b_auto[t]["total"], b_ref[t]["total"])
        assert predicted / 1.5 < rms < 1.5 * predicted, (theta[t], rms, predicted)
