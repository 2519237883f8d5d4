"""Connecting to a Dask scheduler (``--scheduler ADDRESS``), for ``microsim run`` (one run's
tracing on the cluster, ``sim.cluster``) and ``microsim sweep`` (its tasks on the cluster).

While connected, Dask's own loggers are quiet: microsim reports what goes wrong in one line
(an unreachable scheduler, a scheduler lost mid-run: ``sim.cluster.SchedulerLost``), which a
page of Dask's reconnection tracebacks on stderr would bury."""

from __future__ import annotations

import gc
import logging
from contextlib import contextmanager

from ..errors import EnvironmentFailure, UsageError

__all__ = ["check_address", "connect", "CONNECT_TIMEOUT"]

CONNECT_TIMEOUT = 10.0
"""Seconds to wait for a scheduler before giving up (``--scheduler-timeout``'s default)."""

DASK_LOGGERS = ("distributed", "tornado")
"""Logger trees (with every child logger) quiet while connected: Dask's and its event loop's."""


@contextmanager
def _quiet_dask_logs():
    """Within the block, the ``DASK_LOGGERS`` trees log nothing; their levels are restored."""
    names = [
        name
        for name in [*DASK_LOGGERS, *logging.root.manager.loggerDict]
        if any(name == top or name.startswith(top + ".") for top in DASK_LOGGERS)
    ]
    loggers = [logging.getLogger(name) for name in dict.fromkeys(names)]
    levels = [lg.level for lg in loggers]
    for lg in loggers:
        lg.setLevel(logging.CRITICAL + 1)
    try:
        yield
    finally:
        for lg, level in zip(loggers, levels):
            lg.setLevel(level)


def check_address(scheduler):
    """``--scheduler ADDRESS`` checked without connecting: a non-empty text (what the
    address says is ``connect``'s to judge)."""
    if not (isinstance(scheduler, str) and scheduler.strip()):
        raise UsageError(f"--scheduler must be a Dask scheduler address, got {scheduler!r}")
    return scheduler


@contextmanager
def connect(scheduler, timeout: float = CONNECT_TIMEOUT):
    """Within the block, a ``dask.distributed.Client`` of ``scheduler`` (an address such as
    "tcp://host:8786", or anything ``Client`` accepts, e.g. a ``LocalCluster``), closed on
    exit, with Dask's loggers quiet; one-line errors for a missing extra, a bad address or an
    unreachable scheduler."""
    try:
        from dask.distributed import Client
    except ImportError:
        raise EnvironmentFailure(
            "--scheduler needs dask.distributed, an optional extra: pip install 'microsim[cluster]'"
        ) from None
    with _quiet_dask_logs():
        failure = None
        try:
            client = Client(scheduler, timeout=timeout)
        except ValueError as e:
            failure = UsageError(f"--scheduler {scheduler}: not a Dask scheduler address ({e})")
        except (OSError, TimeoutError) as e:
            failure = EnvironmentFailure(
                f"--scheduler {scheduler}: no Dask scheduler reachable "
                f"there within {timeout:g} s ({' '.join(str(e).split())})"
            )
        if failure is not None:
            # the Client that failed to start is garbage in a reference cycle: finalise it now.
            # Left to a later collection, its __del__ may run inside another Client's start,
            # and both wait on dask's one loop-runner lock (the process hangs)
            gc.collect()
            raise failure from None
        with client:
            yield client
