"""``acs-twin faults-table [--out FILE]``: seed 000's wheel-fault configurations from one batch run."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

COLUMNS = (
    ("configuration", "configuration", "{}"),
    ("pointing_rms_arcsec", "RMS while scanning (″)", "{:.2f}"),
    ("pointing_max_arcsec", "max while scanning (″)", "{:.2f}"),
    ("kappa_fraction", "orbit with \\|κ\\| ≤ 1/2", "{:.0%}"),
    ("max_roll_rate_deg_s", "fastest feasible roll (°/s)", "{:.3f}"),
    ("route_flown", "route flown", "{}"),
)


def register(sub: argparse._SubParsersAction) -> None:
    """Add the ``faults-table`` subcommand."""
    p = sub.add_parser("faults-table", help="the 11 GE wheel configurations (nominal, singles, pairs + MD): "
                                            "pointing, MD windows, fastest roll, route flown")
    p.add_argument("--scenario", default="somov-ge4-scan", help="library scenario (default: somov-ge4-scan)")
    p.add_argument("--out", type=Path, help="also write the table as JSON to this file")
    p.set_defaults(handler=run)


def _cell(value, fmt: str) -> str:
    if value is None:
        return "—"
    if isinstance(value, bool):
        return "yes" if value else "no"
    return fmt.format(value)


def markdown(rows: list[dict]) -> str:
    """The table as GitHub Markdown; missing figures (κ for ≥ 3 wheels, no feasible roll) as '—'."""
    lines = ["| " + " | ".join(title for _, title, _ in COLUMNS) + " |", "|" + "---|" * len(COLUMNS)]
    for row in rows:
        cells = [_cell(row[key], fmt) for key, _, fmt in COLUMNS]
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


def run(args: argparse.Namespace) -> int:
    """Fly the configurations, print Markdown then JSON, write JSON to --out; exit 2 on a bad scenario."""
    from sim_core import scenario_library
    from sim_core.whatif import configuration_table

    try:
        scenario = scenario_library.get(args.scenario)
        rows = configuration_table(scenario)
    except ValueError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    document = {"scenario": scenario.name, "configurations": rows}
    print(markdown(rows))
    print()
    print(json.dumps(document, indent=2))
    if args.out:
        args.out.write_text(json.dumps(document, indent=2) + "\n")
    return 0
