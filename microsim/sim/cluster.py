"""One run's tracing spread over a Dask cluster, bitwise the local run.

The calling process (the client) plans and tallies exactly as a local run does: it walks the
realisations, incidences and block ranges in the same order and adds each range's per-block
tallies in block order (``tallies.Tally.add_chunk``). A block's tallies depend only on
(seed, realisation, incidence, block) — its random stream (``streams``) — not on where or in
which task it was traced, so the sums, and the ``Result``, are the local run's bit for bit
(on workers of the same instruction set: NumPy and numba dispatch on it). Workers only trace:
a task is (surface, incidence, block range) → that range's per-block tallies.

* Surfaces: each realisation is built on the client (as locally) and sent once to every
  worker (``Client.scatter(..., broadcast=True)``: a copy survives the loss of any one
  worker; a worker that joins later fetches it from a peer), which keeps it, with its
  prepared tracer (``tracer_cache.tracer_for``'s reuse) and chain tasks, for all its tasks of that
  realisation. It is released when the realisation is done.
* Memory: at most ``IN_FLIGHT_PER_THREAD`` × (the cluster's threads) tasks are submitted ahead
  (``schedule.run_in_order``), so the client's memory does not grow with the ray count.
* A worker lost mid-run: Dask recomputes its unfinished tasks on the others; their results
  were never tallied, so nothing counts twice (a task lost with
  ``distributed.scheduler.allowed-failures`` workers in a row fails the run).
* Ctrl-C: as locally — the chunk in hand is tallied, the queued tasks are cancelled, and the
  partial ``Result`` keeps every tallied block for a resume.
* The scheduler lost mid-run (killed, its host or the network gone): Dask cancels every task
  of the client; the run stops as after a Ctrl-C, with every block tallied so far, but raises
  ``SchedulerLost`` (an ``EnvironmentFailure``) carrying that partial ``Result``, which a
  ``resume`` — locally or on another cluster — completes to the uninterrupted run bit for bit.
"""

from __future__ import annotations

from concurrent.futures import CancelledError
from contextlib import contextmanager
from dataclasses import dataclass

from microsim.errors import EnvironmentFailure, UsageError
from microsim.vectors import spherical_deg

from .bounces import chain_task
from .paths import Incidence
from .tallies import ChunkTallies
from .tracer_cache import tracer_for

__all__ = [
    "ClusterPool",
    "RemoteSurface",
    "SchedulerLost",
    "check_client",
    "tracer_info",
    "IN_FLIGHT_PER_THREAD",
]

MIN_TASK_BLOCKS = 64
"""Blocks (of ``streams.BLOCK`` = 4096 rays) a cluster task carries at least, but for the
shrinking last tasks of an incidence (``schedule.chunk_groups``): Dask's own cost per task —
about 4.5 ms on a LocalCluster of this 2-core machine — then stays near a tenth of the
tracing's."""

IN_FLIGHT_PER_THREAD = 4
"""Tasks submitted ahead per worker thread: more than locally (``schedule.IN_FLIGHT``), as
each result crosses the network before the client can tally it."""


def check_client(client):
    """``client`` if it is a usable ``dask.distributed.Client`` (has workers), else a
    ``UsageError`` naming ``cluster``."""
    if client is None:
        return None
    if not all(callable(getattr(client, a, None)) for a in ("submit", "scatter", "nthreads")):
        raise UsageError(
            f"cluster must be a dask.distributed.Client (or None: local threads), got "
            f"{type(client).__name__}"
        )
    return client


class SchedulerLost(EnvironmentFailure):
    """The Dask scheduler at ``address`` was lost mid-run. ``partial``: the run's ``Result``
    of every block tallied before (``meta["partial"]``, ``meta["scheduler_lost"]``: the
    address), to continue with ``estimate(..., resume=partial)``; set by ``estimate``."""

    def __init__(self, address: str, partial=None):
        super().__init__(f"the Dask scheduler {address} was lost mid-run")
        self.address, self.partial = address, partial


def _connected(client) -> bool:
    """Whether ``client`` still talks to its scheduler (Dask's status "running")."""
    return client.status == "running"


@contextmanager
def _scheduler_calls(client):
    """``SchedulerLost`` for what a call to a lost scheduler raises: the tasks Dask cancelled
    when the connection closed (``CancelledError``; this module waits for none it cancelled
    itself) or a failed connection (``OSError``, ``TimeoutError``)."""
    try:
        yield
    except (CancelledError, OSError, TimeoutError):
        raise SchedulerLost(client.scheduler.address) from None


