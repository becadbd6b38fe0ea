"""Checking the seals of stored signals: every signal's seal (:mod:`railval.db.integrity`) and content
hash, per campaign, per configuration (what a verdict rests on) or for the whole database.

``campaign`` is a :data:`railval.db.campaigns.CampaignArg` and ``config`` a
:data:`railval.db.campaigns.ConfigArg`.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from sqlalchemy import func, or_, select
from sqlalchemy.orm import Session

from railval.core.errors import InvalidSignal
from railval.db import codec, integrity
from railval.db.campaigns import (
    CampaignArg,
    CampaignRef,
    ConfigArg,
    ConfigRef,
    campaign_ref,
    config_name,
    get_campaign,
    get_configuration,
    list_campaigns,
    list_configurations,
)
from railval.db.models import Campaign, Channel, Recording, ResultCache, Section, Signal
from railval.db.signals import source_filter


def _decode_problem(blob: bytes, sha: str, n: int) -> str | None:
    """Why a stored array fails its content hash or its recording's length, or ``None``."""
    try:
        a = codec.decode(blob, sha)
    except InvalidSignal as exc:
        return str(exc)
    return _shape_problem(a, n)


def _shape_problem(a, n: int) -> str | None:
    return None if a.shape == (n,) else f"holds shape {a.shape}, the recording has n = {n}"


def _decode_problems(items: list[tuple[str, bytes, str]], n: int) -> dict[str, str]:
    """Name → why, for the ``(name, blob, sha)`` of one recording that fail their content hash
    or its length: all decoded at once on the row threads (:func:`codec.decode_many`); only
    when one fails is each decoded alone, to name every failing one."""
    try:
        arrays = codec.decode_many([(blob, sha) for _, blob, sha in items])
    except InvalidSignal:
        found = {name: _decode_problem(blob, sha, n) for name, blob, sha in items}
    else:
        found = {name: _shape_problem(a, n) for (name, _, _), a in zip(items, arrays, strict=True)}
    return {name: why for name, why in found.items() if why is not None}


def verify_signals(session: Session, campaign: CampaignArg) -> list[dict[str, Any]]:
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
        for name, why in _decode_problems(items, n).items():
            problems.append({**where, "channel": name, "error": why})
    return problems


def _source_problems(session: Session, c: Campaign | CampaignRef, config: ConfigArg | None | bool,
                     secret: bytes, blobs: bool) -> list[dict[str, Any]]:
    """Seal (and with ``blobs`` content-hash) problems of one source of ``c``;
    ``config=True`` means every source of the campaign."""
    names = {x.id: x.name for x in list_configurations(session, c)}
    cond = None if config is True else source_filter(session, c.id, config)
    if not blobs:  # seals only: one query for the recordings, one for every signal row
        if secret is None:
            return []
        recs, by_rec = _seal_rows(session, c, cond)
        return _seal_problems(c, names, recs, by_rec, secret)
    rec_q = (select(Recording.id, Section.section_id, Recording.configuration_id,
                    Recording.distance_sha256, Recording.fs, Recording.t0, Recording.n)
             .join(Section, Recording.section_id == Section.id)
             .where(Section.campaign_id == c.id).order_by(Recording.id))
    if cond is not None:
        rec_q = rec_q.where(cond)
    problems: list[dict[str, Any]] = []
    for rid, sid, conf_id, dsha, fs, t0, n in session.execute(rec_q).all():
        where = {"section": sid, "configuration": names.get(conf_id) if conf_id else None}
        rows = session.execute(
            select(Channel.name, Signal.channel_id, Signal.sha256, Signal.provenance,
                   Signal.blob)
            .join(Channel, Signal.channel_id == Channel.id)
            .where(Signal.recording_id == rid).order_by(Channel.id)).all()
        dblob = session.scalar(select(Recording.distance_blob).where(Recording.id == rid))
        bad = _decode_problems([("distance_m", dblob, dsha)]
                               + [(row[0], row[4], row[2]) for row in rows], n)
        if "distance_m" in bad:
            problems.append({**where, "channel": "distance_m", "error": bad["distance_m"]})
        for row in rows:
            name, cid, sha, prov = row[0], row[1], row[2], row[3] or {}
            seal = prov.get("seal") if isinstance(prov, dict) else None
            why = None if secret is None else _seal_problem(
                secret, seal, rid, cid, sha, dsha, fs, t0, n,
                (c.name, sid, where["configuration"] or "", name))
            if why is not None:
                problems.append({**where, "channel": name, "error": why})
            if name in bad:
                problems.append({**where, "channel": name, "error": bad[name]})
    return problems


