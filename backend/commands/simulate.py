"""``acs-twin simulate SCENARIO``: fly a library scenario (or a JSON file) and write its results."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path


def register(sub: argparse._SubParsersAction) -> None:
    """Add the ``simulate`` subcommand."""
    p = sub.add_parser("simulate", help="run a simulation scenario and write trajectory, plots and summary")
    p.add_argument("scenario", help="library name (see `acs-twin scenarios`) or a scenario JSON file")
    p.add_argument(
        "--set",
        dest="overrides",
        action="append",
        default=[],
        metavar="PATH=VALUE",
        help="override a field, e.g. --set sensors.star_tracker_sigma_arcsec=10 (repeatable)",
    )
    p.add_argument("--duration", type=float, help="simulated duration in seconds")
    p.add_argument("--out", type=Path, help="directory for trajectory.npz/csv/parquet, plots and summary.json")
    p.add_argument("--summary-json", type=Path, help="write the summary of variant 0 as JSON here")
    p.set_defaults(handler=run)


def _load(args: argparse.Namespace):
    from pydantic import ValidationError

    from sim_core import scenario_library
    from sim_core.scenario import Scenario, apply_overrides

    path = Path(args.scenario)
    if path.suffix == ".json" and path.exists():
        scenario = Scenario.model_validate_json(path.read_text())
    else:
        scenario = scenario_library.get(args.scenario)
    sets = list(args.overrides) + ([f"duration_s={args.duration}"] if args.duration is not None else [])
    try:
        return apply_overrides(scenario, sets)
    except ValidationError as exc:
        err = exc.errors()[0]
        field = ".".join(str(x) for x in err["loc"]) or "scenario"
        raise ValueError(f"{field}: {err['msg']}") from None


def _progress_bar(fraction: float) -> None:
    width = 40
    done = int(width * fraction)
    sys.stderr.write(f"\r[{'#' * done}{'.' * (width - done)}] {100 * fraction:5.1f}%")
    sys.stderr.flush()


def run(args: argparse.Namespace) -> int:
    """Validate, fly, print the summary table, write files; exit 2 on bad input."""
    from pydantic import ValidationError

    try:
        scenario = _load(args)
    except (ValueError, ValidationError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    from sim_core.engine import simulate

    traj = simulate(scenario, progress=_progress_bar if sys.stderr.isatty() else None)
    if sys.stderr.isatty():
        sys.stderr.write("\n")
    for v in range(traj.n_variants):
        summary = traj.summary(v)
        print(f"\n{summary['scenario']} / {summary['variant']}")
        for key, value in summary.items():
            if key not in ("scenario", "variant", "events"):
                print(f"  {key:28s} {value}")
        print(f"  {'events':28s} {len(summary['events'])}")
    if args.out:
        from backend.jobs.trajectory_files import write_all

        for path in write_all(traj, args.out):
            print(f"wrote {path}")
    if args.summary_json:
        args.summary_json.write_text(json.dumps(traj.summary(0), indent=2))
    return 0
