"""One write door (docs/design.md §2): no write in the body of a read session anywhere in
``core/``, ``db/``, ``app/`` or ``tools/`` — counted statically by :mod:`tests.write_door`
(the database refuses such a write at run time, ``tests/test_read_only_sessions.py``; this
count finds it without running the code path). Each rule is checked against planted
violations in a temporary source tree.
"""

from __future__ import annotations

import textwrap
from pathlib import Path

from tests import write_door


def _planted(tmp_path: Path, files: dict[str, str]) -> list[str]:
    for rel, text in files.items():
        path = tmp_path / rel
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(textwrap.dedent(text), encoding="utf-8")
    modules = write_door.load(sorted(tmp_path.rglob("*.py")), tmp_path)
    return write_door.writes_in_read_sessions(modules)


DB_WRITER = {
    "db/__init__.py": "",
    "db/things.py": """
        from sqlalchemy import insert, text
        from sqlalchemy.orm import Session

        def add_thing(session: Session, name):
            session.add(name)

        def bump(s, key):
            stmt = insert(Thing).values(key=key)
            s.connection().execute(stmt)

        def wipe(s):
            s.execute(text("DELETE FROM thing"))

        def read_thing(session: Session, name):
            return session.get(Thing, name)

        def via(s, name):  # a writer by what it calls
            return add_thing(s, name)
        """,
}


def test_no_write_in_a_read_session():
    found = write_door.writes_in_read_sessions(write_door.source_modules())
    assert found == [], "writes in read sessions (open them with session(write=True)):\n" \
        + "\n".join(found)


def test_the_session_writers_are_found():
    writers = write_door.session_writers(write_door.source_modules())
    for name in ("railval.db.users.create_user", "railval.db.runs.store_run",
                 "railval.db.cache.cache_put_many", "railval.db.audit.record",
                 "railval.app.services.validation.validate_configuration"):
        assert name in writers, name
    for name in ("railval.db.users.get_user", "railval.db.cache.cache_get_many",
                 "railval.db.repo.get_configuration"):
        assert name not in writers, name


def test_a_write_planted_in_a_read_session_is_counted(tmp_path):
    found = _planted(tmp_path, {**DB_WRITER, "app/__init__.py": "", "app/svc.py": """
        from railval.db import things
        from railval.db.things import via

        def direct(database):
            with database.session() as s:
                s.add(object())

        def called(database):
            with database.read_session() as s:
                things.bump(s, "k")

        def transitive(database):
            with database.session(write=False) as s:
                via(s, "x")

        def sql_text(database):
            with database.session() as session:
                things.wipe(session)

        def bulk(database):
            with database.session() as s:
                s.query(Thing).filter_by(id=1).update({"x": 1})
        """})
    assert found == [
        "app/svc.py:11: railval.db.things.bump(s, …) in a read session",
        "app/svc.py:15: railval.db.things.via(s, …) in a read session",
        "app/svc.py:19: railval.db.things.wipe(session, …) in a read session",
        "app/svc.py:23: s.query(…).update(…) in a read session",
        "app/svc.py:7: s.add(…) in a read session",
    ]


def test_writes_through_the_write_door_and_reads_are_not_counted(tmp_path):
    found = _planted(tmp_path, {**DB_WRITER, "app/__init__.py": "", "app/svc.py": """
        from railval.db import things

        def door(database):
            with database.session(write=True) as s:
                things.add_thing(s, "x")
            with database.write_session(deferred=True) as s:
                things.bump(s, "k")
            with database.write_session() as s:
                s.add(object())

        def reads(database):
            with database.session() as s:
                names = set()
                names.add("x")  # a set, not the session
                return things.read_thing(s, "x")

        def nested(database):
            with database.session() as s:
                with database.session(write=True) as w:
                    things.add_thing(w, s.get(1))
        """})
    assert found == []
