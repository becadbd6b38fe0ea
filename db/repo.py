"""Repository: the functions the rest of railval calls to read and write the database.

All functions take an open :class:`sqlalchemy.orm.Session` (from
:meth:`railval.db.engine.Database.session`, which commits or rolls back the unit of work) and a
campaign given as a :class:`railval.db.models.Campaign`, its name or its id.

Reading signals is a hot path (≈ 50 000 comparisons for a DynoTRAIN-size campaign):
:func:`load_signalsets` issues one SQL query per call, whatever the number of sections and
channels, and :func:`signal_hashes` reads hashes without touching the blobs.
"""

from __future__ import annotations

import datetime as dt
import logging
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from sqlalchemy import String, cast, delete, func, insert, literal, null, or_, select, union_all
from sqlalchemy.orm import Session

from railval.core.errors import InvalidSignal, NotFound
from railval.core.names import check_name
from railval.core.types import SectionInfo, SignalSet
from railval.core.zones import zone_for_radius
from railval.db import audit, codec, integrity
from railval.db.checks import RecordingProblem, check_recording
from railval.db.models import (
    Campaign,
    Channel,
    Configuration,
    Recording,
    ResultCache,
    Section,
    Signal,
    Vehicle,
    utcnow,
)

_log = logging.getLogger(__name__)

__all__ = [
    "CampaignRef",
    "ConfigRef",
    "add_recordings",
    "cache_delete",
    "cache_get",
    "cache_get_many",
    "cache_put",
    "cache_put_many",
    "campaign_summary",
    "channels",
    "check_new_configuration",
    "configuration_state",
    "delete_campaign",
    "delete_configuration",
    "fetch_signalsets",
    "get_campaign",
    "get_configuration",
    "lineage",
    "list_campaigns",
    "list_configurations",
    "load_signalsets",
    "recording_meta",
    "resolve",
    "section_infos",
    "signal_hashes",
    "source_hashes",
    "store_configuration",
    "stored_blobs",
    "vehicle_info",
    "verify_database",
    "verify_evidence",
    "verify_signals",
]


# -- references --------------------------------------------------------------------------
@dataclass(frozen=True)
class CampaignRef:
    """A campaign resolved once at the entrance (:func:`resolve`): its id and name. Every
    function of this module takes it where it takes a campaign, without another lookup."""

    id: int
    name: str


@dataclass(frozen=True)
class ConfigRef:
    """A configuration of a campaign resolved once (:func:`resolve`). Functions that take a
    configuration name (``config``) take this too, without another lookup."""

    campaign: CampaignRef
    id: int
    name: str


def resolve(session: Session, campaign: Campaign | CampaignRef | str | int,
            config: str | ConfigRef | None = None) -> tuple[CampaignRef, ConfigRef | None]:
    """The campaign (and configuration ``config``, when given) as references; raises
    :class:`NotFound` naming what is available."""
    c = get_campaign(session, campaign)
    ref = CampaignRef(c.id, c.name)
    if config is None:
        return ref, None
    if isinstance(config, ConfigRef):
        return ref, config
    conf = get_configuration(session, c, config)
    return ref, ConfigRef(ref, conf.id, conf.name)


def _config_name(config: str | ConfigRef | None) -> str | None:
    return config.name if isinstance(config, ConfigRef) else config


# -- campaigns ---------------------------------------------------------------------------
def list_campaigns(session: Session) -> list[Campaign]:
    """All campaigns, ordered by name."""
    return list(session.scalars(select(Campaign).order_by(Campaign.name)))


def get_campaign(session: Session, name_or_id: Campaign | CampaignRef | str | int) -> Campaign:
    """The campaign with this name (or, failing that, this numeric id; or a :class:`CampaignRef`).

    Raises :class:`railval.core.errors.NotFound` saying how to list the campaigns (it does
    not list them: whoever mistyped a name is not shown the others).
    """
    if isinstance(name_or_id, Campaign):
        return name_or_id
    if isinstance(name_or_id, CampaignRef):
        return session.get(Campaign, name_or_id.id)
    found = session.scalar(select(Campaign).where(Campaign.name == str(name_or_id)))
    if found is None and str(name_or_id).strip().isdigit():
        found = session.get(Campaign, int(name_or_id))
    if found is None:
        # the names of the other campaigns are not shown to whoever typed a wrong one
        raise NotFound(f"campaign {name_or_id!r} not found; list the campaigns with "
                       "`railval list`")
    return found


