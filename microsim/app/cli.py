"""`microsim` command line.

Exit statuses: 0 success; 2 usage error (bad option, malformed scene/sweep/heightfield file,
unusable output path, output locked by another run) — one line on stderr naming the option,
file or key, nothing written; 1 environment failure (disk full, read-only file system,
permission denied, unreachable scheduler) — one line naming the path; 130 interrupted
(Ctrl-C: finished results kept, partial ones saved for --resume). Anything else is a bug and
is shown with its traceback (status 1).
"""

from __future__ import annotations

import argparse
import importlib
import math
import os
import signal
import sys
import threading
import traceback

from .. import __version__
from ..display import ascii_fallback
from ..errors import EXIT_ENVIRONMENT, EXIT_INTERRUPTED, EXIT_USAGE, EnvironmentFailure, UsageError
from .options import SCENE_HELP, rays_option

EPILOG = (
    "exit status: 0 ok; 1 environment failure (disk full, read-only, permission; one "
    "line naming the path) or a bug (with traceback); 2 usage error (one line naming "
    "the option, file or key; nothing written); 130 interrupted (finished results "
    "kept, partial ones saved for --resume)"
)


class _Parser(argparse.ArgumentParser):
    def error(self, message):  # argparse's own errors: one line, status 2
        print(f"microsim: error: {message}", file=sys.stderr)
        raise SystemExit(2)


def _cmd_models(args) -> int:
    import shutil

    from ..analytic.catalogue import model_table

    print(model_table(shutil.get_terminal_size((100, 24)).columns))
    return 0


HEIGHTFIELD_OPTIONS = ("dx", "wavelength", "json", "chart")
"""The options of ``microsim surface`` that only a heightfield file takes."""


def _cmd_surface(args) -> int:
    import warnings

    from .scene import describe_surface, load_scene

    if _is_heightfield(args):
        return _heightfield_report(args)
    given = [f"--{k}" for k in HEIGHTFIELD_OPTIONS if getattr(args, k) not in (None, False)]
    if given:
        raise UsageError(
            f"{', '.join(given)}: only for a heightfield file, and {args.scene!r} is a scene "
            f"(a .toml file or a catalogue name)"
        )
    with warnings.catch_warnings():  # describe_surface lists the generator's warnings
        warnings.simplefilter("ignore", UserWarning)
        print(describe_surface(load_scene(args.scene)))
    return 0


def _is_heightfield(args) -> bool:
    """Whether ``microsim surface FILE`` names a heightfield file rather than a scene: neither
    a .toml file nor a catalogue name, and either an existing file or given with ``--dx``."""
    from .scene import catalogue_names

    if args.scene.endswith(".toml") or args.scene in catalogue_names():
        return False
    return args.dx is not None or os.path.isfile(args.scene)


def _heightfield_report(args) -> int:
    """``microsim surface FILE --dx DX``: the report of a measured heightfield."""
    import json

    from ..analysis.surface_report import surface_chart, surface_report

    chart = None if args.chart is None else _chart_file(args.chart)
    heights, dx = _heightfield_of(args)
    report = surface_report(heights, dx, wavelength=args.wavelength)
    if chart is not None:
        surface_chart(report, chart)
    if args.json:
        print(json.dumps(report.to_dict(), indent=1))
    else:
        print(report.to_markdown(), end="")
    if chart is not None:
        print(f"microsim: chart written to {chart}", file=sys.stderr)
    return 0


def _heightfield_of(args) -> tuple:
    """(heights, dx) of ``microsim surface FILE``: a scan (``surfaces.scan.is_scan``) with its
    own spacing, in micrometres (``scan.SCAN_UNIT``; missing points kept as NaN unless dx ≠ dy,
    when they are filled before the resampling to square cells); an array with ``--dx``."""
    from ..surfaces import scan
    from ..surfaces.loader import read_heights

    if scan.is_scan(args.scene):
        if args.dx is not None:
            raise UsageError(
                f"--dx: {args.scene!r} is a scan, which carries its own spacing; leave --dx out"
            )
        m = scan.read_scan(args.scene)
        h, dx, dy = m.heights / scan.SCAN_UNIT, m.dx / scan.SCAN_UNIT, m.dy / scan.SCAN_UNIT
        if scan.square_shape(h.shape, dx, dy)[0] == h.shape:
            return h, dx
        return scan.square_grid(scan.fill_missing(h, dx, dy)[0], dx, dy)
    if args.dx is None:
        raise UsageError(
            f"--dx is required for the heightfield file {args.scene!r}: its grid step, in the "
            f"unit of its heights"
        )
    return read_heights(args.scene), args.dx


