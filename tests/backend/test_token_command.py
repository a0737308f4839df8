"""``acs-twin token create``: a lost admin token is replaced from the command line, audited."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from backend.cli import main
from backend.core.auth import Role
from backend.core.settings import Settings
from backend.services import build_services


def test_token_create_mints_a_working_admin_token_in_the_server_database(tmp_path: Path, capsys) -> None:
    services = build_services(Settings(data_dir=tmp_path))
    try:
        assert main(["token", "create", "--role", "admin", "--data-dir", str(tmp_path)]) == 0
        token = re.search(r": (acs_\S+)$", capsys.readouterr().out.strip()).group(1)
        principal = services.auth.resolve(token)
        assert principal is not None and principal.role is Role.admin
        assert [row.action for row in services.audit.list(action="token.create")] == ["token.create"]
    finally:
        services.close()


def test_token_create_without_a_server_database_says_where_it_looked(tmp_path: Path, capsys) -> None:
    assert main(["token", "create", "--data-dir", str(tmp_path / "nowhere")]) == 2
    assert "no server database" in capsys.readouterr().err


def test_token_create_refuses_an_unknown_role(tmp_path: Path) -> None:
    with pytest.raises(SystemExit):
        main(["token", "create", "--role", "root", "--data-dir", str(tmp_path)])


def test_token_create_refuses_a_name_the_archive_cannot_record(tmp_path: Path, capsys) -> None:
    """The token's name is the actor of its uploads and alarm actions (varchar(NAME_MAX)): a longer one is refused
    when the token is made, not at its first upload."""
    services = build_services(Settings(data_dir=tmp_path))
    try:
        assert main(["token", "create", "--name", "x" * 65, "--data-dir", str(tmp_path)]) == 2
        assert "name: at most 64 characters" in capsys.readouterr().err
        assert services.audit.list(action="token.create") == []
    finally:
        services.close()