def _campaign_id(session: Session, campaign: Campaign | CampaignRef | str | int) -> int:
    if isinstance(campaign, (Campaign, CampaignRef)):
        return campaign.id
    return get_campaign(session, campaign).id


def section_infos(session: Session, campaign: Campaign | str | int) -> list[SectionInfo]:
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


def section_layouts(session: Session, campaign: Campaign | str | int) -> dict[str, dict | None]:
    """section id → the optional ``layout`` record of the manifest (built-in simulator)."""
    cid = _campaign_id(session, campaign)
    rows = session.execute(
        select(Section.section_id, Section.layout).where(Section.campaign_id == cid).order_by(Section.id)
    )
    return {sid: layout for sid, layout in rows}


def vehicle_info(session: Session, campaign: Campaign | str | int) -> dict[str, Any]:
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


def channels(session: Session, campaign: Campaign | str | int) -> list[Channel]:
    """The campaign's declared channels in manifest order."""
    cid = _campaign_id(session, campaign)
    return list(session.scalars(select(Channel).where(Channel.campaign_id == cid).order_by(Channel.id)))


# -- configurations ----------------------------------------------------------------------
def list_configurations(session: Session, campaign: Campaign | str | int) -> list[Configuration]:
    """The campaign's configurations in creation order."""
    cid = _campaign_id(session, campaign)
    return list(
        session.scalars(
            select(Configuration).where(Configuration.campaign_id == cid).order_by(Configuration.id)
        )
    )


def get_configuration(session: Session, campaign: Campaign | CampaignRef | str | int,
                      name: str | ConfigRef) -> Configuration:
    """The configuration ``name``; :class:`NotFound` lists the available ones."""
    if isinstance(name, ConfigRef):
        return session.get(Configuration, name.id)
    c = get_campaign(session, campaign)
    found = session.scalar(
        select(Configuration).where(Configuration.campaign_id == c.id, Configuration.name == name)
    )
    if found is None:
        names = [x.name for x in list_configurations(session, c)]
        raise NotFound(
            f"configuration {name!r} not found in campaign {c.name!r}; available: "
            f"{', '.join(names) or '(none)'}"
        )
    return found


def lineage(session: Session, campaign: Campaign | str | int, name: str) -> list[Configuration]:
    """The chain of parents of configuration ``name``, root first, ``name`` last."""
    conf = get_configuration(session, campaign, name)
    chain = [conf]
    seen = {conf.id}
    while chain[-1].parent_id is not None:
        parent = session.get(Configuration, chain[-1].parent_id)
        if parent is None or parent.id in seen:  # pragma: no cover - FK and checks prevent it
            break
        seen.add(parent.id)
        chain.append(parent)
    return chain[::-1]


def add_recordings(
    session: Session,
    items: list[tuple[Section, Configuration | None, SignalSet, dict[str, dict[str, Any]]]],
    channel_rows: Mapping[str, Channel],
) -> None:
    """Encode and insert already checked recordings with their signals (fills ``hashes``).

    ``items``: (section, configuration or None for the measurement, signal set, channel →
    provenance). Recordings go through the ORM; the signals are one bulk INSERT.
    """
    recs = []
    for section, configuration, ss, _prov in items:
        dblob, dsha = codec.encode(np.asarray(ss.distance_m, dtype=np.float64))
        rec = Recording(section=section, configuration=configuration, fs=float(ss.fs),
                        t0=float(ss.time_s[0]), n=len(ss), distance_blob=dblob,
                        distance_sha256=dsha, source_file="")
        session.add(rec)
        recs.append(rec)
    session.flush()
    secret = integrity.session_secret(session)
    rows = []
    for rec, (section, conf, ss, prov) in zip(recs, items, strict=True):
        ss.hashes = {}
        for name, values in ss.channels.items():
            a = np.asarray(values, dtype=np.float64)
            blob, sha = codec.encode(a)
            ss.hashes[name] = sha
            cid = channel_rows[name].id
            seal = integrity.seal_signal(
                secret, rec.id, cid, sha, rec.distance_sha256, rec.fs, rec.t0, rec.n,
                names=(section.campaign.name, section.section_id,
                       conf.name if conf is not None else "", name))
            rows.append({"recording_id": rec.id, "channel_id": cid,
                         "blob": blob, "dtype": a.dtype.str, "sha256": sha,
                         "provenance": {**dict(prov.get(name, {})), "seal": seal}})
    if rows:
        session.execute(insert(Signal), rows)