def _chart_file(name: str) -> str:
    """The PNG ``--chart name`` writes (".png" added to a name without a suffix), refused if it
    is a directory, has another suffix or its folder does not exist."""
    from pathlib import Path

    path = Path(name)
    if not path.suffix:
        path = path.with_suffix(".png")
    if path.suffix.lower() != ".png":
        raise UsageError(f"--chart {name}: must be a .png file, got suffix {path.suffix!r}")
    if path.is_dir():
        raise UsageError(f"--chart {name}: is a directory; give a file, e.g. surface.png")
    if not path.resolve().parent.is_dir():
        raise UsageError(f"--chart {name}: no such folder {str(path.parent)!r}")
    return str(path)


def _length(text: str) -> float:
    """``--dx`` and ``--wavelength``: a finite length > 0."""
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not (math.isfinite(value) and value > 0):
        raise argparse.ArgumentTypeError(f"must be a finite length > 0, got {text!r}")
    return value


def _theta_list(text: str) -> list[float]:
    """``--theta-i 0,30,60`` or ``--theta-i 0 30 60`` (argparse nargs) → floats, each in
    [0, ``scene.MAX_THETA_I``]."""
    from .scene import MAX_THETA_I

    try:
        angles = [float(t) for t in text.replace(",", " ").split()]
    except ValueError:
        angles = []
    if not angles or not all(0 <= t <= MAX_THETA_I for t in angles):
        raise argparse.ArgumentTypeError(
            f"must be angles in degrees, each in [0, {MAX_THETA_I:g}], got {text!r}"
        )
    return angles


def _incidences(parts) -> list[float] | None:
    """The angles of every ``--theta-i`` (None: none given); an angle given twice is refused."""
    if parts is None:
        return None
    angles = [t for part in parts for t in part]
    twice = sorted({t for t in angles if angles.count(t) > 1})
    if twice:
        raise UsageError(f"--theta-i: {twice[0]:g}° given twice; give each incidence once")
    return angles


def _cmd_run(args) -> int:
    from .runner import execute, plan_run

    theta = _incidences(args.theta_i)
    plan = plan_run(
        args.scene,
        rays=args.rays,
        theta_i=theta,
        out=args.out,
        threads=args.threads,
        seed=args.seed,
        quick=args.quick,
        resume=args.resume,
        force=args.force,
        scheduler=args.scheduler,
    )
    outcome = execute(plan, progress=not args.no_progress)
    if outcome.status == 0 and outcome.document is not None:
        if args.json:  # verdicts.json's content, as written
            from .runner.publishing import VERDICTS_FILE

            print((outcome.out / VERDICTS_FILE).read_text(encoding="utf-8"), end="")
        else:
            from ..analysis.report import run_summary

            print(run_summary(outcome.document))
    return outcome.status


def _cmd_report(args) -> int:
    from .runner import run_report

    return run_report(
        args.catalogue,
        args.out,
        quick=args.quick,
        threads=args.threads,
        progress=not args.no_progress,
        resume=args.resume,
        scheduler=args.scheduler,
    )


def _add_run_command(sub) -> None:
    """Register ``microsim run SCENE [options]``."""
    r = sub.add_parser(
        "run",
        help="simulate a scene, compare and fit the models, write "
        "brdf.npz, meta.json, verdicts.json, report.md and charts",
    )
    r.add_argument("scene", help=SCENE_HELP)
    r.epilog = EPILOG
    r.add_argument(
        "--rays",
        type=rays_option,
        help="primary rays per incidence (default: the scene's; --quick caps it at 200000)",
    )
    r.add_argument(
        "--theta-i",
        type=_theta_list,
        nargs="+",
        action="extend",
        metavar="DEG",
        help="incidence angles in degrees, each once (default: the scene's); repeatable: "
        "--theta-i 30 --theta-i 60 is --theta-i 30 60 (or 30,60)",
    )
    r.add_argument("--out", help="output directory (default: runs/<scene name>)")
    r.add_argument("--threads", type=int, default=2, help="tracing threads (default 2)")
    r.add_argument(
        "--scheduler",
        metavar="ADDRESS",
        help="trace on the workers of this Dask scheduler (e.g. tcp://host:8786); the result "
        "is the local run's bit for bit (needs the `cluster` extra)",
    )
    r.add_argument("--seed", type=int, help="random seed (default: the scene's)")
    r.add_argument(
        "--quick",
        action="store_true",
        help="fewer rays, smaller surface, quick fits and side studies (docs/cli.md)",
    )
    g = r.add_mutually_exclusive_group()
    g.add_argument("--resume", metavar="DIR", help="continue an interrupted run saved in DIR")
    g.add_argument("--force", action="store_true", help="replace an existing output directory")
    r.add_argument("--no-progress", action="store_true", help="no progress bar on stderr")
    r.add_argument(
        "--json",
        action="store_true",
        help="print verdicts.json's content on stdout instead of the verdict table",
    )
    r.set_defaults(func=_cmd_run)


