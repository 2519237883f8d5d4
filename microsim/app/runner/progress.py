"""Progress on stderr: rays traced by the main simulation, then the analysis stages.

On a terminal: tqdm bars (rays/s and the time left; the second bar names each stage). When
stderr is not a terminal (piped to a file or a CI log) a bar's carriage returns would make one
long line, so plain lines are printed instead: one per 10 % of the rays, one per stage. The
rate and the time left are measured from the first chunk on, so the first compilation of the
kernels (announced separately, ``sim.compilation``) does not inflate them. Without a stderr
(file descriptor 2 closed: ``sys.stderr`` is None) nothing is printed.
"""

from __future__ import annotations

import sys
import time

from tqdm import tqdm

from ...sim.progress import RaysDone

__all__ = ["RayProgress", "StageProgress", "LINE_STEP", "RATE_AFTER"]

LINE_STEP = 10
"""Percent of the rays between two progress lines when stderr is not a terminal."""
RATE_AFTER = 0.5
"""Seconds after the first chunk before a line states a rate (chunks finishing together on
several threads would give nonsense before)."""


def _terminal() -> bool:
    try:
        return bool(sys.stderr.isatty())
    except (AttributeError, ValueError):  # closed or replaced stream
        return False


def _say(line: str) -> None:
    print(line, file=sys.stderr, flush=True)


def _duration(seconds: float) -> str:
    s = int(round(seconds))
    return f"{s // 60}:{s % 60:02d}" if s >= 60 else f"{s} s"


class RayProgress:
    """Progress over the ``total`` primary rays still to trace; a ``simulate(progress=…)``
    callback advancing by each ``RaysDone`` event's ``rays``."""

    def __init__(self, total: int, desc: str, enabled: bool = True):
        self.total, self.desc = int(total), desc
        self.on = enabled and sys.stderr is not None
        self.lines = self.on and not _terminal()
        self.done, self.first, self.t0, self.next_pct = 0, None, None, LINE_STEP
        self.bar = tqdm(
            total=self.total,
            unit="ray",
            unit_scale=True,
            desc=desc,
            file=sys.stderr,
            disable=not self.on or self.lines,
            dynamic_ncols=True,
            smoothing=0.1,
        )

    def __call__(self, event: RaysDone) -> None:
        if not event.rays:
            return
        self.done += event.rays
        if self.first is None:  # rate and time left from here on: compilation excluded
            self.first, self.t0 = self.done, time.perf_counter()
            self.bar.reset(total=self.total)
            self.bar.n = self.done
            self.bar.refresh()
        else:
            self.bar.update(event.rays)
        if self.lines and self.total:
            pct = 100.0 * self.done / self.total
            if pct >= self.next_pct or self.done >= self.total:
                self._line(pct)
                while self.next_pct <= pct:
                    self.next_pct += LINE_STEP

    def _line(self, pct: float) -> None:
        elapsed = time.perf_counter() - self.t0
        rate = (self.done - self.first) / elapsed if elapsed >= RATE_AFTER else None
        tail = ""
        if rate:
            left = (self.total - self.done) / rate
            tail = f" ({rate / 1e6:.3g} M rays/s, {_duration(left)} left)"
        _say(f"{self.desc}: {pct:.0f} % of {self.total:,} rays{tail}")

    def close(self) -> None:
        self.bar.close()


class StageProgress:
    """The analysis after the simulation, one step per stage (models, fits, stability sweep,
    speed runs, [wave optics,] charts, writing), the current one named; ``extra``: stages
    beyond ``STAGES`` (1 for a scene with ``[wave]``). ``seconds``: the wall time of each
    stage finished so far, by name, in order (``timings.json``)."""

    STAGES = ("models", "fits", "stability sweep", "speed runs", "charts", "writing")

    def __init__(self, desc: str, enabled: bool = True, extra: int = 0):
        self.desc, self.total = desc, len(self.STAGES) + extra
        on = enabled and sys.stderr is not None
        self.lines = on and not _terminal()
        self.bar = tqdm(
            total=self.total,
            desc=f"{desc} analysis",
            unit="stage",
            file=sys.stderr,
            disable=not on or self.lines,
            dynamic_ncols=True,
            bar_format="{desc}: {n_fmt}/{total_fmt} {bar} {postfix} [{elapsed}]",
        )
        self.current, self.count = None, 0
        self.seconds: dict[str, float] = {}
        self._started = 0.0

    def _finish(self) -> None:
        now = time.perf_counter()
        if self.current is not None:
            self.bar.update(1)
            self.seconds[self.current] = now - self._started
        self._started = now

    def stage(self, name: str) -> None:
        self._finish()
        self.current, self.count = name, self.count + 1
        self.bar.set_postfix_str(name)
        if self.lines:
            _say(f"{self.desc} analysis: {name} ({self.count}/{self.total})")

    def close(self) -> None:
        self._finish()
        self.current = None
        self.bar.close()
