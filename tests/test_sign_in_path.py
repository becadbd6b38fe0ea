"""The one sign-in path (docs/security.md, "Sign-in for railval serve"): one open-mode rule
for the app and the workshop pages, and the argon2 hash verified outside the write
transaction without opening a race (``app/services/sessions.py``, ``db/users.py``).

Real parts: SQLite files and the PostgreSQL server, the served app over HTTP, real argon2id
hashes (the hasher is only slowed down to make the timing visible).
"""

from __future__ import annotations

import threading
import time
import urllib.request

import pytest

from railval.app.auth import is_local_request
from railval.app.main import served
from railval.app.services import sessions
from railval.app.services.users import cookie_principal
from railval.db import audit, users
from tests.test_login import SECRET, Client


def _web_open(base: str, *, proxied: bool = False) -> tuple[bool, bool]:
    """(app open without sign-in, workshop pages open without sign-in) for a fresh client on
    the loopback; ``proxied``: the request carries X-Forwarded-For as through a proxy."""
    c = Client(base)
    out = []
    for path in ("/app", "/workshops"):
        req = urllib.request.Request(base + path)
        if proxied:
            req.add_header("X-Forwarded-For", "203.0.113.9")
        status, _body, url = c._open(req)
        out.append(status == 200 and "login" not in url)
    return out[0], out[1]


def test_one_open_mode_rule_for_the_service_the_app_and_the_workshop_pages(database, monkeypatch):
    """No users → open on loopback only; a user without a password (nobody can sign in) → still
    open on loopback only; a user with a password → sign-in required everywhere, at once (no
    restart)."""
    monkeypatch.setenv("RAILVAL_COOKIE_SECRET", SECRET)
    with served(database) as url:
        base = url.rsplit("/app", 1)[0]
        # no users
        assert sessions.is_open(database, True) and not sessions.is_open(database, False)
        assert cookie_principal(database, None, True).open_mode
        assert cookie_principal(database, None, False) is None
        assert _web_open(base) == (True, True)
        assert _web_open(base, proxied=True) == (False, False)
        # a user without a password (e.g. made by an answer import): nobody could sign in
        with database.session(write=True) as s:
            users.create_user(s, "pan", roles=["panelist"])
        assert sessions.is_open(database, True) and not sessions.is_open(database, False)
        assert _web_open(base) == (True, True)
        assert _web_open(base, proxied=True) == (False, False)
        # a user with a password: sign-in required for every request
        with database.session(write=True) as s:
            users.create_user(s, "eng", password="engineer pw", roles=["engineer"])
        assert not sessions.is_open(database, True) and not sessions.is_open(database, False)
        assert cookie_principal(database, None, True) is None
        assert _web_open(base) == (False, False)
        assert _web_open(base, proxied=True) == (False, False)
        c = Client(base)
        assert c.post("/login", username="eng", password="engineer pw")[2].endswith("/app")
        assert "eng" in c.get("/app")[1]


def test_a_local_request_is_loopback_without_proxy_headers():
    class Req:
        def __init__(self, ip, headers=None):
            self.remote_ip, self.headers = ip, headers or {}

    assert is_local_request(Req("127.0.0.1")) and is_local_request(Req("::1"))
    assert not is_local_request(Req("192.168.1.5"))
    assert not is_local_request(Req("127.0.0.1", {"X-Real-Ip": "203.0.113.9"}))
    assert not is_local_request(Req("127.0.0.1", {"Forwarded": "for=203.0.113.9"}))
    assert not is_local_request(Req("")) and not is_local_request(None)


class _SlowHasher:
    """argon2id as stored, slowed by ``delay_s`` per verification; ``during`` runs inside
    the verification (a change made while the hash is being checked)."""

    def __init__(self, real, delay_s: float, during=None):
        self.real, self.delay_s, self.during = real, delay_s, during
        self.verifying = threading.Event()

    def verify(self, stored, password):
        self.verifying.set()
        if self.during is not None:
            self.during()
        time.sleep(self.delay_s)
        return self.real.verify(stored, password)

    def __getattr__(self, name):
        return getattr(self.real, name)


def _writer_wait(database, sign_in) -> float:
    """Seconds a concurrent write session waits while ``sign_in`` verifies a 0.5 s hash."""
    slow = _SlowHasher(users._hasher, 0.5)
    waited = []
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(users, "_hasher", slow)
        t = threading.Thread(target=sign_in)
        t.start()
        assert slow.verifying.wait(10)
        time.sleep(0.05)
        t0 = time.perf_counter()
        with database.session(actor="rev", write=True) as s:
            audit.record(s, "rev", "workshop.answer", "workshop:W1", detail={"plot": 1})
        waited.append(time.perf_counter() - t0)
        t.join(10)
    return waited[0]


