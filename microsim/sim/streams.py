"""Per-block random streams and the origins of the primary rays.

The primary rays of one (realisation r, incidence i) are numbered 0 … N − 1 and cut into
blocks of ``BLOCK`` rays. Block b draws its numbers from its own slot of the PCG64 stream
seeded with the key (seed, r, i) (``block_uniforms``), so its rays depend on (key, b) alone:
never on how blocks are grouped into chunks or spread over threads. This is what makes
``simulate`` bitwise reproducible for any ``threads``/``chunk`` and resumable block by block.

Origins lie on the horizontal plane z = zmax + top_margin above one tile
[−Lx/2, Lx/2] × [−Ly/2, Ly/2] (tile coordinates), spread uniformly over it: uniform origins on
a horizontal plane sample the surface seen from wi flux-weighted, which is the
(n_j·wi) dx_j / ((n·wi) dA) factor of the explicit integral (Mikkelsen 2009, eq. 9).
``"stratified"`` origins give rays 2k and 2k + 1 the stratum [2k/N, (2k + 2)/N) of a
row-major sweep of the tile, each uniform inside it (two independent samples per stratum,
which makes the standard error unbiased: ``tallies.bin_estimate``); ``"independent"``
origins are i.i.d. uniform. Angles are in radians here (groove azimuths ψ, block rotations
ψ_b).
"""

from __future__ import annotations

import functools
from typing import NamedTuple, Sequence

import numpy as np

from . import origin_kernels, pcg64
from .scratch import WorkArray, WorkColumns
from .tracer import Tracer

__all__ = [
    "BLOCK",
    "ORIGINS",
    "DESIGN",
    "key_stream",
    "block_uniforms",
    "block_span",
    "sweep_rows",
    "StratifiedDraw",
    "stratified_draw",
    "chunk_origins",
    "groove_starts",
    "block_origins",
    "block_rotation",
]

BLOCK = 4096
"""Rays per block: the unit of the random streams, of the tallies and of resuming (even, so
the pairs (2k, 2k + 1) of the paired-strata error never straddle two blocks)."""
ORIGINS = ("stratified", "independent")
DESIGN = 2
"""Version of the rays' design (their origins and strata): a resumed run or a cached result
must share it. 2: rays 2k and 2k + 1 share a stratum, and ``isotropic`` blocks are replicates
(saved runs without the key are of design 1: one ray per stratum)."""
ROTATION_STREAM = 0x150
"""Extra key of the per-block incidence-azimuth generator (``block_rotation``)."""

# this thread's work arrays (``scratch``): a chunk's origins, azimuths and uniforms
_CHUNK_ORIGIN = WorkColumns("chunk-origin")
_CHUNK_PSI = WorkArray("chunk-psi")
_CHUNK_UNIFORM = WorkArray("chunk-uniform")
_GROOVE_UNIFORM = WorkArray("groove-uniform")
_GROOVE_X = WorkArray("groove-x")
_GROOVE_PSI = WorkArray("groove-psi")


def key_stream(key) -> tuple:
    """The PCG64 stream seeded with SeedSequence(``key``), key = (seed, realisation,
    incidence) (any integers), as ``pcg64.fill_uniforms`` takes it (``pcg64.stream_of``);
    computed once per key."""
    return _seeded_stream(tuple(int(k) for k in key))


@functools.lru_cache(maxsize=64)
def _seeded_stream(key: tuple) -> tuple:
    return pcg64.stream_of(np.random.PCG64(np.random.SeedSequence(list(key))).state)


def block_uniforms(key, block: int, per_ray: int, out: np.ndarray, skip: int = 0) -> None:
    """``out`` ← the numbers of stream ``key`` from block ``block``'s slot on, past its first
    ``skip``: block b owns the numbers [b·k·BLOCK, (b + 1)·k·BLOCK) of the PCG64 stream
    seeded with SeedSequence(key), k = ``per_ray`` numbers per ray (ξ, η, and ψ for groove
    azimuths, in runs of the block's length), so every block's rays depend only on (key, b),
    whatever the chunking; consecutive blocks' slots follow one another. Bitwise
    ``Generator(PCG64).random`` from there (``pcg64.fill_uniforms``, compiled)."""
    position = block * per_ray * BLOCK + skip
    pcg64.fill_uniforms(key_stream(key), position, out)


