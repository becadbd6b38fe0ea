"""Campaign data for the web app's state, the report and the CLI's analysis verbs: the one
door between them and the database (docs/design.md §2).

Each function opens one unit of work on ``database`` (``railval.db.engine.Database``) and
returns plain data: campaign and configuration lists, a campaign's layout
(:class:`CampaignOverview`), one section's signals, content hashes, the lineage, a
configuration's validation and curve metrics, the sign-offs with their status, the evidence
check. :func:`acting_as` names the user a background job's changes are recorded as.

Reads open read sessions the database refuses to write in (``read_session``: SQLite
``query_only``, PostgreSQL ``READ ONLY`` transaction); :func:`validation` (fills the result
cache) and :func:`metrics` (stores its run) end with a short write: they open a deferred
unit of work (``write_session(deferred=True)``), which takes SQLite's write lock only at that
write, not for the whole computation (docs/database.md).
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

from railval.core import lazy
from railval.core.coverage import (
    MIN_POSITIONS,
    MIN_SECTIONS,
    MIN_SECTIONS_PER_ZONE,
    layout_shortfalls,
)
from railval.core.errors import NotFound
from railval.core.types import ZONES, SectionInfo
from railval.db import audit, repo

#: services and modules only some requests reach, loaded at their first use (validation and
#: metrics bring numba, scipy and pandas; the sign-offs only the sign-off and audit views read)
signoff_service = lazy.module("railval.app.services.signoff")
validation_service = lazy.module("railval.app.services.validation")
metrics_service = lazy.module("railval.app.services.metrics")
db_signoff = lazy.module("railval.db.signoff")
db_engine = lazy.module("railval.db.engine")

if TYPE_CHECKING:  # the verdict's module loads numba: imported by the validation itself
    from railval.core.validation import ValidationResult


@dataclass
class ConfigInfo:
    name: str
    parent: str | None
    effects: dict[str, Any] = field(default_factory=dict)
    description: str = ""


@dataclass
class CampaignOverview:
    name: str
    description: str
    vehicle: dict[str, Any]
    sections: list[SectionInfo]
    channels: list[dict[str, str]]
    configurations: list[ConfigInfo]

    def zone_counts(self) -> dict[int, int]:
        counts = {z: 0 for z in ZONES}
        for s in self.sections:
            counts[s.zone] = counts.get(s.zone, 0) + 1
        return counts

    def coverage_shortfalls(self, min_sections: int = MIN_SECTIONS,
                            min_per_zone: int = MIN_SECTIONS_PER_ZONE,
                            min_signals: int = MIN_POSITIONS) -> list[str]:
        """The coverage rules checked on the campaign layout alone
        (:func:`railval.core.coverage.layout_shortfalls`, Polach & Böttcher 2014 §5)."""
        return layout_shortfalls([s.zone for s in self.sections], [c["kind"] for c in self.channels],
                                 min_sections=min_sections, min_per_zone=min_per_zone,
                                 min_signals=min_signals)

    def children(self) -> dict[str | None, list[str]]:
        tree: dict[str | None, list[str]] = {}
        for c in self.configurations:
            tree.setdefault(c.parent, []).append(c.name)
        return tree


def campaign_names(database) -> list[str]:
    with database.read_session() as s:
        return [c.name for c in repo.list_campaigns(s)]


def _configurations(session, campaign: repo.CampaignArg) -> list[ConfigInfo]:
    confs = list(repo.list_configurations(session, campaign))
    names = {c.id: c.name for c in confs}
    return [ConfigInfo(name=c.name, parent=names.get(c.parent_id),
                       effects=dict(c.effects or {}), description=c.description or "")
            for c in confs]


def configurations(database, campaign: str) -> list[ConfigInfo]:
    with database.read_session() as s:
        return _configurations(s, repo.campaign_ref(s, campaign))


def overview(database, campaign: str) -> CampaignOverview:
    """Sections, vehicle, channels and configurations of a campaign, in one unit of work that
    looks the campaign up once."""
    with database.read_session() as s:
        camp = repo.get_campaign(s, campaign)
        sections = list(repo.section_infos(s, camp))
        vehicle = dict(repo.vehicle_info(s, camp))
        chans = [{"name": ch.name, "kind": ch.kind, "position": ch.position, "unit": ch.unit}
                 for ch in repo.channels(s, camp)]
        name, desc = camp.name, camp.description or ""
        confs = _configurations(s, camp)
    return CampaignOverview(name=name, description=desc, vehicle=vehicle, sections=sections,
                            channels=chans, configurations=confs)


#: a shared entry (:func:`shared`) is recomputed after this long even when the stamp is unchanged
#: (an edit in place, e.g. a description, adds or deletes no row)
SHARED_MAX_AGE_S = 30.0
#: most entries kept (campaign lists and overviews of every database the process serves)
SHARED_MAX_ENTRIES = 256
_shared: dict[tuple, tuple[float, tuple, Any]] = {}
_shared_lock = threading.Lock()


def shared(database, key: tuple, make: Callable[[], Any]) -> Any:
    """``make()``, computed once per process and shared by every session while the database's
    :func:`railval.db.repo.catalogue_stamp` is unchanged and at most :data:`SHARED_MAX_AGE_S`
    old (docs/app.md, "Cheap sessions"): a new Panel session reads the stamp (one query)
    instead of the campaign list and overview. The value is shared: callers must not change it."""
    with database.read_session() as s:
        stamp = repo.catalogue_stamp(s)
    k = (database.url, *key)
    now = time.monotonic()
    with _shared_lock:
        hit = _shared.get(k)
    if hit is not None and hit[1] == stamp and now - hit[0] < SHARED_MAX_AGE_S:
        return hit[2]
    value = make()
    with _shared_lock:
        if len(_shared) >= SHARED_MAX_ENTRIES:
            _shared.clear()
        _shared[k] = (now, stamp, value)
    return value


def shared_campaign_names(database) -> list[str]:
    """:func:`campaign_names` through the process-wide cache (:func:`shared`); a copy."""
    return list(shared(database, ("campaigns",), lambda: campaign_names(database)))


def shared_overview(database, campaign: str) -> CampaignOverview:
    """:func:`overview` through the process-wide cache (:func:`shared`); read-only."""
    return shared(database, ("overview", campaign), lambda: overview(database, campaign))


def signals(database, campaign: str, config: str | None, section: str,
            channels: list[str] | None = None):
    """One section's SignalSet of the measurement (``config`` None) or a configuration."""
    with database.read_session() as s:
        camp, conf = repo.resolve(s, campaign, config)
        sets = repo.load_signalsets(s, camp, config=conf, sections=[section], channels=channels)
    if section not in sets:
        raise NotFound(f"section {section!r} has no recording for "
                       f"{'the measurement' if config is None else 'configuration ' + repr(config)}")
    return sets[section]


