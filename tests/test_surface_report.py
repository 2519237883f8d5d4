"""The report of a measured heightfield (``analysis.surface_report``, ``microsim surface FILE``):
each statistic checked on a catalogue surface whose truth is known (a Gaussian field's Beckmann
m, an ABC field's A, B, C, an anisotropic field's axes), the warnings on the surfaces that
deserve them, and the command line's refusals (one line, status 2, nothing written)."""

from __future__ import annotations

import json
import warnings

import numpy as np
import pytest
from support import refused

from microsim.analysis.surface_report import MIN_CORR_CELLS, surface_chart, surface_report
from microsim.app.cli import main
from microsim.surfaces.heightfields import abc, gaussian


def _quiet(make, *args, **kw):
    """A catalogue surface without its generator's warnings (the coarse one warns)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)
        return make(*args, **kw)


def _within(estimate, truth, k=3.0) -> bool:
    return estimate.error is not None and abs(estimate.value - truth) <= k * estimate.error


def test_gaussian_beckmann_m_is_the_ensemble_rms_slope_within_its_error():
    """Convention: Beckmann m = √(2 × per-axis slope variance) = √(E[sx²] + E[sy²]). The fit of
    a random-amplitude Gaussian tile is within 3 standard errors of the ensemble's mesh m (the
    generator's prediction), the error counts the correlated facets honestly (neither a
    facet-count error, 30× too small, nor a uselessly large one), and GGX is rejected."""
    surf = gaussian(128, 1.0, 1.0, 8.0, seed=4, exact_amplitude=False)
    report = surface_report(surf.heights, 1.0)
    m = report.fit("beckmann").params["m"]
    assert _within(m, surf.predicted.m), (m, surf.predicted.m)
    assert 0.01 < m.error / m.value < 0.1
    assert m.value == pytest.approx(report.slopes.rms, rel=1e-2)  # the MLE of m is the rms
    assert report.fit("beckmann").consistent and not report.fit("ggx").consistent
    assert report.best_ndf in ("beckmann", "student-t")
    assert report.heights_stats.corr_len == pytest.approx(8.0, rel=0.15)
    assert not report.anisotropy.anisotropic


def test_abc_fit_recovers_the_catalogue_parameters():
    """A, B, C of a random-amplitude ABC tile (band up to Nyquist) within 3 standard errors of
    the generator's, with errors small enough to mean something."""
    surf = _quiet(abc, 128, 1.0, 1.0, 20.0, 3.5, seed=5, band_limit=1, exact_amplitude=False)
    fit = surface_report(surf.heights, 1.0).abc
    nominal = surf.nominal
    assert _within(fit.A, nominal["A"]) and fit.A.error < 0.5 * nominal["A"], fit
    assert _within(fit.B, nominal["B"]) and fit.B.error < 0.2 * nominal["B"], fit
    assert _within(fit.C, nominal["C"]) and fit.C.error < 0.2, fit
    assert fit.reduced_chi2 < 3.0
    assert fit.sigma == pytest.approx(1.0, rel=0.2)


def test_abc_fit_of_a_band_limited_tile_is_unbiased():
    """A band-limited tile (the catalogue's ABC scenes: power only up to f = 1/(2·4·dx), the
    cut-off running through a ring): A, B, C within 3 standard errors, and the residuals those
    of the periodogram's own scatter — reduced χ² within 4 of its standard deviations
    √(2/dof) of 1 (a ring averaged over cells the band leaves empty biases C up and B down,
    and χ² with them)."""
    surf = _quiet(abc, 256, 1.0, 1.0, 32.0, 2.0, seed=3, band_limit=4, exact_amplitude=False)
    fit = surface_report(surf.heights, 1.0).abc
    nominal = surf.nominal
    assert fit.f_range[1] <= 0.125 + 1e-9  # fitted over the band only
    for name in "ABC":
        assert _within(getattr(fit, name), nominal[name]), fit
    rings = 0.125 * 256 - 1  # about one ring per frequency step inside the band
    assert abs(fit.reduced_chi2 - 1.0) < 4.0 * np.sqrt(2.0 / (rings - 3)), fit


