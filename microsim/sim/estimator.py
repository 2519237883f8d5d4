"""Ray-traced single-bounce BRDF from the explicit microfacet integral (Mikkelsen eq. 9).

Parallel primary rays from wi fall on the periodic surface from origins spread uniformly over
one tile (uniform origins on a horizontal plane = flux-weighted sampling of the surface seen
from wi, i.e. the (n_j·wi) dx_j / ((n·wi) dA) factor of eq. 9). At the first hit with unit
facet normal n a ray carries the weight F(n·wi) (exact Fresnel) and reflects to
wo = 2(wi·n)n − wi; if wo points up and the reflected ray escapes (visibility V), the weight is
tallied in the (θo, Δφ) bin of wo. The bin average of eq. 9 is then

    f̄_B = Σ_rays w / (N Ω_B),      Ω_B = bin projected solid angle (``Bins``),

and its standard error follows from the per-ray variance,
    se_B = √((Σw²/N − (Σw/N)²)/(N − 1)) / Ω_B,
which is conservative because the origins are stratified (jittered along the tile).

Every primary ray ends in exactly one ledger class: ``single`` (escaped after one bounce),
``masked`` (the reflected ray met the surface), ``downward`` (wo_z ≤ 0: a multiple-scattering
event), ``unresolved`` (wrap cap reached, or a numerically back-facing hit) or ``missed`` (no
hit at all: impossible for a closed periodic surface). ``single_fresnel`` is the measured
single-bounce albedo ρ(θi) (Mikkelsen eq. 27); ``lost``/``lost_fresnel`` are the unweighted and
Fresnel-weighted fractions that single scattering loses (masked + downward).

Reproducibility: the rays of (realisation r, incidence i) are cut into fixed blocks of
``BLOCK`` rays; block b draws its numbers from ``default_rng([seed, r, i, b])``, is traced as
its own batch and tallied on its own; block tallies are summed in block order. A ``chunk`` (a
whole number of blocks) is only the unit of work handed to a thread, so results are bitwise
identical for any ``threads``/``chunk``.

V-grooves (``surface.azimuth_average``): each ray gets its own uniformly random groove azimuth
ψ; wi is rotated by −ψ about z into the groove frame, traced, and wo rotated back by +ψ. This
gives the isotropic V-cavity BRDF with independent rays (so the per-ray variance is valid).

Masking offsets: traced masking rays start eps ≈ 2 float32 ulp of the largest coordinate above
the facet (1.2e-7 on a unit tile). The resulting bias scales like eps/feature depth, amplified
~1/cos θo near the horizon: on heightfields with features ≥ 1e-3 of the tile it is ~1e-4
relative (≪ 0.1%); on a unit tile of 4000 V-grooves it was measured at +0.1–0.4% for θo ≥ 80°
(below the statistical error of 10⁶ rays), and ``masking="exact"`` removes it.
"""
from __future__ import annotations

import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from functools import partial
from typing import Callable, Sequence

import numpy as np

from microsim.analytic._checks import spherical_deg
from microsim.analytic.fresnel import fresnel, resolve_material

from .bins import Bins
from .result import Result
from .tracer import ESCAPED, HIT, MISSED, Tracer, VGrooveProfile

__all__ = ["simulate", "ray_events", "Events", "BLOCK", "LEDGER", "MASKING"]

BLOCK = 4096
SINGLE, MASKED, DOWNWARD, RAY_UNRESOLVED, RAY_MISSED = range(5)
LEDGER = ("single", "masked", "downward", "unresolved", "missed")
MASKING = ("traced", "exact")


@dataclass(frozen=True)
class Events:
    """Per-ray outcome of primary rays (global frame).

    ``status`` (N,) int8 index into ``LEDGER``; ``weight`` (N,) Fresnel weight F(n·wi) (0 when
    nothing was hit); ``wo`` (N, 3) reflected direction (NaN without a hit); ``normal`` (N, 3)
    facet normal (rotated back to the global frame for azimuth-averaged grooves);
    ``margin`` (N,) exact V-groove masking margin (> 0 ⇔ masked; NaN unless computed).
    """

    status: np.ndarray
    weight: np.ndarray
    wo: np.ndarray
    normal: np.ndarray
    margin: np.ndarray


# --- ray generation ----------------------------------------------------------------------
def _rotate_z(w: np.ndarray, c: np.ndarray, s: np.ndarray) -> np.ndarray:
    """Rotate vectors (N, 3) about +z by the angles whose cosines/sines are ``c``/``s`` (N,)."""
    out = np.empty(np.broadcast_shapes(w.shape, c.shape + (3,)))
    out[:, 0] = c * w[..., 0] - s * w[..., 1]
    out[:, 1] = s * w[..., 0] + c * w[..., 1]
    out[:, 2] = w[..., 2]
    return out


