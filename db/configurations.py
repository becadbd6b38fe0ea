"""Storing, replacing and deleting configurations (e.g. a simulation or calibration result)
with their signals; every change is audited with the configuration's before/after state.

``campaign`` is a :data:`railval.db.campaigns.CampaignArg` (a :class:`CampaignRef` resolved
once, or the row, name or id); an existing configuration a
:data:`railval.db.campaigns.ConfigArg` (a :class:`ConfigRef` or its name).
"""

from __future__ import annotations

import datetime as dt
from collections.abc import Mapping
from typing import Any

import numpy as np
from sqlalchemy import delete, select
from sqlalchemy.orm import Session

from railval.core.errors import InvalidParameter, InvalidSignal, NotFound
from railval.core.names import check_name
from railval.core.types import SignalSet
from railval.db import audit
from railval.db.campaigns import (
    CampaignArg,
    CampaignRef,
    ConfigArg,
    campaign_ref,
    channels,
    config_name,
    get_configuration,
    lineage,
)
from railval.db.checks import RecordingProblem, check_recording
from railval.db.models import Channel, Configuration, Recording, Section, Signal, utcnow
from railval.db.signals import add_recordings


def check_new_configuration(session: Session, campaign: CampaignArg, name: str, *,
                            replace: bool = False) -> Configuration | None:
    """Check that configuration ``name`` (a new name) may be stored: a safe name
    (:func:`railval.core.names.check_name`) that does not exist yet unless ``replace``.
    Returns the existing configuration (when replacing) or ``None``. Callers that compute
    for minutes call it before computing, so a clash is reported at once."""
    check_name(name, "configuration name")
    c = campaign_ref(session, campaign)
    existing = session.scalar(
        select(Configuration).where(Configuration.campaign_id == c.id, Configuration.name == name)
    )
    if existing is not None and not replace:
        raise InvalidParameter(f"configuration {name!r} already exists in campaign {c.name!r}; "
                               "choose another name, or overwrite it with --replace")
    return existing


def store_configuration(
    session: Session,
    campaign: CampaignArg,
    name: str,
    *,
    parent: ConfigArg | None,
    effects: dict[str, Any],
    parameters: dict[str, Any],
    description: str,
    signalsets: Mapping[str, SignalSet],
    replace: bool = False,
    calibration: dict[str, Any] | None = None,
) -> Configuration:
    """Store a configuration (e.g. a simulation result) with its signals.

    ``name`` is the new configuration's name, ``parent`` the configuration it derives from.
    ``signalsets`` maps section id → :class:`SignalSet`. Everything is checked before
    anything is added, with the importer's rules (:func:`railval.db.checks.check_recording`):
    known sections and channels, equal lengths, finite values, equally spaced time at the
    set's ``fs``, strictly increasing distance. ``replace=True`` overwrites an existing
    configuration of that name in place (its id and children are kept). Fills each set's
    ``hashes``. ``calibration``: how a calibrated configuration was fitted (fit and held-out
    section ids, fitted parameters), stored in ``Configuration.calibration``. Raises
    :class:`InvalidSignal`, :class:`NotFound` or :class:`railval.core.errors.InvalidParameter`.
    """
    check_name(name, "configuration name")
    c = campaign_ref(session, campaign)
    sections, chans = _checked_sources(session, c, name, signalsets)
    parent_row = get_configuration(session, c, parent) if parent is not None else None
    existing = check_new_configuration(session, c, name, replace=replace)
    if (parent_row is not None and existing is not None
            and existing.id in {x.id for x in lineage(session, c, parent_row.name)}):
        raise InvalidParameter(f"configuration {name!r} cannot have {parent_row.name!r} as "
                                   "parent: that would make a cycle in the lineage")
    before = configuration_state(session, existing) if existing is not None else None
    record = {"parent_id": parent_row.id if parent_row is not None else None,
              "effects": dict(effects), "parameters": dict(parameters), "description": description,
              "calibration": dict(calibration) if calibration is not None else None}
    if existing is not None:
        session.execute(delete(Recording).where(Recording.configuration_id == existing.id))
        session.expire(existing, ["recordings"])
        conf = existing
        for key, value in record.items():
            setattr(conf, key, value)
        conf.created_at = utcnow()
    else:
        conf = Configuration(campaign_id=c.id, name=name, **record)
        session.add(conf)
    stamp = dt.datetime.now(dt.UTC).isoformat()
    items = []
    for sid, ss in signalsets.items():
        prov = {ch: {"source": "store_configuration", "configuration": name, "stored_at": stamp}
                for ch in ss.channels}
        items.append((sections[sid], conf, ss, prov))
    add_recordings(session, items, chans)
    session.flush()
    audit.record(session, audit.actor_of(session),
                 "configuration.replace" if before is not None else "configuration.store",
                 f"configuration:{c.name}/{name}", before, configuration_state(session, conf),
                 detail={"parent": config_name(parent), "effects": sorted(effects)})
    return conf


