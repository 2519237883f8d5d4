"""Fault corpus of the Python API: every bad input is refused up front with a
``UsageError`` (a ``ValueError``) whose one-line message names the parameter; a run of any
size stops promptly on an interrupt with bounded memory; progress arrives per chunk of rays.

Each case asserts a behaviour (the exception type, the parameter named in the message, a
partial result within a time and memory bound), never a number copied from output."""

import math
import os
import signal
import threading
import time
import tracemalloc
from contextlib import contextmanager

import numpy as np
import pytest
from support import heightfield_surface, random_heights

from microsim import analytic as an
from microsim import checks as _checks
from microsim import vectors
from microsim.analytic.fresnel import fresnel_real_arithmetic
from microsim.checkpoints import interrupt_at
from microsim.errors import UsageError
from microsim.sim import BLOCK, Bins, RaysDone, ray_events, simulate
from microsim.sim.auto import simulate_auto
from microsim.surfaces import abc, flat, from_file, gaussian, vgrooves
from microsim.surfaces.loader import check_heightfield_file, read_heights

FLAT = flat()
SMALL = dict(rays=2 * BLOCK, bins=Bins(6, 4))


@contextmanager
def deadline(seconds: float):
    """Fail (instead of hanging) if the block runs longer than ``seconds`` (SIGALRM)."""

    def fire(signum, frame):
        raise TimeoutError(f"still running after {seconds} s")

    old = signal.signal(signal.SIGALRM, fire)
    signal.setitimer(signal.ITIMER_REAL, seconds)
    try:
        yield
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, old)


def refused(call, word):
    """``call()`` raises a one-line UsageError naming ``word``."""
    with deadline(30):
        with pytest.raises(UsageError) as info:
            call()
    msg = str(info.value)
    assert isinstance(info.value, ValueError)
    assert word in msg, msg
    assert "\n" not in msg, msg
    return msg


# --- simulate / ray_events / simulate_auto: argument corpus -----------------------------------
def sim(**kw):
    args = dict(surface=FLAT, material="aluminium", theta_i=30.0, **SMALL)
    args.update(kw)
    return lambda: simulate(**args)


SIMULATE_CASES = [
    (sim(rays="1000"), "rays"),
    (sim(rays=1.5), "rays"),
    (sim(rays=0), "rays"),
    (sim(rays=-4096), "rays"),
    (sim(rays=math.nan), "rays"),
    (sim(rays=math.inf), "rays"),
    (sim(rays=True), "rays"),
    (sim(rays=None), "rays"),
    (sim(rays=10**30), "rays"),
    (sim(surface="vgrooves"), "surface"),
    (sim(surface=None), "surface"),
    (sim(surface=42), "surface"),
    (sim(surface=np.zeros((8, 8))), "surface"),
    (sim(seed=1.5), "seed"),
    (sim(seed=-1), "seed"),
    (sim(seed="0"), "seed"),
    (sim(seed=None), "seed"),
    (sim(seed=math.nan), "seed"),
    (sim(theta_i=[10.0, 20.0], phi_i=[0.0, 10.0, 20.0]), "phi_i"),
    (sim(theta_i=[10.0, 20.0, 30.0], phi_i=[0.0, 10.0]), "phi_i"),
    (sim(phi_i=[[0.0]]), "phi_i"),
    (sim(phi_i=math.nan), "phi_i"),
    (sim(phi_i=math.inf), "phi_i"),
    (sim(phi_i="north"), "phi_i"),
    (sim(phi_i=None), "phi_i"),
    (sim(theta_i=math.nan), "theta_i"),
    (sim(theta_i=math.inf), "theta_i"),
    (sim(theta_i=90.0), "theta_i"),
    (sim(theta_i=95.0), "theta_i"),
    (sim(theta_i=-1.0), "theta_i"),
    (sim(theta_i=[]), "theta_i"),
    (sim(theta_i="thirty"), "theta_i"),
    (sim(theta_i=[[10.0]]), "theta_i"),
    (sim(theta_i=None), "theta_i"),
    (sim(threads=1.5), "threads"),
    (sim(threads="2"), "threads"),
    (sim(threads=0), "threads"),
    (sim(threads=math.nan), "threads"),
    (sim(threads=10**6), "threads"),
    (sim(chunk=1.5), "chunk"),
    (sim(chunk="65536"), "chunk"),
    (sim(chunk=0), "chunk"),
    (sim(chunk=10**12), "chunk"),
    (sim(bins=(45, 37)), "bins"),
    (sim(bins=None), "bins"),
    (sim(material="unobtainium"), "material"),
    (sim(material=-1.0), "material"),
    (sim(material=[1.5]), "material"),
    (sim(masking="bogus"), "masking"),
    (sim(masking="analytic"), "masking"),
    (sim(origins="grid"), "origins"),
    (sim(isotropic="yes"), "isotropic"),
    (sim(progress=5), "progress"),
    (sim(resume={"rays": 10}), "resume"),
    (sim(surface=None, realisations=[]), "realisations"),
    (sim(surface=None, realisations=["vgrooves"]), "realisations"),
    (sim(surface=None, realisations=(lambda s: FLAT, [1, 2])), "surface_factory"),
    (sim(surface=None, surface_factory=lambda s: "not a surface", seeds=[1, 2]), "surface_factory"),
    (sim(surface=None, surface_factory=lambda s: FLAT, seeds=[]), "seeds"),
    (sim(surface=None, surface_factory=lambda s: FLAT, seeds=[1.5]), "seeds"),
    (sim(surface=None, surface_factory=lambda s: FLAT, seeds=7), "seeds"),
    (
        sim(surface=None, surface_factory=lambda s: FLAT, seeds=[1, 2], realisations=3),
        "realisations",
    ),
    (sim(surface=None, surface_factory=lambda s: FLAT, realisations=0), "realisations"),
    (sim(surface=None, surface_factory=lambda s: FLAT, realisations=2.5), "realisations"),
    (sim(surface=None, surface_factory=lambda s: FLAT, realisations=[FLAT]), "realisations"),
    (sim(surface=None, surface_factory="flat"), "surface_factory"),
    (sim(surface_factory=lambda s: FLAT, realisations=2), "surface"),
    (sim(seeds=[1, 2]), "seeds"),
    (sim(realisations=[flat(), FLAT]), "surface"),
    (sim(surface=None, realisations=5), "realisations"),
    (sim(rays=1, surface=None, realisations=[FLAT, FLAT]), "rays"),
]


