"""Sign-in of the served app over HTTP: each refusal has a clear message and an audit row.

Real server (``railval.app.main.served``) on loopback, real HTTP requests (no browser:
the pages are plain forms). SQLite and PostgreSQL.
"""

from __future__ import annotations

import datetime as dt
import http.cookiejar
import re
import time
import urllib.error
import urllib.parse
import urllib.request

import pytest

from railval.app.auth import StartupRefused, check_startup, is_loopback
from railval.app.main import served
from railval.db import audit, users
from railval.db.models import Invitation

SECRET = "s" * 40


class Client:
    """A cookie-keeping HTTP client that never raises on 4xx (returns status, body)."""

    def __init__(self, base: str):
        self.base = base
        self.jar = http.cookiejar.CookieJar()
        self.opener = urllib.request.build_opener(urllib.request.HTTPCookieProcessor(self.jar))

    def get(self, path: str) -> tuple[int, str, str]:
        return self._open(urllib.request.Request(self.base + path))

    def post(self, path: str, *, forged: bool = False, **form: str) -> tuple[int, str, str]:
        """POST a form with the anti-forgery token the app's pages hand out for this
        client's session (as its own forms do); ``forged``: without it, as a page of
        another site would."""
        if not forged:
            form = {"_xsrf": self.xsrf(), **form}
        data = urllib.parse.urlencode(form).encode()
        return self._open(urllib.request.Request(self.base + path, data=data))

    def xsrf(self) -> str:
        """The anti-forgery token of this client's current session (or pre-session), as the
        sign-in page's form holds it."""
        _status, body, _ = self.get("/login")
        m = re.search(r'name="_xsrf" value="([^"]+)"', body)
        if m is None:
            raise AssertionError("the sign-in page holds no anti-forgery token")
        return m.group(1)

    def _open(self, req) -> tuple[int, str, str]:
        try:
            with self.opener.open(req, timeout=60) as r:
                return r.status, r.read().decode("utf-8", "replace"), r.geturl()
        except urllib.error.HTTPError as e:
            return e.code, e.read().decode("utf-8", "replace"), e.geturl()


@pytest.fixture
def server(database, monkeypatch):
    monkeypatch.setenv("RAILVAL_COOKIE_SECRET", SECRET)
    with database.session(write=True) as s:
        users.create_user(s, "eng", display_name="Eng One", password="engineer pw",
                          roles=["engineer"])
        users.create_user(s, "gone", password="disabled pw", roles=["engineer"])
        users.disable(s, "gone")
    with served(database) as url:
        yield database, url.rsplit("/app", 1)[0]


def rows(database, action):
    with database.session() as s:
        return list(audit.iter_rows(s, action=action))


def test_unauthenticated_request_is_sent_to_the_login_page(server):
    database, base = server
    status, body, final = Client(base).get("/app")
    assert status == 200 and "/login" in final and 'name="password"' in body


def test_right_password_signs_in_and_logout_ends_the_session(server):
    database, base = server
    c = Client(base)
    status, body, final = c.post("/login", username="eng", password="engineer pw", next="/app")
    assert status == 200 and final.endswith("/app"), final
    assert "railval" in body
    assert [r["object"] for r in rows(database, "login.ok")] == ["user:eng"]
    status, body, final = c.get("/logout")  # a link only asks to confirm
    assert status == 200 and 'id="signout"' in body and c.get("/app")[2].endswith("/app")
    assert c.post("/logout")[2].endswith("/login?out=1")
    assert "/login" in c.get("/app")[2]
    assert [r["actor"] for r in rows(database, "logout")] == ["eng"]


def test_wrong_password_is_refused_and_recorded(server):
    database, base = server
    status, body, _ = Client(base).post("/login", username="eng", password="guess")
    assert status == 401 and "Wrong user name or password." in body
    (row,) = rows(database, "login.failed")
    assert row["object"] == "user:eng" and row["detail"]["source"] == "127.0.0.1"


def test_disabled_user_is_refused_and_recorded(server):
    database, base = server
    status, body, _ = Client(base).post("/login", username="gone", password="disabled pw")
    assert status == 403 and "This account is disabled; ask an administrator." in body
    assert rows(database, "login.failed")[0]["reason"] == "account disabled"


def test_brute_force_hits_the_rate_limit(server):
    database, base = server
    c = Client(base)
    for i in range(users.MAX_FAILURES_PER_USER):
        assert c.post("/login", username="eng", password=f"guess {i}")[0] == 401
    status, body, _ = c.post("/login", username="eng", password="engineer pw")
    assert status == 429 and "Too many failed sign-ins; try again in 15 minutes." in body
    assert len(rows(database, "login.failed")) == users.MAX_FAILURES_PER_USER
    assert len(rows(database, "login.refused")) == 1


