"""Agreement checks for anyone's BRDF and importance sampler, from their own test suite.

    from microsim.testing import assert_brdf_agrees

    def test_my_ggx():
        assert_brdf_agrees(my_ggx, "vgroove-ggx-0.3", theta_i=[0, 30, 60, 80])

``assert_brdf_agrees`` bin-averages the callable as microsim bin-averages its own models and
judges it against a ray-traced explicit surface (``agreement``); the reference simulation is
cached on disk (``cache``: ``reference``, ``cache_dir``; env ``MICROSIM_CACHE``).
``assert_sampler_matches`` is the Pearson χ² harness for importance samplers (``sampler``).
The pytest plugin (``plugin``, entry point ``pytest11``) adds ``--microsim-cache DIR``, the
``microsim_reference`` fixture and the ``microsim`` marker. docs/testing.md has the guide.
"""

from .agreement import Agreement, BRDFMismatch, assert_brdf_agrees, tolerance_check
from .cache import ENV_VAR, cache_dir, find_scene, reference, set_default_dir
from .sampler import SamplerCheck, assert_sampler_matches, pearson_chi2

__all__ = [
    "assert_brdf_agrees",
    "assert_sampler_matches",
    "pearson_chi2",
    "reference",
    "cache_dir",
    "set_default_dir",
    "find_scene",
    "tolerance_check",
    "Agreement",
    "BRDFMismatch",
    "SamplerCheck",
    "ENV_VAR",
]
