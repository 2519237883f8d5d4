"""The ``[surface]`` table as one frozen description per kind (``microsim.app.scene_surface``):
read by attribute, the table's keys in its order, each key's check naming the allowed values."""

import dataclasses

import pytest

from microsim import analytic as an
from microsim.app.scene import CATALOGUE as SCENES
from microsim.app.scene import SceneError, load_scene
from microsim.app.scene_surface import (
    SURFACE_TYPES,
    GaussianSurface,
    SurfaceSpec,
    VGrooveSurface,
    surface_spec,
)

CATALOGUE = sorted(SCENES.glob("*.toml"))


@pytest.mark.parametrize("path", CATALOGUE, ids=[p.stem for p in CATALOGUE])
def test_each_scene_surface_is_its_kinds_frozen_description(path):
    spec = load_scene(path).surface
    assert type(spec) is SURFACE_TYPES[spec.kind] and isinstance(spec, SurfaceSpec)
    keys = list(spec.schema())
    if isinstance(spec, VGrooveSurface):
        keys += list(an.scene_distribution(spec.ndf).scene_params)
    assert list(spec.params) == keys  # the table's keys, defaults filled in, in its order
    for key in spec.schema():
        assert spec.params[key] == getattr(spec, key)
    with pytest.raises(dataclasses.FrozenInstanceError):
        spec.kind_was_changed = True


def test_a_vgroove_table_names_its_distribution_parameters():
    spec = surface_spec("f.toml", {"kind": "vgrooves", "ndf": "ggx", "alpha": 1})
    assert spec.ndf_params == {"alpha": 1.0} and type(spec.ndf_params["alpha"]) is float
    assert spec.distribution().alpha == 1.0 and spec.n_grooves == 4000
    with pytest.raises(SceneError, match=r"surface\.alpha: must be a number in \[1e-06, 10\]"):
        surface_spec("f.toml", {"kind": "vgrooves", "ndf": "ggx", "alpha": 20})


def test_a_required_key_and_a_cross_key_check_name_the_key():
    assert GaussianSurface.schema()["dx"][0] == 1.0
    with pytest.raises(SceneError, match=r"f\.toml: surface\.sigma: required; must be a number"):
        surface_spec("f.toml", {"kind": "gaussian", "corr_len": 5})
    with pytest.raises(SceneError, match=r"surface\.corr_len: must be >= dx = 1"):
        surface_spec("f.toml", {"kind": "gaussian", "sigma": 0.1, "corr_len": 0.5})
    with pytest.raises(SceneError, match="allowed keys: kind, size"):
        surface_spec("f.toml", {"kind": "flat", "n": 8})
