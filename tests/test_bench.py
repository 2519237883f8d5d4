"""Performance machinery (microsim.app.bench, the batched pipeline of microsim.sim):
figures are measured, never asserted; what is asserted is that batching changes no result,
that the per-facet table path equals the per-ray path, and that memory does not grow with
the number of rays."""

import json

import numpy as np
import pytest
from support import heightfield_surface, random_heights

from microsim.analytic.fresnel import fresnel, resolve_material
from microsim.app import bench_report
from microsim.app.bench import (
    BenchConfig,
    build_times,
    format_bench,
    machine,
    marginal_throughput,
    peak_rss_mb,
    throughput,
)
from microsim.app.bench_report import Bench, Marginal, to_json
from microsim.app.cli import build_parser
from microsim.jit import numba_target
from microsim.sim import (
    BLOCK,
    Bins,
    events,
    facet_tables,
    paths,
    ray_columns,
    simulate,
    streams,
    tracer_cache,
)
from microsim.sim.tallies import Tally, chunk_tallies
from microsim.surfaces.surface import flat
from microsim.vectors import spherical_deg

AL = resolve_material("aluminium")


@pytest.fixture(scope="module")
def rough():
    return heightfield_surface(random_heights(sigma=0.03, seed=4), 1 / 64)  # 8192 facets


def test_per_ray_path_is_identical_for_any_threads_and_chunk(rough):
    """Fewer rays than facets: the per-ray path (no facet table) with Fresnel per block."""
    rays = BLOCK + 77
    assert rays < len(rough.faces)
    kw = dict(rays=rays, bins=Bins(10, 7), seed=3)
    a = simulate(rough, "aluminium", [25.0, 75.0], threads=1, chunk=BLOCK, **kw)
    b = simulate(rough, "aluminium", [25.0, 75.0], threads=2, chunk=2 * BLOCK, **kw)
    for name in ("sum_w", "sum_w2", "counts", "brdf"):
        assert np.array_equal(getattr(a, name), getattr(b, name)), name
    assert all(np.array_equal(a.ledger[k], b.ledger[k]) for k in a.ledger)


@pytest.mark.parametrize("theta", [0.0, 40.0, 85.0])
def test_fast_paths_equal_the_per_ray_events(rough, theta):
    """Same rays through the facet-table and column paths (tallies) and ``_trace`` (the
    per-ray Events of ``ray_events``): identical ledger classes and bins; Fresnel weights equal
    to rounding (the table evaluates F once per facet, the others once per hit). Rays whose
    primary hit is a float32 edge tie (the float64 grid walk and Embree's float32 test give
    neighbouring facets: ``heightfield_caster``) are left out; they are rare."""
    tracer, profile, az = tracer_cache.tracer_for(rough, "traced")
    wi = spherical_deg(theta, 10.0)
    bins = Bins(18, 13)
    starts = np.concatenate(
        [streams.block_origins(tracer, 3 * BLOCK, b, (0, 0, 0), False)[0] for b in range(3)]
    )
    ev = events.trace_events(tracer, profile, wi, starts, None, AL, False)
    single = ev.status == paths.SINGLE
    assert single.mean() > 0.5 and np.any(ev.status == paths.MASKED)  # not vacuous
    table = facet_tables.facet_table(tracer, wi, AL, bins, 10.0)
    cols = [np.ascontiguousarray(starts[:, k]) for k in range(3)]
    walked = tracer.cast_falling(cols, [float(-c) for c in wi])  # None: Embree casts both
    tie = (
        np.zeros(len(starts), bool)
        if walked is None
        else walked[1] != tracer.first_hit(starts, -wi).prim
    )
    assert tie.mean() < 1e-3
    for status, weight, where in (
        ray_columns.trace_tabled(tracer, table, wi, starts),
        ray_columns.trace_columns(tracer, None, wi, 10.0, bins, starts, None, AL),
    ):
        assert np.mean(status != ev.status) <= 1e-4  # float32-grazing decisions only
        same = (status == ev.status) & ~tie
        assert np.allclose(weight[same], ev.weight[same], rtol=1e-13, atol=0)
        ok = same & single
        assert np.array_equal(where[ok], bins.locate(ev.wo[ok], 10.0))


