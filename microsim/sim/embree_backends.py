"""The Embree scene a ``Tracer`` walks: embreex's single rays (``EmbreexScene``, the tests'
reference) or coherent packets (``embree_packets.PacketScene``), behind one call
``run(origins, dirs, dists, occlusion) -> (prim, t)`` (``open_scene`` picks one)."""

from __future__ import annotations

import numpy as np
from embreex import mesh_construction as mc
from embreex import rtcore_scene as rs

from microsim.errors import UsageError

from . import embree_packets

__all__ = ["BACKENDS", "EmbreexScene", "check_backend", "scene_backend", "open_scene"]

BACKENDS = ("auto", "packets", "embreex")


class EmbreexScene:
    """Robust embreex scene (``embree``) of (V, 3) ``vertices`` and (F, 3) ``faces``
    (float32/int32 copies); the BVH is built here, so that tracing times exclude it."""

    def __init__(self, vertices: np.ndarray, faces: np.ndarray):
        self.embree = rs.EmbreeScene(robust=True)
        self._mesh = mc.TriangleMesh(
            self.embree, vertices.astype(np.float32), faces.astype(np.int32)
        )
        # embreex builds the BVH (rtcCommit) on the first query
        self.embree.run(
            np.zeros((1, 3), dtype=np.float32),
            np.array([[0.0, 0.0, -1.0]], dtype=np.float32),
            dists=0.0,
        )

    def run(self, origins, dirs, dists, occlusion: bool = False):
        """``PacketScene.run``'s answer (prim, t) from embreex (t None for ``occlusion``)."""
        if occlusion:
            return self.embree.run(origins, dirs, dists=dists, query="OCCLUDED"), None
        res = self.embree.run(origins, dirs, dists=dists, query="INTERSECT", output=1)
        return res["primID"], res["tfar"]


def check_backend(backend: str) -> None:
    """UsageError unless ``backend`` is one of ``BACKENDS``."""
    if backend not in BACKENDS:
        raise UsageError(f"backend must be 'auto', 'packets' or 'embreex', got {backend!r}")


def scene_backend(backend: str) -> str:
    """The backend ``backend`` resolves to: "embreex", "packets" (UsageError when the library
    cannot be bound) or "auto" (packets when available, else embreex;
    ``MICROSIM_EMBREE_PACKETS=0`` in the environment makes it embreex)."""
    check_backend(backend)
    reason = None if backend == "embreex" else embree_packets.binding_error()
    if backend == "packets" and reason is not None:
        raise UsageError(f"backend='packets' is unavailable here: {reason}")
    return "packets" if backend != "embreex" and reason is None else "embreex"


def open_scene(vertices: np.ndarray, faces: np.ndarray, backend: str):
    """The scene of a resolved ``backend`` (``scene_backend``), its BVH built."""
    if backend == "packets":
        return embree_packets.PacketScene(vertices, faces)
    return EmbreexScene(vertices, faces)