def _block_rays(tracer: Tracer, n_total: int, block: int, key: Sequence[int], azimuth: bool):
    """Origins (n, 3) and groove azimuths ψ (n,) (zeros unless ``azimuth``) of one block.

    Ray r of n_total gets a stratum q ∈ [(r)/N, (r+1)/N) of a row-major sweep of the tile
    (``rows`` rows, ~square strata), jittered uniformly inside it; y is jittered inside its
    row. The union of strata is the whole tile, so origins are uniform over one period.
    """
    lx, ly = tracer.tile
    start = block * BLOCK
    r = np.arange(start, min(start + BLOCK, n_total), dtype=np.float64)
    rng = np.random.default_rng(list(key) + [block])
    xi, eta = rng.random(len(r)), rng.random(len(r))
    psi = 2 * np.pi * rng.random(len(r)) if azimuth else np.zeros(len(r))
    rows = max(1, int(round(np.sqrt(n_total * ly / lx))))
    q = (r + xi) / n_total * rows
    row = np.minimum(np.floor(q), rows - 1)
    x = (q - row) * lx - lx / 2
    y = (row + eta) / rows * ly - ly / 2
    z = np.full(len(r), tracer.zmax + tracer.top_margin)
    return np.stack([x, y, z], axis=1), psi


def _trace(tracer: Tracer, profile, wi: np.ndarray, origins, psi, ior, azimuth: bool) -> Events:
    """Follow primary rays from direction ``wi`` (global) to their ledger class (vectorised)."""
    n = len(origins)
    if azimuth:                                          # trace in the groove frame: wi by −ψ
        cpsi, spsi = np.cos(psi), np.sin(psi)
        wl = _rotate_z(wi, cpsi, -spsi)
    else:
        wl = np.broadcast_to(wi, (n, 3))
    hits = tracer.first_hit(origins, -wl)
    status = np.full(n, RAY_UNRESOLVED, dtype=np.int8)
    status[hits.status == MISSED] = RAY_MISSED
    status[hits.status == ESCAPED] = RAY_MISSED          # a falling ray cannot escape
    weight = np.zeros(n)
    wo = np.full((n, 3), np.nan)
    margin = np.full(n, np.nan)
    h = np.flatnonzero(hits.status == HIT)
    nrm = hits.normal[h]
    c = np.einsum("ij,ij->i", wl[h], nrm)
    front = c > 0                                        # back-facing hits stay unresolved
    h, nrm, c = h[front], nrm[front], c[front]
    weight[h] = fresnel(c, ior)
    wlo = 2.0 * c[:, None] * nrm - wl[h]
    up = wlo[:, 2] > 0
    status[h[~up]] = DOWNWARD
    hu = h[up]
    if profile is not None:
        m = profile.masking_margin(hits.prim[hu], hits.point[hu], wlo[up])
        margin[hu] = m
        status[hu] = np.where(m > 0, MASKED, SINGLE)
    else:
        esc = tracer.escapes(hits.point[hu], nrm[up], wlo[up])
        status[hu] = np.select([esc == ESCAPED, esc == HIT, esc == MISSED],
                               [SINGLE, MASKED, RAY_MISSED], RAY_UNRESOLVED)
    wo[h] = wlo if not azimuth else _rotate_z(wlo, cpsi[h], spsi[h])   # back by +ψ
    normal = np.full((n, 3), np.nan)
    normal[h] = nrm if not azimuth else _rotate_z(nrm, cpsi[h], spsi[h])
    return Events(status=status, weight=weight, wo=wo, normal=normal, margin=margin)


# --- tallies -------------------------------------------------------------------------------
def _block_tallies(tracer, profile, wi, phi_i, bins, ior, n_total, block, key, azimuth):
    """Tallies of one block: Σw, Σw², counts per bin; ledger counts and Fresnel sums.

    Each block is traced as its own batch: NumPy's SIMD kernels may round a value differently
    depending on its position in an array, so batching blocks together would make the last
    bits depend on the chunk size."""
    origins, psi = _block_rays(tracer, n_total, block, key, azimuth)
    ev = _trace(tracer, profile, wi, origins, psi, ior, azimuth)
    nbin = bins.shape[0] * bins.shape[1]
    single = np.flatnonzero(ev.status == SINGLE)
    idx = bins.locate(ev.wo[single], phi_i)
    ok = idx >= 0
    flat, w = idx[ok], ev.weight[single[ok]]
    return (np.bincount(flat, weights=w, minlength=nbin),
            np.bincount(flat, weights=w * w, minlength=nbin),
            np.bincount(flat, minlength=nbin),
            np.bincount(ev.status, minlength=len(LEDGER)),
            np.bincount(ev.status, weights=ev.weight, minlength=len(LEDGER)))


