"""Surface container, flat mirror, meshes, and heightfields read from files."""

import numpy as np
import pytest

from microsim import analytic as an
from microsim.surfaces import Surface, flat, from_file, gaussian, vgrooves
from microsim.surfaces.loader import mirror_periodic


def test_flat():
    s = flat(2.0)
    assert s.kind == "flat" and s.periodic and s.tile_size == (2.0, 2.0)
    assert len(s.faces) == 2 and np.all(s.vertices[:, 2] == 0)
    assert np.allclose(s.facet_normals(), [0, 0, 1])
    assert s.facet_areas().sum() == pytest.approx(4.0)
    assert s.stats()["m_realised"] == 0
    with pytest.raises(ValueError, match="size"):
        flat(-1.0)


@pytest.mark.parametrize(
    "surf",
    [gaussian(32, 0.1, 0.05, 0.8), vgrooves(40, an.GGX(0.5), tile=3.0), flat()],
    ids=["gaussian", "vgrooves", "flat"],
)
def test_mesh_contract(surf):
    m = surf.mesh()
    v32 = surf.vertices.astype(np.float32)
    assert np.array_equal(m.vertices, v32) and np.array_equal(m.faces, surf.faces)  # float32 values
    assert len(m.vertices) == len(surf.vertices) and len(m.faces) == len(
        surf.faces
    )  # not processed
    lx, ly = surf.tile_size
    assert np.allclose(surf.vertices[:, 0].min(), -lx / 2) and np.allclose(
        surf.vertices[:, 0].max(), lx / 2
    )
    assert np.allclose(surf.vertices[:, 1].min(), -ly / 2) and np.allclose(
        surf.vertices[:, 1].max(), ly / 2
    )
    assert surf.vertices.dtype == np.float64 and surf.faces.dtype == np.int32
    n = surf.facet_normals()
    assert np.allclose(np.linalg.norm(n, axis=1), 1) and np.all(n[:, 2] > 0)
    assert np.allclose(surf.projected_areas(), surf.facet_areas() * n[:, 2])
    assert surf.projected_areas().sum() == pytest.approx(lx * ly)  # covers the tile once
    zmin, zmax = surf.z_range
    assert zmin <= zmax


def test_empirical_ndf_of_surface():
    """Surface.ndf() is the projected-area-weighted facet histogram: its tilt CDF at the
    median facet tilt is ½ within the histogram's bin resolution."""
    surf = gaussian(128, 1.0, 1.0, 8.0, seed=1)
    e = surf.ndf()
    assert isinstance(e, an.Empirical)
    n = surf.facet_normals()
    med = np.median(np.arctan2(np.hypot(n[:, 0], n[:, 1]), n[:, 2]))
    assert abs(e.cdf_theta_rad(med) - 0.5) < 0.02


def write(tmp_path, name, arr):
    p = tmp_path / name
    if name.endswith(".npy"):
        np.save(p, arr)
    elif name.endswith(".npz"):
        np.savez(p, **arr) if isinstance(arr, dict) else np.savez(p, arr)
    else:
        np.savetxt(p, arr)
    return p


@pytest.mark.parametrize("name", ["h.npy", "h.npz", "h.txt", "heights.npz"])
def test_from_file_formats(tmp_path, name):
    h = np.random.default_rng(0).normal(size=(12, 10)) + 5.0
    arr = {"heights": h, "other": np.zeros(3)} if name == "heights.npz" else h
    s = from_file(write(tmp_path, name, arr), dx=0.5, periodic=True)
    assert s.kind == "file" and s.heights.shape == (12, 10) and s.tile_size == (5.0, 6.0)
    assert np.allclose(s.heights, h - h.mean()) and abs(s.heights.mean()) < 1e-12
    assert len(s.faces) == 2 * 12 * 10


def test_from_file_mirrors_non_periodic(tmp_path):
    """Even reflection: (2n − 2)² grid, every x/y slope of the input kept (up to sign), none new."""
    rng = np.random.default_rng(1)
    h = np.cumsum(rng.normal(size=(9, 11)), axis=1)  # strongly non-periodic
    s = from_file(write(tmp_path, "h.npy", h), dx=1.0)
    assert s.heights.shape == (16, 20) and s.tile_size == (20.0, 16.0) and s.periodic
    assert s.warnings and "mirror" in s.warnings[0]
    hm = s.heights
    for ax in (0, 1):
        new = np.unique(np.round(np.abs(np.roll(hm, -1, axis=ax) - hm), 9))
        old = np.unique(np.round(np.abs(np.diff(h, axis=ax)), 9))
        assert np.array_equal(new, old)
    assert np.array_equal(mirror_periodic(h)[:9, :11], h)


@pytest.mark.parametrize(
    "arr, dx, key",
    [
        (np.full((10, 10), np.nan), 1.0, "NaN"),
        (np.zeros(20), 1.0, "2D"),
        (np.zeros((7, 20)), 1.0, "8x8"),
        (np.zeros((10, 10)), 0.0, "dx"),
        (np.zeros((10, 10)), float("nan"), "dx"),
        (np.zeros((10, 10)), float("inf"), "dx"),
        (np.zeros((10, 10, 2)), 1.0, "2D"),
    ],
)
def test_from_file_errors(tmp_path, arr, dx, key):
    with pytest.raises(ValueError, match=key):
        from_file(write(tmp_path, "h.npy", arr), dx=dx)


def test_from_file_ambiguous_npz_and_missing(tmp_path):
    with pytest.raises(ValueError, match="heights"):
        from_file(write(tmp_path, "h.npz", {"a": np.zeros((9, 9)), "b": np.zeros((9, 9))}), 1.0)
    with pytest.raises(ValueError, match="no such"):
        from_file(tmp_path / "missing.npy", 1.0)


def test_surface_is_frozen():
    s = flat()
    assert isinstance(s, Surface)
    with pytest.raises(AttributeError):
        s.kind = "other"


def test_surfaces_carry_what_their_generator_knows():
    """Each generator attaches its ensemble NDF, the shadowing exact for it and its predictions,
    and the repr is one line, not a vertex dump."""
    vg = vgrooves(50, an.Beckmann(0.3))
    assert vg.ensemble_ndf == an.Beckmann(0.3) and vg.exact_shadowing == "vgroove"
    assert vg.predicted is None and "n_grooves" in vg.stats()
    g = gaussian(64, 1.0, 1.0, 8.0)
    assert g.ensemble_ndf == an.Beckmann(0.25) and g.exact_shadowing is None
    assert g.stats()["predicted_m"] == g.predicted.m
    f = flat()
    assert f.ensemble_ndf is None and f.exact_shadowing == "none" and f.predicted is None
    for s in (vg, g, f):
        text = repr(s)
        assert "\n" not in text and len(text) < 200 and text.startswith(f"Surface({s.kind}")
