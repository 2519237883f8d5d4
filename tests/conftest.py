"""Suite-wide hygiene for the Ctrl-C tests, which drive SIGINT in-process
(``microsim.app.cli.main``, ``DeferredInterrupt``) and into subprocesses that inherit the
test process's disposition:

* a suite started as a background job of a non-interactive shell inherits an *ignored* SIGINT
  (POSIX: such jobs ignore SIGINT), under which Ctrl-C cannot be tested: the session starts
  from Python's default handler and an unblocked SIGINT;
* a test that leaves the handler or the mask changed would make a later one meaningless: both
  are restored after every test, with a warning naming the test.
"""

import os
import shutil
import signal
import tempfile
import time
import warnings
from pathlib import Path

import pytest


def _sigint():
    return signal.getsignal(signal.SIGINT), signal.pthread_sigmask(signal.SIG_BLOCK, [])


@pytest.fixture(autouse=True, scope="session")
def _sigint_deliverable():
    if signal.getsignal(signal.SIGINT) is signal.SIG_IGN:
        signal.signal(signal.SIGINT, signal.default_int_handler)
    signal.pthread_sigmask(signal.SIG_UNBLOCK, [signal.SIGINT])


@pytest.fixture(autouse=True)
def _sigint_restored(request, _sigint_deliverable):
    before = _sigint()
    yield
    now = _sigint()
    if now != before:
        signal.signal(signal.SIGINT, before[0])
        signal.pthread_sigmask(signal.SIG_SETMASK, before[1])
        warnings.warn(f"{request.node.nodeid} left SIGINT as {now}; restored", stacklevel=1)


def pytest_addoption(parser):
    parser.addoption(
        "--warm-kernels",
        action="store_true",
        help="before the xdist workers start, compile microsim's kernels once into numba's "
        "cache (dispatch_probe.py natively) while the AVX2-pinned probe of test_portability "
        "runs on the other core: the workers then load the kernels instead of both compiling "
        "them (make test)",
    )


def pytest_configure(config):
    """``--warm-kernels`` (controller only): the two probe processes, side by side; the
    pinned output is handed to the workers through ``dispatch_probe.PREPARED``. A failed
    probe is not reported here: test_portability then runs it again and says why."""
    if not config.getoption("warm_kernels") or hasattr(config, "workerinput"):
        return
    import dispatch_probe

    started = time.monotonic()
    folder = Path(tempfile.mkdtemp(prefix="microsim-warm-kernels-"))
    config.add_cleanup(lambda: shutil.rmtree(folder, ignore_errors=True))
    inputs, pinned = dispatch_probe.write_inputs(folder), folder / "avx2.npz"
    runs = [
        dispatch_probe.start(inputs, folder / "native.npz", pinned=False),
        dispatch_probe.start(inputs, pinned, pinned=True),
    ]
    for run in runs:
        run.communicate()
    if all(run.returncode == 0 for run in runs):
        os.environ[dispatch_probe.PREPARED] = f"{inputs}{os.pathsep}{pinned}"
    config.stash[_WARMED] = (time.monotonic() - started, [run.returncode for run in runs])


_WARMED = pytest.StashKey[tuple]()


class _FailuresNamedAtOnce:
    """Under pytest-xdist, each failure is named on the terminal when its report arrives:
    the summary that names them comes only at the end, which a run stopped by a time limit
    never reaches."""

    def __init__(self, terminal):
        self.terminal = terminal

    def pytest_runtest_logreport(self, report):
        if report.failed:
            crash = getattr(report.longrepr, "reprcrash", None)
            why = (crash.message if crash else str(report.longrepr)).strip().splitlines()
            self.terminal.write_line(f"\nFAILED {report.nodeid}: {why[0] if why else report.when}")


@pytest.hookimpl(trylast=True)
def pytest_sessionstart(session):
    config = session.config
    terminal = config.pluginmanager.get_plugin("terminalreporter")
    if terminal and config.pluginmanager.has_plugin("dsession"):  # the xdist controller
        config.pluginmanager.register(_FailuresNamedAtOnce(terminal), "failures-named-at-once")


def pytest_report_header(config):
    """What ``--warm-kernels`` took (the session's own time does not include it)."""
    if _WARMED in config.stash:
        seconds, status = config.stash[_WARMED]
        return (
            f"--warm-kernels: {seconds:.0f} s before the workers started (dispatch probe "
            f"natively and AVX2-pinned, exit statuses {status})"
        )
    return None


def pytest_collection_modifyitems(config, items):
    """Tests marked ``long`` (each ≥ 20 s on a cold start) first, in their collected order:
    pytest-xdist hands tests out in collection order, so the two workers share the long ones
    from the start instead of one worker finishing a long test alone at the end."""
    items.sort(key=lambda item: item.get_closest_marker("long") is None)


@pytest.fixture
def mitsuba():
    """The Mitsuba tests' guard: skip (with the reason) where Mitsuba or its LLVM backend is
    unusable."""
    from microsim.app.bench_peer import PeerUnavailable
    from microsim.testing.mitsuba import _microfacet_kernels_compile

    pytest.importorskip("mitsuba")
    try:
        _microfacet_kernels_compile()
    except PeerUnavailable as exc:
        pytest.skip(str(exc))
