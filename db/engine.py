"""Database connection, unit of work and schema migration.

``connect(url)`` → :class:`Database`. The URL comes from the argument, else ``$RAILVAL_DB``,
else the embedded SQLite file ``sqlite:///railval.db`` in the working directory.

* SQLite: WAL journal (readers never block the writer), foreign keys enforced, a busy
  timeout so concurrent writers wait instead of failing, and real ``BEGIN`` statements so
  a unit of work — DDL included — is atomic. Reads use a memory map of the file (up to
  2 GiB) and a 64 MiB page cache per connection: signal blobs are chains of overflow pages,
  and reading a column stored after a blob (a content hash) walks the whole chain.
* PostgreSQL: ``postgresql+psycopg://user@host/db`` (psycopg 3); ``postgresql://`` is taken
  to mean the same driver.

``Database.session()`` is one unit of work: it commits when the block ends normally and
rolls back when it raises. It is a read session unless it says it writes: the database itself
keeps it from writing — SQLite ``PRAGMA query_only = ON`` on its connection (set back OFF at
the ``BEGIN`` of any write unit of work on that pooled connection, so the pragma never leaks
into a write), PostgreSQL ``SET TRANSACTION READ ONLY`` as the first statement of the
transaction; a write there raises :class:`WriteInReadSession`. The one write door is
``session(write=True)`` (:meth:`Database.write_session`): on SQLite it takes the write lock at
``BEGIN IMMEDIATE``, so concurrent writers wait their turn; ``write_session(deferred=True)``
(``session(write=True, deferred=True)``) is a unit of work that reads and computes first and
ends with a short write — a plain ``BEGIN``, SQLite's lock taken only at that write.
``Database.init()`` migrates
the schema to the newest Alembic revision (idempotent); ``ensure_initialised()`` is the cheap
check the CLI runs first.
"""

from __future__ import annotations

import contextvars
import os
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from sqlalchemy import Engine, create_engine, event, inspect, text
from sqlalchemy.engine import make_url
from sqlalchemy.exc import DBAPIError
from sqlalchemy.orm import Session, sessionmaker
from sqlalchemy.pool import StaticPool

from railval.core import lazy
from railval.core.errors import RailvalError
from railval.db.settings import setting

#: deferred (railval.core.lazy): the ORM models (and the audit trail, which imports them)
#: load with a PostgreSQL engine or a legacy trail's sealing, not with every connection (the
#: fast path of ``railval list`` reads the catalogue without them); the migration scripts'
#: head (read by the catalogue module) only when a revision is compared
audit = lazy.module("railval.db.audit")
declare_postgresql_options = lazy.function("railval.db.models", "declare_postgresql_options")
scripts_head = lazy.function("railval.db.catalogue", "head_revision")

DEFAULT_URL = "sqlite:///railval.db"
MIGRATIONS = Path(__file__).with_name("migrations")
SQLITE_BUSY_TIMEOUT_MS = 30_000
#: bytes of the file SQLite may memory-map (it clamps this to its compile-time maximum,
#: 2 GiB in the usual builds); reads of mapped pages skip the read() copy into the cache
SQLITE_MMAP_BYTES = 1 << 31
#: page cache per connection in KiB (negative PRAGMA cache_size); holds the overflow pages
#: of one configuration's blobs (≈ 46 MB at DynoTRAIN size) between reading the hashes and
#: reading the blobs, which matters for the part of the file beyond the mapped 2 GiB
SQLITE_CACHE_KIB = 65_536


#: the actor of new :class:`Database` objects (the CLI sets the acting user before a verb runs)
default_actor = "system"
#: the actor of the current thread/context (the web app's jobs run inside :func:`acting_as`)
_current_actor: contextvars.ContextVar[str | None] = contextvars.ContextVar(
    "railval_actor", default=None)


@contextmanager
def acting_as(actor: str) -> Iterator[None]:
    """Within the block, units of work that name no actor are recorded as ``actor``."""
    token = _current_actor.set(actor)
    try:
        yield
    finally:
        _current_actor.reset(token)


