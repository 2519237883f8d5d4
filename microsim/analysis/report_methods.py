"""The index subsection "What each method costs", from ``methods.json`` (``microsim bench
--methods``): its loader and checker, and the table of wall times against errors."""

from __future__ import annotations

import os
import re
from dataclasses import dataclass, field
from typing import ClassVar, Mapping, Sequence

from microsim.atomic import read_json
from microsim.errors import UsageError

from .json_record import JsonRecord
from .markdown import md_table, percent
from .report_cells import fmt

__all__ = ["METHODS_COMMAND", "MethodsDocument", "load_methods", "methods_section"]


METHODS_COMMAND = "microsim bench --methods"
_METHODS_KEYS = {
    "machine": ("cpus", "load_average_start", "threads", "commit"),
    "panel": ("title", "scene", "reference", "error_measure", "points"),
    "point": ("method", "kind", "setting", "seconds", "error", "error_se"),
}
"""The keys ``load_methods`` requires of the machine, each panel and each point."""


@dataclass(frozen=True, eq=False)
class MethodPoint(JsonRecord):
    """One timed setting of a method: its wall ``seconds`` and its ``error`` (± ``error_se``;
    ``noise_floor``: the ray noise alone, where known)."""

    method: str = ""
    kind: str = ""
    setting: str = ""
    seconds: float | None = None
    error: float | None = None
    error_se: float | None = None
    noise_floor: float | None = None


@dataclass(frozen=True, eq=False)
class MethodsPanel(JsonRecord):
    """One scene of the study: its ``title``, ``scene``, the ``reference`` (timed
    ``reference_seconds``), the ``error_measure`` and the methods' ``points``."""

    title: str = ""
    scene: str = ""
    reference: str = ""
    reference_seconds: float | None = None
    error_measure: str = ""
    points: tuple[MethodPoint, ...] = ()
    _nested: ClassVar = {"points": MethodPoint}


@dataclass(frozen=True, eq=False)
class Machine(JsonRecord):
    """Where the study ran: ``cpus``, the load average at the start, ``threads``, the
    ``commit`` and whether the worktree had uncommitted changes."""

    cpus: int | None = None
    load_average_start: float | Sequence[float] = 0.0
    threads: int | None = None
    commit: str | None = None
    worktree_modified: bool = False


@dataclass(frozen=True, eq=False)
class MethodsDocument(JsonRecord):
    """``methods.json`` as ``methods_section`` reads it: the ``machine``, the ``panels`` and
    whether the study was ``quick``."""

    machine: Machine = field(default_factory=Machine)
    panels: tuple[MethodsPanel, ...] = ()
    quick: bool = False
    _nested: ClassVar = {"machine": Machine, "panels": MethodsPanel}


def load_methods(path) -> MethodsDocument:
    """``methods.json`` (``microsim bench --methods``) read and checked: top-level ``machine``,
    ``panels``, and the keys ``_METHODS_KEYS`` names in each machine, panel and point; a
    missing, damaged (``atomic.read_json``) or incomplete file raises ``UsageError`` naming
    what is wrong (an ``OSError`` if the environment fails); the file's object, as a
    ``MethodsDocument``."""
    d = read_json(path)
    panels, machine = d.get("panels"), d.get("machine")
    if not isinstance(panels, list) or not all(isinstance(p, dict) for p in panels):
        raise UsageError(f"{path}: no 'panels' list of objects")
    if not isinstance(machine, dict):
        raise UsageError(f"{path}: no 'machine' object")
    missing = [k for k in _METHODS_KEYS["machine"] if k not in machine]
    for i, p in enumerate(panels):
        missing += [f"panels[{i}].{k}" for k in _METHODS_KEYS["panel"] if k not in p]
        for j, q in enumerate(p.get("points") or []):
            missing += [
                f"panels[{i}].points[{j}].{k}" for k in _METHODS_KEYS["point"] if k not in q
            ]
    if missing:
        raise UsageError(f"{path}: missing keys {missing[:5]}{' …' if len(missing) > 5 else ''}")
    return MethodsDocument.from_json(d)


def _setting(text: str) -> str:
    """A method's setting with its ray count written out ("1.02e+07 rays" → "10,200,000 rays")."""
    m = re.fullmatch(r"([0-9.]+(?:e[+-]?[0-9]+)?) rays", str(text))
    return f"{int(round(float(m.group(1)))):,} rays" if m else str(text)


def _methods_rows(panel: MethodsPanel) -> list[list[str]]:
    """Every closed form; of each method with several points (ray counts, tile sizes) the
    first and the last."""
    by: dict[str, list[MethodPoint]] = {}
    for p in panel.points:
        by.setdefault(p.method, []).append(p)
    rows = []
    for method, pts in by.items():
        for p in pts if len(pts) <= 2 else [pts[0], pts[-1]]:
            err = percent(p.error, 3, unit=" %")
            if p.error is not None and p.error_se is not None:
                err = f"{percent(p.error, 3, unit='')} ± {percent(p.error_se, unit=' %')}"
            if p.error_se is None and p.noise_floor is not None:
                err += f" (ray noise alone {percent(p.noise_floor, unit=' %')})"
            rows.append([f"{method}, {_setting(p.setting)}", f"{fmt(p.seconds)} s", err])
    return rows


def methods_section(methods) -> list[str]:
    """Subsection "What each method costs": the chart ``methods.png`` and a table (method,
    wall time, error, scene) from ``methods`` (the path of ``methods.json`` or its dict,
    ``load_methods``); when the file is absent or unreadable, the command that makes it.
    Nothing is timed here: the figures are those of the last ``microsim bench --methods``."""
    head = ["### What each method costs", ""]
    if not isinstance(methods, Mapping):
        if not os.path.isfile(methods):
            return head + [
                f"Not measured yet: `{METHODS_COMMAND}` writes `methods.json` and "
                "`methods.png` here (a few minutes; `--quick` for a small version).",
                "",
            ]
        try:
            methods = load_methods(methods)
        except (OSError, ValueError) as err:
            return head + [f"`methods.json` unreadable ({err}); rerun `{METHODS_COMMAND}`.", ""]
    methods = MethodsDocument.from_json(methods)
    m = methods.machine
    load = m.load_average_start
    load = load[0] if isinstance(load, (list, tuple)) else load
    commit = (m.commit or "unknown")[:7]
    lines = head + [
        "Wall time for one incidence against the error of each method on a geometric scene, "
        "a wave scene and (with the `fullwave` extra) a 1D random grating against rigorous "
        "coupled-wave solutions, each against its own reference (ray-trace errors include their "
        "noise, so they fall with the ray count until the method's own error; ± is one "
        "standard error where a point has one).",
        "",
        "![What each method costs](methods.png)",
        "",
    ]
    for p in methods.panels:
        lines += [
            f"*{p.title}* — scene: {p.scene}; reference: {p.reference}"
            + (
                f" ({fmt(p.reference_seconds)} s)"
                if isinstance(p.reference_seconds, (int, float))
                else ""
            )
            + f"; error: {p.error_measure}.",
            "",
            md_table(["method", "time", "error"], _methods_rows(p)),
            "",
        ]
    lines += [
        f"Measured by `{METHODS_COMMAND}`{' --quick' if methods.quick else ''} on "
        f"{m.cpus} cores at load {float(load):.2f}, commit {commit}"
        f"{' (with uncommitted changes)' if m.worktree_modified else ''}; "
        f"{m.threads} threads; the machine may be shared, so the times are indicative.",
        "",
    ]
    return lines
