"""The tensor file: the container of the RGL ".bsdf" format (Mitsuba's ``TensorFile``).

Tensor file (the container; Mitsuba's ``TensorFile``), little-endian:
    12 bytes "tensor_file\\0", 2 bytes version (1, 0), uint32 number of fields; per field
    uint16 name length, the name (UTF-8), uint16 ndim, uint8 dtype code (1 uint8, 2 int8,
    3 uint16, 4 int16, 5 uint32, 6 int32, 7 uint64, 8 int64, 9 float16, 10 float32,
    11 float64), uint64 byte offset of the data, ndim × uint64 shape; then the data of each
    field, C order (last axis fastest), at its offset (this module aligns offsets to 8 bytes).
"""

from __future__ import annotations

import os
import stat
import struct
from pathlib import Path

import numpy as np

from microsim.errors import UsageError

__all__ = ["tensor_file_bytes", "read_tensor_file", "file_error"]

_MAGIC = b"tensor_file\x00"
_VERSION = (1, 0)
_ALIGN = 8
_CODE_OF = {
    np.dtype(np.uint8): 1,
    np.dtype(np.int8): 2,
    np.dtype(np.uint16): 3,
    np.dtype(np.int16): 4,
    np.dtype(np.uint32): 5,
    np.dtype(np.int32): 6,
    np.dtype(np.uint64): 7,
    np.dtype(np.int64): 8,
    np.dtype(np.float16): 9,
    np.dtype(np.float32): 10,
    np.dtype(np.float64): 11,
}
_DTYPE_OF = {code: dt.newbyteorder("<") for dt, code in _CODE_OF.items()}


# --- the tensor-file container ----------------------------------------------------------------
def tensor_file_bytes(fields: dict) -> bytes:
    """The tensor file (module docstring) holding ``fields`` (name → array; a str is stored as
    its UTF-8 bytes), in the given order, data aligned to 8 bytes."""
    arrays = {}
    for name, value in fields.items():
        if isinstance(value, str):
            value = np.frombuffer(value.encode("utf-8"), dtype=np.uint8)
        a = np.ascontiguousarray(value)
        if a.dtype.newbyteorder("=") not in _CODE_OF:
            raise UsageError(
                f"field {name!r} has dtype {a.dtype}; a tensor file holds "
                f"{sorted(str(d) for d in _CODE_OF)}"
            )
        arrays[name] = a.astype(a.dtype.newbyteorder("<"), copy=False)
    head = len(_MAGIC) + 2 + 4
    head += sum(2 + len(k.encode("utf-8")) + 2 + 1 + 8 + 8 * a.ndim for k, a in arrays.items())
    offsets, pos = {}, head
    for name, a in arrays.items():
        pos = -(-pos // _ALIGN) * _ALIGN
        offsets[name] = pos
        pos += a.nbytes
    out = bytearray(pos)
    out[: len(_MAGIC)] = _MAGIC
    cursor = len(_MAGIC)
    struct.pack_into("<BBI", out, cursor, *_VERSION, len(arrays))
    cursor += 6
    for name, a in arrays.items():
        label = name.encode("utf-8")
        struct.pack_into(f"<H{len(label)}sHBQ", out, cursor, len(label), label, a.ndim,
                         _CODE_OF[a.dtype.newbyteorder("=")], offsets[name])  # fmt: skip
        cursor += 2 + len(label) + 2 + 1 + 8
        struct.pack_into(f"<{a.ndim}Q", out, cursor, *a.shape)
        cursor += 8 * a.ndim
        out[offsets[name] : offsets[name] + a.nbytes] = a.tobytes()
    return bytes(out)


def file_error(path, what: str) -> UsageError:
    return UsageError(f"{path}: {what}")


def read_tensor_file(path) -> dict:
    """The fields (name → array, native byte order) of the tensor file ``path``; a
    ``UsageError`` naming the file for a missing, foreign or truncated one."""
    path = Path(os.fspath(path))
    try:
        st = path.stat()
    except FileNotFoundError:
        raise file_error(path, "no such RGL .bsdf file") from None
    if not stat.S_ISREG(st.st_mode):
        raise file_error(path, "not a regular file (an RGL BRDF is a .bsdf tensor file)")
    data = path.read_bytes()
    size = len(data)
    if size < len(_MAGIC) + 6:
        raise file_error(
            path,
            f"truncated: {size} bytes, shorter than the 18-byte tensor-file header "
            f"(not an RGL .bsdf file)",
        )
    if data[: len(_MAGIC)] != _MAGIC:
        raise file_error(
            path,
            f"not a tensor file: it starts with {data[:12]!r}, an RGL .bsdf file with {_MAGIC!r}",
        )
    version = tuple(data[12:14])
    if version != _VERSION:
        raise file_error(path, f"tensor-file version {version}, only {_VERSION} is defined")
    (n_fields,) = struct.unpack_from("<I", data, 14)
    cursor, fields = 18, {}

    def take(fmt: str, what: str):
        nonlocal cursor
        need = struct.calcsize(fmt)
        if cursor + need > size:
            raise file_error(
                path,
                f"truncated: the header of {n_fields} fields ends inside {what} at byte "
                f"{cursor} of {size}",
            )
        values = struct.unpack_from(fmt, data, cursor)
        cursor += need
        return values

    for k in range(n_fields):
        (n_name,) = take("<H", f"field {k}'s name length")
        (raw,) = take(f"<{n_name}s", f"field {k}'s name")
        name = raw.decode("utf-8", errors="replace")
        ndim, code, offset = take("<HBQ", f"field {name!r}'s description")
        shape = take(f"<{ndim}Q", f"field {name!r}'s shape")
        if code not in _DTYPE_OF:
            raise file_error(path, f"field {name!r} has the unknown dtype code {code} (1 … 11)")
        dtype = _DTYPE_OF[code]
        nbytes = dtype.itemsize * int(np.prod(shape, dtype=np.uint64))
        if offset + nbytes > size:
            raise file_error(
                path,
                f"truncated: field {name!r} {tuple(shape)} {dtype.name} needs bytes "
                f"[{offset}, {offset + nbytes}), the file has {size}",
            )
        a = np.frombuffer(data, dtype=dtype, count=nbytes // dtype.itemsize, offset=offset)
        fields[name] = a.reshape(shape).astype(dtype.newbyteorder("="))
    return fields
