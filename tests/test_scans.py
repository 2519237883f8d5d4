"""Measured scans (``microsim.surfaces.scan`` through ``surfaces.from_file`` and scene files):
X3P written and read back, SurfaceTopography's formats, missing points, non-square grids,
dx != dy, form removal, and every bad input refused in one line naming it."""

from __future__ import annotations

import re
import sys

import numpy as np
import pytest
from support import random_heights, refused
from test_faults_cli import run_cli, tree

from microsim import surfaces
from microsim.analysis.report_cells import params_text
from microsim.app.scene import load_scene
from microsim.sim import Bins, simulate
from microsim.surfaces import scan
from microsim.surfaces.loader import check_heightfield_file

UM = scan.SCAN_UNIT


def _scan_heights(ny=24, nx=40, sigma=0.05):
    """A rough non-square patch (ny, nx) in metres, rms ``sigma`` µm."""
    return random_heights(max(ny, nx), sigma=sigma, corr_cells=4.0, seed=3)[:ny, :nx] * UM


def _scene(tmp, path, extra=""):
    text = f'name = "scan"\n[surface]\nkind = "file"\npath = "{path}"\n{extra}'
    (tmp / "scan.toml").write_text(text)
    return tmp / "scan.toml"


def test_an_x3p_reads_back_its_heights_spacings_and_missing_points(tmp_path):
    h = _scan_heights()
    h[3, 5] = np.nan
    scan.write_x3p(tmp_path / "s.x3p", h, 0.5 * UM, 0.75 * UM)
    back = scan.read_scan(tmp_path / "s.x3p")
    assert np.array_equal(back.heights, h, equal_nan=True)  # float64 heights: exact
    assert (back.dx, back.dy) == (0.5 * UM, 0.75 * UM)


def test_a_scan_with_missing_points_is_filled_and_traced(tmp_path):
    h = _scan_heights()
    h[10:13, 20:24] = np.nan  # a hole inside
    h[0, :6] = np.nan  # and one at the border
    scan.write_x3p(tmp_path / "s.x3p", h, 0.5 * UM)
    s = surfaces.from_file(tmp_path / "s.x3p")
    assert np.isfinite(s.heights).all()
    assert s.nominal["filled_fraction"] == 18 / h.size
    assert any("not measured" in w for w in s.warnings)
    r = simulate(s, "aluminium", 30.0, rays=2000, bins=Bins(6, 4), seed=1, threads=1)
    assert np.isfinite(r.brdf).all() and r.brdf.max() > 0


def test_missing_points_of_a_plane_are_filled_on_the_plane():
    y, x = np.mgrid[0:20, 0:30]
    plane = 0.3 * x - 0.2 * y + 1.0
    holed = plane.copy()
    holed[5:9, 10:14] = np.nan  # inside: a plane is harmonic, so it is filled exactly
    filled, fraction = scan.fill_missing(holed, 1.0, 2.0)
    assert np.allclose(filled, plane, rtol=0, atol=1e-9) and fraction == 16 / 600
    holed[0, :3] = np.nan  # at the border: between the measured heights around the hole
    filled, _ = scan.fill_missing(holed, 1.0, 2.0)
    assert plane[1, :4].min() <= filled[0, :3].min() <= filled[0, :3].max() <= plane[1, :4].max()


def test_a_non_square_grid_gives_a_non_square_tile(tmp_path):
    h = _scan_heights(ny=24, nx=40)
    scan.write_x3p(tmp_path / "s.x3p", h, 0.5 * UM)
    s = surfaces.from_file(tmp_path / "s.x3p", form="none")
    assert s.heights.shape == (2 * 24 - 2, 2 * 40 - 2)  # mirrored, rows = y
    assert s.tile_size == pytest.approx(((2 * 40 - 2) * 0.5, (2 * 24 - 2) * 0.5))  # in µm
    top_left = s.heights[:24, :40]
    assert np.allclose(top_left - top_left[0, 0], (h - h[0, 0]) / UM, atol=1e-12)


