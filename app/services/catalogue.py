"""The campaign catalogue behind ``railval list`` (docs/app.md, docs/validation.md §speed).

Two ways to the same document, :func:`railval.db.repo.campaign_summary` of every campaign
ordered by name: the fast one reads it with the database driver alone
(:func:`railval.db.catalogue.read_catalogue`, nothing of SQLAlchemy, the ORM or the audit trail
imported) and answers only in the plain case; otherwise :func:`summaries` takes the ordinary
path. This module imports nothing heavy at import time, so that ``railval list`` starts at once.
"""

from __future__ import annotations

from typing import Any

from railval.core import lazy

#: deferred (railval.core.lazy): the fast path of ``railval list`` answers from the
#: catalogue table without the ORM models; the repository only when it must fall back
catalogue = lazy.module("railval.db.catalogue")
repo = lazy.module("railval.db.repo")


def fast(db_url: str | None, who: str | None) -> tuple[list[dict[str, Any]] | None, str]:
    """(the catalogue or None when the ordinary path must answer, the URL with its password
    hidden) for the database named by ``db_url`` (else ``$RAILVAL_DB``)."""

    url = catalogue.resolve_url(db_url)
    return catalogue.read_catalogue(url, who), catalogue.safe_url(url)


def summaries(database) -> list[dict[str, Any]]:
    """The ordinary path: every campaign's summary through the ORM, ordered by name."""

    with database.session() as s:
        return [repo.campaign_summary(s, c.id) for c in repo.list_campaigns(s)]
