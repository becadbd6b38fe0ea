"""Campaigns and their configurations: looking them up, resolving them once, summaries.

A request resolves its campaign and configuration once at its entrance (:func:`resolve`,
docs/design.md §2) and passes the references (:class:`CampaignRef`, :class:`ConfigRef`) to
every repository function, which then needs no further lookup. For callers that have not
resolved yet, the functions also take the campaign's row, name or id and the configuration's
name (:data:`CampaignArg`, :data:`ConfigArg`); those are looked up on each call.

All functions take an open :class:`sqlalchemy.orm.Session` (from
:meth:`railval.db.engine.Database.session`).
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from typing import Any

from sqlalchemy import func, select
from sqlalchemy.orm import Session

from railval.core.errors import InvalidParameter, NotFound
from railval.core.names import check_name
from railval.core.types import SectionInfo
from railval.core.zones import zone_for_radius
from railval.db import audit
from railval.db.models import (
    AuditEvent,
    Base,
    Campaign,
    Channel,
    Configuration,
    Recording,
    Section,
    Signal,
    Vehicle,
)


# -- references --------------------------------------------------------------------------
@dataclass(frozen=True)
class CampaignRef:
    """A campaign resolved once at the entrance (:func:`resolve`): its id and name. Every
    repository function takes it where it takes a campaign, without another lookup."""

    id: int
    name: str


@dataclass(frozen=True)
class ConfigRef:
    """A configuration of a campaign resolved once (:func:`resolve`). Every repository
    function that takes a configuration (``config``) takes this, without another lookup."""

    campaign: CampaignRef
    id: int
    name: str


#: A campaign as the repository functions take it: a :class:`CampaignRef` resolved once at the
#: entrance (what services pass), the :class:`Campaign` row, or — for callers that have not
#: resolved it — its name or numeric id, looked up on every call.
CampaignArg = CampaignRef | Campaign | str | int

#: A stored configuration as the repository functions take it: a :class:`ConfigRef` resolved
#: once, or its name in the campaign (looked up on every call).
ConfigArg = ConfigRef | str


def resolve(session: Session, campaign: CampaignArg,
            config: ConfigArg | None = None) -> tuple[CampaignRef, ConfigRef | None]:
    """Resolve a request's campaign and configuration once, at its entrance.

    Parameters
    ----------
    session : Session
        An open unit of work.
    campaign : CampaignArg
        The campaign's name (or numeric id, row or reference).
    config : ConfigArg or None
        The configuration's name (or reference); ``None`` for none.

    Returns
    -------
    tuple of (CampaignRef, ConfigRef or None)
        The references every other repository function takes without another lookup.
        Raises :class:`NotFound` naming how to find what is available.
    """
    ref = campaign_ref(session, campaign)
    if config is None:
        return ref, None
    if isinstance(config, ConfigRef):
        return ref, config
    conf = get_configuration(session, ref, config)
    return ref, ConfigRef(ref, conf.id, conf.name)


def campaign_ref(session: Session, campaign: CampaignArg) -> CampaignRef:
    """``campaign`` as a :class:`CampaignRef`; no query when it is one already (or a row)."""
    if isinstance(campaign, CampaignRef):
        return campaign
    c = campaign if isinstance(campaign, Campaign) else get_campaign(session, campaign)
    return CampaignRef(c.id, c.name)


def config_name(config: ConfigArg | None) -> str | None:
    """The name of a configuration given as a :class:`ConfigRef` or a name (``None`` stays)."""
    return config.name if isinstance(config, ConfigRef) else config


# -- campaigns ---------------------------------------------------------------------------
def list_campaigns(session: Session) -> list[Campaign]:
    """All campaigns, ordered by name."""
    return list(session.scalars(select(Campaign).order_by(Campaign.name)))


#: a campaign id as the CLI and the services take it: ASCII digits only, at most 18 of them
#: (ids are 64-bit integers; a longer string is no id, not an overflow in the database)
_ID_RE = re.compile(r"[0-9]{1,18}")


def is_campaign_id(text: object) -> bool:
    """``True`` when ``text`` is a numeric campaign id (an int, or ASCII digits only)."""
    return isinstance(text, int) or (isinstance(text, str) and bool(_ID_RE.fullmatch(text.strip())))


def check_campaign_name(name: object, what: str = "campaign name") -> str:
    """:func:`railval.core.names.check_name`, and no name of digits only.

    A campaign is found by its name or by its numeric id (``railval validate 1``); a campaign
    called ``1`` would hide, or be mistaken for, the campaign with id 1. Every way a campaign
    is created (``railval import``, ``railval synth``, the Import page) calls this before
    anything is stored. Raises :class:`railval.core.errors.InvalidParameter`.
    """
    check_name(name, what)
    if str(name).isdigit():
        raise InvalidParameter(
            f"{what} {name!r} is digits only: a campaign is also found by its numeric id "
            f"(`railval validate {name}` means the campaign with id {name}), so such a name "
            f"would hide another campaign; add a letter, e.g. {'C' + str(name)!r}")
    return str(name)


def get_campaign(session: Session, campaign: CampaignArg) -> Campaign:
    """The row of ``campaign``: a :class:`CampaignRef` (by id), a row (returned as it is), a
    numeric id (an int, or a string of ASCII digits: :func:`is_campaign_id`), or a name.

    Digits are always an id: no new campaign may be named so (:func:`check_campaign_name`),
    and a row called ``1`` left by an older version or a restored backup cannot stand in for
    the campaign with id 1 (it stays reachable by its own id).

    Raises :class:`railval.core.errors.NotFound` saying how to list the campaigns (it does
    not list them: whoever mistyped a name is not shown the others).
    """
    if isinstance(campaign, Campaign):
        return campaign
    if isinstance(campaign, CampaignRef):
        found = session.get(Campaign, campaign.id)
        if found is None:  # deleted since it was resolved
            raise NotFound(f"campaign {campaign.name!r} no longer exists")
        return found
    if is_campaign_id(campaign):
        found = session.get(Campaign, int(str(campaign).strip()))
    else:
        found = session.scalar(select(Campaign).where(Campaign.name == str(campaign)))
    if found is None:
        # the names of the other campaigns are not shown to whoever typed a wrong one
        raise NotFound(f"campaign {campaign!r} not found; list the campaigns with "
                       "`railval list`")
    return found


def campaign_id(session: Session, campaign: CampaignArg) -> int:
    """The id of ``campaign``; no query when it is a :class:`CampaignRef` or a row."""
    if isinstance(campaign, (Campaign, CampaignRef)):
        return campaign.id
    return get_campaign(session, campaign).id


def section_infos(session: Session, campaign: CampaignArg) -> list[SectionInfo]:
    """The campaign's sections (import order) with their EN 14363 zone.

    The zone comes from :func:`railval.core.zones.zone_for_radius` with the campaign's zone 1/2
    radius boundary; a section's ``zone_override`` wins.
    """
    c = get_campaign(session, campaign)
    rows = session.scalars(select(Section).where(Section.campaign_id == c.id).order_by(Section.id))
    return [
        SectionInfo(
            id=s.section_id,
            radius_m=s.radius_m,
            cant_mm=s.cant_mm,
            speed_kmh=s.speed_kmh,
            zone=zone_for_radius(s.radius_m, c.zone1_min_radius_m, s.zone_override),
            eval_start_m=s.eval_start_m,
            eval_end_m=s.eval_end_m,
            country=s.country,
            curve_direction=s.curve_direction,
        )
        for s in rows
    ]


def section_layouts(session: Session, campaign: CampaignArg) -> dict[str, dict | None]:
    """section id → the optional ``layout`` record of the manifest (built-in simulator)."""
    cid = campaign_id(session, campaign)
    rows = session.execute(
        select(Section.section_id, Section.layout).where(Section.campaign_id == cid).order_by(Section.id)
    )
    return {sid: layout for sid, layout in rows}


def vehicle_info(session: Session, campaign: CampaignArg) -> dict[str, Any]:
    """``{name, kind, secondary_suspension, Q0_kN, template, parameters}`` of the vehicle."""
    c = get_campaign(session, campaign)
    v = session.scalar(select(Vehicle).where(Vehicle.campaign_id == c.id))
    if v is None:
        raise NotFound(f"campaign {c.name!r} has no vehicle record")
    return {
        "name": v.name,
        "kind": v.kind,
        "secondary_suspension": bool(v.secondary_suspension),
        "Q0_kN": float(v.Q0_kN),
        "template": v.template,
        "parameters": dict(v.parameters or {}),
    }


def channels(session: Session, campaign: CampaignArg) -> list[Channel]:
    """The campaign's declared channels in manifest order."""
    cid = campaign_id(session, campaign)
    return list(session.scalars(select(Channel).where(Channel.campaign_id == cid).order_by(Channel.id)))


