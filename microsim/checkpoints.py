"""Named interrupt points of the long commands, and the in-process hook the fault tests use.

Every phase of ``microsim run``/``report``/``sweep`` calls ``checkpoint(phase)`` at a place
where stopping is safe (between chunks of rays, before each side study, fit set, chart,
sweep task, catalogue scene). By default it does nothing. A test installs a hook with
``interrupt_at(phase)`` that raises ``KeyboardInterrupt`` there — exactly what Ctrl-C raises —
so the behaviour of every phase under an interrupt is tested deterministically, without
sending signals or racing a progress bar.

Phases (``PHASES``): "simulation" (after each chunk of rays tallied by ``simulate``, in the
main run and in the side studies alike), "side-studies"
(before the stability sweep and each speed run), "fits", "charts", "publish" (just before the
finished directory replaces the old one), "report-scene" (before each scene of
``microsim report``), "report-index" (before the catalogue index), "sweep-task" (after each
finished sweep task is collected).
"""

from __future__ import annotations

from contextlib import contextmanager
from typing import Callable, Iterator

__all__ = ["PHASES", "checkpoint", "interrupt_at", "set_hook"]

PHASES = (
    "simulation",
    "side-studies",
    "fits",
    "charts",
    "publish",
    "report-scene",
    "report-index",
    "sweep-task",
)

_hook: Callable[[str], None] | None = None


def checkpoint(phase: str) -> None:
    """Mark a safe stopping point of ``phase`` (one of ``PHASES``); calls the installed hook."""
    if _hook is not None:
        _hook(phase)


def set_hook(hook: Callable[[str], None] | None) -> Callable[[str], None] | None:
    """Install ``hook(phase)`` (None removes it); returns the previous hook."""
    global _hook
    if hook is not None and not callable(hook):
        raise ValueError(f"hook must be callable or None, got {hook!r}")
    old, _hook = _hook, hook
    return old


@contextmanager
def interrupt_at(phase: str, after: int = 0) -> Iterator[dict]:
    """Within the block, raise ``KeyboardInterrupt`` at the ``after + 1``-th checkpoint of
    ``phase`` (once). Yields a dict whose ``"fired"`` says whether it happened."""
    if phase not in PHASES:
        raise ValueError(f"phase must be one of {', '.join(PHASES)}, got {phase!r}")
    state = {"seen": 0, "fired": False}

    def hook(p: str) -> None:
        if p != phase or state["fired"]:
            return
        state["seen"] += 1
        if state["seen"] > after:
            state["fired"] = True
            raise KeyboardInterrupt

    old = set_hook(hook)
    try:
        yield state
    finally:
        set_hook(old)
