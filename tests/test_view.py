"""pyvista views render off screen (no DISPLAY) to non-blank PNGs of the requested size.

Each view runs in a subprocess with DISPLAY unset, as on a headless CI machine. The tests are
skipped only when no OpenGL implementation can be loaded at all (a tiny probe render fails).
"""

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from microsim.app.scene import CATALOGUE

ROOT = Path(__file__).resolve().parents[1]
SCENE = CATALOGUE / "vgroove-beckmann-0.3.toml"
SIZE = (640, 480)
PROBE = (
    "import pyvista as pv; p = pv.Plotter(off_screen=True, window_size=(64, 64)); "
    "p.add_mesh(pv.Sphere()); p.screenshot({path!r}); p.close()"
)


def _env():
    env = {k: v for k, v in os.environ.items() if k not in ("DISPLAY", "WAYLAND_DISPLAY")}
    env["VTK_DEFAULT_OPENGL_WINDOW"] = "vtkEGLRenderWindow"
    return env


@pytest.fixture(scope="module")
def opengl(tmp_path_factory):
    path = tmp_path_factory.mktemp("probe") / "probe.png"
    r = subprocess.run(
        [sys.executable, "-c", PROBE.format(path=str(path))],
        env=_env(),
        capture_output=True,
        text=True,
        timeout=60,
    )
    if r.returncode != 0 or not path.exists():
        pytest.skip(
            "no OpenGL implementation could be loaded off screen (VTK needs libEGL, "
            "e.g. apt-get install libegl1, or an OSMesa build): "
            + (r.stderr.strip().splitlines() or ["no output"])[-1]
        )
    return True


def _run(args, cwd=None):
    return subprocess.run(
        [sys.executable, "-m", "microsim.app.view", *map(str, args)],
        env=_env(),
        capture_output=True,
        text=True,
        timeout=120,
        cwd=cwd,
    )


def _image(path) -> np.ndarray:
    from PIL import Image

    return np.asarray(Image.open(path).convert("RGB")).astype(np.int32)


def _content_fraction(img: np.ndarray) -> float:
    """Fraction of pixels that differ from the white background by more than 40 levels."""
    return float(np.mean(np.max(np.abs(img - 255), axis=-1) > 40))


RAYS = {"rays": 200, "lobe": 20_000, "disk": 20_000}


@pytest.mark.integration
@pytest.mark.parametrize(
    "what",
    # one render in the default run (each costs ~6 s of VTK); every view in the slow run
    ["surface"]
    + [pytest.param(w, marks=pytest.mark.slow) for w in ("rays", "lobe", "disk", "normals")],
)
def test_view_renders_off_screen(opengl, tmp_path, what):
    out = tmp_path / f"{what}.png"
    args = [SCENE, "--what", what, "--screenshot", out, "--size", f"{SIZE[0]}x{SIZE[1]}"]
    if what in RAYS:
        args += ["--rays", RAYS[what]]
    r = _run(args)
    assert r.returncode == 0, r.stderr
    assert out.exists()
    img = _image(out)
    assert img.shape[:2] == (SIZE[1], SIZE[0])
    assert img.std() > 10.0  # not one flat colour
    # titles alone cover well under 2% of the image; the geometry covers much more
    assert _content_fraction(img) > 0.02


@pytest.mark.integration
def test_lobe_shows_model_and_simulation_colours(opengl, tmp_path):
    """Simulation (left, coolwarm z-colours) and model (right, green) are both drawn."""
    out = tmp_path / "lobe.png"
    r = _run(
        [
            SCENE,
            "--what",
            "lobe",
            "--rays",
            20_000,
            "--screenshot",
            out,
            "--size",
            f"{SIZE[0]}x{SIZE[1]}",
        ]
    )
    assert r.returncode == 0, r.stderr
    img = _image(out)
    red, green, blue = img[..., 0], img[..., 1], img[..., 2]
    half = img.shape[1] // 2
    greenish = (green > red + 40) & (green > blue + 40)
    # coolwarm: a grey-white centre tinted towards blue or red; no green-dominant colours;
    # exclude the white background and the dark text/arrows
    lum = img.mean(axis=-1)
    tinted = (~greenish) & (lum > 60) & (lum < 245) & (np.abs(red - blue) > 8)
    assert greenish[:, half:].mean() > 0.005
    assert greenish[:, :half].mean() < greenish[:, half:].mean() / 10
    assert tinted[:, :half].mean() > 0.005


