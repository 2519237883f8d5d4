"""Running the tasks: local worker processes or a Dask distributed cluster, the output lock,
interrupts (``SweepInterrupted``) and broken pools; ``run_sweep`` is the entry point."""

from __future__ import annotations

import multiprocessing
import multiprocessing.forkserver
import os
import signal
import tempfile
import threading
from concurrent.futures import ProcessPoolExecutor, as_completed
from concurrent.futures.process import BrokenProcessPool
from contextlib import ExitStack, contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

from ... import atomic
from ...checkpoints import checkpoint
from ...errors import EnvironmentFailure
from ..cluster import connect
from ..runner.planning import check_output_path
from .grid import SweepSpec, fail, task_label, varying_values
from .summary import SummaryFiles, write_summary
from .task import is_done, load_result, run_task, worker_init

LOCK_FILE = ".sweep.lock"
"""The lock file inside a sweep's output directory (``atomic.output_lock``)."""


class SweepInterrupted(KeyboardInterrupt):
    """A sweep stopped by Ctrl-C (``signum`` SIGINT) or SIGTERM: ``done`` of ``total`` tasks
    have complete results in ``out`` (kept; a rerun computes the rest)."""

    def __init__(self, out, done: int, total: int, signum: int = signal.SIGINT):
        super().__init__(f"sweep interrupted: {done}/{total} tasks done in {out}")
        self.out, self.done, self.total = str(out), int(done), int(total)
        self.signum = int(signum)


def _check_out(out: Path) -> None:
    """Refuse, before anything runs or is written, an output that is not a sweep's (beyond
    the checks every output path gets, ``planning.check_output_path``)."""
    try:
        if out.exists() and not out.is_dir():
            fail(str(out), "exists and is not a directory; --out must be a directory")
        anc = out
        while not anc.exists() and anc != anc.parent:
            anc = anc.parent
        if not anc.is_dir():
            fail(str(out), f"{anc} is a file, not a directory")
        tasks = out / "tasks"
        if tasks.exists() and not tasks.is_dir():
            fail(str(out), f"{tasks} exists and is not a directory")
        if out.is_dir() and not tasks.is_dir() and any(out.iterdir()):
            fail(
                str(out),
                "not empty and not a sweep output (no tasks/ folder); choose a new "
                "or empty --out directory",
            )
    except OSError as e:
        fail(str(out), f"unusable output path ({e.strerror or e})")
    if not os.access(anc, os.W_OK | os.X_OK):
        raise EnvironmentFailure(
            f"{out}: {anc} is not writable (permission denied or a read-only file system)"
        )


@contextmanager
def _sigterm_interrupts():
    """While active (main thread, SIGTERM not ignored), SIGTERM raises KeyboardInterrupt as
    Ctrl-C does, so the sweep stops its workers before it exits; yields {"signal": the
    signal that interrupted, SIGINT unless a SIGTERM arrived}."""
    received = {"signal": signal.SIGINT}

    def terminate(signum, frame):
        received["signal"] = signum
        raise KeyboardInterrupt

    main = threading.current_thread() is threading.main_thread()
    old = signal.getsignal(signal.SIGTERM) if main else None
    if old is not signal.SIG_DFL:
        yield received
        return
    signal.signal(signal.SIGTERM, terminate)
    try:
        yield received
    finally:
        signal.signal(signal.SIGTERM, old)


def _local(todo, out: Path, workers: int, collect, notice: Callable[[str], None], context) -> None:
    """Run ``todo`` in local worker processes (from ``context``, ``_worker_context``);
    ``collect(record)`` for each finished one.

    A worker process that dies (SIGKILL, the out-of-memory killer) breaks the pool: the tasks
    without a complete result then run again in a fresh pool (``notice`` says so); when two
    pools in a row break before any task finishes, ``BrokenProcessPool`` is raised."""
    fruitless = 0
    while todo:
        finished = set()

        def note(rec: dict) -> None:
            collect(rec)
            finished.add(rec["id"])

        try:
            _local_pool(todo, out, workers, note, context)
            return
        except BrokenProcessPool:
            pass
        rest = []
        for task in todo:
            if task.id in finished:
                continue
            rec = load_result(task, out)
            if rec is None:
                rest.append(task)
            else:  # written just before the pool broke
                note(rec)
        fruitless = 0 if finished else fruitless + 1
        if fruitless == 2:
            raise BrokenProcessPool("worker processes died twice in a row")
        notice(f"a worker process died; running its {len(rest)} unfinished tasks again")
        todo = rest


