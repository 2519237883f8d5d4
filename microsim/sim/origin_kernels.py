"""Stratified ray origins (``streams.chunk_origins``): rays 2k and 2k + 1 of N at independent
places s = (2k + 2ξ)/N·rows of one stratum of a row-major sweep of the tile, y jittered in
its row, and, for V-grooves, x and the groove azimuth ψ stratified over the grooves in order
of tilt and the rows. Tile coordinates, ψ in radians."""

from __future__ import annotations

import math

import numpy as np

from microsim.jit import vector_inlined, vectorised

from .pcg64 import fill_uniforms


@vector_inlined
def _stratum(r, xi, n_total, rows):
    """Ray r's place (r as a float) in its stratum of a row-major sweep of ``rows`` rows.
    Rays 2k and 2k + 1 share the stratum [2k/N, (2k + w)/N), w = min(2, N − 2k) (a trailing
    odd ray has one of width 1/N to itself), each uniform in it independently:
    s = (2k + w·ξ)/N · rows; (s − row, row) with row = ⌊s⌋ capped at rows − 1. Two
    independent samples per stratum make the pair error of ``tallies.bin_estimate`` unbiased."""
    pair = math.floor(r * 0.5) * 2.0
    s = (pair + min(2.0, n_total - pair) * xi) / n_total * rows
    row = min(math.floor(s), rows - 1.0)
    return s - row, row


@vector_inlined
def _block_xy(u, first, m, n_total, rows, lx, ly, xs, ys):
    """``stratified_origins``' x and y of one block's m rays, rays ``first`` (a float) onwards,
    from its uniforms ``u``: ξ = u[:m], η = u[m:2m]."""
    # on slices, indexed from 0: the loop then vectorises (5× faster than indexing the whole
    # columns at lo + q, whose index checks kept it scalar)
    xi, eta = u[:m], u[m:]
    for q in range(m):
        frac, row = _stratum(first + float(q), xi[q], n_total, rows)
        xs[q] = frac * lx - lx / 2
        ys[q] = (row + eta[q]) / rows * ly - ly / 2


@vectorised
def stratified_origins(u, r0, n, block, n_total, rows, lx, ly, azimuth, strata, x, y, psi):
    """Stratified origins and groove azimuths of rays r0 … r0 + n − 1 (``streams.
    chunk_origins``; r0 a multiple of ``block``) from their uniforms ``u``: block j of the
    chunk (m rays) holds ξ, η (and ψ/2π if ``azimuth``) as runs of m numbers from
    u[k·block·j], k = 3 if ``azimuth`` else 2. Ray r's stratum (``_stratum``) gives
    x = (s − ⌊s⌋)·Lx − Lx/2, y = (⌊s⌋ + η)/rows · Ly − Ly/2, and ψ = 2π·(ψ/2π) if
    ``azimuth``. With groove ``strata`` (``Tracer.groove_strata``: V-grooves, azimuth) x and
    ψ are stratified over the grooves in order of tilt and the rows instead
    (``_groove_strata``). Writes ``x``, ``y`` (and ``psi``)."""
    per_ray = 3 if azimuth else 2
    for j in range((n + block - 1) // block):
        lo = j * block
        m = min(block, n - lo)
        base = per_ray * lo
        first = float(r0 + lo)  # float(r0 + lo) + q = float(r0 + lo + q) exactly (< 2⁵³)
        _block_xy(u[base:], first, m, n_total, rows, lx, ly, x[lo : lo + m], y[lo : lo + m])
        if azimuth:
            _groove_strata(u, base, base + 2 * m, first, m, n_total, rows, strata, lo, x, psi)


@vectorised
def draw_block(draw, k, block, u, x, y):
    """The origins (x, y) of the rays k … k + m − 1 of the chunk of ``draw``
    (``streams.StratifiedDraw``; k a multiple of ``block``, m = min(``block``, n − k)): their
    2m uniforms, ξ then η, from their block's slot of the stream into ``u``
    (``pcg64.fill_uniforms``, as ``streams.block_uniforms``), then their places as
    ``stratified_origins`` gives them.
    Writes ``x[:m]``, ``y[:m]``; returns m."""
    m = min(block, draw.n - k)
    r0 = draw.lo + k
    fill_uniforms(draw.stream, (r0 // block) * 2 * block, u[: 2 * m])
    _block_xy(u, float(r0), m, draw.n_total, draw.rows, draw.lx, draw.ly, x[:m], y[:m])
    return m


@vectorised
def stratified_groove_starts(u, r0, n, block, n_total, rows, lx, strata, x, psi):
    """x and groove azimuth ψ of stratified rays r0 … r0 + n − 1 as ``stratified_origins``
    (``azimuth``) gives them, from ξ and ψ/2π alone: block j (m rays) holds them as two runs
    of m numbers from u[2·block·j] (``streams.groove_starts``)."""
    for j in range((n + block - 1) // block):
        lo = j * block
        m = min(block, n - lo)
        base = 2 * lo
        first = float(r0 + lo)
        xs, xi = x[lo : lo + m], u[base : base + m]  # slices: the loop vectorises
        for q in range(m):
            frac, _ = _stratum(first + float(q), xi[q], n_total, rows)
            xs[q] = frac * lx - lx / 2
        _groove_strata(u, base, base + m, first, m, n_total, rows, strata, lo, x, psi)


@vector_inlined
def _groove_strata(u, at_xi, at_psi, first, m, n_total, rows, strata, lo, x, psi):
    """Groove azimuths ψ of m rays from their uniforms u[at_psi …] (ξ at u[at_xi …]), ray
    ``first`` + q at x[lo + q], psi[lo + q]. Without ``strata`` (an empty array): ψ = 2π·u.
    With them, (left rims x of the grooves in order of tilt (G,), groove width) of equal-width
    V-grooves along y (whose BRDF does not depend on y): the ray's stratum (s − ⌊s⌋ =
    (k + φ)/G, row ⌊s⌋) is mapped to position φ across the k-th groove in order of tilt,
    x = strata[k] + φ·W, and ψ = 2π(row + u)/rows is stratified by the row. Both maps keep
    every stratum's measure (x uniform over the tile, ψ over [0, 2π)), so the estimate stays
    unbiased; rays 2k and 2k + 1 then meet grooves of neighbouring tilt at neighbouring
    azimuths, which halves the rays a V-groove run needs for a given error (the paired-
    strata error estimate stays unbiased: tests/test_stderr.py)."""
    rim = strata[0]
    ps, up, xs, xi = psi[lo : lo + m], u[at_psi : at_psi + m], x[lo : lo + m], u[at_xi:]
    if len(rim) == 0:
        for q in range(m):
            ps[q] = 2 * np.pi * up[q]
        return
    width, g = strata[1], len(rim)
    for q in range(m):
        frac, row = _stratum(first + q, xi[q], n_total, rows)
        ps[q] = 2 * np.pi * ((row + up[q]) / rows)
        rank = frac * g
        k = min(math.floor(rank), g - 1.0)
        xs[q] = rim[int(k)] + (rank - k) * width