def check_new_configuration(session: Session, campaign: Campaign | str | int, name: str, *,
                            replace: bool = False) -> Configuration | None:
    """Check that configuration ``name`` may be stored: a safe name
    (:func:`railval.core.names.check_name`) that does not exist yet unless ``replace``.
    Returns the existing configuration (when replacing) or ``None``. Callers that compute
    for minutes call it before computing, so a clash is reported at once."""
    from railval.core.errors import InvalidParameter

    check_name(name, "configuration name")
    c = get_campaign(session, campaign)
    existing = session.scalar(
        select(Configuration).where(Configuration.campaign_id == c.id, Configuration.name == name)
    )
    if existing is not None and not replace:
        raise InvalidParameter(f"configuration {name!r} already exists in campaign {c.name!r}; "
                               "choose another name, or overwrite it with --replace")
    return existing


def store_configuration(
    session: Session,
    campaign: Campaign | str | int,
    name: str,
    *,
    parent: str | None,
    effects: dict[str, Any],
    parameters: dict[str, Any],
    description: str,
    signalsets: Mapping[str, SignalSet],
    replace: bool = False,
    calibration: dict[str, Any] | None = None,
) -> Configuration:
    """Store a configuration (e.g. a simulation result) with its signals.

    ``signalsets`` maps section id → :class:`SignalSet`. Everything is checked before
    anything is added, with the importer's rules (:func:`railval.db.checks.check_recording`):
    known sections and channels, equal lengths, finite values, equally spaced time at the
    set's ``fs``, strictly increasing distance. ``replace=True`` overwrites an existing
    configuration of that name in place (its id and children are kept). Fills each set's
    ``hashes``. ``calibration``: how a calibrated configuration was fitted (fit and held-out
    section ids, fitted parameters), stored in ``Configuration.calibration``. Raises
    :class:`InvalidSignal`, :class:`NotFound` or :class:`railval.core.errors.InvalidParameter`.
    """
    from railval.core.errors import InvalidParameter

    check_name(name, "configuration name")
    c = get_campaign(session, campaign)
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
    parent_row = get_configuration(session, c, parent) if parent is not None else None
    existing = check_new_configuration(session, c, name, replace=replace)
    if parent_row is not None and existing is not None:
        ids = {x.id for x in lineage(session, c, parent_row.name)}
        if existing.id in ids:
            raise InvalidParameter(f"configuration {name!r} cannot have {parent!r} as parent: "
                                   "that would make a cycle in the lineage")
    before = configuration_state(session, existing) if existing is not None else None
    if existing is not None:
        session.execute(delete(Recording).where(Recording.configuration_id == existing.id))
        session.expire(existing, ["recordings"])
        conf = existing
        conf.parent_id = parent_row.id if parent_row is not None else None
        conf.effects, conf.parameters, conf.description = dict(effects), dict(parameters), description
        conf.calibration = dict(calibration) if calibration is not None else None
        conf.created_at = utcnow()
    else:
        conf = Configuration(
            campaign_id=c.id, name=name, parent_id=parent_row.id if parent_row else None,
            effects=dict(effects), parameters=dict(parameters), description=description,
            calibration=dict(calibration) if calibration is not None else None,
        )
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
                 detail={"parent": parent, "effects": sorted(effects)})
    return conf


