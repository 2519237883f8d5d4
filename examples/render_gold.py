"""Gold in colour: spectral RGL files of gold, a closed form and a simulated surface, rendered by
Mitsuba 3's spectral variant.

    .venv/bin/python examples/render_gold.py [OUT.png] [--appearance PNG] [--rays N]
    (needs the `peer` and `materials` extras; ~1 minute on 2 cores)

Closed form: Torrance–Sparrow GGX α = 0.3 with height-correlated Smith G on gold
(``("gold", λ)``: Johnson & Christy 1972 through refractiveindex.info) at ``WAVELENGTHS_NM``,
one closed form per wavelength, as a ``measured.SpectralBRDF``; written to RGL ``.bsdf`` files
(``measured.write_rgl``, warped by the GGX NDF): the spectral flavour, and the RGB flavour
(linear sRGB under D65); a control, the same BRDF at 550 nm for every wavelength (a grey BRDF,
written in the spectral flavour).

Simulated: the Gaussian heightfield ``SIMULATED`` (ensemble NDF Beckmann m = 2σ/ℓ = 0.3)
traced once by ``simulate_spectral`` for gold at ``SIMULATED_NM`` (16 wavelengths, 400–700 nm),
every order of scattering, isotropic, at each incidence of ``SIMULATED_THETA_I`` (0–85° every
5°: the table an RGL file is written from), ``--rays`` rays each. Each wavelength's ``Result``
is a BRDF twice: itself (``SpectralBRDF`` takes a ``Result`` as its whole BRDF, every order
it traced: ``BRDFTable.from_result``), and the ``BRDFTable`` of its single-scattering part
(``single_table``: the order-1 estimate); each set, as a ``SpectralBRDF``, is written in the
spectral flavour as ``microsim measure`` writes a simulated table (warped by the ensemble NDF
with the Lambertian share ``RGL_FLOOR``); beside them the closed form of the same NDF
(Torrance–Sparrow Beckmann 0.3, height-correlated Smith: single scattering) in the spectral
flavour.

Each file is loaded by Mitsuba 3's ``measured`` BSDF on a sphere lit by ``scene``'s lights (a
uniform sky and a sun, both of the spectrum of CIE D65); the spectral files rendered in
``scalar_spectral``, the RGB one in ``scalar_rgb``, same camera and samples. Writes the renders
side by side to ``OUT.png`` (default ``docs/gold-render.png``, one exposure, the sRGB curve),
prints each render's mean linear sRGB over the sphere and the simulated renders' difference
from the closed form of their NDF, and writes the appearance picture of the simulated BRDFs
beside that closed form (``analysis.pictures.appearance_colour`` at ``APPEARANCE_THETA_I``) to
``--appearance`` (default ``docs/gold-appearance.png``).
"""

from __future__ import annotations

import argparse
import tempfile
from pathlib import Path

import numpy as np

from microsim.analysis.pictures import appearance_colour
from microsim.analytic import GGX, Smith, TorranceSparrow
from microsim.analytic.colour_matching import srgb_encode
from microsim.app.measure import RGL_FLOOR
from microsim.measured import BRDFTable, SpectralBRDF, write_rgl
from microsim.sim import Bins, simulate_spectral
from microsim.surfaces import gaussian
from microsim.surfaces.heightfields import gaussian_ensemble_ndf

ROOT = Path(__file__).resolve().parents[1]
WAVELENGTHS_NM = np.arange(380.0, 781.0, 20.0)
SUN_DEG = 50.0
"""Angle between the sun's direction and the camera axis (degrees)."""
SIMULATED = {"n": 128, "dx": 1.0, "sigma": 1.2, "corr_len": 8.0, "seed": 1}
"""``surfaces.gaussian``'s arguments for the simulated surface: rms slope m = 2σ/ℓ = 0.3."""
SIMULATED_NM = np.linspace(400.0, 700.0, 16)
SIMULATED_THETA_I = np.arange(0.0, 86.0, 5.0)
SIMULATED_BINS = Bins(45, 37)
APPEARANCE_THETA_I = 45.0
"""Incidence of the appearance picture (degrees; one of ``SIMULATED_THETA_I``)."""


