"""The Mitsuba 3 peer of the bench (microsim.app.bench_peer): it estimates the same single-bounce
integral as ``simulate`` (agreement within the two runs' own standard errors), it refuses bad
input with a UsageError naming the parameter, and it fails with PeerUnavailable (naming the
pip command) when mitsuba cannot be imported. Throughput figures are measured, not asserted."""

import sys

import numpy as np
import pytest
from scipy import stats

from microsim.analytic import Beckmann
from microsim.app.bench_peer import PeerUnavailable, mitsuba_single_bounce, peer_throughput
from microsim.errors import EnvironmentFailure, UsageError
from microsim.sim import Bins, simulate
from microsim.surfaces import gaussian, vgrooves

MIN_EVENTS = 100  # bins compared: >= 100 single-bounce events in both runs (microsim.testing)


@pytest.fixture(scope="module")
def tile():
    """64² Gaussian heightfield, dx = 1, σ = 1.2, ℓ = 8 (8192 facets, Beckmann m ≈ 0.3)."""
    return gaussian(64, 1.0, 1.2, 8.0, seed=0)


@pytest.fixture(scope="module")
def small():
    return gaussian(16, 1.0, 0.3, 7.0, seed=1)


def test_unavailable_without_mitsuba(monkeypatch, small):
    """No mitsuba: an EnvironmentFailure whose message gives the pip command."""
    monkeypatch.setitem(sys.modules, "mitsuba", None)  # makes `import mitsuba` fail
    with pytest.raises(PeerUnavailable, match="pip install") as err:
        mitsuba_single_bounce(small, "aluminium", 30.0, rays=1000, bins=Bins(9, 7))
    assert isinstance(err.value, EnvironmentFailure)
    with pytest.raises(PeerUnavailable, match="pip install"):
        peer_throughput(small, "aluminium", 30.0, rays=1000)


def test_agrees_with_simulate(tile):
    """Both estimate f̄_B = Σw/(NΩ_B) of the same surface: per bin the difference is within
    the runs' combined standard errors (χ² below its 99.9 % quantile), the albedo within 3σ,
    and every ray is in exactly one ledger class."""
    pytest.importorskip("mitsuba")
    bins, rays = Bins(9, 7), 200_000
    peer = mitsuba_single_bounce(tile, "aluminium", 30.0, rays, bins, seed=1, threads=2)
    ref = simulate(tile, "aluminium", 30.0, rays=rays, bins=bins, seed=0, threads=2)
    assert sum(peer.ledger.values()) == rays
    assert peer.copies == 7  # the 88° rule on this 64² tile of relief 6.3 (module docstring)
    used = (peer.counts >= MIN_EVENTS) & (ref.counts[0] >= MIN_EVENTS)
    assert used.sum() >= 10
    se = np.hypot(peer.stderr, ref.stderr[0])[used]
    chi2 = float(np.sum(((peer.brdf - ref.brdf[0])[used] / se) ** 2))
    assert chi2 < stats.chi2.ppf(0.999, used.sum()), (chi2, used.sum())
    omega = bins.projected_solid_angle()
    ref_albedo_se = np.sqrt(np.sum((ref.stderr[0] * omega) ** 2))  # covariances ≤ 0 dropped
    assert abs(peer.albedo - ref.albedo()[0]) < 3 * np.hypot(peer.albedo_stderr, ref_albedo_se)
    # the same integral: the bins' sum is the albedo
    assert np.isclose(np.sum(peer.brdf * omega), peer.albedo, rtol=1e-12)


def test_fresnel_difference_is_detected(tile):
    """Power of the comparison above: a mirror peer (F = 1) against aluminium (F ≈ 0.92) is
    many standard errors away."""
    pytest.importorskip("mitsuba")
    bins, rays = Bins(9, 7), 50_000
    peer = mitsuba_single_bounce(tile, None, 30.0, rays, bins, seed=1, threads=1)
    ref = simulate(tile, "aluminium", 30.0, rays=rays, bins=bins, seed=0, threads=1)
    omega = bins.projected_solid_angle()
    ref_albedo_se = np.sqrt(np.sum((ref.stderr[0] * omega) ** 2))
    assert abs(peer.albedo - ref.albedo()[0]) > 10 * np.hypot(peer.albedo_stderr, ref_albedo_se)


def test_threads_change_only_rounding(small):
    """Same rays on 1 and 2 Dr.Jit threads: identical ledger and counts; sums equal up to
    the order of the atomic float64 additions."""
    pytest.importorskip("mitsuba")
    kw = dict(rays=20_000, bins=Bins(9, 7), seed=5)
    a = mitsuba_single_bounce(small, "aluminium", 45.0, threads=1, **kw)
    b = mitsuba_single_bounce(small, "aluminium", 45.0, threads=2, **kw)
    assert a.ledger == b.ledger
    assert np.array_equal(a.counts, b.counts)
    np.testing.assert_allclose(a.brdf, b.brdf, rtol=1e-12, atol=0)