class WriteInReadSession(RailvalError):
    """A read session (every unit of work not opened with ``write=True``) tried to write;
    writes go through ``Database.session(write=True)`` (:meth:`Database.write_session`)."""


#: what SQLite (``query_only``) and PostgreSQL (``READ ONLY`` transaction) say about a refused write
_READ_ONLY_REFUSALS = ("attempt to write a readonly database", "read-only transaction")


class DatabaseNotInitialised(RailvalError):
    """The database schema is missing or older than this railval; run ``railval init``."""


def resolve_url(url: str | None = None) -> str:
    """Argument, else ``$RAILVAL_DB`` (or its ``_FILE``), else :data:`DEFAULT_URL`; normalises
    PostgreSQL URLs and adds ``$RAILVAL_DB_PASSWORD`` (or its ``_FILE``) to a URL without
    password (:mod:`railval.db.settings`)."""
    url = url or setting("RAILVAL_DB") or DEFAULT_URL
    if url.startswith(("postgresql://", "postgres://")):
        url = "postgresql+psycopg://" + url.split("://", 1)[1]
    if url.startswith("postgresql") and make_url(url).password is None:
        password = setting("RAILVAL_DB_PASSWORD")  # a secret file, never in the URL's source
        if password:
            url = make_url(url).set(password=password).render_as_string(hide_password=False)
    return url


def _sqlite_pragmas(dbapi_conn, _record) -> None:
    # Take over transaction control from pysqlite (SQLAlchemy's documented recipe), so
    # BEGIN is emitted by the "begin" event below and DDL is transactional.
    dbapi_conn.isolation_level = None
    cur = dbapi_conn.cursor()
    cur.execute("PRAGMA foreign_keys=ON")
    cur.execute(f"PRAGMA busy_timeout={SQLITE_BUSY_TIMEOUT_MS}")
    cur.execute("PRAGMA journal_mode=WAL")
    cur.execute("PRAGMA synchronous=NORMAL")
    cur.execute(f"PRAGMA mmap_size={SQLITE_MMAP_BYTES}")
    cur.execute(f"PRAGMA cache_size=-{SQLITE_CACHE_KIB}")
    cur.close()


def _sqlite_begin(conn) -> None:
    # A unit of work that will write takes the write lock at BEGIN (BEGIN IMMEDIATE): it
    # waits up to the busy timeout for another writer and then reads a fresh snapshot. A
    # deferred transaction that reads and then writes cannot wait — SQLite refuses its
    # upgrade at once with "database is locked" when another writer got in between
    # (SQLAlchemy docs, "Serializable isolation / Savepoints / Transactional DDL" of pysqlite).
    # query_only is a property of the connection, not of the transaction: it is set at every
    # BEGIN, ON for a read session and OFF for anything else, so a pooled connection (or the
    # one shared connection of an in-memory database) never carries it into a write.
    options = conn.get_execution_options()
    write = options.get("railval_write", False)  # True, "deferred" or False
    read_only = options.get("railval_read_only", False) and not write
    conn.exec_driver_sql(f"PRAGMA query_only = {'ON' if read_only else 'OFF'}")
    conn.exec_driver_sql("BEGIN IMMEDIATE" if write is True else "BEGIN")


def _postgresql_begin(conn) -> None:
    # psycopg begins the transaction implicitly at the first statement, so this statement
    # is the transaction's first: the read session's transaction is READ ONLY (PostgreSQL
    # docs, SET TRANSACTION); it ends with the transaction, so the pooled connection is clean.
    if conn.get_execution_options().get("railval_read_only", False):
        conn.exec_driver_sql("SET TRANSACTION READ ONLY")


#: the first schema revision whose audit rows and sign-offs are signed
SIGNING_REVISION = "0007_signatures"


