"""One run identity (microsim.sim.identity): every field of the run description reaches every
consumer — ``simulate(resume=)`` and ``microsim run --resume`` refuse a run that differs in
it, the testing cache's key and a sweep task's id change with it — and a run saved by an
older microsim is still read (or refused with a message naming what differs)."""

import dataclasses
import json
import re

import numpy as np
import pytest
from support import heightfield_surface, random_heights, vgroove_surface

from microsim.app.runner.planning import QUICK, _check_resumable, run_description, tally_settings
from microsim.app.scene import load_scene
from microsim.app.sweep.grid import Task
from microsim.checkpoints import interrupt_at
from microsim.errors import UsageError
from microsim.sim import BLOCK, Bins, Result, simulate
from microsim.sim.identity import RunDescription, saved_identity
from microsim.testing.cache import resolve_reference

BASE = RunDescription(
    material=complex(1.5, 0.1),
    theta_i=(20.0, 70.0),
    phi_i=(0.0, 0.0),
    bins=Bins(10, 7),
    rays=7 * BLOCK + 321,
    seed=4,
    surfaces={"fingerprints": ["a"]},
)
CHANGES = {
    "material": None,
    "theta_i": (20.0, 60.0),
    "phi_i": (0.0, 15.0),
    "bins": Bins(10, 8),
    "rays": 7 * BLOCK + 322,
    "seed": 5,
    "surfaces": {"fingerprints": ["b"]},
    "bounces": 2,
    "realisations": 2,
    "masking": "exact",
    "origins": "independent",
    "isotropic": True,
    "transmission": True,
}


def test_the_changes_cover_every_field_of_the_description():
    assert set(CHANGES) == {f.name for f in dataclasses.fields(RunDescription)}


@pytest.mark.parametrize("field", sorted(CHANGES))
def test_each_field_changes_the_identity_its_key_and_is_named_as_a_mismatch(field):
    changed = dataclasses.replace(BASE, **{field: CHANGES[field]})
    assert changed.identity() != BASE.identity()
    assert changed.key() != BASE.key()
    assert [k for k, _, _ in changed.mismatches(BASE.identity())] == [field]
    assert BASE.mismatches(BASE.identity()) == []
    json.dumps(changed.identity())  # JSON values only


# --- simulate(resume=) ---------------------------------------------------------------------
THETA = [20.0, 70.0]
KW = dict(rays=7 * BLOCK + 321, bins=Bins(10, 7), seed=4)


def heightfield(seed=3):
    return heightfield_surface(random_heights(sigma=0.02, seed=seed), 1 / 32)


@pytest.fixture(scope="module")
def partial():
    with interrupt_at("simulation", after=1):
        part = simulate(heightfield(), "aluminium", THETA, **KW)
    assert part.is_partial
    return part


API_CHANGES = {
    "material": dict(material="methanol"),
    "theta_i": dict(theta_i=[20.0, 60.0]),
    "phi_i": dict(phi_i=10.0),
    "bins": dict(bins=Bins(10, 9)),
    "rays": dict(rays=KW["rays"] + 1),
    "seed": dict(seed=5),
    "bounces": dict(bounces=2),
    "realisations": dict(surface=None, realisations=[heightfield(), heightfield(4)]),
    "origins": dict(origins="independent"),
    "isotropic": dict(isotropic=True),
    "surfaces": dict(surface=heightfield(5)),
}


@pytest.mark.parametrize("field", sorted(API_CHANGES))
def test_resume_refuses_a_run_that_differs_in_any_field(partial, field):
    args = {**KW, "surface": heightfield(), "material": "aluminium", "theta_i": THETA}
    with pytest.raises(UsageError, match="surface" if field == "surfaces" else field):
        simulate(resume=partial, **{**args, **API_CHANGES[field]})


