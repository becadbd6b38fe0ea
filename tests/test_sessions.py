"""Sessions the server can end, anti-forgery tokens bound to the session and writes that
re-read the principal (docs/security.md, threat model), on SQLite and PostgreSQL.

Real served app (``railval.app.main.served``) on loopback and plain HTTP clients (no browser:
they send no ``Origin``, so the token alone decides; the browser attacks are in
``tests/test_browser_cookie_tossing.py``):

* a copied ``railval_session`` cookie is refused after ``POST /logout``, after the user is
  disabled, after a password change and after a role change — on page loads and on ``POST``;
* a ``POST`` carrying the victim's session cookie with a tossed ``_xsrf`` cookie and the same
  value as token (Tornado's double-submit), or with the attacker's own pre-session cookie and
  token, is refused on every state-changing endpoint; nothing changes;
* a disabled panelist's next answer is refused from the commit of the disable on, also while
  the disable is in progress (the answer waits for it, then is refused).
"""

from __future__ import annotations

import http.cookiejar
import json
import re
import threading
import time
import urllib.error
import urllib.parse
import urllib.request

import pytest
from sqlalchemy import func, select

from railval.app.main import served
from railval.db import audit, users
from railval.db import workshops as wsdb
from railval.db.models import AppSession, Campaign, WorkshopAnswer

SECRET = "t" * 48


class Client:
    """A cookie-keeping HTTP client that never raises on 4xx and never follows a redirect
    (returns status, body, Location)."""

    class _NoRedirect(urllib.request.HTTPRedirectHandler):
        def redirect_request(self, *args, **kwargs):
            return None

    def __init__(self, base: str):
        self.base = base
        self.jar = http.cookiejar.CookieJar()
        self.opener = urllib.request.build_opener(urllib.request.HTTPCookieProcessor(self.jar),
                                                  self._NoRedirect)

    def cookie(self, name: str) -> str | None:
        return next((c.value for c in self.jar if c.name == name), None)

    def request(self, path: str, data: bytes | None = None, *,
                headers: dict[str, str] | None = None, jar: bool = True) -> tuple[int, str, str]:
        req = urllib.request.Request(self.base + path, data=data, headers=headers or {})
        opener = self.opener if jar else urllib.request.build_opener(self._NoRedirect)
        try:
            with opener.open(req, timeout=60) as r:
                return r.status, r.read().decode("utf-8", "replace"), ""
        except urllib.error.HTTPError as e:
            return e.code, e.read().decode("utf-8", "replace"), e.headers.get("Location", "")

    def token(self, path: str = "/login") -> str:
        """The anti-forgery token the page at ``path`` hands out to this client."""
        body = self.request(path)[1]
        m = re.search(r'name="_xsrf" value="([^"]+)"', body) or re.search(
            r'name="xsrf-token" content="([^"]+)"', body)
        assert m, f"{path} holds no anti-forgery token"
        return m.group(1)

    def post(self, path: str, form: dict[str, str], token: str | None = None):
        form = {"_xsrf": token if token is not None else self.token(), **form}
        return self.request(path, urllib.parse.urlencode(form).encode())

    def sign_in(self, username: str, password: str) -> None:
        status, _, location = self.post("/login", {"username": username, "password": password,
                                                   "next": "/app"})
        assert status == 302 and self.cookie("railval_session"), (status, location)


def raw_cookie_get(base: str, path: str, cookie: str) -> tuple[int, str]:
    """GET ``path`` with nothing but ``Cookie: railval_session=<cookie>`` → (status,
    Location): 200 when the session is accepted, a redirect to the sign-in otherwise."""
    c = Client(base)
    status, _, location = c.request(path, headers={"Cookie": f"railval_session={cookie}"},
                                    jar=False)
    return status, location


def _workshop(database) -> str:
    with database.session(write=True) as s:
        camp = Campaign(name="c")
        s.add(camp)
        s.flush()
        plots = [{"kind": "Y_time", "section": "S01", "configuration": "base",
                  "channel": f"Y_w{i}L", "render": {"i": i}, "image": b"\x89PNG fake %d" % i}
                 for i in range(4)]
        w = wsdb.create_workshop(s, "W", camp.id, blind=False, repeat_share=0.0, auto_share=0.0,
                                 settings={}, scales={}, plots=plots)
        users.create_user(s, "pan", password="panelist pw", roles=["panelist"])
        return wsdb.invite(s, w, "pan", seed=1)


@pytest.fixture
def server(database, monkeypatch):
    monkeypatch.setenv("RAILVAL_COOKIE_SECRET", SECRET)
    with database.session(write=True) as s:
        for name in ("org", "org2", "org3", "org4"):
            users.create_user(s, name, password=f"{name} password", roles=["organiser"])
    token = _workshop(database)
    with served(database) as url:
        yield database, url.rsplit("/app", 1)[0], token