def sweep_rows(size: int, lx: float, ly: float) -> int:
    """The rows of a row-major sweep of ``size`` strata over an ``lx`` × ``ly`` tile: about
    square strata, at least one row."""
    return max(1, int(round(np.sqrt(size * ly / lx))))


class StratifiedDraw(NamedTuple):
    """The stratified origins of a chunk of consecutive blocks, for a kernel that draws them
    itself block by block (``origin_kernels.draw_block``), bitwise as ``chunk_origins``
    gives them (stratified, without azimuths or replicates): the PCG64 ``stream`` of the
    run's key (``key_stream``), the chunk's first ray ``lo`` and its ``n`` rays, the run's
    ``n_total`` rays over ``rows`` rows of strata of the ``lx`` × ``ly`` tile, the origins'
    height ``z`` and the tile's half-widths ``hx``, ``hy`` (a start lies in the tile when
    −hx ≤ x < hx and −hy ≤ y < hy, as ``Tracer.holds``)."""

    stream: tuple
    lo: int
    n: int
    n_total: float
    rows: float
    lx: float
    ly: float
    z: float
    hx: float
    hy: float


def stratified_draw(tracer: Tracer, n_total: int, blocks, key) -> StratifiedDraw:
    """The ``StratifiedDraw`` of the rays of consecutive ``blocks`` of a run of ``n_total``
    stratified rays with the random stream ``key``."""
    lo, n = block_span(n_total, list(blocks))
    lx, ly = tracer.tile
    return StratifiedDraw(
        key_stream(key),
        lo,
        n,
        float(n_total),
        float(sweep_rows(n_total, lx, ly)),
        float(lx),
        float(ly),
        float(tracer.zmax + tracer.top_margin),
        float(tracer.half[0]),
        float(tracer.half[1]),
    )


def block_span(n_total: int, blocks) -> tuple:
    """(first ray, number of rays) of the consecutive ``blocks`` (a sequence) of a run of
    ``n_total`` rays: the last block may be short."""
    lo = blocks[0] * BLOCK
    return lo, min(n_total, (blocks[-1] + 1) * BLOCK) - lo


def chunk_origins(
    tracer: Tracer,
    n_total: int,
    blocks,
    key,
    azimuth: bool,
    origins: str = "stratified",
    replicates: bool = False,
):
    """Origin columns [x, y, z] and groove azimuths ψ (None unless ``azimuth``) of the rays of
    consecutive ``blocks``, in this thread's work arrays (valid until its next call). Every
    origin starts at z = zmax + top_margin.

    Each block draws ξ, η, then (``azimuth``) ψ/2π, n each (n its length), from its own slot
    of the stream ``key`` (``block_uniforms``), so its rays do not depend on the chunking.
    ``origins="stratified"``: rays 2k and 2k + 1 of n_total share a stratum
    q ∈ [2k/N, (2k + 2)/N) of a row-major sweep of the tile (``rows`` rows), each uniform
    inside it independently;
    y is jittered inside its row (``origin_kernels.stratified_origins``). The union of strata is the
    whole tile, so origins are uniform over one period (and a block covers a compact strip:
    coherent rays). On equal-width V-grooves (``Tracer.groove_strata``, azimuth) x runs over
    the grooves in order of tilt and ψ is stratified by the row instead
    (``origin_kernels._groove_strata``). ``origins="independent"``: i.i.d. uniform origins over the
    whole tile, then sorted row-major on a ~square grid of the block's size (coherence only:
    the set is unchanged). ``replicates`` (``simulate(isotropic=True)``): each block's m rays
    are a stratified sweep of the whole tile by themselves (as a run of m rays), so that the
    blocks are independent, identically designed replicates (``tallies.bin_estimate``'s
    "blocks" error).
    """
    blocks = list(blocks)
    lo, n = block_span(n_total, blocks)
    x, y, z = _CHUNK_ORIGIN(n)
    z.fill(tracer.zmax + tracer.top_margin)
    psi = _CHUNK_PSI(n if azimuth else 0)
    lx, ly = tracer.tile
    per_ray = 3 if azimuth else 2
    u = _CHUNK_UNIFORM(per_ray * n)  # ξ, η (, ψ/2π) of each block in turn
    block_uniforms(key, blocks[0], per_ray, u)  # consecutive slots from there on
    if origins == "independent":
        for b in blocks:
            k = b * BLOCK - lo
            m, base = min(n - k, BLOCK), per_ray * k
            xi, eta = u[base : base + m], u[base + m : base + 2 * m]
            rows = sweep_rows(m, lx, ly)
            order = np.lexsort((xi, np.minimum(np.floor(eta * rows), rows - 1)))
            x[k : k + m], y[k : k + m] = xi[order] * lx - lx / 2, eta[order] * ly - ly / 2
            if azimuth:
                psi[k : k + m] = 2 * np.pi * u[base + 2 * m : base + 3 * m][order]
    else:
        for first, size, at, count in _sweeps(n_total, blocks, lo, n, replicates):
            rows = sweep_rows(size, lx, ly)
            k = slice(at, at + count)
            origin_kernels.stratified_origins(
                u[per_ray * at :],
                first,
                count,
                BLOCK,
                float(size),
                float(rows),
                float(lx),
                float(ly),
                azimuth,
                tracer.groove_strata,
                x[k],
                y[k],
                psi[k] if azimuth else psi,
            )
    return [x, y, z], (psi if azimuth else None)


