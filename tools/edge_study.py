"""The edge-method study of a measured scan (docs/scenes.md, "Edges of a scan"): how much a
scan's BRDF depends on how rays meet its edges, against a periodic original.

    .venv/bin/python tools/edge_study.py [--realisations 12] [--rays 1048576] [--threads 2]

Each realisation is a periodic Gaussian tile (128², dx 1 µm, σ 1.2 µm, ℓ 8 µm: m = 0.3,
aluminium). Its BRDF (single bounce, θi 0°, 30°, 60°, 9 × 6 bins) is compared, bin by bin, with
that of the same surface made periodic by each edge method:

* mirror, whole tile: the 128² tile written as X3P and read back as a scan (form none), so
  mirrored (``loader.mirror_periodic``) into a 254² tile — the scan path's method;
* mirror, window: the central 96² window read as a scan, mirrored into 190²;
* wrap: that window taken as periodic as it is (``periodic = true``): a cliff where its
  opposite edges meet;
* taper: that window tapered to its mean by a Tukey window (25 % cosine edges; Harris 1978)
  and taken as periodic — windowing, which microsim does not offer (shown for its cost);
* another realisation: an independent 128² tile of the same process, the sampling scale.

A last row, "seams alone", compares the whole-tile mirror with the same facets traced without
seams (the tile's four reflections as periodic tiles). Per θi: χ²/dof and max |z| of the
difference against the ray noise alone, the relative L2 difference over the hemisphere
(weights the bins' projected solid angles) as mean ± its standard error over realisations,
and the bias: the largest paired |t| of the mean difference over realisations, against its
two-sided Šidák limit at a 1 % family-wise false-alarm rate. Then the cost of each method.
"""

from __future__ import annotations

import argparse
import sys
import time
import warnings
from dataclasses import dataclass
from pathlib import Path
from tempfile import TemporaryDirectory

import numpy as np
from scipy.signal.windows import tukey

from microsim import surfaces
from microsim.errors import EXIT_INTERRUPTED
from microsim.sim import Bins, simulate
from microsim.stats import MIN_EVENTS, sidak, t_isf
from microsim.surfaces import scan
from microsim.surfaces.surface import Surface, heightfield_mesh

N, SIGMA, CORR_LEN = 128, 1.2, 8.0
WINDOW = slice(16, 112)
THETA_I = (0.0, 30.0, 60.0)
BINS = Bins(9, 6)
ALPHA = 0.01
TAPER = 0.25
METHODS = (
    "mirror, whole tile",
    "mirror, 96² window",
    "wrap, 96² window",
    "taper, 96² window",
    "another realisation",
    "seams alone",
)


@dataclass
class Run:
    """One traced surface: BRDF, its ray standard error, the bins with enough events, the
    mesh's triangles and the seconds ``simulate`` took."""

    brdf: np.ndarray
    stderr: np.ndarray
    used: np.ndarray
    triangles: int
    seconds: float


def trace(surface: Surface, rays: int, seed: int, threads: int) -> Run:
    start = time.perf_counter()
    r = simulate(surface, "aluminium", THETA_I, rays=rays, bins=BINS, seed=seed, threads=threads)
    seconds = time.perf_counter() - start
    return Run(r.brdf, r.stderr, r.counts >= MIN_EVENTS, len(surface.faces), seconds)


def periodic(heights) -> Surface:
    """``heights`` (dx = 1) traced as a periodic tile as they are."""
    vertices, faces = heightfield_mesh(heights, 1.0)
    ny, nx = heights.shape
    return Surface("file", vertices, faces, (nx, ny), True, {}, heights=heights, dx=1.0)


def as_scan(folder: Path, heights, is_periodic: bool = False) -> Surface:
    """``heights`` (µm, dx = 1 µm) written as X3P and read back as a scan, form none."""
    path = folder / "scan.x3p"
    scan.write_x3p(path, heights * scan.SCAN_UNIT, scan.SCAN_UNIT)
    return surfaces.from_file(path, form="none", periodic=is_periodic)


def tapered(heights) -> np.ndarray:
    """``heights`` about their mean, times a 2-D Tukey window (``TAPER`` of each side tapered)."""
    ny, nx = heights.shape
    return (heights - heights.mean()) * np.outer(tukey(ny, TAPER), tukey(nx, TAPER))


def realisation(k: int, folder: Path, rays: int, threads: int) -> dict[str, tuple[Run, Run]]:
    """Per method (``METHODS``): its run and the run it is compared with."""
    original = surfaces.gaussian(N, 1.0, SIGMA, CORR_LEN, seed=k)
    other = surfaces.gaussian(N, 1.0, SIGMA, CORR_LEN, seed=10_000 + k)
    window = original.heights[WINDOW, WINDOW]
    seed = iter(range(100 * k, 100 * (k + 1)))

    def run(surface):
        return trace(surface, rays, next(seed), threads)

    reference = run(original)
    whole = run(as_scan(folder, original.heights))
    h = original.heights - original.heights.mean()
    reflections = [run(periodic(r)) for r in (h, h[:, ::-1], h[::-1], h[::-1, ::-1])]
    seamless = Run(
        np.mean([r.brdf for r in reflections], axis=0),
        np.sqrt(np.sum([r.stderr**2 for r in reflections], axis=0)) / len(reflections),
        np.logical_and.reduce([r.used for r in reflections]),
        reflections[0].triangles,
        sum(r.seconds for r in reflections),
    )
    return {
        METHODS[0]: (whole, reference),
        METHODS[1]: (run(as_scan(folder, window)), reference),
        METHODS[2]: (run(as_scan(folder, window, is_periodic=True)), reference),
        METHODS[3]: (run(periodic(tapered(window))), reference),
        METHODS[4]: (run(other), reference),
        METHODS[5]: (whole, seamless),
    }