def test_masking_exact_with_several_bounces_is_refused_once_before_any_work():
    s = vgroove_surface([30.0] * 4)
    with pytest.raises(UsageError, match="masking='exact'.*analytic") as refusal:
        simulate(s, "aluminium", 30.0, rays=BLOCK, masking="exact", bounces=2)
    assert "bounces 2" in str(refusal.value)


def _saved(result, tmp_path, change=None) -> Result:
    """``result`` saved and loaded back, its meta.json edited by ``change`` in between."""
    result.save(tmp_path)
    meta = json.loads((tmp_path / "meta.json").read_text())
    if change is not None:
        change(meta)
    (tmp_path / "meta.json").write_text(json.dumps(meta))
    return Result.load(tmp_path)


def test_a_partial_run_saved_before_origins_isotropic_and_bounces_were_recorded_resumes(
    partial, tmp_path
):
    def older(meta):
        for key in ("origins", "isotropic", "bounces"):
            meta.pop(key, None)

    old = _saved(partial, tmp_path, older)
    assert "origins" not in old.meta
    resumed = simulate(heightfield(), "aluminium", THETA, resume=old, **KW)
    full = simulate(heightfield(), "aluminium", THETA, **KW)
    assert not resumed.is_partial
    assert np.array_equal(resumed.brdf, full.brdf, equal_nan=True)
    assert np.array_equal(resumed.stderr, full.stderr, equal_nan=True)


def test_a_partial_run_of_another_ray_design_is_refused_naming_the_design(partial, tmp_path):
    old = _saved(partial, tmp_path, lambda meta: meta.pop("design"))  # design 1 wrote none
    assert saved_identity(old)["design"] == 1
    with pytest.raises(UsageError, match=r"design \(partial run: 1, now: 2\)"):
        simulate(heightfield(), "aluminium", THETA, resume=old, **KW)


# --- microsim run --resume -------------------------------------------------------------------
SCENE = """\
name = "t"
[surface]
kind = "vgrooves"
n_grooves = 40
ndf = "beckmann"
m = 0.3
[material]
ior = "aluminium"
[simulation]
theta_i = [30]
rays = 20000
theta_bins = 9
phi_bins = 10
seed = 3
"""
CLI_CHANGES = {
    "surfaces": ("scene", lambda text: text.replace('name = "t"', 'name = "u"')),
    "surface.m": ("surface.m", lambda text: text.replace("m = 0.3", "m = 0.2")),
    "material": ("material.ior", lambda text: text.replace('"aluminium"', "1.5")),
    "theta_i": ("theta_i", lambda text: text.replace("theta_i = [30]", "theta_i = [40]")),
    "phi_i": ("simulation.phi_i", lambda text: text.replace("seed = 3", "seed = 3\nphi_i = 10")),
    "bins": ("bins", lambda text: text.replace("theta_bins = 9", "theta_bins = 8")),
    "rays": ("rays", lambda text: text.replace("rays = 20000", "rays = 20001")),
    "seed": ("seed", lambda text: text.replace("seed = 3", "seed = 4")),
    "bounces": ("simulation.bounces", lambda text: text + "bounces = 2\n"),
}


def _plan_description(tmp_path, text):
    (tmp_path / "t.toml").write_text(text)
    scene = load_scene(tmp_path / "t.toml")
    sim = scene.simulation
    return scene, run_description(scene, sim.theta_i, sim.seed, True, sim.rays, QUICK, 1)


@pytest.fixture(scope="module")
def saved_run(tmp_path_factory):
    """A complete run of SCENE as ``microsim run --quick`` records it (``meta["run"]``)."""
    tmp = tmp_path_factory.mktemp("saved")
    scene, d = _plan_description(tmp, SCENE)
    res = simulate(
        vgroove_surface([30.0] * 4), scene.ior, list(d.theta_i), phi_i=list(d.phi_i),
        rays=d.rays, bins=d.bins, seed=d.seed,
    )  # fmt: skip
    run = {"scene": scene.name, "quick": True, **tally_settings(scene)}
    return _saved(res, tmp / "o", lambda meta: meta.update(run=run))