def _sweeps(n_total: int, blocks, lo: int, n: int, replicates: bool):
    """The stratified sweeps of a chunk's ``n`` rays (from ray ``lo`` of the run) as (index in
    its sweep of the chunk's first ray there, rays in the sweep, offset in the chunk, rays of
    the chunk in it): one sweep of the whole run of ``n_total`` rays, or with ``replicates``
    one sweep per block, of that block's rays alone."""
    if not replicates:
        return [(lo, n_total, 0, n)]
    sizes = [min(BLOCK, n_total - b * BLOCK) for b in blocks]
    return [(0, m, b * BLOCK - lo, m) for b, m in zip(blocks, sizes)]


def groove_starts(tracer: Tracer, n_total: int, blocks, key, replicates: bool = False):
    """x and groove azimuths ψ of the stratified rays of consecutive ``blocks``, bitwise as
    ``chunk_origins(..., azimuth=True)`` gives them, without y (grooves run along y, so the
    analytic V-groove path never uses it): each block's η run is skipped by advancing the
    generator instead of drawn; ``replicates`` as there. In this thread's work arrays (valid
    until its next call)."""
    blocks = list(blocks)
    lo, n = block_span(n_total, blocks)
    lx, ly = tracer.tile
    u = _GROOVE_UNIFORM(2 * n)  # ξ, then ψ/2π, of each block in turn
    for b in blocks:
        k = b * BLOCK - lo
        m = min(n - k, BLOCK)
        block_uniforms(key, b, 3, u[2 * k : 2 * k + m])
        block_uniforms(key, b, 3, u[2 * k + m : 2 * k + 2 * m], skip=2 * m)  # past η
    x, psi = _GROOVE_X(n), _GROOVE_PSI(n)
    for first, size, at, count in _sweeps(n_total, blocks, lo, n, replicates):
        rows = sweep_rows(size, lx, ly)
        k = slice(at, at + count)
        origin_kernels.stratified_groove_starts(
            u[2 * at :], first, count, BLOCK, float(size), float(rows), float(lx),
            tracer.groove_strata, x[k], psi[k],
        )  # fmt: skip
    return x, psi


def block_origins(
    tracer: Tracer,
    n_total: int,
    block: int,
    key: Sequence[int],
    azimuth: bool,
    origins: str = "stratified",
):
    """Origins (n, 3) and groove azimuths ψ (n,) (zeros unless ``azimuth``) of one block, in
    arrays of their own (``chunk_origins``)."""
    cols, psi = chunk_origins(tracer, n_total, [block], key, azimuth, origins)
    return np.stack(cols, axis=1), (psi.copy() if azimuth else np.zeros(len(cols[0])))


def block_rotation(key, block: int) -> float:
    """Incidence-azimuth rotation ψ_b (radians, uniform in [0, 2π)) of block ``block`` of the
    stream ``key`` (``simulate(isotropic=True)``), from a generator of its own."""
    return 2.0 * np.pi * np.random.default_rng(list(key) + [block, ROTATION_STREAM]).random()
