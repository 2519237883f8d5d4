"""The index subsection "What each method costs", from ``methods.json`` (``microsim bench
--methods``): its loader and checker, and the table of wall times against errors."""

from __future__ import annotations

import os
import re
from typing import Mapping

from microsim.atomic import read_json
from microsim.errors import UsageError

from .markdown import md_table, percent
from .report_cells import fmt

__all__ = ["METHODS_COMMAND", "load_methods", "methods_section"]


METHODS_COMMAND = "microsim bench --methods"
_METHODS_KEYS = {
    "machine": ("cpus", "load_average_start", "threads", "commit"),
    "panel": ("title", "scene", "reference", "error_measure", "points"),
    "point": ("method", "kind", "setting", "seconds", "error", "error_se"),
}


def load_methods(path) -> dict:
    """``methods.json`` (``microsim bench --methods``) read and checked: top-level ``machine``,
    ``panels``, and the keys ``_METHODS_KEYS`` names in each machine, panel and point; a
    missing, damaged (``atomic.read_json``) or incomplete file raises ``UsageError`` naming
    what is wrong (an ``OSError`` if the environment fails)."""
    d = read_json(path)
    if not isinstance(d.get("panels"), list) or not all(isinstance(p, dict) for p in d["panels"]):
        raise UsageError(f"{path}: no 'panels' list of objects")
    if not isinstance(d.get("machine"), dict):
        raise UsageError(f"{path}: no 'machine' object")
    missing = [k for k in _METHODS_KEYS["machine"] if k not in d["machine"]]
    for i, p in enumerate(d["panels"]):
        missing += [f"panels[{i}].{k}" for k in _METHODS_KEYS["panel"] if k not in p]
        for j, q in enumerate(p.get("points") or []):
            missing += [
                f"panels[{i}].points[{j}].{k}" for k in _METHODS_KEYS["point"] if k not in q
            ]
    if missing:
        raise UsageError(f"{path}: missing keys {missing[:5]}{' …' if len(missing) > 5 else ''}")
    return d


def _setting(text: str) -> str:
    """A method's setting with its ray count written out ("1.02e+07 rays" → "10,200,000 rays")."""
    m = re.fullmatch(r"([0-9.]+(?:e[+-]?[0-9]+)?) rays", str(text))
    return f"{int(round(float(m.group(1)))):,} rays" if m else str(text)


def _methods_rows(panel: Mapping) -> list[list[str]]:
    """Every closed form; of each method with several points (ray counts, tile sizes) the
    first and the last."""
    by: dict[str, list] = {}
    for p in panel["points"]:
        by.setdefault(p["method"], []).append(p)
    rows = []
    for method, pts in by.items():
        for p in pts if len(pts) <= 2 else [pts[0], pts[-1]]:
            err = percent(p["error"], 3, unit=" %")
            if p["error"] is not None and p.get("error_se") is not None:
                err = f"{percent(p['error'], 3, unit='')} ± {percent(p['error_se'], unit=' %')}"
            if p.get("error_se") is None and p.get("noise_floor") is not None:
                err += f" (ray noise alone {percent(p['noise_floor'], unit=' %')})"
            rows.append([f"{method}, {_setting(p['setting'])}", f"{fmt(p['seconds'])} s", err])
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
    m = methods["machine"]
    load = m["load_average_start"]
    load = load[0] if isinstance(load, (list, tuple)) else load
    commit = (m.get("commit") or "unknown")[:7]
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
    for p in methods["panels"]:
        lines += [
            f"*{p['title']}* — scene: {p['scene']}; reference: {p['reference']}"
            + (
                f" ({fmt(p['reference_seconds'])} s)"
                if isinstance(p.get("reference_seconds"), (int, float))
                else ""
            )
            + f"; error: {p['error_measure']}.",
            "",
            md_table(["method", "time", "error"], _methods_rows(p)),
            "",
        ]
    lines += [
        f"Measured by `{METHODS_COMMAND}`{' --quick' if methods.get('quick') else ''} on "
        f"{m['cpus']} cores at load {float(load):.2f}, commit {commit}"
        f"{' (with uncommitted changes)' if m.get('worktree_modified') else ''}; "
        f"{m['threads']} threads; the machine may be shared, so the times are indicative.",
        "",
    ]
    return lines
