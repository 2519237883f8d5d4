"""``microsim sweep``: the command-line subcommand."""

from __future__ import annotations

import os
import signal
import sys

from ..options import rays_option
from .execution import SweepInterrupted, run_sweep
from .grid import load_sweep, with_effort


def _cmd_sweep(args) -> int:
    spec = with_effort(load_sweep(args.sweep), args.rays, args.quick)
    out = args.out or os.path.join("sweeps", "out", spec.name + ("-quick" if args.quick else ""))
    try:
        res = run_sweep(
            spec,
            out,
            scheduler=args.scheduler,
            workers=args.workers,
            progress=lambda s: print(s, file=sys.stderr, flush=True),
            connect_timeout=args.scheduler_timeout,
        )
    except SweepInterrupted as e:
        how = "interrupted" if e.signum == signal.SIGINT else "terminated"
        print(
            f"microsim: {how}: {e.done}/{e.total} tasks done and kept in "
            f"{os.path.join(out, 'tasks')}, summary not written; rerun the same command "
            f"(microsim sweep {args.sweep}{' --out ' + args.out if args.out else ''}"
            f"{' --quick' if args.quick else ''}{f' --rays {args.rays}' if args.rays else ''}) "
            f"to compute the rest",
            file=sys.stderr,
        )
        return 128 + e.signum
    print(
        f"{len(res.computed)} tasks computed, {len(res.skipped)} already done; "
        f"{res.summary.markdown}, {res.summary.csv}, {res.summary.chart}"
    )
    return 0


def configure_sweep(p) -> None:
    """The arguments of ``microsim sweep SWEEP.toml [--scheduler ADDRESS] [--scheduler-timeout
    S] [--out DIR] [--workers N | --threads N] [--rays N] [--quick]`` on its parser ``p``
    (``cli.COMMANDS``)."""
    p.add_argument("sweep", help="sweep file (TOML), e.g. sweeps/vgroove-roughness.toml")
    p.add_argument(
        "--scheduler",
        metavar="ADDRESS",
        help="Dask distributed scheduler address (default: local worker processes)",
    )
    p.add_argument(
        "--scheduler-timeout",
        type=float,
        default=10.0,
        metavar="SECONDS",
        help="give up connecting to --scheduler after this long (default 10)",
    )
    p.add_argument("--out", help="output directory (default sweeps/out/<name>)")
    p.add_argument(
        "--workers",
        "--threads",
        dest="workers",
        type=int,
        default=2,
        help="local worker processes, one thread each (default 2; --threads is the same)",
    )
    p.add_argument(
        "--rays", type=rays_option, help="primary rays per task, instead of the sweep file's rays"
    )
    from ..runner.planning import QUICK

    p.add_argument(
        "--quick",
        action="store_true",
        help=f"the effort of microsim run --quick: at most {QUICK.max_rays:,} rays and "
        f"{QUICK.max_bins[0]} × {QUICK.max_bins[1]} bins per task (default output "
        "sweeps/out/<name>-quick)",
    )
    p.set_defaults(func=_cmd_sweep)
