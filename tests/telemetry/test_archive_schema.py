"""A new archive is created at head directly: the same schema as the migration chain builds, created once.

``upgrade`` creates a database without the archive's tables from the models and stamps it at head; the
migrations stay the truth for existing databases, so the created catalog must equal the migrated one on
SQLite and PostgreSQL: tables, columns in order with their types, nullability and defaults, constraints,
indexes, sequences, file pragmas.
"""

from __future__ import annotations

import os
import re
import select
import signal
import time
import traceback
from collections.abc import Iterator
from typing import Any

import pytest
from alembic import command
from alembic.autogenerate import compare_metadata
from alembic.runtime.migration import MigrationContext
from alembic.script import ScriptDirectory
from sqlalchemy import Connection, event, text

from telemetry.archive import upgrade
from telemetry.archive.engine import create_archive_engine
from telemetry.archive.migrate import HEAD_REVISION, alembic_config
from telemetry.archive.models import Base
from tests.telemetry.archive_databases import new_postgres_schema

FIRST_REVISION = "0001"
CHILD_DEADLINE_S = 120.0  # a child's upgrade waits behind the other's lock; minutes only on a badly loaded machine
SQLITE_WAIT_S = 0.5  # time given to the second opener to reach SQLite's write lock (nothing shows it waiting)


@pytest.fixture(params=["sqlite", pytest.param("postgresql", marks=pytest.mark.postgres)])
def two_new_databases(request: pytest.FixtureRequest, tmp_path) -> Iterator[tuple[str, str]]:
    """URLs of two empty databases of one kind: SQLite files, or two new PostgreSQL schemas."""
    if request.param == "sqlite":
        yield f"sqlite:///{tmp_path / 'a.sqlite'}", f"sqlite:///{tmp_path / 'b.sqlite'}"
        return
    base_url = request.getfixturevalue("postgres_url")
    with new_postgres_schema(base_url) as first, new_postgres_schema(base_url) as second:
        yield first, second


def migrate_with_alembic(url: str, revision: str) -> None:
    """Run the alembic chain on ``url`` up to ``revision`` (what existing archives went through)."""
    engine = create_archive_engine(url)
    with engine.begin() as connection:
        config = alembic_config(url)
        config.attributes["connection"] = connection
        command.upgrade(config, revision)
    engine.dispose()


def _sqlite_table_sql(sql: str) -> tuple[str, ...]:
    """A CREATE TABLE statement as its column clauses in order, then its constraint clauses sorted (alembic's
    table rebuilds and create_all list the same constraints in another order); identifiers unquoted."""
    lines = [line.strip().rstrip(",") for line in sql.replace('"', "").splitlines()]
    head, body = lines[0], lines[1:-1]
    columns = [c for c in body if not c.startswith("CONSTRAINT ")]
    return (head, *columns, *sorted(c for c in body if c.startswith("CONSTRAINT ")))


def sqlite_catalog(connection: Connection) -> dict[str, Any]:
    """sqlite_master (SQL normalised), each table's columns, indexes and foreign keys, the file's pragmas."""
    catalog: dict[str, Any] = {}
    for kind, name, table, sql in connection.exec_driver_sql("SELECT type, name, tbl_name, sql FROM sqlite_master"):
        normal = _sqlite_table_sql(sql) if kind == "table" else (sql and re.sub(r'"', "", sql))
        catalog[f"{kind} {name}"] = (table, normal)
        if kind != "table":
            continue
        catalog[f"columns {name}"] = connection.exec_driver_sql(f'PRAGMA table_xinfo("{name}")').all()
        indexes = connection.exec_driver_sql(f'PRAGMA index_list("{name}")').all()
        catalog[f"indexes {name}"] = sorted(tuple(row[1:]) for row in indexes)  # (name, unique, origin, partial)
        for index in indexes:
            catalog[f"index {index[1]}"] = connection.exec_driver_sql(f'PRAGMA index_xinfo("{index[1]}")').all()
        keys = connection.exec_driver_sql(f'PRAGMA foreign_key_list("{name}")').all()
        catalog[f"foreign keys {name}"] = sorted(tuple(row[2:]) for row in keys)  # without the key's number
    for pragma in ("journal_mode", "auto_vacuum", "page_size", "encoding", "user_version", "application_id"):
        catalog[f"pragma {pragma}"] = connection.exec_driver_sql(f"PRAGMA {pragma}").scalar()
    return catalog


