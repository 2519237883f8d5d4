"""The two kinds of failure microsim reports to its users, and the CLI's exit statuses.

``UsageError`` (a ``ValueError``): the input is wrong — a parameter out of its allowed range,
a malformed scene, sweep or heightfield file, an output path that cannot be used. The message
is one line that names the parameter, key or path and the allowed values. The CLI prints it
and exits with status 2. Every deliberate check in the package raises it; a plain
``ValueError`` from elsewhere is a bug and the CLI shows it as one (traceback, status 1).

``EnvironmentFailure`` (a ``RuntimeError``): the input is fine but the environment failed —
disk full, read-only file system, permission denied, a scheduler that cannot be reached. The
CLI prints one line naming the path or address and exits with status 1. ``OSError`` raised
while reading or writing is reported the same way.

Exit statuses of ``microsim``: 0 success; 1 environment failure (or, with a traceback, a bug);
2 usage error; 130 interrupted (Ctrl-C: finished results kept, partial ones saved for
``--resume`` or recomputed on the next run).
"""

from __future__ import annotations

__all__ = [
    "UsageError",
    "EnvironmentFailure",
    "EXIT_OK",
    "EXIT_ENVIRONMENT",
    "EXIT_USAGE",
    "EXIT_INTERRUPTED",
]

EXIT_OK, EXIT_ENVIRONMENT, EXIT_USAGE, EXIT_INTERRUPTED = 0, 1, 2, 130


class UsageError(ValueError):
    """Bad input: the one-line message names the parameter/key/path and the allowed values."""


class EnvironmentFailure(RuntimeError):
    """The environment failed (disk, permissions, network): one line naming the path/address."""
