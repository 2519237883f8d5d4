"""The Mitsuba 3 peer of the dielectric path (``bench_peer.PeerScene.run_dielectric``): it
estimates the same R, T and bin averages as ``simulate(..., transmission=True,
bounces="all")`` (agreement within the runs' standard errors, from the air and from inside
the medium), every path ends in one ledger class, a wrong index is detected, and bad input is
refused naming the parameter. Its speed is measured by ``microsim bench``, never asserted."""

import json

import numpy as np
import pytest
from scipy import stats

from microsim.app import bench_report
from microsim.app.bench import _bins, _surface, interface_throughput
from microsim.app.bench_report import BenchConfig, InterfaceThroughput, to_json
from microsim.errors import UsageError
from microsim.sim import Bins, simulate
from microsim.surfaces import gaussian

ETA = 1.5
MIN_PATHS = 100  # bins compared: >= 100 paths in both runs


@pytest.fixture(scope="module")
def tile():
    """64² Gaussian heightfield with the bench surface's statistics (σ = 1.2, ℓ = 8)."""
    return gaussian(64, 1.0, 1.2, 8.0, seed=0)


@pytest.fixture(scope="module")
def mitsuba():
    """The peer module, or a skip saying why Mitsuba's LLVM backend is unusable here."""
    from microsim.app import bench_peer

    try:
        bench_peer.load_mitsuba()
    except bench_peer.PeerUnavailable as exc:
        pytest.skip(str(exc))
    return bench_peer


def _binomial_sigma(p: float, n: int) -> float:
    """Standard error of a fraction of n independent paths (stratified origins only lower
    it)."""
    return float(np.sqrt(max(p * (1 - p), 1.0 / n) / n))


def _agreement(peer, ref, rays: int, bins) -> dict:
    """The peer against microsim at one incidence: R and T differences in combined standard
    errors, and the χ² of the bin averages over the bins with >= MIN_PATHS paths in both
    runs, with its 99.9 % quantile."""
    out = {}
    for name, p, m in (
        ("R", peer.reflectance, ref.reflectance()[0]),
        ("T", peer.transmittance, ref.transmittance()[0]),
    ):
        out[name] = (p - m) / np.hypot(_binomial_sigma(p, rays), _binomial_sigma(m, rays))
    chi2, dof = 0.0, 0
    for side, (f, se, f_ref, se_ref) in enumerate(
        (
            (peer.brdf, peer.stderr_brdf, ref.brdf_total()[0], ref.stderr_orders[:, 0]),
            (peer.btdf, peer.stderr_btdf, ref.btdf_total()[0], ref.stderr_btdf_orders[:, 0]),
        )
    ):
        se_ref = np.sqrt(np.sum(se_ref**2, axis=0))  # each path in one order: variances add
        ref_counts = f_ref * rays * bins.projected_solid_angle()  # weights are 1
        used = (peer.counts[side] >= MIN_PATHS) & (ref_counts >= MIN_PATHS - 0.5)
        chi2 += float(np.sum(((f - f_ref)[used] / np.hypot(se, se_ref)[used]) ** 2))
        dof += int(used.sum())
    out["chi2"], out["dof"], out["chi2_max"] = chi2, dof, float(stats.chi2.ppf(0.999, dof))
    return out


def _compare(mitsuba, surface, theta_i, rays, bins, peer_eta=ETA):
    peer = mitsuba.mitsuba_dielectric(surface, peer_eta, theta_i, rays, bins, seed=1, threads=2)
    ref = simulate(
        surface, ETA, theta_i, transmission=True, bounces="all", rays=rays, bins=bins, threads=2
    )
    return peer, _agreement(peer, ref, rays, bins)


@pytest.mark.parametrize("theta_i", [30.0, 150.0])
def test_agrees_with_simulate(mitsuba, tile, theta_i):
    """From the air (30°) and from inside the glass (150°): R and T within 4 combined
    standard errors, the bins' χ² below its 99.9 % quantile, every path in exactly one ledger
    class (none lost on this surface) and the bins' sums equal to R and T."""
    rays, bins = 100_000, Bins(9, 7)
    peer, agree = _compare(mitsuba, tile, theta_i, rays, bins)
    assert sum(peer.ledger.values()) == rays
    assert peer.ledger["reflected"] + peer.ledger["transmitted"] == rays, peer.ledger
    assert abs(agree["R"]) < 4 and abs(agree["T"]) < 4, agree
    assert agree["dof"] >= 10 and agree["chi2"] < agree["chi2_max"], agree
    omega = bins.projected_solid_angle()
    assert np.sum(peer.brdf * omega) == pytest.approx(peer.reflectance, rel=1e-12)
    assert np.sum(peer.btdf * omega) == pytest.approx(peer.transmittance, rel=1e-12)
    assert peer.segments > 1  # continuation rays were traced


def test_a_wrong_index_is_detected(mitsuba, tile):
    """Power of the comparison: a peer with η = 1.6 against microsim's 1.5 is many standard
    errors away in R (flat glass: 5.3 % against 4.0 % at 30°)."""
    _, agree = _compare(mitsuba, tile, 30.0, 100_000, Bins(9, 7), peer_eta=1.6)
    assert abs(agree["R"]) > 10, agree


@pytest.mark.slow
@pytest.mark.parametrize("theta_i", [30.0, 150.0])
def test_agrees_with_simulate_on_the_bench_surface(mitsuba, theta_i):
    """The same agreement on the bench's own 512² surface and bins (what ``microsim bench``
    times): 3 × 3 tile copies of 524 288 triangles for the peer."""
    rays = 400_000
    peer, agree = _compare(mitsuba, _surface(BenchConfig()), theta_i, rays, _bins())
    assert peer.ledger["reflected"] + peer.ledger["transmitted"] >= rays - 3, peer.ledger
    assert abs(agree["R"]) < 4 and abs(agree["T"]) < 4, agree
    assert agree["dof"] >= 10 and agree["chi2"] < agree["chi2_max"], agree


