"""Engine, unit of work and migrations on SQLite and PostgreSQL."""

from __future__ import annotations

import pytest
from alembic.autogenerate import compare_metadata
from alembic.migration import MigrationContext
from sqlalchemy import text
from sqlalchemy.exc import IntegrityError

from railval.core.errors import RailvalError
from railval.db import codec
from railval.db.engine import DatabaseNotInitialised, connect, resolve_url
from railval.db.models import (
    SQLITE_ONLY_INDEXES,
    Base,
    Campaign,
    Configuration,
    Recording,
    Section,
)


def test_upgrade_to_head_matches_the_models(database):
    assert database.current_revision() == database.head_revision()
    with database.engine.connect() as conn:
        diff = compare_metadata(MigrationContext.configure(
            conn, opts={"compare_type": True, "include_name": _declared}), Base.metadata)
    assert diff == []
    if database.engine.dialect.name == "sqlite":  # the SQLite-only covering index exists
        with database.engine.connect() as conn:
            names = {r[0] for r in conn.exec_driver_sql(
                "SELECT name FROM sqlite_master WHERE type = 'index'")}
        assert SQLITE_ONLY_INDEXES <= names


def _declared(name, type_, _parent) -> bool:
    """The model comparison leaves out the indexes made on SQLite only by a migration."""
    return not (type_ == "index" and name in SQLITE_ONLY_INDEXES)


def test_init_is_idempotent(database):
    with database.session(write=True) as s:
        s.add(Campaign(name="kept", manifest={}))
    assert database.init() == database.head_revision()
    with database.session() as s:
        assert s.query(Campaign).count() == 1


def test_ensure_initialised(db_url):
    database = connect(db_url)
    with pytest.raises(DatabaseNotInitialised, match="railval init"):
        database.ensure_initialised()
    database.ensure_initialised(upgrade=True)
    assert database.current_revision() == database.head_revision()
    connect(db_url).ensure_initialised()  # a second connection sees the migrated schema
    database.dispose()


def test_session_commits_or_rolls_back(database):
    with pytest.raises(ZeroDivisionError), database.session(write=True) as s:
        s.add(Campaign(name="lost", manifest={}))
        s.flush()
        _ = 1 / 0
    with database.session(write=True) as s:
        s.add(Campaign(name="stored", manifest={}))
    with database.session() as s:
        assert [c.name for c in s.query(Campaign)] == ["stored"]


def test_foreign_keys_and_cascades_are_enforced(database):
    with pytest.raises(IntegrityError), database.session(write=True) as s:
        s.add(Section(campaign_id=999, section_id="S1", speed_kmh=100, eval_start_m=0,
                      eval_end_m=1))
        s.flush()
    blob, sha = codec.encode(codec.np.arange(3.0))
    with database.session(write=True) as s:
        c = Campaign(name="c", manifest={})
        sec = Section(section_id="S1", speed_kmh=100, eval_start_m=0, eval_end_m=1)
        c.sections.append(sec)
        s.add(c)
        s.add(Recording(section=sec, fs=1.0, n=3, distance_blob=blob, distance_sha256=sha))
    with database.session(write=True) as s:  # deleting the campaign at the SQL level cascades
        s.execute(text("DELETE FROM campaign"))
    with database.session() as s:
        assert s.query(Section).count() == 0 and s.query(Recording).count() == 0


def test_one_measurement_per_section(database):
    blob, sha = codec.encode(codec.np.arange(3.0))
    with database.session(write=True) as s:
        c = Campaign(name="c", manifest={})
        sec = Section(section_id="S1", speed_kmh=100, eval_start_m=0, eval_end_m=1)
        conf = Configuration(name="sim")
        c.sections.append(sec)
        c.configurations.append(conf)
        s.add(c)
        s.add(Recording(section=sec, fs=1.0, n=3, distance_blob=blob, distance_sha256=sha))
        s.add(Recording(section=sec, configuration=conf, fs=1.0, n=3, distance_blob=blob,
                        distance_sha256=sha))
    with pytest.raises(IntegrityError), database.session(write=True) as s:
        sec = s.query(Section).one()
        s.add(Recording(section=sec, fs=1.0, n=3, distance_blob=blob, distance_sha256=sha))
        s.flush()


def test_sqlite_pragmas(tmp_path):
    database = connect(f"sqlite:///{tmp_path / 'p.db'}")
    with database.engine.connect() as conn:
        assert conn.exec_driver_sql("PRAGMA journal_mode").scalar() == "wal"
        assert conn.exec_driver_sql("PRAGMA foreign_keys").scalar() == 1
        assert conn.exec_driver_sql("PRAGMA busy_timeout").scalar() == 30000
    database.dispose()


def test_sqlite_ddl_is_transactional(tmp_path):
    database = connect(f"sqlite:///{tmp_path / 't.db'}")
    with pytest.raises(RuntimeError), database.engine.begin() as conn:
        conn.exec_driver_sql("CREATE TABLE x (a INTEGER)")
        raise RuntimeError("abort")
    with database.engine.connect() as conn:
        names = conn.exec_driver_sql("SELECT name FROM sqlite_master WHERE type='table'").all()
    assert names == []
    database.dispose()


def test_in_memory_sqlite_shares_one_database():
    database = connect("sqlite://")
    database.init()
    with database.session(write=True) as s:
        s.add(Campaign(name="m", manifest={}))
    with database.session() as s:
        assert s.query(Campaign).count() == 1


def test_resolve_url(monkeypatch):
    monkeypatch.delenv("RAILVAL_DB", raising=False)
    assert resolve_url() == "sqlite:///railval.db"
    monkeypatch.setenv("RAILVAL_DB", "postgresql://u@h/db")
    assert resolve_url() == "postgresql+psycopg://u@h/db"
    assert resolve_url("sqlite:///x.db") == "sqlite:///x.db"
    with pytest.raises(RailvalError, match="unsupported backend"):
        connect("mysql://u@h/db")


def test_migration_file_names_follow_the_revision_chain():
    """The files of db/migrations/versions, sorted by name, are the chain from base to head:
    a reader who opens them in name order reads the schema's history in the order it runs."""
    import importlib.util
    from pathlib import Path

    folder = Path(__file__).resolve().parents[1] / "db" / "migrations" / "versions"
    files = sorted(p for p in folder.glob("[0-9][0-9][0-9][0-9]_*.py"))
    revisions = {}
    for path in files:
        spec = importlib.util.spec_from_file_location(path.stem, path)
        module = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(module)
        revisions[path.name] = (module.revision, module.down_revision)
    chain, parent = [], None
    by_parent = {down: (name, rev) for name, (rev, down) in revisions.items()}
    assert len(by_parent) == len(revisions), "two migrations revise the same parent"
    while parent in by_parent:
        name, parent = by_parent[parent]
        chain.append(name)
    assert chain == [p.name for p in files]
