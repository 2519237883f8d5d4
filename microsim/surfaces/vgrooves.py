"""V-groove surfaces: a 1D profile of symmetric V-grooves, extruded (docs/design.md, "Facts to
build on — Surfaces").

Long straight symmetric grooves whose rims all lie at z = 0 with the surface below make the
V-groove G (Mikkelsen 2009, eq. 25; Blinn 1977) exact for single scattering. Grooves run
along y over the whole tile; groove k spans [x_k, x_k + w] with equal width w = L/n, its two
planar faces tilted by θ_k towards ±x, depth (w/2) tan θ_k; four triangles per groove describe
it exactly.

With equal widths, every face has the same projected area, so the tilts must be drawn from
the projected-area tilt density 2π D(θ) cos θ sin θ of the NDF (its ``tilt_quantile_rad``); equal
depths would be wrong (weight ∝ cot θ). Averaging the groove azimuth uniformly (the
estimator's job: ``Surface.azimuth_average``) gives the isotropic V-cavity surface.
"""

from __future__ import annotations

import numpy as np

from microsim.analytic.ndf import NDF
from microsim.checks import check_memory, integer, positive
from microsim.errors import UsageError

from .surface import Surface

__all__ = ["vgrooves", "groove_tilts_rad", "groove_profile", "groove_stats"]

SAMPLINGS = ("stratified", "random")
BYTES_PER_GROOVE = 1600
"""Peak memory per groove of a V-groove surface built and traced (four triangles): measured
≈ 1100 (traced masking) to 1500 bytes (analytic) of RSS growth at 10⁶ and 4·10⁶ grooves
(tilts, profile, mesh, Embree BVH, tracer facet arrays, groove caster); checked against
``microsim.checks.memory_limit`` before anything is allocated."""


def groove_tilts_rad(
    n_grooves: int, ndf, seed: int = 0, sampling: str = "stratified"
) -> np.ndarray:
    """Tilts θ_k (radians, in x order) of ``n_grooves`` grooves drawn from ``ndf``'s tilt density.

    ``stratified``: θ at the quantiles (k + ½)/n, then shuffled along x with ``seed`` (the order
    carries no information, and a monotone depth ramp would look nothing like a rough surface);
    the empirical tilt CDF then deviates from the NDF's by at most 1/(2n) and nothing beyond
    the 1 − 1/(2n) quantile exists (the tail is missing). ``random``: independent draws
    ``tilt_quantile_rad(u)``, u ~ U[0, 1).
    """
    rng = np.random.default_rng(seed)
    if sampling == "stratified":
        u = (np.arange(n_grooves) + 0.5) / n_grooves
        theta = np.asarray(ndf.tilt_quantile_rad(u), dtype=np.float64)[rng.permutation(n_grooves)]
    elif sampling == "random":
        theta = np.asarray(ndf.tilt_quantile_rad(rng.random(n_grooves)), dtype=np.float64)
    else:
        raise UsageError(f"sampling must be one of {', '.join(SAMPLINGS)}, got {sampling!r}")
    if not np.all(np.isfinite(theta) & (theta >= 0.0) & (theta < np.pi / 2)):
        raise UsageError(
            f"ndf.tilt_quantile_rad must return tilts in [0, π/2) for groove depths "
            f"to be finite; {ndf!r} gave {theta[~(theta < np.pi / 2)][:3]!r}"
        )
    return theta


def groove_profile(tilts: np.ndarray, tile: float) -> tuple[np.ndarray, np.ndarray]:
    """(x, z) of the 2n + 1 profile vertices: rims at x_k = −L/2 + k w (z = 0) and groove
    bottoms at x_k + w/2 (z = −(w/2) tan θ_k), w = L/n."""
    n = len(tilts)
    w = tile / n
    x = -tile / 2.0 + np.arange(2 * n + 1) * (w / 2.0)
    z = np.zeros(2 * n + 1)
    z[1::2] = -(w / 2.0) * np.tan(tilts)
    return x, z


def _extrude(x: np.ndarray, z: np.ndarray, length: float) -> tuple[np.ndarray, np.ndarray]:
    """Extrude a profile along y over [−length/2, length/2]: two triangles per segment, ordered
    segment by segment (groove k → faces 4k … 4k+3), normals up."""
    m = len(x)
    lo = np.stack([x, np.full(m, -length / 2.0), z], axis=1)
    hi = np.stack([x, np.full(m, length / 2.0), z], axis=1)
    vertices = np.concatenate([lo, hi])
    a = np.arange(m - 1)
    b, c, d = a + 1, a + 1 + m, a + m
    faces = np.stack([np.stack([a, b, c], axis=1), np.stack([a, c, d], axis=1)], axis=1)
    return vertices, faces.reshape(-1, 3).astype(np.int32)