def source_hashes(session: Session, campaign: Campaign | str | int,
                  config: str | None = None) -> dict[str, dict[str, str]]:
    """Section id → {``distance_m``: hash of the distance axis, channel: content hash} of the
    measurement (``config=None``) or a configuration; reads no blob."""
    c = get_campaign(session, campaign)
    if config is not None:
        get_configuration(session, c, config)
    out: dict[str, dict[str, str]] = {}
    for sid, dsha in session.execute(
        select(Section.section_id, Recording.distance_sha256)
        .join(Section, Recording.section_id == Section.id)
        .where(Section.campaign_id == c.id, _source_filter(session, c.id, config))
        .order_by(Section.id)
    ):
        out[sid] = {"distance_m": dsha}
    for sid, chans in signal_hashes(session, c, config).items():
        out.setdefault(sid, {}).update(chans)
    return out


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


def delete_configuration(session: Session, campaign: Campaign | str | int, name: str, *,
                         reason: str = "") -> None:
    """Delete configuration ``name`` with its recordings (children keep no parent); audited."""
    c = get_campaign(session, campaign)
    conf = get_configuration(session, c, name)
    before = configuration_state(session, conf)
    session.delete(conf)
    session.flush()
    audit.record(session, audit.actor_of(session), "configuration.delete",
                 f"configuration:{c.name}/{name}", before, None, reason)


def delete_campaign(session: Session, campaign: Campaign | str | int, *, reason: str = "") -> None:
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


# -- signals -----------------------------------------------------------------------------
def _source_filter(session: Session, cid: int, config: str | ConfigRef | None):
    if config is None:
        return Recording.configuration_id.is_(None)
    if isinstance(config, ConfigRef):
        return Recording.configuration_id == config.id
    sub = (
        select(Configuration.id)
        .where(Configuration.campaign_id == cid, Configuration.name == config)
        .scalar_subquery()
    )
    return Recording.configuration_id == sub


def load_signalsets(
    session: Session,
    campaign: Campaign | str | int,
    config: str | None = None,
    sections: list[str] | None = None,
    channels: list[str] | None = None,
    *,
    verify: bool = False,
) -> dict[str, SignalSet]:
    """Section id → :class:`SignalSet` of the measurement (``config=None``) or a configuration.

    ``sections``/``channels`` restrict what is read. ``verify=True`` recomputes every
    content hash while decoding (about 10–30 % slower) and raises
    :class:`railval.core.errors.InvalidSignal` on a mismatch. Raises :class:`NotFound` for an
    unknown configuration, section or channel. One SQL query: see :func:`fetch_signalsets`.
    """
    return fetch_signalsets(session, campaign, config, sections, channels, verify=verify)()


