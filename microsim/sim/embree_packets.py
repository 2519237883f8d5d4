"""Coherent Embree ray packets over the Embree 4 library that embreex bundles (ctypes).

embreex traces one ray per call (``rtcIntersect1``); Embree's packet calls
``rtcIntersect{4,8,16}``/``rtcOccluded{4,8,16}`` flagged ``RTC_RAY_QUERY_FLAG_COHERENT`` trace
coherent rays in SIMD lanes. The width used is the widest the library traces
natively on this CPU (device properties ``RTC_DEVICE_PROPERTY_NATIVE_RAY{16,8,4}_SUPPORTED``):
16 with AVX-512, 8 with AVX2. On an AVX2 CPU, ``rtcIntersect16`` has no native intersector and
Embree splits it into single rays (measured: no gain over embreex).

This module loads the ``libembree4`` shared library shipped in the embreex wheel
(``embreex.libs/`` or next to the extension modules), binds the handful of C entry points it
needs with ctypes (the packet calls are also resolved by name through llvmlite for the numba
kernel ``_trace``, so that numba caches it on disk instead of compiling it in every process),
and builds a robust triangle scene from (V, 3) float32 vertices and (F, 3)
uint32 faces in one ``memmove`` per buffer (Embree allocates the padded buffers with
``rtcSetNewGeometryBuffer``).

Layouts assumed (Embree 4.x, ``rtcore_ray.h``/``rtcore_scene.h``, RTC_MAX_INSTANCE_LEVEL_COUNT
1): ``RTCRayHitW`` (W = 4, 8, 16) is structure-of-arrays, W lanes of 4 bytes per field, in
the order org_x org_y org_z tnear dir_x dir_y dir_z time tfar mask id flags | Ng_x Ng_y Ng_z
u v primID geomID instID (+ instPrimID in 4.3+), 64-byte aligned; ``RTCRayW`` is its first
12 fields.
``RTCIntersectArguments``/``RTCOccludedArguments`` = {uint32 flags, uint32 feature_mask,
context*, filter*, intersect/occluded*, [float minWidthDistanceFactor]} (zero padding beyond).
On load, ``packets_available`` traces one triangle with a known answer through these layouts;
if the library is missing, not Embree 4, or the answer is wrong, ``PacketBindingError``
carries the reason and callers keep the embreex path (``MICROSIM_EMBREE_PACKETS=0`` in the
environment forces that path).

Queries use tnear = 0, mask = all ones, time = 0, like embreex's single rays. A lane's answer
can differ from ``rtcIntersect1`` only where the ray meets two facets at the same float32
distance (a shared edge or vertex): both traversals are exact per triangle in robust mode but
may visit the tied facets in a different order.
"""

from __future__ import annotations

import ctypes
import functools
import glob
import os
import threading

import llvmlite.binding as llvm
import numpy as np
from numba import types as nb_types

from microsim.kernel_cache import cached_njit

__all__ = [
    "PacketBindingError",
    "PacketScene",
    "packets_available",
    "binding_error",
    "library_path",
]

ENV_SWITCH = "MICROSIM_EMBREE_PACKETS"  # "0" disables the packet path (embreex fallback)

# Embree 4 enums (rtcore_common.h, rtcore_buffer.h, rtcore_geometry.h, rtcore_scene.h)
_GEOMETRY_TYPE_TRIANGLE = 0
_BUFFER_TYPE_INDEX, _BUFFER_TYPE_VERTEX = 0, 1
_FORMAT_UINT3, _FORMAT_FLOAT3 = 0x5003, 0x9003
_SCENE_FLAG_ROBUST = 1 << 2
_QUERY_FLAG_COHERENT = 1 << 0
_FEATURE_FLAG_ALL = 0xFFFFFFFF
_DEVICE_PROPERTY_VERSION_MAJOR = 1
_DEVICE_PROPERTY_VERSION = 0
INVALID_ID = 0xFFFFFFFF