def hashes(database, campaign: str, config: str | None) -> dict[str, dict[str, str]]:
    """section → channel → SHA-256 of the stored samples (no blob read)."""
    with database.read_session() as s:
        camp, conf = repo.resolve(s, campaign, config)
        return repo.signal_hashes(s, camp, conf)


def lineage(database, campaign: str, config: str) -> list[str]:
    """Names from the root configuration down to ``config``."""
    with database.read_session() as s:
        camp, conf = repo.resolve(s, campaign, config)
        return [c.name for c in repo.lineage(s, camp, conf)]


def require_sealed(database, campaign: str, config: str) -> None:
    """Every blob of the measurement and of ``config`` against its hash and seal
    (:func:`railval.db.repo.require_sealed`); raises on the first mismatch."""
    with database.read_session() as s:
        camp, conf = repo.resolve(s, campaign, config)
        repo.require_sealed(s, camp, conf, blobs=True)


def signoff_items(database, campaign: str | None = None, config: str | None = None
                  ) -> list[tuple[dict[str, Any], Any]]:
    """The sign-offs (of one campaign/configuration, or all) as ``(record dict,
    SignoffStatus)``."""
    with database.write_session(deferred=True) as s:  # may fill the result cache
        return [(db_signoff.as_dict(so), st)
                for so, st in signoff_service.statuses(s, campaign, config)]


def audit_and_signoffs(database) -> tuple[list[tuple[dict[str, Any], Any]], list[Any]]:
    """Every sign-off with its status and every audit row, read in one unit of work (the
    audit report)."""
    with database.write_session(deferred=True) as s:  # may fill the result cache
        items = [(db_signoff.as_dict(so), st) for so, st in signoff_service.statuses(s)]
        return items, list(audit.iter_rows(s))


def validation(database, campaign: str, config: str, **kw: Any) -> ValidationResult:
    """:func:`railval.app.services.validation.validate_configuration` in one unit of work."""
    # a read that may end with a short write (the result cache, best effort): a deferred
    # unit of work takes the write lock only at that write, so reviewers' answers never wait
    # for the validation's computation (docs/database.md, "One write door")
    with database.write_session(deferred=True) as s:
        return validation_service.validate_configuration(s, campaign, config, **kw)


def metrics(database, campaign: str, config: str, sections: Sequence[str] | None = None,
            channels: Sequence[str] | None = None, **kw: Any):
    """:func:`railval.app.services.metrics.metrics_for_configuration` in one unit of work."""
    # a read that ends with a short write (the metrics run): deferred, as in :func:`validation`
    with database.write_session(deferred=True) as s:
        return metrics_service.metrics_for_configuration(s, campaign, config, sections,
                                                         channels, **kw)


@contextmanager
def acting_as(username: str) -> Iterator[None]:
    """Within the block, database changes are recorded as ``username``
    (:func:`railval.db.engine.acting_as`)."""
    with db_engine.acting_as(username):
        yield


def in_session(database, service: Any, *args: Any, **kw: Any) -> Any:
    """``service(session, *args, **kw)`` — a service function that takes a session — in one
    read session of its own (the database refuses a write in it)."""
    with database.read_session() as s:
        return service(s, *args, **kw)
