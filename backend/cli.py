"""The ``acs-twin`` command line: subcommands are the modules of :mod:`backend.commands`."""

from __future__ import annotations

import argparse
import importlib
import pkgutil
import sys

from backend import commands


def build_parser() -> argparse.ArgumentParser:
    """Parser with one subcommand per module in backend.commands (each has ``register``)."""
    parser = argparse.ArgumentParser(
        prog="acs-twin",
        description="Mission-operations control centre for small-satellite attitude control.",
    )
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for info in sorted(pkgutil.iter_modules(commands.__path__), key=lambda m: m.name):
        module = importlib.import_module(f"{commands.__name__}.{info.name}")
        module.register(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    """Entry point of the ``acs-twin`` console script; returns the process exit code."""
    from backend.core.processes import die_with_parent

    die_with_parent()  # a child of `acs-twin serve` (the demo emulator) goes when the server goes
    parser = build_parser()
    args = parser.parse_args(argv)
    if not getattr(args, "handler", None):
        parser.print_help()
        return 0
    try:
        return int(args.handler(args) or 0)
    except KeyboardInterrupt:  # Ctrl-C: a stop, not a crash (no traceback)
        return 130
    except BrokenPipeError:  # `acs-twin … | head`: the reader left
        sys.stderr.close()
        return 0


if __name__ == "__main__":
    sys.exit(main())
