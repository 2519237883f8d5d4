"""What W wavelengths cost in one spectral run (``simulate_spectral``) against one material
(``simulate``): on a 128² Gaussian heightfield (rms slope ≈ 0.35), gold, θi = 30°, 1 thread,
``bounces`` 1 and "all", W = 1, 3 and 16 wavelengths in 400–700 nm; best of ``--repeat`` (3) runs
after a warm-up (compilation, tracer). Prints the wall time of each, its ratio to W separate
``simulate`` runs, and the marginal cost of a wavelength: (t_W − t_1)/(W − 1) and the rays·s⁻¹
that makes. docs/performance.md quotes it.

    .venv/bin/python tools/spectral_cost.py [--rays N] [--threads T] [--repeat R]
"""

import argparse
import time

import numpy as np

from microsim.sim import Bins, simulate, simulate_spectral
from microsim.surfaces import gaussian

WAVELENGTHS = {w: tuple(np.linspace(400.0, 700.0, w)) if w > 1 else (550.0,) for w in (1, 3, 16)}


def best_time(call, repeat: int) -> float:
    """The least wall time of ``repeat`` calls of ``call``, in seconds."""
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        call()
        times.append(time.perf_counter() - t0)
    return min(times)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--rays", type=int, default=2**19)
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args()
    surface = gaussian(128, 1.0, 2.0, 8.0, seed=1)
    kw = dict(rays=args.rays, bins=Bins(45, 37), threads=args.threads, seed=1)
    print(f"128² Gaussian, gold, θi = 30°, {args.rays:,} rays, {args.threads} thread(s)")
    for bounces in (1, "all"):
        simulate_spectral(surface, "gold", 30.0, wavelengths_nm=[550.0], bounces=bounces, **kw)
        one = best_time(
            lambda: simulate(surface, ("gold", 550.0), 30.0, bounces=bounces, **kw), args.repeat
        )
        print(f"\nbounces={bounces!r}: simulate, one material: {one:.3f} s")
        print("    W   spectral (s)   / W simulate runs", end="")
        print("   marginal s per wavelength   marginal rays/s")
        t1 = None
        for w, nm in WAVELENGTHS.items():
            t = best_time(
                lambda: simulate_spectral(
                    surface, "gold", 30.0, wavelengths_nm=list(nm), bounces=bounces, **kw
                ),
                args.repeat,
            )
            t1 = t if w == 1 else t1
            marginal = (t - t1) / (w - 1) if w > 1 else float("nan")
            rate = args.rays / marginal if w > 1 and marginal > 0 else float("nan")
            print(f"  {w:3d}   {t:12.3f}   {t / (w * one):17.3f}   {marginal:25.4f}   {rate:15.3g}")


if __name__ == "__main__":
    main()
