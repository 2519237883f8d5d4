"""The run's three frozen descriptions: ``estimate(Experiment, Estimator, Execution)`` is
``simulate`` with its keyword arguments sorted into physics, estimator and execution; each
description checks its own fields, and execution options never change a number."""

import dataclasses

import numpy as np
import pytest

from microsim.analytic import Beckmann
from microsim.errors import UsageError
from microsim.sim import Bins, Estimator, Execution, Experiment, estimate, simulate
from microsim.sim.auto import Precision, estimate_to_precision, simulate_auto
from microsim.surfaces import vgrooves

SURFACE = vgrooves(200, Beckmann(0.3), seed=1)
BINS = Bins(9, 6)


def _same(a, b):
    for name in ("brdf", "stderr", "counts", "rays"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name))
    assert a.ledger.keys() == b.ledger.keys()
    for k in a.ledger:
        np.testing.assert_array_equal(a.ledger[k], b.ledger[k])


@pytest.mark.parametrize("bounces", [1, "all"])
def test_estimate_is_simulate(bounces):
    kw = dict(rays=40_000, bins=BINS, seed=3, masking="analytic", bounces=bounces)
    a = simulate(SURFACE, "aluminium", [20, 60], phi_i=10.0, threads=1, **kw)
    b = estimate(
        Experiment(SURFACE, "aluminium", (20, 60), 10.0, BINS, bounces),
        Estimator(rays=40_000, seed=3, masking="analytic"),
        Execution(threads=2, chunk=4096),
    )
    _same(a, b)
    assert b.meta["threads"] == 2 and a.meta["threads"] == 1


def test_realisations_through_the_experiment():
    factory = lambda s: vgrooves(100, Beckmann(0.3), seed=s)  # noqa: E731
    ex = Experiment(None, 1.5, 30, bins=BINS, surface_factory=factory, realisations=2)
    a = estimate(ex, Estimator(rays=20_000, seed=4), Execution(threads=1))
    b = simulate(None, 1.5, 30, rays=20_000, bins=BINS, seed=4, threads=1,
                 surface_factory=factory, realisations=2)  # fmt: skip
    _same(a, b)
    assert len(a.meta["realisations"]) == 2


def test_descriptions_are_frozen_and_normalised():
    ex = Experiment(SURFACE, "aluminium", [0, 45], 5, BINS)
    assert ex.theta_i == (0.0, 45.0) and ex.phi_i == (5.0, 5.0)
    est, run = Estimator(rays=np.int64(1000)), Execution(threads=1)
    assert type(est.rays) is int and est.stderr_method == "pairs"
    for obj, field in ((ex, "theta_i"), (est, "rays"), (run, "threads")):
        with pytest.raises(dataclasses.FrozenInstanceError):
            setattr(obj, field, 1)


@pytest.mark.parametrize(
    "make, name",
    [
        (lambda: Experiment(SURFACE, "aluminium", 95), "theta_i"),
        (lambda: Experiment(SURFACE, "aluminium", [10, 20], [1, 2, 3]), "phi_i"),
        (lambda: Experiment(SURFACE, "unobtainium", 10), "material"),
        (lambda: Experiment(SURFACE, None, 10, bins=(9, 6)), "bins"),
        (lambda: Experiment(SURFACE, None, 10, bounces=0), "bounces"),
        (lambda: Experiment("a mesh", None, 10), "surface"),
        (lambda: Estimator(rays=0), "rays"),
        (lambda: Estimator(seed=-1), "seed"),
        (lambda: Estimator(masking="fast"), "masking"),
        (lambda: Estimator(origins="grid"), "origins"),
        (lambda: Estimator(isotropic="yes"), "isotropic"),
        (lambda: Execution(threads=0), "threads"),
        (lambda: Execution(chunk=2**40), "chunk"),
        (lambda: Execution(progress="bar"), "progress"),
        (lambda: Precision(target=0), "target"),
    ],
)
def test_each_description_names_its_bad_field(make, name):
    with pytest.raises(UsageError, match=name):
        make()


def test_exact_masking_is_refused_with_bounces_before_any_work():
    ex = Experiment(SURFACE, "aluminium", 30, bins=BINS, bounces=2)
    with pytest.raises(UsageError, match="masking='exact'"):
        estimate(ex, Estimator(masking="exact"))


def test_estimate_to_precision_is_simulate_auto():
    kw = dict(bins=BINS, seed=2, masking="analytic", first=8192)
    a = simulate_auto(SURFACE, "aluminium", [30, 60], target=0.05, threads=1, **kw)
    b = estimate_to_precision(
        Experiment(SURFACE, "aluminium", (30, 60), bins=BINS),
        Estimator(rays=10**9, seed=2, masking="analytic"),
        Execution(threads=2),
        Precision(target=0.05, first=8192),
    )
    _same(a, b)
    assert all(d["converged"] for d in b.meta["auto"]["incidences"])
    with pytest.raises(UsageError, match="one surface"):
        estimate_to_precision(
            Experiment(None, None, 30, surface_factory=lambda s: SURFACE, realisations=2),
            Estimator(),
            Execution(),
            Precision(),
        )