def _chunk_tallies(tracer, profile, wi, phi_i, bins, ior, n_total, blocks, *, key, azimuth):
    """Per-block tallies of a chunk of consecutive blocks (one thread task)."""
    return [_block_tallies(tracer, profile, wi, phi_i, bins, ior, n_total, b, key, azimuth)
            for b in blocks]


@dataclass
class _Tally:
    """Running sums for one (realisation, incidence), added block by block in block order."""

    sum_w: np.ndarray
    sum_w2: np.ndarray
    count: np.ndarray
    led_n: np.ndarray
    led_f: np.ndarray

    @classmethod
    def empty(cls, nbin: int) -> "_Tally":
        return cls(np.zeros(nbin), np.zeros(nbin), np.zeros(nbin, np.int64),
                   np.zeros(len(LEDGER), np.int64), np.zeros(len(LEDGER)))

    def add(self, block) -> None:
        """Add one block's tallies (callers add blocks in block order)."""
        self.sum_w += block[0]
        self.sum_w2 += block[1]
        self.count += block[2]
        self.led_n += block[3]
        self.led_f += block[4]


def _check_inputs(theta_i, phi_i, rays, threads, chunk, masking):
    th = np.atleast_1d(np.asarray(theta_i, dtype=np.float64))
    if th.ndim != 1 or th.size == 0:
        raise ValueError(f"theta_i must be a scalar or a non-empty 1-D sequence of degrees, got {theta_i!r}")
    if not np.all((th >= 0) & (th < 90)):
        raise ValueError(f"theta_i must lie in [0, 90) degrees, got {theta_i!r}")
    ph = np.broadcast_to(np.asarray(phi_i, dtype=np.float64), th.shape).copy()
    if not np.all(np.isfinite(ph)):
        raise ValueError(f"phi_i must be finite degrees (scalar or one per theta_i), got {phi_i!r}")
    for name, val in (("rays", rays), ("threads", threads), ("chunk", chunk)):
        if isinstance(val, (bool, np.bool_)) or not float(val).is_integer() or val < 1:
            raise ValueError(f"{name} must be an integer >= 1, got {val!r}")
    if masking not in MASKING:
        raise ValueError(f"masking must be one of {', '.join(MASKING)}, got {masking!r}")
    return th, ph


def _realisation_list(surface, realisations):
    """(count, getter) over the surfaces to trace: ``surface`` alone, a list of surfaces, or
    (factory, seeds) built lazily one at a time."""
    if realisations is None:
        if surface is None:
            raise ValueError("surface must be a Surface (or pass realisations)")
        return 1, lambda r: surface
    if (isinstance(realisations, tuple) and len(realisations) == 2
            and callable(realisations[0])):
        factory, seeds = realisations
        seeds = list(seeds)
        if not seeds:
            raise ValueError("realisations must hold at least one seed")
        return len(seeds), lambda r: factory(seeds[r])
    lst = list(realisations)
    if not lst:
        raise ValueError("realisations must be a non-empty list of surfaces or (factory, seeds)")
    return len(lst), lambda r: lst[r]


def _tracer_for(surface, masking):
    tracer = Tracer(surface)
    azimuth = bool(getattr(surface, "azimuth_average", False))
    profile = None
    if masking == "exact":
        if not azimuth:
            raise ValueError("masking='exact' is only available for V-groove surfaces "
                             "(azimuth_average=True); use masking='traced'")
        profile = VGrooveProfile(tracer)
    return tracer, profile, azimuth


