"""The one reader of scene and sweep files: a regular file of at most ``MAX_SCENE_BYTES`` of
UTF-8 TOML, each problem a one-line ``SceneError`` naming the file."""

from __future__ import annotations

import errno
import os
import stat
import sys

from microsim.checks import file_path
from microsim.errors import EnvironmentFailure

from .scene_checks import SceneError

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

__all__ = ["read_toml", "MAX_SCENE_BYTES"]

MAX_SCENE_BYTES = 1 << 20
"""Largest scene (or sweep) file read: 1 MiB."""


def read_toml(path, what: str = "scene") -> dict:
    """The TOML table of the ``what`` file (scene, sweep) at ``path``, the one reader of both.

    ``SceneError`` (one line naming the file) for a missing file, a symbolic-link loop, a name
    too long, a directory or anything else not a regular file (opened without blocking, so a
    FIFO is refused, never read), more than ``MAX_SCENE_BYTES``, not UTF-8, NUL bytes, arrays
    or tables nested too deeply, or malformed TOML; a leading byte-order mark is allowed.
    Other OS errors (permission denied, an I/O error) are an ``EnvironmentFailure`` naming the
    path (exit status 1, as for any file the machine will not let microsim read)."""
    file_path(f"the {what} file", path)
    try:
        return _parse_toml(path, what)
    except OSError as e:
        raise EnvironmentFailure(
            f"{path}: cannot read the {what} file ({e.strerror or e})"
        ) from None


def _parse_toml(path, what: str) -> dict:
    """``read_toml`` without its translation of unexpected OS errors."""
    try:
        fd = os.open(path, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0))
    except FileNotFoundError:
        raise SceneError(f"{path}: no such {what} file") from None
    except IsADirectoryError:
        raise SceneError(f"{path}: is a directory, not a {what} file") from None
    except OSError as e:  # a symlink loop, a name too long, a file used as a directory
        if e.errno not in (errno.ELOOP, errno.ENAMETOOLONG, errno.ENOTDIR):
            raise
        raise SceneError(f"{path}: {e.strerror}; not a usable {what} file") from None
    too_large = f"{path}: larger than {MAX_SCENE_BYTES >> 20} MiB; not a {what} file"
    try:
        st = os.fstat(fd)
        if stat.S_ISDIR(st.st_mode):
            raise SceneError(f"{path}: is a directory, not a {what} file")
        if not stat.S_ISREG(st.st_mode):
            raise SceneError(f"{path}: not a regular file (a {what} file must be a TOML file)")
        if st.st_size > MAX_SCENE_BYTES:
            raise SceneError(too_large)
        raw = b""
        while len(raw) <= MAX_SCENE_BYTES:
            part = os.read(fd, MAX_SCENE_BYTES + 1 - len(raw))
            if not part:
                break
            raw += part
    finally:
        os.close(fd)
    if len(raw) > MAX_SCENE_BYTES:  # grew while being read
        raise SceneError(too_large)
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as e:
        raise SceneError(
            f"{path}: not UTF-8 text (invalid byte at offset {e.start}); "
            f"a {what} file is UTF-8 TOML"
        ) from None
    if "\x00" in text:
        raise SceneError(f"{path}: contains NUL bytes (a binary file?); a {what} file is TOML text")
    try:
        return tomllib.loads(text.removeprefix("\ufeff"))
    except tomllib.TOMLDecodeError as e:
        raise SceneError(f"{path}: not valid TOML ({' '.join(str(e).split())})") from None
    except RecursionError:
        raise SceneError(f"{path}: arrays or tables nested too deeply; not a {what} file") from None