def fetch_signalsets(
    session: Session,
    campaign: Campaign | str | int,
    config: str | None = None,
    sections: list[str] | None = None,
    channels: list[str] | None = None,
    *,
    verify: bool = False,
) -> Callable[[], dict[str, SignalSet]]:
    """Read the blobs of :func:`load_signalsets` now; return the function that decodes them.

    The returned function uses no database session, so another thread may call it (the
    validation service decodes and processes one chunk of sections in a worker thread
    while this thread reads the next). Unknown names raise :class:`NotFound` here.

    One SQL query (a UNION ALL of the recordings' distance axes and the signal blobs,
    selecting only the columns decoded) executed through SQLAlchemy Core; rows are put in
    recording, then channel-name order in Python, because an SQL ``ORDER BY`` over the blob
    columns made SQLite copy every blob into a temporary sort B-tree (3–4× the time of the
    read itself on the benchmark database).
    """
    c = get_campaign(session, campaign)
    src = _source_filter(session, c.id, config)
    sec_filter = [Section.section_id.in_(sections)] if sections is not None else []
    rec_q = (
        select(
            Section.section_id, Recording.id, Recording.fs, Recording.t0, Recording.n,
            cast(null(), String).label("channel"), Recording.distance_blob.label("blob"),
            Recording.distance_sha256.label("sha"), literal(0).label("is_signal"),
        )
        .join(Section, Recording.section_id == Section.id)
        .where(Section.campaign_id == c.id, src, *sec_filter)
    )
    sig_q = (
        select(
            Section.section_id, Recording.id, Recording.fs, Recording.t0, Recording.n,
            Channel.name, Signal.blob, Signal.sha256, literal(1),
        )
        .join(Recording, Signal.recording_id == Recording.id)
        .join(Section, Recording.section_id == Section.id)
        .join(Channel, Signal.channel_id == Channel.id)
        .where(Section.campaign_id == c.id, src, *sec_filter)
    )
    if channels is not None:
        sig_q = sig_q.where(Channel.name.in_(channels))
    rows = session.connection().execute(union_all(rec_q, sig_q)).all()
    rows.sort(key=lambda r: (r[1], r[8], r[5] or ""))
    present: dict[str, list[str]] = {}
    for r in rows:
        chans = present.setdefault(r[0], [])
        if r[8]:
            chans.append(r[5])
    _check_requested(session, c, config, present, sections, channels)

    cname = c.name

    def decode_all() -> dict[str, SignalSet]:
        out: dict[str, SignalSet] = {}
        decode = codec.decode
        for sid, _rid, fs, t0, n, chan, blob, sha, is_signal in rows:
            try:
                if not is_signal:
                    dist = decode(blob, sha if verify else None)
                    out[sid] = SignalSet(fs=float(fs),
                                         time_s=t0 + np.arange(n, dtype=np.float64) / fs,
                                         distance_m=dist)
                else:
                    ss = out[sid]
                    ss.channels[chan] = decode(blob, sha if verify else None)
                    ss.hashes[chan] = sha
            except InvalidSignal as exc:
                src = "measurement" if config is None else f"configuration {config!r}"
                raise InvalidSignal(f"campaign {cname!r}, {src}, section {sid!r}, "
                                    f"{chan or 'distance_m'}: {exc}; check the database with "
                                    "`railval verify`") from None
        return out

    return decode_all


def _check_requested(session: Session, c: Campaign, config: str | None,
                     out: Mapping[str, list[str]], sections: list[str] | None,
                     channel_names: list[str] | None) -> None:
    # Only the error paths run further queries, to explain what is missing.
    if config is not None and not out:
        get_configuration(session, c, config)
    if sections is not None:
        missing = [s for s in sections if s not in out]
        if missing:
            known = [s.id for s in section_infos(session, c)]
            src = "the measurement" if config is None else f"configuration {_config_name(config)!r}"
            unknown = [s for s in missing if s not in known]
            what = (f"unknown section(s) {unknown}; sections: {known}" if unknown
                    else f"{src} has no recording of section(s) {missing}")
            raise NotFound(f"campaign {c.name!r}: {what}")
    if channel_names is not None:
        seen = {ch for chans in out.values() for ch in chans}
        missing = [ch for ch in channel_names if ch not in seen]
        if missing:
            known = [ch.name for ch in channels(session, c)]
            unknown = [ch for ch in missing if ch not in known]
            if unknown:
                raise NotFound(f"campaign {c.name!r}: unknown channel(s) {unknown}; "
                               f"channels: {known}")


def signal_hashes(
    session: Session, campaign: Campaign | str | int, config: str | None = None
) -> dict[str, dict[str, str]]:
    """Section id → channel → SHA-256 content hash, without reading any blob."""
    c = get_campaign(session, campaign)
    rows = session.execute(
        select(Section.section_id, Channel.name, Signal.sha256)
        .join(Recording, Signal.recording_id == Recording.id)
        .join(Section, Recording.section_id == Section.id)
        .join(Channel, Signal.channel_id == Channel.id)
        .where(Section.campaign_id == c.id, _source_filter(session, c.id, config))
        .order_by(Section.id, Channel.id)
    )
    out: dict[str, dict[str, str]] = {}
    for sid, chan, sha in rows:
        out.setdefault(sid, {})[chan] = sha
    if config is not None and not out:
        get_configuration(session, c, config)
    return out


