"""Atomic file writes, output directories published in one rename, and output locks.

Every output goes to a temporary file (or staging directory) beside its target and is renamed
onto the target with ``os.replace`` only once it is complete; on any error the temporary is
removed and the old target, if any, is left untouched. Files and directories get the user's
normal permissions (0o666 / 0o777 minus the umask), not ``mkstemp``'s 0o600 / 0o700.

Temporaries of a directory ``DIR`` are named ``.DIR.tmp-<pid>-*`` (staging) and
``.DIR.old-<pid>-*`` (the replaced directory, removed after the swap). A process killed by
SIGKILL/SIGTERM leaves them behind; ``clean_stale(DIR)`` removes exactly those whose process
is gone — call it only while holding ``output_lock(DIR)`` — once ``recover_publish(DIR)`` has
dealt with a process killed inside ``publish_dir``: the old ``DIR`` is put back if it was
aside, and the finished staging directory is kept as ``DIR.unpublished-<pid>-*``.

``output_lock(DIR)`` is an exclusive ``fcntl.flock`` on ``.DIR.lock`` beside ``DIR`` (holding
the owner's pid), held for a run's duration: a second run on the same ``DIR`` is refused with
a ``UsageError`` (a sweep holds ``OUT/.sweep.lock`` inside its output instead). The kernel drops
the lock when its process dies, so a stale lock file never blocks anyone. ``clean_temp_files``
removes the temporaries of atomic writes cut short, under the lock.

Files microsim saved are read back through ``read_json`` and ``read_npz``: a file that is
missing, not a regular file, cut short, overwritten with something else or of another JSON
type is a one-line ``UsageError`` naming it and what is wrong, never a parser's traceback.
"""

from __future__ import annotations

import errno
import fcntl
import json
import math
import os
import re
import shutil
import stat
import tempfile
import zipfile
import zlib
from contextlib import contextmanager
from pathlib import Path
from typing import Callable

import numpy as np

from .errors import UsageError

__all__ = [
    "atomic_open",
    "write_text",
    "json_safe",
    "write_json",
    "read_json",
    "read_npz",
    "umask",
    "file_mode",
    "dir_mode",
    "make_staging",
    "publish_dir",
    "output_lock",
    "clean_stale",
    "clean_temp_files",
    "recover_publish",
    "normalise_modes",
]


def umask() -> int:
    """The process umask (read without changing it where /proc allows)."""
    try:
        with open("/proc/self/status") as fh:
            for line in fh:
                if line.startswith("Umask:"):
                    return int(line.split()[1], 8)
    except (OSError, ValueError):
        pass
    old = os.umask(0o022)
    os.umask(old)
    return old


def file_mode() -> int:
    """Mode of a new regular file: 0o666 minus the umask."""
    return 0o666 & ~umask()


def dir_mode() -> int:
    """Mode of a new directory: 0o777 minus the umask."""
    return 0o777 & ~umask()