def test_invitation_single_use_and_expiry(server):
    database, base = server
    with database.session(write=True) as s:
        _inv, token = users.create_invitation(s, actor="eng")  # (to a workshop: test_invite_to_workshop)
        old, old_token = users.create_invitation(s, actor="eng")
        s.query(Invitation).filter_by(id=old.id).update(
            {"expires_at": dt.datetime.now(dt.UTC) - dt.timedelta(hours=1)})
    c = Client(base)
    status, body, _ = c.get(f"/invite?token={token}")
    assert status == 200 and "panelist" in body
    status, body, final = c.post("/invite", token=token, username="rev1", display_name="R. One",
                                 password="reviewer pw", password2="reviewer pw")
    # a panelist lands on their workshops (no app page is theirs)
    assert status == 200 and final.endswith("/workshops/mine") and "My workshops" in body
    status, body, _ = Client(base).get(f"/invite?token={token}")
    assert status == 403 and "already been used" in body
    status, body, _ = Client(base).post("/invite", token=token, username="rev2",
                                        password="reviewer pw", password2="reviewer pw")
    assert status == 403 and "already been used" in body
    status, body, _ = Client(base).get(f"/invite?token={old_token}")
    assert status == 403 and "expired" in body
    refused = rows(database, "invitation.refused")
    assert len(refused) == 3 and all(r["reason"] for r in refused)
    with database.session() as s:
        assert users.get_user(s, "rev1").role_names == ["panelist"]
        assert users.find_user(s, "rev2") is None


def test_session_ends_when_the_password_changes(server):
    database, base = server
    c = Client(base)
    c.post("/login", username="eng", password="engineer pw")
    assert c.get("/app")[2].endswith("/app")
    time.sleep(0.01)
    with database.session(write=True) as s:
        users.set_password(s, "eng", "a new password")
    assert "/login" in c.get("/app")[2]


def test_no_users_open_mode_on_loopback_only(db_url):
    from railval.db.engine import connect

    database = connect(db_url)
    database.init()
    assert is_loopback("127.0.0.1") and is_loopback("::1") and is_loopback("localhost")
    assert not is_loopback("0.0.0.0") and not is_loopback("192.168.1.5")
    assert check_startup(database, "127.0.0.1") is False
    with pytest.raises(StartupRefused, match="has no users.*railval user add NAME --role admin"):
        check_startup(database, "0.0.0.0")
    from railval.app.cli import main

    assert main(["--db", db_url, "serve", "--address", "0.0.0.0", "--no-demo"]) == 2
    with database.session(write=True) as s:
        users.create_user(s, "admin", password="admin password", roles=["admin"])
    assert check_startup(database, "0.0.0.0") is True
    database.dispose()


def test_behind_proxy_the_rate_limit_counts_the_forwarded_client(database, monkeypatch):
    monkeypatch.setenv("RAILVAL_COOKIE_SECRET", SECRET)
    with database.session(write=True) as s:
        users.create_user(s, "eng", password="engineer pw", roles=["engineer"])
    with served(database, behind_proxy=True) as url:
        c = Client(url.rsplit("/app", 1)[0])
        req = urllib.request.Request(c.base + "/login",
                                     data=f"username=eng&password=nope&_xsrf={c.xsrf()}".encode(),
                                     headers={"X-Forwarded-For": "203.0.113.7"})
        assert c._open(req)[0] == 401
    assert rows(database, "login.failed")[0]["detail"]["source"] == "203.0.113.7"


def test_session_cookie_expires_and_forged_cookies_are_refused(database):
    from tornado.web import create_signed_value

    from railval.app.auth import COOKIE, RailvalAuth
    from railval.db.models import AppSession

    with database.session(write=True) as s:
        user = users.create_user(s, "eng", password="engineer pw", roles=["engineer"])
        sid = users.open_session(s, user, max_age_s=60)
        old_sid = users.open_session(s, user, max_age_s=60)
        s.query(AppSession).filter_by(id_sha256=users.session_hash(old_sid)).update(
            {"expires_at": dt.datetime.now(dt.UTC) - dt.timedelta(seconds=1)})
    auth = RailvalAuth(database, SECRET, max_age_s=60)
    fresh = create_signed_value(SECRET, COOKIE, sid).decode()
    old = create_signed_value(SECRET, COOKIE, old_sid).decode()
    forged = create_signed_value("y" * 40, COOKIE, sid).decode()
    unknown = create_signed_value(SECRET, COOKIE, "not-a-session-of-this-server").decode()
    assert auth.principal_from_cookie(fresh).roles == frozenset({"engineer"})
    assert auth.principal_from_cookie(old) is None  # older than the session lifetime
    assert auth.principal_from_cookie(forged) is None  # signed with another secret
    assert auth.principal_from_cookie(unknown) is None  # signed, but no session on the server
    assert auth.principal_from_cookie(None) is None
    assert auth.principal_from_cookie(sid) is None  # unsigned


