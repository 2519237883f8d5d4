"""The uniform numbers of a PCG64 stream, compiled, bitwise as NumPy draws them.

``numpy.random.Generator(PCG64).random`` steps a 128-bit linear congruential state
s ← a·s + c (mod 2¹²⁸; a = ``MULTIPLIER``, c the stream's odd increment), outputs the XSL-RR
permutation of the new state (the high and low 64-bit halves xor-ed, rotated right by the top
6 bits) and keeps the top 53 bits of that output as a double in [0, 1): (x >> 11)·2⁻⁵³
(O'Neill 2014, §6.3; NumPy's ``pcg64.h``). ``fill_uniforms`` does the same in a compiled
loop: a stream is a sequence of states, so the numbers from position p on are those of the
state advanced by p steps (s ← A_p·s + C_p, computed by squaring: Brown 1994), and an array
is filled in four consecutive runs, each from its own jumped state, whose steps are
independent of one another and so overlap in the processor's pipeline, where NumPy's one
generator waits for each step's multiply before the next. tests/test_pcg64.py compares them
bit for bit with NumPy.
"""

from __future__ import annotations

import numpy as np
from llvmlite import ir
from numba import types
from numba.extending import intrinsic

from microsim.jit import compiled, inlined

__all__ = ["MULTIPLIER", "stream_of", "fill_uniforms"]

MULTIPLIER = 0x2360ED051FC65DA44385DF649FCCF645
"""PCG64's 128-bit LCG multiplier (NumPy's ``PCG_DEFAULT_MULTIPLIER_128``)."""
_RUNS = 4  # the runs ``fill_uniforms`` fills side by side (its four states h0 … h3)

_HALF = (1 << 64) - 1
_MUL_HI, _MUL_LO = np.uint64(MULTIPLIER >> 64), np.uint64(MULTIPLIER & _HALF)
_ZERO, _ONE = np.uint64(0), np.uint64(1)
_S11, _S58, _S64, _M63 = np.uint64(11), np.uint64(58), np.uint64(64), np.uint64(63)
_TO_UNIT = 1.0 / 9007199254740992.0  # 2⁻⁵³


def stream_of(state: dict) -> tuple:
    """The kernels' form of a ``numpy.random.PCG64`` ``state`` dict: its state and increment
    as 64-bit halves (state high, state low, increment high, increment low), uint64."""
    s, c = int(state["state"]["state"]), int(state["state"]["inc"])
    return tuple(np.uint64(v) for v in (s >> 64, s & _HALF, c >> 64, c & _HALF))


@intrinsic
def _wide_product(typingctx, a, b):
    """(high, low) 64-bit halves of the full 128-bit product of uint64 ``a`` and ``b``."""
    sig = types.UniTuple(types.uint64, 2)(types.uint64, types.uint64)

    def codegen(context, builder, signature, args):
        i128, i64 = ir.IntType(128), ir.IntType(64)
        p = builder.mul(builder.zext(args[0], i128), builder.zext(args[1], i128))
        hi = builder.trunc(builder.lshr(p, ir.Constant(i128, 64)), i64)
        return context.make_tuple(builder, signature.return_type, (hi, builder.trunc(p, i64)))

    return sig, codegen


@inlined
def _mul(ah, al, bh, bl):
    """(a·b) mod 2¹²⁸ of 128-bit numbers given as uint64 halves."""
    ph, pl = _wide_product(al, bl)
    return ph + ah * bl + al * bh, pl


@inlined
def _add(ah, al, bh, bl):
    """(a + b) mod 2¹²⁸ of 128-bit numbers given as uint64 halves."""
    lo = al + bl
    return ah + bh + (_ONE if lo < al else _ZERO), lo


@inlined
def _jump(sh, sl, ch, cl, steps):
    """The LCG state (sh, sl) advanced by ``steps`` ≥ 0 steps of s ← a·s + c (increment
    (ch, cl)): s·A + C with A = aᵏ and C = c·(aᵏ⁻¹ + … + 1), accumulated over the bits of k."""
    ah, al, gh, gl = _ZERO, _ONE, _ZERO, _ZERO  # A, C so far
    mh, ml, ph, pl = _MUL_HI, _MUL_LO, ch, cl  # a^(2^j) and c·(a^(2^j) − 1)/(a − 1)
    k = steps
    while k > 0:
        if k & 1:
            ah, al = _mul(ah, al, mh, ml)
            gh, gl = _mul(gh, gl, mh, ml)
            gh, gl = _add(gh, gl, ph, pl)
        nh, nl = _add(mh, ml, _ZERO, _ONE)
        ph, pl = _mul(nh, nl, ph, pl)
        mh, ml = _mul(mh, ml, mh, ml)
        k >>= 1
    sh, sl = _mul(sh, sl, ah, al)
    return _add(sh, sl, gh, gl)


@inlined
def _step(sh, sl, ch, cl):
    """One step s ← a·s + c (mod 2¹²⁸)."""
    sh, sl = _mul(sh, sl, _MUL_HI, _MUL_LO)
    return _add(sh, sl, ch, cl)


@inlined
def _unit(sh, sl):
    """The double in [0, 1) of state s: XSL-RR output x, then (x >> 11)·2⁻⁵³."""
    x = sh ^ sl
    rot = sh >> _S58
    x = (x >> rot) | (x << ((_S64 - rot) & _M63))
    return np.float64(np.int64(x >> _S11)) * _TO_UNIT  # < 2⁵³: exact as a signed integer


@compiled
def fill_uniforms(stream, position, out):
    """``out`` ← the numbers at ``position`` … ``position`` + len(out) − 1 of the PCG64
    ``stream`` (``stream_of``; position 0 is the first number a fresh generator draws),
    bitwise ``Generator(PCG64).random`` after ``advance(position)``: four runs of
    ⌈len/4⌉ numbers, each from its own jumped state, one step of each per pass."""
    sh, sl, ch, cl = stream
    n = len(out)
    q = (n + _RUNS - 1) // _RUNS
    h0, l0 = _jump(sh, sl, ch, cl, position)
    h1, l1 = _jump(h0, l0, ch, cl, q)
    h2, l2 = _jump(h1, l1, ch, cl, q)
    h3, l3 = _jump(h2, l2, ch, cl, q)
    last = max(n - 3 * q, 0)  # the last run's length (≤ q)
    for k in range(q):
        h0, l0 = _step(h0, l0, ch, cl)
        h1, l1 = _step(h1, l1, ch, cl)
        h2, l2 = _step(h2, l2, ch, cl)
        h3, l3 = _step(h3, l3, ch, cl)
        out[k] = _unit(h0, l0)
        if k < last:  # all four runs (every pass but the last few)
            out[q + k], out[2 * q + k], out[3 * q + k] = _unit(h1, l1), _unit(h2, l2), _unit(h3, l3)
        else:  # the first three (short arrays: the first two or the first alone)
            if q + k < n:
                out[q + k] = _unit(h1, l1)
            if 2 * q + k < n:
                out[2 * q + k] = _unit(h2, l2)
