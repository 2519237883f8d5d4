"""Deterministic periodic heightfields: the extruded sinusoidal and triangular gratings.

A grating is the one rough surface whose Kirchhoff far field has a closed form (Jacobi–Anger:
exp(i a q_z sin(2πx/Λ)) = Σ_m J_m(a q_z) exp(i 2π m x/Λ); Beckmann & Spizzichino 1963, ch. 4),
so it is the exact check of the wave solver (``microsim.wave``). Its diffraction orders leave at
sin θm = sin θi + mλ/Λ in the plane of the grating vector.
"""

from __future__ import annotations

import numpy as np

from microsim.checks import check_memory, integer, positive
from microsim.errors import UsageError

from .heightfields import MIN_GRID, traced_bytes
from .surface import Surface, check_relief

__all__ = ["sinusoidal_grating", "triangular_grating", "PERIOD_RTOL"]

PERIOD_RTOL = 1e-9
"""Relative tolerance of "the period divides the tile": |nx·dx/Λ − round(nx·dx/Λ)| ≤ this ×
nx·dx/Λ (a float period such as 7.3/128 × 128 is not exactly 7.3)."""


def sinusoidal_grating(
    n: int,
    dx: float,
    amplitude: float,
    period: float,
    *,
    ny: int | None = None,
    phase_deg: float = 0.0,
) -> Surface:
    """Periodic extruded sinusoidal grating h(x, y) = a sin(2πx/Λ + φ) on an (ny, n) grid.

    ``n`` grid points along x (the grating vector), ``ny`` along y (default n), spacing ``dx``,
    ``amplitude`` a ≥ 0 (half the peak-to-valley height), ``period`` Λ, all in one length unit;
    ``phase_deg`` φ in degrees. Heights are sampled at the mesh vertices x_j = −L/2 + j·dx
    (``heightfield_mesh``; row = y). The tile L = n·dx must hold a whole number of periods
    (so that the tile is periodic), and a period must hold at least 2 grid steps
    (UsageError otherwise). The surface is deterministic: no seed, no ensemble NDF.
    """
    n = integer("n", n, MIN_GRID, None, " (grid points along x)")
    ny = n if ny is None else integer("ny", ny, 1, None, " (grid points along y)")
    dx = positive("dx", dx)
    period = positive("period", period)
    a = float(amplitude)
    if not (np.isfinite(a) and a >= 0.0):
        raise UsageError(f"amplitude must be a finite number >= 0, got {amplitude!r}")
    phase = float(phase_deg)
    if not np.isfinite(phase):
        raise UsageError(f"phase_deg must be a finite number of degrees, got {phase_deg!r}")
    lx = n * dx
    cycles = lx / period
    whole = round(cycles)
    if whole < 1 or abs(cycles - whole) > PERIOD_RTOL * cycles:
        raise UsageError(
            f"period must divide the tile n·dx = {lx:g} a whole number of times (the tile is "
            f"periodic), got period = {period:g} ({cycles:.6g} periods); e.g. period = "
            f"{lx / max(whole, 1):g}"
        )
    if period < 2.0 * dx:
        raise UsageError(
            f"period must be at least 2·dx = {2 * dx:g} (a period needs two grid steps), "
            f"got {period:g}"
        )
    x = (np.arange(n) - n / 2.0) * dx
    row = a * np.sin(2.0 * np.pi * x / period + np.radians(phase))
    return _extruded(row, ny, dx, {"amplitude": a, "period": period, "phase_deg": phase,
                                    "n": n, "ny": ny, "dx": dx, "periods": int(whole)})  # fmt: skip


def triangular_grating(n: int, dx: float, amplitude: float, period: float, *, ny=None) -> Surface:
    """Periodic extruded symmetric triangular (V-groove) grating on an (ny, n) grid: h rises
    linearly from 0 to ``amplitude`` (peak to valley) over half a ``period`` and falls back
    (facet slope tan α = 2·amplitude/period), the profile of ``wave.gratings.Grating``
    ("triangular"). A half period must be a whole number of grid steps (the apex and the
    valley on vertices, so the mesh holds the profile exactly); otherwise as
    ``sinusoidal_grating``."""
    n = integer("n", n, MIN_GRID, None, " (grid points along x)")
    ny = n if ny is None else integer("ny", ny, 1, None, " (grid points along y)")
    dx, period, a = positive("dx", dx), positive("period", period), positive("amplitude", amplitude)
    half = period / (2.0 * dx)
    if abs(half - round(half)) > PERIOD_RTOL * half or round(half) < 1:
        raise UsageError(f"period must be an even number of grid steps dx = {dx:g}, got {period:g}")
    cycles = n * dx / period
    if abs(cycles - round(cycles)) > PERIOD_RTOL * cycles or round(cycles) < 1:
        raise UsageError(
            f"period must divide the tile n·dx = {n * dx:g} a whole number of times, got {period:g}"
        )
    phase = (np.arange(n) * dx / period) % 1.0
    row = a * (1.0 - np.abs(2.0 * phase - 1.0))
    return _extruded(row, ny, dx, {"amplitude": a, "period": period, "n": n, "ny": ny,
                                    "dx": dx, "periods": int(round(cycles))})  # fmt: skip


def _extruded(row: np.ndarray, ny: int, dx: float, nominal: dict) -> Surface:
    """The periodic grating Surface of one profile row repeated along y."""
    n = len(row)
    lx = n * dx
    check_memory(
        "n",
        traced_bytes(n * ny),
        f"a {n}x{ny} heightfield ({traced_bytes(n * ny) / (n * ny):.0f} bytes per grid point)",
    )
    heights = np.tile(row, (ny, 1))
    tile = (lx, ny * dx)
    check_relief("amplitude", heights.min(), heights.max(), tile)
    return Surface(
        kind="grating",
        vertices=None,  # derived from the heights where needed
        faces=None,
        tile_size=tile,
        periodic=True,
        nominal=nominal,
        heights=heights,
        dx=dx,
    )