@pytest.mark.parametrize("masking", ["traced", "exact"])
def test_groove_column_path_equals_the_per_ray_events(masking):
    """Azimuth-averaged grooves: binning in the groove frame against φi − ψ gives the bins of
    the rotated-back wo."""
    from microsim import analytic as an
    from microsim.surfaces import vgrooves

    tracer, profile, az = tracer_cache.tracer_for(vgrooves(64, an.Beckmann(0.4), seed=1), masking)
    wi, bins = spherical_deg(60.0, 25.0), Bins(18, 13)
    drawn = [streams.block_origins(tracer, 2 * BLOCK, b, (1, 0, 0), True) for b in range(2)]
    starts, psi = (np.concatenate(x) for x in zip(*drawn))
    ev = events.trace_events(tracer, profile, wi, starts, psi, AL, True)
    status, weight, where = ray_columns.trace_columns(
        tracer, profile, wi, 25.0, bins, starts, psi, AL
    )
    assert np.mean(status != ev.status) <= 1e-4 and np.any(status == paths.MASKED)
    same = status == ev.status
    assert np.allclose(weight[same], ev.weight[same], rtol=1e-13, atol=0)
    ok = same & (ev.status == paths.SINGLE)
    assert np.mean(where[ok] != bins.locate(ev.wo[ok], 25.0)) <= 1e-4  # bin edges to rounding


def test_peak_memory_does_not_grow_with_the_ray_count():
    """Any per-ray storage costs ≥ 8 bytes per ray (one float64); 8x more rays must add less
    than half of that, i.e. memory is bounded by the chunk, not by the run."""
    cfg = BenchConfig(n=64)
    small, large = 2**19, 2**22  # both long enough for every buffer to reach its size
    a, b = peak_rss_mb(cfg, small), peak_rss_mb(cfg, large)
    assert b - a < 0.5 * 8 * (large - small) / 2**20, (a, b)


def test_bench_figures_are_measured_and_printable():
    cfg = BenchConfig(n=32, rays=2**14)
    raw, pipe = throughput(cfg, repeat=1)
    assert raw.primary_rays == 2**14 and 0 < raw.masking_rays <= raw.primary_rays
    for t in (1, 2):
        assert np.isfinite(raw.rays_per_s[t]) and raw.rays_per_s[t] > 0
        assert np.isfinite(pipe[t]) and pipe[t] > 0
    if raw.packets_unavailable is None:
        assert raw.packet_width in (4, 8, 16)
        assert all(np.isfinite(raw.packet_rays_per_s[t]) for t in (1, 2))
    else:
        assert raw.packet_rays_per_s is None
    b = Bench(
        config=BenchConfig(target=0.01),
        load_average=[0.0],
        cpus=2,
        mesh_triangles=2048,
        raw=raw,
        pipeline_samples_per_s=pipe,
        ratio={t: pipe[t] / raw.samples_per_s[t] for t in (1, 2)},
        peak_rss_mb={2**14: 100.0},
        build_seconds=build_times(flat(), repeat=1),
        machine=machine(),
    )
    assert b.build_seconds.embreex > 0
    assert b.machine.isa in ("AVX-512", "AVX2") or "x86" not in b.machine.isa
    text = format_bench(b)
    assert text.startswith(f"machine: {b.machine.cpu}, {b.machine.isa}")
    assert "raw embreex rays/s" in text and "pipeline / raw" in text and "BVH build" in text
    assert ("packets / embreex" in text) == (raw.packets_unavailable is None)
    saved = json.loads(json.dumps(b.to_json()))
    assert list(saved) == [
        "config",
        "machine",
        "load_average",
        "cpus",
        "mesh_triangles",
        "raw",
        "pipeline_samples_per_s",
        "ratio",
        "build_seconds",
        "peak_rss_mb",
    ]
    assert list(saved["raw"])[:3] == ["rays", "primary_rays", "masking_rays"]
    assert Bench.from_json(saved) == b and format_bench(Bench.from_json(saved)) == text


def test_marginal_throughput_fits_a_line_through_two_ray_counts():
    """The marginal figures are the slope and intercept of the line through the two calls'
    best wall times: it passes through both points (a timing that did not resolve the margin
    is reported as such, not as a rate); printed, with the ratio only when the peer ran."""
    cfg = BenchConfig(n=32, rays=2**16)
    mg = marginal_throughput(cfg, repeat=1, peer=(None, "not in this test"))
    assert mg.rays == [2**14, 2**16] and mg.peer is None and mg.ratio is None
    for t in (1, 2):
        fig = mg.pipeline[t]
        (t1, t2), rate = fig.seconds, fig.samples_per_s
        assert 0 < t1 and 0 < t2
        if rate is None:
            assert t2 <= t1
        else:
            for n, seconds in zip(mg.rays, (t1, t2)):
                assert fig.fixed_seconds + n / rate == pytest.approx(seconds, rel=1e-9)
    saved = Marginal.from_json(json.loads(json.dumps(to_json(mg))))
    assert saved == mg
    text = "\n".join(bench_report._marginal_lines(saved))
    assert "marginal, 16,384 → 65,536 rays" in text and "Mitsuba" not in text


