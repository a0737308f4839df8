"""Database engines of the archive: SQLite in WAL mode by default, PostgreSQL in production."""

from __future__ import annotations

import logging
import threading
from collections.abc import Mapping, Sequence
from typing import TYPE_CHECKING, Any, cast

from sqlalchemy import Connection, Dialect, Engine, Select, Table, Update, create_engine, event, insert
from sqlalchemy.engine import make_url
from sqlalchemy.sql.compiler import ExpandedState, SQLCompiler

if TYPE_CHECKING:
    import sqlite3

    import psycopg

__all__ = [
    "create_archive_engine",
    "DEFAULT_URL",
    "WalCheckpointer",
    "fetch_rows",
    "run_update",
    "insert_rows",
    "insert_returning_ids",
]

_log = logging.getLogger(__name__)

DEFAULT_URL = "sqlite:///data/archive.sqlite"
SQLITE_BUSY_TIMEOUT_MS = 30_000  # writers queue behind a bulk upload instead of failing at once


WAL_RESTART_FRAMES = 16_384  # a WAL this long (64 MiB of 4 KiB pages) is restarted, waiting for its readers
CHECKPOINT_RETRY_S = 1.0  # a checkpoint that readers held back is tried again this much later
RESTART_WAIT_MS = 100  # how long a RESTART waits for readers (new writers wait meanwhile), then tries again later


def _sqlite_pragmas(dbapi_connection: Any, _record: Any) -> None:
    """WAL journal, full fsync on commit (an acknowledged upload survives a crash), foreign keys."""
    dbapi_connection.isolation_level = None  # let SQLAlchemy's BEGIN below take over transactions
    cursor = dbapi_connection.cursor()
    cursor.execute("PRAGMA journal_mode=WAL")
    cursor.execute("PRAGMA synchronous=FULL")
    cursor.execute("PRAGMA foreign_keys=ON")
    cursor.execute(f"PRAGMA busy_timeout={SQLITE_BUSY_TIMEOUT_MS}")
    cursor.close()


def _sqlite_no_autocheckpoint(dbapi_connection: Any, _record: Any) -> None:
    """No checkpoint inside this connection's commits (a :class:`WalCheckpointer` runs them)."""
    cursor = dbapi_connection.cursor()
    cursor.execute("PRAGMA wal_autocheckpoint=0")
    cursor.close()


def _sqlite_begin_immediate(conn: Any) -> None:
    """Take the write lock at BEGIN so concurrent writers queue rather than deadlock."""
    conn.exec_driver_sql("BEGIN IMMEDIATE")


def _sqlite_begin_deferred(conn: Any) -> None:
    """Plain BEGIN: a read snapshot that never waits for writers (WAL)."""
    conn.exec_driver_sql("BEGIN")


def create_archive_engine(url: str, *, writer: bool = True, autocheckpoint: bool = True) -> Engine:
    """Engine for an archive URL (``sqlite:///path`` or ``postgresql+psycopg://...``).

    On SQLite a *writer* engine takes the write lock at BEGIN; a reader engine's transactions
    stay deferred, so reads run beside a bulk upload (WAL) instead of queueing behind it. Without
    *autocheckpoint* a commit never checkpoints the WAL itself: the caller runs a :class:`WalCheckpointer`.
    """
    if not isinstance(url, str) or not url:
        raise ValueError("url: expected a SQLAlchemy database URL such as sqlite:///archive.sqlite")
    parsed = make_url(url)
    if parsed.get_backend_name() == "sqlite":
        engine = create_engine(url, connect_args={"check_same_thread": False})
        event.listen(engine, "connect", _sqlite_pragmas)
        if not autocheckpoint:
            event.listen(engine, "connect", _sqlite_no_autocheckpoint)
        event.listen(engine, "begin", _sqlite_begin_immediate if writer else _sqlite_begin_deferred)
        return engine
    if parsed.get_backend_name() == "postgresql":
        return create_engine(url, pool_pre_ping=True)
    raise ValueError(f"url: unsupported database backend {parsed.get_backend_name()!r} (sqlite or postgresql)")


