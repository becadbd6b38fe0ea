"""The organiser's and panelist's units of work on workshops (docs/design.md §5): what the
workshop pages and the ``workshop`` verbs show and change, each call one unit of work.

Pages and verbs call these functions, never :mod:`railval.db.workshops` (docs/design.md §2:
services are the only door to the database); a call that writes opens
``session(write=True)``; an organiser's write re-reads the organiser inside it
(:func:`railval.db.users.require_live`), never trusting the principal the page resolved.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from railval.app.services import workshops as ws
from railval.app.services.workshop_documents import plots_document, status_document
from railval.core.errors import InvalidParameter
from railval.db import repo, users
from railval.db import workshops as wsdb


def overview(database) -> list[dict[str, Any]]:
    """One row per workshop: name, campaign, status, blind, reviewers, answers."""
    with database.session() as s:
        out = []
        for w in wsdb.list_workshops(s):
            prog = wsdb.progress(s, w)
            out.append({"name": w.name, "campaign": w.campaign.name, "status": w.status,
                        "blind": w.blind, "reviewers": len(prog),
                        "answers": sum(r["answered"] for r in prog)})
        return out


def campaign_choices(database) -> dict[str, dict[str, list[str]]]:
    """campaign → its configurations and section ids (the new-workshop form's choices)."""
    with database.session() as s:
        return {c.name: {"configurations": [x.name for x in repo.list_configurations(s, c)],
                         "sections": [x.id for x in repo.section_infos(s, c)]}
                for c in repo.list_campaigns(s)}


def plan_counts(database, campaign: str, configurations: Sequence[str] | None,
                sections: Sequence[str] | None, kinds: Sequence[str] | None) -> dict[str, Any]:
    """``{"plots": n, "by_kind": {kind: n}}`` of the plots a workshop of these choices gets."""

    with database.session() as s:
        planned = ws.plan(s, campaign, configurations, sections, kinds)
    return {"plots": len(planned), "by_kind": ws.count_by_kind(planned)}


def check_new(database, name: str, campaign: str, *, configurations: Sequence[str],
              sections: Sequence[str], kinds: Sequence[str], scaling: str, repeats: float,
              auto_share: float, actor: Any) -> int:
    """Refuse a new workshop's choices before its creation job starts (the checks
    :func:`railval.app.services.workshops.create` makes first: permission, name, options, an
    existing name, a choice that gives no plot) with the same
    :class:`~railval.core.errors.InvalidParameter`; returns the number of plots."""

    ws._check_options(name, scaling, "auto", repeats, auto_share, actor)
    with database.session() as s:
        ws._refuse_existing(s, name)
        n = len(ws.plan(s, campaign, configurations, sections, kinds))
    if n == 0:
        raise InvalidParameter("this choice of configurations, sections and kinds gives no plot "
                               "(no section has the channels of the chosen kinds on both sides)")
    return n


def status(database, name: str) -> dict[str, Any]:
    """The workshop's status with every reviewer's progress
    (:func:`railval.app.services.workshop_documents.status_document`)."""

    with database.session() as s:
        return status_document(s, name)


def plots(database, name: str) -> dict[str, Any]:
    """The workshop's plots (:func:`railval.app.services.workshop_documents.plots_document`)."""

    with database.session() as s:
        return plots_document(s, name)


def invite(database, name: str, reviewer: str, *, actor: Any) -> str:
    """A new personal link token of ``reviewer`` in workshop ``name`` (replaces an earlier one)."""
    with database.session(write=True) as s:
        users.require_live(s, actor, "workshop.run")  # the organiser as stored now
        return wsdb.invite(s, wsdb.get_workshop(s, name), reviewer, actor=actor)


def set_status(database, name: str, status: str, *, actor: Any) -> str:
    """Open or close workshop ``name``; returns the stored status."""
    with database.session(write=True) as s:
        users.require_live(s, actor, "workshop.run")  # the organiser as stored now
        return wsdb.set_status(s, wsdb.get_workshop(s, name), status, actor=actor).status


def plot_image(database, name: str, plot_id: int) -> tuple[bytes, str]:
    """(PNG bytes, SHA-256) of a stored plot of workshop ``name``."""
    with database.session() as s:
        return wsdb.plot_image(s, wsdb.get_workshop(s, name).id, plot_id)


def sibling_workshops(database, name: str) -> list[str]:
    """The other workshops on the same campaign (reviewer groups a card can show)."""
    with database.session() as s:
        w = wsdb.get_workshop(s, name)
        return [x.name for x in wsdb.list_workshops(s)
                if x.campaign_id == w.campaign_id and x.name != name]


def participations(database, username: str) -> list[dict[str, Any]]:
    """The workshops ``username`` takes part in, with their progress."""
    with database.session() as s:
        return wsdb.participations(s, username)


def own_link(database, name: str, username: str) -> str:
    """A fresh personal link token of ``username``'s own participation in ``name``."""
    with database.session(write=True) as s:
        return wsdb.own_link(s, name, username)
