"""Per-block tallies (``tallies``): Σw, Σw², counts and the paired-strata pair sum
Σ w_2k·w_2k+1 per bin, stored sparsely per block, and the ledger per class; added in ray
order and block order, so bitwise independent of chunking and threads."""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from microsim.jit import compiled, inlined

from .engine.codes import DOWNWARD, MASKED, RAY_MISSED, RAY_UNRESOLVED, SINGLE


@compiled
def block_tallies(
    status, weight, where, block, acc, touched, out_bin, out_sums, out_cnt, offsets, ln, lf
):
    """Per-block sums of a batch of whole blocks of ``block`` rays (``tallies.split_tallies``),
    added in ray order, stored sparsely (only the bins a block touches: a block has at most
    ``block`` events, while a fine grid has thousands of bins).

    For single-bounce rays with a bin (``where`` ≥ 0): Σw, Σw² and the pair sum
    (w_2k·w_2k+1 where rays 2k and 2k + 1, counted from the batch start, are both tallied in
    the same bin) accumulate in the dense scratch ``acc`` (3, bins) (zero on entry and on
    return) and the counts in ``touched`` (bins,) int64; block b's bins are then written, in
    the order first touched, to ``out_bin``/``out_sums`` (3, N)/``out_cnt`` between
    ``offsets[b]`` and ``offsets[b + 1]``. Ledger counts and Fresnel sums per class go to
    ``ln``, ``lf`` (blocks, classes)."""
    n = len(status)
    j = 0
    for b in range((n + block - 1) // block):
        offsets[b] = j
        lo, hi = b * block, min(n, (b + 1) * block)
        n0 = n1 = n2 = n3 = n4 = 0  # ledger sums in registers, per class
        f0 = f1 = f2 = f3 = f4 = 0.0
        for i in range(lo, hi):
            s = status[i]
            if s == SINGLE:
                n0 += 1
                f0 += weight[i]
            elif s == MASKED:
                n1 += 1
                f1 += weight[i]
            elif s == DOWNWARD:
                n2 += 1
                f2 += weight[i]
            elif s == RAY_UNRESOLVED:
                n3 += 1
                f3 += weight[i]
            else:
                n4 += 1
                f4 += weight[i]
            if s == SINGLE and where[i] >= 0:
                k = where[i]
                out_bin[j] = k  # kept (j advances) only on the bin's first event: no branch
                j += touched[k] == 0
                w = weight[i]
                acc[0, k] += w
                acc[1, k] += w * w
                touched[k] += 1
        ln[b, SINGLE], ln[b, MASKED], ln[b, DOWNWARD] = n0, n1, n2
        ln[b, RAY_UNRESOLVED], ln[b, RAY_MISSED] = n3, n4
        lf[b, SINGLE], lf[b, MASKED], lf[b, DOWNWARD] = f0, f1, f2
        lf[b, RAY_UNRESOLVED], lf[b, RAY_MISSED] = f3, f4
        for i in range(lo, hi - 1, 2):
            if (
                status[i] == SINGLE
                and status[i + 1] == SINGLE
                and where[i] >= 0
                and where[i] == where[i + 1]
            ):
                acc[2, where[i]] += weight[i] * weight[i + 1]
        close_block(b, j, ChunkSums(acc, touched, out_bin, out_sums, out_cnt, offsets, ln, lf))
    offsets[(n + block - 1) // block] = j  # also for an empty batch


@compiled
def add_blocks(sum_w, sum_w2, count, sum_pair, block2, block_rays, led_n, led_f, first, chunk):
    """Add a chunk's sparse per-block sums (``block_tallies``: block b's distinct bins are
    ``bins[offsets[b]:offsets[b + 1]]``) to the running totals, block by block in block order
    — bitwise what adding each block's dense sums would give (an untouched bin adds 0).
    ``chunk``: (bins, sums, cnt, offsets, ln, lf) as ``block_tallies`` writes them. Besides
    Σw, Σw², counts and Σ pairs per bin, the blocks' own sums: ``block2`` Σ_b S_b² and
    ``block_rays`` Σ_b m_b S_b (S_b the block's Σw in the bin, m_b its rays: its counts in
    the ``first`` first-bounce ledger classes, which every ray enters once)."""
    bins, sums, cnt, offsets, ln, lf = chunk
    for b in range(len(offsets) - 1):
        m = 0
        for c in range(first):
            m += ln[b, c]
        for q in range(offsets[b], offsets[b + 1]):
            k = bins[q]
            s = sums[0, q]
            sum_w[k] += s
            sum_w2[k] += sums[1, q]
            count[k] += cnt[q]
            sum_pair[k] += sums[2, q]
            block2[k] += s * s
            block_rays[k] += m * s
        for c in range(led_n.shape[0]):
            led_n[c] += ln[b, c]
            led_f[c] += lf[b, c]


class ChunkSums(NamedTuple):
    """Where a chunk's per-block tallies are summed (``order_block_tallies``): the dense
    scratch ``acc`` (3, bins) and ``touched`` (bins,) (zero on entry and on return), each
    block's bins in the order first touched in ``out_bin`` with their Σw, Σw², Σ pairs in
    ``out_sums`` (3, ·) and counts in ``out_cnt``, block b's between ``offsets[b]`` and
    ``offsets[b + 1]``, and its ledger counts and weight sums ``ln``, ``lf`` (blocks,
    classes)."""

    acc: np.ndarray
    touched: np.ndarray
    out_bin: np.ndarray
    out_sums: np.ndarray
    out_cnt: np.ndarray
    offsets: np.ndarray
    ln: np.ndarray
    lf: np.ndarray


@inlined
def tally_path(i, r, b, j, outcome, sums, tir_col):
    """Add path ``i``, the ``r``-th of block ``b``, to the block's sums (``order_block_tallies``)
    when its ``outcome`` (``dielectric.InterfaceOutcome``'s fields, ``tir`` empty for opaque
    chains) is final; ``j``: the bins listed so far, returned updated. The block's first path
    opens its list, every second one adds its pair's product; ``close_block`` writes the block
    out after its last."""
    status1, weight1, term, wterm, where, tir = outcome
    if r == 0:
        sums.offsets[b] = j
    s = status1[i]
    sums.ln[b, s] += 1
    sums.lf[b, s] += weight1[i]
    t = term[i]
    sums.ln[b, 5 + t] += 1
    sums.lf[b, 5 + t] += wterm[i]
    if len(tir) > 0 and tir[i] != 0:
        for q in range(4):
            if (tir[i] >> q) & 1:
                sums.ln[b, tir_col + q] += 1
                sums.lf[b, tir_col + q] += 1.0
    k = where[i]
    if k >= 0:
        if sums.touched[k] == 0:
            sums.out_bin[j] = k
            j += 1
        v = wterm[i]
        sums.acc[0, k] += v
        sums.acc[1, k] += v * v
        sums.touched[k] += 1
        # rays 2k, 2k + 1 of the block (blocks are even) are one stratum's pair
        if r & 1 and where[i - 1] == k:
            sums.acc[2, k] += wterm[i - 1] * v
    return j


@inlined
def close_block(b, j, sums):
    """Write block ``b``'s bins (listed from ``sums.offsets[b]`` to ``j``) out of the dense
    scratch, zeroing it, and open the next block's list at ``j``."""
    for q in range(sums.offsets[b], j):
        k = sums.out_bin[q]
        for m in range(3):
            sums.out_sums[m, q] = sums.acc[m, k]
            sums.acc[m, k] = 0.0
        sums.out_cnt[q] = sums.touched[k]
        sums.touched[k] = 0
    sums.offsets[b + 1] = j


@compiled
def order_block_tallies(outcome, block, sums, tir_col):
    """``block_tallies`` for paths followed over several bounces (``bounces``), written to the
    ``ChunkSums`` ``sums``: a path that escapes adds its carried weight ``wterm`` to its
    (order, bin) slot ``where`` (≥ 0; −1 for paths that do not escape), with Σw, Σw², counts
    and the pair sum (rays 2k, 2k + 1 in the same slot) per block, stored sparsely as there.
    Ledger (blocks, 5 + N_TERMINAL): columns 0–4 count the first-bounce classes ``status1``
    and sum their Fresnel weights ``weight1`` (``paths.LEDGER``), columns 5 + ``term`` the
    terminal classes and sum their carried weights ``wterm`` (the energy each class takes
    away). ``tir`` (paths through a dielectric interface; else empty): each path's
    total-internal-reflection bits, bit k counted in column ``tir_col`` + k of both ``ln``
    and ``lf``. ``outcome``: (status1, weight1, term, wterm, where, tir); each path is added
    by ``tally_path``, as the loops that follow paths to their end add them."""
    n = len(outcome[2])
    j = 0
    sums.offsets[0] = 0
    for b in range((n + block - 1) // block):
        lo, hi = b * block, min(n, (b + 1) * block)
        for i in range(lo, hi):
            j = tally_path(i, i - lo, b, j, outcome, sums, tir_col)
        close_block(b, j, sums)