@contextmanager
def atomic_open(path, mode: str = "w"):
    """Open a temporary file beside ``path`` (``mode`` "w" text or "wb" binary); on a clean
    exit rename it onto ``path``, on an exception remove it. Creates missing parent folders.
    An ``OSError`` that names no file (a failed write: disk full) is raised naming ``path``."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}-", suffix=".tmp")
    try:
        os.fchmod(fd, file_mode())
        with os.fdopen(fd, mode, **({} if "b" in mode else {"encoding": "utf-8"})) as fh:
            yield fh
        os.replace(tmp, path)
    except OSError as e:
        if os.path.exists(tmp):
            os.remove(tmp)
        if e.filename is None:  # a failed write(2) (disk full, I/O error): name the file
            raise OSError(e.errno, e.strerror or str(e), str(path)) from e
        raise
    except BaseException:
        if os.path.exists(tmp):
            os.remove(tmp)
        raise


def write_text(path, text: str) -> None:
    """Write ``text`` (UTF-8) to ``path`` atomically."""
    with atomic_open(path) as fh:
        fh.write(text)


def json_safe(obj):
    """JSON-safe copy of ``obj``: NumPy arrays and scalars → Python lists and numbers,
    NaN/±inf → None, tuples → lists, complex → [re, im], mapping keys → str. Anything else is
    left for ``json`` to refuse (TypeError)."""
    if isinstance(obj, dict):
        return {str(k): json_safe(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [json_safe(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return json_safe(obj.tolist())
    if isinstance(obj, np.generic):
        obj = obj.item()
    if isinstance(obj, float) and not math.isfinite(obj):
        return None
    if isinstance(obj, complex):
        return [json_safe(obj.real), json_safe(obj.imag)]
    return obj


def write_json(path, obj) -> None:
    """Strict JSON (``json_safe(obj)``, indent 1, non-ASCII escaped) to ``path`` atomically;
    nothing is written if ``obj`` holds something JSON cannot represent (TypeError)."""
    data = json.dumps(json_safe(obj), indent=1, allow_nan=False)
    with atomic_open(path) as fh:
        fh.write(data)


# --- reading saved files -----------------------------------------------------------------------
_JSON_TYPES = ((dict, "an object"), (list, "an array"), (str, "a string"), (bool, "a boolean"))
_JSON_TYPES += (((int, float), "a number"), (type(None), "null"))


def _json_type(value) -> str:
    return next(name for kind, name in _JSON_TYPES if isinstance(value, kind))


def _damaged(path, what: str, error: Exception) -> UsageError:
    reason = " ".join(f"{error}".split()) or type(error).__name__
    return UsageError(f"{path}: {what}, damaged or cut short ({reason[:160]})")


def _check_saved_file(path: Path) -> None:
    """UsageError unless ``path`` is a regular file (checked before opening: a FIFO would
    block). An ``OSError`` of the environment (permission denied, I/O error) propagates."""
    try:
        mode = path.stat().st_mode
    except FileNotFoundError:
        raise UsageError(f"{path}: no such file") from None
    except OSError as e:  # a symlink loop, a name too long, a file used as a directory
        if e.errno not in (errno.ELOOP, errno.ENAMETOOLONG, errno.ENOTDIR):
            raise
        raise UsageError(f"{path}: {os.strerror(e.errno)}") from None
    if stat.S_ISDIR(mode):
        raise UsageError(f"{path}: is a directory, not a file")
    if not stat.S_ISREG(mode):
        raise UsageError(f"{path}: not a regular file")


def read_json(path, kind: type = dict):
    """The JSON value saved in ``path`` (UTF-8), which must be a ``kind`` (``dict``: an
    object, ``list``: an array). Missing, not a regular file, not UTF-8 or not JSON (a write
    cut short, another file put there), or JSON of another type: a one-line ``UsageError``
    naming ``path`` and what is wrong. The keys inside are the caller's to check."""
    path = Path(path)
    _check_saved_file(path)
    try:
        with open(path, encoding="utf-8") as fh:
            value = json.load(fh)
    except UnicodeDecodeError as e:
        raise _damaged(path, "not UTF-8 text", e) from None
    except ValueError as e:  # json.JSONDecodeError
        raise _damaged(path, "not valid JSON", e) from None
    if not isinstance(value, kind):
        want = next(name for k, name in _JSON_TYPES if k is kind)
        raise UsageError(f"{path}: must hold {want}, holds {_json_type(value)}")
    return value


_ZIP_MAGIC = b"PK\x03\x04"  # how every archive of np.savez starts
_NPZ_ERRORS = (zipfile.BadZipFile, zlib.error, EOFError, ValueError, KeyError, NotImplementedError)
"""What NumPy and ``zipfile`` raise on a damaged ``.npz``: no zip directory (cut short),
a bad member CRC or size, a bad ``.npy`` header, an object array (pickles are refused)."""


def read_npz(path) -> dict[str, np.ndarray]:
    """Every array of the ``.npz`` archive ``path`` (``np.savez``), read into memory; object
    arrays are refused (no pickles). Missing, not a regular file, cut short, not an ``.npz``
    archive or a damaged member: a one-line ``UsageError`` naming ``path`` and what is wrong.
    The arrays' names, shapes and values are the caller's to check."""
    path = Path(path)
    _check_saved_file(path)
    with open(path, "rb") as fh:
        start = fh.read(len(_ZIP_MAGIC))
        if start != _ZIP_MAGIC:
            got = "is empty" if not start else f"starts with {start!r}, not a zip header"
            raise UsageError(f"{path}: not an .npz archive ({got}): damaged or another file")
        try:
            with zipfile.ZipFile(fh) as archive:  # np.load checks no CRC: testzip reads all
                broken = archive.testzip()
            if broken is not None:
                raise zipfile.BadZipFile(f"bad CRC-32 for {broken}")
            fh.seek(0)
            with np.load(fh, allow_pickle=False) as archive:
                return {k: archive[k] for k in archive.files}
        except _NPZ_ERRORS as e:
            raise _damaged(path, "not a readable .npz archive", e) from None
        except OSError as e:  # a seek to a damaged offset; other errors are the environment's
            if e.errno != errno.EINVAL:
                raise
            raise _damaged(path, "not a readable .npz archive", e) from None


