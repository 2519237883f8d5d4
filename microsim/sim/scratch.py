"""Per-thread reusable work arrays for the tracing pipeline, declared where they are used.

A chunk of 65 536 rays needs a few dozen arrays of that length between its Embree calls.
Allocated afresh, arrays that large come straight from the operating system and fault in
page by page on first write (~2–5 % of a bench run in system time, unevenly across threads);
reused, they stay mapped. Each such array is declared once, at module level next to the code
that uses it, as a ``WorkArray`` (one array of a fixed dtype, shape (n,) or (n, columns)) or a
``WorkColumns`` (three float64 arrays x, y, z: a point or direction per ray); ``rows=r``
gives views of shape (r, n) instead; a name is
declared at most once in the package (a second declaration raises), so two users can never
share a buffer by accident. ``generations=2`` gives an array two alternating buffers, for a
loop whose step k writes what step k + 1 reads.

Calling a declaration with a length returns a view of this thread's buffer, grown when too
small. Its contents are undefined, and it is valid only until the same thread asks for the
same declaration (and generation) again — so only arrays that a function consumes before it
returns (or hands to its caller for immediate use, as documented there) come from here;
results that outlive the call are allocated normally. Memory stays bounded by the largest
chunk each thread has traced.
"""

from __future__ import annotations

import threading

import numpy as np

__all__ = ["WorkArray", "WorkColumns", "declared"]

_local = threading.local()
_DECLARED: set[str] = set()


def declared() -> frozenset:
    """The names of every work array declared so far."""
    return frozenset(_DECLARED)


class WorkArray:
    """One declared per-thread work array: ``name`` (unique in the package), ``dtype``,
    views of shape (n,), or (n, ``columns``), or (``rows``, n); ``generations`` alternating
    buffers. ``array(n, generation=0)`` is this thread's view for n rays."""

    __slots__ = ("name", "dtype", "columns", "rows", "_keys")

    def __init__(
        self, name: str, dtype=np.float64, columns: int = 1, rows: int = 1, generations: int = 1
    ):
        if name in _DECLARED:
            raise ValueError(f"work array {name!r} is declared twice")
        _DECLARED.add(name)
        self.name, self.dtype = name, np.dtype(dtype)
        self.columns, self.rows = int(columns), int(rows)
        self._keys = tuple((name, g) for g in range(generations))

    def __call__(self, n: int, generation: int = 0) -> np.ndarray:
        n = int(n)
        size = n * self.columns * self.rows
        try:
            buffers = _local.buffers
        except AttributeError:
            buffers = _local.buffers = {}
        key = self._keys[generation]
        buf = buffers.get(key)
        if buf is None or buf.size < size:
            buf = buffers[key] = np.empty(max(size, 1), dtype=self.dtype)
        if self.rows > 1:
            return buf[:size].reshape(self.rows, n)
        return buf[:size] if self.columns == 1 else buf[:size].reshape(n, self.columns)

    def __repr__(self) -> str:
        return f"WorkArray({self.name!r}, {self.dtype}, columns={self.columns})"


class WorkColumns:
    """Three declared float64 work arrays ``name``-x, -y, -z of one length; ``columns(n,
    generation=0)`` is the list [x, y, z] of this thread's views."""

    __slots__ = ("parts",)

    def __init__(self, name: str, generations: int = 1):
        self.parts = tuple(WorkArray(f"{name}-{a}", generations=generations) for a in "xyz")

    def __call__(self, n: int, generation: int = 0) -> list:
        return [p(n, generation) for p in self.parts]
