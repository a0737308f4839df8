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
    ("pointing_rms_per_course_arcsec", "RMS per course (″)", "{:.1f}"),
    ("pointing_rms_seed_law_arcsec", "RMS, seed 000's MD law (″)", "{:.2f}"),
    ("kappa_fraction", "orbit with \\|κ\\| ≤ 1/2", "{:.0%}"),
    ("max_roll_rate_deg_s", "fastest feasible roll (°/s)", "{:.3f}"),
    ("route_flown", "route flown", "{}"),
    ("why_not_flown", "why not (pairs)", "{}"),
)


def register(sub: argparse._SubParsersAction) -> None:
    """Add the ``faults-table`` subcommand."""
    p = sub.add_parser(
        "faults-table",
        help="the 11 GE wheel configurations (nominal, singles, pairs + MD): "
        "pointing, MD windows, fastest roll, route flown",
    )
    p.add_argument("--scenario", default="somov-ge4-scan", help="library scenario (default: somov-ge4-scan)")
    p.add_argument(
        "--out",
        type=Path,
        action="append",
        default=[],
        help="also write the table to this file, Markdown for .md, JSON for .json (repeatable)",
    )
    p.set_defaults(handler=run)


def _cell(value, fmt: str) -> str:
    if value is None:
        return "—"
    if isinstance(value, bool):
        return "yes" if value else "no"
    if isinstance(value, list):
        return " / ".join(fmt.format(v) for v in value)
    return fmt.format(value)


def markdown(rows: list[dict]) -> str:
    """The table as GitHub Markdown; missing figures (κ for ≥ 3 wheels, no feasible roll) as '—'."""
    lines = ["| " + " | ".join(title for _, title, _ in COLUMNS) + " |", "|" + "---|" * len(COLUMNS)]
    for row in rows:
        cells = [_cell(row[key], fmt) for key, _, fmt in COLUMNS]
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


FORMATS = {".md": "markdown", ".markdown": "markdown", ".json": "json"}


def _out_format(path: Path) -> str:
    """The file format its name says (ValueError naming --out for another suffix)."""
    try:
        return FORMATS[path.suffix.lower()]
    except KeyError:
        raise ValueError(
            f"--out {path}: the file name must end in {', '.join(FORMATS)} (the format to write)"
        ) from None


def run(args: argparse.Namespace) -> int:
    """Fly the configurations, print Markdown then JSON, write each --out in its suffix's format; exit 2 if bad."""
    from sim_core import scenario_library
    from sim_core.whatif import configuration_table

    try:
        formats = [_out_format(path) for path in args.out]
        scenario = scenario_library.get(args.scenario)
        rows = configuration_table(scenario)
    except ValueError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    document = {"scenario": scenario.name, "configurations": rows}
    print(markdown(rows))
    print()
    print(json.dumps(document, indent=2))
    for path, fmt in zip(args.out, formats):
        path.write_text((markdown(rows) if fmt == "markdown" else json.dumps(document, indent=2)) + "\n")
    return 0
