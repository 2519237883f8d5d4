"""Scenes with a wavelength: the ``[wave]`` table's checks, ``microsim run`` with
the Kirchhoff solver and the wave verdicts, and Löw's smooth-surface model marked outside its
domain in geometric scenes.

Facts checked: every bad ``[wave]`` input is a one-line error naming the file, the key and
what is allowed or needed (exit 2, nothing written); scenes without ``[wave]`` load as before;
a tiny wave scene runs end to end through ``microsim run --quick``: its Kirchhoff result is
saved, its specular order carries the Davies/Debye–Waller power F(θi)·e^(−g) of the tile the
ray tracer saw (the quick-scaled one), every wave verdict follows the schema and names its
reference, and the report has the section; an interrupt in the wave stage writes no report
and ``--resume`` completes it; a geometric scene's report and index mark ``low-smooth``
outside its domain and keep its fit.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from microsim.analysis.wave_verdicts import WAVE_MODELS, validate_wave_verdict
from microsim.analytic.fresnel import fresnel
from microsim.app.cli import main
from microsim.app.runner import plan_run
from microsim.app.scene import CATALOGUE, MIN_TILE_WAVELENGTHS, SceneError, load_scene
from microsim.errors import UsageError
from microsim.sim import Result

WAVE = """\
name = "tiny-wave"
[surface]
kind = "abc"
n = {n}
dx = {dx}
sigma = {sigma}
B = 5.0
C = 2.5
[material]
ior = "aluminium"
[simulation]
theta_i = [0, 30]
rays = 20000
theta_bins = 9
phi_bins = 7
realisations = 2
seed = 1
{wave}"""
WAVE_TABLE = "[wave]\nwavelength = 0.5\n"


def _write(tmp: Path, text: str, name="tiny-wave") -> Path:
    p = tmp / f"{name}.toml"
    p.write_text(text)
    return p


def _wave_scene(tmp, n=128, dx=0.1, sigma=0.01, wave=WAVE_TABLE, kind=None) -> Path:
    text = WAVE.format(n=n, dx=dx, sigma=sigma, wave=wave)
    if kind is not None:
        text = text.replace('kind = "abc"', kind).replace("B = 5.0\nC = 2.5\n", "")
    return _write(tmp, text)


# --- bad input ---------------------------------------------------------------------------------
@pytest.mark.parametrize(
    "wave, key, words",
    [
        ("[wave]\nupsample = 2\n", "wave.wavelength", ["required", "unit of dx"]),
        ("[wave]\nwavelength = 0\n", "wave.wavelength", ["must be a number > 0", "got 0"]),
        ("[wave]\nwavelength = -0.5\n", "wave.wavelength", ["must be a number > 0"]),
        ('[wave]\nwavelength = "red"\n', "wave.wavelength", ["must be a number > 0"]),
        ("[wave]\nwavelength = 0.5\ncolour = 1\n", "wave.colour", ["unknown key", "wavelength"]),
        (
            '[wave]\nwavelength = 0.5\nsurface_model = "exact"\n',
            "wave.surface_model",
            ['"smooth" or "mesh"'],
        ),
        (
            '[wave]\nwavelength = 0.5\nfresnel_angle = "h"\n',
            "wave.fresnel_angle",
            ['"half" or "incident"'],
        ),
        ("[wave]\nwavelength = 0.5\nupsample = 0\n", "wave.upsample", ["[1, 16]"]),
        (
            '[wave]\nwavelength = 0.5\nsurface_model = "mesh"\nupsample = 2\n',
            "wave.upsample",
            ['must be 1 with surface_model = "mesh"'],
        ),
        # dx = 0.1 ≥ λ/(2(1 + sin 30°)) = 0.1 at λ = 0.3: the orders' phase is not sampled
        ("[wave]\nwavelength = 0.3\n", "surface.dx", ["grid too coarse", "need dx < 0.1"]),
        # tile 128 × 0.1 = 12.8 < 10 λ = 20
        ("[wave]\nwavelength = 2.0\n", "wave.wavelength", ["6.4 wavelengths", ">= 10"]),
    ],
)
def test_bad_wave_table_is_one_line_naming_file_and_key(tmp_path, wave, key, words):
    scene = _wave_scene(tmp_path, wave=wave)
    with pytest.raises(SceneError) as err:
        load_scene(scene)
    msg = str(err.value)
    assert "\n" not in msg and msg.startswith(f"{scene}: {key}:"), msg
    for w in words:
        assert w in msg, msg


def test_wave_needs_a_heightfield_with_a_psd(tmp_path):
    scene = _write(
        tmp_path,
        'name = "vg"\n[surface]\nkind = "vgrooves"\nndf = "beckmann"\nm = 0.3\n'
        "[wave]\nwavelength = 0.5\n",
        "vg",
    )
    with pytest.raises(SceneError, match=r"vg.toml: wave: needs surface.kind gaussian or abc"):
        load_scene(scene)


def test_grid_check_suggests_the_upsampling_that_passes(tmp_path):
    """dx = 0.1 at λ = 0.3 and θi ≤ 30°: the order bound is λ/3 = 0.1; upsample 2 passes."""
    scene = _wave_scene(tmp_path, wave="[wave]\nwavelength = 0.3\n")
    with pytest.raises(SceneError, match="upsample >= 2"):
        load_scene(scene)
    _wave_scene(tmp_path, wave="[wave]\nwavelength = 0.3\nupsample = 2\n")
    assert load_scene(scene).wave.upsample == 2


def test_minimum_tile_is_checked_on_the_quick_tile_at_plan_time(tmp_path):
    """n = 128 at dx = 0.1 holds 25.6 λ of 0.5; --quick halves n: 12.8 λ still passes; at
    λ = 1 the full tile (12.8 λ) loads but the quick one (6.4 λ) is refused before anything is
    written."""
    scene = _wave_scene(tmp_path, wave="[wave]\nwavelength = 1.0\n")
    assert load_scene(scene).wave.wavelength == 1.0
    plan_run(scene, out=tmp_path / "full")  # full size: fine
    with pytest.raises(UsageError) as err:
        plan_run(scene, out=tmp_path / "q", quick=True)
    msg = str(err.value)
    assert "wave.wavelength" in msg and "scale 0.5" in msg and "6.4 wavelengths" in msg
    assert f">= {MIN_TILE_WAVELENGTHS:g}" in msg
    assert sorted(p.name for p in tmp_path.iterdir()) == [scene.name]


def test_height_phase_check_at_plan_time_cli_exit_2_nothing_written(tmp_path, capsys):
    """σ = 0.1 on dx = 0.1 at λ = 0.5: the heights step the phase by more than the grid
    samples; the run is refused with the dx needed and the upsampling to try."""
    scene = _wave_scene(tmp_path, sigma=0.1)
    out = tmp_path / "out"
    assert main(["run", str(scene), "--quick", "--out", str(out), "--no-progress"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1, err
    assert "surface.dx: grid too coarse for wavelength 0.5" in err[0]
    assert "height phase" in err[0] and "need dx/upsample <=" in err[0] and "upsample >=" in err[0]
    assert sorted(p.name for p in tmp_path.iterdir()) == [scene.name]


def test_scenes_without_wave_are_geometric_only():
    for p in sorted(CATALOGUE.glob("*.toml")):
        sc = load_scene(p)
        assert (sc.wave is not None) == p.stem.endswith("-wave"), p


def test_catalogue_wave_scenes_are_smooth_and_transition_regime():
    """σ/λ = 1/77 (g/2 ≤ 1.4 % at θi ≤ 30°: Rayleigh–Rice within ~1–2 % of Kirchhoff) and 1/4,
    aluminium, ABC kind, and both plan in quick mode."""
    want = {"abc-smooth-wave": 0.0065 / 0.5, "abc-transition-wave": 1 / 4}
    for name, ratio in want.items():
        sc = load_scene(CATALOGUE / f"{name}.toml")
        assert sc.surface.kind == "abc" and sc.wave is not None
        assert sc.surface.params["sigma"] / sc.wave.wavelength == pytest.approx(ratio)
        assert sc.ior == load_scene(CATALOGUE / "abc-fractal-c2.toml").ior  # aluminium
        plan_run(CATALOGUE / f"{name}.toml", quick=True, out=Path("/nonexistent/x"))


# --- end to end --------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def wave_run(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("wave")
    scene = _wave_scene(tmp)
    out = tmp / "run"
    argv = ["run", str(scene), "--quick", "--out", str(out), "--no-progress", "--threads", "2"]
    assert main(argv) == 0
    return scene, out


@pytest.mark.integration
def test_wave_scene_runs_end_to_end(wave_run):
    scene, out = wave_run
    doc = json.loads((out / "verdicts.json").read_text())
    w = doc["wave"]
    assert w["reference"] == "kirchhoff" and w["kind"] == "theory-vs-theory"
    # the quick tile: n = 128 × 0.5 = 64 samples of dx = 0.1 → 6.4 = 12.8 λ
    assert w["tile"] == [pytest.approx(6.4)] * 2 and w["realisations"] == 2
    models = {v["model"] for v in w["verdicts"]}
    assert models == set(WAVE_MODELS)
    assert len(w["verdicts"]) == 2 * len(WAVE_MODELS)
    for v in w["verdicts"]:
        validate_wave_verdict(v)
        assert v["reference"] == "kirchhoff" and v["kind"] == "theory-vs-theory"
    # the geometric verdicts stay judged against the ray tracer
    assert all(v.get("reference", "ray-noise") != "kirchhoff" for v in doc["verdicts"])
    kres = Result.load(out / "kirchhoff")
    assert kres.meta["method"] == "kirchhoff" and kres.meta["wavelength"] == 0.5
    assert kres.brdf.shape == (2, 9, 7) and np.all(np.isfinite(kres.brdf))
    # Davies/Debye–Waller: for the tiles' realised rms height σ_r (the band limit keeps part
    # of the nominal σ², never more), |I_00|² = |<e^{i q h}>|² = e^{−g}(1 + O(g²)) with
    # g = (4πσ_r cos θi/λ)² ≤ 0.064 here: the specular order carries F(θi)·e^{−g} to ~g² = 0.4 %.
    s_r = w["realised_sigma_over_lambda"] * 0.5
    assert 0.5 * 0.01 < s_r <= 0.01 * (1 + 1e-9)
    g = (4.0 * math.pi * s_r * np.cos(np.radians([0.0, 30.0])) / 0.5) ** 2
    dw = fresnel(np.cos(np.radians([0.0, 30.0])), "aluminium") * np.exp(-g)
    assert np.allclose(w["g"], g, rtol=1e-12)
    assert np.allclose(w["specular_power"], dw, rtol=1e-2)
    report = (out / "report.md").read_text()
    assert "## Wave optics: closed forms against Kirchhoff (theory vs theory)" in report
    assert report.count("Kirchhoff, theory vs theory") == len(w["verdicts"])
    assert "agreement region (θo)" in report and "deviates" not in report.split("## Wave")[1]
    assert "wave_seconds" in json.loads((out / "timings.json").read_text())


@pytest.mark.slow  # two more analyses of the scene (~30 s on a busy 2-core machine)
@pytest.mark.integration
def test_interrupt_in_the_wave_stage_writes_no_report_and_resume_completes(
    wave_run, tmp_path, monkeypatch
):
    from microsim.app.runner import wave_run as wr

    scene, done = wave_run
    out = tmp_path / "run"

    def interrupted(*a, **k):
        raise KeyboardInterrupt

    monkeypatch.setattr(wr, "kirchhoff_brdf", interrupted)
    argv = ["run", str(scene), "--quick", "--out", str(out), "--no-progress"]
    assert main(argv) == 130
    names = sorted(p.name for p in out.iterdir())
    assert names == ["brdf.npz", "meta.json"], names  # the complete tallies, no report
    monkeypatch.undo()
    assert main(["run", str(scene), "--quick", "--resume", str(out), "--no-progress"]) == 0
    a = json.loads((out / "verdicts.json").read_text())["wave"]
    b = json.loads((done / "verdicts.json").read_text())["wave"]
    assert a == b  # same tiles, same solver: the same verdicts


@pytest.mark.slow  # a whole quick run (12 s); reports/index.md shows the marking too
@pytest.mark.integration
def test_geometric_scene_marks_low_smooth_outside_its_domain(tmp_path):
    from microsim.analysis.report import OUT_OF_DOMAIN, index_report

    scene = _write(
        tmp_path,
        'name = "tiny-vg"\n[surface]\nkind = "vgrooves"\nn_grooves = 400\nndf = "beckmann"\n'
        'm = 0.3\n[material]\nior = "aluminium"\n[simulation]\ntheta_i = [0, 45]\n'
        "rays = 20000\ntheta_bins = 9\nphi_bins = 10\nseed = 3\n",
        "tiny-vg",
    )
    out = tmp_path / "run"
    assert main(["run", str(scene), "--quick", "--out", str(out), "--no-progress"]) == 0
    doc = json.loads((out / "verdicts.json").read_text())
    assert "wave" not in doc and "low-smooth" in doc["outside_domain"]
    assert "low-smooth" in {v["model"] for v in doc["verdicts"]}  # the fit is kept
    report = (out / "report.md").read_text()
    assert f"| low-smooth | {OUT_OF_DOMAIN} |" in report
    fits = report.split("## Fits")[1].split("##")[0]
    assert "| low-smooth |" in fits
    index = index_report([doc], None, True)
    row = next(line for line in index.splitlines() if line.startswith("| [tiny-vg]"))
    assert OUT_OF_DOMAIN in row and "✗" not in row.split("|")[-2]


def test_index_section_where_each_method_holds(tmp_path, monkeypatch):
    """``microsim report``'s regime section: the chart is written and the crossover table
    gives, for Rayleigh–Rice at θi = 0°, the σ/λ between 0.01 (RR above Kirchhoff by ≈ g/2 =
    0.8 %) and 0.3 (g = 14: RR's first-order diffuse power ≈ F·g is many times the reflected
    power, Kirchhoff's is F(1 − e^{−g}) < F); the settings are stated. A reduced map (2 σ,
    32 λ tiles, one incidence) keeps it fast."""
    from microsim.analysis import regimes
    from microsim.analysis.report import index_report
    from microsim.app.runner import catalogue, wave_run

    def tiny(quick):
        maps = [
            regimes.regime_map(f, [0.01, 0.3], (0.0,), tile_over_lambda=32.0)
            for f in ("abc", "gaussian")
        ]
        return {"maps": maps, "settings": "tiny test map"}

    monkeypatch.setattr(catalogue, "regime_maps", tiny)
    reg = catalogue._regimes(tmp_path, True)
    assert (tmp_path / reg["chart"]).stat().st_size > 1000
    text = index_report([], None, True, regimes=reg)
    section = text.split("## Where each method holds")[1]
    assert "Settings: tiny test map." in section and f"]({reg['chart']})" in section
    for fam in ("abc", "gaussian"):
        row = next(r for r in section.splitlines() if r.startswith(f"| {fam} | rayleigh-rice"))
        cell = row.split("|")[3].strip()  # θi = 0°: "σ/λ < x", Rayleigh–Rice holds below x
        assert cell.startswith("σ/λ < "), row
        assert 0.01 < float(cell.removeprefix("σ/λ < ")) < 0.3, row
    assert wave_run.REGIME_QUICK.sigmas < 14  # the quick map is the reduced one