# -- configurations ----------------------------------------------------------------------
def list_configurations(session: Session, campaign: CampaignArg) -> list[Configuration]:
    """The campaign's configurations in creation order."""
    cid = campaign_id(session, campaign)
    return list(
        session.scalars(
            select(Configuration).where(Configuration.campaign_id == cid).order_by(Configuration.id)
        )
    )


def get_configuration(session: Session, campaign: CampaignArg, config: ConfigArg) -> Configuration:
    """The row of configuration ``config`` of ``campaign`` (no lookup by name when ``config``
    is a :class:`ConfigRef`); :class:`NotFound` lists the available ones."""
    if isinstance(config, ConfigRef):
        found = session.get(Configuration, config.id)
        if found is None:  # deleted since it was resolved
            raise NotFound(f"configuration {config.name!r} of campaign {config.campaign.name!r} "
                           "no longer exists")
        return found
    c = get_campaign(session, campaign)
    found = session.scalar(
        select(Configuration).where(Configuration.campaign_id == c.id, Configuration.name == config)
    )
    if found is None:
        names = [x.name for x in list_configurations(session, c)]
        raise NotFound(
            f"configuration {config!r} not found in campaign {c.name!r}; available: "
            f"{', '.join(names) or '(none)'}"
        )
    return found


def lineage(session: Session, campaign: CampaignArg, config: ConfigArg) -> list[Configuration]:
    """The chain of parents of configuration ``config``, root first, ``config`` last."""
    conf = get_configuration(session, campaign, config)
    chain = [conf]
    seen = {conf.id}
    while chain[-1].parent_id is not None:
        parent = session.get(Configuration, chain[-1].parent_id)
        if parent is None or parent.id in seen:  # pragma: no cover - FK and checks prevent it
            break
        seen.add(parent.id)
        chain.append(parent)
    return chain[::-1]


