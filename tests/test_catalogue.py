"""`microsim models` lists every closed form, and every name it lists exists."""

import subprocess
import sys

from microsim import analytic as an
from microsim.analytic.catalogue import MODELS


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


def test_cli_models_prints_every_entry():
    out = subprocess.run(
        [sys.executable, "-m", "microsim.app.cli", "models"],
        capture_output=True,
        text=True,
        check=True,
    ).stdout
    for m in MODELS:
        assert m.label in out and m.source in out and m.params in out