@pytest.mark.parametrize("call, word", SIMULATE_CASES)
def test_simulate_refuses_bad_input(call, word):
    refused(call, word)


def events(**kw):
    args = dict(surface=FLAT, material="aluminium", theta_i=30.0, rays=1000)
    args.update(kw)
    return lambda: ray_events(**args)


RAY_EVENTS_CASES = [
    (events(rays="1000"), "rays"),
    (events(rays=2.5), "rays"),
    (events(rays=0), "rays"),
    (events(rays=10**12), "rays"),  # per-ray output: refused by its memory
    (events(surface="vgrooves"), "surface"),
    (events(seed=1.5), "seed"),
    (events(seed=-3), "seed"),
    (events(theta_i=[10.0, 20.0]), "theta_i"),
    (events(theta_i=90.0), "theta_i"),
    (events(theta_i=math.nan), "theta_i"),
    (events(phi_i=[0.0, 1.0]), "phi_i"),
    (events(phi_i=math.nan), "phi_i"),
    (events(material="gold"), "material"),
    (events(masking="exact"), "masking"),
]


@pytest.mark.parametrize("call, word", RAY_EVENTS_CASES)
def test_ray_events_refuses_bad_input(call, word):
    refused(call, word)


def auto(**kw):
    args = dict(
        surface=FLAT,
        material="aluminium",
        theta_i=30.0,
        first=BLOCK,
        max_rays=BLOCK,
        bins=Bins(6, 4),
    )
    args.update(kw)
    return lambda: simulate_auto(**args)


AUTO_CASES = [
    (auto(surface="vgrooves"), "surface"),
    (auto(theta_i="thirty"), "theta_i"),
    (auto(theta_i=95.0), "theta_i"),
    (auto(theta_i=[10.0, 20.0], phi_i=[0.0, 1.0, 2.0]), "phi_i"),
    (auto(phi_i=math.nan), "phi_i"),
    (auto(target=0.0), "target"),
    (auto(target="1%"), "target"),
    (auto(target=math.nan), "target"),
    (auto(first=1.5), "first"),
    (auto(first="8"), "first"),
    (auto(max_rays="1e9"), "max_rays"),
    (auto(max_rays=10**30), "max_rays"),
    (auto(energy="most"), "energy"),
    (auto(energy=math.nan), "energy"),
    (auto(min_events=-1), "min_events"),
    (auto(bins=(45, 37)), "bins"),
    (auto(seed=1.5), "seed"),
    (auto(seed=-1), "seed"),
    (auto(threads=1.5), "threads"),
    (auto(chunk="big"), "chunk"),
    (auto(material="gold"), "material"),
    (auto(masking="bogus"), "masking"),
    (auto(origins="grid"), "origins"),
    (auto(progress=3), "progress"),
    (auto(threads=0), "threads"),
    (auto(threads="all"), "threads"),
]