_NO_SEAL = "has no seal (stored outside railval, or before seals existed)"
_BAD_SEAL = ("fails its seal: the samples, their hash, the recording or its place (campaign, "
             "section, configuration, channel) were changed outside railval")


def _seal_problem(secret: bytes, seal, rid: int, cid: int, sha: str, dsha: str, fs: float,
                  t0: float, n: int, names: tuple[str, str, str, str]) -> str | None:
    """Why one signal row fails its seal (:func:`integrity.check_signal_seal`), or ``None``."""
    if seal is None:
        return _NO_SEAL
    if not integrity.check_signal_seal(secret, seal, rid, cid, sha, dsha, fs, t0, n, names):
        return _BAD_SEAL
    return None


def _seal_rows(session: Session, c: Campaign | CampaignRef, cond) -> tuple[list, dict]:
    """The recordings (id, section id, configuration id, distance hash, fs, t0, n; by id) of
    the sources of ``c`` selected by ``cond`` (``None``: all) and recording id → (channel,
    channel id, content hash, seal) of their signals, by channel id: two queries; the seal
    is read from the provenance JSON by the database (``provenance["seal"]``, SQL NULL
    when the provenance has none or is no object), not decoded here row by row."""
    rec_q = (select(Recording.id, Section.section_id, Recording.configuration_id,
                    Recording.distance_sha256, Recording.fs, Recording.t0, Recording.n)
             .join(Section, Recording.section_id == Section.id)
             .where(Section.campaign_id == c.id).order_by(Recording.id))
    meta_q = (select(Signal.recording_id, Channel.name, Signal.channel_id, Signal.sha256,
                     Signal.provenance["seal"].as_string())
              .join(Channel, Signal.channel_id == Channel.id)
              .join(Recording, Signal.recording_id == Recording.id)
              .join(Section, Recording.section_id == Section.id)
              .where(Section.campaign_id == c.id).order_by(Signal.recording_id, Channel.id))
    if cond is not None:
        rec_q, meta_q = rec_q.where(cond), meta_q.where(cond)
    by_rec: dict[int, list] = {}
    for rid, name, cid, sha, seal in session.execute(meta_q).tuples():
        by_rec.setdefault(rid, []).append((name, cid, sha, seal))
    return session.execute(rec_q).all(), by_rec


def _seal_problems(c: Campaign | CampaignRef, names: dict[int, str], recs: list,
                   by_rec: dict[int, list], secret: bytes) -> list[dict[str, Any]]:
    """Seal problems of the signal rows ``by_rec`` of the recordings ``recs``
    (:func:`_seal_rows`), in recording and channel order; the seals of one recording are
    checked together (:func:`integrity.check_signal_seals`)."""
    problems: list[dict[str, Any]] = []
    for rid, sid, conf_id, dsha, fs, t0, n in recs:
        conf = names.get(conf_id) if conf_id else None
        rows = by_rec.get(rid, ())
        ok = iter(integrity.check_signal_seals(secret, (rid, dsha, fs, t0, n),
                                               (c.name, sid, conf or ""),
                                               [r for r in rows if r[3] is not None]))
        for name, _cid, _sha, seal in rows:
            if seal is None or not next(ok):
                problems.append({"section": sid, "configuration": conf, "channel": name,
                                 "error": _NO_SEAL if seal is None else _BAD_SEAL})
    return problems