def delete_campaign(session: Session, campaign: CampaignArg, *, reason: str = "") -> None:
    """Delete a campaign with everything below it; audited (before = its signal hashes)."""
    c = get_campaign(session, campaign)
    hashes = sorted(session.scalars(
        select(Signal.sha256).join(Recording, Signal.recording_id == Recording.id)
        .join(Section, Recording.section_id == Section.id).where(Section.campaign_id == c.id)))
    name = c.name
    session.delete(c)
    session.flush()
    audit.record(session, audit.actor_of(session), "campaign.delete", f"campaign:{name}",
                 {"campaign": name, "signals": hashes}, None, reason)


def count_signals(session: Session, campaign: CampaignArg) -> int:
    """Number of stored arrays of the campaign (signals plus distance axes)."""
    cid = campaign_id(session, campaign)
    recs = session.scalar(select(func.count()).select_from(Recording)
                          .join(Section, Recording.section_id == Section.id)
                          .where(Section.campaign_id == cid)) or 0
    sigs = session.scalar(select(func.count()).select_from(Signal)
                          .join(Recording, Signal.recording_id == Recording.id)
                          .join(Section, Recording.section_id == Section.id)
                          .where(Section.campaign_id == cid)) or 0
    return int(recs) + int(sigs)


def row_counts(session: Session) -> dict[str, int]:
    """Number of rows per table (used by tests and ``railval list``)."""
    return {
        name: int(session.scalar(select(func.count()).select_from(table)) or 0)
        for name, table in sorted(Base.metadata.tables.items())
    }


def campaign_summary(session: Session, campaign: CampaignArg) -> dict[str, Any]:
    """A campaign at a glance (``railval list``): name, id, description, vehicle, sections
    with zones, channels, configurations with parent and effects, number of stored signals."""
    c = get_campaign(session, campaign)
    infos = section_infos(session, c)
    n_signals = session.scalar(
        select(func.count(Signal.id)).join(Recording).join(Section).where(Section.campaign_id == c.id))
    confs = list_configurations(session, c)
    parent = {x.id: x.name for x in confs}
    zones: dict[int, int] = {}
    for i in infos:
        zones[i.zone] = zones.get(i.zone, 0) + 1
    return {
        "name": c.name,
        "id": c.id,
        "description": c.description,
        "vehicle": vehicle_info(session, c),
        "n_sections": len(infos),
        "zones": {str(z): n for z, n in sorted(zones.items())},
        "sections": [{"id": i.id, "zone": i.zone, "radius_m": i.radius_m,
                      "speed_kmh": i.speed_kmh} for i in infos],
        "channels": [ch.name for ch in channels(session, c)],
        "configurations": [{"name": x.name, "parent": parent.get(x.parent_id),
                            "effects": sorted(x.effects)} for x in confs],
        "n_signals": int(n_signals or 0),
    }


#: audit actions (prefixes) that change no campaign, vehicle, section, channel or
#: configuration: sign-ins and sign-outs, users and their roles, invitations, workshops,
#: backups. Any other action, one added later included, counts as a possible change.
NOT_CATALOGUE_ACTIONS = ("login.", "logout", "user.", "invitation.", "workshop.", "database.backup")


def catalogue_stamp(session: Session) -> tuple:
    """A stamp of what a campaign overview is made of, in one query: row count and largest id
    of the campaign, vehicle, section, channel and configuration tables (any row added or
    deleted changes it), the largest recording id (a configuration replaced in place gets
    new recordings) and the largest id of an audit-trail row that may change the catalogue
    (every stored change is audited, docs/audit.md; the rows of :data:`NOT_CATALOGUE_ACTIONS` —
    sign-ins, users, invitations, workshops — are left out, so that a sign-in does not make
    the next session recompute). The web app's process-wide cache of campaign lists and
    overviews (docs/app.md, "Cheap sessions") recomputes an entry when it changes."""
    parts = []
    for model in (Campaign, Vehicle, Section, Channel, Configuration):
        parts += [select(func.count(model.id)).scalar_subquery(), select(func.max(model.id)).scalar_subquery()]
    catalogue_audit = select(func.max(AuditEvent.id)).where(
        *(AuditEvent.action.not_like(f"{prefix}%") for prefix in NOT_CATALOGUE_ACTIONS))
    parts += [select(func.max(Recording.id)).scalar_subquery(), catalogue_audit.scalar_subquery()]
    return tuple(session.execute(select(*parts)).one())
