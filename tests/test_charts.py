"""Report charts: each returns its Figure and writes a PNG of the stated pixel size, not blank,
showing the simulation's and the models' colours, atomically (no temporary leftovers; an existing
file replaced whole); with ``ax=`` a chart draws into the caller's axes, with ``path=None`` it
writes nothing."""

import os

import matplotlib.figure
import matplotlib.image
import numpy as np
import pytest
from matplotlib.backends.backend_agg import FigureCanvasAgg

from microsim import analytic as an
from microsim import surfaces as sf
from microsim.analysis import chart_style
from microsim.analysis import charts as ch
from microsim.analytic.models import TorranceSparrow
from microsim.sim import Bins, simulate
from microsim.sim.predict import Predictor, predict

PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
COLOUR_TOL = 12 / 255  # max per-channel distance for a pixel to "be" a colour
MIN_PIXELS = 15  # a drawn line/marker/frame covers far more pixels than this
CONTROL = "#00ff00"  # pure green: drawn by no chart, so its count must be zero


def rgb(hex_colour):
    h = hex_colour.lstrip("#")
    return np.array([int(h[i : i + 2], 16) for i in (0, 2, 4)]) / 255.0


def load(path):
    img = matplotlib.image.imread(path)
    assert img.ndim == 3 and img.shape[2] in (3, 4)
    return img[..., :3]


def count_colour(img, hex_colour):
    return int(np.sum(np.all(np.abs(img - rgb(hex_colour)) <= COLOUR_TOL, axis=-1)))


def check_png(path, size_in, colours):
    """The PNG at ``path``: ``size_in`` × DPI pixels (±1 for float rounding), not blank, every
    colour in ``colours`` present and the control colour absent."""
    with open(path, "rb") as fh:
        assert fh.read(8) == PNG_SIGNATURE
    img = load(path)
    w, h = size_in
    assert abs(img.shape[1] - w * ch.DPI) <= 1 and abs(img.shape[0] - h * ch.DPI) <= 1
    assert img.mean(axis=-1).std() > 0.05, "image is (nearly) blank"
    for c in colours:
        assert count_colour(img, c) >= MIN_PIXELS, f"colour {c} missing"
    assert count_colour(img, CONTROL) == 0
    assert not [f for f in os.listdir(os.path.dirname(path)) if f.endswith(".tmp")]


# --- a real tiny run ---------------------------------------------------------------------------
NDF = an.Beckmann(0.3)
MODELS = ("ts-vgroove", "ts-ggx")


@pytest.fixture(scope="module")
def run():
    ior = an.resolve_material("aluminium")
    bins = Bins(12, 13)
    res = simulate(sf.vgrooves(400, NDF, seed=0), ior, [0.0, 45.0], rays=20_000, bins=bins, seed=3)
    models = predict(
        [
            Predictor("ts-vgroove", TorranceSparrow(NDF, "vgroove", ior)),
            Predictor("ts-ggx", TorranceSparrow(an.GGX(0.6), "smith", ior)),
        ],
        res.theta_i,
        bins,
        rtol=1e-2,
    )
    return res, models


def verdicts_of(res, models):
    """Minimal verdict dicts (the keys the hemisphere chart reads), computed from the run."""
    out = []
    for t, th in enumerate(res.theta_i):
        ok = res.stderr[t] > 0
        for name, m in models.items():
            z = (res.brdf[t][ok] - m[t][ok]) / res.stderr[t][ok]
            rel = np.sqrt(np.sum((res.brdf[t] - m[t])[ok] ** 2) / np.sum(res.brdf[t][ok] ** 2))
            out.append(
                {
                    "theta_i": float(th),
                    "model": name,
                    "rel_rms": float(rel),
                    "chi2_dof": float(np.mean(z**2)),
                    "max_abs_z": float(np.abs(z).max()),
                    "agrees": bool(np.abs(z).max() < 5),
                }
            )
    return out


