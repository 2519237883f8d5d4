"""The appearance picture (``analysis.pictures``): each pixel of the plane shows its bin's
average times cos θi, seen from the viewing direction the camera geometry gives it.

Facts checked: the pixels' viewing directions are unit vectors above the plane, the image
centre looks along the camera axis on the mirror side; a constant BRDF renders as c·cos θi on
every plane pixel and the sky as NaN; a narrow specular lobe's brightest pixel sees the mirror
direction's bin (or the next one out: the off-specular peak); the chart picks the best and the
worst model by rel RMS and writes a PNG."""

from __future__ import annotations

import math

import numpy as np
import pytest

from microsim.analysis import pictures
from microsim.analytic import Beckmann
from microsim.analytic.models import TorranceSparrow
from microsim.errors import UsageError
from microsim.sim import Bins
from microsim.sim.predict import Predictor, predict

BINS = Bins(45, 37)


def test_view_directions_are_on_the_mirror_side():
    wo, mask = pictures.view_directions(60.0, 0.0, 81, 41)
    assert mask.all()  # 60° ± 19° vertically: the plane fills the frame
    assert not pictures.view_directions(80.0, 0.0, 81, 41)[1].all()  # the horizon in it
    np.testing.assert_allclose(np.linalg.norm(wo, axis=-1), 1.0, rtol=1e-12)
    assert np.all(wo[mask][:, 2] > 0)
    centre = wo[20, 40]
    t = math.radians(60.0)
    np.testing.assert_allclose(centre, [-math.sin(t), 0.0, math.cos(t)], atol=1e-12)
    with pytest.raises(UsageError, match="view_theta"):
        pictures.view_directions(90.0, 0.0)


def test_a_constant_brdf_renders_flat_and_the_sky_is_empty():
    wo, mask = pictures.view_directions(45.0, 0.0)
    img = pictures.render(np.full(BINS.shape, 0.7), BINS, wo, mask, 30.0, 0.0)
    np.testing.assert_allclose(img[mask], 0.7 * math.cos(math.radians(30.0)), rtol=1e-12)
    assert np.all(np.isnan(img[~mask]))


def test_the_highlight_is_where_the_mirror_direction_is():
    spec = Predictor("ts", TorranceSparrow(Beckmann(0.1), "smith-correlated", "aluminium"))
    theta = 50.0
    values = predict([spec], [theta], BINS)["ts"][0]
    wo, mask = pictures.view_directions(theta, 0.0, 241, 161)
    img = pictures.render(values, BINS, wo, mask, theta, 0.0)
    k = np.unravel_index(np.nanargmax(img), img.shape)
    t = math.radians(theta)
    mirror = BINS.locate(np.array([[-math.sin(t), 0.0, math.cos(t)]]))[0]
    # the mirror bin, or its neighbour towards grazing: f's 1/cos θo moves the peak outward
    assert BINS.locate(wo[k][None])[0] in (mirror, mirror + BINS.n_phi)


class _FakeResult:
    """The fields of a Result the chart reads."""

    def __init__(self, brdf, counts):
        self.theta_i, self.phi_i = np.array([60.0]), np.array([0.0])
        self.bins, self.brdf, self.counts = BINS, brdf[None], counts[None]


def test_the_chart_shows_the_best_and_the_worst_model(tmp_path):
    specs = [
        Predictor(n, TorranceSparrow(Beckmann(m), "smith-correlated", "aluminium"))
        for n, m in (("near", 0.3), ("far", 0.5), ("exact", 0.31))
    ]
    models = {k: v for k, v in predict(specs, [60.0], BINS).items()}
    sim = models["exact"][0]
    verdicts = [
        {"theta_i": 60.0, "phi_i": 0.0, "model": n, "rel_rms": r}
        for n, r in (("near", 0.05), ("far", 0.4), ("exact", 0.01))
    ]
    res = _FakeResult(sim, np.full(BINS.shape, 1000))
    fig = pictures.appearance(res, models, verdicts, 0, tmp_path / "a.png", "test")
    titles = [ax.get_title() for ax in fig.axes]
    assert "best: exact" in titles and "worst: far" in titles
    assert (tmp_path / "a.png").stat().st_size > 10_000