def verify_signals(session: Session, campaign: Campaign | str | int) -> list[dict[str, Any]]:
    """Decode every stored array of the campaign and check it against its SHA-256.

    Returns one record per problem (``section``, ``configuration`` or None for the
    measurement, ``channel`` or ``"distance_m"``, ``error``); an empty list means every
    sample is exactly what was imported or stored. Reads one recording at a time.
    """
    c = get_campaign(session, campaign)
    names = {x.id: x.name for x in list_configurations(session, c)}
    problems: list[dict[str, Any]] = []
    recs = session.execute(
        select(Recording.id, Section.section_id, Recording.configuration_id,
               Recording.distance_blob, Recording.distance_sha256, Recording.n)
        .join(Section, Recording.section_id == Section.id)
        .where(Section.campaign_id == c.id).order_by(Recording.id)
    ).all()
    for rid, sid, conf_id, dblob, dsha, n in recs:
        where = {"section": sid, "configuration": names.get(conf_id) if conf_id else None}
        items = [("distance_m", dblob, dsha)] + list(session.execute(
            select(Channel.name, Signal.blob, Signal.sha256)
            .join(Channel, Signal.channel_id == Channel.id).where(Signal.recording_id == rid)
        ).tuples())
        for name, blob, sha in items:
            try:
                a = codec.decode(blob, sha)
                if a.shape != (n,):
                    raise InvalidSignal(f"holds shape {a.shape}, the recording has n = {n}")
            except InvalidSignal as exc:
                problems.append({**where, "channel": name, "error": str(exc)})
    return problems


def _source_problems(session: Session, c: Campaign, config: str | None | bool,
                     secret: bytes, blobs: bool) -> list[dict[str, Any]]:
    """Seal (and with ``blobs`` content-hash) problems of one source of ``c``;
    ``config=True`` means every source of the campaign."""
    names = {x.id: x.name for x in list_configurations(session, c)}
    rec_q = (select(Recording.id, Section.section_id, Recording.configuration_id,
                    Recording.distance_sha256, Recording.fs, Recording.t0, Recording.n)
             .join(Section, Recording.section_id == Section.id)
             .where(Section.campaign_id == c.id).order_by(Recording.id))
    if config is not True:
        rec_q = rec_q.where(_source_filter(session, c.id, config))
    recs = session.execute(rec_q).all()
    problems: list[dict[str, Any]] = []
    by_rec: dict[int, list] = {}
    if not blobs:  # seals only: one query for every signal row of the source
        meta_q = (select(Signal.recording_id, Channel.name, Signal.channel_id, Signal.sha256,
                         Signal.provenance)
                  .join(Channel, Signal.channel_id == Channel.id)
                  .join(Recording, Signal.recording_id == Recording.id)
                  .join(Section, Recording.section_id == Section.id)
                  .where(Section.campaign_id == c.id).order_by(Signal.recording_id, Channel.id))
        if config is not True:
            meta_q = meta_q.where(_source_filter(session, c.id, config))
        for r in session.execute(meta_q):
            by_rec.setdefault(r[0], []).append(tuple(r[1:]))
    for rid, sid, conf_id, dsha, fs, t0, n in recs:
        where = {"section": sid, "configuration": names.get(conf_id) if conf_id else None}
        if blobs:
            rows = session.execute(
                select(Channel.name, Signal.channel_id, Signal.sha256, Signal.provenance,
                       Signal.blob)
                .join(Channel, Signal.channel_id == Channel.id)
                .where(Signal.recording_id == rid).order_by(Channel.id)).all()
        else:
            rows = by_rec.get(rid, [])
        if blobs:
            dblob = session.scalar(select(Recording.distance_blob).where(Recording.id == rid))
            try:
                a = codec.decode(dblob, dsha)
                if a.shape != (n,):
                    raise InvalidSignal(f"holds shape {a.shape}, the recording has n = {n}")
            except InvalidSignal as exc:
                problems.append({**where, "channel": "distance_m", "error": str(exc)})
        for row in rows:
            name, cid, sha, prov = row[0], row[1], row[2], row[3] or {}
            seal = prov.get("seal") if isinstance(prov, dict) else None
            if seal is None:
                problems.append({**where, "channel": name, "error": "has no seal (stored "
                                 "outside railval, or before seals existed)"})
            elif not integrity.check_signal_seal(
                    secret, seal, rid, cid, sha, dsha, fs, t0, n,
                    (c.name, sid, where["configuration"] or "", name)):
                problems.append({**where, "channel": name, "error": "fails its seal: the "
                                 "samples, their hash, the recording or its place (campaign, "
                                 "section, configuration, channel) were changed outside "
                                 "railval"})
            if blobs:
                try:
                    a = codec.decode(row[4], sha)
                    if a.shape != (n,):
                        raise InvalidSignal(f"holds shape {a.shape}, the recording has n = {n}")
                except InvalidSignal as exc:
                    problems.append({**where, "channel": name, "error": str(exc)})
    return problems