def _add_report_command(sub) -> None:
    """Register ``microsim report [options]``."""
    q = sub.add_parser("report", help="run the whole scene catalogue and write reports/index.md")
    q.add_argument("--quick", action="store_true", help="quick runs (as `run --quick`)")
    q.add_argument("--out", default="reports", help="report directory (default reports)")
    q.add_argument(
        "--catalogue",
        help="directory of scene files (default: the catalogue shipped in the package, "
        "microsim/scenes)",
    )
    q.add_argument("--threads", type=int, default=2, help="tracing threads (default 2)")
    q.add_argument(
        "--scheduler",
        metavar="ADDRESS",
        help="trace each scene on the workers of this Dask scheduler (as `run --scheduler`)",
    )
    q.add_argument("--no-progress", action="store_true", help="no progress bars on stderr")
    q.add_argument(
        "--resume",
        action="store_true",
        help="continue an interrupted report (same options): skip the scenes it "
        "finished, continue the interrupted one from its saved tallies",
    )
    q.set_defaults(func=_cmd_report)


COMMANDS = {
    "measure": (
        "tabulate a scene's BRDF over a dense grid of incidences (a virtual "
        "gonioreflectometer), each to an error target; writes table.npz",
        "microsim.app.measure:configure_measure",
    ),
    "view": (
        "inspect a scene with pyvista: surface, rays, lobe, halfway disk or normals (off "
        "screen when headless)",
        "microsim.app.view:configure_view",
    ),
    "bench": (
        "measure raw Embree vs pipeline throughput, peak memory, time to 1%% precision and "
        "the wave solver's time",
        "microsim.app.bench:configure_bench",
    ),
    "sweep": (
        "run a grid of scenes x parameters x incidences and gather the verdicts into one "
        "table and chart",
        "microsim.app.sweep:configure_sweep",
    ),
}
"""The subcommands whose arguments their own modules define: name → (help line, the
``module:function`` that adds the arguments to the subcommand's parser)."""


def build_parser(commands=None) -> argparse.ArgumentParser:
    """The command line's parser. The subcommands of ``COMMANDS`` get their arguments from
    their modules (which import the simulator, ~2 s): every one when ``commands`` is None,
    else those named in it, so that ``microsim --help`` and the other commands' usage errors
    do not wait for them (``command_of``)."""
    p = _Parser(prog="microsim", description=__doc__.splitlines()[0], epilog=EPILOG)
    p.add_argument("--version", action="version", version=f"microsim {__version__}")
    sub = p.add_subparsers(dest="command", required=True, parser_class=_Parser)
    m = sub.add_parser("models", help="list every closed-form model with its parameters and source")
    m.set_defaults(func=_cmd_models)
    s = sub.add_parser(
        "surface",
        help="build a scene's surface and print its statistics next to the nominal values, "
        "or report what a heightfield file is (docs/cli.md)",
    )
    s.add_argument(
        "scene",
        metavar="SCENE_OR_FILE",
        help=SCENE_HELP + "; or a heightfield file (.npy, .npz, text; rows = y) with --dx",
    )
    s.add_argument("--dx", type=_length, help="heightfield file: the grid step (heights' unit)")
    s.add_argument(
        "--wavelength",
        type=_length,
        help="heightfield file: a wavelength in the heights' unit, for σ/λ and the optics regime",
    )
    s.add_argument("--json", action="store_true", help="heightfield file: the report as JSON")
    s.add_argument(
        "--chart", metavar="PNG", help="heightfield file: also write the report's chart here"
    )
    s.set_defaults(func=_cmd_surface)
    _add_run_command(sub)
    _add_report_command(sub)
    for name, (help_line, where) in COMMANDS.items():
        parser = sub.add_parser(name, help=help_line)
        if commands is None or name in commands:
            module, function = where.split(":")
            getattr(importlib.import_module(module), function)(parser)
    return p