def verify_seals(session: Session, campaign: CampaignArg, config: ConfigArg, *,
                 blobs: bool = True) -> list[dict[str, Any]]:
    """Check what a verdict on configuration ``config`` rests on — the measurement's and the
    configuration's signals: every seal (:mod:`railval.db.integrity`) and, with ``blobs``,
    every content hash. Returns one record per problem (``section``, ``configuration``,
    ``channel``, ``error``); empty when the signals are intact. Reports and sign-offs call it
    before they state a verdict."""
    c = campaign_ref(session, campaign)
    conf = get_configuration(session, c, config)
    secret = integrity.session_secret(session)
    if not blobs:  # both sources' rows from two queries (:func:`seal_rows_many`)
        names = {x.id: x.name for x in list_configurations(session, c)}
        recs, by_rec = seal_rows_many(session, c, [conf.id])
        return (_seal_problems(c, names, [r for r in recs if r[2] is None], by_rec, secret)
                + _seal_problems(c, names, [r for r in recs if r[2] is not None], by_rec,
                                 secret))
    return (_source_problems(session, c, None, secret, blobs)
            + _source_problems(session, c, config, secret, blobs))


def require_sealed(session: Session, campaign: CampaignArg, config: ConfigArg, *,
                   blobs: bool = True) -> None:
    """:func:`verify_seals`, raising :class:`railval.db.integrity.IntegrityError` that names
    the first problems and how many there are."""
    _raise_problems(config, verify_seals(session, campaign, config, blobs=blobs))


def require_sealed_many(session: Session, campaign: CampaignArg, configs: list[ConfigArg], *,
                        blobs: bool = True, rows: tuple[list, dict] | None = None) -> None:
    """:func:`require_sealed` for several configurations of one campaign, in their order,
    with the measurement's signals checked once instead of once per configuration. Seals
    only (``blobs=False``): the rows of the measurement and of every configuration are read
    by two queries in all (:func:`seal_rows_many`), or taken from ``rows`` (what
    :func:`seal_rows_many` returned for a superset of ``configs``, e.g. when the caller
    derived its cache keys from them); every row's seal is checked as before."""
    c = campaign_ref(session, campaign)
    secret = integrity.session_secret(session)
    if blobs:
        measured = _source_problems(session, c, None, secret, blobs)
        for config in configs:
            get_configuration(session, c, config)
            _raise_problems(config, measured
                            + _source_problems(session, c, config, secret, blobs))
        return
    listed = list_configurations(session, c)
    names = {x.id: x.name for x in listed}
    by_name = {x.name: x.id for x in listed}
    ids = []
    for config in configs:
        cid = config.id if isinstance(config, ConfigRef) else by_name.get(config)
        ids.append(cid if cid is not None else get_configuration(session, c, config).id)
    recs, by_rec = rows if rows is not None else seal_rows_many(session, c, ids)
    per_source: dict[int | None, list] = {}
    for rec in recs:
        per_source.setdefault(rec[2], []).append(rec)
    measured = _seal_problems(c, names, per_source.get(None, []), by_rec, secret)
    for config, cid in zip(configs, ids, strict=True):
        _raise_problems(config, measured + _seal_problems(c, names, per_source.get(cid, []),
                                                          by_rec, secret))


def seal_rows_many(session: Session, campaign: CampaignArg, config_ids: list[int], *,
                   measurement: bool = True) -> tuple[list, dict]:
    """:func:`_seal_rows` of the measurement (``measurement=False``: without it) and of the
    configurations ``config_ids``: the recordings (id, section id, configuration id or None,
    distance hash, fs, t0, n) and recording id → [(channel, channel id, content hash,
    seal)], two queries, no blob."""
    c = campaign_ref(session, campaign)
    cond = Recording.configuration_id.in_(set(config_ids))
    if measurement:
        cond = or_(Recording.configuration_id.is_(None), cond)
    return _seal_rows(session, c, cond)


def seal_problems(session: Session, campaign: CampaignArg) -> Callable[[list, dict], list]:
    """The check of :func:`require_sealed_many` on rows the caller already holds:
    returns ``problems(recs, by_rec)`` — the seal problems (records as
    :func:`verify_seals`'s) of the recordings ``recs`` of one source with their signal
    rows ``by_rec`` (the form of :func:`seal_rows_many`), every seal checked
    (:func:`integrity.check_signal_seals`). The secret and the configuration names are
    read once, here."""
    c = campaign_ref(session, campaign)
    secret = integrity.session_secret(session)
    names = {x.id: x.name for x in list_configurations(session, c)}
    return lambda recs, by_rec: _seal_problems(c, names, recs, by_rec, secret)


