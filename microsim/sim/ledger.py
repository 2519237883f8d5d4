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
    "TRANSMITTED",
    "TIR_ORDERS",
    "DIELECTRIC_TERMINAL",
    "DIELECTRIC_COLUMNS",
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
TRANSMITTED = ("transmitted_1", "transmitted_2", "transmitted_3", "transmitted_4plus")
"""Terminal classes a dielectric interface's paths add (``dielectric``), in the order of
``codes.TRANS_1`` …: left on the side opposite the incidence after that many interactions."""
DIELECTRIC_TERMINAL = TERMINAL + TRANSMITTED
TIR_ORDERS = ("tir_1", "tir_2", "tir_3", "tir_4plus")
"""Ledger columns of a dielectric interface's paths that are not classes: the paths with a
total internal reflection at their 1st, 2nd, 3rd, ≥ 4th interaction (a path may count in
several)."""
DIELECTRIC_COLUMNS = DIELECTRIC_TERMINAL + TIR_ORDERS
"""The path columns of a dielectric interface's ledger: its terminal classes, then the paths
with a total internal reflection at each order."""
ORDER_NAMES = ("1", "2", "3", "4+")
"""Labels of the order slots of ``Result.brdf_orders``."""
assert len(TERMINAL) == codes.N_TERMINAL and codes.PATH_MISSED == len(TERMINAL) - 1
assert len(DIELECTRIC_TERMINAL) == codes.N_TERMINAL_DIELECTRIC
assert DIELECTRIC_TERMINAL.index("transmitted_1") == codes.TRANS_1