def command_of(argv) -> tuple:
    """The subcommand named in ``argv``: the first word not an option (the top-level options
    take no value), as a 1-tuple, or () if there is none."""
    return tuple(a for a in argv if not a.startswith("-"))[:1]


def _one_line(text) -> str:
    return " ".join(str(text).split())


def _os_error(exc: OSError) -> str:
    """One line naming the path(s) and the system's reason."""
    reason = exc.strerror or _one_line(exc) or type(exc).__name__
    paths = [p for p in (exc.filename, exc.filename2) if p is not None]
    where = " -> ".join(os.fsdecode(p) if isinstance(p, (str, bytes)) else str(p) for p in paths)
    return f"{where}: {reason}" if where else reason


class _CtrlC:
    """While active, SIGINT raises KeyboardInterrupt as Python's default handler does, and is
    remembered in ``seen``: an extension module whose import it cuts short raises ImportError
    instead, which ``main`` then reports as the interrupt it is. Only installed over the
    default handler, in the main thread (an ignored SIGINT stays ignored). With
    ``ignore_after`` SIGINT is ignored, rather than restored, on exit."""

    def __init__(self, ignore_after: bool = False):
        self.ignore_after = ignore_after

    def __enter__(self):
        self.seen, self._old = False, None
        main_thread = threading.current_thread() is threading.main_thread()
        if main_thread and signal.getsignal(signal.SIGINT) is signal.default_int_handler:
            self._old = signal.signal(signal.SIGINT, self._interrupt)
            self._hook, sys.unraisablehook = sys.unraisablehook, self._unraisable
        return self

    def _unraisable(self, info):
        """Our KeyboardInterrupt swallowed by a callback stays silent (``check`` raises it
        again); anything else goes to the previous hook."""
        if not (self.seen and info.exc_type is KeyboardInterrupt):
            self._hook(info)

    def _interrupt(self, signum, frame):
        self.seen = True
        raise KeyboardInterrupt

    def check(self) -> None:
        """Raise KeyboardInterrupt if SIGINT came and was swallowed: raised inside a callback
        that Python runs for an import (a module lock's weakref callback), it is only printed
        as "Exception ignored" and the start-up would go on as if nothing had happened."""
        if self.seen:
            raise KeyboardInterrupt

    def __exit__(self, *exc):
        if self._old is not None:
            signal.signal(signal.SIGINT, signal.SIG_IGN if self.ignore_after else self._old)
            sys.unraisablehook = self._hook
        return False


def main(argv=None) -> int:
    """Run the command line; returns the exit status (module docstring).

    Called as the process's command line (``argv`` None), a Ctrl-C after the command finished
    (while the interpreter shuts down) is ignored: the work is done and its status stands. Called
    with ``argv``, the caller's SIGINT handler is restored on return."""
    ascii_fallback(sys.stdout, sys.stderr)  # symbols as ASCII where a stream lacks them
    with _CtrlC(ignore_after=argv is None) as ctrl_c:
        return _main(argv, ctrl_c)


def _main(argv, ctrl_c: _CtrlC) -> int:
    try:
        argv = sys.argv[1:] if argv is None else list(argv)
        # Ctrl-C while its modules load: status 130
        args = build_parser(command_of(argv)).parse_args(argv)
        if args.func not in (_cmd_models, _cmd_surface):  # the commands that compile kernels
            from ..sim.compilation import announce_compilation

            announce_compilation(sys.stderr)
        ctrl_c.check()
        return args.func(args)
    except UsageError as exc:
        print(f"microsim: error: {_one_line(exc)}", file=sys.stderr)
        return EXIT_USAGE
    except EnvironmentFailure as exc:
        print(f"microsim: error: {_one_line(exc)}", file=sys.stderr)
        return EXIT_ENVIRONMENT
    except BrokenPipeError:  # stdout closed early (`microsim models | head`): stop quietly
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return EXIT_ENVIRONMENT
    except OSError as exc:
        print(f"microsim: error: {_os_error(exc)}", file=sys.stderr)
        return EXIT_ENVIRONMENT
    except KeyboardInterrupt:
        print("microsim: interrupted", file=sys.stderr)
        return EXIT_INTERRUPTED
    except Exception:
        if ctrl_c.seen:  # an import cut short by Ctrl-C (ImportError from an extension)
            print("microsim: interrupted", file=sys.stderr)
            return EXIT_INTERRUPTED
        traceback.print_exc()  # a bug: show it as one
        return EXIT_ENVIRONMENT


if __name__ == "__main__":
    sys.exit(main())
