"""Helpers shared by the tests (importable as ``support``: pytest's ``pythonpath = tests``).

* Goodness of fit (docs/design.md, "Tests"): Pearson χ² of observed counts against expected
  counts, with cells whose expected count is below ``min_expected`` pooled into one — the
  public ``microsim.testing.pearson_chi2`` — and Šidák's correction (``microsim.stats.sidak``)
  for several tests at one family-wise level.
* Small explicit surfaces built directly from their mesh: equal-width V-grooves with given
  tilts, and a periodic Gaussian-filtered heightfield.
* ``walk_on``: the random walk's bin averages on a ``Bins`` grid.
* ``refused``: a call refused with a one-line UsageError naming given words;
  ``TINY_CLUSTER_SCENE``: the small V-groove scene the cluster tests trace.
"""

from __future__ import annotations

import numpy as np
import pytest

from microsim.errors import UsageError
from microsim.stats import sidak  # noqa: F401  (re-exported for the tests)
from microsim.surfaces.surface import Surface, heightfield_mesh
from microsim.testing import pearson_chi2  # noqa: F401  (the public harness, re-exported)


def walk_on(bins, theta_i, ndf, material=None, *, n, seed, orders, phi_i=0.0):
    """``walk_bin_averages`` of ``ndf`` on ``bins``."""
    from microsim.analytic import random_walk as rw

    return rw.walk_bin_averages(
        theta_i, bins, ndf, material, n_paths=n, orders=orders, seed=seed, phi_i=phi_i
    )


def vgroove_surface(tilts_deg, tile=1.0) -> Surface:
    """Equal-width symmetric V-grooves along y with the given tilts (deg); rims at z = 0."""
    t = np.radians(np.asarray(tilts_deg, dtype=float))
    n, w = len(t), tile / len(t)
    x = -tile / 2 + np.arange(2 * n + 1) * (w / 2)
    z = np.zeros(2 * n + 1)
    z[1::2] = -(w / 2) * np.tan(t)
    m = len(x)
    lo = np.stack([x, np.full(m, -tile / 2), z], axis=1)
    hi = np.stack([x, np.full(m, tile / 2), z], axis=1)
    a = np.arange(m - 1)
    faces = np.concatenate([np.stack([a, a + 1, a + 1 + m], 1), np.stack([a, a + 1 + m, a + m], 1)])
    return Surface(
        "vgrooves",
        np.concatenate([lo, hi]),
        faces.astype(np.int32),
        (tile, tile),
        True,
        {"tilts_deg": list(map(float, tilts_deg))},
        azimuth_average=True,
    )


def random_heights(n=64, sigma=0.02, corr_cells=8.0, seed=0) -> np.ndarray:
    """Periodic Gaussian-filtered white noise, rms ``sigma`` (unit tile, dx = 1/n)."""
    rng = np.random.default_rng(seed)
    f = np.fft.fftfreq(n)
    fx, fy = np.meshgrid(f, f)
    spec = np.exp(-((np.pi * corr_cells) ** 2) * (fx**2 + fy**2) / 2)
    h = np.real(np.fft.ifft2(np.fft.fft2(rng.normal(size=(n, n))) * spec))
    h -= h.mean()
    return h * (sigma / h.std())


def heightfield_surface(h: np.ndarray, dx: float) -> Surface:
    v, f = heightfield_mesh(h, dx)
    ny, nx = h.shape
    return Surface("gaussian", v, f, (nx * dx, ny * dx), True, {}, heights=h, dx=dx)


def flat_verdict(sim, stderr, counts, model, omega, theta_edges, **kw) -> dict:
    """``analysis.verdicts.verdict`` from flat arguments: each keyword goes to the group that
    owns it (``Measured``, ``Prediction`` or ``Significance``)."""
    from microsim.analysis.verdicts import Measured, Prediction, Significance, verdict

    def take(group):
        return {k: kw.pop(k) for k in group._fields if k in kw}

    measured = Measured(sim, stderr, counts, omega, theta_edges, **take(Measured))
    prediction = Prediction(model, **take(Prediction))
    significance = Significance(**take(Significance))
    if kw:
        raise TypeError(f"verdict has no argument {sorted(kw)}")
    return verdict(measured, prediction, significance)


def refused(call, *words):
    """``call()`` raises a one-line UsageError naming every one of ``words``; its message."""
    with pytest.raises(UsageError) as info:
        call()
    msg = str(info.value)
    assert isinstance(info.value, ValueError)
    assert "\n" not in msg, msg
    for w in words:
        assert w in msg, msg
    return msg


TINY_CLUSTER_SCENE = """\
name = "tiny-cluster"
[surface]
kind = "vgrooves"
n_grooves = 400
ndf = "beckmann"
m = 0.3
[material]
ior = "aluminium"
[simulation]
theta_i = [20, 60]
rays = 200000
theta_bins = 9
phi_bins = 10
"""
