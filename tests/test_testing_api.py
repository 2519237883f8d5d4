"""microsim.testing: the reference cache (keys, location, concurrent workers), the BRDF
agreement check (passes for the exact model, fails for a wrong one with a message that says
where, tolerance mode), the sampler harness, argument checks and the pytest plugin.

References here are small (200 stratified GGX grooves, 2·10⁴–10⁵ rays, 10 × 10 bins) so each
test traces in about a second; the heavy false-alarm and power measurement is marked slow.
"""

import json
import multiprocessing
import os
import subprocess
import sys
from importlib.metadata import entry_points
from pathlib import Path

import numpy as np
import pytest

import microsim
from microsim.analytic import GGX, torrance_sparrow
from microsim.errors import UsageError
from microsim.surfaces import vgrooves
from microsim.testing import (
    BRDFMismatch,
    assert_brdf_agrees,
    assert_sampler_matches,
    cache_dir,
    pearson_chi2,
    reference,
    set_default_dir,
)
from microsim.testing import cache as cache_mod

AL = "aluminium"
SMALL = dict(rays=20_000, bins=(10, 10))


@pytest.fixture(scope="module")
def surface():
    return vgrooves(200, GGX(0.3))


def ts_ggx(alpha, scale=1.0, material=AL):
    ndf = GGX(alpha)

    def f(wi, wo):
        return scale * torrance_sparrow(wi, wo, ndf, "vgroove", material)

    return f


def entries(root: Path) -> list[str]:
    return sorted(p.name for p in root.iterdir() if p.is_dir() and not p.name.startswith("."))


# --- cache ------------------------------------------------------------------------------------
def test_reference_is_traced_once_then_read_and_keyed_by_what_determines_it(surface, tmp_path):
    a = reference(surface, AL, [30], cache=tmp_path, **SMALL)
    (key,) = entries(tmp_path)
    b = reference(surface, AL, [30], cache=tmp_path, **SMALL)
    assert entries(tmp_path) == [key]
    np.testing.assert_array_equal(a.brdf, b.brdf)
    np.testing.assert_array_equal(a.stderr, b.stderr)
    desc = json.loads((tmp_path / key / "key.json").read_text())
    assert desc["surfaces"]["fingerprints"] == [surface.fingerprint()]
    assert desc["microsim"] == microsim.__version__
    assert desc["rays"] == 20_000 and desc["seed"] == 0 and desc["theta_i"] == [30.0]
    # every ingredient of the key makes a new entry
    reference(surface, AL, [30], cache=tmp_path, seed=1, **SMALL)
    reference(surface, None, [30], cache=tmp_path, **SMALL)
    reference(surface, AL, [30], cache=tmp_path, rays=20_480, bins=(10, 10))
    reference(surface, AL, [30], cache=tmp_path, rays=20_000, bins=(10, 12))
    reference(vgrooves(200, GGX(0.3), seed=5), AL, [30], cache=tmp_path, **SMALL)
    assert len(entries(tmp_path)) == 6


def test_a_damaged_or_foreign_entry_is_traced_again(surface, tmp_path):
    a = reference(surface, AL, [0], cache=tmp_path, **SMALL)
    (key,) = entries(tmp_path)
    desc = json.loads((tmp_path / key / "key.json").read_text())
    desc["seed"] = 99  # as if another description had hashed to this key
    (tmp_path / key / "key.json").write_text(json.dumps(desc))
    b = reference(surface, AL, [0], cache=tmp_path, **SMALL)
    np.testing.assert_array_equal(a.brdf, b.brdf)
    assert json.loads((tmp_path / key / "key.json").read_text())["seed"] == 0


def test_cache_location_argument_then_plugin_then_environment_then_home(tmp_path, monkeypatch):
    monkeypatch.setenv("MICROSIM_CACHE", str(tmp_path / "env"))
    set_default_dir(None)
    try:
        assert cache_dir() == tmp_path / "env"
        set_default_dir(tmp_path / "option")
        assert cache_dir() == tmp_path / "option"
        assert cache_dir(tmp_path / "arg") == tmp_path / "arg"
        set_default_dir(None)
        monkeypatch.delenv("MICROSIM_CACHE")
        monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
        assert cache_dir() == tmp_path / "xdg" / "microsim" / "references"
    finally:
        set_default_dir(None)


def _worker(root, log, out):
    """One 'pytest-xdist worker': count its own traces in ``log``, save its BRDF to ``out``."""
    original = cache_mod._trace

    def counted(ref, threads):
        with open(log, "a") as fh:
            fh.write(f"{os.getpid()}\n")
        return original(ref, threads)

    cache_mod._trace = counted
    res = reference(vgrooves(200, GGX(0.3)), AL, [0, 60], cache=root, threads=1, **SMALL)
    np.save(out, res.brdf)