def summary(pairs: list[tuple[Run, Run]]) -> dict[str, np.ndarray]:
    """Per θi over the realisations' (run, reference) pairs: χ²/dof and max |z| against the
    ray noise, the relative L2 difference (mean, its standard error) and the bias's max |t|
    with its limit."""
    used = np.logical_and.reduce([a.used & b.used for a, b in pairs])
    d = np.array([a.brdf - b.brdf for a, b in pairs])
    k = len(pairs)
    with np.errstate(invalid="ignore", divide="ignore"):  # bins left out below
        z = d / np.sqrt(np.array([a.stderr**2 + b.stderr**2 for a, b in pairs]))
        t = d.mean(axis=0) / (d.std(axis=0, ddof=1) / np.sqrt(k))
    w = BINS.projected_solid_angle()[None] * used
    rel = np.sqrt(np.sum(w * d**2, axis=(2, 3)))
    rel /= np.sqrt(np.array([np.sum(w * b.brdf**2, axis=(1, 2)) for _, b in pairs]))
    out = {
        "chi2": np.array([np.mean(z[:, i][:, used[i]] ** 2) for i in range(len(THETA_I))]),
        "max_z": np.array([np.abs(z[:, i][:, used[i]]).max() for i in range(len(THETA_I))]),
        "rel": rel.mean(axis=0),
        "rel_se": rel.std(axis=0, ddof=1) / np.sqrt(k),
    }
    out["max_t"] = np.array([np.abs(t[i][used[i]]).max() for i in range(len(THETA_I))])
    out["t_limit"] = t_isf(sidak(ALPHA, int(used.sum())) / 2, k - 1)
    return out


def report(results: list[dict[str, tuple[Run, Run]]], rays: int) -> None:
    k = len(results)
    print(
        f"Edge methods against the periodic original: {k} realisations of a {N}² Gaussian tile "
        f"(σ {SIGMA} µm, ℓ {CORR_LEN} µm, dx 1 µm), aluminium, {rays:,} rays per θi, "
        f"{BINS.n_theta} × {BINS.n_phi} bins"
    )
    stats = {m: summary([r[m] for r in results]) for m in METHODS}
    for i, theta in enumerate(THETA_I):
        print(
            f"\nθi = {theta:g}°{'χ²/dof':>22} {'max|z|':>8}   rel. L2 ± se      bias max|t| / limit"
        )
        for m in METHODS:
            s = stats[m]
            note = " *" if s["max_t"][i] > s["t_limit"] else ""
            print(
                f"  {m:<20} {s['chi2'][i]:9.1f} {s['max_z'][i]:8.1f}   "
                f"{s['rel'][i]:.4f} ± {s['rel_se'][i]:.4f}   {s['max_t'][i]:6.2f} / "
                f"{s['t_limit']:.2f}{note}"
            )
    print("\n* biased: beyond the Šidák limit (1 % family-wise false alarms)")
    print("\nCost (mean over realisations, 3 θi per run):")
    print("  method                triangles   seconds per run")
    for m in METHODS[:4]:
        runs = [r[m][0] for r in results]
        print(f"  {m:<20} {runs[0].triangles:>10,}   {np.mean([r.seconds for r in runs]):.3f}")
    reference = [r[METHODS[0]][1] for r in results]
    print(
        f"  {'periodic original':<20} {reference[0].triangles:>10,}   "
        f"{np.mean([r.seconds for r in reference]):.3f}"
    )


def at_least(low: int):
    """An argparse type: an integer ≥ ``low``."""

    def parse(text: str) -> int:
        value = int(text)
        if value < low:
            raise argparse.ArgumentTypeError(f"must be an integer >= {low}, got {text}")
        return value

    return parse


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--realisations", type=at_least(3), default=12)
    ap.add_argument("--rays", type=at_least(1), default=2**20, help="rays per θi and run")
    ap.add_argument("--threads", type=at_least(1), default=2)
    args = ap.parse_args()
    warnings.simplefilter("ignore", UserWarning)  # the mirroring notices
    results = []
    with TemporaryDirectory() as folder:
        for k in range(args.realisations):
            results.append(realisation(k, Path(folder), args.rays, args.threads))
    report(results, args.rays)


if __name__ == "__main__":
    try:
        main()
    except KeyboardInterrupt:
        print("edge_study: interrupted", file=sys.stderr)
        sys.exit(EXIT_INTERRUPTED)
