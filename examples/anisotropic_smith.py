"""How far MaterialX's isotropic stand-in for the anisotropic Smith G is from an explicit
anisotropic Gaussian surface, beside the exact anisotropic Λ — per (θi, φi).

    .venv/bin/python examples/anisotropic_smith.py [REALISATIONS] [RAYS]

Surface: Gaussian heightfields 256² (dx = 1), σ = 1.2, ℓx = 8, ℓy = 32 (αx = 0.3, αy = 0.075:
ratio 1/4), aluminium, REALISATIONS tiles (default 8) and RAYS primary rays per incidence
(default 8·10⁶) on full-azimuth 30 × 36 bins. Models, all Torrance–Sparrow with the ensemble
AnisotropicBeckmann D: height-correlated Smith G with the exact Λ, the same with the Λ of the
isotropic α = √(αx αy) (MaterialX), and the separable G with the exact Λ. Prints each model's
energy-weighted relative RMS error, energy deviation (simulation − model)/model and verdict
(realisations reference). About 10 s on 2 cores.
"""

import sys

from microsim import analytic as an
from microsim.analysis.verdicts import verdict_kind, verdicts_for_result
from microsim.sim import Bins, simulate
from microsim.sim.compare import attach_models
from microsim.surfaces import gaussian


def surface(seed: int):
    return gaussian(256, 1.0, 1.2, 8.0, corr_len_y=32.0, seed=seed)


def models(ndf) -> dict:
    stand_in = an.Smith(ndf.isotropic_equivalent(), correlated=True)
    return {
        "exact Λ, correlated": an.TorranceSparrow(ndf, an.Smith(correlated=True), "aluminium"),
        "MaterialX α = √(αx αy)": an.TorranceSparrow(ndf, stand_in, "aluminium"),
        "exact Λ, separable": an.TorranceSparrow(ndf, an.Smith(), "aluminium"),
    }


def compare(phi_i: float, realisations: int, rays: int, theta_i=(60.0, 80.0)) -> list[dict]:
    """The verdicts of ``models`` at ``theta_i`` for incidence azimuth ``phi_i`` (degrees;
    0° = across the rough x axis)."""
    res = simulate(None, "aluminium", list(theta_i), phi_i=phi_i, rays=rays,
                   bins=Bins(30, 36, folded=False), surface_factory=surface,
                   realisations=realisations, threads=2)  # fmt: skip
    return verdicts_for_result(attach_models(res, models(surface(0).ensemble_ndf)))


def main(realisations: int = 8, rays: int = 8_000_000) -> None:
    print("φi   θi  model                     rel RMS  energy dev  verdict")
    for phi in (0.0, 90.0):
        for v in compare(phi, realisations, rays):
            print(f"{phi:3.0f}  {v['theta_i']:3.0f}  {v['model']:24s}  {100 * v['rel_rms']:5.1f} %"
                  f"  {100 * v['energy_dev']:+7.1f} %   {verdict_kind(v)}")  # fmt: skip


if __name__ == "__main__":
    main(*(int(a) for a in sys.argv[1:3]))
