"""Access ends at the next action in an open session (docs/security.md): the session's
state re-reads its user from the database through the real auth provider and cookie, on
SQLite and PostgreSQL. The browser version is ``tests/test_browser_revocation.py``."""

from __future__ import annotations

import functools
import time

from tornado.web import create_signed_value

from railval.app.auth import COOKIE, RailvalAuth
from railval.app.state.app import ACCESS_ENDED, ACCESS_RECHECK_S, AppState
from railval.app.state.backend import Backend
from railval.db import users

SECRET = "s" * 48


def session_for(database, username: str, *, max_age_s: int = 3600):
    auth = RailvalAuth(database, SECRET, max_age_s=max_age_s)
    with database.session(write=True) as s:
        sid = users.open_session(s, users.get_user(s, username), max_age_s=max_age_s)
    cookie = create_signed_value(SECRET, COOKIE, sid).decode()
    principal = auth.principal_from_cookie(cookie)
    assert principal is not None
    return AppState(Backend(database), principal=principal,
                    recheck=functools.partial(auth.principal_from_cookie, cookie))


def test_disable_password_role_and_expiry_end_open_sessions(database):
    with database.session(write=True) as s:
        for name in ("eng", "eng2", "rev"):
            users.create_user(s, name, password=f"{name} password",
                              roles=["reviewer"] if name == "rev" else ["engineer"])
    eng, eng2, rev = (session_for(database, n) for n in ("eng", "eng2", "rev"))
    expiring = session_for(database, "eng2", max_age_s=1)
    assert eng.guard("simulate") and eng2.guard("calibrate") and rev.guard("signoff.create")
    with database.session(write=True) as s:
        users.disable(s, "eng", actor="admin")
        users.set_password(s, "eng2", "a new password", actor="admin")
        users.set_roles(s, "rev", ["assessor"], actor="admin")
    # actions re-read the user at once
    assert not eng.guard("simulate") and eng.access_ended and eng.status == ACCESS_ENDED
    assert not eng2.guard("calibrate") and eng2.status == ACCESS_ENDED
    # a role change ends the session on the server as well (docs/security.md, "Sessions")
    assert not rev.guard("signoff.create") and rev.access_ended and rev.status == ACCESS_ENDED
    # an ended session stays ended, also for reads and after the user is enabled again
    with database.session(write=True) as s:
        users.enable(s, "eng", actor="admin")
    assert not eng.allowed("data.read") and not eng.page_allowed("overview")
    assert not eng.guard("data.read")
    # cookie expiry: reads notice it within ACCESS_RECHECK_S, actions at once
    time.sleep(1.1)
    assert not expiring.guard("data.read") and expiring.access_ended
    assert ACCESS_RECHECK_S <= 5


def test_reads_are_rechecked_within_a_few_seconds(database, monkeypatch):
    with database.session(write=True) as s:
        users.create_user(s, "eng", password="eng password", roles=["engineer"])
    app = session_for(database, "eng")
    assert app.page_allowed("dashboard")
    with database.session(write=True) as s:
        users.disable(s, "eng", actor="admin")
    assert app.page_allowed("dashboard")  # cached: read less than ACCESS_RECHECK_S ago
    monkeypatch.setattr(app, "_checked_at", time.monotonic() - ACCESS_RECHECK_S)
    assert not app.page_allowed("dashboard") and app.status == ACCESS_ENDED


def test_old_session_rows_are_deleted_when_the_user_signs_in_again(database):
    """The app_session table keeps the live sessions and SESSION_KEEP_DAYS of history: rows
    that expired or ended before that are deleted at the user's next sign-in, recent ones
    and other users' rows stay."""
    import datetime as dt

    from sqlalchemy import select, update

    from railval.db.models import AppSession, utcnow

    with database.session(write=True) as s:
        for name in ("old", "other"):
            users.create_user(s, name, password=f"{name} password", roles=["engineer"])
        ids = {k: users.open_session(s, users.get_user(s, n), max_age_s=3600)
               for k, n in (("expired", "old"), ("ended", "old"), ("recent", "old"),
                            ("other", "other"))}
        long_ago = utcnow() - dt.timedelta(days=users.SESSION_KEEP_DAYS + 1)
        s.execute(update(AppSession).where(AppSession.id_sha256 == users.session_hash(
            ids["expired"])).values(created_at=long_ago, expires_at=long_ago))
        s.execute(update(AppSession).where(AppSession.id_sha256.in_(
            [users.session_hash(ids[k]) for k in ("ended", "other")])).values(ended_at=long_ago))
    with database.session(write=True) as s:
        users.open_session(s, users.get_user(s, "old"), max_age_s=3600)
        kept = set(s.scalars(select(AppSession.id_sha256)))
    assert users.session_hash(ids["expired"]) not in kept
    assert users.session_hash(ids["ended"]) not in kept
    assert users.session_hash(ids["recent"]) in kept and users.session_hash(ids["other"]) in kept
    assert len(kept) == 3