@pytest.mark.parametrize("dx, dy", [(0.5, 1.5), (1.5, 0.5)])
def test_unequal_spacings_are_resampled_to_the_finer_one(tmp_path, dx, dy):
    y, x = np.mgrid[0:10, 0:12]
    plane = 0.02 * x * dx + 0.05 * y * dy  # µm; linear interpolation keeps a plane exactly
    scan.write_x3p(tmp_path / "s.x3p", plane * UM, dx * UM, dy * UM)
    s = surfaces.from_file(tmp_path / "s.x3p", form="none", periodic=True)
    ny, nx = s.heights.shape
    assert s.dx == 0.5 and (ny, nx) == ((10, 34) if dx > dy else (28, 12))
    fy, fx = np.mgrid[0:ny, 0:nx] * 0.5
    expected = 0.02 * fx + 0.05 * fy
    assert np.allclose(s.heights, expected - expected.mean(), atol=1e-12)
    assert any("resampled" in w for w in s.warnings)


@pytest.mark.parametrize("form", ["plane", "poly2", "poly4"])
def test_form_removal_removes_an_added_form_exactly(form):
    h = _scan_heights(ny=30, nx=50) / UM
    h[4:7, 8:12] = np.nan  # fitted on the measured points only
    y, x = np.mgrid[0:30, 0:50].astype(float)
    x, y = (x - 24.5) * 0.4, (y - 14.5) * 0.7  # from the centre, dx 0.4, dy 0.7
    added = {"1": 2.0, "x": 0.3, "y": -0.1}
    if form != "plane":
        added.update({"x^2": 0.01, "x*y": -0.02, "y^2": 0.005})
    terms = {"1": 1, "x": x, "y": y, "x^2": x**2, "x*y": x * y, "y^2": y**2}
    tilted = h + sum(c * terms[t] for t, c in added.items())
    rest, removed = scan.remove_form(tilted, 0.4, 0.7, form)
    alone, own = scan.remove_form(h, 0.4, 0.7, form)
    assert np.allclose(rest, alone, atol=1e-12, equal_nan=True)
    assert np.isnan(rest[5, 9]) and removed.method == form
    coefficients = dict(zip(removed.terms, removed.coefficients))
    for t, c in zip(own.terms, own.coefficients):  # least squares is linear in the heights
        assert coefficients[t] == pytest.approx(c + added.get(t, 0.0), abs=1e-9)
    assert removed.rms_removed > own.rms_removed > 0


def test_a_scene_reads_a_scan_in_micrometres_with_its_plane_removed(tmp_path):
    y, x = np.mgrid[0:24, 0:40]
    h = _scan_heights() + (0.01 * x + 0.02 * y) * UM  # an instrument's tilt
    scan.write_x3p(tmp_path / "s.x3p", h, 0.25 * UM)
    sc = load_scene(_scene(tmp_path, "s.x3p"))
    assert (sc.surface.form, sc.surface.dx) == ("plane", None)
    s = sc.build_surface(0)
    assert s.dx == 0.25 and s.nominal["unit"] == "µm"
    assert s.nominal["form"] == "plane" and s.nominal["form_rms_removed"] > 0
    assert "form = plane" in params_text(s.nominal)  # the report's "nominal" row
    (line,) = [w for w in s.warnings if "form removed: plane" in w]
    slope = float(re.search(r"\bx: ([-+0-9.e]+)", line).group(1))
    assert slope == pytest.approx(0.04, abs=2e-3)  # µm per µm


def test_a_heightfield_array_keeps_no_form_by_default_and_takes_one(tmp_path):
    h = random_heights(32)
    np.save(tmp_path / "h.npy", h + np.arange(32)[None, :] * 0.01)
    kept = load_scene(_scene(tmp_path, "h.npy", "dx = 1.0\nperiodic = true\n"))
    assert kept.surface.form == "none"
    np.save(tmp_path / "p.npy", h + np.arange(32)[None, :] * 0.01)
    flat = load_scene(_scene(tmp_path, "p.npy", 'dx = 1.0\nperiodic = true\nform = "plane"\n'))
    removed = flat.build_surface(0)
    assert removed.nominal["form"] == "plane" and "form" not in kept.build_surface(0).nominal
    expected = scan.remove_form(h, 1.0, 1.0, "plane")[0]
    assert np.allclose(removed.heights, expected - expected.mean(), atol=1e-12)


def _x3p(h, dx=0.5):
    return lambda p: scan.write_x3p(p, h, dx * UM)


