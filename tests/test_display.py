"""What a notebook and a terminal show: compact HTML for results, verdict lists and fits, short
reprs without arrays, and materials named as the user named them."""

import numpy as np
import pytest

from microsim.analysis import fits
from microsim.analysis.verdicts import VerdictList, verdicts_for_result
from microsim.analytic import Beckmann
from microsim.analytic.fresnel import resolve_material
from microsim.sim import Bins, simulate
from microsim.sim.compare import attach_models, default_models
from microsim.surfaces import vgrooves

SURFACE = vgrooves(300, Beckmann(0.3), seed=1)


@pytest.fixture(scope="module")
def judged():
    res = simulate(SURFACE, "aluminium", [30, 60], rays=40_000, bins=Bins(12, 7), seed=2)
    return attach_models(res, default_models(SURFACE, "aluminium"))


def test_result_html_is_a_small_table_with_the_material_name(judged):
    html = judged._repr_html_()
    assert html.startswith("<table>") and "aluminium" in html and len(html) < 5000
    assert html.count("<tr>") == 1 + len(judged.theta_i)  # header + one row per incidence
    assert "aluminium" in repr(judged)


def test_verdicts_show_as_a_model_by_incidence_table(judged):
    vs = verdicts_for_result(judged)
    assert isinstance(vs, VerdictList) and isinstance(vs, list) and vs == list(vs)
    html = vs._repr_html_()
    assert html.count("<tr>") == 1 + len(judged.models) and "θi = 60°" in html
    assert ("✓" in html) or ("✗" in html)


def test_default_models_repr_shows_array_shapes_not_arrays():
    specs = default_models(SURFACE, "aluminium")
    text = repr(specs)
    assert len(text) < 2000 and "ts-facets" in text
    assert "1200 × 3 normals" in text and "[[" not in text  # the facets' shape, not the array


def test_fit_result_repr_and_html():
    fit = fits.FitResult("cook-torrance", {"ks": 0.9, "m": 0.3}, 1.0, 0.04, 0.01, True, 2,
                         np.zeros((1, 2, 2)), ("m",))  # fmt: skip
    assert "not converged" in repr(fit) and "array" not in repr(fit)
    html = fit._repr_html_()
    assert "cook-torrance" in html and html.count("<tr>") == 3 and "search limit" in html


@pytest.mark.parametrize(
    "text, ior", [("1.5", 1.5), ("0.769+6.08i", 0.769 + 6.08j), (" 1.5 + 0.1j ", 1.5 + 0.1j)]
)
def test_materials_are_accepted_as_microsim_writes_them(text, ior):
    assert resolve_material(text) == ior


def test_a_scene_records_its_material_name(tmp_path):
    from microsim.app.scene import load_scene

    sc = load_scene("vgroove-beckmann-0.3")
    assert sc.material == "aluminium" and sc.ior == resolve_material("aluminium")