# RTCRayHitW fields in order (offset of field k, lane j: k * W + j 4-byte words)
ORG_X, ORG_Y, ORG_Z, TNEAR, DIR_X, DIR_Y, DIR_Z, TIME, TFAR, MASK, RID, RFLAGS = range(12)
NG_X, NG_Y, NG_Z, U, V, PRIM_ID, GEOM_ID, INST_ID = range(12, 20)
_NATIVE_RAY_SUPPORTED = {4: 32, 8: 33, 16: 34}  # RTC_DEVICE_PROPERTY_NATIVE_RAYW_SUPPORTED
PACKET_WORDS = 512  # 2 KiB per packet buffer: 16 lanes x 32 fields (room for instPrimID)
ARGS_WORDS = 16  # 64 bytes for RTCIntersectArguments / RTCOccludedArguments


class PacketBindingError(RuntimeError):
    """The Embree 4 library shipped with embreex could not be bound as expected."""


def library_path() -> str:
    """Path of the libembree4 shared library inside the installed embreex wheel."""
    try:
        import embreex
    except ImportError as exc:  # pragma: no cover - embreex is a dependency
        raise PacketBindingError(f"embreex is not importable ({exc})") from exc
    pkg = os.path.dirname(embreex.__file__)
    site = os.path.dirname(pkg)
    pats = [
        os.path.join(site, "embreex.libs", "libembree4*.so*"),
        os.path.join(pkg, "libembree4*.so*"),
        os.path.join(site, "embreex.libs", "libembree4*.dylib"),
        os.path.join(pkg, "libembree4*.dylib"),
        os.path.join(pkg, ".dylibs", "libembree4*.dylib"),
        os.path.join(pkg, "embree4*.dll"),
    ]
    for pat in pats:
        found = sorted(glob.glob(pat))
        if found:
            return found[0]
    raise PacketBindingError(f"no libembree4 shared library found next to embreex ({pkg})")


def aligned(n_words: int, dtype=np.float32, align: int = 64) -> np.ndarray:
    """Zeroed 1-D array of ``n_words`` 4-byte items whose data is ``align``-byte aligned."""
    raw = np.zeros(n_words * 4 + align, dtype=np.uint8)
    start = (-raw.ctypes.data) % align
    return raw[start : start + n_words * 4].view(dtype)


class _Lib:
    """The bound entry points (ctypes) and one Embree device."""

    def __init__(self, path: str, width: int | None = None):
        try:
            lib = ctypes.CDLL(path)
            llvm.load_library_permanently(path)  # symbols for the numba kernel
        except (OSError, RuntimeError) as exc:
            raise PacketBindingError(f"cannot load {path} ({exc})") from exc
        vp, u32, sz = ctypes.c_void_p, ctypes.c_uint32, ctypes.c_size_t
        sigs = {
            "rtcNewDevice": (vp, [ctypes.c_char_p]),
            "rtcGetDeviceProperty": (ctypes.c_ssize_t, [vp, ctypes.c_int]),
            "rtcGetDeviceError": (ctypes.c_int, [vp]),
            "rtcNewScene": (vp, [vp]),
            "rtcSetSceneFlags": (None, [vp, ctypes.c_int]),
            "rtcNewGeometry": (vp, [vp, ctypes.c_int]),
            "rtcSetNewGeometryBuffer": (vp, [vp, ctypes.c_int, u32, ctypes.c_int, sz, sz]),
            "rtcCommitGeometry": (None, [vp]),
            "rtcAttachGeometry": (u32, [vp, vp]),
            "rtcReleaseGeometry": (None, [vp]),
            "rtcCommitScene": (None, [vp]),
            "rtcReleaseScene": (None, [vp]),
            # packet calls: pointers passed as machine-word integers (numba-callable)
        }
        for w in _NATIVE_RAY_SUPPORTED:
            sigs[f"rtcIntersect{w}"] = (None, [ctypes.c_ssize_t] * 4)
            sigs[f"rtcOccluded{w}"] = (None, [ctypes.c_ssize_t] * 4)
        for name, (res, args) in sigs.items():
            try:
                fn = getattr(lib, name)
            except AttributeError as exc:
                raise PacketBindingError(f"{path} has no symbol {name}") from exc
            fn.restype, fn.argtypes = res, args
            setattr(self, name, fn)
        self.lib, self.path = lib, path
        self.device = lib.rtcNewDevice(None)
        if not self.device:
            raise PacketBindingError(f"rtcNewDevice failed ({path})")
        major = lib.rtcGetDeviceProperty(self.device, _DEVICE_PROPERTY_VERSION_MAJOR)
        self.version = int(lib.rtcGetDeviceProperty(self.device, _DEVICE_PROPERTY_VERSION))
        if major != 4:
            raise PacketBindingError(f"{path} is Embree {major}, not Embree 4")
        native = [
            w
            for w, prop in _NATIVE_RAY_SUPPORTED.items()
            if lib.rtcGetDeviceProperty(self.device, prop) == 1
        ]
        self.width = width or (max(native) if native else 8)  # lanes per packet call
        self.native = native

    def check(self, what: str) -> None:
        err = self.rtcGetDeviceError(self.device)
        if err:
            raise PacketBindingError(f"Embree error {err} in {what}")