def test_the_hash_is_verified_outside_the_write_transaction(sqlite_database):
    """On SQLite a write session holds the database's write lock (BEGIN IMMEDIATE): a
    reviewer's answer written while a sign-in verifies a (slowed, 0.5 s) hash completes at
    once; verifying inside the write transaction (the former path, kept in
    ``users.authenticate``) makes the same answer wait for the hash."""
    database = sqlite_database
    with database.session(write=True) as s:
        users.create_user(s, "eng", password="engineer pw", roles=["engineer"])
    results = []

    def one_path():
        results.append(sessions.sign_in(database, "eng", "engineer pw", source="127.0.0.1",
                                        max_age_s=60))

    def inside_lock():
        with database.session(write=True) as s:
            results.append(users.authenticate(s, "eng", "engineer pw", source="127.0.0.1"))

    waited = _writer_wait(database, one_path)
    assert results[-1].ok and results[-1].session_id
    assert waited < 0.15, f"the answer waited {waited:.3f} s for the sign-in's hash"
    waited_inside = _writer_wait(database, inside_lock)
    assert results[-1].ok
    assert waited_inside > 0.3, f"control: inside the lock the answer waited {waited_inside:.3f} s"
    with database.session() as s:
        assert len(list(audit.iter_rows(s, action="login.ok"))) == 2
        assert len(list(audit.iter_rows(s, action="workshop.answer"))) == 2


@pytest.mark.parametrize("change", ["password", "disable"])
def test_an_account_changed_while_its_hash_is_verified_is_refused(database, change):
    """A password changed (or the account disabled) between the read of the hash and the
    write of the outcome: the verified hash is no longer the stored one, so the sign-in is
    refused, recorded, and no session is opened."""
    with database.session(write=True) as s:
        users.create_user(s, "eng", password="engineer pw", roles=["engineer"])

    def change_account():
        with database.session(actor="admin", write=True) as s:
            if change == "password":
                users.set_password(s, "eng", "a new password", actor="admin")
            else:
                users.disable(s, "eng", actor="admin")

    slow = _SlowHasher(users._hasher, 0.0, during=change_account)
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(users, "_hasher", slow)
        res = sessions.sign_in(database, "eng", "engineer pw", source="10.0.0.1", max_age_s=60)
    assert not res.ok and res.reason == "account changed" and res.session_id is None
    assert "sign in again" in res.message
    with database.session() as s:
        refused = list(audit.iter_rows(s, action="login.refused"))
        assert [r["reason"] for r in refused] == ["account changed"]
        assert refused[0]["detail"]["source"] == "10.0.0.1"
        assert list(audit.iter_rows(s, action="login.ok")) == []
        from railval.db.models import AppSession

        assert s.query(AppSession).count() == 0
    # the next attempt reads the account as it is now
    again = sessions.sign_in(database, "eng",
                             "a new password" if change == "password" else "engineer pw",
                             max_age_s=60)
    assert again.ok == (change == "password")
    if change == "disable":
        assert again.reason == "account disabled"


def test_every_outcome_keeps_its_audit_record(database):
    """Failures, the disabled account, the rate limit: the same rows as before the split."""
    with database.session(write=True) as s:
        users.create_user(s, "eng", password="engineer pw", roles=["engineer"])
        users.create_user(s, "gone", password="disabled pw", roles=["engineer"])
        users.disable(s, "gone")
    assert sessions.sign_in(database, "nobody", "whatever pw", source="s").reason == \
        "wrong user name or password"
    assert sessions.sign_in(database, "gone", "disabled pw", source="s").reason == \
        "account disabled"
    for _ in range(users.MAX_FAILURES_PER_USER):
        assert not sessions.sign_in(database, "eng", "wrong pw!", source="t").ok
    limited = sessions.sign_in(database, "eng", "engineer pw", source="t", max_age_s=60)
    assert limited.reason == "rate limit" and limited.session_id is None
    with database.session() as s:
        failed = [(r["object"], r["reason"]) for r in audit.iter_rows(s, action="login.failed")]
        refused = [r["reason"] for r in audit.iter_rows(s, action="login.refused")]
    assert ("user:nobody", "wrong user name or password") in failed
    assert ("user:gone", "account disabled") in failed
    assert failed.count(("user:eng", "wrong user name or password")) == users.MAX_FAILURES_PER_USER
    assert refused == ["rate limit"]
