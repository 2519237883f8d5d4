"""How scene (and sweep) files are checked: ``SceneError``, the value checks — a predicate
and the words naming the allowed values — and the filling of a table from its schema
(name → (default or ``REQUIRED``, check)), each failure one line naming the file and the key."""

from __future__ import annotations

from typing import Any, Callable

import numpy as np

from microsim.checks import PATH_RULE, is_file_path
from microsim.errors import UsageError

__all__ = [
    "SceneError",
    "Check",
    "REQUIRED",
    "is_int",
    "is_num",
    "int_in",
    "num_in",
    "LENGTH",
    "BOOL",
    "ANGLE",
    "STR",
    "PATH",
    "fail",
    "check_value",
    "check_keys",
    "fill",
]


class SceneError(UsageError):
    """A malformed scene file: the message names the file, the key and the allowed values."""


Check = tuple[Callable[[Any], bool], str]
"""A value check: (predicate, description of the allowed values)."""

REQUIRED = object()
"""The default of a key the table must give."""


def is_int(v) -> bool:
    """An integer, not a bool."""
    return isinstance(v, int) and not isinstance(v, bool)


def is_num(v) -> bool:
    """A finite int or float, not a bool."""
    return isinstance(v, (int, float)) and not isinstance(v, bool) and np.isfinite(v)


def int_in(lo, hi) -> Check:
    """An integer in [lo, hi]."""
    return (lambda v: is_int(v) and lo <= v <= hi, f"an integer in [{lo}, {hi}]")


def num_in(lo, hi) -> Check:
    """A number in [lo, hi]."""
    return (lambda v: is_num(v) and lo <= v <= hi, f"a number in [{lo:g}, {hi:g}]")


LENGTH: Check = (lambda v: is_num(v) and 1e-6 <= v <= 1e6, "a number in [1e-6, 1e6]")
BOOL: Check = (lambda v: isinstance(v, bool), "true or false")
ANGLE: Check = (lambda v: is_num(v) and -360.0 <= v <= 360.0, "degrees in [-360, 360]")
STR: Check = (lambda v: isinstance(v, str), "a string")
PATH: Check = (is_file_path, PATH_RULE)


def fail(where: str, key: str, msg: str):
    """Raise the ``SceneError`` "where: key: msg"."""
    raise SceneError(f"{where}: {key}: {msg}")


def check_value(where, key, value, check: Check):
    """``value`` if ``check`` accepts it, else a ``SceneError`` naming the allowed values."""
    pred, allowed = check
    try:
        ok = bool(pred(value))
    except TypeError:
        ok = False
    if not ok:
        fail(where, key, f"must be {allowed}, got {value!r}")
    return value


def check_keys(where, section, table, allowed) -> None:
    """``table`` is a table whose keys are among ``allowed``."""
    if not isinstance(table, dict):
        fail(where, section, f"must be a table, got {table!r}")
    extra = sorted(set(table) - set(allowed))
    if extra:
        fail(where, f"{section}.{extra[0]}", f"unknown key; allowed keys: {', '.join(allowed)}")


def fill(where, section, table, schema: dict[str, tuple[Any, Check]]) -> dict:
    """The values of ``schema``'s keys (in its order) from ``table``, checked, defaults filled
    in; a missing ``REQUIRED`` key is a ``SceneError``."""
    out = {}
    for key, (default, check) in schema.items():
        if key in table:
            out[key] = check_value(where, f"{section}.{key}", table[key], check)
        elif default is REQUIRED:
            fail(where, f"{section}.{key}", f"required; must be {check[1]}")
        else:
            out[key] = default
    return out
