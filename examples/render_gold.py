"""Gold in colour: a spectral RGL file of gold rendered by Mitsuba 3's spectral variant.

    .venv/bin/python examples/render_gold.py [OUT.png]     (needs the `peer` and `materials` extras)

Steps: Torrance–Sparrow GGX α = 0.3 with height-correlated Smith G on gold
(``("gold", λ)``: Johnson & Christy 1972 through refractiveindex.info) at ``WAVELENGTHS_NM``,
one closed form per wavelength, as a ``measured.SpectralBRDF``; written to RGL ``.bsdf`` files
(``measured.write_rgl``, warped by the GGX NDF): the spectral flavour, and the RGB flavour
(linear sRGB under D65); a control, the same BRDF at 550 nm for every wavelength (a grey BRDF,
written in the spectral flavour). Each file is loaded by Mitsuba 3's ``measured`` BSDF on a
sphere lit by ``scene``'s lights (a uniform sky and a sun, both of the spectrum of CIE D65);
the spectral files rendered in ``scalar_spectral``, the RGB one in ``scalar_rgb``, same camera
and samples. Writes the renders side by side to ``OUT.png`` (default ``docs/gold-render.png``,
one exposure, the sRGB curve) and prints each render's mean linear sRGB over the sphere.
"""

from __future__ import annotations

import sys
import tempfile
from pathlib import Path

import numpy as np

from microsim.analytic import GGX, Smith, TorranceSparrow
from microsim.analytic.colour_matching import srgb_encode
from microsim.measured import SpectralBRDF, write_rgl

ROOT = Path(__file__).resolve().parents[1]
WAVELENGTHS_NM = np.arange(380.0, 781.0, 20.0)
SUN_DEG = 50.0
"""Angle between the sun's direction and the camera axis (degrees)."""


def gold_brdf(wavelengths_nm=WAVELENGTHS_NM) -> SpectralBRDF:
    """GGX 0.3, height-correlated Smith, gold at each wavelength."""
    ts = [TorranceSparrow(GGX(0.3), Smith(correlated=True), ("gold", float(nm))) for nm in
          wavelengths_nm]  # fmt: skip
    return SpectralBRDF(wavelengths_nm, [t.f for t in ts])


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


def main(out: Path) -> None:
    gold = gold_brdf()
    grey = gold.functions[int(np.argmin(np.abs(gold.wavelengths_nm - 550.0)))]
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        files = {
            "gold, spectral file\n(scalar_spectral)": (tmp / "gold-spectral.bsdf", "spectral"),
            "gold, RGB file\n(scalar_rgb)": (tmp / "gold-rgb.bsdf", "rgb"),
            "control: gold at 550 nm,\ngrey (scalar_spectral)": (tmp / "grey.bsdf", "spectral"),
        }
        renders = {}
        for name, (path, flavour) in files.items():
            brdf = grey if path.name == "grey.bsdf" else gold
            write_rgl(path, brdf, GGX(0.3), flavour=flavour, description=name)
            renders[name] = render(path, "scalar_rgb" if flavour == "rgb" else "scalar_spectral")
    for name, (img, mask) in renders.items():
        r, g, b = img[mask].mean(axis=0)
        print(f"{name.replace(chr(10), ' ')}: mean linear sRGB ({r:.3f}, {g:.3f}, {b:.3f})")
    _figure(renders, out)
    print(f"wrote {out}")


def _figure(renders: dict, out: Path) -> None:
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(3.0 * len(renders), 3.5), layout="constrained")
    FigureCanvasAgg(fig)
    axes = fig.subplots(1, len(renders))
    spheres = np.concatenate([img[mask].max(axis=-1) for img, mask in renders.values()])
    scale = 0.9 / np.percentile(spheres, 99.5)
    for ax, (name, (img, _)) in zip(axes, renders.items()):
        ax.imshow(srgb_encode(np.clip(img * scale, 0.0, 1.0)))
        ax.set_title(name, fontsize=9)
        ax.set_xticks([])
        ax.set_yticks([])
    fig.suptitle(
        "Mitsuba 3 `measured` BSDF, RGL files written by microsim: GGX 0.3 on gold\n"
        f"D65 sky and sun ({SUN_DEG:g}° from the view axis), one exposure",
        fontsize=9,
    )
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=100)


if __name__ == "__main__":
    main(Path(sys.argv[1]) if len(sys.argv) > 1 else ROOT / "docs" / "gold-render.png")
