"""``acs-twin token create --role admin``: a new API token straight in the server's database.

For the admin who lost the one-time token of the first start (or never saw it): whoever can read
the data directory / database can mint a token; the plain token is printed once, its hash stored,
and the creation is audited like one made through the API.
"""

from __future__ import annotations

import argparse
import getpass
import sys
from pathlib import Path

ROLES = ("viewer", "operator", "admin")


def register(sub: argparse._SubParsersAction) -> None:
    """Add ``token create``."""
    p = sub.add_parser("token", help="make an API token directly in the server's database (lost admin token)")
    verbs = p.add_subparsers(dest="verb", metavar="VERB", required=True)
    create = verbs.add_parser("create", help="issue a token and print it once")
    create.add_argument("--role", choices=ROLES, default="admin", help="role of the token (default admin)")
    create.add_argument("--name", help="who the token is for (default: admin (command line, <user>))")
    create.add_argument("--data-dir", type=Path, help="data directory of the server (default ./data)")
    create.add_argument("--database-url", help="SQLAlchemy URL of the server (default SQLite in the data directory)")
    create.set_defaults(handler=run)


def run(args: argparse.Namespace) -> int:
    """Issue the token in the configured database; exit 2 on a bad setting."""
    from pydantic import ValidationError

    from backend.core.audit_repository import AuditRepository
    from backend.core.auth import Authenticator, Role
    from backend.core.database import create_schema, make_engine, make_session_factory
    from backend.core.settings import Settings
    from backend.core.token_repository import TokenRepository

    values = {"data_dir": args.data_dir, "database_url": args.database_url}
    try:
        settings = Settings(**{k: v for k, v in values.items() if v is not None})
    except ValidationError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    if settings.database_url is None and not (settings.data_dir / "acs-twin.sqlite").exists():
        print(
            f"error: no server database in {settings.data_dir.resolve()} (use --data-dir or --database-url)",
            file=sys.stderr,
        )
        return 2
    engine = make_engine(settings.resolved_database_url())
    try:
        create_schema(engine)
        sessions = make_session_factory(engine)
        name = args.name or f"{args.role} (command line, {getpass.getuser()})"
        token_id, token = Authenticator(TokenRepository(sessions), enabled=True).issue(name, Role.parse(args.role))
        AuditRepository(sessions).record(
            "acs-twin token create", "token.create", f"token/{token_id}", {"role": args.role, "name": name}
        )
    finally:
        engine.dispose()
    print(f"{args.role} token {token_id} (shown once, stored hashed): {token}")
    return 0