def gold_brdf(wavelengths_nm=WAVELENGTHS_NM, ndf=GGX(0.3)) -> SpectralBRDF:
    """Torrance–Sparrow with ``ndf`` (default GGX 0.3), height-correlated Smith, gold at each
    wavelength."""
    ts = [TorranceSparrow(ndf, Smith(correlated=True), ("gold", float(nm))) for nm in
          wavelengths_nm]  # fmt: skip
    return SpectralBRDF(wavelengths_nm, [t.f for t in ts])


def simulated_gold(rays: int) -> tuple[SpectralBRDF, SpectralBRDF, object]:
    """(the spectral BRDF of gold on the ``SIMULATED`` heightfield, every order of scattering,
    and its single-scattering part — from one ``simulate_spectral`` run, ``rays`` rays per
    incidence —, the heightfield's ensemble NDF)."""
    surface = gaussian(**SIMULATED)
    spectrum = simulate_spectral(
        surface,
        "gold",
        SIMULATED_THETA_I,
        wavelengths_nm=SIMULATED_NM,
        rays=rays,
        bins=SIMULATED_BINS,
        bounces="all",
        isotropic=True,
    )
    nm = spectrum.wavelengths_nm
    whole = SpectralBRDF(nm, list(spectrum))
    single = SpectralBRDF(nm, [single_table(r).f for r in spectrum])
    return whole, single, gaussian_ensemble_ndf(SIMULATED["sigma"], SIMULATED["corr_len"])


def single_table(result) -> BRDFTable:
    """The table of ``result``'s single-scattering BRDF (order 1 of ``brdf_orders``)."""
    return BRDFTable(
        result.theta_i, result.bins, result.brdf_orders[0], result.stderr_orders[0], "order 1"
    )


def scene(
    bsdf_file, mi, size: int = 128, spp: int = 64, sky: float = 0.2, sun: float = 3.0
) -> dict:
    """A unit sphere of the measured BSDF ``bsdf_file`` seen from 4.5 units away (30° field of
    view), lit by a uniform sky of D65 radiance ``sky`` and a directional sun of D65 irradiance
    ``sun`` at ``SUN_DEG`` from the camera axis (the spectrum ``{"type": "d65"}`` in spectral
    variants, white in RGB ones: the white of sRGB either way); RGBA film (alpha marks the
    sphere)."""
    t = np.radians(SUN_DEG)
    spectral = mi.variant().endswith("spectral")
    white = (lambda s: {"type": "d65", "scale": s}) if spectral else (lambda s: s)
    return {
        "type": "scene",
        "integrator": {"type": "direct"},
        "sensor": {
            "type": "perspective",
            "fov": 30,
            "to_world": mi.ScalarTransform4f().look_at(
                origin=[0, 0, 4.5], target=[0, 0, 0], up=[0, 1, 0]
            ),
            "film": {"type": "hdrfilm", "width": size, "height": size, "pixel_format": "rgba"},
            "sampler": {"type": "independent", "sample_count": spp},
        },
        "sphere": {"type": "sphere", "bsdf": {"type": "measured", "filename": str(bsdf_file)}},
        "sky": {"type": "constant", "radiance": white(sky)},
        "sun": {
            "type": "directional",
            "direction": [-float(np.sin(t)), 0.0, -float(np.cos(t))],
            "irradiance": white(sun),
        },
    }


def render(bsdf_file, variant: str, **kw) -> tuple[np.ndarray, np.ndarray]:
    """(linear sRGB (H, W, 3), sphere mask (H, W)) of ``scene`` in Mitsuba 3 ``variant``."""
    import mitsuba as mi

    mi.set_variant(variant)
    img = np.array(mi.render(mi.load_dict(scene(bsdf_file, mi, **kw)), seed=1))
    return img[..., :3], img[..., 3] > 0.999


