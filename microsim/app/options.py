"""Command-line option types shared by the subcommands (argparse ``type=`` callables)."""

from __future__ import annotations

import argparse

__all__ = ["rays_option", "SCENE_HELP"]

SCENE_HELP = (
    "a scene file (TOML) or the name of a catalogue scene (docs/scenes.md), e.g. "
    "vgroove-beckmann-0.3"
)
"""Help of every subcommand's SCENE argument (``scene.resolve_scene`` reads it)."""


def rays_option(text: str) -> int:
    """``--rays N``: an integer in [1, ``sim.arguments.MAX_RAYS``]."""
    from ..sim.arguments import MAX_RAYS

    try:
        rays = int(text)
    except ValueError:
        rays = None
    if rays is None or not 1 <= rays <= MAX_RAYS:
        raise argparse.ArgumentTypeError(
            f"must be an integer in [1, {MAX_RAYS:,}] (primary rays per incidence), got {text!r}"
        )
    return rays