def test_the_ratio_round_by_round_pairs_each_rounds_calls():
    """Within a round the two sides' margins are divided (the same turn of the host): their
    median and range over the rounds, a round where either side's larger call was not the
    slower left out; the best-of figures still come from each side's fastest calls; records
    written before the rounds were kept load without them."""
    rays = [100, 400]
    pipe = {t: {100: [1.0, 1.1, 1.2, 1.0], 400: [2.0, 2.3, 2.0, 0.9]} for t in (1, 2)}
    peer = {t: {100: [2.0, 2.0, 2.1, 2.0], 400: [4.0, 5.0, 3.9, 4.0]} for t in (1, 2)}
    mg = Marginal.of(rays, pipe, peer, None)
    per_round = [2.0 / 1.0, 3.0 / 1.2, 1.8 / 0.8]  # (q2 − q1)/(p2 − p1); round 4 unresolved
    for t in (1, 2):
        r = mg.ratio_rounds[t]
        assert r.rounds == 3
        assert (r.median, r.low, r.high) == pytest.approx((2.25, min(per_round), max(per_round)))
        assert mg.pipeline[t].seconds == [1.0, 0.9] and mg.pipeline[t].samples_per_s is None
        assert mg.peer[t].seconds == [2.0, 3.9]
    saved = json.loads(json.dumps(to_json(mg)))
    assert Marginal.from_json(saved) == mg
    del saved["ratio_rounds"]
    assert Marginal.from_json(saved).ratio_rounds is None
    slower = {t: {100: [1.0], 400: [0.5]} for t in (1, 2)}
    assert Marginal.of(rays, slower, slower, None).ratio_rounds == {1: None, 2: None}
    assert Marginal.of(rays, pipe, None, "no peer").ratio_rounds is None


def test_the_command_line_has_the_bench_subcommand():
    args = build_parser(("bench",)).parse_args(["bench", "--json", "--quick"])
    assert args.json and args.quick and callable(args.func)


@pytest.mark.parametrize(
    "argv, rays",
    [
        (["--quick", "--rays", "5000"], 5000),
        (["--rays", "7000"], 7000),
        (["--quick"], 2**17),
        ([], BenchConfig.rays),
    ],
)
def test_bench_rays_option_is_honoured_with_and_without_quick(monkeypatch, capsys, argv, rays):
    """``bench --quick --rays N`` measures N rays (--quick once ignored --rays)."""
    import microsim.app.bench as B

    seen = []
    monkeypatch.setattr(B, "run_bench", lambda cfg: seen.append(cfg))
    monkeypatch.setattr(B, "format_bench", lambda b: "")
    args = build_parser(("bench",)).parse_args(["bench", *argv])
    assert args.func(args) == 0
    assert seen[0].rays == rays
    assert seen[0].n == (128 if "--quick" in argv else BenchConfig.n)