@pytest.mark.parametrize("call, word", AUTO_CASES)
def test_simulate_auto_refuses_bad_input(call, word):
    refused(call, word)


# --- bins, fresnel, surfaces ------------------------------------------------------------------
BINS_CASES = [
    (lambda: Bins(10**6), "n_theta"),
    (lambda: Bins(10, 10**7), "n_phi"),
    (lambda: Bins(0), "n_theta"),
    (lambda: Bins(2.5), "n_theta"),
    (lambda: Bins("45"), "n_theta"),
    (lambda: Bins(math.nan), "n_theta"),
    (lambda: Bins(None), "n_theta"),
    (lambda: Bins(45, math.inf), "n_phi"),
    (lambda: Bins(45, 1), "n_phi"),
    (lambda: Bins(45, 7, folded=False), "n_phi"),
    (lambda: Bins(45, 8, folded="no"), "folded"),
]


@pytest.mark.parametrize("call, word", BINS_CASES)
def test_bins_refuse_bad_input(call, word):
    refused(call, word)


def test_bins_cap_states_the_limit_and_why():
    msg = refused(lambda: Bins(10**6), "n_theta")
    assert "limit" in msg and "bytes" in msg


FRESNEL_CASES = [
    (lambda: an.fresnel(2.0, 1.5), "cos_theta"),
    (lambda: an.fresnel(-0.5, 1.5), "cos_theta"),
    (lambda: an.fresnel([0.2, 1.01], "aluminium"), "cos_theta"),
    (lambda: an.fresnel(-1e-3, None), "cos_theta"),
    (lambda: an.fresnel(math.inf, 1.5), "cos_theta"),
    (lambda: an.fresnel(math.nan, 1.5), "cos_theta"),
    (lambda: an.fresnel("0.5", 1.5), "cos_theta"),
    (lambda: an.fresnel_transmittance(2.0, 1.5), "cos_theta"),
    (lambda: an.schlick(2.0, 0.04), "cos_theta"),
    (lambda: an.schlick(-0.5, 0.04), "cos_theta"),
    (lambda: fresnel_real_arithmetic(2.0, 1.5), "cos_theta"),
    (lambda: fresnel_real_arithmetic(np.array([0.5, -0.5]), 0.77 + 6.1j), "cos_theta"),
]


@pytest.mark.parametrize("call, word", FRESNEL_CASES)
def test_fresnel_refuses_cosines_outside_the_unit_interval(call, word):
    msg = refused(call, word)
    assert "[0, 1]" in msg


def test_fresnel_accepts_rounding_above_one_and_at_zero():
    """A cosine of two vectors that ``microsim.checks.directions`` accepts as unit may exceed 1 by
    2·UNIT_TOL (|a·b| ≤ |a||b|): clipped, not refused."""
    c = np.array([0.0, 1.0, 1.0 + 2 * _checks.UNIT_TOL, -_checks.UNIT_TOL])
    r = an.fresnel(c, "aluminium")
    assert np.all(np.isfinite(r)) and r[0] == 1.0 and r[1] == r[2] and r[3] == 1.0


def test_fresnel_callers_stay_in_range():
    """The analytic models feed fresnel only cosines in range (else they would now raise),
    also for directions only unit within ``microsim.checks.UNIT_TOL``."""
    wi = vectors.spherical_deg(np.array([0.0, 45.0, 89.9]), 0.0)
    wo = vectors.spherical_deg(np.array([0.0, 60.0, 89.9]), np.array([180.0, 90.0, 0.0]))
    for scale in (1.0, 1.0 + 0.9 * _checks.UNIT_TOL):
        for kind in ("smith", "vgroove"):
            val = an.torrance_sparrow(
                wi * scale, wo * scale, an.Beckmann(0.3), shadowing=kind, material="aluminium"
            )
            assert np.all(np.isfinite(val))


