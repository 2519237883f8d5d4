"""Suite-wide hygiene: the SIGINT disposition and the signal mask are the process's, not a
test's. Tests drive Ctrl-C in-process (``microsim.app.cli.main``, ``DeferredInterrupt``) and
start subprocesses that inherit an ignored or blocked SIGINT; a test that leaves either changed
would make a later one meaningless. Each is restored after every test, with a warning naming
the test that changed it (seen once, on a heavily loaded machine, and not reproduced since)."""

import signal
import warnings

import pytest


@pytest.fixture(autouse=True)
def _sigint_restored(request):
    handler, mask = signal.getsignal(signal.SIGINT), signal.pthread_sigmask(signal.SIG_BLOCK, [])
    yield
    now = signal.getsignal(signal.SIGINT), signal.pthread_sigmask(signal.SIG_BLOCK, [])
    if now != (handler, mask):
        signal.signal(signal.SIGINT, handler)
        signal.pthread_sigmask(signal.SIG_SETMASK, mask)
        warnings.warn(f"{request.node.nodeid} left SIGINT as {now}; restored", stacklevel=1)