@functools.cache
def _lib() -> _Lib:
    lib = _Lib(library_path())
    _self_test(lib)
    return lib


def binding_error() -> str | None:
    """Why the packet path is unavailable (None when it is available)."""
    if os.environ.get(ENV_SWITCH, "1") == "0":
        return f"disabled by {ENV_SWITCH}=0"
    try:
        _lib()
    except PacketBindingError as exc:
        return str(exc)
    return None


def packets_available() -> bool:
    """True when the Embree 4 packet calls are bound and passed the layout self-test."""
    return binding_error() is None


_SIG = nb_types.void(nb_types.intp, nb_types.intp, nb_types.intp, nb_types.intp)
# resolved by name in the library loaded with llvmlite (``_Lib``): no address is baked into
# the compiled kernel, so numba caches it on disk (no compile per process)
_intersect4 = nb_types.ExternalFunction("rtcIntersect4", _SIG)
_intersect8 = nb_types.ExternalFunction("rtcIntersect8", _SIG)
_intersect16 = nb_types.ExternalFunction("rtcIntersect16", _SIG)
_occluded4 = nb_types.ExternalFunction("rtcOccluded4", _SIG)
_occluded8 = nb_types.ExternalFunction("rtcOccluded8", _SIG)
_occluded16 = nb_types.ExternalFunction("rtcOccluded16", _SIG)


def _layout(width: int) -> np.ndarray:
    """Word offsets of the RTCRayHitW fields used (ORG_X … INST_ID) for ``width`` lanes."""
    fields = (ORG_X, ORG_Y, ORG_Z, TNEAR, DIR_X, DIR_Y, DIR_Z, TIME, TFAR, MASK, RID, RFLAGS)
    fields += (PRIM_ID, GEOM_ID, INST_ID)
    return np.array(fields, dtype=np.int64) * width