SURFACE_CASES = [
    (lambda: vgrooves(10**8, an.Beckmann(0.3)), "n_grooves"),
    (lambda: gaussian(100_000, 1.0, 1.0, 8.0), "n"),
    (lambda: abc(100_000, 1.0, 1.0, 8.0, 4.0), "n"),
    (lambda: gaussian(64, 1.0, 1.0, 1e-9), "corr_len"),
    (lambda: gaussian(64, 1.0, 1.0, 0.5), "corr_len"),
    (lambda: gaussian(64, 1.0, 1e200, 8.0), "sigma"),
    (lambda: abc(64, 1.0, 1e200, 8.0, 4.0), "sigma"),
    (lambda: gaussian(64.5, 1.0, 1.0, 8.0), "n"),
    (lambda: gaussian("64", 1.0, 1.0, 8.0), "n"),
    (lambda: gaussian(64, 1.0, 1.0, 8.0, seed=1.5), "seed"),
    (lambda: vgrooves(100, an.Beckmann(0.3), seed="x"), "seed"),
    (lambda: vgrooves("100", an.Beckmann(0.3)), "n_grooves"),
    (lambda: vgrooves(100, "beckmann"), "ndf"),
    (lambda: vgrooves(100, an.Beckmann(0.3), sampling="sobol"), "sampling"),
]


@pytest.mark.parametrize("call, word", SURFACE_CASES)
def test_surface_generators_refuse_bad_input(call, word):
    refused(call, word)


@pytest.mark.parametrize(
    "call", [lambda: vgrooves(10**8, an.Beckmann(0.3)), lambda: gaussian(100_000, 1.0, 1.0, 8.0)]
)
def test_oversized_surfaces_state_memory_and_limit_before_allocating(call):
    tracemalloc.start()
    try:
        msg = refused(call, "memory")
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert "GB" in msg and "limit" in msg
    assert peak < 50 << 20  # refused before any large allocation


@pytest.mark.parametrize("ell", [1.0, 1.5, 3.0])
def test_gaussian_short_corr_len_warning_states_the_realised_m(ell):
    """Below 7·dx the warning's "realised m" is the mesh's own √(var_x + var_y)."""
    with pytest.warns(UserWarning, match="corr_len") as rec:
        s = gaussian(128, 1.0, 0.3, ell, seed=1)
    text = str(rec[0].message)
    stated = float(text.split("realised m ")[1].split()[0])
    st = s.stats()
    assert stated == pytest.approx(st["m_realised"], rel=0.01)
    assert st["predicted_m"] == pytest.approx(st["m_realised"], rel=0.01)


# --- heightfield files ------------------------------------------------------------------------
def heightfile(tmp_path, kind):
    p = tmp_path / "h.npy"
    good = np.random.default_rng(0).normal(size=(16, 16))
    if kind == "text-as-npy":
        p.write_text("1 2 3\n4 5 6\n")
    elif kind == "empty":
        p.write_bytes(b"")
    elif kind == "truncated":
        np.save(p, good)
        p.write_bytes(p.read_bytes()[:-100])
    elif kind == "1d":
        np.save(p, good.ravel())
    elif kind == "3d":
        np.save(p, good[None])
    elif kind == "small":
        np.save(p, good[:4, :4])
    elif kind == "nan":
        good[3, 3] = np.nan
        np.save(p, good)
    elif kind == "complex":
        np.save(p, good + 1j)
    elif kind == "object":
        np.save(p, np.array([[None] * 8] * 8, dtype=object), allow_pickle=True)
    elif kind == "huge":  # a header promising 10^5 x 10^5 floats
        with open(p, "wb") as f:
            np.lib.format.write_array_header_1_0(
                f, {"descr": "<f8", "fortran_order": False, "shape": (100_000, 100_000)}
            )
            f.truncate(f.tell() + 8 * 100_000 * 100_000)  # sparse: no disk used
    elif kind == "directory":
        p.mkdir()
    elif kind == "missing":
        pass
    elif kind == "npz-bomb":
        p = tmp_path / "h.npz"
        np.savez_compressed(p, heights=np.zeros((2048, 2048), dtype=np.float32))
    elif kind == "text-garbage":
        p = tmp_path / "h.txt"
        p.write_bytes(b"\xff\xfe garbage \x00\x01")
    return p


FILE_KINDS = [
    "text-as-npy",
    "empty",
    "truncated",
    "1d",
    "3d",
    "small",
    "nan",
    "complex",
    "object",
    "huge",
    "directory",
    "missing",
    "text-garbage",
]


@pytest.mark.parametrize("kind", FILE_KINDS)
def test_heightfield_file_problems_are_one_line_naming_the_file(tmp_path, kind):
    p = heightfile(tmp_path, kind)
    for call in (
        lambda: check_heightfield_file(p, 1.0),
        lambda: read_heights(p),
        lambda: from_file(p, 1.0),
    ):
        refused(call, str(p))