_HOLED = _scan_heights()
_HOLED[:, :12] = np.nan  # 30 % missing
BAD_SCANS = [
    # (id, file name, writer, extra scene keys, words of the one line)
    ("x3p-with-dx", "s.x3p", _x3p(_scan_heights()), "dx = 1.0\n", ["surface.dx", "leave dx out"]),
    ("npy-without-dx", "h.npy", lambda p: np.save(p, random_heights(16)), "", ["surface.dx"]),
    (
        "form-poly9",
        "s.x3p",
        _x3p(_scan_heights()),
        'form = "poly9"\n',
        ["surface.form", '"none"', '"plane"', '"poly4"'],
    ),
    ("30-percent-missing", "s.x3p", _x3p(_HOLED), "", ["s.x3p", "30.0%", "20%"]),
    ("x3p-damaged", "s.x3p", lambda p: p.write_bytes(b"PK\x03\x04 not a zip"), "", ["X3P"]),
    ("x3p-flat", "s.x3p", _x3p(np.full((16, 16), 1e-6)), "", ["s.x3p", "flat"]),
]


@pytest.mark.parametrize(
    "name, write, extra, words", [c[1:] for c in BAD_SCANS], ids=[c[0] for c in BAD_SCANS]
)
def test_a_bad_scan_scene_is_one_line_before_anything_is_written(
    tmp_path, capsys, monkeypatch, name, write, extra, words
):
    monkeypatch.chdir(tmp_path)
    write(tmp_path / name)
    path = _scene(tmp_path, name, extra)
    before = tree(tmp_path)
    status, lines, err = run_cli(capsys, "run", path, "--quick", "--threads", "1")
    assert status == 2 and len(lines) == 1 and "Traceback" not in err, err
    for w in words:
        assert w in lines[0], (w, lines[0])
    assert tree(tmp_path) == before


def test_python_calls_refuse_bad_scans(tmp_path):
    scan.write_x3p(tmp_path / "s.x3p", _scan_heights(), 0.5 * UM)
    refused(lambda: surfaces.from_file(tmp_path / "s.x3p", 1.0), "dx", "leave dx out")
    refused(lambda: surfaces.from_file(tmp_path / "s.x3p", form="cubic"), "form", "poly2")
    refused(lambda: check_heightfield_file(tmp_path / "s.x3p", form="tilt"), "form", "plane")
    (tmp_path / "s.xyz1").write_text("1 2 3\n")
    refused(lambda: scan.read_scan(tmp_path / "s.xyz1"), "s.xyz1", ".x3p", ".sur", ".gwy")
    refused(lambda: scan.write_x3p(tmp_path / "w.x3p", np.zeros(5), 1e-6), "2-D")
    refused(lambda: scan.write_x3p(tmp_path / "w.x3p", np.zeros((8, 8)), -1.0), "dx")
    assert not (tmp_path / "w.x3p").exists()


def test_without_surfacetopography_its_formats_say_how_to_install_it(tmp_path, monkeypatch):
    (tmp_path / "s.sur").write_bytes(b"\0" * 64)
    monkeypatch.setitem(sys.modules, "SurfaceTopography", None)  # import fails
    refused(lambda: scan.read_scan(tmp_path / "s.sur"), "s.sur", "pip install microsim[topography]")


def test_surfacetopography_formats_read_back_in_metres_rows_along_y(tmp_path):
    st = pytest.importorskip("SurfaceTopography", reason="extra topography not installed")
    h = _scan_heights(ny=12, nx=20) / UM  # µm
    # SurfaceTopography's arrays are indexed [x, y]: its (20, 12) is our (12, 20)
    st.Topography(h.T.copy(), physical_sizes=(20 * 0.5, 12 * 0.8), unit="um").to_gwy(
        str(tmp_path / "s.gwy")
    )
    back = scan.read_scan(tmp_path / "s.gwy")
    assert np.allclose(back.heights, h * UM, rtol=1e-12, atol=0)
    assert back.dx == pytest.approx(0.5 * UM) and back.dy == pytest.approx(0.8 * UM)
    (tmp_path / "bad.sur").write_bytes(b"not a Digital Surf file" * 4)
    refused(lambda: scan.read_scan(tmp_path / "bad.sur"), "bad.sur", "SurfaceTopography")