def test_model_styles_fixed_and_no_colour_twice_in_a_chart():
    """One style per model (stable, case/underscore-insensitive); in any chart the models get
    distinct colours, none the simulation's: the heightfield set (nominal and realised
    Beckmann with each G, facets, the fits) and the V-groove set, with new names mixed in."""
    from microsim.analytic.catalogue import report_names

    assert ch.model_style("ts-vgroove") == ch.model_style("TS_vgroove")
    assert ch.model_style("some new model") == ch.model_style("some new model")
    assert all(n.replace("_", "-") in chart_style._STYLES for n in report_names())
    heightfield = [f"ts-beckmann-{v}-{g}" for v in ("nominal", "realised")
                   for g in ("vgroove", "smith", "smith-corr")]  # fmt: skip
    fits = ["cook-torrance", "low-microfacet", "low-smooth", "edwards"]
    for names in (
        heightfield + ["ts-facets"] + fits,
        ["ts-vgroove", "ts-smith", "ts-smith-corr", "ts-facets"] + fits,
        ["ts-vgroove", "my model", "another model", "ts-smith", "model 7"],
    ):
        styles = ch.chart_styles(names)
        colours = [c for c, _ in styles.values()]
        assert len(set(colours)) == len(colours), styles
        for c in colours:
            assert np.abs(rgb(c) - rgb(ch.SIM_COLOUR)).max() > 3 * COLOUR_TOL
    nominal, realised = ch.model_style(heightfield[0]), ch.model_style(heightfield[3])
    assert nominal[0] != realised[0] and nominal[1] != realised[1]


def test_inplane_curves(run, tmp_path):
    res, models = run
    p = tmp_path / "inplane.png"
    ch.inplane_curves(res, models, p, "tiny V-grooves")
    check_png(
        p,
        ch.figure_size("inplane", len(res.theta_i)),
        [ch.SIM_COLOUR] + [ch.model_colour(n) for n in MODELS],
    )
    assert count_colour(load(p), ch.model_colour("ts-smith")) == 0  # a model not drawn


def test_hemisphere_maps_best_and_worst(run, tmp_path):
    res, models = run
    verdicts = verdicts_of(res, models)
    p = tmp_path / "hemi.png"
    ch.hemisphere_maps(res, models, verdicts, p, 1, scene_name="tiny")
    check_png(
        p, ch.figure_size("hemisphere_maps"), [ch.SIM_COLOUR] + [ch.model_colour(n) for n in MODELS]
    )
    # nested containers (per incidence, per model) are accepted as well
    nested = {float(t): {v["model"]: v for v in verdicts if v["theta_i"] == t} for t in res.theta_i}
    nested[0.0]["ts-ggx"].update(chi2_dof=None, max_abs_z=None)  # undefined numbers
    ch.hemisphere_maps(res, models, nested, tmp_path / "hemi2.png", 0)
    check_png(tmp_path / "hemi2.png", ch.figure_size("hemisphere_maps"), [ch.SIM_COLOUR])


def test_hemisphere_maps_rejects_bad_index_and_missing_verdicts(run, tmp_path):
    res, models = run
    with pytest.raises(ValueError, match="t_index"):
        ch.hemisphere_maps(res, models, verdicts_of(res, models), tmp_path / "x.png", 2)
    with pytest.raises(ValueError, match="verdicts"):
        ch.hemisphere_maps(res, models, [], tmp_path / "x.png", 0)
    assert not os.listdir(tmp_path)


def test_unfold_covers_the_circle_and_mirrors_the_folded_half():
    bins = Bins(3, 5)
    v = np.arange(15.0).reshape(3, 5)
    ang, full = ch._unfold(v, bins)
    assert ang[0] == pytest.approx(-np.pi) and ang[-1] == pytest.approx(np.pi)
    assert np.all(np.diff(ang) > 0) and full.shape == (3, len(ang) - 1)
    np.testing.assert_array_equal(full, full[:, ::-1])  # symmetric in ±Δφ


