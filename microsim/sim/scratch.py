"""Per-thread reusable work arrays for the tracing pipeline.

A chunk of 65 536 rays needs a few dozen arrays of that length between its Embree calls.
Allocated afresh, arrays that large come straight from the operating system and fault in
page by page on first write (measured: ~2–5 % of a bench run in system time, unevenly across
threads); reused, they stay mapped. ``work(name, shape, dtype)`` hands out a view of this
thread's buffer for ``name``, grown when too small. Its contents are undefined, and it is
valid only until the same thread asks for ``name`` again — so only arrays that a function
consumes before it returns (or hands to its caller for immediate use, as documented there)
come from here; results that outlive the call are allocated normally. Memory stays bounded
by the largest chunk each thread has traced.
"""

from __future__ import annotations

import threading

import numpy as np

__all__ = ["work"]

_local = threading.local()


def work(name: str, shape, dtype=np.float64) -> np.ndarray:
    """This thread's work array ``name`` viewed as ``shape`` (int or tuple of ints) of
    ``dtype`` (contents undefined; see the module docstring for its lifetime)."""
    if isinstance(shape, (int, np.integer)):
        shape = size = int(shape)
    else:
        size = 1
        for s in shape:
            size *= s
    try:
        buffers = _local.buffers
    except AttributeError:
        buffers = _local.buffers = {}
    buf = buffers.get((name, dtype))
    if buf is None or buf.size < size:
        buf = buffers[(name, dtype)] = np.empty(max(size, 1), dtype=dtype)
    return buf[:size] if isinstance(shape, int) else buf[:size].reshape(shape)