def test_a_scenes_abc_surface_is_described_with_its_psd_fit():
    """``microsim surface SCENE`` on an ABC heightfield: the fitted A, B, C with their errors
    beside the generator's nominal values."""
    from microsim.app.scene import describe_surface

    surf = _quiet(abc, 128, 1.0, 1.0, 20.0, 3.5, seed=5, band_limit=1, exact_amplitude=False)
    text = describe_surface(surf)
    fit = surface_report(surf.heights, 1.0).abc
    for name in "ABC":
        row = next(line for line in text.splitlines() if line.startswith(f"PSD fit {name}"))
        assert f"{getattr(fit, name).value:.4g} ± " in row
        assert row.split()[-1] == f"{surf.nominal[name]:.6g}"
    assert "reduced chi²" in text


def test_anisotropic_gaussian_axes_and_ratio_are_found():
    """ℓx = 6, ℓy = 12 along axes rotated by 30° (random amplitudes): αx/αy ≈ 2 (the
    generator's mesh α's) within 3 errors, the αx axis at 30°."""
    surf = _quiet(
        gaussian, 128, 1.0, 1.0, 6.0, seed=3, corr_len_y=12.0, rotation=30.0, exact_amplitude=False
    )
    an = surface_report(surf.heights, 1.0).anisotropy
    assert an.anisotropic and an.ratio.error < 0.1 * an.ratio.value
    assert _within(an.ratio, surf.predicted.alpha_x / surf.predicted.alpha_y), an
    assert an.angle_deg == pytest.approx(30.0, abs=3.0)
    assert an.alpha_x == pytest.approx(surf.predicted.alpha_x, rel=0.1)


def test_slopes_are_those_of_the_tracers_facets():
    """On a periodic tile the facet slopes are the traced mesh's (``Surface.stats``)."""
    surf = _quiet(gaussian, 64, 1.0, 1.0, 6.0, seed=2, corr_len_y=9.0, rotation=20.0)
    report = surface_report(surf.heights, 1.0)
    st = surf.stats()
    assert report.periodic
    assert report.slopes.rms_x**2 == pytest.approx(st["slope_var_x"], rel=1e-9)
    assert report.slopes.rms_y**2 == pytest.approx(st["slope_var_y"], rel=1e-9)
    assert report.slopes.correlation == pytest.approx(st["slope_corr"], rel=1e-9)


def test_coarse_sampling_warns_and_a_fine_one_does_not():
    coarse = _quiet(gaussian, 64, 1.0, 1.0, 2.0, seed=1)
    fine = gaussian(64, 1.0, 1.0, 2.0 * MIN_CORR_CELLS, seed=1)
    assert any("sampling too coarse" in w for w in surface_report(coarse.heights, 1.0).warnings)
    assert not any("sampling" in w for w in surface_report(fine.heights, 1.0).warnings)


def test_cropped_tile_is_not_periodic_and_missing_points_are_counted():
    h = gaussian(96, 1.0, 1.0, 8.0, seed=6).heights[:70, :80].copy()
    h[10:13, 20:30] = np.nan
    report = surface_report(h, 0.5)
    assert not report.periodic and report.missing == 30
    assert any("not a periodic tile" in w for w in report.warnings)
    assert any("30 of 5600 points missing" in w for w in report.warnings)
    assert np.isfinite(report.heights_stats.Sq) and report.abc is not None


def test_wavelength_gives_the_regime():
    h = gaussian(64, 1.0, 1.0, 8.0, seed=1).heights
    smooth = surface_report(h, 1.0, wavelength=100.0).regime
    rough = surface_report(h, 1.0, wavelength=1.0).regime
    assert smooth.sigma_over_lambda == pytest.approx(0.01, rel=0.05) and smooth.rayleigh_smooth
    assert smooth.optics.startswith("smooth") and rough.optics.startswith("rough")
    assert not rough.rayleigh_smooth


@pytest.mark.parametrize(
    "kw, words",
    [
        ({"heights": np.zeros(16)}, ["heights", "2D"]),
        ({"heights": np.ones((16, 16))}, ["heights", "flat"]),
        ({"heights": np.full((16, 16), np.nan)}, ["heights", "finite"]),
        ({"dx": 0.0}, ["dx"]),
        ({"dx": float("nan")}, ["dx"]),
        ({"wavelength": -1.0}, ["wavelength"]),
    ],
)
def test_bad_arguments_are_refused_in_one_line(kw, words):
    args = {"heights": np.random.default_rng(0).normal(size=(16, 16)), "dx": 1.0, **kw}
    refused(lambda: surface_report(args.pop("heights"), **args), *words)