def vgrooves(
    n_grooves: int,
    ndf,
    seed: int = 0,
    sampling: str = "stratified",
    tile: float = 1.0,
    oriented: bool = False,
) -> Surface:
    """Square tile of side ``tile`` holding ``n_grooves`` equal-width symmetric V-grooves.

    Tilts from ``ndf`` (any object with ``tilt_quantile_rad``; see ``groove_tilts_rad`` for the
    stratified/random choice and the seeded shuffle). Grooves run along y; all rims at z = 0,
    nothing above; 4 triangles per groove; periodic; the surface carries "vgroove" as its
    ``exact_shadowing``. Groove counts beyond the memory limit (``BYTES_PER_GROOVE``) are
    refused before any allocation.

    ``oriented=False`` (the V-cavity of Mikkelsen 2009): ``azimuth_average`` is True — every
    ray sees the grooves at its own uniform azimuth, so the surface is isotropic and ``ndf``
    is its ``ensemble_ndf``. ``oriented=True`` (brushed metal): the grooves keep their
    direction, the BRDF depends on the incidence azimuth φi (0°: incidence across the grooves,
    in the xz plane), there is no ensemble NDF (every facet normal lies in the xz plane), and
    the exact single-bounce BRDF is Torrance–Sparrow with the tile's own facets and Blinn's
    V-groove G evaluated with the 3-D directions: for h in the groove's cross-section plane,
    the G1 = min(1, 2 (n·h)(n·w)/(w·h)) of the directions projected onto that plane equals the
    one of w itself (n·w and w·h scale alike), so ``ts-facets`` is exact there too
    (``sim.compare.default_models``; tests/test_oriented_vgrooves.py).
    """
    if not isinstance(oriented, (bool, np.bool_)):
        raise UsageError(f"oriented must be True or False, got {oriented!r}")
    n_grooves = integer("n_grooves", n_grooves, 1)
    if not isinstance(ndf, NDF) or not ndf.isotropic:
        raise UsageError(
            f"ndf must be an isotropic NDF (e.g. microsim.analytic.Beckmann(0.3)), got {ndf!r}"
        )
    seed, tile = integer("seed", seed, 0), positive("tile", tile)
    if sampling not in SAMPLINGS:
        raise UsageError(f"sampling must be one of {', '.join(SAMPLINGS)}, got {sampling!r}")
    check_memory(
        "n_grooves",
        float(n_grooves) * BYTES_PER_GROOVE,
        f"{n_grooves:,} grooves ({BYTES_PER_GROOVE} bytes per groove to build and trace)",
    )
    tilts = groove_tilts_rad(n_grooves, ndf, seed, sampling)
    vertices, faces = _extrude(*groove_profile(tilts, tile), tile)
    nominal = {
        "ndf": ndf.name,
        **ndf.params(),
        "n_grooves": n_grooves,
        "sampling": sampling,
        "seed": seed,
        "tile": tile,
        **({"oriented": True} if oriented else {}),
    }
    return Surface(
        kind="vgrooves",
        vertices=vertices,
        faces=faces,
        tile_size=(tile, tile),
        periodic=True,
        nominal=nominal,
        azimuth_average=not oriented,
        ensemble_ndf=None if oriented else ndf,
        exact_shadowing="vgroove",
        generator_stats=groove_stats,
        tilt_ndf=ndf,
    )


def groove_stats(surface: Surface) -> dict:
    """Tilt distribution of a V-groove surface (its ``generator_stats``).

    ``n_grooves``, ``tilt_rms_deg``, ``tilt_max_deg``; with the ensemble NDF's ``cdf_theta_rad``:
    ``cdf_max_dev`` = Kolmogorov distance sup|F_n(θ) − F(θ)| of the groove tilts (stratified
    tilts give exactly 1/(2n), the quantisation ``cdf_bound``).
    """
    nrm = surface.facet_normals()[0::4]
    tilts = np.arctan2(np.hypot(nrm[:, 0], nrm[:, 1]), nrm[:, 2])
    n = len(tilts)
    out = {
        "n_grooves": n,
        "tilt_rms_deg": float(np.degrees(np.sqrt(np.mean(tilts**2)))),
        "tilt_max_deg": float(np.degrees(tilts.max())),
        "cdf_bound": 0.5 / n if surface.nominal.get("sampling") == "stratified" else None,
    }
    if surface.ensemble_ndf is not None:
        F = np.asarray(surface.ensemble_ndf.cdf_theta_rad(np.sort(tilts)), dtype=np.float64)
        i = np.arange(1, n + 1)
        out["cdf_max_dev"] = float(max(np.max(i / n - F), np.max(F - (i - 1) / n)))
    return out