def test_app_sign_in_reaches_the_workshop_pages_with_their_role_check(server):
    """One sign-in for the whole server: a user signed in to the app opens the organiser
    pages without a second sign-in when the role allows it, and is refused (403) when not;
    after logout the workshop pages ask for a sign-in again."""
    database, base = server
    with database.session(write=True) as s:
        users.create_user(s, "org", password="organiser pw", roles=["organiser"])
    org = Client(base)
    assert org.post("/login", username="org", password="organiser pw", next="/app")[0] == 200
    status, body, final = org.get("/workshops")
    assert status == 200 and final.endswith("/workshops") and "Sign in" not in body
    eng = Client(base)
    assert eng.post("/login", username="eng", password="engineer pw", next="/app")[0] == 200
    status, body, _ = eng.get("/workshops/new")
    assert status == 403 and "may not open" in body
    org.post("/logout")
    status, body, final = org.get("/workshops")
    assert "/login?next=" in final and 'name="password"' in body
    # the workshop pages' sign-in is the app's
    assert Client(base).get("/workshops/login?next=/workshops")[2].endswith("/login?next=/workshops")


def test_an_empty_workshop_list_says_so_and_how_to_begin(server):
    """No workshop yet: the list page says so instead of an empty table, with the way to
    begin for an organiser (the button and the command) and who begins for an assessor."""
    database, base = server
    with database.session(write=True) as s:
        users.create_user(s, "org2", password="organiser pw", roles=["organiser"])
        users.create_user(s, "ass2", password="assessor pw", roles=["assessor"])
    org = Client(base)
    assert org.post("/login", username="org2", password="organiser pw", next="/workshops")[0] == 200
    status, body, _ = org.get("/workshops")
    assert status == 200 and "No workshop yet." in body and "<table" not in body
    assert "href='/workshops/new'" in body and "railval workshop create" in body
    ass = Client(base)
    assert ass.post("/login", username="ass2", password="assessor pw", next="/workshops")[0] == 200
    status, body, _ = ass.get("/workshops")
    assert status == 200 and "No workshop yet. An organiser creates them." in body
    assert "/workshops/new" not in body


def test_workshop_sign_in_ends_at_the_next_request_after_revocation(server):
    """The one sign-in's cookie on the workshop pages: a role removed refuses at the next request, a
    changed password or a disabled account sends the open session back to the sign-in."""
    database, base = server
    with database.session(write=True) as s:
        users.create_user(s, "org", password="organiser pw", roles=["organiser"])
        users.create_user(s, "org2", password="organiser2 pw", roles=["organiser"])
    org, org2 = Client(base), Client(base)
    assert org.post("/login", username="org", password="organiser pw", next="/workshops")[0] == 200
    assert org2.post("/login", username="org2", password="organiser2 pw",
                     next="/workshops")[0] == 200
    assert org.get("/workshops/new")[0] == 200 and org2.get("/workshops/new")[0] == 200
    with database.session(write=True) as s:
        users.set_roles(s, "org", ["engineer"], actor="admin")
        users.set_password(s, "org2", "another password", actor="admin")
    # a role change ends the session on the server too: sign in again, with the new roles
    status, body, final = org.get("/workshops/new")
    assert "/login?next=" in final and 'name="password"' in body
    status, body, final = org2.get("/workshops/new")
    assert "/login?next=" in final and 'name="password"' in body
    assert org.post("/login", username="org", password="organiser pw", next="/app")[0] == 200
    status, body, _ = org.get("/workshops/new")
    assert status == 403 and "may not open" in body
    with database.session(write=True) as s:
        users.set_roles(s, "org", ["organiser"], actor="admin")
    assert org.post("/login", username="org", password="organiser pw", next="/workshops")[0] == 200
    assert org.get("/workshops/new")[0] == 200
    with database.session(write=True) as s:
        users.disable(s, "org", actor="admin")
    status, body, final = org.get("/workshops/new")
    assert "/login?next=" in final
