"""numba's on-disk cache of the compiled kernels, where the machine offers one.

Every kernel of microsim is compiled with numba's cache: the machine code is kept in the first
writable of ``NUMBA_CACHE_DIR``, the ``__pycache__`` folder beside the module and the user's
cache folder (``~/.cache/numba``), so that later processes load it instead of compiling again
(numba's cache locators, ``numba.core.caching``). Where none of them can be written (a
read-only install, home and cache folder), numba refuses to decorate a cached function at
all; ``cached_njit`` then compiles it uncached — every process compiles it again — and says so
once per process on stderr (``NOTICE``).
"""

from __future__ import annotations

import sys

from numba import njit

__all__ = ["cached_njit", "NOTICE"]

NOTICE = (
    "microsim: numba finds no writable cache folder (NUMBA_CACHE_DIR, the package's "
    "__pycache__, the user's cache folder), so the kernels are compiled in every run; set "
    "NUMBA_CACHE_DIR to a writable folder to keep them"
)

_told: list[bool] = []


def cached_njit(**options):
    """``numba.njit(cache=True, **options)`` as a decorator; where numba finds no writable
    cache folder for the function's module, the function is compiled uncached instead and
    ``NOTICE`` printed (once per process)."""
    compile_uncached = njit(**options)

    def decorate(func):
        dispatcher = compile_uncached(func)
        enable = getattr(dispatcher, "enable_caching", None)  # absent: NUMBA_DISABLE_JIT
        if enable is not None:
            try:
                enable()
            except RuntimeError:  # numba: "cannot cache function …: no locator available"
                _tell_uncached()
        return dispatcher

    return decorate


def _tell_uncached() -> None:
    if _told:
        return
    _told.append(True)
    try:
        print(NOTICE, file=sys.stderr, flush=True)
    except (OSError, ValueError, AttributeError):  # a closed or missing stderr
        pass
