"""Agreement checks for anyone's BRDF and importance sampler, from their own test suite.

    from microsim.testing import assert_brdf_agrees

    def test_my_ggx():
        assert_brdf_agrees(my_ggx, "vgroove-ggx-0.3", theta_i=[0, 30, 60, 80])

``assert_brdf_agrees`` bin-averages the callable as microsim bin-averages its own models and
judges it against a ray-traced explicit surface (``agreement``); the reference simulation is
cached on disk (``cache``: ``reference``, ``cache_dir``; env ``MICROSIM_CACHE``).
``physics_error`` judges microsim's own Smith model against the same reference, the physics'
own error a failure message reports too (``physics``: ``PhysicsError``,
``PHYSICS_REFERENCES``, the scenes to check each distribution against).
``assert_brdf_matches_model`` checks an implementation against microsim's closed form of the
same model, without rays (``implementation``). ``assert_bsdf_matches_model`` and
``assert_bsdf_agrees`` check a BSDF with transmission (a rough dielectric, wo on either side)
the same way, lobe by lobe (``bsdf``). ``assert_brdf_matches_measured`` judges one
against a measured BRDF — a MERL file, a ``microsim measure`` table — within a tolerance
(``measured``). ``assert_sampler_matches`` is the Pearson χ²
harness for importance samplers (``sampler``).
The pytest plugin (``plugin``, entry point ``pytest11``) adds ``--microsim-cache DIR``, the
``microsim_reference`` fixture and the ``microsim`` marker. docs/testing.md has the guide.
"""

import importlib

_WHERE = {
    "assert_brdf_agrees": "agreement",
    "physics_error": "agreement",
    "PhysicsError": "physics",
    "PHYSICS_REFERENCES": "physics",
    "tolerance_check": "agreement",
    "Agreement": "agreement",
    "BRDFMismatch": "agreement",
    "reference": "cache",
    "cache_dir": "cache",
    "set_default_dir": "cache",
    "find_scene": "cache",
    "ENV_VAR": "cache",
    "assert_brdf_matches_model": "implementation",
    "assert_bsdf_matches_model": "bsdf",
    "assert_bsdf_agrees": "bsdf",
    "assert_brdf_matches_measured": "measured",
    "measured_reference": "measured",
    "assert_sampler_matches": "sampler",
    "pearson_chi2": "sampler",
    "SamplerCheck": "sampler",
    "FLOAT32_RTOL": "sampler",
}
__all__ = list(_WHERE)


def __getattr__(name: str):
    """Import the submodule holding ``name`` on first use (PEP 562), so that loading the
    pytest plugin (``microsim.testing.plugin``) does not import the simulator."""
    if name in _WHERE:
        value = getattr(importlib.import_module(f"{__name__}.{_WHERE[name]}"), name)
        globals()[name] = value
        return value
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def __dir__():
    return sorted(list(globals()) + __all__)
