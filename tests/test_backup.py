"""Backup → empty database → restore (db/backup.py, ``railval backup`` / ``restore``): signal
hashes and seals, evidence hashes, the audit chain and sign-offs intact, on both backends."""

from __future__ import annotations

import json
import uuid

import pytest
from sqlalchemy import select
from sqlalchemy.engine import make_url

from railval.app.cli import main
from railval.db.engine import connect


def _state(db) -> dict:
    from railval.app.services.signoff import statuses
    from railval.db.models import Signal, Signoff

    with db.write_session(deferred=True) as s:
        return {"signals": sorted(s.scalars(select(Signal.sha256)).all()),
                "evidence": sorted(s.scalars(select(Signoff.evidence_sha256)).all()),
                "valid": [st.valid for _, st in statuses(s)]}


@pytest.fixture
def target_url(db_url, tmp_path):
    """An empty database of the same backend: a new SQLite file; a new PostgreSQL database
    whose search path names the source's schema (pg_dump keeps schema names)."""
    if db_url.startswith("sqlite"):
        yield f"sqlite:///{tmp_path / 'restored.db'}"
        return
    import psycopg

    url = make_url(db_url)
    name = f"restore_{uuid.uuid4().hex[:10]}"
    admin = url.set(drivername="postgresql", query={}).render_as_string(hide_password=False)
    with psycopg.connect(admin, autocommit=True) as conn:
        conn.execute(f'CREATE DATABASE "{name}"')
    try:
        yield url.set(database=name).render_as_string(hide_password=False)
    finally:
        with psycopg.connect(admin, autocommit=True) as conn:
            conn.execute(f'DROP DATABASE IF EXISTS "{name}" WITH (FORCE)')


def test_backup_then_restore_into_empty_database(db_url, target_url, tmp_path, capsys):
    from railval.app.services import audit as audit_svc
    from railval.app.services.signoff import sign
    from railval.db import users
    from railval.db.importer import import_campaign
    from tests.factories import write_demo_campaign

    db = connect(db_url)
    db.init()
    write_demo_campaign(tmp_path / "demo", n_sections=4, fs=50.0, n_configs=1)
    db.actor = "eng"
    import_campaign(db, tmp_path / "demo")
    with db.session(actor="adm", write=True) as s:
        users.create_user(s, "adm", password="admin password 1", roles=["admin"])
        users.create_user(s, "rev", password="reviewer password", roles=["reviewer"])
    sign(db, "rev", "reviewer password", "demo", "baseline", decision="validated", statement="ok",
         justification="Accepted for the straight-track zones; the curve results are known.")
    before = _state(db)
    db.dispose()
    bk = tmp_path / "backup"
    assert main(["--db", db_url, "--as", "adm", "backup", str(bk), "--json"]) == 0
    manifest = json.loads(capsys.readouterr().out)
    assert (bk / "secret.key").stat().st_mode & 0o777 == 0o600
    # the signing key and the witness travel with it: the restored trail verifies against
    # the same key and the same signed heads
    assert (bk / "signing-key.pem").stat().st_mode & 0o777 == 0o600
    assert {"signing-key.pem", "witness.jsonl"} <= set(manifest["files"])
    assert manifest["signals"] == len(before["signals"]) > 0
    # a non-empty target is refused, nothing written
    assert main(["--db", db_url, "restore", str(bk)]) != 0
    assert "not empty" in capsys.readouterr().err

    assert main(["--db", target_url, "restore", str(bk), "--json"]) == 0
    done = json.loads(capsys.readouterr().out)
    assert done["audit_head"]["seq"] == manifest["audit_head"]["seq"]
    restored = connect(target_url)
    try:
        after = _state(restored)
        assert after == before and all(after["valid"]) and after["evidence"]
        report = audit_svc.verify_database(restored)
        assert report.ok and report.signoffs == 1, report.to_dict()
    finally:
        restored.dispose()
    assert main(["--db", target_url, "--as", "adm", "verify", "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["ok"] is True
    assert main(["--db", target_url, "--as", "adm", "audit", "verify"]) == 0


def test_damaged_backup_is_refused(sqlite_database, tmp_path):
    from railval.db.backup import BackupError, backup, restore

    bk = tmp_path / "bk"
    backup(sqlite_database, bk)
    with (bk / "database.sqlite").open("ab") as fh:
        fh.write(b"x")
    target = connect(f"sqlite:///{tmp_path / 'r.db'}")
    with pytest.raises(BackupError, match="database.sqlite: SHA-256 differs"):
        restore(target, bk)
    assert not (tmp_path / "r.db.key").exists()