def ray_events(surface, material, theta_i: float, phi_i: float = 0.0, rays: int = 100_000,
               seed: int = 0, masking: str = "traced") -> Events:
    """Per-ray outcomes of ``rays`` primary rays at one incidence (degrees), global frame.

    Same ray stream as ``simulate(surface, material, theta_i, ...)`` (realisation 0,
    incidence 0); for diagnostics and tests (paired comparisons of masking modes).
    """
    th, ph = _check_inputs(theta_i, phi_i, rays, 1, 1, masking)
    tracer, profile, azimuth = _tracer_for(surface, masking)
    ior = resolve_material(material)
    wi = spherical_deg(th[0], ph[0])
    blocks = []
    for b in range(-(-int(rays) // BLOCK)):                 # block by block, as in simulate
        origins, psi = _block_rays(tracer, int(rays), b, (int(seed), 0, 0), azimuth)
        blocks.append(_trace(tracer, profile, wi, origins, psi, ior, azimuth))
    return Events(*(np.concatenate([getattr(e, f) for e in blocks])
                    for f in ("status", "weight", "wo", "normal", "margin")))


def _surface_meta(surface) -> dict:
    """JSON-able description of a traced surface (its own warnings plus the tracer's)."""
    warnings = list(getattr(surface, "warnings", ()))
    if not surface.periodic:
        warnings.append("the tile was traced as periodic although surface.periodic is False: "
                        "its seams act as steps")
    z = surface.vertices[:, 2]
    return {"kind": surface.kind, "nominal": dict(surface.nominal),
            "tile_size": [float(t) for t in surface.tile_size], "triangles": int(len(surface.faces)),
            "z_range": [float(np.min(z)), float(np.max(z))], "periodic": bool(surface.periodic),
            "warnings": warnings}


def simulate(surface, material, theta_i, phi_i=0.0, rays: int = 1_000_000, bins: Bins = Bins(),
             seed: int = 0, threads: int = 2, chunk: int = 2 ** 16, masking: str = "traced",
             realisations=None, progress: Callable[[str], None] | None = None) -> Result:
    """Bin-averaged single-bounce BRDF of ``surface`` by ray tracing (Mikkelsen eq. 9).

    ``material``: name, index n / n+ik or None (mirror), see ``resolve_material``.
    ``theta_i``: incidence polar angle(s) in degrees, each in [0, 90); ``phi_i`` azimuth(s) in
    degrees (scalar or one per θi). ``rays``: primary rays per incidence (spread over the
    realisations). ``bins``: outgoing (θo, Δφ) grid. ``seed``: random stream; results are
    bitwise identical for any ``threads`` and ``chunk`` (rays per thread task, rounded to
    whole ``BLOCK``s). ``progress``: optional callback receiving one line per finished
    (realisation, incidence).
    ``masking``: "traced" (Embree, the reference) or "exact" (float64 V-groove test, only for
    ``azimuth_average`` surfaces). ``realisations``: None (trace ``surface``), a list of
    surfaces, or ``(factory, seeds)`` with ``factory(seed) -> Surface``; the BRDF then pools all
    realisations and ``stderr`` combines ray noise with realisation-to-realisation scatter.
    Returns a ``Result`` (BRDF in sr⁻¹).
    """
    th, ph = _check_inputs(theta_i, phi_i, rays, threads, chunk, masking)
    if not isinstance(bins, Bins):
        raise ValueError(f"bins must be a microsim.sim.Bins, got {bins!r}")
    ior = resolve_material(material)
    n_real, get_surface = _realisation_list(surface, realisations)
    rays, seed = int(rays), int(seed)
    per_real = [rays // n_real + (r < rays % n_real) for r in range(n_real)]
    if min(per_real) < 1:
        raise ValueError(f"rays must be >= the number of realisations ({n_real}), got {rays}")
    nbin = bins.shape[0] * bins.shape[1]
    chunk_blocks = max(1, int(round(int(chunk) / BLOCK)))
    tallies = [[_Tally.empty(nbin) for _ in th] for _ in range(n_real)]
    surfaces_meta, timings, build = [], [], 0.0
    t_all = time.perf_counter()
    with ThreadPoolExecutor(max_workers=int(threads)) as pool:
        for r in range(n_real):
            surf = get_surface(r)
            t0 = time.perf_counter()
            tracer, profile, azimuth = _tracer_for(surf, masking)
            build += time.perf_counter() - t0
            surfaces_meta.append({**_surface_meta(surf), "eps": tracer.eps,
                                  "max_wraps": tracer.max_wraps})
            n_r = per_real[r]
            nblk = -(-n_r // BLOCK)
            groups = [range(a, min(a + chunk_blocks, nblk)) for a in range(0, nblk, chunk_blocks)]
            for i, (t_deg, p_deg) in enumerate(zip(th, ph)):
                wi = spherical_deg(t_deg, p_deg)
                key = (seed, r, i)
                work = partial(_chunk_tallies, tracer, profile, wi, p_deg, bins, ior, n_r,
                               key=key, azimuth=azimuth)
                jobs = pool.map(work, groups)
                for part in jobs:                       # in chunk order, blocks in block order
                    for block in part:
                        tallies[r][i].add(block)
                if progress is not None:
                    progress(f"realisation {r + 1}/{n_real}, theta_i = {t_deg:g}°: done")
            timings.append(time.perf_counter() - t0)
            del tracer, profile
    elapsed = time.perf_counter() - t_all
    meta = {"surface": surfaces_meta[0], "realisations": surfaces_meta if n_real > 1 else None,
            "material": _json_material(material, ior), "seed": seed, "rays": rays,
            "masking": masking, "threads": int(threads), "chunk_blocks": chunk_blocks,
            "block": BLOCK, "versions": _versions(), "seconds": elapsed,
            "seconds_scene_build": build, "seconds_per_realisation": timings,
            "rays_per_second": rays * len(th) / (elapsed - build) if elapsed > build else None}
    return _result(th, ph, bins, tallies, per_real, meta)


def _estimate(sum_w, sum_w2, n, omega):
    """BRDF and per-ray standard error of one tally (sr⁻¹)."""
    mean = sum_w / n
    var = np.maximum(sum_w2 / n - mean * mean, 0.0)
    se = np.sqrt(var / (n - 1)) if n > 1 else np.full_like(mean, np.nan)
    return mean / omega, se / omega


def _result(th, ph, bins, tallies, per_real, meta) -> Result:
    omega = bins.projected_solid_angle().ravel()
    shape = (len(th),) + bins.shape
    n_real = len(per_real)
    n_tot = sum(per_real)
    pooled = [_Tally.empty(len(omega)) for _ in th]
    for r in range(n_real):
        for i in range(len(th)):
            t = tallies[r][i]
            pooled[i].add((t.sum_w, t.sum_w2, t.count, t.led_n, t.led_f))
    brdf, se_ray = map(np.array, zip(*[_estimate(p.sum_w, p.sum_w2, n_tot, omega) for p in pooled]))
    extra = {}
    stderr = se_ray
    if n_real > 1:
        per = np.array([[_estimate(tallies[r][i].sum_w, tallies[r][i].sum_w2, per_real[r], omega)[0]
                         for i in range(len(th))] for r in range(n_real)])
        # scatter of the realisation means estimates the total variance of their mean (ray
        # noise included); the realisation component is what exceeds the ray noise
        total_var = np.var(per, axis=0, ddof=1) / n_real
        se_real = np.sqrt(np.maximum(total_var - se_ray ** 2, 0.0))
        stderr = np.sqrt(se_ray ** 2 + se_real ** 2)
        extra = {"stderr_ray": se_ray.reshape(shape), "stderr_realisation": se_real.reshape(shape),
                 "brdf_realisations": per.reshape((n_real,) + shape),
                 "rays_realisations": np.array(per_real, dtype=np.int64)}
    led_n = np.array([p.led_n for p in pooled])
    led_f = np.array([p.led_f for p in pooled])
    ledger = {name: led_n[:, k] / n_tot for k, name in enumerate(LEDGER)}
    for k, name in enumerate(LEDGER[:3]):
        ledger[f"{name}_fresnel"] = led_f[:, k] / n_tot
    ledger["lost"] = (led_n[:, MASKED] + led_n[:, DOWNWARD]) / n_tot
    ledger["lost_fresnel"] = (led_f[:, MASKED] + led_f[:, DOWNWARD]) / n_tot
    counts = {name: led_n[:, k] for k, name in enumerate(LEDGER)}
    return Result(theta_i=th, phi_i=ph, bins=bins, brdf=brdf.reshape(shape),
                  stderr=stderr.reshape(shape), rays=np.full(len(th), n_tot, dtype=np.int64),
                  ledger=ledger, ledger_counts=counts,
                  counts=np.array([p.count for p in pooled]).reshape(shape),
                  sum_w=np.array([p.sum_w for p in pooled]).reshape(shape),
                  sum_w2=np.array([p.sum_w2 for p in pooled]).reshape(shape),
                  meta=meta, **extra)


def _json_material(material, ior):
    name = material if isinstance(material, str) else None
    if ior is None:
        return {"name": name or "mirror", "ior": None}
    c = complex(ior)
    return {"name": name, "ior": [c.real, c.imag]}


def _versions() -> dict:
    import platform

    import embreex
    out = {"numpy": np.__version__, "python": platform.python_version(),
           "embreex": getattr(embreex, "__version__", None)}
    if out["embreex"] is None:
        from importlib.metadata import version
        out["embreex"] = version("embreex")
    return out
