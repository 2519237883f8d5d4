"""The random walk's bin averages are taken on a ``Bins``: its exit directions located by
``Bins.locate`` and divided by ``Bins.projected_solid_angle``, as the simulation bins; the older
form with bin edges still works where the edges are a ``Bins``'s."""

import numpy as np
import pytest

from microsim import analytic as an
from microsim.analytic import random_walk as rw
from microsim.bins import Bins
from microsim.errors import UsageError


@pytest.mark.parametrize("bins, phi_i", [(Bins(45, 37), 0.0), (Bins(9, 12, folded=False), 35.0)])
def test_walk_bins_its_paths_by_bins_locate_over_the_bins_solid_angle(bins, phi_i):
    """The same paths (one generator, one chunk) tallied by ``Bins.locate`` and divided by
    ``Bins.projected_solid_angle`` and by the path count are the walk's values, bit for bit."""
    ndf, theta_i, n, seed = an.GGX(0.3), 30.0, 20_000, 4
    got = rw.walk_bin_averages(theta_i, bins, ndf, n_paths=n, orders=1, seed=seed, phi_i=phi_i)
    t, p = np.radians(theta_i), np.radians(phi_i)
    wi = np.array([np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)])
    if phi_i == 0.0:
        wi[1] = 0.0
    paths = rw.smith_random_walk(
        np.broadcast_to(wi, (n, 3)), rw.WalkNDF.of(ndf), None, np.random.default_rng(seed)
    )
    esc = paths.order > 0
    where = bins.locate(paths.wo[esc], phi_i)
    assert np.all(where >= 0)
    sums = np.bincount(where, paths.weight[esc], minlength=bins.n_theta * bins.n_phi)
    want = sums / float(n) / bins.projected_solid_angle().ravel()
    assert np.array_equal(got.omega, bins.projected_solid_angle())
    assert np.array_equal(got.values[0, 0].ravel(), want)


def test_the_older_edge_form_warns_and_equals_the_bins_form():
    bins = Bins(12, 10, folded=False)
    new = rw.walk_bin_averages(
        [20.0, 60.0], bins, an.Beckmann(0.4), "aluminium", n_paths=5000, seed=2, phi_i=10.0
    )
    with pytest.warns(DeprecationWarning, match="pass the Bins"):
        old = rw.walk_bin_averages(
            [20.0, 60.0],
            bins.theta_edges,
            bins.phi_edges,
            an.Beckmann(0.4),
            "aluminium",
            n_paths=5000,
            seed=2,
            phi_i=10.0,
            folded=False,
        )
    for name in ("values", "stderr", "energy", "omega", "multiple_energy"):
        assert np.array_equal(getattr(old, name), getattr(new, name)), name


@pytest.mark.parametrize(
    "theta_edges, phi_edges, folded",
    [
        ([0, 90], [0, 180], True),  # one folded Δφ bin: no Bins has it
        ([0, 45, 80], Bins(2, 5).phi_edges, True),  # θo not up to 90°
        ([0, 90], [0, 30, 180], True),  # uneven Δφ bins
        (Bins(3, 6).theta_edges, Bins(3, 6).phi_edges, False),  # folded edges, unfolded
    ],
)
def test_edges_no_bins_has_are_refused(theta_edges, phi_edges, folded):
    with pytest.raises(UsageError, match="bins must be a microsim.bins.Bins"):
        rw.walk_bin_averages(0.0, theta_edges, phi_edges, an.GGX(0.3), folded=folded)


def test_a_bins_with_the_folding_or_extra_positions_is_refused():
    with pytest.raises(UsageError, match="folding is the bins'"):
        rw.walk_bin_averages(0.0, Bins(2, 3), an.GGX(0.3), folded=False)
    with pytest.raises(UsageError, match="by keyword"):
        rw.walk_bin_averages(0.0, Bins(2, 3), an.GGX(0.3), None, 1000)
