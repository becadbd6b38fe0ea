"""Stored signals: reading them (one SQL query per call), their content hashes, and adding
recordings with their signals.

Reading signals is a hot path (≈ 50 000 comparisons for a DynoTRAIN-size campaign):
:func:`load_signalsets` issues one SQL query per call, whatever the number of sections and
channels, and :func:`signal_hashes` reads hashes without touching the blobs.

``campaign`` is a :data:`railval.db.campaigns.CampaignArg` (a :class:`CampaignRef` resolved
once, or the row, name or id) and ``config`` a :data:`railval.db.campaigns.ConfigArg` (a
:class:`ConfigRef` or a name) or ``None`` for the measurement.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import Any

import numpy as np
from sqlalchemy import String, bindparam, cast, insert, literal, null, select, union_all
from sqlalchemy.orm import Session

from railval.core.errors import InvalidSignal, NotFound
from railval.core.types import SignalSet
from railval.db import codec, integrity
from railval.db.campaigns import (
    CampaignArg,
    CampaignRef,
    ConfigArg,
    ConfigRef,
    campaign_id,
    campaign_ref,
    config_name,
    get_configuration,
    section_infos,
)
from railval.db.campaigns import (
    channels as campaign_channels,
)
from railval.db.models import Channel, Configuration, Recording, Section, Signal


def source_filter(session: Session, cid: int, config: ConfigArg | None):
    """SQL condition selecting the recordings of the measurement (``config=None``) or of
    configuration ``config`` of campaign ``cid`` (by id for a :class:`ConfigRef`, else a
    subquery on the name)."""
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
    campaign: CampaignArg,
    config: ConfigArg | None = None,
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
    campaign: CampaignArg,
    config: ConfigArg | None = None,
    sections: list[str] | None = None,
    channels: list[str] | None = None,
    *,
    verify: bool = False,
    seals: bool = False,
) -> Callable[[], dict[str, SignalSet]]:
    """Read the blobs of :func:`load_signalsets` now; return the function that decodes them.

    The returned function uses no database session, so another thread may call it (the
    validation service decodes and processes one chunk of sections in a worker thread
    while this thread reads the next). It decodes every blob with
    :func:`railval.db.codec.decode_many` (both cores: the hash of one blob overlaps the
    inflate of another; the arrays of one dtype and shape are rows of one preallocated
    block). Unknown names raise :class:`NotFound` here.

    One SQL query (a UNION ALL of the recordings' distance axes and the signal blobs,
    selecting only the columns decoded) executed through SQLAlchemy Core; rows are put in
    recording, then channel-name order in Python, because an SQL ``ORDER BY`` over the blob
    columns made SQLite copy every blob into a temporary sort B-tree (3–4× the time of the
    read itself on the benchmark database). The statement is built once per form
    (:func:`_fetch_statement`; the campaign, configuration, sections and channels are bound
    parameters), not per call: building and keying it cost ≈ 3 ms a chunk.

    The returned function carries ``read`` = [(recording id, section id, channel or None
    for the distance axis, content hash, fs, t0, n)] of the rows read, for a caller that derived
    its cache keys and checked the seals from rows it read before (the validation service
    compares them: the blobs decoded are those the keys and seals name).

    ``seals=True`` also reads each signal row's seal (``provenance["seal"]``, stored after
    the blob: on SQLite the row's overflow chain is walked for the content hash anyway);
    the returned function then carries ``seals`` = [(recording id, channel, content hash,
    seal or None)] of the signal rows read, for the caller to check
    (:func:`railval.db.seals.seal_problems`).
    """
    c = campaign_ref(session, campaign)
    kind = None if config is None else "id" if isinstance(config, ConfigRef) else "name"
    stmt = _fetch_statement(kind, sections is not None, channels is not None, seals)
    params: dict[str, Any] = {"campaign_id": c.id}
    if kind is not None:
        params["config"] = config.id if kind == "id" else config
    if sections is not None:
        params["sections"] = list(sections)
    if channels is not None:
        params["channels"] = list(channels)
    rows = session.connection().execute(stmt, params).all()
    rows.sort(key=lambda r: (r[1], r[8], r[5] or ""))
    present: dict[str, list[str]] = {}
    for r in rows:
        chans = present.setdefault(r[0], [])
        if r[8]:
            chans.append(r[5])
    _check_requested(session, c, config, present, sections, channels)

    src_name = "measurement" if config is None else f"configuration {config_name(config)!r}"
    decode = _decoder(rows, verify, f"campaign {c.name!r}, {src_name}")
    decode.read = [(r[1], r[0], r[5] if r[8] else None, r[7], r[2], r[3], r[4])
                   for r in rows]
    if seals:
        decode.seals = [(r[1], r[5], r[7], r[9]) for r in rows if r[8]]
    return decode


_FETCH_STATEMENTS: dict[tuple, Any] = {}


def _fetch_statement(kind: str | None, sections: bool, channels: bool, seals: bool):
    """The UNION ALL statement of :func:`fetch_signalsets`, built once per form: ``kind``
    None (the measurement), ``"id"`` (a :class:`ConfigRef`) or ``"name"`` (a configuration
    name, by subquery as :func:`source_filter`), with or without the section and channel
    restrictions and the seals. Bound parameters: ``campaign_id``, ``config``, ``sections``
    and ``channels`` (expanding). SQLAlchemy memoizes a statement's cache key on the
    object, so executing the same object again finds its compiled form at once."""
    key = (kind, sections, channels, seals)
    stmt = _FETCH_STATEMENTS.get(key)
    if stmt is not None:
        return stmt
    if kind is None:
        src = Recording.configuration_id.is_(None)
    elif kind == "id":
        src = Recording.configuration_id == bindparam("config")
    else:
        src = Recording.configuration_id == (
            select(Configuration.id)
            .where(Configuration.campaign_id == bindparam("campaign_id"),
                   Configuration.name == bindparam("config"))
            .scalar_subquery())
    where = [Section.campaign_id == bindparam("campaign_id"), src]
    if sections:
        where.append(Section.section_id.in_(bindparam("sections", expanding=True)))
    extra = [cast(null(), String).label("seal")] if seals else []
    rec_q = (
        select(
            Section.section_id, Recording.id, Recording.fs, Recording.t0, Recording.n,
            cast(null(), String).label("channel"), Recording.distance_blob.label("blob"),
            Recording.distance_sha256.label("sha"), literal(0).label("is_signal"), *extra,
        )
        .join(Section, Recording.section_id == Section.id)
        .where(*where)
    )
    sig_q = (
        select(
            Section.section_id, Recording.id, Recording.fs, Recording.t0, Recording.n,
            Channel.name, Signal.blob, Signal.sha256, literal(1),
            *([Signal.provenance["seal"].as_string()] if seals else []),
        )
        .join(Recording, Signal.recording_id == Recording.id)
        .join(Section, Recording.section_id == Section.id)
        .join(Channel, Signal.channel_id == Channel.id)
        .where(*where)
    )
    if channels:
        sig_q = sig_q.where(Channel.name.in_(bindparam("channels", expanding=True)))
    stmt = _FETCH_STATEMENTS[key] = union_all(rec_q, sig_q)
    return stmt


def _decoder(rows: list, verify: bool, where: str) -> Callable[[], dict[str, SignalSet]]:
    """The decode function of :func:`fetch_signalsets` over its ordered ``rows`` (a
    recording's distance axis before its channels); ``where`` names the source in errors."""

    def decode_all() -> dict[str, SignalSet]:
        try:
            arrays = codec.decode_many([(r[6], r[7] if verify else None) for r in rows])
        except codec.BlobError as exc:
            sid, chan = rows[exc.index][0], rows[exc.index][5]
            raise InvalidSignal(f"{where}, section {sid!r}, {chan or 'distance_m'}: {exc}; "
                                "check the database with `railval verify`") from None
        out: dict[str, SignalSet] = {}
        for (sid, _rid, fs, t0, n, chan, _blob, sha, is_signal, *_), a in zip(rows, arrays,
                                                                             strict=True):
            if not is_signal:
                out[sid] = SignalSet(fs=float(fs),
                                     time_s=t0 + np.arange(n, dtype=np.float64) / fs,
                                     distance_m=a)
            else:
                ss = out[sid]
                ss.channels[chan] = a
                ss.hashes[chan] = sha
        return out

    return decode_all


def _check_requested(session: Session, c: CampaignRef, config: ConfigArg | None,
                     out: Mapping[str, list[str]], sections: list[str] | None,
                     channel_names: list[str] | None) -> None:
    # Only the error paths run further queries, to explain what is missing.
    if config is not None and not out:
        get_configuration(session, c, config)
    if sections is not None:
        missing = [s for s in sections if s not in out]
        if missing:
            known = [s.id for s in section_infos(session, c)]
            src = "the measurement" if config is None else f"configuration {config_name(config)!r}"
            unknown = [s for s in missing if s not in known]
            what = (f"unknown section(s) {unknown}; sections: {known}" if unknown
                    else f"{src} has no recording of section(s) {missing}")
            raise NotFound(f"campaign {c.name!r}: {what}")
    if channel_names is not None:
        seen = {ch for chans in out.values() for ch in chans}
        missing = [ch for ch in channel_names if ch not in seen]
        if missing:
            known = [ch.name for ch in campaign_channels(session, c)]
            unknown = [ch for ch in missing if ch not in known]
            if unknown:
                raise NotFound(f"campaign {c.name!r}: unknown channel(s) {unknown}; "
                               f"channels: {known}")


def signal_hashes(
    session: Session, campaign: CampaignArg, config: ConfigArg | None = None
) -> dict[str, dict[str, str]]:
    """Section id → channel → SHA-256 content hash of the measurement (``config=None``) or a
    configuration, without reading any blob."""
    c = campaign_ref(session, campaign)
    rows = session.execute(
        select(Section.section_id, Channel.name, Signal.sha256)
        .join(Recording, Signal.recording_id == Recording.id)
        .join(Section, Recording.section_id == Section.id)
        .join(Channel, Signal.channel_id == Channel.id)
        .where(Section.campaign_id == c.id, source_filter(session, c.id, config))
        .order_by(Section.id, Channel.id)
    )
    out: dict[str, dict[str, str]] = {}
    for sid, chan, sha in rows:
        out.setdefault(sid, {})[chan] = sha
    if config is not None and not out:
        get_configuration(session, c, config)
    return out


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
    for section, conf, ss, _prov in items:
        dblob, dsha = codec.encode(np.asarray(ss.distance_m, dtype=np.float64))
        rec = Recording(section=section, configuration=conf, fs=float(ss.fs),
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


def source_hashes(session: Session, campaign: CampaignArg,
                  config: ConfigArg | None = None) -> dict[str, dict[str, str]]:
    """Section id → {``distance_m``: hash of the distance axis, channel: content hash} of the
    measurement (``config=None``) or a configuration; reads no blob."""
    c = campaign_ref(session, campaign)
    if config is not None:
        get_configuration(session, c, config)
    out: dict[str, dict[str, str]] = {}
    for sid, dsha in session.execute(
        select(Section.section_id, Recording.distance_sha256)
        .join(Section, Recording.section_id == Section.id)
        .where(Section.campaign_id == c.id, source_filter(session, c.id, config))
        .order_by(Section.id)
    ):
        out[sid] = {"distance_m": dsha}
    for sid, chans in signal_hashes(session, c, config).items():
        out.setdefault(sid, {}).update(chans)
    return out


def stored_blobs(session: Session) -> list[tuple[bytes, str]]:
    """Every stored signal blob with its SHA-256 content hash (storage benchmarks)."""
    return [(bytes(b), h) for b, h in session.execute(select(Signal.blob, Signal.sha256))]


def recording_meta(session: Session, campaign: CampaignArg,
                   config: ConfigArg | None = None) -> dict[str, tuple[str, float, int]]:
    """Section id → (distance-axis SHA-256, fs, n) of the recordings of the measurement
    (``config=None``) or a configuration; no blob is read."""
    cid = campaign_id(session, campaign)
    q = (select(Section.section_id, Recording.distance_sha256, Recording.fs, Recording.n)
         .join(Section, Recording.section_id == Section.id)
         .where(Section.campaign_id == cid, source_filter(session, cid, config)))
    return {sid: (sha, float(fs), int(n)) for sid, sha, fs, n in session.execute(q)}