def raise_problems(config: ConfigArg, problems: list[dict[str, Any]]) -> None:
    """Raise :class:`railval.db.integrity.IntegrityError` as :func:`require_sealed` does
    when ``problems`` (records of :func:`verify_seals`) is not empty."""
    _raise_problems(config, problems)


def hash_rows_many(session: Session, campaign: CampaignArg, config_ids: list[int]
                   ) -> tuple[list, dict]:
    """:func:`seal_rows_many` without the seals: the same recordings and recording id →
    [(channel, channel id, content hash, None)], by channel id — what the result-cache keys
    are made of. On SQLite the signals' recording, channel and content hash come from the
    covering index ``ix_signal_evidence`` alone (migration 0009): the table row holds the
    hash after the blob, so reading it there walks the blob's whole overflow chain (≈ 0.45
    CPU-s for the 16 000 signals of a DynoTRAIN run in a fresh process). Other databases
    read the table."""
    c = campaign_ref(session, campaign)
    cond = or_(Recording.configuration_id.is_(None),
               Recording.configuration_id.in_(set(config_ids)))
    if session.get_bind().dialect.name != "sqlite":
        recs, by_rec = _seal_rows(session, c, cond)
        return recs, {rid: [(name, cid, sha, None) for name, cid, sha, _seal in rows]
                      for rid, rows in by_rec.items()}

    rec_q = (select(Recording.id, Section.section_id, Recording.configuration_id,
                    Recording.distance_sha256, Recording.fs, Recording.t0, Recording.n)
             .join(Section, Recording.section_id == Section.id)
             .where(Section.campaign_id == c.id, cond).order_by(Recording.id))
    recs = session.execute(rec_q).all()
    rids = [r[0] for r in recs]
    names = {cid: name for cid, name in session.execute(select(Channel.id, Channel.name))}
    # the driver's rows at once (through SQLAlchemy's rows: 3 times the CPU)
    cur = session.connection().connection.driver_connection
    members: list[tuple[int, int, str]] = []
    for i in range(0, len(rids), 500):
        part = rids[i:i + 500]
        members += cur.execute(
            "SELECT recording_id, channel_id, sha256 FROM signal WHERE recording_id IN ("
            + ",".join("?" * len(part)) + ")", tuple(part)).fetchall()
    by_rec: dict[int, list] = {}
    for rid, cid, sha in sorted(members, key=lambda m: (m[0], m[1])):
        by_rec.setdefault(rid, []).append((names[cid], cid, sha, None))
    return recs, by_rec


def _raise_problems(config: ConfigArg, problems: list[dict[str, Any]]) -> None:
    if problems:
        first = "; ".join(f"section {p['section']}, "
                          f"{'configuration ' + repr(p['configuration']) if p['configuration'] else 'measurement'}, "
                          f"{p['channel']}: {p['error']}" for p in problems[:3])
        raise integrity.IntegrityError(
            f"the stored signals of {config_name(config)!r} are not intact ({len(problems)} problem(s)): {first}; "
            "check the database with `railval verify`")


def verify_storage(session: Session, *, blobs: bool = True, seals: bool = True
                   ) -> dict[str, Any]:
    """Check a whole database: every signal's seal and (``blobs``) content hash, every
    distance axis, and every result-cache entry's seal. Returns ``{"ok", "campaigns":
    {name: [problem, ...]}, "signals": n, "cache_entries": n, "cache_unauthentic": [keys]}``.
    An unauthentic cache entry is never used (it is recomputed); it is listed because
    someone wrote it without the server secret. ``seals=False`` (no secret at hand, e.g. an
    assessor's account): the content hashes only; no seal is checked, no secret made."""
    secret = integrity.session_secret(session) if seals else None
    out: dict[str, Any] = {"campaigns": {}, "signals": 0}
    for c in list_campaigns(session):
        out["campaigns"][c.name] = _source_problems(session, c, True, secret, blobs)
    out["signals"] = int(session.scalar(select(func.count(Signal.id))) or 0)
    bad: list[str] = []
    n = 0
    for k, v in session.execute(select(ResultCache.key, ResultCache.value)):
        n += 1
        if secret is not None and integrity.open_cache_value(secret, k, bytes(v)) is None:
            bad.append(k)
    out["cache_entries"] = n
    out["cache_unauthentic"] = bad
    out["ok"] = not bad and not any(out["campaigns"].values())
    return out