class Database:
    """A connected database: engine, session factory, migrations."""

    def __init__(self, url: str, engine: Engine):
        self.url = url
        self.engine = engine
        #: a deferred write: plain ``BEGIN``, query_only OFF (:meth:`write_session`)
        self._deferred_write_sessions = sessionmaker(engine, expire_on_commit=False)
        self._write_sessions = sessionmaker(engine.execution_options(railval_write=True),
                                            expire_on_commit=False)
        self._read_sessions = sessionmaker(engine.execution_options(railval_read_only=True),
                                           expire_on_commit=False)
        self._initialised = False
        #: who the audit trail names for changes made through :meth:`session` when the
        #: caller names nobody (the CLI sets ``cli:<OS user>``, the web app the signed-in user)
        self.actor = default_actor

    @property
    def dialect(self) -> str:
        return self.engine.dialect.name

    @contextmanager
    def session(self, actor: str | None = None, *, write: bool = False,
                deferred: bool = False) -> Iterator[Session]:
        """One unit of work: commit on success, roll back on any exception.

        ``actor`` (else the one set by :func:`acting_as`, else :attr:`actor`) is kept in
        ``session.info["actor"]``: the audit rows written in this unit of work name it
        (:func:`railval.db.audit.actor_of`).
        Without ``write=True`` it is a read session the database refuses to write in (SQLite
        ``query_only``, PostgreSQL ``READ ONLY`` transaction): a write raises
        :class:`WriteInReadSession` and nothing is stored. ``write=True`` is the one write
        door: on SQLite it starts with ``BEGIN IMMEDIATE`` so concurrent writers queue (up to
        the 30 s busy timeout) instead of failing; on PostgreSQL it is a plain transaction.
        ``deferred=True`` (only with ``write=True``): a unit of work that reads and computes
        and ends with a short write — a plain ``BEGIN``, so SQLite's write lock is taken at that
        write, not for the whole computation (docs/database.md, "One write door").
        """
        if deferred and not write:
            raise ValueError("deferred=True is a kind of write unit of work: write=True with it")
        read_only = not write
        factory = (self._read_sessions if read_only else
                   self._deferred_write_sessions if deferred else self._write_sessions)
        session = factory()
        session.info["actor"] = actor or _current_actor.get() or self.actor
        session.info["read_only"] = read_only
        try:
            yield session
            session.commit()
        except BaseException as exc:
            session.rollback()
            if read_only and isinstance(exc, DBAPIError) and any(
                    m in str(exc.orig) for m in _READ_ONLY_REFUSALS):
                raise WriteInReadSession(
                    f"a write in a read session of {self.safe_url} was refused by the database "
                    f"({str(exc.orig).strip().splitlines()[0]}): write through "
                    "session(write=True)") from exc
            raise
        finally:
            session.close()

    def read_session(self, actor: str | None = None):
        """A read session: the same as :meth:`session` without ``write=True``."""
        return self.session(actor)

    def write_session(self, actor: str | None = None, *, deferred: bool = False):
        """The write door: :meth:`session` with ``write=True`` (and ``deferred``)."""
        return self.session(actor, write=True, deferred=deferred)

    # -- migrations ---------------------------------------------------------------------
    def _alembic_config(self):
        from alembic.config import Config

        cfg = Config()
        cfg.set_main_option("script_location", str(MIGRATIONS))
        cfg.set_main_option("sqlalchemy.url", self.url.replace("%", "%%"))
        return cfg

    def head_revision(self) -> str:
        """The newest migration revision, read from the scripts without importing Alembic
        (:func:`railval.db.catalogue.head_revision`; Alembic's ScriptDirectory when the
        scripts do not form one linear head)."""
        head = scripts_head()
        if head is None:
            from alembic.script import ScriptDirectory

            head = ScriptDirectory.from_config(self._alembic_config()).get_current_head()
        assert head is not None
        return head

    def current_revision(self) -> str | None:
        """The revision stamped in the database (None before the first migration): the query
        of Alembic's ``MigrationContext.get_current_revision``, without importing Alembic
        (a verb checks the revision on every start)."""
        with self.engine.connect() as conn:
            if not inspect(conn).has_table("alembic_version"):
                return None
            rows = conn.execute(text("SELECT version_num FROM alembic_version")).scalars().all()
        if len(rows) > 1:
            raise RuntimeError(f"database {self.safe_url} has {len(rows)} revisions stamped "
                               f"({', '.join(rows)}): a branched migration history")
        return rows[0] if rows else None

    def init(self) -> str:
        """Create or upgrade the schema to the newest revision; returns that revision."""
        from alembic import command

        before = self.current_revision()
        cfg = self._alembic_config()
        with self.engine.begin() as conn:
            cfg.attributes["connection"] = conn
            command.upgrade(cfg, "head")
        self._initialised = True
        if before is not None and before < SIGNING_REVISION:
            self._seal_legacy_trail(before)
        return self.head_revision()

    def _seal_legacy_trail(self, before: str) -> None:
        """A database from before signed audit rows (revision ``before``): the upgrade states
        in a signed ``audit.seal`` row that the earlier rows and sign-offs were written
        unsigned, binding them as found (docs/audit.md); without it they would read as edited
        outside railval."""
        with self.session(actor="railval upgrade", write=True) as s:
            audit.seal(s, "railval upgrade", f"rows written before signing existed (revision "
                                             f"{before}), sealed at the upgrade")

    def ensure_initialised(self, *, upgrade: bool = False) -> None:
        """Raise :class:`DatabaseNotInitialised` unless the schema is at the newest revision.

        With ``upgrade=True`` an empty or older database is migrated instead. The check is
        one small query and is remembered for the lifetime of this object.
        """
        if self._initialised:
            return
        current = self.current_revision()
        if current == self.head_revision():
            self._initialised = True
            return
        if upgrade:
            self.init()
            return
        if current is None:
            tables = inspect(self.engine).get_table_names()
            state = "is empty" if not tables else f"has tables {tables[:5]} but no revision"
        else:
            state = f"is at revision {current}, this railval needs {self.head_revision()}"
        raise DatabaseNotInitialised(f"database {self.safe_url} {state}; run `railval init`")

    @property
    def safe_url(self) -> str:
        return make_url(self.url).render_as_string(hide_password=True)

    def dispose(self) -> None:
        self.engine.dispose()

    def __repr__(self) -> str:
        return f"Database({self.safe_url!r})"


