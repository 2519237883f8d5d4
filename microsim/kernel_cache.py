"""numba's on-disk cache of the compiled kernels, where the machine offers one.

Every kernel of microsim is compiled with numba's cache: the machine code is kept in the first
writable of ``NUMBA_CACHE_DIR``, the ``__pycache__`` folder beside the module and the user's
cache folder (``~/.cache/numba``), so that later processes load it instead of compiling again
(numba's cache locators, ``numba.core.caching``). Where none of them can be written (a
read-only install, home and cache folder), numba refuses to decorate a cached function at
all; ``cached_njit`` then compiles it uncached — every process compiles it again — and says so
once per process on stderr (``NOTICE``).

A kernel inlines helpers from other modules, and numba checks a cached kernel only against its
own source file (its modification time and size): after an edit of a helper's module it would
load the kernel compiled with the old helper. So every kernel's cache entry is also stamped
with ``PACKAGE_STAMP``, the modification times and sizes of all of microsim's modules: any
change to any of them recompiles the kernels (an installed package only changes on
reinstall; a checkout after every edit or pull).

numba reads a kernel's whole cache index (the types of its compiled signatures, pickled)
before it compares the stamp, so an index written by another version of microsim, whose
signatures name a type that no longer exists, would fail to load with an AttributeError on
every call (an upgrade keeps the old ``__pycache__``; so does a checkout switched to an
older commit). ``cached_njit`` treats an index that cannot be read back as empty: the kernel
is compiled anew and its index rewritten.
"""

from __future__ import annotations

import hashlib
import pickle
import sys
from pathlib import Path

from numba import njit

__all__ = ["cached_njit", "NOTICE", "PACKAGE_STAMP"]


def _package_stamp() -> str:
    """A digest of the modification time and size of every module of the package."""
    digest = hashlib.sha256()
    for path in sorted(Path(__file__).resolve().parent.rglob("*.py")):
        st = path.stat()
        digest.update(f"{path.name}:{st.st_mtime_ns}:{st.st_size};".encode())
    return digest.hexdigest()


PACKAGE_STAMP = _package_stamp()

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
            else:
                _stamp_with_package(dispatcher)
                _read_stale_index_as_empty(dispatcher)
        return dispatcher

    return decorate


def _stamp_with_package(dispatcher) -> None:
    """Add ``PACKAGE_STAMP`` to the source stamp numba's index of ``dispatcher`` is saved with
    and checked against (``numba.core.caching.IndexDataCacheFile``)."""
    index = getattr(getattr(dispatcher, "_cache", None), "_cache_file", None)
    if index is not None and hasattr(index, "_source_stamp"):
        index._source_stamp = (index._source_stamp, PACKAGE_STAMP)


_UNREADABLE = (AttributeError, ImportError, pickle.UnpicklingError, EOFError, TypeError, ValueError)
"""What unpickling an index written by another version of the package can raise."""


def _read_stale_index_as_empty(dispatcher) -> None:
    """Make numba's index of ``dispatcher`` load as empty (a cache miss: compile, then
    overwrite) where it cannot be unpickled, instead of raising on every call."""
    index = getattr(getattr(dispatcher, "_cache", None), "_cache_file", None)
    load = getattr(index, "_load_index", None)
    if load is None:
        return

    def load_index():
        try:
            return load()
        except _UNREADABLE:
            return {}

    index._load_index = load_index


def _tell_uncached() -> None:
    if _told:
        return
    _told.append(True)
    try:
        print(NOTICE, file=sys.stderr, flush=True)
    except (OSError, ValueError, AttributeError):  # a closed or missing stderr
        pass
