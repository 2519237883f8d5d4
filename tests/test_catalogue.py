"""`microsim models` lists every closed form, and every name it lists exists."""

import os
import subprocess
import sys

import pytest

from microsim import analytic as an
from microsim.analytic.catalogue import MODELS, REPORT_MODELS, report_names


def _resolve(name):
    obj = an
    for part in name.split("."):
        obj = getattr(obj, part, None)
    return obj


def test_every_listed_model_exists_in_the_public_namespace():
    missing = [n for m in MODELS for n in (m.name, *m.functions) if _resolve(n) is None]
    assert not missing, f"catalogue lists names microsim.analytic lacks: {missing}"


def test_every_public_ndf_and_brdf_is_listed():
    listed = {n for m in MODELS for n in (m.name, *m.functions)}
    required = {
        "Beckmann",
        "GGX",
        "BlinnPhong",
        "VonMisesFisher",
        "ABC",
        "Empirical",
        "torrance_sparrow",
        "vgroove_g",
        "smith_g1",
        "smith_g2",
        "fresnel",
        "schlick",
        "low_smooth",
        "low_microfacet",
        "rayleigh_rice",
        "edwards_empirical",
        "edwards_fit_brdf",
        "mikkelsen_mix",
        "mikkelsen_diffuse",
        "KullaConty",
        "directional_albedo",
        "walk_bin_averages",
        "sample_microfacet",
        "sample_low_smooth",
        "sample_low_microfacet",
        "sample_edwards",
        "sample_visible_normals",
        "low_e1",
        "low_e2",
        *(c.__name__ for c in an.MODEL_CLASSES + an.MASKING_CLASSES),
    }
    assert required <= listed, required - listed


def _words(text: str) -> str:
    """The text without its whitespace (wrapping may split a long token across lines)."""
    return "".join(text.split())


@pytest.mark.parametrize("columns", [pytest.param("60", marks=pytest.mark.slow), "100"])
def test_cli_models_prints_every_entry_wrapped_to_the_terminal(columns):
    out = subprocess.run(
        [sys.executable, "-m", "microsim.app.cli", "models"],
        capture_output=True,
        text=True,
        check=True,
        env={**os.environ, "COLUMNS": columns},
    ).stdout
    assert max(len(line) for line in out.splitlines()) <= int(columns)
    words = _words(out)
    for m in MODELS:
        assert _words(m.label) in words and _words(m.source) in words
        assert _words(m.params) in words
    for m in REPORT_MODELS:
        assert _words(m.source) in words and _words(m.what) in words


def test_every_model_name_the_runner_produces_is_listed():
    """The names of default_models (V-grooves, a heightfield, a flat surface), the fits, the
    wave verdicts and the multiple-scattering section are the names ``microsim models``
    explains: one name per model everywhere."""
    from microsim.analysis import multiple, wave_verdicts
    from microsim.analysis.fits import FIT_MODELS
    from microsim.sim.compare import default_models
    from microsim.surfaces import flat, gaussian, vgrooves

    produced = set(FIT_MODELS) | set(wave_verdicts.WAVE_MODELS) | set(multiple.MODELS)
    produced |= set(multiple.WALK_VERDICTS)
    for surface in (
        vgrooves(50, an.Beckmann(0.3)),
        gaussian(32, 1.0, 0.5, 8.0),
        flat(),
    ):
        produced |= {s.name for s in default_models(surface, "aluminium")}
    assert produced <= report_names(), produced - report_names()