def _create_private(path: Path) -> None:
    """Create a new SQLite file readable and writable by its owner only (0600); SQLite gives
    its ``-wal`` and ``-shm`` files the same permissions. An existing file is left as is."""
    if path.exists() or not path.parent.is_dir():
        return
    try:
        fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
    except FileExistsError:  # created by a concurrent process meanwhile
        return
    os.close(fd)


def connect(url: str | None = None, *, echo: bool = False) -> Database:
    """Connect to the database at ``url`` (else ``$RAILVAL_DB``, else ``sqlite:///railval.db``)."""
    url = resolve_url(url)
    parsed = make_url(url)
    if parsed.get_backend_name() == "sqlite":
        kwargs: dict = {"connect_args": {"timeout": SQLITE_BUSY_TIMEOUT_MS / 1000}}
        if parsed.database not in (None, "", ":memory:") and not parsed.database.startswith("file:"):
            _create_private(Path(parsed.database))
        if parsed.database in (None, "", ":memory:"):
            # one shared connection, else every pooled connection sees its own empty DB
            kwargs["poolclass"] = StaticPool
            kwargs["connect_args"]["check_same_thread"] = False
        engine = create_engine(url, echo=echo, **kwargs)
        event.listen(engine, "connect", _sqlite_pragmas)
        event.listen(engine, "begin", _sqlite_begin)
    elif parsed.get_backend_name() == "postgresql":
        declare_postgresql_options()
        engine = create_engine(url, echo=echo, pool_pre_ping=True)
        event.listen(engine, "begin", _postgresql_begin)
    else:
        raise RailvalError(
            f"database URL {parsed.render_as_string(hide_password=True)} has an unsupported "
            "backend; use sqlite:///FILE or postgresql+psycopg://USER@HOST/DB"
        )
    return Database(url, engine)