@pytest.mark.parametrize(
    "kwargs, name",
    [
        (dict(rays=0), "rays"),
        (dict(rays=2.5), "rays"),
        (dict(theta_i_deg=95.0), "theta_i"),
        (dict(theta_i_deg=-1.0), "theta_i"),
        (dict(material="unobtainium"), "material"),
        (dict(bins=(9, 7)), "bins"),
        (dict(seed=-1), "seed"),
        (dict(threads=0), "threads"),
    ],
)
def test_bad_input(small, kwargs, name):
    pytest.importorskip("mitsuba")
    args = dict(material="aluminium", theta_i_deg=30.0, rays=1000, bins=Bins(9, 7))
    args.update(kwargs)
    with pytest.raises(UsageError, match=name):
        mitsuba_single_bounce(small, **args)


def test_bad_surface_and_throughput_arguments(small):
    """Checked before mitsuba is needed: V-grooves (azimuth-averaged), non-surfaces, and
    peer_throughput's threads/repeat."""
    with pytest.raises(UsageError, match="surface"):
        mitsuba_single_bounce(object(), "aluminium", 30.0, 1000)
    grooves = vgrooves(100, Beckmann(0.3), seed=0)
    with pytest.raises(UsageError, match="V-grooves"):
        mitsuba_single_bounce(grooves, "aluminium", 30.0, 1000)
    with pytest.raises(UsageError, match="threads"):
        peer_throughput(small, "aluminium", 30.0, 1000, threads=0)
    with pytest.raises(UsageError, match="repeat"):
        peer_throughput(small, "aluminium", 30.0, 1000, repeat=0)


def test_throughput_report(small):
    """The figures' bookkeeping (not their size): samples/s = rays / best seconds, and the
    caller's Dr.Jit thread count is restored."""
    pytest.importorskip("mitsuba")
    import drjit as dr

    before = dr.thread_count()
    out = peer_throughput(small, "aluminium", 30.0, rays=2**14, threads=1, repeat=2)
    assert dr.thread_count() == before
    assert out["threads"] == 1 and out["rays"] == 2**14
    assert out["samples_per_s"] == pytest.approx(out["rays"] / out["seconds"], rel=1e-12)
    assert out["variant"].startswith("llvm") and out["mitsuba_version"]
    assert out["build_seconds"] > 0 and sum(out["ledger"].values()) == 2**14


_PINNED = """
import json
import numpy as np
from microsim.app.bench_peer import llvm_target, mitsuba_single_bounce
from microsim.sim import Bins, simulate
from microsim.surfaces import gaussian
tile = gaussian(64, 1.0, 1.2, 8.0, seed=0)
peer = mitsuba_single_bounce(tile, "aluminium", 30.0, 200_000, Bins(9, 7), seed=1, threads=2)
ref = simulate(tile, "aluminium", 30.0, rays=200_000, bins=Bins(9, 7), seed=0, threads=2)
se = float(np.sqrt(np.sum((ref.stderr[0] * Bins(9, 7).projected_solid_angle()) ** 2)))
print(json.dumps({"target": llvm_target(), "peer": [peer.albedo, peer.albedo_stderr],
                  "ref": [float(ref.albedo()[0]), se]}))
"""


def test_pinned_llvm_target_changes_the_kernels_not_the_estimate():
    """``MICROSIM_PEER_LLVM_CPU=haswell`` (in a fresh process: the target is process-wide)
    compiles the peer's kernels for Haswell at 8 lanes, and its albedo still agrees with
    ``simulate``'s within 3 combined standard errors."""
    import json
    import os
    import subprocess

    pytest.importorskip("mitsuba")
    env = {**os.environ, "MICROSIM_PEER_LLVM_CPU": "haswell"}
    out = subprocess.run(
        [sys.executable, "-c", _PINNED], env=env, capture_output=True, text=True, timeout=300
    )
    if out.returncode != 0 and "PeerUnavailable" in out.stderr:
        pytest.skip(out.stderr.strip().splitlines()[-1])
    assert out.returncode == 0, out.stderr[-2000:]
    got = json.loads(out.stdout.strip().splitlines()[-1])
    assert got["target"] == {"cpu": "haswell", "lanes": 8}
    (a, sa), (b, sb) = got["peer"], got["ref"]
    assert abs(a - b) < 3 * np.hypot(sa, sb), got
