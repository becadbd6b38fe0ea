"""Read sessions the database keeps from writing, and one write door (SQLite and PostgreSQL).

Every unit of work not opened with ``write=True`` — ``Database.session()``,
``read_session()`` — is a read session: it runs with SQLite ``PRAGMA query_only = ON`` / a
PostgreSQL ``READ ONLY`` transaction, a write planted in it raises
:class:`railval.db.engine.WriteInReadSession` and stores nothing, and the pooled connection
carries no read-only state into the next write session. The services that write — the
diagnosis store, the overview's validation (result cache) and metrics (stored run), the
workshop cards and the sign-in — go through ``session(write=True)`` (``write_session()``,
``deferred=True`` for a computation that ends with a short write). The static half — no write
found in the body of a read session anywhere in the source — is
tests/test_architecture_write_door.py.
"""

from __future__ import annotations

import pytest
from sqlalchemy import func, insert, select, text

from railval.db import users
from railval.db.engine import WriteInReadSession
from railval.db.models import AppUser


def _user_count(database) -> int:
    with database.session() as s:
        return s.scalar(select(func.count()).select_from(AppUser))


def _read_only_flag(session, dialect: str) -> bool:
    if dialect == "sqlite":
        return bool(session.execute(text("PRAGMA query_only")).scalar())
    return session.execute(text("SHOW transaction_read_only")).scalar() == "on"


def test_a_write_planted_in_a_read_session_is_refused_by_the_database(database):
    before = _user_count(database)
    with pytest.raises(WriteInReadSession, match="write through session"):  # SQL insert
        with database.read_session() as s:
            s.execute(insert(AppUser).values(username="planted", display_name="x"))
    with pytest.raises(WriteInReadSession):  # an ORM object flushed at commit
        with database.read_session() as s:
            users.create_user(s, "planted2", roles=["engineer"])
    with pytest.raises(WriteInReadSession):  # the plain session() is a read session
        with database.session() as s:
            s.execute(insert(AppUser).values(username="planted3", display_name="x"))
    assert _user_count(database) == before


def test_pooled_connections_never_carry_read_only_into_a_write(database):
    dialect = database.dialect
    for _ in range(3):  # alternate on the same pooled connection(s)
        with database.read_session() as s:
            assert _read_only_flag(s, dialect) is True
        with database.session(write=True) as s:
            assert _read_only_flag(s, dialect) is False
            users.create_user(s, f"door{_}", roles=["engineer"])
        with database.session() as s:  # the plain unit of work reads only
            assert _read_only_flag(s, dialect) is True
        with database.write_session(deferred=True) as s:  # read, compute, short write
            assert _read_only_flag(s, dialect) is False
    # the engine's own connections (migrations, revision check) are not read-only either
    with database.read_session():
        pass
    database.init()
    assert _user_count(database) >= 3
    with pytest.raises(ValueError, match="write=True with it"):
        with database.session(deferred=True):
            pass


def test_overview_validation_metrics_and_cards_write_through_the_write_door(database, tmp_path):
    """Result cache filled, metrics run stored and workshop cards made with every plain
    session read-only."""
    from railval.app.services import overview, workshop_cards
    from railval.app.services import workshops as ws
    from railval.db import runs
    from railval.db.importer import import_campaign
    from railval.db.models import ResultCache
    from tests.factories import write_demo_campaign

    manifest = write_demo_campaign(tmp_path / "demo", n_sections=4, n_configs=1, name="demo")
    import_campaign(database, manifest.parent)
    ws.create(database, "PZ", "demo", sections=["S01", "S04"], kinds=["Y_time"], repeats=0.0)
    res = overview.validation(database, "demo", "baseline", n_boot=10)
    with database.session() as s:
        cached = s.scalar(select(func.count()).select_from(ResultCache))
    assert res is not None and cached > 0
    df = overview.metrics(database, "demo", "baseline")
    with database.session() as s:
        conf = overview.repo.get_configuration(s, "demo", "baseline")
        assert len(runs.list_runs(s, conf.id, "metrics")) == 1
    assert len(df) > 0
    doc = workshop_cards.cards(database, "PZ")
    assert doc["cards"] and all(c["en"] for c in doc["cards"])
    assert overview.campaign_names(database) == ["demo"]


def test_diagnosis_store_writes_through_the_write_door(database):
    from railval.app.services import diagnosis as diagnosis_service
    from railval.app.services.synth import synth

    synth(database, name="demo", template="coach", hidden=["conicity"], seed=1, n_sections=12)
    first = diagnosis_service.diagnose(database, "demo", "baseline", effects=["conicity"],
                                       values_per_parameter=2, workers=1)
    assert first.run["reused"] is False
    with database.session() as s:
        listed = diagnosis_service.diagnosis_runs(s, "demo", "baseline")
    assert [r["id"] for r in listed] == [first.run["id"]]


def test_sign_in_writes_through_the_write_door(database, monkeypatch):
    from railval.app.main import served
    from railval.db import audit
    from tests.test_login import SECRET, Client

    monkeypatch.setenv("RAILVAL_COOKIE_SECRET", SECRET)
    with database.session(write=True) as s:
        users.create_user(s, "eng", display_name="Eng One", password="engineer pw",
                          roles=["engineer"])
    with served(database) as url:
        c = Client(url.rsplit("/app", 1)[0])
        status, _body, final = c.post("/login", username="eng", password="wrong pw",
                                      next="/app")
        assert status == 401
        status, _body, final = c.post("/login", username="eng", password="engineer pw",
                                      next="/app")
        assert status == 200 and final.endswith("/app"), final
    with database.session() as s:
        actions = [r["action"] for r in audit.iter_rows(s)]
    assert "login.ok" in actions and "login.failed" in actions


@pytest.mark.parametrize("service", ["validation", "metrics"])
def test_a_computation_that_ends_with_a_cache_write_does_not_hold_the_write_lock(
        sqlite_database, monkeypatch, service):
    """The overview's validation and metrics read, compute and end with a short write (result
    cache, metrics run). On SQLite a unit of work opened with ``BEGIN IMMEDIATE`` would hold
    the database's write lock for the whole computation, and every reviewer's answer would
    wait behind it: a writer that starts while the computation runs must finish at once."""
    import threading
    import time

    from railval.app.services import metrics as metrics_service
    from railval.app.services import overview
    from railval.app.services import validation as validation_service

    def slow(session, *args, **kw):
        session.execute(text("SELECT count(*) FROM app_user")).scalar()
        started.set()
        time.sleep(0.8)  # the computation
        return "done"

    started = threading.Event()
    monkeypatch.setattr(validation_service, "validate_configuration", slow)
    monkeypatch.setattr(metrics_service, "metrics_for_configuration", slow)
    out = {}
    worker = threading.Thread(target=lambda: out.setdefault(
        "r", getattr(overview, service)(sqlite_database, "demo", "baseline")))
    worker.start()
    assert started.wait(10)
    t0 = time.perf_counter()
    with sqlite_database.session(write=True) as s:  # a reviewer's answer, say
        users.create_user(s, "answering", roles=["panelist"])
    waited = time.perf_counter() - t0
    worker.join(10)
    assert out["r"] == "done"
    assert waited < 0.5, f"the writer waited {waited:.2f} s for the {service} computation"