def test_energy_chart(run, tmp_path):
    res, _ = run
    g = np.linspace(0.0, 89.0, 60)
    rho_models = {
        "ts-vgroove": (g, an.AlbedoTable(NDF, "vgroove", "aluminium").rho(np.cos(np.radians(g))))
    }
    rho = res.ledger["single_fresnel"]
    err = np.sqrt(rho * (1 - rho) / res.rays)
    lost = {"masked": res.ledger["masked_fresnel"], "downward": res.ledger["downward_fresnel"]}
    p = tmp_path / "energy.png"
    ch.energy_chart(res.theta_i, rho, err, rho_models, lost, p, scene_name="tiny")
    check_png(p, ch.figure_size("energy"), [ch.SIM_COLOUR, ch.model_colour("ts-vgroove")])
    p = tmp_path / "energy2.png"
    ch.energy_chart(res.theta_i, rho, err, rho_models, res.ledger["lost_fresnel"], p)
    check_png(p, ch.figure_size("energy"), [ch.SIM_COLOUR])


def test_mikkelsen_fig6(tmp_path):
    g = np.linspace(0.0, 89.5, 90)
    sim_t = np.arange(0.0, 90.0, 15.0)
    curves = []
    for mat in ("methanol", "aluminium"):
        ior = an.resolve_material(mat)
        ft = an.fresnel_transmittance(np.cos(np.radians(g)), ior)
        for kappa in (17, 1024):
            tab = an.AlbedoTable(
                an.VonMisesFisher(kappa), "vgroove", ior, n_theta=10, n_grazing=4, n_gl_phi=4
            )
            one_minus = 1 - tab.rho(np.cos(np.radians(g)))
            sim = 1 - tab.rho(np.cos(np.radians(sim_t)))
            curves.append(
                {
                    "label": f"{mat} κ={kappa}",
                    "theta": g,
                    "one_minus_rho_model": one_minus,
                    "fresnel_T": ft,
                    "sim_theta": sim_t,
                    "sim_one_minus_rho": sim,
                    "sim_err": np.full_like(sim, 0.01),
                }
            )
    p = tmp_path / "fig6.png"
    ch.mikkelsen_fig6(curves, p)
    check_png(
        p,
        ch.figure_size("mikkelsen_fig6", 2),
        [ch.SIM_COLOUR, ch.FRESNEL_COLOUR, ch.model_colour("κ=17"), ch.model_colour("κ=1024")],
    )
    first, last = ch.Fig6Curve.of(curves[0]), ch.Fig6Curve.of(curves[-1])
    assert first.series == "κ=17" and last.material == "aluminium"


def test_speed_accuracy(tmp_path):
    t = np.geomspace(0.5, 50.0, 6)
    runs = {"stratified": (t, 0.01 / np.sqrt(t)), "independent": (t * 1.2, 0.03 / np.sqrt(t))}
    p = tmp_path / "speed.png"
    ch.speed_accuracy(runs, p)
    check_png(
        p,
        ch.figure_size("speed_accuracy"),
        [ch.model_colour("stratified"), ch.model_colour("independent")],
    )


def test_stability_chart_and_fail_ranges(tmp_path):
    th = np.arange(0.0, 90.0, 1.0)
    rel = {"ts-vgroove": 0.003 + 0.2 * np.exp((th - 89) / 6), "ts-smith": np.full_like(th, 0.004)}
    warnings = ["unresolved rays at grazing incidence", "lobe narrower than a bin"]
    p = tmp_path / "stab.png"
    ch.stability_chart(th, rel, p, warnings)
    check_png(
        p,
        ch.figure_size("stability", len(warnings)),
        [ch.model_colour("ts-vgroove"), ch.model_colour("ts-smith")],
    )
    e = np.array([0.01, 0.06, 0.07, 0.01, np.nan, 0.2])
    assert ch._fail_ranges(np.arange(6.0), e, 0.05) == [(1.0, 2.0), (5.0, 5.0)]
    assert ch._fail_ranges(np.arange(3.0), np.full(3, 0.01), 0.05) == []


