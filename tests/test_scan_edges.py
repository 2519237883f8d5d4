"""How rays meet a scan's edges: a periodic Gaussian surface cut to a window, written as X3P and
read back as a scan (form "none"), is mirrored into a periodic tile (``loader.mirror_periodic``);
its BRDF against the periodic original's. docs/scenes.md ("Edges of a scan") gives the numbers
of ``tools/edge_study.py``.

What must agree: the mirrored tile holds exactly the scan's facets, each in its four
reflections, and nothing else — the seams rearrange facets but add none (the first test, exact).
A window is a different *sample* of the surface's random process than the periodic original
(it shares only part of it), so their BRDFs differ by the sampling scatter any finite scan has,
far beyond the ray noise; what must hold is that the mirror adds no bias: over independent
realisations the mean of BRDF(mirrored window) − BRDF(periodic original) is zero in every bin
within the scatter of that difference. The seams themselves (ridges and valleys where the surface
meets its reflection, which change the masking near them) are measured against the same facets
traced without seams, and must cost a small part of the sampling scatter.
"""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from microsim import surfaces
from microsim.sim import Bins, simulate
from microsim.stats import MIN_EVENTS, sidak, t_isf
from microsim.surfaces import scan
from microsim.surfaces.surface import Surface, heightfield_mesh

N, SIGMA, CORR_LEN = 128, 1.2, 8.0  # µm on dx = 1 µm: slopes m = 2σ/ℓ = 0.3
WINDOW = slice(16, 112)  # the central 96² of the tile
THETA_I = (0.0, 30.0, 60.0)
BINS = Bins(9, 6)
RAYS = 2**20
ALPHA = 0.01  # family-wise false-alarm rate of the bias test


def _original(seed: int) -> Surface:
    return surfaces.gaussian(N, 1.0, SIGMA, CORR_LEN, seed=seed)


def _read_as_scan(tmp_path, heights_um) -> Surface:
    """``heights_um`` (µm on a 1 µm grid) written as X3P and read back as a scan, form none."""
    path = tmp_path / "window.x3p"
    scan.write_x3p(path, heights_um * scan.SCAN_UNIT, scan.SCAN_UNIT)
    return surfaces.from_file(path, form="none")


def _periodic(heights) -> Surface:
    """``heights`` traced as a periodic tile as they are (dx = 1)."""
    vertices, faces = heightfield_mesh(heights, 1.0)
    ny, nx = heights.shape
    return Surface("file", vertices, faces, (nx, ny), True, {}, heights=heights, dx=1.0)


def _facet_slopes(heights, wrap: bool) -> np.ndarray:
    """(x, y) height differences of both triangles of every cell of ``heights``' mesh (the
    split of ``heightfield_mesh``), one row each; ``wrap=False`` leaves out the cells that
    join the last row or column to the first."""
    h = np.pad(heights, ((0, 1), (0, 1)), mode="wrap") if wrap else heights
    h00, h01, h10, h11 = h[:-1, :-1], h[:-1, 1:], h[1:, :-1], h[1:, 1:]
    upper = np.stack([h01 - h00, h11 - h01], axis=-1)  # (v00, v01, v11)
    lower = np.stack([h11 - h10, h10 - h00], axis=-1)  # (v00, v11, v10)
    return np.concatenate([upper.reshape(-1, 2), lower.reshape(-1, 2)])


def _reflections(heights) -> tuple[np.ndarray, ...]:
    """``heights`` as they are, reflected in x, in y and in both."""
    return heights, heights[:, ::-1], heights[::-1], heights[::-1, ::-1]


def _sorted_rows(a: np.ndarray) -> np.ndarray:
    return a[np.lexsort(a.T[::-1])]