def _snapshot(database) -> dict:
    from railval.db.models import AppUser, Workshop, WorkshopReviewer

    with database.session() as s:
        return {"audit": audit.count(s),
                "users": s.scalar(select(func.count()).select_from(AppUser)),
                "sessions": sorted(s.execute(select(AppSession.id, AppSession.ended_at)).all()),
                "status": sorted(s.execute(select(Workshop.name, Workshop.status)).all()),
                "links": sorted(map(str, s.scalars(select(WorkshopReviewer.token_sha256)))),
                "answers": s.scalar(select(func.count()).select_from(WorkshopAnswer))}


# ----------------------------------------------------------------- copied cookies
def test_copied_cookie_is_refused_after_sign_out_disable_password_and_role_change(server):
    database, base, _token = server
    clients = {name: Client(base) for name in ("org", "org2", "org3", "org4")}
    copies = {}
    for name, c in clients.items():
        c.sign_in(name, f"{name} password")
        copies[name] = c.cookie("railval_session")
        assert raw_cookie_get(base, "/workshops", copies[name])[0] == 200
        assert raw_cookie_get(base, "/app", copies[name])[0] == 200
    # a token copied along with the cookie (from the page): accepted while the session lives
    stolen_token = clients["org"].token("/workshops/W")
    status, _, _ = clients["org"].post("/logout", {})
    assert status == 302
    with database.session(write=True) as s:
        users.disable(s, "org2", actor="admin")
        users.set_password(s, "org3", "a new password", actor="admin")
        users.set_roles(s, "org4", ["organiser", "engineer"], actor="admin")
    for name, why in (("org", "logout"), ("org2", "user.disable"), ("org3", "user.password"),
                      ("org4", "user.roles")):
        for path in ("/workshops", "/app", "/workshops/W"):
            status, location = raw_cookie_get(base, path, copies[name])
            assert status == 302 and "login?next=" in location, (name, path, status, location)
        with database.session() as s:
            row = s.scalar(select(AppSession).where(
                AppSession.id_sha256 == users.session_hash(_session_id(copies[name]))))
            assert row is not None and row.ended_at is not None and row.end_reason == why
    # the copied cookie with the copied token cannot write either
    before = _snapshot(database)
    data = urllib.parse.urlencode({"_xsrf": stolen_token, "status": "close"}).encode()
    status, _, location = Client(base).request(
        "/workshops/W/status", data, headers={"Cookie": f"railval_session={copies['org']}"},
        jar=False)
    assert status in (302, 403) and (status == 403 or "login?next=" in location)
    assert _snapshot(database) == before
    # the user signs in again: a new session, the old copy stays refused
    clients["org"].sign_in("org", "org password")
    assert clients["org"].request("/workshops")[0] == 200
    assert raw_cookie_get(base, "/workshops", copies["org"])[0] == 302


def _session_id(cookie: str) -> str:
    from tornado.web import decode_signed_value

    return decode_signed_value(SECRET, "railval_session", cookie.strip('"'),
                               max_age_days=1).decode()


# ----------------------------------------------------------------- bound tokens
def test_tossed_or_foreign_tokens_are_refused_on_every_endpoint(server):
    """No ``Origin`` header (not a browser): the token decides. The victim's session cookie
    goes along; the attacker adds a ``_xsrf`` cookie of their choosing and the same value as
    token (what defeats Tornado's double-submit), or their own signed pre-session cookie and
    its token (obtained from the server's sign-in page)."""
    database, base, token = server
    victim = Client(base)
    victim.sign_in("org", "org password")
    session = victim.cookie("railval_session")
    attacker = Client(base)
    pre_token = attacker.token("/login")
    pre_cookie = attacker.cookie("railval_presession")
    assert pre_cookie and pre_token
    endpoints = {
        "/workshops/W/status": {"status": "close"},
        "/workshops/W/invite": {"reviewer": "mallory"},
        "/workshops/new": {"name": "EVIL", "campaign": "c"},
        "/workshops/W": {"status": "close"},
        "/workshops/mine/W/open": {},
        "/logout": {},
        "/login": {"username": "org2", "password": "org2 password"},
        "/invite": {"token": "x" * 43, "username": "mallory", "password": "mallory pw",
                    "password2": "mallory pw"},
    }
    before = _snapshot(database)
    for path, form in endpoints.items():
        for cookies, tok in ((f"railval_session={session}; _xsrf=tossed1234", "tossed1234"),
                             (f"railval_session={session}; railval_presession={pre_cookie}; "
                              f"_xsrf={pre_token}", pre_token)):
            data = urllib.parse.urlencode({"_xsrf": tok, **form}).encode()
            status, body, _ = Client(base).request(path, data, headers={"Cookie": cookies},
                                                    jar=False)
            assert status == 403, (path, cookies, status, body[:200])
    # the review link's JSON endpoints with the token in the query (a no-cors fetch cannot
    # set headers); they act on the link's authority, so a pre-session token is theirs too —
    # against a browser the origin check stops the tossed one (the Chromium test)
    body = json.dumps({"position": 0, "answer": "yes", "seconds": 1}).encode()
    for path in (f"/review/{token}/answer", f"/review/{token}/finish"):
        status, _, _ = Client(base).request(
            f"{path}?_xsrf=tossed1234", body,
            headers={"Cookie": f"railval_session={session}; _xsrf=tossed1234",
                     "Content-Type": "application/json"}, jar=False)
        assert status == 403, path
    assert _snapshot(database) == before
    # the victim's own token still works: the forged requests changed nothing
    assert victim.post("/workshops/W/status", {"status": "close"},
                       token=victim.token("/workshops/W"))[0] == 302
    with database.session() as s:
        assert wsdb.get_workshop(s, "W").status == "closed"