@pytest.mark.integration
def test_concurrent_workers_trace_a_reference_once_and_read_the_same(tmp_path):
    ctx = multiprocessing.get_context("spawn")  # fresh interpreters, like xdist workers
    log = tmp_path / "traces.log"
    procs = [
        ctx.Process(target=_worker, args=(tmp_path / "cache", log, tmp_path / f"w{k}.npy"))
        for k in range(3)
    ]
    for p in procs:
        p.start()
    for p in procs:
        p.join(300)
        assert p.exitcode == 0
    assert len(log.read_text().split()) == 1  # one trace, the others waited and read it
    results = [np.load(tmp_path / f"w{k}.npy") for k in range(3)]
    for r in results[1:]:
        np.testing.assert_array_equal(r, results[0])
    left = sorted(os.listdir(tmp_path / "cache"))
    assert len(left) == 1 and not left[0].startswith(".")  # no lock, staging or stale dirs


# --- agreement ----------------------------------------------------------------------------------
def test_the_exact_model_agrees_and_the_result_holds_the_verdicts(surface, tmp_path):
    """Torrance–Sparrow with the V-groove G is the stratified V-groove surface's BRDF up to
    its tilt quantisation (module docstring of microsim.testing.agreement); a correct model
    fails with probability ≤ α = 0.01 (false alarms measured in the slow test below)."""
    out = assert_brdf_agrees(ts_ggx(0.3), surface, AL, [0, 60], cache=tmp_path, **SMALL)
    assert out["passed"] and out["failing"] == [] and out["chart"] is None
    assert [v["reference"] for v in out["verdicts"]] == ["one-tile"] * 2
    # the tile's departure from its ensemble is computed and discounted, as microsim run does
    assert all(v["tile_departure"] is not None for v in out["verdicts"])
    assert all(v["n_tests"] == 2 and v["alpha"] == 0.01 for v in out["verdicts"])
    # a catalogue model by name is bin-averaged the same way
    assert assert_brdf_agrees("ts-vgroove", surface, AL, [0, 60], cache=tmp_path, **SMALL)["passed"]


def test_a_model_wrong_by_ten_percent_fails_with_a_table_and_a_chart(surface, tmp_path):
    with pytest.raises(BRDFMismatch) as err:
        assert_brdf_agrees(ts_ggx(0.3, 1.1), surface, AL, [0, 60], cache=tmp_path, **SMALL)
    msg, ag = str(err.value), err.value.agreement
    assert isinstance(err.value, AssertionError)
    assert ag["failing"] == [0.0, 60.0]
    for part in ("χ²/dof", "max|z|", "rel err (E)", "energy dev", "deviating θo", "worst bins"):
        assert part in msg
    # the energy deviation the table shows is the 10 % the model was made wrong by, within
    # the reference's noise (a few standard errors of ~1 % at 2·10⁴ rays)
    for v in ag["verdicts"]:
        assert abs(-v["energy_dev"] / (1 - v["energy_dev"]) - 0.1) < 0.05
    assert Path(ag["chart"]).is_file() and ag["chart"] in msg


def test_tolerance_mode_accepts_a_small_error_and_rejects_a_large_one(surface, tmp_path):
    kw = dict(cache=tmp_path, rays=100_000, bins=(10, 10))
    assert_brdf_agrees(ts_ggx(0.3, 1.01), surface, AL, [30], rtol=0.05, **kw)
    with pytest.raises(BRDFMismatch, match="within rtol = 0.05"):
        assert_brdf_agrees(ts_ggx(0.3, 1.3), surface, AL, [30], rtol=0.05, **kw)


def test_a_brdf_returning_negative_or_nan_values_fails(surface, tmp_path):
    with pytest.raises(AssertionError, match="non-finite or negative"):
        assert_brdf_agrees(
            lambda wi, wo: -np.ones(len(wo)), surface, AL, [0], cache=tmp_path, **SMALL
        )


@pytest.mark.parametrize(
    "kwargs, name",
    [
        (dict(rays=10), "rays"),
        (dict(rays="many"), "rays"),
        (dict(alpha=1.5), "alpha"),
        (dict(rtol=0.0), "rtol"),
        (dict(bins=(10,)), "bins"),
        (dict(seed=-1), "seed"),
        (dict(target=2.0, rays="auto"), "target"),
        (dict(symmetric="yes"), "symmetric"),
        (dict(min_events=0), "min_events"),
    ],
)
def test_bad_arguments_raise_usage_errors_naming_them(surface, tmp_path, kwargs, name):
    args = {**SMALL, **kwargs}
    with pytest.raises(UsageError, match=name):
        assert_brdf_agrees(ts_ggx(0.3), surface, AL, [0], cache=tmp_path, **args)