def test_existing_file_replaced_whole_and_kept_on_failure(tmp_path, monkeypatch):
    path = tmp_path / "chart.png"
    path.write_bytes(b"old contents " * 10_000)
    runs = {"stratified": ([1.0, 4.0], [0.1, 0.05])}
    ch.speed_accuracy(runs, path)
    data = path.read_bytes()
    assert data.startswith(PNG_SIGNATURE) and b"old contents" not in data
    assert os.listdir(tmp_path) == ["chart.png"]

    def broken(self, fh, **kwargs):
        fh.write(b"partial")
        raise RuntimeError("disk full")

    monkeypatch.setattr(matplotlib.figure.Figure, "savefig", broken)
    with pytest.raises(RuntimeError, match="disk full"):
        ch.speed_accuracy(runs, path)
    assert path.read_bytes() == data
    assert os.listdir(tmp_path) == ["chart.png"]


def test_figure_size_rejects_unknown_chart():
    with pytest.raises(ValueError, match="chart"):
        ch.figure_size("pie")


def _agg_figure(size=(8.0, 6.0)):
    fig = matplotlib.figure.Figure(figsize=size, dpi=ch.DPI)
    FigureCanvasAgg(fig)
    return fig


def test_charts_return_the_figure_and_draw_into_given_axes(run, tmp_path):
    """path=None writes nothing and returns a Figure; ax= draws into the caller's axes (the
    caller's figure is returned, the panels get the chart's content)."""
    res, models = run
    fig = ch.inplane_curves(res, models)
    assert isinstance(fig, matplotlib.figure.Figure) and fig.axes
    speed = ch.speed_accuracy({"stratified": ([1.0, 4.0], [0.1, 0.05])})
    assert speed.axes[0].get_xscale() == "log"
    assert not os.listdir(tmp_path)

    mine = _agg_figure()
    axes = mine.subplots(1, 2)
    assert ch.inplane_curves(res, models, ax=axes) is mine
    assert [a.get_yscale() for a in axes] == ["log", "log"]
    assert axes[1].get_title() == f"θi = {res.theta_i[1]:g}°"

    polar = _agg_figure((13.0, 8.6))
    hemi = polar.subplots(2, 3, subplot_kw={"projection": "polar"})
    out = tmp_path / "hemi-ax.png"
    assert ch.hemisphere_maps(res, models, verdicts_of(res, models), out, 1, ax=hemi) is polar
    check_png(out, (13.0, 8.6), [ch.SIM_COLOUR] + [ch.model_colour(n) for n in MODELS])

    g = np.linspace(0.0, 89.0, 30)
    pair = _agg_figure().subplots(1, 2)
    ch.energy_chart(
        res.theta_i,
        res.ledger["single_fresnel"],
        np.zeros(2),
        {"ts-vgroove": (g, np.ones_like(g))},
        res.ledger["lost_fresnel"],
        ax=pair,
    )
    assert pair[0].get_ylabel().startswith("ρ")
    three = _agg_figure().subplots(3, 1)
    ch.stability_chart(g, {"ts-vgroove": 0.01 + g / 900}, ax=three, warnings=["note"])
    assert three[1].get_title().startswith("θi where")
    assert not [p for p in os.listdir(tmp_path) if p != "hemi-ax.png"]


def test_given_axes_are_checked(run):
    res, models = run
    with pytest.raises(ValueError, match="ax must be 2"):
        ch.inplane_curves(res, models, ax=_agg_figure().subplots(1, 3))
    with pytest.raises(ValueError, match="polar"):
        ch.hemisphere_maps(
            res, models, verdicts_of(res, models), t_index=1, ax=_agg_figure().subplots(2, 3)
        )
