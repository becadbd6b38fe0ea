"""The one navigation (app/navigation.py) and the anti-forgery token in pages
(app/security.py ``with_xsrf``), without a server; the served behaviour is in
tests/test_browser_review.py."""

from __future__ import annotations

import pytest

from railval.app import navigation
from railval.app.security import with_xsrf
from railval.core.roles import PAGE_ACTIONS, ROLES, Principal, open_principal

READ = ["overview", "compare", "dashboard", "metrics", "diagnose", "report", "signoff"]
#: role → (app pages, areas), written out independently of the registries
EXPECTED = {
    "admin": (READ + ["audit"], []),
    "organiser": (READ, ["workshops"]),
    "engineer": (READ + ["import"], []),
    "panelist": ([], ["my-workshops"]),
    "reviewer": (READ, ["workshops"]),
    "assessor": (READ + ["audit"], ["workshops"]),
}


@pytest.mark.parametrize("role", list(ROLES))
def test_entries_per_role(role):
    p = Principal(f"u_{role}", frozenset({role}))
    got = navigation.entries(p)
    pages, areas = EXPECTED[role]
    assert [e.name for e in got if e.kind == "page"] == pages
    assert [e.name for e in got if e.kind == "area"] == areas
    assert all(e.href == f"/app?page={e.name}" for e in got if e.kind == "page")
    assert navigation.landing(p) == ("/workshops/mine" if role == "panelist" else "/app")


def test_open_mode_and_several_roles():
    names = [e.name for e in navigation.entries(open_principal())]
    assert names[-2:] == ["workshops", "my-workshops"] and names[0] == "overview"
    both = Principal("x", frozenset({"panelist", "reviewer"}))
    assert navigation.landing(both) == "/app"
    assert [e.name for e in navigation.entries(both) if e.kind == "area"] == ["workshops",
                                                                             "my-workshops"]


def test_a_page_added_to_the_registries_appears_without_other_edits(monkeypatch):
    from railval.app.state import app as state_app

    monkeypatch.setattr(navigation, "PAGES", (*state_app.PAGES, "import"))
    monkeypatch.setitem(navigation.PAGE_TITLES, "import", "Import")
    monkeypatch.setitem(PAGE_ACTIONS, "import", "data.import")
    eng = [e.title for e in navigation.entries(Principal("e", frozenset({"engineer"})))]
    rev = [e.title for e in navigation.entries(Principal("r", frozenset({"reviewer"})))]
    assert eng[-1] == "Import" and "Import" not in rev


def test_page_url_selection():
    assert navigation.page_url("compare", campaign="a b", configuration=None) == \
        "/app?page=compare&campaign=a+b"


def test_with_xsrf_fills_every_post_form_and_the_meta():
    page = ("<!doctype html><html><head><title>t</title></head><body>"
            "<form method='post' action='/a'><input name='x'></form>"
            "<FORM action=\"/b\" METHOD=\"POST\" class='row'></FORM>"
            "<form method='get' action='/c'></form></body></html>")
    out = with_xsrf(page, 'tok"<en')
    hidden = '<input type="hidden" name="_xsrf" value="tok&quot;&lt;en">'
    assert out.count(hidden) == 2
    assert "<form method='get' action='/c'></form>" in out
    assert '<head><meta name="xsrf-token" content="tok&quot;&lt;en">' in out


@pytest.mark.parametrize("name", ["mine", "new", "Plan"])
def test_workshop_names_of_pages_are_refused(name):
    from railval.app.services import workshops as ws
    from railval.core.errors import InvalidParameter

    with pytest.raises(InvalidParameter, match="reserved"):
        ws.create(None, name, "demo")
