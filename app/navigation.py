"""One navigation for the whole web app: the Panel pages and the workshop pages
(docs/app.md "Navigation").

:func:`entries` lists what a signed-in user may open, in one order, from the registries:
the Panel pages of :data:`railval.app.state.PAGES` (titles :data:`~railval.app.state.PAGE_TITLES`,
permissions :data:`railval.core.roles.PAGE_ACTIONS`) and the workshop areas of
:data:`AREAS`. A page added to those registries appears in the navigation of both parts
without further edits. :func:`landing` is where a user goes after signing in: the first
entry (a panelist, who may open no Panel page, lands on "My workshops").

No Panel or Tornado import: the Panel sidebar (:mod:`railval.app.main`) and the workshop
pages' header (:mod:`railval.app.workshop_web.common`) both render these entries.
"""

from __future__ import annotations

from dataclasses import dataclass
from urllib.parse import urlencode

from railval.app.state.app import PAGE_TITLES, PAGES
from railval.core.roles import PAGE_ACTIONS, Principal, allowed

APP_URL = "/app"

#: web areas outside the Panel app: name → (title, path, actions of which one is needed)
AREAS: dict[str, tuple[str, str, tuple[str, ...]]] = {
    "workshops": ("Workshops", "/workshops", ("workshop.run", "workshop.results")),
    "my-workshops": ("My workshops", "/workshops/mine", ("workshop.answer",)),
}


@dataclass(frozen=True)
class Entry:
    """One navigation entry: ``kind`` is ``page`` (a Panel page) or ``area``."""

    name: str
    title: str
    href: str
    kind: str


def page_url(page: str, **selection: str | None) -> str:
    """The app's URL opening ``page`` (optionally with campaign/configuration selected)."""
    query = {"page": page, **{k: v for k, v in selection.items() if v}}
    return f"{APP_URL}?{urlencode(query)}"


def entries(principal: Principal) -> list[Entry]:
    """Every page and area ``principal`` may open, Panel pages first."""
    out = [Entry(p, PAGE_TITLES[p], page_url(p), "page") for p in PAGES
           if p in PAGE_ACTIONS and allowed(principal, PAGE_ACTIONS[p])]
    for name, (title, path, actions) in AREAS.items():
        if any(allowed(principal, a) for a in actions):
            out.append(Entry(name, title, path, "area"))
    return out


def landing(principal: Principal) -> str:
    """Where ``principal`` starts: the app when it may open a page, else its first area."""
    items = entries(principal)
    if not items or items[0].kind == "page":
        return APP_URL
    return items[0].href