def verify_evidence(session: Session, campaign: Campaign | str | int, config: str, *,
                    blobs: bool = True) -> list[dict[str, Any]]:
    """Check what a verdict on configuration ``config`` rests on — the measurement's and the
    configuration's signals: every seal (:mod:`railval.db.integrity`) and, with ``blobs``,
    every content hash. Returns one record per problem (``section``, ``configuration``,
    ``channel``, ``error``); empty when the evidence is intact. Reports and sign-offs call it
    before they state a verdict."""
    c = get_campaign(session, campaign)
    get_configuration(session, c, config)
    secret = integrity.session_secret(session)
    return (_source_problems(session, c, None, secret, blobs)
            + _source_problems(session, c, config, secret, blobs))


def require_evidence(session: Session, campaign: Campaign | str | int, config: str, *,
                     blobs: bool = True) -> None:
    """:func:`verify_evidence`, raising :class:`railval.db.integrity.IntegrityError` that names
    the first problems and how many there are."""
    problems = verify_evidence(session, campaign, config, blobs=blobs)
    if problems:
        first = "; ".join(f"section {p['section']}, "
                          f"{'configuration ' + repr(p['configuration']) if p['configuration'] else 'measurement'}, "
                          f"{p['channel']}: {p['error']}" for p in problems[:3])
        raise integrity.IntegrityError(
            f"the evidence of {config!r} is not intact ({len(problems)} problem(s)): {first}; "
            "check the database with `railval verify`")


def verify_database(session: Session, *, blobs: bool = True) -> dict[str, Any]:
    """Check a whole database: every signal's seal and (``blobs``) content hash, every
    distance axis, and every result-cache entry's seal. Returns ``{"ok", "campaigns":
    {name: [problem, ...]}, "signals": n, "cache_entries": n, "cache_unauthentic": [keys]}``.
    An unauthentic cache entry is never used (it is recomputed); it is listed because
    someone wrote it without the server secret."""
    secret = integrity.session_secret(session)
    out: dict[str, Any] = {"campaigns": {}, "signals": 0}
    for c in list_campaigns(session):
        out["campaigns"][c.name] = _source_problems(session, c, True, secret, blobs)
    out["signals"] = int(session.scalar(select(func.count(Signal.id))) or 0)
    bad: list[str] = []
    n = 0
    for k, v in session.execute(select(ResultCache.key, ResultCache.value)):
        n += 1
        if integrity.open_cache_value(secret, k, bytes(v)) is None:
            bad.append(k)
    out["cache_entries"] = n
    out["cache_unauthentic"] = bad
    out["ok"] = not bad and not any(out["campaigns"].values())
    return out


def count_signals(session: Session, campaign: Campaign | str | int) -> int:
    """Number of stored arrays of the campaign (signals plus distance axes)."""
    cid = _campaign_id(session, campaign)
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
    from railval.db.models import Base

    return {
        name: int(session.scalar(select(func.count()).select_from(table)) or 0)
        for name, table in sorted(Base.metadata.tables.items())
    }


# -- result cache ------------------------------------------------------------------------
def cache_get(session: Session, key: str) -> bytes | None:
    """The cached bytes under ``key``, or ``None`` (also when the stored value fails its
    seal: :mod:`railval.db.integrity`)."""
    return cache_get_many(session, [key]).get(key)