@dataclass(frozen=True)
class _Chunks:
    """What a worker needs to trace blocks of one (realisation, incidence) — everything of
    ``paths.Incidence`` but the tracer, which the worker prepares from the surface."""

    masking: str
    fingerprint: str
    theta_i: float
    phi_i: float
    bins: object
    ior: object
    rays: int
    key: tuple
    origins: str
    isotropic: bool
    bounces: object


def _prepared(surface, masking: str, fingerprint: str):
    """The worker's prepared tracer of ``surface`` (kept while the surface is)."""
    return tracer_for(surface, masking, fingerprint)


def tracer_info(tracer) -> dict:
    """What a run's meta records of a surface's tracer."""
    return {"eps": tracer.eps, "max_wraps": tracer.max_wraps, "grid_walk": tracer.grid is not None}


def _tracer_info(surface, masking: str, fingerprint: str) -> dict:
    """``tracer_info`` of the worker's prepared tracer (worker side; prepares it)."""
    return tracer_info(_prepared(surface, masking, fingerprint)[0])


_TASKS: dict = {}
_TASK_SLOTS = 4
"""Chain tasks a worker keeps (its most recent incidences): building one costs milliseconds
(the path's tables), more than tracing a short block range."""


def _chain(spec: _Chunks, surface):
    """The worker's chain task of ``spec`` on ``surface`` (``bounces.chain_task``), kept."""
    key = spec  # its fingerprint names the mesh: the same key, the same trace
    task = _TASKS.get(key)
    if task is None:
        tracer, profile, azimuth = _prepared(surface, spec.masking, spec.fingerprint)
        incidence = Incidence(
            tracer,
            spherical_deg(spec.theta_i, spec.phi_i),
            spec.phi_i,
            spec.bins,
            spec.ior,
            spec.rays,
            spec.key,
            spec.origins,
            spec.isotropic,
        )
        task = chain_task(incidence, profile, azimuth, spec.isotropic, spec.bounces)
        _TASKS[key] = task
        for old in list(_TASKS)[:-_TASK_SLOTS]:
            _TASKS.pop(old, None)
    return task


def _trace_blocks(spec: _Chunks, surface, start: int, stop: int) -> tuple:
    """Per-block tallies (``ChunkTallies.take()``) of blocks start … stop − 1 (worker side)."""
    return _chain(spec, surface)(range(start, stop)).take()


class RemoteSurface:
    """One realisation on the cluster: the scattered surface and its tracer's meta (prepared
    on a worker, which also checks the masking mode against the surface)."""

    def __init__(self, client, surface, masking: str, fingerprint: str):
        self.client, self.masking, self.fingerprint = client, masking, fingerprint
        with _scheduler_calls(client):
            self.future = client.scatter(surface, hash=False, broadcast=True)
            self.info = client.submit(
                _tracer_info, self.future, masking, fingerprint, pure=False
            ).result()

    def chunks(self, theta_i, phi_i, bins, ior, rays, key, origins, isotropic, bounces):
        """The thread task of one incidence (``bounces.chain_task``'s role) as a cluster task:
        ``ClusterPool.submit(chunks, blocks)``."""
        spec = _Chunks(
            self.masking, self.fingerprint, float(theta_i), float(phi_i), bins, ior,
            int(rays), tuple(key), origins, bool(isotropic), bounces,
        )  # fmt: skip
        return _RemoteTask(spec, self.future)

    def release(self) -> None:
        """Drop the scattered surface from the cluster (nothing to drop on a lost scheduler)."""
        if _connected(self.client):
            self.future.release()


@dataclass(frozen=True)
class _RemoteTask:
    spec: _Chunks
    surface: object  # the scattered surface's Future


class _Pending:
    """A submitted task, as ``run_in_order`` handles futures: ``result()`` gives the chunk's
    tallies, ``cancel()`` withdraws it."""

    def __init__(self, future):
        self.future = future

    def result(self) -> ChunkTallies:
        with _scheduler_calls(self.future.client):
            return ChunkTallies(self.future.result())

    def cancel(self) -> None:
        if _connected(self.future.client):  # a lost scheduler has cancelled it already
            self.future.cancel()


class ClusterPool:
    """Stands in for the thread pool (``schedule.thread_pool``): ``submit(task, blocks)``
    sends a ``RemoteSurface.chunks`` task over ``blocks`` (a range) to the cluster."""

    def __init__(self, client):
        self.client = client
        self.threads = max(1, sum(client.nthreads().values()))
        self.depth = IN_FLIGHT_PER_THREAD * self.threads
        self.min_blocks = MIN_TASK_BLOCKS

    def submit(self, task: _RemoteTask, blocks: range) -> _Pending:
        return _Pending(
            self.client.submit(
                _trace_blocks, task.spec, task.surface, blocks.start, blocks.stop, pure=False
            )
        )