def test_the_mirrored_scan_holds_its_facets_in_four_reflections_and_no_other(tmp_path):
    window = _original(1).heights[WINDOW, WINDOW]
    s = _read_as_scan(tmp_path, window)
    n = window.shape[0]
    assert s.heights.shape == (2 * n - 2, 2 * n - 2)
    scanned = s.heights[:n, :n]  # the scan as read: µm, its mean moved
    assert np.allclose(scanned - scanned.mean(), window - window.mean(), rtol=0, atol=1e-9)
    expected = np.concatenate([_facet_slopes(r, wrap=False) for r in _reflections(scanned)])
    traced = _facet_slopes(s.heights, wrap=True)
    assert np.array_equal(_sorted_rows(traced), _sorted_rows(expected))


def _brdf(surface: Surface, seed: int):
    """(BRDF, its ray standard error, bins with at least ``MIN_EVENTS`` events)."""
    r = simulate(surface, "aluminium", THETA_I, rays=RAYS, bins=BINS, seed=seed, threads=2)
    return r.brdf, r.stderr, r.counts >= MIN_EVENTS


def _relative_l2(f, reference, used) -> np.ndarray:
    """Per θi: ‖f − reference‖ / ‖reference‖ over the used bins, the norm of L2(cos θo dω)."""
    w = BINS.projected_solid_angle()[None] * used
    return np.sqrt(np.sum(w * (f - reference) ** 2, axis=(1, 2)) / np.sum(w * reference**2, (1, 2)))


@pytest.mark.slow
def test_the_mirrored_window_is_unbiased_within_the_sampling_scatter(tmp_path):
    """Paired over K realisations: d_k = BRDF(mirrored window) − BRDF(periodic original) per
    bin; the mean of d over k, divided by its standard error (the scatter of d over k: ray
    noise and the two surfaces' sampling scatter together), is Student-t with K − 1 degrees
    of freedom if the mirror adds no bias. Every used bin of every θi must stay within the
    two-sided Šidák-corrected quantile: a false alarm in at most ``ALPHA`` of the runs."""
    k_realisations = 12
    differences, used = [], True
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)  # the mirroring notice
        for k in range(k_realisations):
            original = _original(100 + k)
            mirrored = _read_as_scan(tmp_path, original.heights[WINDOW, WINDOW])
            f_mirror, _, used_mirror = _brdf(mirrored, seed=2 * k)
            f_original, _, used_original = _brdf(original, seed=2 * k + 1)
            differences.append(f_mirror - f_original)
            used = used & used_mirror & used_original
    d = np.array(differences)[:, used]
    t = d.mean(axis=0) / (d.std(axis=0, ddof=1) / np.sqrt(k_realisations))
    limit = t_isf(sidak(ALPHA, d.shape[1]) / 2, k_realisations - 1)
    assert used.any(axis=(1, 2)).all()
    assert np.abs(t).max() < limit, (np.abs(t).max(), limit)


@pytest.mark.slow
def test_the_seams_cost_a_small_part_of_the_sampling_scatter(tmp_path):
    """The whole periodic tile read as a scan is mirrored: its facets are the tile's in four
    reflections (less the cells across the tile's wrap-around, which no scan has). Traced
    against those four reflections as seamless periodic tiles, the BRDFs differ only by the
    seams (and those cells); that difference (ray noise included) must be below a fifth of
    the difference between two independent realisations of the same process, per θi."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)
        original, other = _original(7), _original(8)
        mirrored = _read_as_scan(tmp_path, original.heights)
    reflections = _reflections(mirrored.heights[:N, :N])
    f_seamless = np.mean([_brdf(_periodic(r), seed=k)[0] for k, r in enumerate(reflections)], 0)
    f_mirror, _, used = _brdf(mirrored, seed=4)
    f_original, _, used_original = _brdf(original, seed=5)
    f_other, _, used_other = _brdf(other, seed=6)
    used = used & used_original & used_other
    seams = _relative_l2(f_mirror, f_seamless, used)
    sampling = _relative_l2(f_other, f_original, used)
    assert np.all(seams < 0.2 * sampling), (seams, sampling)