def _checked_sources(session: Session, c: CampaignRef, name: str,
                     signalsets: Mapping[str, SignalSet]) -> tuple[dict[str, Section], dict[str, Channel]]:
    """(section id → row, channel name → row) of campaign ``c`` after checking every signal set
    of configuration ``name`` with the importer's rules
    (:func:`railval.db.checks.check_recording`); raises naming configuration, section, field."""
    if not signalsets:
        raise InvalidSignal(f"configuration {name!r}: no signal sets given")
    sections = {
        s.section_id: s for s in session.scalars(select(Section).where(Section.campaign_id == c.id))
    }
    chans = {ch.name: ch for ch in channels(session, c)}
    for sid, ss in signalsets.items():
        if sid not in sections:
            raise NotFound(f"configuration {name!r}: section {sid!r} is not in campaign "
                           f"{c.name!r} (sections: {sorted(sections)})")
        try:
            fs = check_recording(ss.time_s, ss.distance_m, ss.channels, chans)
        except RecordingProblem as exc:
            raise InvalidSignal(f"configuration {name!r}, section {sid!r}, field {exc.field}: "
                                f"{exc}") from None
        if not np.isclose(fs, ss.fs, rtol=1e-6):
            raise InvalidSignal(f"configuration {name!r}, section {sid!r}: fs is {ss.fs} Hz but "
                                f"time_s is sampled at {fs} Hz")
    return sections, chans


def configuration_state(session: Session, conf: Configuration) -> dict[str, Any]:
    """What the audit trail's before/after hash of a configuration covers: parent, effects,
    parameters, description and every signal's content hash (no blob is read)."""
    parent = session.get(Configuration, conf.parent_id).name if conf.parent_id else None
    rows = session.execute(
        select(Section.section_id, Recording.distance_sha256, Channel.name, Signal.sha256)
        .join(Recording, Signal.recording_id == Recording.id)
        .join(Section, Recording.section_id == Section.id)
        .join(Channel, Signal.channel_id == Channel.id)
        .where(Recording.configuration_id == conf.id)
    )
    signals: dict[str, dict[str, str]] = {}
    for sid, dsha, chan, sha in rows:
        signals.setdefault(sid, {"distance_m": dsha})[chan] = sha
    return {"parent": parent, "effects": _jsonable(conf.effects),
            "parameters": _jsonable(conf.parameters), "description": conf.description,
            "signals": signals}


def _jsonable(obj: Any) -> Any:
    """A JSON document with non-finite floats written as strings (canonical JSON refuses them)."""
    if isinstance(obj, float) and not np.isfinite(obj):
        return repr(obj)
    if isinstance(obj, Mapping):
        return {str(k): _jsonable(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [_jsonable(v) for v in obj]
    return obj


def delete_configuration(session: Session, campaign: CampaignArg, config: ConfigArg, *,
                         reason: str = "") -> None:
    """Delete configuration ``config`` with its recordings (children keep no parent); audited."""
    c = campaign_ref(session, campaign)
    conf = get_configuration(session, c, config)
    name = conf.name
    before = configuration_state(session, conf)
    session.delete(conf)
    session.flush()
    audit.record(session, audit.actor_of(session), "configuration.delete",
                 f"configuration:{c.name}/{name}", before, None, reason)
