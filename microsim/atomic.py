"""Atomic file writes: nothing is ever half-written.

Every output goes to a temporary file in the target's directory and is renamed onto the target
with ``os.replace`` only once it is complete; on any error the temporary file is removed and the
old target, if any, is left untouched.
"""
from __future__ import annotations

import json
import os
import tempfile
from contextlib import contextmanager
from pathlib import Path

__all__ = ["atomic_open", "write_text", "write_json"]


@contextmanager
def atomic_open(path, mode: str = "w"):
    """Open a temporary file beside ``path`` (``mode`` "w" text or "wb" binary); on a clean
    exit rename it onto ``path``, on an exception remove it. Creates missing parent folders."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}-", suffix=".tmp")
    try:
        with os.fdopen(fd, mode, **({} if "b" in mode else {"encoding": "utf-8"})) as fh:
            yield fh
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.remove(tmp)
        raise


def write_text(path, text: str) -> None:
    """Write ``text`` (UTF-8) to ``path`` atomically."""
    with atomic_open(path) as fh:
        fh.write(text)


def write_json(path, obj, **dump_options) -> None:
    """``json.dump(obj, indent=1, **dump_options)`` to ``path`` atomically."""
    with atomic_open(path) as fh:
        json.dump(obj, fh, indent=1, **dump_options)