def test_bad_inputs_name_the_parameter(surface, tmp_path):
    kw = dict(cache=tmp_path, **SMALL)
    with pytest.raises(UsageError, match="material"):
        assert_brdf_agrees(ts_ggx(0.3), surface, theta_i=[0], **kw)
    with pytest.raises(UsageError, match="theta_i"):
        assert_brdf_agrees(ts_ggx(0.3), surface, AL, **kw)
    with pytest.raises(UsageError, match="theta_i"):
        assert_brdf_agrees(ts_ggx(0.3), surface, AL, [95], **kw)
    with pytest.raises(UsageError, match="surface_or_scene"):
        assert_brdf_agrees(ts_ggx(0.3), "no-such-scene", AL, [0], **kw)
    with pytest.raises(UsageError, match="brdf"):
        assert_brdf_agrees("no-such-model", surface, AL, [0], **kw)
    with pytest.raises(UsageError, match="brdf"):
        assert_brdf_agrees(lambda wi, wo: np.ones(3), surface, AL, [0], **kw)
    with pytest.raises(UsageError, match="realisations"):
        assert_brdf_agrees(ts_ggx(0.3), surface, AL, [0], realisations=2, **kw)
    with pytest.raises(UsageError, match="realisations"):
        assert_brdf_agrees(ts_ggx(0.3), "vgroove-ggx-0.3", realisations=0, **kw)


def test_rays_auto_stops_at_the_target_or_the_cap(surface, tmp_path):
    res = reference(surface, AL, [0], rays="auto", target=0.05, bins=(10, 10), cache=tmp_path)
    inc = res.meta["auto"]["incidences"][0]
    assert inc["converged"] and inc["rse"] <= 0.05
    capped = reference(
        surface, AL, [0], rays="auto", target=1e-4, max_rays=50_000, bins=(10, 10), cache=False
    )
    assert capped.rays[0] <= 50_000 + 4096 and not capped.meta["auto"]["incidences"][0]["converged"]


def test_several_realisations_are_judged_as_an_ensemble_with_auto_rays(tmp_path):
    """Two random-tilt groove tiles: the callable is a model of the ensemble (t tests over the
    realisations); rays="auto" traces realisation 0 to the target first (a pilot), then every
    realisation with its ray count."""
    tiles = [vgrooves(200, GGX(0.3), seed=s, sampling="random") for s in (0, 1)]
    out = assert_brdf_agrees(
        ts_ggx(0.3), tiles, AL, [30], rays="auto", target=0.05, bins=(10, 10), cache=tmp_path
    )
    (v,) = out["verdicts"]
    assert v["reference"] == "realisations" and v["realisations"] == 2
    assert out["reference"].rays[0] == 2 * 262_144  # pilot: one first batch met the target


def test_a_scene_name_supplies_material_incidences_and_bins():
    from microsim.testing.cache import resolve_reference

    ref = resolve_reference("vgroove-ggx-0.3", rays=1000)
    assert ref.material == pytest.approx(0.769 + 6.08j)
    assert ref.theta_i == (0.0, 30.0, 60.0, 80.0) and ref.bins.shape == (45, 72)
    assert len(ref.surfaces) == 1 and ref.surfaces[0].nominal["n_grooves"] == 4000
    # a random scene whose file says realisations = "auto" gets MIN_AUTO unless told
    ref = resolve_reference("gaussian-m0.3", rays=1000, realisations=2)
    assert len({s.fingerprint() for s in ref.surfaces}) == 2
    assert cache_mod.DEFAULT_REALISATIONS == 8


# --- sampler harness ----------------------------------------------------------------------------
def cosine_sampler(u1, u2):
    r, phi = np.sqrt(u1), 2 * np.pi * u2
    return np.stack([r * np.cos(phi), r * np.sin(phi), np.sqrt(1 - u1)], axis=1)


def cosine_pdf(w):
    return np.where(w[:, 2] > 0, w[:, 2] / np.pi, 0.0)


def test_sampler_harness_passes_a_correct_sampler_and_fails_a_wrong_pdf():
    check = assert_sampler_matches(cosine_sampler, cosine_pdf, n=100_000)
    assert check["p_value"] >= check["p_threshold"] and check["outside"] == 0
    with pytest.raises(AssertionError, match="sampler does not match its pdf"):
        # uniform hemisphere pdf for cosine samples
        assert_sampler_matches(
            cosine_sampler, lambda w: np.where(w[:, 2] > 0, 0.5 / np.pi, 0.0), n=100_000
        )