@cached_njit(nogil=True)
def _trace(scene, W, lay, o, d, tfar, occlusion, prim, t_out, buf, ubuf, valid, args):
    """Rays o[i] + t d[i] (d of shape (1, 3): shared), t in [0, tfar[i]], W (4, 8 or 16) per
    packet call; ``lay`` = ``_layout(W)``. Intersection: prim[i] = primID (−1 without a hit),
    t_out[i] = hit distance (tfar[i] without); occlusion: prim[i] = 0 if blocked else −1."""
    ox, oy, oz, tn, dx, dy, dz, tm, tfr = (
        lay[0],
        lay[1],
        lay[2],
        lay[3],
        lay[4],
        lay[5],
        lay[6],
        lay[7],
        lay[8],
    )
    msk, rid, rfl, pid, gid, iid = lay[9], lay[10], lay[11], lay[12], lay[13], lay[14]
    u_all = np.uint32(0xFFFFFFFF)
    n = o.shape[0]
    shared = d.shape[0] == 1
    bptr = buf.ctypes.data
    vptr = valid.ctypes.data
    aptr = args.ctypes.data
    for j in range(W):  # the fields Embree only reads, written once for every packet
        buf[tn + j] = 0.0
        buf[tm + j] = 0.0
        ubuf[msk + j] = u_all
        ubuf[rid + j] = 0
        ubuf[rfl + j] = 0
        if shared:
            buf[dx + j] = d[0, 0]
            buf[dy + j] = d[0, 1]
            buf[dz + j] = d[0, 2]
    for base in range(0, n, W):
        m = min(W, n - base)
        for j in range(m):
            i = base + j
            buf[ox + j] = o[i, 0]
            buf[oy + j] = o[i, 1]
            buf[oz + j] = o[i, 2]
            if not shared:
                buf[dx + j] = d[i, 0]
                buf[dy + j] = d[i, 1]
                buf[dz + j] = d[i, 2]
            buf[tfr + j] = tfar[i]
            ubuf[gid + j] = u_all  # Embree writes the hit fields only on a hit
            ubuf[pid + j] = u_all
            ubuf[iid + j] = u_all
            valid[j] = -1
        for j in range(m, W):
            valid[j] = 0
        if occlusion:
            if W == 16:
                _occluded16(vptr, scene, bptr, aptr)
            elif W == 8:
                _occluded8(vptr, scene, bptr, aptr)
            else:
                _occluded4(vptr, scene, bptr, aptr)
            for j in range(m):
                prim[base + j] = 0 if buf[tfr + j] == -np.inf else -1
        else:
            if W == 16:
                _intersect16(vptr, scene, bptr, aptr)
            elif W == 8:
                _intersect8(vptr, scene, bptr, aptr)
            else:
                _intersect4(vptr, scene, bptr, aptr)
            for j in range(m):
                hit = ubuf[gid + j] != u_all
                prim[base + j] = np.int32(ubuf[pid + j]) if hit else -1
                t_out[base + j] = buf[tfr + j]
    return n


def _buffers():
    """This thread's packet buffers (ray/hit words, their uint32 view, the valid mask, the
    query arguments), made once per thread: ``_trace`` sets every field it relies on."""
    try:
        return _thread.buffers
    except AttributeError:
        buf = aligned(PACKET_WORDS)
        args = aligned(ARGS_WORDS, np.uint32)
        args[0] = _QUERY_FLAG_COHERENT
        args[1] = _FEATURE_FLAG_ALL  # context/filter/callback pointers stay NULL
        _thread.buffers = buf, buf.view(np.uint32), aligned(16, np.int32), args
        return _thread.buffers


_thread = threading.local()