def _cli(capsys, *args):
    """(status, stdout, stderr lines) of ``microsim ARGS`` in-process."""
    capsys.readouterr()
    try:
        status = main([str(a) for a in args])
    except SystemExit as e:  # argparse's own errors
        status = e.code
    out, err = capsys.readouterr()
    return status, out, err.strip().splitlines()


@pytest.fixture
def heightfile(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    np.save(tmp_path / "h.npy", gaussian(48, 1.0, 1.0, 7.0, seed=0).heights[:40, :44])
    return tmp_path / "h.npy"


def test_cli_reports_a_heightfield_file(capsys, heightfile):
    status, out, err = _cli(capsys, "surface", heightfile, "--dx", "1")
    assert status == 0, err
    assert "Sq" in out and "beckmann" in out and "not periodic" in out
    status, out, err = _cli(capsys, "surface", heightfile, "--dx", "1", "--json")
    assert status == 0, err
    record = json.loads(out)
    assert record["shape"] == [40, 44] and record["best_ndf"] in ("beckmann", "student-t")


def test_chart_is_written(capsys, heightfile):
    status, _, err = _cli(capsys, "surface", heightfile, "--dx", "1", "--chart", "s")
    assert status == 0, err
    assert (heightfile.parent / "s.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    fig = surface_chart(surface_report(np.load(heightfile), 1.0))
    assert len(fig.axes) == 6  # four panels and two colour bars


@pytest.mark.parametrize(
    "make, args, words",
    [
        (None, ["h.npy"], ["--dx", "h.npy"]),
        (None, ["h.npy", "--dx", "-1"], ["--dx"]),
        (None, ["h.npy", "--dx", "abc"], ["--dx"]),
        (None, ["h.npy", "--dx", "1", "--wavelength", "0"], ["--wavelength"]),
        (None, ["missing.npy", "--dx", "1"], ["missing.npy"]),
        (lambda d: (d / "bad.txt").write_text("1 2\nx y\n"), ["bad.txt", "--dx", "1"], ["bad.txt"]),
        (lambda d: np.save(d / "v.npy", np.zeros(20)), ["v.npy", "--dx", "1"], ["v.npy", "2D"]),
        (None, ["h.npy", "--dx", "1", "--chart", "c.jpg"], ["--chart"]),
        (None, ["h.npy", "--dx", "1", "--chart", "no/c.png"], ["--chart", "no"]),
        (None, ["gaussian-m0.3", "--dx", "1"], ["--dx", "gaussian-m0.3"]),
        (None, ["s.toml", "--json"], ["--json", "s.toml"]),
    ],
    ids=[
        "no-dx",
        "dx-negative",
        "dx-text",
        "wavelength-zero",
        "missing-file",
        "bad-text",
        "one-dimensional",
        "chart-suffix",
        "chart-folder",
        "dx-on-catalogue-scene",
        "json-on-scene-file",
    ],
)
def test_cli_bad_input_one_line_status_2_nothing_written(capsys, heightfile, make, args, words):
    if make is not None:
        make(heightfile.parent)
    before = sorted(p.name for p in heightfile.parent.iterdir())
    status, out, err = _cli(capsys, "surface", *args)
    assert status == 2 and len(err) == 1 and out == "", err
    for w in words:
        assert w in err[0], (w, err[0])
    assert sorted(p.name for p in heightfile.parent.iterdir()) == before


def test_cli_reports_a_scan_in_micrometres_with_its_own_spacing(capsys, tmp_path, monkeypatch):
    """An X3P carries its spacing: the report reads it (in µm), keeps the missing points out of
    the statistics and refuses a --dx."""
    from microsim.surfaces import scan

    monkeypatch.chdir(tmp_path)
    h = gaussian(48, 1.0, 1.0, 7.0, seed=0).heights * 1e-6  # metres
    h[3:5, 7:11] = np.nan
    scan.write_x3p("s.x3p", h, 0.5e-6, 0.5e-6)
    status, out, err = _cli(capsys, "surface", "s.x3p", "--json")
    assert status == 0, err
    record = json.loads(out)
    assert record["dx"] == pytest.approx(0.5) and record["missing"] == 8
    assert record["heights_stats"]["Sq"] == pytest.approx(np.nanstd(h) * 1e6, rel=0.05)
    status, out, err = _cli(capsys, "surface", "s.x3p", "--dx", "1")
    assert status == 2 and len(err) == 1 and "--dx" in err[0]
