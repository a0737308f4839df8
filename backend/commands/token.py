"""``acs-twin token create --role admin`` / ``acs-twin token revoke ID``: API tokens straight in the server's database.

For the admin who lost the one-time token of the first start (or never saw it): whoever can read
the data directory / database can mint a token; the plain token is printed once, its hash stored,
and the creation is audited like one made through the API. A revocation made here reaches a running
server sharing the database within its revocation watch period (backend.core.auth.REVOCATION_POLL_S):
its REST cache forgets the token and its WebSockets and monitor sessions opened with it close.
"""

from __future__ import annotations

import argparse
import getpass
import sys
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from sqlalchemy.orm import Session, sessionmaker

ROLES = ("viewer", "operator", "admin")


def _database_options(p: argparse.ArgumentParser) -> None:
    p.add_argument("--data-dir", type=Path, help="data directory of the server (default ./data)")
    p.add_argument("--database-url", help="SQLAlchemy URL of the server (default SQLite in the data directory)")


def register(sub: argparse._SubParsersAction) -> None:
    """Add ``token create`` and ``token revoke``."""
    p = sub.add_parser("token", help="make or revoke an API token directly in the server's database")
    verbs = p.add_subparsers(dest="verb", metavar="VERB", required=True)
    create = verbs.add_parser("create", help="issue a token and print it once")
    create.add_argument("--role", choices=ROLES, default="admin", help="role of the token (default admin)")
    create.add_argument("--name", help="who the token is for (default: admin (command line, <user>))")
    _database_options(create)
    create.set_defaults(handler=run)
    revoke = verbs.add_parser("revoke", help="revoke a token; running servers close its sessions within a second")
    revoke.add_argument("token_id", type=int, help="id of the token (GET /api/v1/tokens lists them)")
    _database_options(revoke)
    revoke.set_defaults(handler=run_revoke)


class _NoDatabase(Exception):
    """The settings name no server database."""


@contextmanager
def _sessions(args: argparse.Namespace) -> Iterator[sessionmaker[Session]]:
    """A session factory on the server's database; _NoDatabase (with the message) if there is none."""
    from pydantic import ValidationError

    from backend.core.database import create_schema, make_engine, make_session_factory
    from backend.core.settings import Settings

    values = {"data_dir": args.data_dir, "database_url": args.database_url}
    try:
        settings = Settings(**{k: v for k, v in values.items() if v is not None})
    except ValidationError as exc:
        raise _NoDatabase(f"error: {exc}") from None
    if settings.database_url is None and not (settings.data_dir / "acs-twin.sqlite").exists():
        raise _NoDatabase(
            f"error: no server database in {settings.data_dir.resolve()} (use --data-dir or --database-url)"
        )
    engine = make_engine(settings.resolved_database_url())
    try:
        create_schema(engine)
        yield make_session_factory(engine)
    finally:
        engine.dispose()


def run(args: argparse.Namespace) -> int:
    """Issue the token in the configured database; exit 2 on a bad setting or a name the archive cannot record."""
    from backend.core.audit_repository import AuditRepository
    from backend.core.auth import Authenticator, Role
    from backend.core.token_repository import TokenRepository

    try:
        with _sessions(args) as sessions:
            name = args.name or f"{args.role} (command line, {getpass.getuser()})"
            token_id, token = Authenticator(TokenRepository(sessions), enabled=True).issue(name, Role.parse(args.role))
            AuditRepository(sessions).record(
                "acs-twin token create", "token.create", f"token/{token_id}", {"role": args.role, "name": name}
            )
    except (_NoDatabase, ValueError) as exc:  # ValueError: a name the archive cannot record (Authenticator.issue)
        print(exc, file=sys.stderr)
        return 2
    print(f"{args.role} token {token_id} (shown once, stored hashed): {token}")
    return 0


def run_revoke(args: argparse.Namespace) -> int:
    """Revoke the token in the configured database, audited; exit 2 on a bad setting or an unknown id."""
    from backend.core.audit_repository import AuditRepository
    from backend.core.auth import REVOCATION_POLL_S
    from backend.core.token_repository import TokenRepository

    try:
        with _sessions(args) as sessions:
            row = TokenRepository(sessions).revoke(args.token_id)
            if row is None:
                print(f"error: token_id: no token with id {args.token_id}", file=sys.stderr)
                return 2
            AuditRepository(sessions).record(
                f"acs-twin token revoke ({getpass.getuser()})",
                "token.revoke",
                f"token/{args.token_id}",
                {"name": row.name},
            )
    except _NoDatabase as exc:
        print(exc, file=sys.stderr)
        return 2
    print(
        f"token {args.token_id} ({row.name}) revoked; running servers on this database close its sessions "
        f"within {REVOCATION_POLL_S:g} s"
    )
    return 0
