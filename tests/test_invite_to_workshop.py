"""``railval user invite --role panelist --workshop W1`` end to end: the invitation made on
the command line, the account created through the ``/invite`` form of the served app (real
HTTP with the anti-forgery token the form hands out), and the panelist's landing page lists
W1 with its "Open review" button, which opens the personal review. SQLite and PostgreSQL.

Also the refusals: an unknown workshop or a role other than panelist when the invitation is
made (nothing stored), and a workshop gone before the link is used (the form is refused,
without listing other workshops to the anonymous invitee).
"""

from __future__ import annotations

import http.cookiejar
import json
import re
import urllib.error
import urllib.parse
import urllib.request

import pytest
from sqlalchemy import func, select, update

from railval.app.cli import main as cli
from railval.app.main import served
from railval.app.services import workshops as ws
from railval.db import audit, users
from railval.db.importer import import_campaign
from railval.db.models import Invitation, Workshop, WorkshopReviewer

from tests.factories import write_demo_campaign

SECRET = "w" * 40


class Client:
    """A cookie-keeping HTTP client that returns (status, body, final URL) on 4xx too."""

    def __init__(self, base: str):
        self.base = base
        self.opener = urllib.request.build_opener(
            urllib.request.HTTPCookieProcessor(http.cookiejar.CookieJar()))

    def get(self, path: str) -> tuple[int, str, str]:
        return self._open(urllib.request.Request(self.base + path))

    def post(self, path: str, form: dict[str, str]) -> tuple[int, str, str]:
        data = urllib.parse.urlencode(form).encode()
        return self._open(urllib.request.Request(self.base + path, data=data))

    def _open(self, req) -> tuple[int, str, str]:
        try:
            with self.opener.open(req, timeout=120) as r:
                return r.status, r.read().decode("utf-8", "replace"), r.geturl()
        except urllib.error.HTTPError as e:
            return e.code, e.read().decode("utf-8", "replace"), e.geturl()


def _xsrf(body: str) -> str:
    m = re.search(r'name="_xsrf" value="([^"]+)"', body)
    assert m is not None, "the form holds no anti-forgery token"
    return m.group(1)


@pytest.fixture
def site(database, tmp_path, monkeypatch):
    monkeypatch.setenv("RAILVAL_COOKIE_SECRET", SECRET)
    write_demo_campaign(tmp_path / "demo", n_sections=1, fmt="parquet", seed=4, name="demo")
    import_campaign(database, tmp_path / "demo")
    ws.create(database, "W1", "demo", kinds=["Y_time"], repeats=0.0)
    with database.session(write=True) as s:
        users.create_user(s, "adm", password="admin password", roles=["admin"])
    with served(database) as url:
        yield database, url.rsplit("/app", 1)[0]


def _invite(database, capsys, *extra: str) -> tuple[int, dict | str]:
    capsys.readouterr()
    code = cli(["--db", database.url, "--as", "adm", "user", "invite", "--role", "panelist",
                *extra])
    out, err = capsys.readouterr()
    return code, (json.loads(out) if code == 0 and "--json" in extra else out + err)


def test_invited_panelist_lands_in_the_workshop(site, capsys):
    database, base = site
    code, text = _invite(database, capsys, "--workshop", "W1", "--base-url", base)
    assert code == 0 and "single-use invitation (panelist to workshop W1)" in text
    token = re.search(r"/invite\?token=([\w-]+)", text).group(1)

    c = Client(base)
    status, body, _ = c.get(f"/invite?token={token}")
    assert status == 200 and "You are invited as <b>panelist</b> to workshop W1" in body
    status, body, final = c.post("/invite", {
        "_xsrf": _xsrf(body), "token": token, "username": "pia", "display_name": "Pia Panel",
        "password": "panelist password", "password2": "panelist password"})
    assert status == 200 and final.endswith("/workshops/mine"), (status, final, body[:300])
    assert "You take part in no workshop yet" not in body
    row = re.search(r"<tr><td>W1</td><td>open</td><td class='num'>0 of (\d+)</td>", body)
    assert row is not None and int(row.group(1)) > 0, body
    assert "action='/workshops/mine/W1/open'" in body

    status, review, final = c.post("/workshops/mine/W1/open", {"_xsrf": _xsrf(body)})
    assert status == 200 and "/review/" in final, (status, final)
    with database.session() as s:
        took_part = s.scalar(select(func.count()).select_from(WorkshopReviewer)
                             .join(Workshop).where(Workshop.name == "W1"))
        assert took_part == 1
        assert users.get_user(s, "pia").role_names == ["panelist"]
        joined = list(audit.iter_rows(s, action="workshop.join"))
        assert [(r["actor"], r["object"]) for r in joined] == [("pia", "workshop:W1")]


def test_invitation_to_an_unknown_workshop_or_for_another_role_is_refused(site, capsys):
    database, _ = site
    with database.session() as s:
        before = s.scalar(select(func.count()).select_from(Invitation))
    code, text = _invite(database, capsys, "--workshop", "W9")
    assert code == 2 and "workshop 'W9' not found" in text
    capsys.readouterr()
    code = cli(["--db", database.url, "--as", "adm", "user", "invite", "--role", "engineer",
                "--workshop", "W1"])
    err = capsys.readouterr().err
    assert code == 2 and "only with the role panelist, not 'engineer'" in err
    with database.session() as s:
        assert s.scalar(select(func.count()).select_from(Invitation)) == before


def test_link_to_a_workshop_gone_is_refused_without_listing_others(site, capsys):
    database, base = site
    code, doc = _invite(database, capsys, "--workshop", "W1", "--base-url", base, "--json")
    assert code == 0 and doc["workshop"] == "W1"
    token = doc["link"].rsplit("token=", 1)[1]
    with database.session(write=True) as s:  # the organiser renamed (or removed) the workshop
        s.execute(update(Workshop).where(Workshop.name == "W1").values(name="W1-archived"))
    status, body, _ = Client(base).get(f"/invite?token={token}")
    assert status == 403 and "The workshop &#x27;W1&#x27; of this invitation no longer exists" in body
    assert "W1-archived" not in body
    with database.session() as s:
        assert users.find_user(s, "pia") is None


def test_invite_help_texts_name_the_panelist(capsys):
    """The role is ``panelist`` ("reviewer" is the independent reviewer who signs off): the
    help of both invitation verbs says so; only the flag keeps its name ``--reviewer``."""
    for argv in (["workshop", "invite", "--help"], ["workshop", "--help"]):
        with pytest.raises(SystemExit):
            cli(argv)
        out = capsys.readouterr().out
        assert "panelist" in out
        assert "reviewer" not in out.replace("--reviewer", "").replace(
            "reviewer strictness", ""), out  # (analyse: the statistics' term for a rater)
    with pytest.raises(SystemExit):
        cli(["user", "invite", "--help"])
    out = capsys.readouterr().out
    assert "--workshop NAME" in out and "with --role panelist" in out
