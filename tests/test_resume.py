"""Interrupt and resume (microsim.sim.simulate(..., resume=)): an interrupted run returns the
complete blocks as a partial Result; resuming it — also after save/load — gives tallies
bitwise identical to an uninterrupted run; mismatched configurations are refused."""

import os
import signal

import numpy as np
import pytest
from support import heightfield_surface, random_heights, vgroove_surface

from microsim.checkpoints import interrupt_at
from microsim.sim import BLOCK, LEDGER, Bins, Result, simulate

THETA = [20.0, 70.0]
KW = dict(rays=7 * BLOCK + 321, bins=Bins(10, 7), seed=4)  # not a whole number of blocks
FIELDS = ("sum_w", "sum_w2", "counts", "brdf", "stderr", "rays")


def surface():
    return heightfield_surface(random_heights(sigma=0.02, seed=3), 1 / 32)


def assert_identical(a: Result, b: Result):
    for name in FIELDS:
        assert np.array_equal(getattr(a, name), getattr(b, name), equal_nan=True), name
    for k in a.ledger:
        assert np.array_equal(a.ledger[k], b.ledger[k]), k
    for k in a.ledger_counts:
        assert np.array_equal(a.ledger_counts[k], b.ledger_counts[k]), k
    for k in a.tallies:
        assert np.array_equal(a.tallies[k], b.tallies[k]), k


@pytest.mark.parametrize("threads", [1, 2])
def test_interrupted_run_is_partial_and_resumes_bitwise(tmp_path, threads):
    s = surface()
    full = simulate(s, "aluminium", THETA, threads=threads, chunk=BLOCK, **KW)
    assert not full.is_partial and np.all(full.rays == KW["rays"])
    with interrupt_at("simulation", after=3) as hit:  # after 4 of the first incidence's 8
        part = simulate(s, "aluminium", THETA, threads=threads, chunk=BLOCK, **KW)
    assert hit["fired"]
    assert part.is_partial and part.meta["interrupted"]
    assert 0 < part.rays[0] < KW["rays"] and part.rays[0] % BLOCK == 0  # whole blocks only
    assert part.rays[1] == 0 and np.all(np.isnan(part.brdf[1]))  # not started
    led = sum(part.ledger_counts[k] for k in LEDGER)
    assert np.array_equal(led, part.rays)  # the ledger closes on done blocks
    assert 0 < part.counts[0].sum() <= part.ledger_counts["single"][0]
    part.save(tmp_path)
    back = Result.load(tmp_path)
    assert back.is_partial
    resumed = simulate(
        s, "aluminium", THETA, threads=3 - threads, chunk=3 * BLOCK, resume=back, **KW
    )
    assert not resumed.is_partial and resumed.meta["resumed"]
    assert resumed.meta["rays_traced"] == 2 * KW["rays"] - part.rays.sum()
    assert_identical(full, resumed)


def test_sigint_stops_after_the_chunk_in_flight_and_restores_the_handler():
    s = vgroove_surface([20.0, 35.0, 50.0, 10.0] * 8)
    full = simulate(s, "aluminium", THETA, chunk=BLOCK, **KW)
    before = signal.getsignal(signal.SIGINT)
    seen = []

    def sigint_at_third_chunk(event):  # a real SIGINT, mid-incidence
        seen.append(event)
        if len(seen) == 3:
            os.kill(os.getpid(), signal.SIGINT)

    part = simulate(
        s,
        "aluminium",
        THETA,
        threads=1,
        chunk=BLOCK,  # returns, no raise
        progress=sigint_at_third_chunk,
        **KW,
    )
    assert signal.getsignal(signal.SIGINT) is before
    assert part.is_partial and part.rays.sum() < 2 * KW["rays"]
    resumed = simulate(s, "aluminium", THETA, resume=part, **KW)
    assert_identical(full, resumed)


