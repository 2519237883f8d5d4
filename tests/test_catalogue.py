"""`microsim models` lists every closed form, and every name it lists exists."""

import subprocess
import sys

from microsim import analytic as an
from microsim.analytic.catalogue import MODELS


def _names(entry):
    return [n.strip() for n in entry.name.split("/")]


def test_every_listed_model_exists_in_the_public_namespace():
    missing = [n for m in MODELS for n in _names(m) if not hasattr(an, n)]
    assert not missing, f"catalogue lists names microsim.analytic lacks: {missing}"


def test_every_public_ndf_and_brdf_is_listed():
    listed = {n for m in MODELS for n in _names(m)}
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
        "fresnel",
        "schlick",
        "low_smooth",
        "low_microfacet",
        "rayleigh_rice",
        "edwards_empirical",
        "edwards_fit_brdf",
        "mikkelsen_mix",
    }
    assert required <= listed, required - listed


def test_cli_models_prints_every_entry():
    out = subprocess.run(
        [sys.executable, "-m", "microsim.cli", "models"], capture_output=True, text=True, check=True
    ).stdout
    for m in MODELS:
        assert m.name in out and m.source in out