def test_the_cli_resumes_its_own_run(saved_run, tmp_path):
    _, description = _plan_description(tmp_path, SCENE)
    _check_resumable(saved_run, description, "o")


@pytest.mark.parametrize("change", sorted(CLI_CHANGES))
def test_the_cli_refuses_a_run_that_differs_in_any_field(saved_run, tmp_path, change):
    name, edit = CLI_CHANGES[change]
    _, description = _plan_description(tmp_path, edit(SCENE))
    message = rf"--resume o: {re.escape(name)}( \(.*\))? is .* there but .* now"
    with pytest.raises(UsageError, match=message):
        _check_resumable(saved_run, description, "o")


def test_the_cli_refuses_a_run_that_does_not_record_its_surface(saved_run, tmp_path):
    _, description = _plan_description(tmp_path, SCENE)
    old = _saved(saved_run, tmp_path / "old", lambda meta: meta["run"].pop("surface"))
    with pytest.raises(UsageError, match="does not record its surface.*older microsim"):
        _check_resumable(old, description, "o")


# --- the testing cache -----------------------------------------------------------------------
REFERENCE_CHANGES = {
    "material": dict(material=None),
    "theta_i": dict(theta_i=[40.0]),
    "phi_i": dict(phi_i=15.0),
    "bins": dict(bins=(10, 12)),
    "rays": dict(rays=20_480),
    "seed": dict(seed=1),
    "surfaces": dict(surface_or_scene="other"),
    "realisations": dict(surface_or_scene="two"),
}


@pytest.mark.parametrize("field", sorted(REFERENCE_CHANGES))
def test_the_reference_cache_key_is_the_runs_identity(field):
    surfaces = {
        "one": vgroove_surface([30.0] * 4),
        "other": vgroove_surface([35.0] * 4),
        "two": [vgroove_surface([30.0] * 4), vgroove_surface([35.0] * 4)],
    }
    args = dict(surface_or_scene="one", material="aluminium", theta_i=[30.0], rays=20_000)
    args.update(bins=(10, 10))

    def ref(**change):
        a = {**args, **change}
        return resolve_reference(surfaces[a.pop("surface_or_scene")], **a)

    base, changed = ref(), ref(**REFERENCE_CHANGES[field])
    assert base.description() == {**base.run().identity(), **_cache_extra(base)}
    assert changed.key() != base.key()
    assert field in [k for k, _, _ in changed.run().mismatches(base.run().identity())]


def _cache_extra(ref) -> dict:
    return {k: v for k, v in ref.description().items() if k in ("microsim", "stderr_rule")}


# --- the sweep -------------------------------------------------------------------------------
TASK = Task(
    "s", {"kind": "vgrooves", "m": 0.3}, "aluminium", 30.0, 1000, 0, 9, 10, ("smith",), "traced"
)
TASK_CHANGES = {
    "scene": "u",
    "surface": {"kind": "vgrooves", "m": 0.2},
    "ior": 1.5,
    "theta_i": 40.0,
    "rays": 1001,
    "seed": 1,
    "theta_bins": 8,
    "phi_bins": 12,
    "models": ("smith", "vgroove"),
    "masking": "exact",
}


def test_the_task_changes_cover_every_field_of_a_task():
    assert set(TASK_CHANGES) == {f.name for f in dataclasses.fields(Task)}


@pytest.mark.parametrize("field", sorted(TASK_CHANGES))
def test_a_sweep_task_id_is_the_key_of_its_run_and_models(field):
    changed = dataclasses.replace(TASK, **{field: TASK_CHANGES[field]})
    assert changed.id != TASK.id
    assert TASK.id == dataclasses.replace(TASK).id  # stable
    if field != "models":  # the models judge the run; they do not change it
        assert changed.run().identity() != TASK.run().identity()