def main(out: Path, appearance: Path, rays: int) -> None:
    gold = gold_brdf()
    grey = gold.functions[int(np.argmin(np.abs(gold.wavelengths_nm - 550.0)))]
    simulated, single, ndf = simulated_gold(rays)
    closed = gold_brdf(SIMULATED_NM, ndf)
    beckmann = f"Beckmann {ndf.m:g}"
    closed_name = f"{beckmann}, closed form\n(scalar_spectral)"
    simulated_names = {
        "single scattering": f"{beckmann}, simulated,\nsingle scattering (scalar_spectral)",
        "all orders": f"{beckmann}, simulated,\nall orders (scalar_spectral)",
    }
    exports = {  # name: (file, BRDF, NDF, flavour, floor)
        "gold, spectral file\n(scalar_spectral)": ("gold-spectral", gold, GGX(0.3), "spectral", 0),
        "gold, RGB file\n(scalar_rgb)": ("gold-rgb", gold, GGX(0.3), "rgb", 0),
        "control: gold at 550 nm,\ngrey (scalar_spectral)": ("grey", grey, GGX(0.3), "spectral", 0),
        closed_name: ("closed", closed, ndf, "spectral", 0),
        simulated_names["single scattering"]: ("single", single, ndf, "spectral", RGL_FLOOR),
        simulated_names["all orders"]: ("simulated", simulated, ndf, "spectral", RGL_FLOOR),
    }  # fmt: skip
    renders = {}
    with tempfile.TemporaryDirectory() as tmp:
        for name, (stem, brdf, d, flavour, floor) in exports.items():
            path = Path(tmp) / f"{stem}.bsdf"
            write_rgl(path, brdf, d, flavour=flavour, description=name, floor=floor)
            renders[name] = render(path, "scalar_rgb" if flavour == "rgb" else "scalar_spectral")
    means = {name: img[mask].mean(axis=0) for name, (img, mask) in renders.items()}
    for name, (r, g, b) in means.items():
        print(f"{name.replace(chr(10), ' ')}: mean linear sRGB ({r:.3f}, {g:.3f}, {b:.3f})")
    for what, name in simulated_names.items():
        sim, cf = means[name], means[closed_name]
        print(
            f"simulated ({what}) - closed form: ("
            + ", ".join(f"{d:+.3f}" for d in sim - cf)
            + "), relative ("
            + ", ".join(f"{d:+.1%}" for d in sim / cf - 1.0)
            + ")"
        )
    _figure(renders, out)
    print(f"wrote {out}")
    appearance_colour(
        {
            "simulated, all orders": simulated,
            "simulated, single scattering": single,
            "closed form": closed,
        },
        APPEARANCE_THETA_I,
        appearance,
        scene_name=f"gold, Gaussian heightfield m = {ndf.m:g}",
    )
    print(f"wrote {appearance}")


def _figure(renders: dict, out: Path) -> None:
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    rows = -(-len(renders) // 3)
    fig = Figure(figsize=(9.0, 3.0 * rows + 0.5), layout="constrained")
    FigureCanvasAgg(fig)
    axes = fig.subplots(rows, 3).ravel()
    spheres = np.concatenate([img[mask].max(axis=-1) for img, mask in renders.values()])
    scale = 0.9 / np.percentile(spheres, 99.5)
    for ax, (name, (img, _)) in zip(axes, renders.items()):
        ax.imshow(srgb_encode(np.clip(img * scale, 0.0, 1.0)))
        ax.set_title(name, fontsize=9)
        ax.set_xticks([])
        ax.set_yticks([])
    for ax in axes[len(renders) :]:
        ax.set_axis_off()
    fig.suptitle(
        "Mitsuba 3 `measured` BSDF, RGL files written by microsim: gold, closed forms and\n"
        "simulated (a Gaussian heightfield); "
        f"D65 sky and sun ({SUN_DEG:g}° from the view axis), one exposure",
        fontsize=9,
    )
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=100)


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("out", nargs="?", type=Path, default=ROOT / "docs" / "gold-render.png")
    ap.add_argument("--appearance", type=Path, default=ROOT / "docs" / "gold-appearance.png")
    ap.add_argument("--rays", type=int, default=2**19, help="rays per incidence (simulated)")
    args = ap.parse_args()
    main(args.out, args.appearance, args.rays)
