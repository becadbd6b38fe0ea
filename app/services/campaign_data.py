"""Campaign data in and out (docs/database.md): importing a campaign or a configuration
folder, exporting a campaign, a campaign's summary, checking the whole database.

The ``import``, ``export``, ``list`` and ``verify`` verbs and the demo seeding of ``serve``
call these instead of :mod:`railval.db` (docs/design.md §2: services are the only door to
the database). Imports write in one ``session(write=True)`` opened by the importer.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

from railval.core import lazy
from railval.db import repo

#: deferred (railval.core.lazy): the importer and exporter (readers, pandas) only for
#: an import or export
import_campaign = lazy.function("railval.db.importer", "import_campaign")
import_configuration = lazy.function("railval.db.importer", "import_configuration")
export_campaign = lazy.function("railval.db.exporter", "export_campaign")

Progress = Callable[[int, int, str], None]


def import_folder(database, folder: str | Path, *, progress: Progress | None = None) -> str:
    """Validate the campaign folder completely, then store it in one unit of work
    (:func:`railval.db.importer.import_campaign`); returns the campaign name."""

    return import_campaign(database, folder, progress=progress)


def import_configuration_folder(database, campaign: str, folder: str | Path, *,
                                progress: Progress | None = None) -> str:
    """Add a configuration's simulated files to the stored ``campaign``
    (:func:`railval.db.importer.import_configuration`); returns the configuration name."""

    return import_configuration(database, campaign, folder, progress=progress)


def export(database, campaign: str, folder: str | Path, *, fmt: str = "parquet") -> Path:
    """Write a stored campaign as a re-importable campaign folder; returns its manifest."""

    with database.session() as s:
        return export_campaign(s, campaign, folder, fmt=fmt)


def summary(database, campaign: str | int) -> dict[str, Any]:
    """A campaign at a glance (:func:`railval.db.repo.campaign_summary`)."""
    with database.session() as s:
        return repo.campaign_summary(s, campaign)


def has_campaigns(database) -> bool:
    """True when the database holds at least one campaign."""
    with database.session() as s:
        return bool(repo.list_campaigns(s))


def verify(database, *, blobs: bool = True) -> dict[str, Any]:
    """Every signal's content hash and seal and every cached result's seal
    (:func:`railval.db.repo.verify_storage`)."""
    with database.session() as s:
        return repo.verify_storage(s, blobs=blobs)