class WalCheckpointer:
    """SQLite WAL checkpoints on a thread of their own, after the commits, instead of inside them.

    SQLite's automatic checkpoint runs in the commit that takes the WAL past 1,000 pages: that commit copies the
    WAL's pages into the database file and fsyncs it before it returns (NOAA-20's 9.7 MB upload: ~40-60 ms of its
    wall). Here the writer's connections do not checkpoint (``wal_autocheckpoint=0``); :meth:`committed` wakes a
    thread that runs a PASSIVE checkpoint (beside readers and writers, copying what no reader still needs). The
    WAL stays bounded: frames that readers held back are tried again CHECKPOINT_RETRY_S later, and a WAL of
    WAL_RESTART_FRAMES or more is restarted (RESTART: new writers wait, at most RESTART_WAIT_MS a try, while the
    readers of older snapshots finish, so overlapping readers cannot grow it without end; a reader that never ends
    its transaction holds the WAL back, as it would SQLite's own checkpoint). Durability is unchanged: a commit still
    fsyncs the WAL (synchronous=FULL), and a checkpoint interrupted by a crash is redone from the WAL on the next open.
    The thread exists only while there is work; :meth:`wait` returns once the commits so far are checkpointed.
    """

    def __init__(self, engine: Engine) -> None:
        self._engine = engine
        self._state = threading.Condition()
        self._requested = self._done = 0  # commits announced / covered by a finished checkpoint
        self._thread: threading.Thread | None = None
        self._closed = False
        self.last: tuple[int, int, int] = (0, 0, 0)  # the last checkpoint's (busy, WAL frames, frames copied)

    def committed(self) -> None:
        """A write transaction has committed: checkpoint its frames on the thread."""
        with self._state:
            if self._closed:
                return
            self._requested += 1
            if self._thread is None:
                self._thread = threading.Thread(target=self._run, name="archive-wal-checkpoint", daemon=True)
                self._thread.start()
            self._state.notify_all()

    def wait(self) -> None:
        """Block until a checkpoint has run after every commit announced so far."""
        with self._state:
            target = self._requested
            self._state.wait_for(lambda: self._done >= target or self._thread is None)

    def close(self) -> None:
        """Let the thread finish its checkpoint and stop (closing the last connection checkpoints the rest)."""
        with self._state:
            self._closed = True
            self._state.notify_all()
            thread = self._thread
        if thread is not None:
            thread.join()

    def checkpoint(self) -> tuple[int, int, int]:
        """One PASSIVE checkpoint, then a RESTART if the WAL holds WAL_RESTART_FRAMES or more:
        (busy, frames in the WAL, frames copied into the database file) as SQLite reports them."""
        raw = self._engine.raw_connection()
        try:
            sqlite = cast("sqlite3.Connection", raw.driver_connection)
            busy, frames, copied = sqlite.execute("PRAGMA wal_checkpoint(PASSIVE)").fetchone()
            if frames >= WAL_RESTART_FRAMES:
                sqlite.execute(f"PRAGMA busy_timeout={RESTART_WAIT_MS}")
                try:
                    busy, frames, copied = sqlite.execute("PRAGMA wal_checkpoint(RESTART)").fetchone()
                finally:
                    sqlite.execute(f"PRAGMA busy_timeout={SQLITE_BUSY_TIMEOUT_MS}")
            return int(busy), int(frames), int(copied)
        finally:
            raw.close()

    def _run(self) -> None:
        held_back = False  # readers kept frames in the WAL: try again later even without a commit
        while True:
            with self._state:
                pending = self._state.wait_for(
                    lambda: self._requested > self._done or self._closed,
                    timeout=CHECKPOINT_RETRY_S if held_back else 0.0,
                )
                if not pending and not held_back or self._closed:
                    self._done, self._thread = self._requested, None
                    self._state.notify_all()
                    return
                target = self._requested
            try:
                self.last = self.checkpoint()
                held_back = self.last[0] != 0 or self.last[2] < self.last[1]
            except Exception:  # the database went away: the next commit or the last close checkpoints
                _log.exception("WAL checkpoint of %s failed", self._engine.url)
                held_back = False
            with self._state:
                self._done = target
                self._state.notify_all()