def test_heightfield_file_bomb_refused_by_its_memory(tmp_path, monkeypatch):
    """A small compressed .npz that would inflate past the memory limit is refused from its
    header (the limit lowered to 256 MiB so that the test is the same on any machine: the
    mirrored 4094² grid would need ~3 GB)."""
    monkeypatch.setattr(_checks, "memory_limit", lambda: 256 << 20)
    p = heightfile(tmp_path, "npz-bomb")
    tracemalloc.start()
    try:
        msg = refused(lambda: check_heightfield_file(p, 1.0), str(p))
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert "memory" in msg and peak < 50 << 20


def test_heightfield_file_check_accepts_a_good_file_and_names_dx(tmp_path):
    p = tmp_path / "h.npy"
    np.save(p, np.random.default_rng(0).normal(size=(16, 12)))
    assert check_heightfield_file(p, 0.5) == (16, 12)
    refused(lambda: check_heightfield_file(p, -1.0), "dx")
    refused(lambda: check_heightfield_file(p, math.nan), "dx")


# --- interrupts and memory at any ray count ---------------------------------------------------
def rough():
    return heightfield_surface(random_heights(n=32, sigma=0.02, seed=3), 1 / 32)


def test_interrupt_after_the_first_chunk_of_a_huge_run_is_prompt_and_bounded():
    s = rough()
    simulate(s, "aluminium", 30.0, rays=BLOCK, bins=Bins(6, 4))  # compile/warm up
    tracemalloc.start()
    t0 = time.perf_counter()
    try:
        with deadline(60), interrupt_at("simulation") as hit:
            res = simulate(s, "aluminium", [30.0, 60.0], rays=10**12, bins=Bins(6, 4))
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    seconds = time.perf_counter() - t0
    assert hit["fired"] and res.is_partial and res.meta["interrupted"]
    assert 0 < res.rays[0] < 10**12 and res.rays[1] == 0
    assert seconds < 5, seconds
    assert peak < 64 << 20, peak  # 10^12 rays' worth of anything would be ≫ 1 GB


def test_sigint_stops_a_huge_run_within_a_second():
    s = rough()
    simulate(s, "aluminium", 30.0, rays=BLOCK, bins=Bins(6, 4))
    timer = threading.Timer(0.5, os.kill, (os.getpid(), signal.SIGINT))
    t0 = time.perf_counter()
    timer.start()
    try:
        with deadline(60):
            res = simulate(s, "aluminium", 30.0, rays=10**12, bins=Bins(6, 4))
    finally:
        timer.cancel()
    assert res.is_partial and res.meta["interrupted"]
    assert time.perf_counter() - t0 < 1.5 + 0.5


def test_simulate_auto_honours_the_simulation_checkpoint():
    with deadline(60), interrupt_at("simulation") as hit:
        with pytest.raises(KeyboardInterrupt):
            simulate_auto(
                rough(),
                "aluminium",
                30.0,
                target=1e-6,
                first=4 * BLOCK,
                max_rays=10**12,
                bins=Bins(6, 4),
            )
    assert hit["fired"]


# --- structured progress ----------------------------------------------------------------------
def test_rays_done_events_sum_to_the_rays_of_each_pair_and_arrive_per_chunk():
    make = lambda seed: heightfield_surface(random_heights(n=16, sigma=0.02, seed=seed), 1 / 16)  # noqa: E731
    rays = 2 * (5 * BLOCK) + 7  # realisation 0 gets one ray more (odd total)
    got = []
    res = simulate(
        None,
        "aluminium",
        [20.0, 70.0],
        rays=rays,
        bins=Bins(6, 4),
        chunk=BLOCK,
        threads=2,
        surface_factory=make,
        seeds=[1, 2],
        progress=got.append,
    )
    assert not res.is_partial and all(isinstance(e, RaysDone) for e in got)
    for r in range(2):
        for i, th in enumerate([20.0, 70.0]):
            mine = [e for e in got if (e.realisation, e.incidence) == (r, i)]
            assert len(mine) > 1  # per chunk
            assert sum(e.rays for e in mine) == res.tallies["rays"][r, i]
            assert [e.finished for e in mine] == [False] * (len(mine) - 1) + [True]
            assert all(e.realisations == 2 and e.theta_i == th and e.rays > 0 for e in mine)
    assert sum(e.rays for e in got) == 2 * rays


def test_interrupt_from_progress_keeps_the_chunks_tallied():
    s = rough()
    seen = []

    def progress(ev):
        seen.append(ev)
        if len(seen) == 2:
            raise KeyboardInterrupt

    res = simulate(
        s, "aluminium", 30.0, rays=8 * BLOCK, bins=Bins(6, 4), chunk=BLOCK, progress=progress
    )
    assert res.is_partial and res.rays[0] == sum(e.rays for e in seen) == 2 * BLOCK
