"""Connecting to a Dask scheduler (``--scheduler ADDRESS``), for ``microsim run`` (one run's
tracing on the cluster, ``sim.cluster``) and ``microsim sweep`` (its tasks on the cluster)."""

from __future__ import annotations

from ..errors import EnvironmentFailure, UsageError

__all__ = ["check_address", "connect", "CONNECT_TIMEOUT"]

CONNECT_TIMEOUT = 10.0
"""Seconds to wait for a scheduler before giving up (``--scheduler-timeout``'s default)."""


def check_address(scheduler):
    """``--scheduler ADDRESS`` checked without connecting: a non-empty text (what the
    address says is ``connect``'s to judge)."""
    if not (isinstance(scheduler, str) and scheduler.strip()):
        raise UsageError(f"--scheduler must be a Dask scheduler address, got {scheduler!r}")
    return scheduler


def connect(scheduler, timeout: float = CONNECT_TIMEOUT):
    """A ``dask.distributed.Client`` of ``scheduler`` (an address such as "tcp://host:8786",
    or anything ``Client`` accepts, e.g. a ``LocalCluster``); one-line errors for a missing
    extra, a bad address or an unreachable scheduler."""
    try:
        from dask.distributed import Client
    except ImportError:
        raise EnvironmentFailure(
            "--scheduler needs dask.distributed, an optional extra: pip install 'microsim[cluster]'"
        ) from None
    try:
        return Client(scheduler, timeout=timeout)
    except ValueError as e:
        raise UsageError(f"--scheduler {scheduler}: not a Dask scheduler address ({e})") from None
    except (OSError, TimeoutError) as e:
        raise EnvironmentFailure(
            f"--scheduler {scheduler}: no Dask scheduler reachable "
            f"there within {timeout:g} s ({' '.join(str(e).split())})"
        ) from None