def test_sampler_harness_counts_rejected_samples_against_the_missing_probability():
    def half(u1, u2):  # rejects half the samples (NaN), pdf integrates to 1/2
        w = cosine_sampler(u1, u2)
        w[u2 >= 0.5] = np.nan
        return w

    assert_sampler_matches(half, lambda w: cosine_pdf(w) * (w[:, 1] >= 0), n=100_000)
    with pytest.raises(AssertionError):
        assert_sampler_matches(half, cosine_pdf, n=100_000)  # claims none are rejected


def test_sampler_harness_checks_returned_pdf_values_and_arguments():
    with pytest.raises(AssertionError, match="pdf values disagree"):
        assert_sampler_matches(
            lambda u1, u2: (cosine_sampler(u1, u2), np.full(len(u1), 0.3)), cosine_pdf, n=10_000
        )
    with pytest.raises(UsageError, match="sample"):
        assert_sampler_matches(lambda u1, u2: np.zeros((3, 3)), cosine_pdf)
    with pytest.raises(UsageError, match="n must"):
        assert_sampler_matches(cosine_sampler, cosine_pdf, n=10)
    with pytest.raises(AssertionError, match="not a probability density"):
        assert_sampler_matches(cosine_sampler, lambda w: 2 * cosine_pdf(w), n=10_000)


def test_support_reexports_the_public_pearson_chi2():
    import support

    assert support.pearson_chi2 is pearson_chi2
    stat, dof, p = pearson_chi2([10, 20, 30, 2], [15, 15, 30, 2])  # the last (< 5) pooled alone
    assert dof == 3 and stat == pytest.approx(25 / 15 * 2) and 0 < p < 1


# --- pytest plugin --------------------------------------------------------------------------------
@pytest.mark.integration
def test_plugin_option_fixture_and_marker(tmp_path):
    (tmp_path / "test_user.py").write_text(
        "import pytest\n"
        "from microsim.surfaces import vgrooves\n"
        "from microsim.analytic import GGX\n"
        "@pytest.mark.microsim\n"
        "def test_ref(microsim_reference):\n"
        "    r = microsim_reference(vgrooves(50, GGX(0.3)), material=None, theta_i=[0],\n"
        "                           rays=5000, bins=(5, 5))\n"
        "    assert r.brdf.shape == (1, 5, 5)\n"
    )
    installed = any(e.name == "microsim" for e in entry_points(group="pytest11"))
    plugin = [] if installed else ["-p", "microsim.testing.plugin"]
    cache = tmp_path / "refs"
    cmd = [sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", "--strict-markers"]
    cmd += [*plugin, "--microsim-cache", str(cache), str(tmp_path / "test_user.py")]
    run = subprocess.run(cmd, cwd=tmp_path, capture_output=True, text=True, timeout=300)
    assert run.returncode == 0, run.stdout + run.stderr
    assert len(entries(cache)) == 1


# --- calibration (slow) ---------------------------------------------------------------------------
@pytest.mark.slow
def test_false_alarm_and_power_over_seeds(tmp_path):
    """Over 20 seeds of the 4000-groove GGX scene (4 incidences, 2.5·10⁵ rays each): the exact
    model fails at most as often as the binomial bound of α = 0.01 allows (P(≥ 2 of 20) =
    0.017 under α), and the 3 % rougher GGX fails every time."""
    false_alarms = misses = 0
    for seed in range(20):
        kw = dict(rays=250_000, bins=(30, 37), seed=seed, cache=tmp_path, symmetric=True)
        try:
            assert_brdf_agrees(ts_ggx(0.3), "vgroove-ggx-0.3", **kw)
        except BRDFMismatch:
            false_alarms += 1
        try:
            assert_brdf_agrees(ts_ggx(0.309), "vgroove-ggx-0.3", **kw)
            misses += 1
        except BRDFMismatch:
            pass
    assert false_alarms <= 1
    assert misses == 0


def test_isotropic_is_the_deprecated_name_of_symmetric():
    """``symmetric=`` says the callable is symmetric in Δφ; the older ``isotropic=`` still
    sets it, with a DeprecationWarning, and is checked the same way."""
    from microsim.testing.agreement import symmetric_keyword

    assert symmetric_keyword(True) is True and symmetric_keyword(False) is False
    with pytest.warns(DeprecationWarning, match="symmetric="):
        assert symmetric_keyword(False, isotropic=True) is True
    with pytest.raises(UsageError, match="symmetric must be True or False"):
        symmetric_keyword("yes")