def _worker_context():
    """Where local workers come from, started now (EnvironmentFailure if it cannot be): a
    fork server, a fresh single-threaded interpreter that imported this package once.
    Forking the sweep's own process instead would copy its threads' held locks (a deadlocked
    child) and its open files (an orphaned child holding a parent's pipes) into every worker;
    Python 3.14 makes this its default on Linux for the same reasons."""
    ctx = multiprocessing.get_context("forkserver")
    ctx.set_forkserver_preload([__name__])
    try:
        multiprocessing.forkserver.ensure_running()
    except OSError as e:  # its socket lives in the temporary folder, e.g. "path too long"
        raise EnvironmentFailure(
            f"cannot start the local worker processes' fork server ({e.strerror or e}); its "
            f"socket lives in {tempfile.gettempdir()}: a shorter or writable TMPDIR fixes it"
        ) from None
    return ctx


def _local_pool(todo, out: Path, workers: int, collect, context) -> None:
    """One process pool for ``todo`` (``_local``). On any exception (Ctrl-C included) the
    queued tasks are cancelled, the running ones asked to stop (SIGINT: their simulation
    returns partial and writes nothing), and the exception re-raised once they have; a second
    Ctrl-C kills them."""
    pool = ProcessPoolExecutor(
        max_workers=min(int(workers), len(todo)),
        mp_context=context,
        initializer=worker_init,
    )
    futures = []
    try:
        futures = [pool.submit(run_task, t, str(out)) for t in todo]
        for fut in as_completed(futures):
            collect(fut.result())
    except BaseException:
        for f in futures:
            f.cancel()
        for proc in list((getattr(pool, "_processes", None) or {}).values()):
            if proc.is_alive():  # never a pid the pool has already reaped
                try:
                    os.kill(proc.pid, signal.SIGINT)
                except OSError:
                    pass
        try:
            pool.shutdown(wait=True, cancel_futures=True)
        except KeyboardInterrupt:
            for p in list((getattr(pool, "_processes", None) or {}).values()):
                p.kill()
            pool.shutdown(wait=False, cancel_futures=True)
        raise
    pool.shutdown(wait=True)


def _dask(todo, out: Path, client, collect) -> None:
    from dask.distributed import as_completed as dask_completed

    futures = [
        client.submit(run_task, t, str(out), key=f"microsim-{t.id}", pure=False) for t in todo
    ]
    try:
        for fut in dask_completed(futures):
            collect(fut.result())
    except BaseException:
        client.cancel(futures)  # tasks already running finish and store complete results
        raise


@dataclass(frozen=True)
class SweepOutcome:
    """What ``run_sweep`` did: the ids of the tasks it ``computed`` and of those it
    ``skipped`` (complete results found), and the ``summary`` files it wrote."""

    computed: list
    skipped: list
    summary: SummaryFiles


def _check_options(workers, connect_timeout) -> None:
    if isinstance(workers, bool) or not isinstance(workers, int) or workers < 1:
        fail("--workers", f"must be an integer >= 1, got {workers!r}")
    if not (isinstance(connect_timeout, (int, float)) and 0 < connect_timeout <= 3600):
        fail("--scheduler-timeout", f"must be seconds in (0, 3600], got {connect_timeout!r}")


def _open_out(stack: ExitStack, out: Path) -> None:
    """Create ``out/tasks``, hold the sweep's lock on ``out`` for the ``stack``'s lifetime and
    remove the temporary files interrupted writes of earlier sweeps left."""
    try:
        (out / "tasks").mkdir(parents=True, exist_ok=True)
        stack.enter_context(atomic.output_lock(out, out / LOCK_FILE, holder="sweep"))
    except OSError as e:
        raise EnvironmentFailure(
            f"{out}: cannot create the sweep output ({e.strerror or e})"
        ) from None
    for d in (out, out / "tasks"):
        atomic.clean_temp_files(d)


