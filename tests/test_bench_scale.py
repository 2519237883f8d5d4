"""``microsim bench --scale`` (``microsim.app.bench_scale``): per tile size a fresh process's
build, first call, marginal rate and peak memory; a size the machine cannot hold is skipped
with the reason, not run; the command's refusals."""

from __future__ import annotations

import json

import pytest

from microsim.app import bench_scale
from microsim.app.cli import main
from microsim.sim.facet_tables import table_pays


def _cli(capsys, *args):
    capsys.readouterr()
    status = main([str(a) for a in args])
    out, err = capsys.readouterr()
    return status, out, err.strip().splitlines()


def test_a_size_that_does_not_fit_is_skipped_with_its_need(monkeypatch):
    """No process is started for a tile whose expected peak exceeds the available memory."""
    monkeypatch.setattr(bench_scale, "available_mb", lambda: 1024.0)
    monkeypatch.setattr(bench_scale, "_probe", lambda *a: pytest.fail("probed a size too big"))
    (row,) = bench_scale.scale_rows(sizes=(4096,))
    need = f"{bench_scale.BYTES_PER_POINT_GUESS * 4096**2 / 2**30:.1f} GB"
    assert row.skipped and need in row.skipped and "1.0 GB available" in row.skipped
    assert "skipped: needs" in bench_scale.format_scale([row])


def test_a_size_whose_probe_fails_is_listed_with_the_failure(monkeypatch):
    """The surface's own refusal (or any failure) of one size ends that row, not the table."""
    refusal = "microsim.errors.UsageError: n: a 64x64 heightfield would need too much memory"
    monkeypatch.setattr(bench_scale, "_PROBE", f"import sys; sys.exit({refusal!r})")
    (row,) = bench_scale.scale_rows(sizes=(64,))
    assert row.skipped == f"the probe failed with status 1: {refusal}"
    assert f"| 64² | skipped: {row.skipped} |" in bench_scale.format_scale([row])


def test_both_ray_counts_of_a_size_take_one_path():
    """A marginal rate is a line through two calls: never one per ray and one through the
    facet table (rays ≥ the tile's 2n² facets, ``facet_tables.uses_facet_table``)."""
    for n in (64, 128, 512, 1024, 2048, 4096, 8192):
        for rays in (bench_scale.RAYS, bench_scale.QUICK_RAYS):
            (lo, hi), path = bench_scale.rays_for(n, rays)
            table = [r >= 2 * n * n for r in (lo, hi)]
            assert table[0] == table[1] and path == bench_scale.PATHS[0 if table[0] else 1]
            assert 0 < lo < hi
    assert bench_scale.rays_for(1024, (2**20, 2**22)) == ((2**18, 2**20), "per ray")
    for n in (64, 512, 1024, 2048, 4096):  # the table's counts: one and two rays per facet
        facets = 2 * n * n
        assert bench_scale.tabled_rays(n) == (facets, 2 * facets)
        assert all(table_pays(facets, r) for r in bench_scale.tabled_rays(n))
    assert bench_scale.tabled_rays(8192) is None  # more facets than a table is built for
    assert not table_pays(2 * 8192**2, 2 * 8192**2)


def test_each_size_is_measured_on_both_paths_where_it_can_take_both(monkeypatch):
    """A size traced per ray at ``RAYS`` gets a row through the facet table (where its tile
    can have one) and a tabled size a row per ray, so that each path is compared with itself
    across sizes; a table row that would not fit is skipped with the table's own need."""
    probed = []

    def probe(cfg, n, rays, min_seconds):
        probed.append((n, tuple(rays)))
        path = bench_scale.rays_for(n, rays)[1]
        return bench_scale.ScaleRow(n, 0.1, 0.1, 0.0, 1e6, 300.0, 200.0, 250.0, rays, path)

    monkeypatch.setattr(bench_scale, "_probe", probe)
    monkeypatch.setattr(bench_scale, "available_mb", lambda: 1e6)
    rows = bench_scale.scale_rows(sizes=(512, 4096, 8192))
    assert probed == [
        (512, bench_scale.RAYS),
        (512, bench_scale.per_ray_rays(512)),
        (4096, bench_scale.RAYS),
        (4096, bench_scale.tabled_rays(4096)),
        (8192, bench_scale.RAYS),
    ]
    assert [r.path for r in rows] == ["facet table", "per ray", "per ray", "facet table", "per ray"]
    probed.clear()
    room = 200.0 + 300 * 4096**2 / 2**20  # the per-ray run fits, the table's 100 B/point not
    monkeypatch.setattr(bench_scale, "available_mb", lambda: room / 0.9)
    monkeypatch.setattr(bench_scale, "BYTES_PER_POINT_GUESS", 300.0)
    rows = bench_scale.scale_rows(sizes=(4096,))
    assert probed == [(4096, bench_scale.RAYS)]
    assert rows[1].skipped.startswith("needs ~") and "through the facet table" in rows[1].skipped


def test_scale_refuses_ray_options(capsys):
    status, out, err = _cli(capsys, "bench", "--scale", "--rays", "1000")
    assert status == 2 and out == "" and len(err) == 1 and "--rays" in err[0]


@pytest.mark.slow  # two fresh processes (~7 s)
def test_the_quick_scale_table_measures_each_size(capsys):
    status, out, err = _cli(capsys, "bench", "--scale", "--quick", "--json")
    assert status == 0, err
    rows = json.loads(out)["rows"]
    assert sorted({r["n"] for r in rows}) == list(bench_scale.QUICK_SIZES)
    assert {r["path"] for r in rows} == {"facet table"}  # more rays than facets, both sizes
    for r in rows:
        assert r["skipped"] is None and r["samples_per_s"] > 0 and r["path"] in bench_scale.PATHS
        assert r["rss_mb"] >= r["build_rss_mb"] >= r["base_mb"] > 0 and r["first_seconds"] > 0
