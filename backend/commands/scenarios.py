"""``acs-twin scenarios``: list the library scenarios (or print one as JSON)."""

from __future__ import annotations

import argparse


def register(sub: argparse._SubParsersAction) -> None:
    """Add the ``scenarios`` subcommand."""
    p = sub.add_parser("scenarios", help="list the library scenarios, or print one as JSON")
    p.add_argument("name", nargs="?", help="print this scenario's full JSON")
    p.set_defaults(handler=run)


def run(args: argparse.Namespace) -> int:
    """List names with descriptions, or dump one scenario."""
    from sim_core import scenario_library

    if args.name:
        try:
            print(scenario_library.get(args.name).model_dump_json(indent=2))
        except ValueError as exc:
            print(f"error: {exc}")
            return 2
        return 0
    for name in scenario_library.names():
        print(f"{name:22s} {scenario_library.get(name).description}")
    return 0