_INSERTS: dict[tuple[str, str, str, str, tuple[str, ...]], tuple[str, bool]] = {}


def _insert_sql(dialect: Dialect, table: Table, columns: tuple[str, ...]) -> tuple[str, bool]:
    """``table``'s INSERT of ``columns`` (no RETURNING) in the driver's parameter style, and whether its parameters
    are positional; compiled once per table, columns and kind of driver."""
    key = (dialect.name, str(dialect.driver), str(dialect.paramstyle), table.name, columns)
    if key not in _INSERTS:
        compiled = insert(table).inline().compile(dialect=dialect, column_keys=list(columns))
        if compiled.positional and tuple(compiled.positiontup or ()) != columns:
            raise RuntimeError(f"{table.name} INSERT binds {compiled.positiontup}, expected {columns}")
        _INSERTS[key] = str(compiled), compiled.positional
    return _INSERTS[key]


_EXPANDED: dict[tuple[tuple[str, str, str, int], tuple[tuple[str, int], ...]], tuple[SQLCompiler, ExpandedState]] = {}
_EXPANDED_MAX = 1_024  # expanded statements kept (per statement, driver and lengths of its IN lists)
_STATEMENTS: dict[tuple[str, str, str, int], tuple[Select[Any] | Update, SQLCompiler]] = {}


def fetch_rows(conn: Connection, statement: Select[Any], params: Mapping[str, Any]) -> list[tuple[Any, ...]]:
    """The rows of ``statement`` (a SELECT of plain columns: int, str, float or bytes, no conversion) with
    ``params``, run through the driver inside the caller's transaction: compiled once per statement and kind of
    driver; an expanding IN list is rendered per call. SQLAlchemy's execute costs ~40 us of Python per statement
    where the driver runs an indexed look-up in ~2 us on SQLite, and an upload runs one per APID and archive
    chunk."""
    cursor = _execute(conn, statement, params)
    try:
        return cast("list[tuple[Any, ...]]", cursor.fetchall())
    finally:
        cursor.close()


def run_update(conn: Connection, statement: Update, params: Mapping[str, Any]) -> None:
    """Run ``statement`` (an UPDATE built once, its values bound by name) with ``params`` as :func:`fetch_rows`
    runs a SELECT: through the driver, values handed over as they are (int, str, float, bytes or None)."""
    _execute(conn, statement, params).close()


def _execute(conn: Connection, statement: Select[Any] | Update, params: Mapping[str, Any]) -> Any:
    """The driver's cursor having run ``statement`` (compiled once per statement and kind of driver)."""
    dialect = conn.dialect
    key = (dialect.name, str(dialect.driver), str(dialect.paramstyle), id(statement))
    cached = _STATEMENTS.get(key)
    if cached is None or cached[0] is not statement:
        cached = _STATEMENTS[key] = (statement, statement.compile(dialect=dialect))
    compiled = cached[1]
    if compiled.literal_execute_params:  # values rendered into the SQL: expanded for them
        state = compiled.construct_expanded_state(dict(params))
        sql, names, values = state.statement, state.positiontup, state.parameters
    elif compiled.post_compile_params:  # an expanding IN: one placeholder per value, rendered once per list length
        lengths = tuple((name, len(v)) for name, v in params.items() if isinstance(v, list | tuple))
        known = _EXPANDED.get((key, lengths))
        if known is None or known[0] is not compiled:
            if len(_EXPANDED) >= _EXPANDED_MAX:
                _EXPANDED.clear()
            known = _EXPANDED[(key, lengths)] = (compiled, compiled.construct_expanded_state(dict(params)))
        expansion = known[1]
        values = dict(expansion.parameters)  # the statement's own values (a literal IN list), then this call's
        for name, value in params.items():
            expanded = expansion.parameter_expansion.get(name)
            values.update({name: value} if expanded is None else zip(expanded, value, strict=True))
        sql, names = expansion.statement, expansion.positiontup
    else:
        sql, names, values = compiled.string, compiled.positiontup, params
    args = [values[n] for n in names] if compiled.positional and names is not None else dict(values)
    cursor = conn.connection.dbapi_connection.cursor()  # type: ignore[union-attr]
    try:
        cursor.execute(sql, args)
    except BaseException:
        cursor.close()
        raise
    return cursor


