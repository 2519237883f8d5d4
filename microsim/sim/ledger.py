"""The names of the ray ledger: what became of every primary ray and of every path.

``LEDGER``: the first-bounce classes of a primary ray, in the order of their codes
(``SINGLE`` … ``RAY_MISSED``, the kernels' ``engine.codes``): the reflected ray escaped
(``single``, tallied in its bin), met the surface again (``masked``), left downwards
(``downward``, wo_z ≤ 0), the walk hit its wrap cap (``unresolved``) or the ray leaked through
the mesh (``missed``). ``TERMINAL``: how a path of the bounce chain ended (``bounces``), in the
order of ``codes.ESC_1`` …; ``ORDER_NAMES``: the labels of the scattering-order slots of
``Result.brdf_orders``. Below the ray engine and the estimator, so that results, tallies and
reports name the classes without importing the code that traces them.
"""

from __future__ import annotations

from .engine import codes

__all__ = [
    "LEDGER",
    "SINGLE",
    "MASKED",
    "DOWNWARD",
    "RAY_UNRESOLVED",
    "RAY_MISSED",
    "TERMINAL",
    "ORDER_NAMES",
]

SINGLE, MASKED, DOWNWARD, RAY_UNRESOLVED, RAY_MISSED = range(5)
LEDGER = ("single", "masked", "downward", "unresolved", "missed")
assert (SINGLE, MASKED, DOWNWARD, RAY_UNRESOLVED, RAY_MISSED) == (
    codes.SINGLE,
    codes.MASKED,
    codes.DOWNWARD,
    codes.RAY_UNRESOLVED,
    codes.RAY_MISSED,
)
TERMINAL = (
    "escaped_1",
    "escaped_2",
    "escaped_3",
    "escaped_4plus",
    "cut_bounces",
    "cut_weight",
    "unresolved_path",
    "missed_path",
)
"""Terminal classes of a path, in the order of ``codes.ESC_1`` …"""
ORDER_NAMES = ("1", "2", "3", "4+")
"""Labels of the order slots of ``Result.brdf_orders``."""
assert len(TERMINAL) == codes.N_TERMINAL and codes.PATH_MISSED == len(TERMINAL) - 1