def test_realisations_interrupted_between_surfaces_resume_bitwise():
    make = lambda seed: heightfield_surface(random_heights(sigma=0.02, seed=seed), 1 / 32)  # noqa: E731
    kw = dict(KW, rays=3 * 2 * BLOCK + 5)
    full = simulate(None, "aluminium", THETA, surface_factory=make, seeds=[1, 2, 3], **kw)

    def flaky(seed):  # Ctrl-C while building realisation 2
        if seed == 2:
            raise KeyboardInterrupt
        return make(seed)

    part = simulate(None, "aluminium", THETA, surface_factory=flaky, seeds=[1, 2, 3], **kw)
    assert part.is_partial
    assert np.array_equal(part.tallies["rays"][:, 0], [full.rays_realisations[0], 0, 0])
    assert part.meta["realisations"][1] is None
    resumed = simulate(
        None, "aluminium", THETA, surface_factory=make, seeds=[1, 2, 3], resume=part, **kw
    )
    assert_identical(full, resumed)
    for name in ("stderr_ray", "stderr_realisation", "brdf_realisations"):
        assert np.array_equal(getattr(full, name), getattr(resumed, name)), name


def test_a_run_of_the_first_realisations_is_extended_bitwise():
    """A complete 2-realisation run, resumed as the first 2 of 4 with the same rays per
    realisation, traces only realisations 2 and 3 and equals the 4-realisation run bitwise;
    a prefix with other rays per realisation, or an uneven split, is refused."""
    make = lambda seed: heightfield_surface(random_heights(sigma=0.02, seed=seed), 1 / 32)  # noqa: E731
    per = 2 * BLOCK
    kw = {k: v for k, v in KW.items() if k != "rays"}
    full = simulate(
        None, "aluminium", THETA, surface_factory=make, seeds=[1, 2, 3, 4], rays=4 * per, **kw
    )
    pilot = simulate(
        None, "aluminium", THETA, surface_factory=make, seeds=[1, 2], rays=2 * per, **kw
    )
    more = simulate(
        None,
        "aluminium",
        THETA,
        surface_factory=make,
        seeds=[1, 2, 3, 4],
        rays=4 * per,
        resume=pilot,
        **kw,
    )
    assert more.meta["rays_traced"] == 2 * per * len(THETA)
    assert_identical(full, more)
    for name in ("stderr_ray", "stderr_realisation", "brdf_realisations"):
        assert np.array_equal(getattr(full, name), getattr(more, name)), name
    for rays in (4 * per + 2, 3 * per):  # uneven, or other rays per realisation
        with pytest.raises(ValueError, match="rays"):
            simulate(
                None,
                "aluminium",
                THETA,
                surface_factory=make,
                seeds=[1, 2, 3, 4],
                rays=rays,
                resume=pilot,
                **kw,
            )


def test_resuming_a_complete_run_traces_nothing():
    s = surface()
    full = simulate(s, "aluminium", THETA, **KW)
    again = simulate(s, "aluminium", THETA, resume=full, **KW)
    assert again.meta["rays_traced"] == 0
    assert_identical(full, again)


@pytest.mark.parametrize(
    "change, word",
    [
        (dict(seed=5), "seed"),
        (dict(theta_i=[20.0, 60.0]), "theta_i"),
        (dict(phi_i=10.0), "phi_i"),
        (dict(bins=Bins(10, 9)), "bins"),
        (dict(rays=KW["rays"] + 1), "rays"),
        (dict(material="methanol"), "material"),
        (dict(origins="independent"), "origins"),
        (dict(surface=vgroove_surface([30.0] * 4)), "surface"),
    ],
)
def test_resume_with_a_different_configuration_is_refused(change, word):
    s = surface()
    with interrupt_at("simulation", after=1):
        part = simulate(s, "aluminium", THETA, **KW)
    assert part.is_partial
    args = {**KW, "surface": s, "material": "aluminium", "theta_i": THETA, **change}
    with pytest.raises(ValueError, match=word):
        simulate(resume=part, **args)


def test_resume_needs_a_result():
    with pytest.raises(ValueError, match="resume"):
        simulate(surface(), None, 30.0, rays=10, resume={"rays": 10})