PG_CATALOG = {
    "tables": "SELECT relname, relkind, relpersistence, reloptions FROM pg_class WHERE relnamespace = {ns} "
    "ORDER BY relname",
    "columns": "SELECT table_name, ordinal_position, column_name, data_type, character_maximum_length, "
    "numeric_precision, is_nullable, column_default, is_identity FROM information_schema.columns "
    "WHERE table_schema = current_schema() ORDER BY table_name, ordinal_position",
    "constraints": "SELECT t.relname, c.conname, c.contype, pg_get_constraintdef(c.oid) FROM pg_constraint c "
    "JOIN pg_class t ON t.oid = c.conrelid WHERE c.connamespace = {ns} ORDER BY t.relname, c.conname",
    "indexes": "SELECT tablename, indexname, indexdef FROM pg_indexes WHERE schemaname = current_schema() "
    "ORDER BY indexname",
    "sequences": "SELECT sequencename, data_type, start_value, min_value, max_value, increment_by, cycle, "
    "cache_size FROM pg_sequences WHERE schemaname = current_schema() ORDER BY sequencename",
    "sequence owners": "SELECT s.relname, t.relname, a.attname FROM pg_class s JOIN pg_depend d ON d.objid = s.oid "
    "AND d.classid = 'pg_class'::regclass AND d.refclassid = 'pg_class'::regclass JOIN pg_class t ON "
    "t.oid = d.refobjid JOIN pg_attribute a ON a.attrelid = t.oid AND a.attnum = d.refobjsubid "
    "WHERE s.relkind = 'S' AND s.relnamespace = {ns} ORDER BY s.relname",
}


def postgres_catalog(connection: Connection) -> dict[str, Any]:
    """The schema's tables, columns in order, constraints, indexes, sequences and their owners (pg_catalog)."""
    schema = connection.execute(text("SELECT current_schema()")).scalar_one()
    namespace = "current_schema()::regnamespace"
    return {
        part: [
            tuple(str(v).replace(f"{schema}.", "") if isinstance(v, str) else v for v in row)
            for row in connection.exec_driver_sql(sql.format(ns=namespace))
        ]
        for part, sql in PG_CATALOG.items()
    }


def catalog(url: str) -> dict[str, Any]:
    """The catalog of the database at ``url``, its alembic revision, and how its tables differ from the models."""
    engine = create_archive_engine(url)
    with engine.connect() as connection:
        found = sqlite_catalog(connection) if engine.dialect.name == "sqlite" else postgres_catalog(connection)
        context = MigrationContext.configure(connection)
        found["revision"] = context.get_current_revision()
        found["differences from the models"] = compare_metadata(context, Base.metadata)
    engine.dispose()
    return found


def test_head_revision_is_the_newest_migration() -> None:
    assert ScriptDirectory.from_config(alembic_config("sqlite://")).get_current_head() == HEAD_REVISION


def test_new_archive_is_created_with_the_schema_the_migrations_build(two_new_databases: tuple[str, str]) -> None:
    created_url, migrated_url = two_new_databases
    upgrade(created_url)
    migrate_with_alembic(migrated_url, FIRST_REVISION)
    upgrade(migrated_url)  # an existing archive: migrated from 0001 to the head by the chain
    created, migrated = catalog(created_url), catalog(migrated_url)
    assert created["revision"] == migrated["revision"] == HEAD_REVISION
    assert created["differences from the models"] == migrated["differences from the models"] == []
    assert set(created) == set(migrated)
    assert {k: v for k, v in created.items() if v != migrated[k]} == {}
    if created_url.startswith("sqlite"):
        assert created["pragma journal_mode"] == "wal"