def test_browser_origin_of_another_port_is_refused_even_with_a_valid_token(server):
    database, base, _token = server
    victim = Client(base)
    victim.sign_in("org", "org password")
    tok = victim.token("/workshops/W")
    before = _snapshot(database)
    port = int(base.rsplit(":", 1)[1])
    data = urllib.parse.urlencode({"_xsrf": tok, "status": "close"}).encode()
    for headers in ({"Origin": f"http://127.0.0.1:{port + 1}"}, {"Sec-Fetch-Site": "same-site"},
                    {"Origin": "null"}, {"Sec-Fetch-Site": "cross-site"}):
        assert victim.request("/workshops/W/status", data, headers=headers)[0] == 403, headers
    assert _snapshot(database) == before
    ok = {"Origin": base, "Sec-Fetch-Site": "same-origin"}
    assert victim.request("/workshops/W/status", data, headers=ok)[0] == 302


# ----------------------------------------------------------------- disabled panelist
def _answer(base: str, token: str, position: int, answer: str) -> tuple[int, dict]:
    c = Client(base)
    tok = c.token(f"/review/{token}")
    body = json.dumps({"position": position, "answer": answer, "seconds": 1.0,
                       "submission": f"s{position}{answer}"}).encode()
    status, raw, _ = c.request(f"/review/{token}/answer", body,
                               headers={"Content-Type": "application/json", "X-XSRFToken": tok})
    return status, json.loads(raw)


def test_disabled_panelists_next_answer_is_refused(server):
    database, base, token = server
    status, doc = _answer(base, token, 0, "yes")
    assert status == 200 and doc["stored"] == "new"
    with database.session(write=True) as s:
        users.disable(s, "pan", actor="admin")
    # at once: the link's cached context still names an enabled panelist, the write does not
    status, doc = _answer(base, token, 1, "no")
    assert status == 403 and "disabled" in doc["error"]
    with database.session() as s:
        assert s.scalar(select(func.count()).select_from(WorkshopAnswer)) == 1


def test_answer_during_a_disable_waits_for_it_and_is_refused(database):
    """The disable holds the user's row (``FOR UPDATE`` on PostgreSQL, the write lock on
    SQLite) until it commits; the answer's write transaction reads the user ``FOR SHARE``
    and so waits, then sees the disable: refused, nothing stored."""
    token = _workshop(database)
    with database.session() as s:
        ctx = wsdb.reviewer_by_token(s, token)
    outcome: list[object] = []

    def answer() -> None:
        try:
            with database.session(write=True) as s:
                outcome.append(wsdb.record_answer(s, ctx, 0, True, seconds=1.0))
        except Exception as exc:  # noqa: BLE001 - checked below
            outcome.append(exc)

    with database.session(write=True) as s:
        users.disable(s, "pan", actor="admin")
        th = threading.Thread(target=answer)
        th.start()
        time.sleep(0.8)
        assert th.is_alive() and not outcome  # waiting for the disable's commit
    th.join(30)
    from railval.core.roles import PermissionDenied

    assert len(outcome) == 1 and isinstance(outcome[0], PermissionDenied), outcome
    with database.session() as s:
        assert s.scalar(select(func.count()).select_from(WorkshopAnswer)) == 0
    # an answer whose transaction committed first is kept; the next one is refused
    with database.session(write=True) as s:
        users.enable(s, "pan", actor="admin")
    with database.session(write=True) as s:
        assert wsdb.record_answer(s, ctx, 0, True, seconds=1.0) == "new"
    with database.session(write=True) as s:
        users.disable(s, "pan", actor="admin")
    with pytest.raises(PermissionDenied), database.session(write=True) as s:
        wsdb.record_answer(s, ctx, 1, True, seconds=1.0)


def test_a_change_reports_the_answer_it_replaced(database):
    token = _workshop(database)
    with database.session() as s:
        ctx = wsdb.reviewer_by_token(s, token)
    with database.session(write=True) as s:
        first = wsdb.record_answer(s, ctx, 2, True, seconds=1.0, submission="tabA")
    assert first == "new" and first.previous is None
    with database.session(write=True) as s:
        second = wsdb.record_answer(s, ctx, 2, False, seconds=1.0, submission="tabB")
    assert second == "changed" and second.previous is True and second.previous_at is not None
    with database.session() as s:
        row = s.scalar(select(WorkshopAnswer).where(WorkshopAnswer.position == 2))
        assert row.answer is False and row.changes == 1
