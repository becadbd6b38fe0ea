"""The services are the door to the database (docs/design.md §2): every unit of work that
writes is opened as one (on SQLite: ``BEGIN IMMEDIATE``, the write lock taken at the start),
reads stay deferred; the audit page's rows come from one limited, ordered query."""

from __future__ import annotations

import pytest
from railval.app.services import audit as audit_service
from railval.app.services import users as user_service
from railval.app.services import workshop_admin, workshop_review
from railval.db import audit
from railval.db import workshops as wsdb
from railval.db.models import Campaign
from sqlalchemy import event


@pytest.fixture
def begins(sqlite_database):
    """The BEGIN statements SQLite receives, in order (a listener on the real engine)."""
    seen: list[str] = []

    def listen(_conn, _cursor, statement, *_args) -> None:
        if statement.upper().startswith("BEGIN"):
            seen.append(statement.upper())

    event.listen(sqlite_database.engine, "before_cursor_execute", listen)
    yield seen
    event.remove(sqlite_database.engine, "before_cursor_execute", listen)


def _workshop(database) -> str:
    with database.session(write=True) as s:
        camp = Campaign(name="c")
        s.add(camp)
        s.flush()
        plots = [{"kind": "Y_time", "section": "S01", "configuration": "base",
                  "channel": f"Y_w{i}L", "render": {"i": i}, "image": b"\x89PNG fake %d" % i}
                 for i in range(3)]
        w = wsdb.create_workshop(s, "W", camp.id, blind=False, repeat_share=0.0, auto_share=0.0,
                                 settings={}, scales={}, plots=plots)
        return wsdb.invite(s, w, "alice", seed=1)


def test_writes_take_the_write_lock_and_reads_do_not(sqlite_database, begins):
    db = sqlite_database
    token = _workshop(db)
    begins.clear()
    ctx = workshop_review.context(db, token)
    assert begins == ["BEGIN"]
    assert workshop_review.record_answer(db, ctx, 0, True, seconds=1.5) == "new"
    assert begins[-1] == "BEGIN IMMEDIATE"
    stored = workshop_review.answers(db, ctx.reviewer_id)
    assert list(stored) == [0] and stored[0]["answer"] is True and stored[0]["comment"] == ""
    assert stored[0]["changes"] == 0 and stored[0]["updated_at"].endswith("Z")
    assert begins[-1] == "BEGIN"
    assert workshop_admin.set_status(db, "W", "closed", actor="org") == "closed"
    assert begins[-1] == "BEGIN IMMEDIATE"
    with pytest.raises(workshop_review.WorkshopClosed):
        workshop_review.record_answer(db, ctx, 1, False, seconds=1.0)
    assert workshop_admin.invite(db, "W", "bob", actor="org")
    assert begins[-1] == "BEGIN IMMEDIATE"
    assert user_service.add(db, "carol", password=None, roles=["panelist"]) == ("carol", ["panelist"])
    assert begins[-1] == "BEGIN IMMEDIATE"
    ok, message = user_service.sign_in(db, "carol", "wrong password 123")
    assert not ok and message and begins[-1] == "BEGIN IMMEDIATE"
    seq, _h, _n = audit_service.seal(db, "org", "test")
    assert seq >= 1 and begins[-1] == "BEGIN IMMEDIATE"
    n_before = len(begins)
    assert [r["username"] for r in user_service.rows(db)] == ["alice", "bob", "carol"]
    assert begins[n_before:] == ["BEGIN"]


def test_newest_audit_rows_are_one_limited_ordered_query(database):
    for i in range(7):
        with database.session(write=True) as s:
            audit.record(s, "tester", "test.event", f"thing:{i}")
    rows, total = audit_service.newest(database, 3)
    with database.session() as s:
        every = list(audit.iter_rows(s))
    assert total == len(every) >= 7
    assert [r["seq"] for r in rows] == [r["seq"] for r in reversed(every)][:3]
    assert [r["object"] for r in rows] == ["thing:6", "thing:5", "thing:4"]
    assert audit_service.newest(database, 0) == ([], total)
    assert [r["seq"] for r in audit_service.newest(database, 1000)[0]] == [r["seq"] for r in reversed(every)]