class PacketScene:
    """Robust Embree 4 triangle scene traced in coherent ray packets (``width`` lanes).

    ``vertices`` (V, 3) and ``faces`` (F, 3) are copied once each into Embree's own
    buffers (float32 / uint32); the BVH is built here (``rtcCommitScene``)."""

    def __init__(self, vertices, faces, *, _bound: _Lib | None = None):
        lib = _lib() if _bound is None else _bound
        v = np.ascontiguousarray(vertices, dtype=np.float32)
        f = np.ascontiguousarray(faces, dtype=np.uint32)
        if v.ndim != 2 or v.shape[1] != 3 or f.ndim != 2 or f.shape[1] != 3:
            raise ValueError("vertices and faces must be (V, 3) and (F, 3) arrays")
        self._lib, self.width = lib, lib.width
        self.scene = lib.rtcNewScene(lib.device)
        lib.rtcSetSceneFlags(self.scene, _SCENE_FLAG_ROBUST)
        geom = lib.rtcNewGeometry(lib.device, _GEOMETRY_TYPE_TRIANGLE)
        pv = lib.rtcSetNewGeometryBuffer(geom, _BUFFER_TYPE_VERTEX, 0, _FORMAT_FLOAT3, 12, len(v))
        pf = lib.rtcSetNewGeometryBuffer(geom, _BUFFER_TYPE_INDEX, 0, _FORMAT_UINT3, 12, len(f))
        lib.check("rtcSetNewGeometryBuffer")
        if not pv or not pf:
            raise PacketBindingError("rtcSetNewGeometryBuffer returned NULL")
        ctypes.memmove(pv, v.ctypes.data, v.nbytes)
        ctypes.memmove(pf, f.ctypes.data, f.nbytes)
        lib.rtcCommitGeometry(geom)
        lib.rtcAttachGeometry(self.scene, geom)
        lib.rtcReleaseGeometry(geom)
        lib.rtcCommitScene(self.scene)
        lib.check("building the scene")

    def __del__(self):
        scene = getattr(self, "scene", None)
        if scene:
            self._lib.rtcReleaseScene(scene)
            self.scene = None

    def run(self, origins, dirs, dists, occlusion: bool = False):
        """Trace rays ``origins`` (N, 3) float32 along ``dirs`` ((N, 3) or (1, 3) shared,
        float32, not necessarily unit) over t in [0, ``dists``] (N,) float32.

        Returns (prim, t): prim (N,) int32 primID (−1 without a hit) and t (N,) float32 hit
        distance (``dists`` where nothing was hit); for ``occlusion`` prim is 0 where the
        segment is blocked, −1 where it is free, and t is None."""
        o = np.ascontiguousarray(origins, dtype=np.float32)
        d = np.ascontiguousarray(dirs, dtype=np.float32)
        tf = np.ascontiguousarray(dists, dtype=np.float32)
        n = len(o)
        if d.shape[0] not in (1, n) or tf.shape != (n,):
            raise ValueError("dirs must be (N, 3) or (1, 3) and dists (N,)")
        prim = np.empty(n, dtype=np.int32)
        t = np.empty(0 if occlusion else n, dtype=np.float32)
        buf, ubuf, valid, args = _buffers()
        w = self.width
        _trace(self.scene, w, _layout(w), o, d, tf, occlusion, prim, t, buf, ubuf, valid, args)
        return prim, (None if occlusion else t)


def _self_test(lib: _Lib) -> None:
    """Trace one triangle through the assumed struct layouts; raise if the answer is wrong."""
    v = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], dtype=np.float32)
    try:
        s = PacketScene(v, np.array([[0, 1, 2]]), _bound=lib)
    except PacketBindingError:
        raise
    except Exception as exc:  # noqa: BLE001 - any failure means the binding is unusable
        raise PacketBindingError(f"building a test scene failed ({exc})") from exc
    n = 20  # one or more full packets and a partial one
    o = np.zeros((n, 3), dtype=np.float32)
    o[:, 0] = np.where(np.arange(n) % 2 == 0, 0.25, 2.0)  # even lanes above the triangle
    o[:, 1] = 0.25
    o[:, 2] = np.arange(1, n + 1, dtype=np.float32)
    d = np.array([[0, 0, -1]], dtype=np.float32)
    tf = np.full(n, 1e30, dtype=np.float32)
    prim, t = s.run(o, d, tf)
    blocked, _ = s.run(o, d, tf, occlusion=True)
    even = np.arange(n) % 2 == 0
    ok = (
        np.all(prim[even] == 0)
        and np.all(prim[~even] == -1)
        and np.all(np.abs(t[even] - o[even, 2]) <= 4 * np.spacing(o[even, 2]))  # float32
        and np.all(blocked[even] == 0)
        and np.all(blocked[~even] == -1)
    )
    if not ok:
        raise PacketBindingError(
            f"packet self-test failed on {lib.path}: the RTCRayHit / argument layouts are "
            "not what microsim.sim.embree_packets expects"
        )
