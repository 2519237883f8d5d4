"""What ``microsim.testing`` keeps in its cache besides the references (``cache.derived``):
a V-groove tile's departure from its ensemble and the bin averages of catalogue and physics
models, which the surfaces, material, incidences and bins alone determine. A new process
reads them instead of computing them again (the test clears the in-process copies to act as
one); what it reads equals what it would compute, bitwise; another input (material, bins,
incidence, model, microsim's source) is another entry, rays and seed are not;
a damaged entry is reported, discarded and computed again.

References are tiny (200 GGX V-grooves, 2·10⁴ rays, one incidence, 9 × 10 bins)."""

import shutil

import numpy as np
import pytest

from microsim.analytic import GGX
from microsim.errors import UsageError
from microsim.surfaces import vgrooves
from microsim.testing import BRDFMismatch, assert_brdf_agrees, reference
from microsim.testing import agreement as agreement_mod
from microsim.testing import cache as cache_mod

AL = "aluminium"
TINY = dict(rays=20_000, bins=(9, 10))


@pytest.fixture(scope="module")
def surface():
    return vgrooves(200, GGX(0.3))


@pytest.fixture(scope="module")
def warm(surface, tmp_path_factory):
    """A cache holding the reference and the derived entries of one ts-smith-corr check, and
    that check's Agreement."""
    root = tmp_path_factory.mktemp("warm")
    return root, _check("ts-smith-corr", surface, root)


@pytest.fixture
def copy(warm, tmp_path):
    """A copy of the warm cache (the test may change it)."""
    shutil.copytree(warm[0], tmp_path / "cache")
    return tmp_path / "cache"


@pytest.fixture
def fresh_process(monkeypatch):
    """Forget what this process computed, as a new process would; count the computations of
    derived quantities (a list of the ``what`` of each)."""
    monkeypatch.setattr(cache_mod, "_DERIVED", {})
    computed = []
    original = cache_mod._derived_value

    def counted(text, shape, compute, cache):
        def compute_counted():
            computed.append(text)
            return compute()

        return original(text, shape, compute_counted, cache)

    monkeypatch.setattr(cache_mod, "_derived_value", counted)
    return computed


def _check(brdf, surface, cache, **kw):
    """The Agreement of ``assert_brdf_agrees`` (passed or not) at θi = 30°."""
    kw = {"material": AL, "theta_i": [30], **TINY, **kw}
    try:
        return assert_brdf_agrees(brdf, surface, cache=cache, **kw)
    except BRDFMismatch as e:
        return e.agreement


def _numbers(out) -> tuple:
    return (out["model"].tobytes(), repr(out["verdicts"]), out["passed"])


def _entries(root):
    return sorted(p.name for p in (root / cache_mod.DERIVED_DIR).iterdir())


def test_a_new_process_reads_departure_and_model_and_gets_bitwise_the_same(
    surface, warm, copy, fresh_process
):
    assert len(_entries(copy)) == 2  # the tile's departure and the model's bin averages
    again = _check("ts-smith-corr", surface, copy)
    assert fresh_process == [], "the new process computed instead of reading the cache"
    assert _numbers(again) == _numbers(warm[1])


def test_the_cached_departure_and_model_equal_the_recomputed_ones(
    surface, warm, copy, fresh_process
):
    recomputed = _check("ts-smith-corr", surface, False)
    assert len(fresh_process) == 2
    assert _numbers(recomputed) == _numbers(warm[1])
    ref = cache_mod.resolve_reference(surface, AL, [30], **TINY)
    res = reference(surface, AL, [30], cache=copy, **TINY)
    computed = agreement_mod._one_tile_departure(ref, res, False)  # this process's
    cache_mod._DERIVED.clear()
    read = agreement_mod._one_tile_departure(ref, res, copy)
    assert len(fresh_process) == 2  # both read, not computed again
    assert read.shape == (1, 9, 10) and np.any(read != 0)
    assert read.tobytes() == computed.tobytes()


def test_a_callable_is_never_cached_but_its_departure_is(surface, warm, copy, fresh_process):
    before = _entries(copy)
    _check(lambda wi, wo: np.full(len(wi), 0.1), surface, copy)
    _check(lambda wi, wo: np.full(len(wi), 0.2), surface, copy)
    assert fresh_process == [] and _entries(copy) == before


@pytest.mark.parametrize(
    "change, new",
    [
        (dict(material=1.5), 2),
        pytest.param(dict(bins=(9, 12)), 2, marks=pytest.mark.slow),
        pytest.param(dict(theta_i=[40]), 2, marks=pytest.mark.slow),
        (dict(brdf="ts-smith"), 1),  # the model's bin averages only
    ],
)
def test_another_input_is_another_entry(surface, copy, fresh_process, change, new):
    before = _entries(copy)
    brdf = change.pop("brdf", "ts-smith-corr")
    _check(brdf, surface, copy, **change)
    after = _entries(copy)
    assert set(before) < set(after) and len(after) - len(before) == new == len(fresh_process)


def test_rays_and_seed_do_not_change_the_entries(surface, copy, fresh_process):
    before = _entries(copy)
    _check("ts-smith-corr", surface, copy, rays=30_000, seed=3)
    assert _entries(copy) == before and fresh_process == []


def test_a_damaged_entry_is_reported_discarded_and_computed_again(
    surface, warm, copy, fresh_process
):
    for name in _entries(copy):
        (copy / cache_mod.DERIVED_DIR / name).write_bytes(b"PK\x03\x04 cut short")
    with pytest.warns(UserWarning, match=r"derived/[0-9a-f]{24}\.npz.*computing it again"):
        again = _check("ts-smith-corr", surface, copy)
    assert len(fresh_process) == 2
    assert _numbers(again) == _numbers(warm[1])
    cache_mod._DERIVED.clear()
    _check("ts-smith-corr", surface, copy)  # repaired: read, not computed
    assert len(fresh_process) == 2


def test_an_entry_of_another_quantity_is_not_used(surface, warm, copy, fresh_process):
    a, b = (copy / cache_mod.DERIVED_DIR / n for n in _entries(copy))
    a_bytes, b_bytes = a.read_bytes(), b.read_bytes()
    a.write_bytes(b_bytes)
    b.write_bytes(a_bytes)
    with pytest.warns(UserWarning, match="made for another quantity"):
        again = _check("ts-smith-corr", surface, copy)
    assert _numbers(again) == _numbers(warm[1])


def test_an_unknown_model_name_is_still_refused(surface, copy, fresh_process):
    before = _entries(copy)
    with pytest.raises(UsageError, match="catalogue models ts-vgroove, ts-smith"):
        _check("ts-nonsense", surface, copy)
    assert _entries(copy) == before


def test_another_microsim_source_is_another_entry(surface, warm, copy, fresh_process, monkeypatch):
    monkeypatch.setattr(cache_mod, "source_digest", lambda: "0" * 24)
    again = _check("ts-smith-corr", surface, copy)
    assert len(fresh_process) == 2 and len(_entries(copy)) == 4
    assert _numbers(again) == _numbers(warm[1])