@pytest.mark.parametrize(
    "kwargs, name",
    [
        (dict(material=None), "transmission=True needs a material"),
        (dict(material=0.7 + 6j), "material must be a real index"),
        (dict(theta_i_deg=60.0), "theta_i"),
        (dict(bounces=0), "bounces"),
        (dict(rays=1), "rays"),
        (dict(bins=(9, 7)), "bins"),
    ],
)
def test_bad_input(mitsuba, tile, kwargs, name):
    scene = mitsuba.PeerScene(tile, 30.0)
    args = dict(material=ETA, theta_i_deg=30.0, rays=1000, bins=Bins(9, 7))
    args.update(kwargs)
    with pytest.raises(UsageError, match=name):
        scene.run_dielectric(**args)


def _check_interface_figures(di, peer: bool) -> str:
    """The bookkeeping of ``interface_throughput`` (not the figures' size): one line per
    incidence (the bench's θi from the air and from inside), marginal lines through both
    calls, the ratio of the rates where both resolved; the JSON round trip; its text."""
    assert di.eta == ETA and [line.theta_i for line in di.incidences] == [30.0, 150.0]
    for line in di.incidences:
        mg = line.marginal
        for t in (1, 2):
            for fig in [mg.pipeline[t]] + ([mg.peer[t]] if peer else []):
                assert all(s > 0 for s in fig.seconds)
                for n, seconds in zip(mg.rays, fig.seconds) if fig.resolved() else ():
                    assert fig.fixed_seconds + n / fig.samples_per_s == pytest.approx(seconds)
            if peer and mg.ratio[t] is not None:
                rate = mg.pipeline[t].samples_per_s / mg.peer[t].samples_per_s
                assert mg.ratio[t] == pytest.approx(rate, rel=1e-12)
        assert (mg.peer is not None) == peer and (line.rays_per_path is not None) == peer
    saved = InterfaceThroughput.from_json(json.loads(json.dumps(to_json(di))))
    assert saved == di
    text = "\n".join(bench_report._interface_lines(saved))
    assert "θi = 30° (from the air" in text and "θi = 150° (from inside" in text
    return text


def test_the_bench_measures_the_dielectric_path():
    """Without the peer: the pipeline's figures alone, nothing printed about Mitsuba."""
    cfg = BenchConfig(n=32, rays=2**14)
    di = interface_throughput(cfg, repeat=1, peer=(None, "not in this test"))
    assert "Mitsuba" not in _check_interface_figures(di, peer=False)


def test_the_bench_measures_the_dielectric_path_against_the_peer(mitsuba):
    """With the peer: both sides' figures side by side, their ratio, its rays per path (a
    primary ray and at least one continuation)."""
    cfg = BenchConfig(n=32, rays=2**14)
    di = interface_throughput(cfg, repeat=1)
    text = _check_interface_figures(di, peer=True)
    assert "Mitsuba peer paths/s" in text
    assert all(line.rays_per_path > 1 for line in di.incidences)


@pytest.mark.parametrize("surface_name", ["tile", "flat"])
def test_the_dielectric_shortcuts_change_nothing(monkeypatch, tile, surface_name):
    """``dielectric.leaving`` with ``bounces.trace_continuing``: a continuing ray leaving the
    surface on its own side more steeply than the steepest facet gets its walk's status
    without a walk — most of the paths refracted into the glass at 30° — and
    ``dielectric.bin_side_escapes`` bins the escapes by the single bounce's vectorised
    binning; every number stays bitwise that of tracing every ray (``Tracer.surely_escapes``
    switched off) and binning by ``Bins.locate`` (on the flat interface every escape lies on
    a Δφ edge or at the zenith). The tile is traced through Embree step by step (its grid walk
    switched off: ``interface_grid`` has its own test)."""
    from microsim.sim import bounces, dielectric
    from microsim.sim.tracer import Tracer
    from microsim.sim.tracer_cache import GRID_SWITCH
    from microsim.surfaces import flat

    monkeypatch.setenv(GRID_SWITCH, "0")

    surface, incidences = (
        (tile, [30.0, 150.0]) if surface_name == "tile" else (flat(1.0), [0.0, 60.0, 150.0])
    )
    traced = []
    trace_columns = Tracer.trace_columns

    def counting(self, x, *args, **kwargs):
        traced[-1] += len(x[0])
        return trace_columns(self, x, *args, **kwargs)

    def run():
        traced.append(0)
        kw = dict(transmission=True, bounces="all", rays=20_000, bins=Bins(9, 7), seed=3)
        return simulate(surface, ETA, incidences, **kw)

    monkeypatch.setattr(Tracer, "trace_columns", counting)
    fast = run()
    monkeypatch.setattr(Tracer, "surely_escapes", lambda self, dx, dy, dz: np.zeros(len(dx), bool))

    def by_locate(bins, esc, e, phi, offset, where):
        bounces.bin_escapes(bins, esc.index[:e], [c[:e] for c in esc[1:4]], phi, offset, where)

    monkeypatch.setattr(dielectric, "bin_side_escapes", by_locate)
    every = run()
    if surface_name == "tile":
        assert traced[0] < 0.6 * traced[1], traced
    for name in ("brdf_orders", "btdf_orders", "stderr_orders", "stderr_btdf_orders"):
        np.testing.assert_array_equal(getattr(fast, name), getattr(every, name))
    for key, counts in every.ledger_counts.items():
        np.testing.assert_array_equal(fast.ledger_counts[key], counts)
