"""Thread pool and lazy, in-order scheduling of thread tasks; SIGINT deferred between tasks.

``simulate`` cuts the blocks of each (realisation, incidence) into thread tasks
(``chunk_groups``), runs them on a process-wide pool (``thread_pool``) with at most
``IN_FLIGHT``·threads tasks queued or running (``run_in_order``), and consumes their results
in block order on the calling thread. While it does, Ctrl-C only sets an event
(``DeferredInterrupt``) that is honoured after the task in hand is consumed, so the running
sums are never left half-updated. Memory and the delay before an interrupt is honoured (one
task) do not depend on the number of rays.
"""

from __future__ import annotations

import itertools
import os
import signal
import threading
from collections import deque
from concurrent.futures import Future, ThreadPoolExecutor, wait
from typing import Iterator

__all__ = [
    "IN_FLIGHT",
    "PART_ITEMS",
    "thread_pool",
    "in_parts",
    "chunk_groups",
    "run_in_order",
    "DeferredInterrupt",
]

IN_FLIGHT = 2
"""Thread tasks submitted ahead per thread: the scheduler keeps at most IN_FLIGHT·threads
tasks queued or running, so memory and the reaction to an interrupt do not depend on rays."""

_POOLS: dict = {}
_POOLS_LOCK = threading.Lock()
os.register_at_fork(after_in_child=_POOLS.clear)  # a forked child has none of the threads


def thread_pool(threads: int) -> ThreadPoolExecutor:
    """The process's pool of ``threads`` worker threads, kept between ``simulate`` calls: its
    threads keep their work arrays (``scratch``), so a run does not pay for faulting in fresh
    pages (expensive on this VM: ~4 µs per 4 KiB page), and ``simulate_auto``'s batches do not
    start threads anew."""
    with _POOLS_LOCK:
        if threads not in _POOLS:
            _POOLS[threads] = ThreadPoolExecutor(
                max_workers=threads, thread_name_prefix=f"microsim-{threads}"
            )
        return _POOLS[threads]


def set_up_pool() -> tuple[ThreadPoolExecutor, int]:
    """(pool, parts) for a run's one-off set-up passes split into independent ranges (an
    incidence's facet table, ``facet_tables.facet_table``): the process's pool of one thread
    per core and that many parts, whatever the run's own threads, as ``in_parts``. Call it
    from outside the pool's own tasks."""
    cores = os.cpu_count() or 1
    return thread_pool(cores), cores


PART_ITEMS = 1 << 21
"""Fewest items per part of a one-off pass that ``in_parts`` runs on several threads."""


def in_parts(n: int, fill) -> list:
    """``fill(lo, hi)`` over ``n`` items cut into consecutive ranges, one per core but none
    under ``PART_ITEMS`` items, run on the process's pool of as many threads (``thread_pool``;
    for passes that release the GIL, such as a tracer's set-up: the first touches of a large
    new array then fault its pages in in parallel); their results in order. Call it from
    outside the pool's own tasks."""
    parts = max(1, min(os.cpu_count() or 1, n // PART_ITEMS))
    if parts == 1:
        return [fill(0, n)]
    cuts = [n * k // parts for k in range(parts + 1)]
    return list(thread_pool(parts).map(fill, cuts[:-1], cuts[1:]))


def chunk_groups(start: int, end: int, chunk_blocks: int, threads: int) -> Iterator[range]:
    """Blocks start … end − 1 cut into consecutive thread tasks of ``chunk_blocks`` blocks,
    guided: no task takes more than 1/(2·threads) of the blocks still left, so the tasks
    shrink towards the end and the threads finish together (and a short run still gives
    every thread work). A generator: nothing is built ahead of the scheduler
    (``run_in_order``), whatever the number of blocks."""
    a = start
    while a < end:
        step = min(chunk_blocks, max(1, (end - a) // (2 * threads)))
        yield range(a, a + step)
        a += step


def run_in_order(
    pool: ThreadPoolExecutor, work, groups, depth: int, stop: threading.Event, consume
) -> None:
    """Run ``work(group)`` on ``pool`` for the groups of the iterator ``groups``, submitting
    lazily with at most ``depth`` tasks queued or running, and hand each result to
    ``consume`` in group order (calling thread). Raises KeyboardInterrupt when ``stop`` is set
    after a result was consumed; anything ``consume`` or a task raises propagates. On return
    no task of this call is left queued or running (a cluster's tasks, ``sim.cluster``, are
    cancelled: one still running there finishes unheeded)."""
    groups = iter(groups)
    pending: deque = deque(pool.submit(work, g) for g in itertools.islice(groups, depth))
    try:
        while pending:
            chunk = pending.popleft().result()  # in group order, blocks in block order
            nxt = next(groups, None)
            if nxt is not None:  # keep the pool busy while we tally
                pending.append(pool.submit(work, nxt))
            consume(chunk)
            if stop.is_set():
                raise KeyboardInterrupt
    finally:
        for fut in pending:
            fut.cancel()
        wait([f for f in pending if isinstance(f, Future)])  # a cluster's: cancel() withdraws


class DeferredInterrupt:
    """While active (main thread only), SIGINT sets ``event`` instead of raising, so that the
    running sums are never left half-updated; ``simulate`` checks the event between chunks."""

    def __enter__(self) -> threading.Event:
        self.event = threading.Event()
        self._installed = threading.current_thread() is threading.main_thread()
        if self._installed:
            self._old = signal.signal(signal.SIGINT, lambda signum, frame: self.event.set())
        return self.event

    def __exit__(self, *exc):
        if self._installed:
            signal.signal(
                signal.SIGINT, signal.default_int_handler if self._old is None else self._old
            )
        return False
