"""Shared fixtures: a database URL on every backend, and a ready database.

``db_url`` is parametrised over the backends: ``sqlite`` (a fresh file in the test's tmp
folder) and ``postgresql`` (a fresh schema in the database ``test`` on 127.0.0.1:5432,
dropped after the test; override the server with ``$RAILVAL_TEST_PG``). When no PostgreSQL
server answers, the ``postgresql`` cases are skipped with the reason — unless
``RAILVAL_REQUIRE_PG=1`` (CI), which turns the skip into a failure.

``module_db_url`` is the same with one database per test module (for read-only tests that
share an expensive set-up). ``backend_url(kind, folder)`` is the context manager behind both.

``database`` is a :class:`railval.db.engine.Database` connected to ``db_url`` and migrated to the
newest schema revision. Tests that want SQLite only use ``sqlite_database``.
``demo_campaign_dir`` is a demo campaign folder (``tests.factories.write_demo_campaign``
with its defaults plus a ``variant1`` child configuration, Parquet files) written once per
test session: read it, never modify it (copy it first).
"""

from __future__ import annotations

import atexit
import os
import shutil
import tempfile
import uuid
from collections.abc import Iterator
from contextlib import contextmanager

import pytest

# The suite's signing keys, seal secrets, trust anchors and witnesses go to a configuration
# folder of its own (db/integrity.py, db/trust.py: ``$XDG_CONFIG_HOME/railval``), never to the
# user's: a test run must neither read a real server's anchors nor leave thousands of its own.
_CONFIG_HOME = tempfile.mkdtemp(prefix="railval-test-config-")
os.environ["XDG_CONFIG_HOME"] = _CONFIG_HOME
atexit.register(shutil.rmtree, _CONFIG_HOME, True)

PG_SERVER_URL = os.environ.get(
    "RAILVAL_TEST_PG", "postgresql+psycopg://postgres@127.0.0.1:5432/test"
)
_pg_state: dict[str, str | None] = {}


def require_program(path: str | None, hint: str) -> str:
    """``path`` of an outside program a test drives (nginx, systemd-analyze); when it is
    missing the test skips with ``hint`` — or fails under ``RAILVAL_REQUIRE_PROGRAMS=1`` (CI,
    whose .ci/run installs them), so a missing program can never pass CI silently."""
    if path is not None:
        return path
    if os.environ.get("RAILVAL_REQUIRE_PROGRAMS") == "1":
        pytest.fail(f"RAILVAL_REQUIRE_PROGRAMS=1 but {hint}")
    pytest.skip(hint)


def _pg_unavailable() -> str | None:
    """``None`` when the PostgreSQL test server answers, else the reason it does not."""
    if "reason" not in _pg_state:
        try:
            import psycopg

            conninfo = PG_SERVER_URL.replace("postgresql+psycopg://", "postgresql://")
            with psycopg.connect(conninfo, connect_timeout=3) as conn:
                conn.execute("SELECT 1")
            _pg_state["reason"] = None
        except Exception as exc:  # noqa: BLE001 - any failure means "no server"
            _pg_state["reason"] = f"no PostgreSQL server at {PG_SERVER_URL}: {exc}".strip()
    return _pg_state["reason"]


BACKENDS = ["sqlite", pytest.param("postgresql", marks=pytest.mark.postgres)]


@contextmanager
def backend_url(kind: str, folder) -> Iterator[str]:
    """URL of a fresh empty database of backend ``kind`` ('sqlite' or 'postgresql').

    SQLite: a file in ``folder``. PostgreSQL: a new schema in the test database, dropped on
    exit; skips (or fails under ``RAILVAL_REQUIRE_PG=1``) when no server answers.
    """
    if kind == "sqlite":
        yield f"sqlite:///{folder / f'railval-{uuid.uuid4().hex[:8]}.db'}"
        return
    reason = _pg_unavailable()
    if reason is not None:
        if os.environ.get("RAILVAL_REQUIRE_PG") == "1":
            pytest.fail(f"RAILVAL_REQUIRE_PG=1 but {reason}")
        pytest.skip(reason)
    import psycopg

    schema = f"t_{uuid.uuid4().hex[:16]}"
    conninfo = PG_SERVER_URL.replace("postgresql+psycopg://", "postgresql://")
    with psycopg.connect(conninfo, autocommit=True) as conn:
        conn.execute(f'CREATE SCHEMA "{schema}"')
    sep = "&" if "?" in PG_SERVER_URL else "?"
    try:
        yield f"{PG_SERVER_URL}{sep}options=-csearch_path%3D{schema}"
    finally:
        with psycopg.connect(conninfo, autocommit=True) as conn:
            conn.execute(f'DROP SCHEMA IF EXISTS "{schema}" CASCADE')


@pytest.fixture(params=BACKENDS)
def db_url(request: pytest.FixtureRequest, tmp_path) -> Iterator[str]:
    """A URL of an empty database (one per test) on each backend."""
    with backend_url(request.param, tmp_path) as url:
        yield url


@pytest.fixture(scope="module", params=BACKENDS)
def module_db_url(request: pytest.FixtureRequest, tmp_path_factory) -> Iterator[str]:
    """Like ``db_url`` but one database per test module and backend (shared state)."""
    with backend_url(request.param, tmp_path_factory.mktemp("db")) as url:
        yield url


@pytest.fixture
def database(db_url: str):
    """A :class:`railval.db.engine.Database` on ``db_url``, migrated to the newest revision."""
    from railval.db.engine import connect

    db = connect(db_url)
    db.init()
    try:
        yield db
    finally:
        db.dispose()


@pytest.fixture
def sqlite_database(tmp_path):
    """An initialised SQLite-only database (for tests that need no backend matrix)."""
    from railval.db.engine import connect

    db = connect(f"sqlite:///{tmp_path / 'railval-sqlite.db'}")
    db.init()
    try:
        yield db
    finally:
        db.dispose()


@pytest.fixture(scope="session")
def demo_campaign_dir(tmp_path_factory):
    """A read-only demo campaign folder (12 sections, zones 1–4, baseline → variant1)."""
    from tests.factories import write_demo_campaign

    folder = tmp_path_factory.mktemp("demo-campaign")
    write_demo_campaign(folder, fmt="parquet", n_configs=2)
    return folder


@pytest.fixture(scope="session")
def browser_type_launch_args(browser_type_launch_args):
    """pytest-playwright's launch arguments pointed at Debian's Chromium (no browser download)."""
    from tests.browser_support import CHROMIUM, CHROMIUM_ARGS, require_browser

    require_browser()
    return {**browser_type_launch_args, "executable_path": CHROMIUM, "args": CHROMIUM_ARGS}