def _open_new_archive(url: str, created_fd: int, go_fd: int | None, waiting_fd: int | None) -> None:
    """Child body: ``upgrade(url)`` on an engine of its own; ``go_fd``: before its first CREATE TABLE, say so on
    ``created_fd`` and wait for a byte; ``waiting_fd``: say when it has connected. Exits 0 if it created
    the schema, 3 if it found it made, 1 on an error."""
    try:
        engine = create_archive_engine(url)
        creates: list[str] = []

        def before_execute(_conn: Any, _cursor: Any, statement: str, *_args: Any) -> None:
            if statement.lstrip().startswith("CREATE TABLE"):
                if not creates and go_fd is not None:
                    os.write(created_fd, b"c")
                    os.read(go_fd, 1)
                creates.append(statement)

        event.listen(engine, "before_cursor_execute", before_execute)
        if waiting_fd is not None:  # connected: next its transaction begins (BEGIN IMMEDIATE on SQLite)
            event.listen(engine, "connect", lambda _dbapi, _record: os.write(waiting_fd, b"b"))
        upgrade(url, engine)
        engine.dispose()
        os._exit(0 if creates else 3)
    except BaseException:
        traceback.print_exc()
        os._exit(1)


def _fork(body: Any, *args: Any) -> int:
    pid = os.fork()
    if pid == 0:  # forked: the child has the archive's modules loaded already
        body(*args)
    return pid


def _read_byte(fd: int) -> bytes:
    ready, _, _ = select.select([fd], [], [], CHILD_DEADLINE_S)
    assert ready, f"no word from the child in {CHILD_DEADLINE_S} s"
    return os.read(fd, 1)


def _exit_code(pid: int) -> int:
    deadline = time.monotonic() + CHILD_DEADLINE_S
    while time.monotonic() < deadline:
        done, status = os.waitpid(pid, os.WNOHANG)
        if done:
            return os.waitstatus_to_exitcode(status)
        time.sleep(0.05)
    raise AssertionError(f"child {pid} did not finish its upgrade in {CHILD_DEADLINE_S} s")


def _wait_for_lock_waiter(url: str) -> None:
    """Until a session of the database waits for the archive's upgrade lock (PostgreSQL)."""
    engine = create_archive_engine(url)
    deadline = time.monotonic() + CHILD_DEADLINE_S
    query = text(
        "SELECT count(*) FROM pg_stat_activity WHERE wait_event_type = 'Lock' AND wait_event = 'advisory' "
        "AND datname = current_database() AND query LIKE '%acs_twin.archive.upgrade%'"
    )
    with engine.connect() as connection:
        while not connection.execute(query).scalar_one():
            assert time.monotonic() < deadline, "the second opener never waited for the upgrade lock"
            time.sleep(0.02)
            connection.rollback()
    engine.dispose()


def test_two_processes_opening_a_new_archive_at_once_create_it_once(two_new_databases: tuple[str, str]) -> None:
    url = two_new_databases[0]
    created_r, created_w = os.pipe()
    go_r, go_w = os.pipe()
    waiting_r, waiting_w = os.pipe()
    children, codes = [_fork(_open_new_archive, url, created_w, go_r, None)], []
    try:
        assert _read_byte(created_r) == b"c"  # the first is in its transaction, about to create the first table
        children.append(_fork(_open_new_archive, url, created_w, None, waiting_w))
        assert _read_byte(waiting_r) == b"b"  # the second has connected and goes on to begin its transaction
        if url.startswith("postgresql"):
            _wait_for_lock_waiter(url)
        else:
            time.sleep(SQLITE_WAIT_S)
        os.write(go_w, b"g")
        for pid in children:
            codes.append(_exit_code(pid))
    finally:
        for fd in (created_r, created_w, go_r, go_w, waiting_r, waiting_w):
            os.close(fd)
        for pid in children[len(codes) :]:  # not reaped: the test failed before its end
            os.kill(pid, signal.SIGKILL)
            os.waitpid(pid, 0)
    assert codes == [0, 3]  # the first created the schema, the second found it made
    found = catalog(url)
    assert found["revision"] == HEAD_REVISION and found["differences from the models"] == []