def cache_get_many(session: Session, keys: list[str], chunk: int = 500) -> dict[str, bytes]:
    """``key → bytes`` of the keys present and authentic (one query per ``chunk`` keys).

    A value whose seal does not match (copied from another key, edited, or written without
    the server secret) is left out, so the caller computes it again; it is logged.
    """
    secret = integrity.session_secret(session)
    out: dict[str, bytes] = {}
    bad = 0
    for i in range(0, len(keys), chunk):
        part = list(keys[i:i + chunk])
        for k, v in session.execute(select(ResultCache.key, ResultCache.value)
                                    .where(ResultCache.key.in_(part))):
            payload = integrity.open_cache_value(secret, k, bytes(v))
            if payload is None:
                bad += 1
            else:
                out[k] = payload
    if bad:
        _log.warning("%d result-cache entries failed their seal and are recomputed", bad)
    return out


def cache_put(session: Session, key: str, value: bytes) -> None:
    """Insert or overwrite ``key`` (one atomic upsert on SQLite and PostgreSQL)."""
    cache_put_many(session, {key: value})


def cache_delete(session: Session, *, keys: Sequence[str] | None = None, prefix: str | None = None) -> int:
    """Delete the cached entries under ``keys`` and/or whose key starts with ``prefix``
    (e.g. ``"en14363:"``, every processed section); returns how many were deleted."""
    conditions = []
    if keys is not None:
        conditions.append(ResultCache.key.in_(list(keys)))
    if prefix is not None:
        conditions.append(ResultCache.key.startswith(prefix, autoescape=True))
    if not conditions:
        return 0
    return int(session.execute(delete(ResultCache).where(or_(*conditions))).rowcount or 0)


#: keys per bulk cache read (SQL IN list)
CACHE_CHUNK = 500


def cache_put_many(session: Session, items: Mapping[str, bytes]) -> None:
    """Insert or overwrite every ``key → value`` of ``items`` in one executemany upsert."""
    if not items:
        return
    dialect = session.get_bind().dialect.name
    if dialect == "postgresql":
        from sqlalchemy.dialects.postgresql import insert
    elif dialect == "sqlite":
        from sqlalchemy.dialects.sqlite import insert
    else:  # pragma: no cover - connect() only admits these two
        raise NotImplementedError(dialect)
    stmt = insert(ResultCache)
    stmt = stmt.on_conflict_do_update(
        index_elements=[ResultCache.key],
        set_={"value": stmt.excluded.value, "created_at": stmt.excluded.created_at},
    )
    now = utcnow()
    secret = integrity.session_secret(session)
    rows = [{"key": k, "value": integrity.seal_cache_value(secret, k, bytes(v)), "created_at": now}
            for k, v in items.items()]
    if dialect == "sqlite" and not session.get_bind().get_execution_options().get("railval_write"):
        # a read unit of work that caches what it computed: on SQLite its deferred
        # transaction cannot wait for another writer, and a cache entry is worth no error —
        # skip it (it is computed again next time)
        from sqlalchemy.exc import OperationalError

        try:
            session.connection().execute(stmt, rows)
        except OperationalError as exc:
            if "locked" not in str(exc.orig) and "busy" not in str(exc.orig):
                raise
            _log.info("result cache not written (database busy): %d entries", len(rows))
        return
    session.connection().execute(stmt, rows)


# -- summaries ---------------------------------------------------------------------------
def stored_blobs(session: Session) -> list[tuple[bytes, str]]:
    """Every stored signal blob with its SHA-256 content hash (storage benchmarks)."""
    return [(bytes(b), h) for b, h in session.execute(select(Signal.blob, Signal.sha256))]


def recording_meta(session: Session, campaign: Campaign | CampaignRef | str | int,
                   config: str | ConfigRef | None = None) -> dict[str, tuple[str, float, int]]:
    """Section id → (distance-axis SHA-256, fs, n) of the recordings of the measurement
    (``config=None``) or a configuration; no blob is read."""
    cid = _campaign_id(session, campaign)
    q = (select(Section.section_id, Recording.distance_sha256, Recording.fs, Recording.n)
         .join(Section, Recording.section_id == Section.id)
         .where(Section.campaign_id == cid, _source_filter(session, cid, config)))
    return {sid: (sha, float(fs), int(n)) for sid, sha, fs, n in session.execute(q)}


def campaign_summary(session: Session, campaign: Campaign | CampaignRef | str | int) -> dict[str, Any]:
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
