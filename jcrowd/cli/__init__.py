"""The ``jcrowd`` command line: parses arguments, calls the library, writes files.

Every subcommand takes ``--json`` and then prints exactly one JSON object on stdout; logs and
progress bars go to stderr. A :class:`~jcrowd.errors.JcrowdError` becomes a one-line message on
stderr (and ``{"error": {...}}`` on stdout under ``--json``) with exit status 2; nothing else is
caught, so a bug still shows its traceback.
"""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Callable, Sequence
from typing import Any

from jcrowd.errors import JcrowdError
from jcrowd.version import __version__

__all__ = ["main"]

Handler = Callable[[argparse.Namespace], dict[str, Any]]


def _build_parser() -> tuple[argparse.ArgumentParser, dict[str, Handler]]:
    from jcrowd.cli import calibrate as calibrate_cmd
    from jcrowd.cli import demo as demo_cmd
    from jcrowd.cli import eval as eval_cmd
    from jcrowd.cli import export as export_cmd
    from jcrowd.cli import fit as fit_cmd
    from jcrowd.cli import inspect as inspect_cmd
    from jcrowd.cli import optimize as optimize_cmd
    from jcrowd.cli import render as render_cmd
    from jcrowd.cli import run as run_cmd
    from jcrowd.cli import simplify as simplify_cmd

    parser = argparse.ArgumentParser(
        prog="jcrowd",
        description="Crowds whose motion is synthesized from motion capture.",
    )
    parser.add_argument("--version", action="version", version=f"jcrowd {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    handlers: dict[str, Handler] = {}
    for module in (
        inspect_cmd,
        simplify_cmd,
        fit_cmd,
        eval_cmd,
        run_cmd,
        render_cmd,
        export_cmd,
        demo_cmd,
        optimize_cmd,
        calibrate_cmd,
    ):
        p = module.add_parser(sub)
        p.add_argument("--json", action="store_true", help="print one JSON object on stdout")
        handlers[p.prog.split()[-1]] = module.run
    return parser, handlers


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``jcrowd`` console script; returns the exit status."""
    parser, handlers = _build_parser()
    args = parser.parse_args(argv)
    if args.command is None:
        parser.print_help(sys.stderr)
        return 2
    try:
        handlers[args.command](args)
    except JcrowdError as err:
        sys.stderr.write(f"jcrowd {args.command}: error: {err}\n")
        if getattr(args, "json", False):
            payload = {"error": {"type": type(err).__name__, "message": str(err)}}
            sys.stdout.write(json.dumps(payload) + "\n")
        return 2
    return 0


if __name__ == "__main__":  # pragma: no cover
    raise SystemExit(main())
