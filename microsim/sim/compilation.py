"""Telling the user, once, that the compiled kernels are being built.

numba compiles each kernel the first time a process calls it and caches the machine code on
disk (docs/reproducibility.md); a fresh install or another CPU therefore spends tens of
seconds compiling before its first run, silently unless told. ``announce_compilation`` prints one
line when the first kernel of ``microsim`` misses the cache, and nothing when every kernel
loads from it.
"""

from __future__ import annotations

import threading

from numba.core import event

__all__ = ["MESSAGE", "announce_compilation"]

MESSAGE = (
    "microsim: compiling the numba kernels for this CPU (once: later runs load them from the cache)"
)


class _FirstCompilation(event.Listener):
    """Writes ``MESSAGE`` to ``stream`` at the first cache miss of a ``microsim`` kernel."""

    def __init__(self, stream):
        self.stream = stream
        self.said = False
        self._lock = threading.Lock()

    def on_start(self, ev):
        func = getattr(ev.data.get("dispatcher"), "py_func", None)
        if not getattr(func, "__module__", "").startswith("microsim."):
            return
        with self._lock:
            if self.said:
                return
            self.said = True
        try:
            print(MESSAGE, file=self.stream, flush=True)
        except (OSError, ValueError, AttributeError):  # a closed or missing stream
            pass

    def on_end(self, ev):
        pass


_INSTALLED: list[_FirstCompilation] = []


def announce_compilation(stream) -> None:
    """Print ``MESSAGE`` to ``stream`` once per process, when the first ``microsim`` kernel
    is compiled rather than loaded from the cache; only where ``stream`` is a terminal (a
    log or a test's captured stderr keeps its one-line-per-event contract). Idempotent."""
    try:
        interactive = stream is not None and stream.isatty()
    except (OSError, ValueError, AttributeError):
        interactive = False
    if not interactive or _INSTALLED:
        return
    listener = _FirstCompilation(stream)
    event.register("numba:compile", listener)
    _INSTALLED.append(listener)
