"""One navigation for the whole web app: the Panel pages and the workshop pages
(docs/app.md "Navigation").

:func:`entries` lists what a signed-in user may open, in one order, from the registries:
the Panel pages of :data:`railval.app.state.PAGES` (titles :data:`~railval.app.state.PAGE_TITLES`,
permissions :data:`railval.core.roles.PAGE_ACTIONS`) and the workshop areas of
:data:`AREAS`. A page added to those registries appears in the navigation of both parts
without further edits. :func:`landing` is where a user goes after signing in: the first
entry (a panelist, who may open no Panel page, lands on "My workshops").

One look: :func:`nav_html` renders the entries as one bar (:data:`NAV_CSS`) with the
current page marked (``rv-current``, ``aria-current="page"``); the Panel app shows it in
its header (:mod:`railval.app.main`; an app page's entry is a button there, which switches
the page inside the session) and the workshop pages in theirs
(:mod:`railval.app.workshop_web.common`; every entry a link). :func:`jobs_html` renders the
user's running and recently finished jobs (:func:`railval.app.state.jobs.jobs_of`) for both.
Roles decide which entries show; the pages still check the permission on every request.

No Panel or Tornado import: the Panel app and the workshop pages both render these.
"""

from __future__ import annotations

import html
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

from railval.app.state.app import PAGE_TITLES, PAGES
from railval.app.state.jobs import APP_URL, app_link
from railval.core.roles import PAGE_ACTIONS, Principal, allowed

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
    return app_link(page, **selection)


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


#: the one look of the navigation bar and of the job list (white on the app's blue header)
NAV_CSS = """
.rv-nav{display:flex;gap:4px;flex-wrap:wrap;align-items:center;font-family:'DejaVu Sans',Arial,sans-serif}
.rv-nav .rv-nav-link{display:inline-block;text-decoration:none;padding:4px 9px;border-radius:4px;
  font-size:14px;line-height:20px;color:#fff;background:transparent;border:0;cursor:pointer;
  font-family:inherit;margin:0}
.rv-nav .rv-nav-link:hover{background:rgba(255,255,255,.18)}
.rv-nav .rv-nav-link.rv-current{background:#fff;color:#0b5394;font-weight:bold}
.rv-nav .rv-areas{display:inline-flex;gap:4px;padding-left:8px;margin-left:4px;
  border-left:1px solid rgba(255,255,255,.5)}
.rv-jobs{font-family:'DejaVu Sans',Arial,sans-serif;font-size:13px;background:#fff;
  border:1px solid #ccd;border-radius:4px;padding:6px 8px;margin:6px 0}
.rv-jobs b{display:block;margin-bottom:3px}.rv-jobs ul{margin:0;padding-left:16px}
.rv-jobs li{margin:2px 0}.rv-jobs .rv-job-failed{color:#b42318}
.rv-jobs .rv-job-done{color:#1a7f37}
"""


def nav_items(principal: Principal, current: str = "") -> list[dict[str, Any]]:
    """The entries of :func:`nav_html` as data (``title``, ``name``, ``href``, ``kind``,
    ``current``): the Panel app builds the same bar from them in the browser."""
    return [{"title": e.title, "name": e.name, "href": e.href, "kind": e.kind,
             "current": e.name == current or e.href == current} for e in entries(principal)]


def nav_html(principal: Principal, current: str = "", *, in_app: bool = False,
             selection: Mapping[str, str | None] | None = None) -> str:
    """The navigation bar of ``principal``: ``<nav class="rv-nav">`` with the app pages, then
    the workshop areas (``<span class="rv-areas">``); the entry named ``current`` (a page
    name, an area name or an area's path) marked. ``in_app``: app pages as buttons
    (``data-page``) that the Panel app turns into a page switch; else links to the app with
    ``selection`` (campaign, configuration) kept."""
    sel = dict(selection or {})
    pages, areas = [], []
    for e in entries(principal):
        mark = e.name == current or e.href == current
        cls = "rv-nav-link rv-current" if mark else "rv-nav-link"
        aria = " aria-current='page'" if mark else ""
        title = html.escape(e.title)
        if e.kind == "page" and in_app:
            pages.append(f"<button type='button' class='{cls}' data-page='{html.escape(e.name)}'"
                         f"{aria}>{title}</button>")
        elif e.kind == "page":
            href = html.escape(page_url(e.name, **sel), quote=True)
            pages.append(f"<a class='{cls}' href='{href}'{aria}>{title}</a>")
        else:
            areas.append(f"<a class='{cls} rv-area' href='{html.escape(e.href, quote=True)}'"
                         f"{aria}>{title}</a>")
    tail = f"<span class='rv-areas'>{''.join(areas)}</span>" if areas else ""
    return f"<nav class='rv-nav' aria-label='railval'>{''.join(pages)}{tail}</nav>"


_STATE_TEXT = {"queued": "queued", "running": "running", "done": "done", "failed": "failed",
               "cancelled": "cancelled"}


def job_line(job: Mapping[str, Any]) -> str:
    """One job as plain text: title, state, progress (``n of N`` where counted), elapsed."""
    state = job["state"]
    if state == "running" and job.get("total"):
        what = f"{job.get('done') or 0} of {job['total']}"
    elif state == "running":
        what = f"{round(100 * job.get('fraction', 0.0))} %"
    else:
        what = _STATE_TEXT.get(state, state)
    text = f"{job['title']}: {what} · {job['elapsed_s']:.0f} s"
    if state == "failed" and job.get("error"):
        err = job["error"]
        text += f" — {err if len(err) <= 160 else err[:159] + '…'}"  # the whole on its page
    return text


def jobs_html(jobs: Sequence[Mapping[str, Any]]) -> str:
    """The user's jobs as a list with a link each to the result (or, while running, to the
    page that shows it); empty without jobs."""
    if not jobs:
        return ""
    items = "".join(
        f"<li class='rv-job rv-job-{html.escape(j['state'])}' data-state='{html.escape(j['state'])}'>"
        f"<a href='{html.escape(j['link'], quote=True)}'>{html.escape(job_line(j))}</a></li>"
        for j in jobs)
    return f"<div class='rv-jobs'><b>Your jobs</b><ul>{items}</ul></div>"
