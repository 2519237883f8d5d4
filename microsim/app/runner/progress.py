"""Progress bars on stderr (tqdm): rays traced by the main simulation, then the analysis stages.
Without a stderr (file descriptor 2 closed: ``sys.stderr`` is None) the bars are off."""

from __future__ import annotations

import sys

from tqdm import tqdm

from ...sim.progress import RaysDone

__all__ = ["RayProgress", "StageProgress"]


class RayProgress:
    """Bar over the ``total`` primary rays still to trace (rays/s and time left); a
    ``simulate(progress=…)`` callback advancing by each ``RaysDone`` event's ``rays``."""

    def __init__(self, total: int, desc: str, enabled: bool = True):
        self.bar = tqdm(
            total=int(total),
            unit="ray",
            unit_scale=True,
            desc=desc,
            file=sys.stderr,
            disable=not enabled or sys.stderr is None,
            dynamic_ncols=True,
            smoothing=0.1,
        )

    def __call__(self, event: RaysDone) -> None:
        if event.rays:
            self.bar.update(event.rays)

    def close(self) -> None:
        self.bar.close()


class StageProgress:
    """The analysis after the simulation, one step per stage (models, fits, stability sweep,
    speed runs, [wave optics,] charts, writing), the current one named; ``extra``: stages
    beyond ``STAGES`` (1 for a scene with ``[wave]``)."""

    STAGES = ("models", "fits", "stability sweep", "speed runs", "charts", "writing")

    def __init__(self, desc: str, enabled: bool = True, extra: int = 0):
        self.bar = tqdm(
            total=len(self.STAGES) + extra,
            desc=f"{desc} analysis",
            unit="stage",
            file=sys.stderr,
            disable=not enabled or sys.stderr is None,
            dynamic_ncols=True,
            bar_format="{desc}: {n_fmt}/{total_fmt} {bar} {postfix} [{elapsed}]",
        )
        self.current = None

    def stage(self, name: str) -> None:
        if self.current is not None:
            self.bar.update(1)
        self.current = name
        self.bar.set_postfix_str(name)

    def close(self) -> None:
        if self.current is not None:
            self.bar.update(1)
        self.bar.close()