def insert_rows(conn: Connection, table: Table, columns: tuple[str, ...], rows: Sequence[tuple[Any, ...]]) -> None:
    """Insert ``rows`` (values of ``columns``) inside the caller's transaction, handed to the driver as they are:
    no per-row statement processing (an upload writes thousands of rows), so the values must need no conversion
    (int, str, float, bytes or None). One COPY on PostgreSQL (psycopg's executemany sends a statement per row:
    an upload's 359,361 alarm events took 5 s of CPU), one executemany elsewhere."""
    if conn.dialect.name == "postgresql" and conn.dialect.driver == "psycopg":
        _copy_rows(conn, table, columns, rows)
        return
    sql, positional = _insert_sql(conn.dialect, table, columns)
    cursor = conn.connection.dbapi_connection.cursor()  # type: ignore[union-attr]
    try:  # the driver's executemany itself: SQLAlchemy's exec_driver_sql added ~30 us per call
        cursor.executemany(sql, rows if positional else [dict(zip(columns, row, strict=True)) for row in rows])
    finally:
        cursor.close()


def insert_returning_ids(
    conn: Connection, table: Table, columns: tuple[str, ...], rows: Sequence[tuple[Any, ...]]
) -> list[int]:
    """Insert ``rows`` (values of ``columns``, as for :func:`insert_rows`) and return their ids in row order. On
    SQLite one prepared statement per row through the driver and its ``lastrowid`` (SQLAlchemy's executemany with
    RETURNING built a multi-row statement and processed every parameter: ~1 ms per call of 1-2 archive chunks);
    elsewhere INSERT ... RETURNING, sorted as the rows were given."""
    if conn.dialect.name == "sqlite":
        sql, positional = _insert_sql(conn.dialect, table, columns)
        cursor = conn.connection.dbapi_connection.cursor()  # type: ignore[union-attr]
        try:
            ids = []
            for row in rows:
                cursor.execute(sql, row if positional else dict(zip(columns, row, strict=True)))
                ids.append(int(cursor.lastrowid))
            return ids
        finally:
            cursor.close()
    statement = insert(table).returning(table.c.id, sort_by_parameter_order=True)
    return [int(i) for i in conn.execute(statement, [dict(zip(columns, row, strict=True)) for row in rows]).scalars()]


def _copy_rows(conn: Connection, table: Table, columns: tuple[str, ...], rows: Sequence[tuple[Any, ...]]) -> None:
    """``COPY table (columns) FROM STDIN`` of ``rows`` on the connection's psycopg connection (same transaction)."""
    quote = conn.dialect.identifier_preparer
    sql = f"COPY {quote.format_table(table)} ({', '.join(quote.quote(c) for c in columns)}) FROM STDIN"
    dbapi = cast("psycopg.Connection[Any]", conn.connection.dbapi_connection)
    with dbapi.cursor() as cursor, cursor.copy(sql) as copy:
        for row in rows:
            copy.write_row(row)
