"""``microsim view`` / ``python -m microsim.app.view``: build one view and show it, or render it
off screen to a PNG (``--screenshot``, or by default with no display)."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from microsim.checks import in_range

from ...errors import UsageError
from ..options import SCENE_HELP
from ..scene import load_scene
from .common import DEFAULT_RAYS, DEFAULT_THETA, WINDOW, headless
from .disk import view_disk
from .lobe import view_lobe
from .normals import view_normals
from .rays import view_rays
from .surface import view_surface

__all__ = ["VIEWS", "view", "configure_view", "run_view", "main"]

VIEWS = ("surface", "rays", "lobe", "disk", "normals")
IMAGE_SUFFIXES = (".png", ".jpeg", ".jpg", ".bmp", ".tif", ".tiff")
"""File types ``--screenshot`` writes (pyvista's); a name without a suffix gets ".png"."""


def view(
    scene_or_surface,
    what: str = "surface",
    theta_i: float | None = None,
    rays=None,
    seed: int = 0,
    window_size=WINDOW,
    off_screen=None,
    **options,
):
    """Build the ``what`` view (one of ``VIEWS``) and return its ``pyvista.Plotter``.

    ``theta_i`` (degrees): incidence for rays/lobe, viewing direction θo for disk; ignored by
    surface/normals. ``rays``: rays traced (default per view: 300 / 200 000 / 100 000)."""
    if what not in VIEWS:
        raise UsageError(f"what must be one of {', '.join(VIEWS)}, got {what!r}")
    theta = DEFAULT_THETA[what] if theta_i is None else float(theta_i)
    if what in ("rays", "lobe", "disk"):
        in_range("theta_i", theta, 0.0, 90.0, hi_open=True)
    common = {"off_screen": off_screen, "window_size": window_size}
    n = DEFAULT_RAYS.get(what) if rays is None else int(rays)
    if what == "surface":
        return view_surface(scene_or_surface, **options, **common)
    if what == "normals":
        return view_normals(scene_or_surface, **options, **common)
    if what == "rays":
        return view_rays(scene_or_surface, theta, rays=n, seed=seed, **options, **common)
    if what == "lobe":
        return view_lobe(scene_or_surface, theta, rays=n, seed=seed, **options, **common)
    return view_disk(scene_or_surface, theta, rays=n, seed=seed, **options, **common)


def _window_size(text: str) -> tuple[int, int]:
    try:
        w, h = (int(s) for s in text.lower().split("x"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"size must be WIDTHxHEIGHT, e.g. 1200x800, got {text!r}")
    if not (16 <= w <= 8192 and 16 <= h <= 8192):
        raise argparse.ArgumentTypeError(
            f"size must be between 16 and 8192 pixels per side, got {text!r}"
        )
    return w, h


def configure_view(p: argparse.ArgumentParser) -> None:
    """The arguments of ``microsim view`` (``cli.COMMANDS``) and of ``python -m
    microsim.app.view`` on their parser ``p``."""
    p.add_argument("scene", help=SCENE_HELP)
    p.add_argument("--what", choices=VIEWS, default="surface", help="which view (default surface)")
    p.add_argument(
        "--theta-i",
        type=float,
        default=None,
        metavar="DEG",
        help="incidence for rays/lobe, viewing angle θo for disk (default: "
        + ", ".join(f"{k} {v:g}" for k, v in DEFAULT_THETA.items() if k in ("rays", "lobe", "disk"))
        + ")",
    )
    p.add_argument(
        "--screenshot",
        metavar="PNG",
        default=None,
        help="render off screen to this image file (.png, .jpg, .bmp, .tif; default with no "
        "display: microsim-view-<scene>-<what>.png)",
    )
    p.add_argument(
        "--size",
        type=_window_size,
        default=WINDOW,
        metavar="WxH",
        help="image size in pixels (default 1200x800)",
    )
    p.add_argument("--rays", type=int, default=None, help="rays traced (rays/lobe/disk)")
    p.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    p.add_argument(
        "--color",
        choices=("height", "slope"),
        default="slope",
        help="surface view colouring (default slope)",
    )
    p.add_argument(
        "--scale",
        choices=("linear", "log"),
        default="linear",
        help="lobe radius: f·cosθo or log-scaled (default linear)",
    )
    p.set_defaults(func=run_view)


def _screenshot_file(shot: str) -> str:
    """The image file ``--screenshot shot`` writes: refused if it is a directory or not an
    image type of ``IMAGE_SUFFIXES``; ".png" added to a name without a suffix."""
    path = Path(shot)
    if path.is_dir():
        raise UsageError(f"--screenshot {shot}: is a directory; give an image file, e.g. view.png")
    if not path.suffix:
        return str(path.with_suffix(".png"))
    if path.suffix not in IMAGE_SUFFIXES:
        raise UsageError(
            f"--screenshot {shot}: must end in one of {', '.join(IMAGE_SUFFIXES)}, "
            f"got {path.suffix!r}"
        )
    return shot


def run_view(args) -> int:
    """Run the ``view`` subcommand: show the view, or write a PNG (``--screenshot`` / headless)."""
    shot = None if args.screenshot is None else _screenshot_file(args.screenshot)
    scene = load_scene(args.scene)
    options = {"surface": {"color": args.color}, "lobe": {"scale": args.scale}}.get(args.what, {})
    if shot is None and headless():
        shot = f"microsim-view-{scene.name}-{args.what}.png"
        print(f"microsim: no display: rendering off screen to {shot}", file=sys.stderr)
    p = view(
        scene,
        args.what,
        args.theta_i,
        args.rays,
        args.seed,
        args.size,
        off_screen=shot is not None,
        **options,
    )
    if shot is None:
        p.show()
        return 0
    Path(shot).parent.mkdir(parents=True, exist_ok=True)
    p.screenshot(shot, window_size=args.size)
    p.close()
    print(shot)
    return 0


class _Parser(argparse.ArgumentParser):
    def error(self, message):
        print(f"microsim view: error: {message}", file=sys.stderr)
        raise SystemExit(2)


def main(argv=None) -> int:
    """``python -m microsim.app.view SCENE [options]`` (same options as ``microsim view``)."""
    p = _Parser(prog="python -m microsim.app.view", description="Inspect a scene with pyvista.")
    configure_view(p)
    args = p.parse_args(argv)
    try:
        return args.func(args)
    except (ValueError, FileNotFoundError) as exc:
        print(f"microsim view: error: {' '.join(str(exc).split())}", file=sys.stderr)
        return 2