# --- directories -------------------------------------------------------------------------------
def _temp_dir(out: Path, kind: str) -> Path:
    """A new empty ``.OUT.KIND-<pid>-*`` beside ``out`` in the normal mode; removed again if
    setting the mode fails (a full copy-on-write file system refuses even that)."""
    out.parent.mkdir(parents=True, exist_ok=True)
    d = Path(tempfile.mkdtemp(dir=out.parent, prefix=f".{out.name}.{kind}-{os.getpid()}-"))
    try:
        os.chmod(d, dir_mode())
    except BaseException:
        os.rmdir(d)
        raise
    return d


def make_staging(out) -> Path:
    """A new empty staging directory ``.OUT.tmp-<pid>-*`` beside ``out`` (normal mode)."""
    return _temp_dir(Path(out), "tmp")


def normalise_modes(root) -> None:
    """Give ``root`` and everything under it the normal modes (files 0o666, directories 0o777,
    minus the umask): undo ``mkstemp``/``mkdtemp``'s private 0o600/0o700."""
    fmode, dmode = file_mode(), dir_mode()
    os.chmod(root, dmode)
    for base, dirs, files in os.walk(root):
        for d in dirs:
            os.chmod(os.path.join(base, d), dmode)
        for f in files:
            os.chmod(os.path.join(base, f), fmode)


def publish_dir(stage, out, keep: Callable[[str], bool] | None = None) -> None:
    """Move the finished ``stage`` directory to ``out``: one rename when ``out`` is new; else
    the old one is renamed aside (``.OUT.old-<pid>-*``), the new one renamed in, and only then
    the old one removed. If the second rename fails the old directory is put back, so the old
    result is never lost before the new one is in place. ``keep(name)``: entries of the old
    ``out`` to carry into the new one (hard links, copies where the file system has none;
    they keep their own modes); entries ``stage`` has are never carried."""
    stage, out = Path(stage), Path(out)
    normalise_modes(stage)
    if not out.exists():
        os.rename(stage, out)
        return
    if keep is not None:
        for entry in os.scandir(out):
            if keep(entry.name) and not os.path.lexists(stage / entry.name):
                _carry(entry, stage / entry.name)
    old = _temp_dir(out, "old")
    os.rename(out, old / "d")
    try:
        os.rename(stage, out)
    except BaseException:
        os.rename(old / "d", out)
        os.rmdir(old)
        raise
    shutil.rmtree(old, ignore_errors=True)


def _link_or_copy(src, dst) -> None:
    try:
        os.link(src, dst, follow_symlinks=False)
    except OSError:
        shutil.copy2(src, dst, follow_symlinks=False)


def _carry(entry: os.DirEntry, dst: Path) -> None:
    """``entry`` (file, symbolic link or directory tree) recreated at ``dst``."""
    if entry.is_dir(follow_symlinks=False):
        shutil.copytree(entry.path, dst, symlinks=True, copy_function=_link_or_copy)
    else:
        _link_or_copy(entry.path, dst)


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def _stale(out: Path) -> dict[str, list[os.DirEntry]]:
    """``"tmp"``/``"old"`` → microsim's temporary directories beside ``out`` whose process
    is gone (a live or unknown owner's are left out)."""
    pattern = re.compile(re.escape(f".{out.name}.") + r"(tmp|old)-(\d+)-[A-Za-z0-9_]+")
    found: dict[str, list[os.DirEntry]] = {"tmp": [], "old": []}
    try:
        entries = list(os.scandir(out.parent))
    except OSError:
        return found
    for e in entries:
        m = pattern.fullmatch(e.name)
        if not m or int(m.group(2)) == os.getpid() or _alive(int(m.group(2))):
            continue
        if e.is_dir(follow_symlinks=False):
            found[m.group(1)].append(e)
    return found


