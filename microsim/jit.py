"""Compile options of every kernel (numba, ``nogil``, cached on disk where a cache folder is
writable: ``microsim.kernel_cache``) and the rules they follow.

Why compiled: written as NumPy array passes, the steps around Embree's traversal (ray
origins, segment bounds, hit points, masking-ray starts, per-facet look-ups, tallies) cost
about as much per sample as the traversal itself, each pass reading and writing whole arrays;
one fused loop per stage does the same arithmetic in a few ns per ray and releases the GIL, so
both threads run in parallel (``microsim bench`` reports the pipeline next to raw Embree).

Vectorised passes: the heavier per-ray arithmetic (groove-frame rotations, Fresnel weights,
bins, masking-ray starts) runs in branch-free loops over tiles of ``TILE`` rays that LLVM
compiles to the CPU's vector instructions (AVX2 or AVX-512), with the per-facet look-ups
(indexed loads, which it does not vectorise) in scalar loops between them, and without a libm call
per ray (``trig.cos_sin``, ``trig.atan_approx``; bins near an edge by ``Bins.locate``'s
arithmetic). Those use ``error_model="numpy"`` (``vectorised``): a zero-divisor check is a
branch per division, which keeps a loop scalar (the values a select then discards may be inf
or NaN). And they index their arrays by the loop variable itself, on views that start at the
tile's first ray (``a[t:]``), not by ``t + j``: numba wraps a negative index, and an index
the compiler cannot tell is not negative turns each load and store of the vector loop into
one per lane.

Reproducibility: every kernel is a loop in ray order that evaluates each ray on its own, with
no fast-math (no FMA contraction or reassociation); sums (``tally_kernels``) add a block's
rays in ray order, like ``np.bincount``. Results are therefore independent of batch size and
thread count; tests/test_kernels.py checks each kernel against the NumPy statement of what it
computes. Grouped arguments are ``typing.NamedTuple``s of arrays and scalars (passed by
value). Units and frames are the callers': tile coordinates, unit directions, distances
along the ray.

No reference counting: the kernels are compiled without numba's runtime (``_nrt=False``), so
they cannot allocate (scratch comes from the caller or from an ``allocating`` kernel around
them), and numba does not increment and decrement the count of every array a helper
receives — on the heightfield grid walk, which hands its height arrays to an inlined helper
per ray, those calls cost a fifth of its time. The few kernels that allocate their per-tile
scratch (``allocating``) keep the runtime; their per-ray loops index arrays directly.

Compile time (a fresh install, and every test run's warm-up, compiles them all): numba
compiles a ``compiled`` callee once per distinct tuple of argument types, and a constant
passed from compiled code is typed as its own literal (``m = 0`` carried through a loop of
calls compiles the callee for ``Literal[int](0)`` and for ``int64``). Compiled callers
therefore pass ``int(0)``/``bool(True)`` (plain types), the ``NamedTuple`` their Python
callers pass, and read-only arrays (``read_only``) where Python passes read-only ones.
``inlined`` helpers are copied into every call site before typing, and numba's copy grows
with the square of a helper's size: a large helper (the grid walk ``cast_one``) has one call
site per kernel.
"""

from __future__ import annotations

import numpy as np
from numba import types
from numba.core import cgutils
from numba.extending import intrinsic

from microsim.kernel_cache import cached_njit

__all__ = [
    "compiled",
    "inlined",
    "vectorised",
    "vector_inlined",
    "allocating",
    "TILE",
    "read_only",
    "numba_target",
    "wide_vectors",
    "lane_scratch",
]

compiled = cached_njit(nogil=True, _nrt=False)


inlined = cached_njit(nogil=True, inline="always", _nrt=False)  # the per-ray loops' helpers


# branch-free passes the compiler vectorises: float division by zero gives inf/NaN there
# instead of raising (the check is a branch per division), values the selects then discard
vectorised = cached_njit(nogil=True, error_model="numpy", _nrt=False)

# ``vectorised`` kernels that allocate their per-tile scratch (numba's runtime kept)
allocating = cached_njit(nogil=True, error_model="numpy")


TILE = 1024  # rays per tile of a kernel's vectorised passes (its scratch stays in L1/L2)


vector_inlined = cached_njit(nogil=True, error_model="numpy", inline="always", _nrt=False)


def read_only(a: np.ndarray) -> np.ndarray:
    """A read-only view of ``a``, for an argument that reaches a kernel both as a frozen and as
    a writable array: typed read-only every time, the kernel is compiled once (above)."""
    view = a.view()
    view.flags.writeable = False
    return view


def numba_target() -> str:
    """numba's target CPU: the host's, or the one ``NUMBA_CPU_NAME`` names — with "with the
    host's features" where ``NUMBA_CPU_FEATURES`` is unset, as numba then compiles for that
    CPU with every feature of the host (its AVX-512 ones too), and with the features
    ``NUMBA_CPU_FEATURES`` lists where it is set to any (``NUMBA_CPU_FEATURES=""``: the
    named CPU's own)."""
    from numba.core import config

    if config.CPU_NAME is None:
        import llvmlite.binding as llvm

        return str(llvm.get_host_cpu_name())
    if config.CPU_FEATURES is None:
        return f"{config.CPU_NAME} with the host's features"
    return f"{config.CPU_NAME} {config.CPU_FEATURES}".strip()


def wide_vectors() -> bool:
    """Whether numba compiles for AVX-512 (``avx512f`` among its target's features): the host's,
    or those ``NUMBA_CPU_FEATURES`` lists (``numba_target``)."""
    from numba.core import config

    if config.CPU_FEATURES is not None:
        features = config.CPU_FEATURES
    else:
        import llvmlite.binding as llvm

        features = llvm.get_host_cpu_features().flatten()
    return "+avx512f" in features.split(",")


@intrinsic
def lane_scratch(typingctx, size, dtype):
    """A pointer to ``size`` (a compile-time int) values of ``dtype`` on the calling kernel's
    stack, indexed p[k] (no runtime needed). Lane state lives there: the compiler knows that
    stack memory no array argument can alias, so a loop over lanes that stores to it and loads
    from arrays at computed indices (gathers) can be vectorised."""

    def lower(context, builder, signature, args):
        return cgutils.alloca_once(builder, context.get_value_type(dtype.dtype), size=args[0])

    return types.CPointer(dtype.dtype)(types.int64, dtype), lower
