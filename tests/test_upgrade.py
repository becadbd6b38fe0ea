"""Upgrade: a database written by the previous release (schema ``0006_signoff_review``, made
by ``tests/fixtures/make_release_db.py`` with that release's code) migrates to the newest
revision on start with nothing lost: signals and their seals, users, the sign-off (still
valid, not stale), workshop answers and the audit chain."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest
from sqlalchemy import select

FIXTURES = Path(__file__).resolve().parent / "fixtures"


@pytest.fixture
def release_db(tmp_path, monkeypatch):
    monkeypatch.delenv("RAILVAL_SECRET_KEY", raising=False)
    for name in ("release-0006.db", "release-0006.db.key"):
        shutil.copy(FIXTURES / name, tmp_path / name)
    return f"sqlite:///{tmp_path / 'release-0006.db'}"


def test_previous_release_database_migrates_on_start_with_nothing_lost(release_db, capsys):
    from railval.app.cli import main
    from railval.app.services import audit as audit_svc
    from railval.app.services.signoff import statuses
    from railval.db import repo, users
    from railval.db import workshops as wsdb
    from railval.db.engine import connect
    from railval.db.models import AuditEvent, Signal

    expected = json.loads((FIXTURES / "release-0006.json").read_text())
    db = connect(release_db)
    assert db.current_revision() == expected["revision"] == "0006_signoff_review"
    try:
        db.ensure_initialised(upgrade=True)  # what `railval serve` does on start
        assert db.current_revision() == db.head_revision()
        with db.write_session(deferred=True) as s:
            assert sorted(s.scalars(select(Signal.sha256)).all()) == expected["signal_hashes"]
            assert sorted(u.username for u in users.list_users(s)) == expected["users"]
            assert [c.name for c in repo.list_campaigns(s)] == expected["campaigns"]
            assert len(wsdb.answer_rows(s, wsdb.get_workshop(s, "W1"))) == expected["answers"]
            assert len(s.scalars(select(AuditEvent.id)).all()) >= expected["audit_events"]
            (_so, st), = statuses(s)
            assert st.valid, st.to_dict()
            assert repo.verify_storage(s)["ok"]
            assert users.verify_password(s, "rev", "reviewer password") is not None
        report = audit_svc.verify_database(db)
        assert report.ok and report.signoffs == 1, report.to_dict()
    finally:
        db.dispose()
    assert main(["--db", release_db, "--as", "ass", "verify", "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["ok"] is True
