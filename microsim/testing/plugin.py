"""pytest plugin (entry point ``pytest11``: ``microsim = "microsim.testing.plugin"``).

* ``--microsim-cache DIR``: where reference simulations are cached (``microsim.testing.cache``;
  otherwise ``$MICROSIM_CACHE`` or ``~/.cache/microsim/references``). Every pytest-xdist worker
  gets the same option, and the cache is safe to share between them.
* ``microsim_reference`` fixture: a function ``(scene, **options) -> Result`` — ``scene`` a
  scene file, a catalogue name ("vgroove-ggx-0.3"), a Scene or a Surface; ``options`` those of
  ``microsim.testing.reference`` (material, theta_i, rays, bins, seed, target, max_rays) —
  returning the cached reference ``Result``.
* ``microsim`` marker: for tests that may trace a reference (deselect them with
  ``-m "not microsim"``; a cold cache makes them slow, a warm one fast).

Failures of ``assert_brdf_agrees``/``assert_sampler_matches`` are plain ``AssertionError``s
whose message is the report, so pytest shows them as assertion failures.
"""

from __future__ import annotations

import pytest

MARKER = (
    "microsim: the test may trace a microsim reference simulation (cached on disk; "
    "--microsim-cache DIR or $MICROSIM_CACHE)"
)


def pytest_addoption(parser):
    group = parser.getgroup("microsim", "microsim reference simulations")
    group.addoption(
        "--microsim-cache",
        action="store",
        default=None,
        metavar="DIR",
        help="directory of cached microsim reference simulations "
        "(default: $MICROSIM_CACHE or ~/.cache/microsim/references)",
    )


def pytest_configure(config):
    config.addinivalue_line("markers", MARKER)
    path = config.getoption("--microsim-cache", default=None)
    if path:  # the simulator is imported only when a test asks for the cache
        from .cache import set_default_dir

        set_default_dir(path)


def pytest_unconfigure(config):
    if config.getoption("--microsim-cache", default=None):
        from .cache import set_default_dir

        set_default_dir(None)


@pytest.fixture
def microsim_reference():
    """``microsim_reference(scene, **options)`` → the cached reference ``Result``."""

    from .cache import reference

    def get(scene, **options):
        return reference(scene, **options)

    return get