# --- incidence-azimuth rotation (statistically isotropic heightfields) ---------------------------
def _tallies(tracer, wi, blocks_per_chunk, n_total, bins, rotate):
    """Running totals (``Tally.items()``) after adding the chunks of ``blocks_per_chunk``."""
    nblk, nbin = -(-n_total // BLOCK), bins.shape[0] * bins.shape[1]
    incidence = paths.Incidence(tracer, wi, 0.0, bins, AL, n_total, (5, 0, 0))
    path = paths.choose_path(incidence, None, False, isotropic=rotate)
    total = Tally.empty(nbin)
    for a in range(0, nblk, blocks_per_chunk):
        total.add_chunk(chunk_tallies(path, nbin, range(a, min(a + blocks_per_chunk, nblk))))
    return total.items()


def test_rotated_incidence_is_reproducible_for_any_chunk(rough):
    tracer = tracer_cache.tracer_for(rough, "traced")[0]
    wi, bins, n = spherical_deg(50.0, 0.0), Bins(10, 7), 3 * BLOCK + 5
    a = _tallies(tracer, wi, 1, n, bins, True)
    b = _tallies(tracer, wi, 3, n, bins, True)
    c = _tallies(tracer, wi, 4, n, bins, False)
    assert all(np.array_equal(x, y) for x, y in zip(a, b))
    assert not np.array_equal(a[0], c[0])  # the rotation acts


@pytest.mark.parametrize("theta", [20.0, 65.0])
def test_rotated_incidence_keeps_the_mirror_direction_of_a_flat_surface(theta):
    """Bins follow the rotated incidence: all energy F(θi) stays in the mirror bin Δφ = 180°."""
    tracer = tracer_cache.tracer_for(flat(), "traced")[0]
    bins = Bins(45, 37)
    tallies = _tallies(tracer, spherical_deg(theta, 0.0), 2, 3 * BLOCK, bins, True)
    sw = tallies[0]
    k = bins.locate(spherical_deg(theta, 180.0), 0.0)
    assert sw[k] / (3 * BLOCK) == pytest.approx(
        float(fresnel(np.cos(np.radians(theta)), AL)), rel=1e-12
    )
    assert np.count_nonzero(sw) == 1


def test_wave_rows_are_measured_and_printed():
    """``bench``'s wave rows: one per roughness, a measured wall time, and on the
    smooth tile (σ = λ/100, g = (4πσ cos θi/λ)² = 0.012) the order powers sum to the Fresnel
    reflectance F(30°): the diffuse share is ~g, and Kirchhoff's obliquity factor moves it by
    far less than 1 % of F (a broken solver or wrong tile misses it by more)."""
    from microsim.app.bench import QUICK, wave_rows

    cfg = BenchConfig(wave_n=64, wave_tile=12.5)  # the quick tile's dx = 0.195 λ
    rows = wave_rows(cfg)
    assert [r.sigma for r in rows] == [0.01, 1.0]
    f30 = float(fresnel(np.cos(np.radians(30.0)), AL))
    assert rows[0].albedo == pytest.approx(f30, rel=1e-2)
    for r in rows:
        assert r.n == 64 and r.orders > 100 and np.isfinite(r.seconds) and r.seconds > 0
    text = format_bench(Bench.from_json({**_minimal_bench(), "wave": to_json(rows)}))
    assert text.count("wave solver (Kirchhoff") == 2 and "σ = 1 λ" in text
    assert QUICK["wave_n"] == 128 and BenchConfig().wave_n == 1024


def _minimal_bench():
    raw = {
        "primary_rays": 1,
        "masking_rays": 1,
        "rays_per_s": {1: 1.0, 2: 1.0},
        "samples_per_s": {1: 1.0, 2: 1.0},
        "packets_unavailable": "test",
    }
    return {
        "config": {"target": 0.01},
        "load_average": [0.0],
        "cpus": 2,
        "mesh_triangles": 2,
        "raw": raw,
        "pipeline_samples_per_s": {1: 1.0, 2: 1.0},
        "ratio": {1: 1.0, 2: 1.0},
        "peak_rss_mb": {},
    }


def test_the_memory_probe_ignores_a_microsim_folder_in_the_working_directory(tmp_path, monkeypatch):
    """`microsim bench` run from a folder holding a `microsim/` directory (a checkout's parent,
    say): the probe's child process imports the same microsim as the parent."""
    from microsim.app import bench

    (tmp_path / "microsim").mkdir()
    (tmp_path / "microsim" / "__init__.py").write_text("raise ImportError('the wrong microsim')")
    monkeypatch.chdir(tmp_path)
    assert bench.peak_rss_mb(bench.BenchConfig(n=64), rays=4096) > 10.0


def test_a_failing_memory_probe_is_an_environment_failure_naming_its_error(monkeypatch):
    from microsim.app import bench
    from microsim.errors import EnvironmentFailure

    monkeypatch.setattr(bench, "_PROBE", "import sys; sys.exit('probe: out of luck')")
    with pytest.raises(EnvironmentFailure, match="probe: out of luck"):
        bench.peak_rss_mb(bench.BenchConfig(n=64), rays=4096)


@pytest.mark.parametrize(
    "name, features, reported",
    [
        ("haswell", None, "haswell with the host's features"),
        ("haswell", "", "haswell"),
        ("skylake-avx512", "-avx512f", "skylake-avx512 -avx512f"),
    ],
)
def test_the_machine_record_says_when_numba_adds_the_hosts_features(
    monkeypatch, name, features, reported
):
    # NUMBA_CPU_NAME alone compiles for the named CPU with every feature of the host (AVX-512
    # too): the record must not call that the named CPU's code
    from numba.core import config

    monkeypatch.setattr(config, "CPU_NAME", name)
    monkeypatch.setattr(config, "CPU_FEATURES", features)
    assert numba_target() == reported
