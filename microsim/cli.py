"""`microsim` command line.

Every user error (bad parameter, malformed scene file) is printed as one line on stderr and
exits with status 2, without a traceback; nothing is written.
"""
from __future__ import annotations

import argparse
import sys


class _Parser(argparse.ArgumentParser):
    def error(self, message):  # argparse's own errors: one line, status 2
        print(f"microsim: error: {message}", file=sys.stderr)
        raise SystemExit(2)


def _cmd_models(args) -> int:
    from .analytic.catalogue import model_table
    print(model_table())
    return 0


def _cmd_surface(args) -> int:
    from .scene import describe_surface, load_scene
    print(describe_surface(load_scene(args.scene)))
    return 0


def build_parser() -> argparse.ArgumentParser:
    p = _Parser(prog="microsim", description=__doc__.splitlines()[0])
    sub = p.add_subparsers(dest="command", required=True, parser_class=_Parser)
    m = sub.add_parser("models", help="list every closed-form model with its parameters and source")
    m.set_defaults(func=_cmd_models)
    s = sub.add_parser("surface", help="build a scene's surface and print its statistics next to the nominal values")
    s.add_argument("scene", help="scene file (TOML), e.g. surfaces/gaussian-m0.3.toml")
    s.set_defaults(func=_cmd_surface)
    return p


def main(argv=None) -> int:
    args = build_parser().parse_args(argv)
    try:
        return args.func(args)
    except (ValueError, FileNotFoundError) as exc:
        msg = " ".join(str(exc).split())
        print(f"microsim: error: {msg}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("microsim: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