class _Collector:
    """Receives the finished task records of a sweep: keeps their ids and reports each in
    one progress line ("k/N done: <scene params, material, θi> (s)")."""

    def __init__(self, spec: SweepSpec, todo: list, skipped: list, progress):
        self.spec, self.skipped, self.progress = spec, skipped, progress
        self.by_id = {t.id: t for t in todo}
        self.varying = varying_values(spec.tasks)
        self.computed: list = []

    def start(self, workers: int, on_cluster: bool) -> None:
        """The first progress line: how many tasks, how many done, where the rest run."""
        todo, total = self.by_id, len(self.spec.tasks)
        if not (self.progress and todo):
            return
        where = (
            f"{len(todo)} on the Dask cluster"
            if on_cluster
            else f"{len(todo)} on {min(workers, len(todo))} local workers"
        )
        self.progress(
            f"sweep {self.spec.name}: {total} tasks, {len(self.skipped)} already done, "
            f"running {where}"
        )

    def __call__(self, rec: dict) -> None:
        if rec.get("partial"):  # a worker was interrupted
            raise KeyboardInterrupt
        task_id = rec["id"]
        self.computed.append(task_id)
        if self.progress:
            task = self.by_id[task_id]
            done = len(self.skipped) + len(self.computed)
            self.progress(
                f"sweep {self.spec.name}: {done}/{len(self.spec.tasks)} done: "
                f"{task_label(task, self.varying.get(task.scene))} ({rec['seconds']:.1f} s)"
            )
        checkpoint("sweep-task")


def run_sweep(
    spec: SweepSpec,
    out,
    *,
    scheduler=None,
    workers: int = 2,
    limit: int | None = None,
    progress: Callable[[str], None] | None = None,
    connect_timeout: float = 10.0,
) -> SweepOutcome:
    """Run the tasks of ``spec`` that have no complete result in ``out`` yet, then
    ``write_summary``.

    ``scheduler``: None (local processes, ``workers`` of them) or a Dask scheduler address
    (anything ``dask.distributed.Client`` accepts, e.g. "tcp://host:8786" or a LocalCluster),
    reached within ``connect_timeout`` seconds or EnvironmentFailure. ``limit``: run at most
    this many of the missing tasks, then summarise what is done. ``progress``: receives one
    line per finished task ("k/N done: <scene params, material, θi> (s)"), and one at the start.
    Ctrl-C or SIGTERM: raises ``SweepInterrupted`` (the workers stopped, finished tasks
    kept, no summary written). Local worker processes that die: their tasks run again
    (``_local``), or EnvironmentFailure. Local workers import the caller's main module (as
    with Python's forkserver and spawn start methods): a script calling this keeps the call
    under ``if __name__ == "__main__":``.
    """
    _check_options(workers, connect_timeout)
    check_output_path(Path(out), "--out", spec.path)
    out = Path(out).absolute()
    _check_out(out)
    with ExitStack() as stack:
        received = stack.enter_context(_sigterm_interrupts())
        client = context = None
        if scheduler is not None:
            client = stack.enter_context(connect(scheduler, float(connect_timeout)))
        else:  # as the cluster's connection: before anything is written
            context = _worker_context()
        _open_out(stack, out)
        todo = [t for t in spec.tasks if not is_done(t, out)]
        skipped = [t.id for t in spec.tasks if t not in todo]
        if limit is not None:
            todo = todo[: int(limit)]
        total = len(spec.tasks)
        collect = _Collector(spec, todo, skipped, progress)
        collect.start(workers, client is not None)

        def done() -> int:
            return sum(is_done(t, out) for t in spec.tasks)

        try:
            if todo and client is None:
                _local(todo, out, workers, collect, progress or (lambda line: None), context)
            elif todo:
                _dask(todo, out, client, collect)
            paths = write_summary(spec, out)
        except KeyboardInterrupt:
            raise SweepInterrupted(out, done(), total, received["signal"]) from None
        except BrokenProcessPool:
            raise EnvironmentFailure(
                f"{out}: sweep worker processes died twice in a row before finishing a task "
                f"(killed, e.g. by the out-of-memory killer); {done()}/{total} tasks done and "
                f"kept in {out / 'tasks'}, summary not written; rerun the same command to "
                f"compute the rest"
            ) from None
    return SweepOutcome(collect.computed, skipped, paths)