@pytest.mark.integration
@pytest.mark.slow  # off-screen rendering runs by default in test_view_renders_off_screen
def test_headless_without_screenshot_writes_default_file(opengl, tmp_path):
    r = _run([SCENE, "--what", "surface", "--size", "320x240"], cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    out = tmp_path / "microsim-view-vgroove-beckmann-0.3-surface.png"
    assert out.exists() and "no display" in r.stderr
    assert _image(out).shape[:2] == (240, 320)


def test_bad_arguments_give_one_line_errors(tmp_path):
    from concurrent.futures import ThreadPoolExecutor

    cases = [
        [SCENE, "--what", "rays", "--theta-i", "95", "--screenshot", tmp_path / "x.png"],
        [SCENE, "--size", "12"],
        [tmp_path / "missing.toml"],
    ]
    with ThreadPoolExecutor(len(cases)) as pool:  # three independent processes at once
        theta, size, missing = pool.map(_run, cases)
    assert theta.returncode == 2 and "theta_i" in theta.stderr
    assert len(theta.stderr.strip().splitlines()) == 1
    assert size.returncode == 2 and "size" in size.stderr
    assert missing.returncode == 2 and "error" in missing.stderr
    assert not (tmp_path / "x.png").exists()


def test_the_command_line_has_the_view_subcommand():
    from microsim.app.cli import build_parser
    from microsim.app.view import run_view

    args = build_parser(("view",)).parse_args(
        ["view", "s.toml", "--what", "disk", "--theta-i", "45"]
    )
    assert args.func is run_view and args.what == "disk" and args.theta_i == 45.0


def test_lobe_z_uses_stderr_and_poisson_floor():
    """z = (sim − model)/σ; an empty bin (σ = 0) whose model predicts λ = model·N·Ω/w̄ rays
    gets z = −√λ (Poisson), and a bin where both vanish gets 0."""
    from microsim.app.view import lobe_z

    sim = np.array([1.0, 0.0, 0.0])
    se = np.array([0.5, 0.0, 0.0])
    model = np.array([0.0, 2.0, 0.0])
    omega, rays, w = np.array([0.1, 0.1, 0.1]), 1000, 0.9
    z = lobe_z(sim, se, model, omega, rays, w)
    lam = model[1] * rays * omega[1] / w
    assert z[0] == pytest.approx(2.0)
    assert z[1] == pytest.approx(-np.sqrt(lam))
    assert z[2] == 0.0


def test_lobe_z_uses_the_poisson_error_where_a_bin_holds_few_events():
    """Two events of equal Fresnel weight in one stratum pair give a pair standard error ≈ 0:
    below MIN_EVENTS events the model's Poisson error is used instead, so |z| stays the size
    the counts support (not the thousands the pair estimate would give)."""
    from microsim.app.view import lobe_z
    from microsim.stats import MIN_EVENTS

    sim, se, model = np.array([0.04, 0.04]), np.array([1e-6, 1e-6]), np.array([0.01, 0.01])
    omega, rays, w = np.array([0.002, 0.002]), 20_000, 0.9
    counts = np.array([2, MIN_EVENTS])
    z = lobe_z(sim, se, model, omega, rays, w, counts)
    poisson = np.sqrt(model[0] * w / (rays * omega[0]))
    assert z[0] == pytest.approx((sim[0] - model[0]) / poisson)
    assert abs(z[0]) < 20 and z[1] == pytest.approx((sim[1] - model[1]) / se[1])