def _pid(entry: os.DirEntry) -> str:
    return entry.name.rsplit("-", 2)[-2]


def recover_publish(out) -> str | None:
    """Undo what a process killed inside ``publish_dir`` left of ``out``: its aside
    ``.OUT.old-<pid>-*/d`` is put back when ``out`` is missing, and its staging directory —
    complete, since ``publish_dir`` had started — is kept as ``OUT.unpublished-<pid>-*``
    beside it rather than removed as stale. Returns one line saying what was done (None:
    nothing to recover). Call only while holding ``output_lock(out)``."""
    out = Path(out)
    stale = _stale(out)
    notes = []
    for old in stale["old"]:
        pid, aside = _pid(old), Path(old.path) / "d"
        # between the renames (the old out aside) or just before them (an empty aside folder)
        publishing = aside.is_dir() or (os.path.lexists(out) and not os.listdir(old.path))
        if not publishing:
            continue
        if not os.path.lexists(out):
            os.rename(aside, out)
            notes.append(f"its previous content was put back from {old.name}")
        for tmp in (t for t in stale["tmp"] if _pid(t) == pid):
            kept = out.parent / f"{out.name}.unpublished-{pid}-{tmp.name.rsplit('-', 1)[-1]}"
            os.rename(tmp.path, kept)
            notes.append(f"the new result it was publishing is kept in {kept}")
    if not notes:
        return None
    return f"{out}: a killed microsim run was replacing it: " + "; ".join(notes)


def clean_stale(out) -> list[Path]:
    """Remove ``.OUT.tmp-<pid>-*`` and ``.OUT.old-<pid>-*`` beside ``out`` left by processes
    that no longer exist (only microsim's own names; a live or unknown owner is left alone),
    after ``recover_publish(out)`` has put back or kept what a publication cut short left.
    Returns what was removed. Call only while holding ``output_lock(out)``."""
    out = Path(out)
    recover_publish(out)
    stale = _stale(out)
    removed = []
    for e in (*stale["tmp"], *stale["old"]):
        shutil.rmtree(e.path, ignore_errors=True)
        removed.append(Path(e.path))
    return removed


def clean_temp_files(directory) -> list[Path]:
    """Remove the files ``.*.tmp`` in ``directory``: ``atomic_open``'s temporaries left by
    writes cut short (a killed process). Returns what was removed; what cannot be removed is
    left. Call only while holding the lock of the output the directory belongs to."""
    removed = []
    for p in Path(directory).glob(".*.tmp"):
        try:
            p.unlink()
        except OSError:
            continue
        removed.append(p)
    return removed


def lock_path(out) -> Path:
    """The lock file of output ``out``: ``.OUT.lock`` in its parent."""
    out = Path(out)
    return out.parent / f".{out.name}.lock"


@contextmanager
def output_lock(out, lock_file=None, holder: str = "run"):
    """Hold an exclusive lock on output ``out`` for the block; a second holder (another
    process or another plan in this one) gets a one-line ``UsageError`` calling it "another
    microsim ``holder``". ``lock_file``: the lock file (default ``lock_path(out)``; a sweep
    keeps it inside its output directory, ``OUT/.sweep.lock``). The lock file is removed on
    exit; the kernel releases the lock if the process dies, and a lock file so left behind is
    simply taken over."""
    path = lock_path(out) if lock_file is None else Path(lock_file)
    path.parent.mkdir(parents=True, exist_ok=True)
    while True:
        fd = os.open(path, os.O_RDWR | os.O_CREAT, file_mode())
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError as e:
            os.close(fd)
            if e.errno in (errno.EWOULDBLOCK, errno.EAGAIN, errno.EACCES):
                try:
                    owner = path.read_text().strip() or "?"
                except OSError:
                    owner = "?"
                raise UsageError(
                    f"{out}: another microsim {holder} (pid {owner}) is writing it; "
                    f"wait for it to finish or choose another --out"
                ) from None
            raise
        try:  # the file may have been unlinked by its previous holder
            same = os.fstat(fd).st_ino == os.stat(path).st_ino
        except FileNotFoundError:
            same = False
        if same:
            break
        os.close(fd)
    try:
        os.ftruncate(fd, 0)
        os.write(fd, f"{os.getpid()}\n".encode())
        yield path
    finally:
        try:
            os.unlink(path)
        except OSError:
            pass
        os.close(fd)
