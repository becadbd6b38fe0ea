"""SQLAlchemy 2.0 ORM models of the railval database.

::

    Campaign 1──1 Vehicle
        │ 1──n Section 1──n Recording 1──n Signal n──1 Channel n──1 Campaign
        │ 1──n Channel             │
        └ 1──n Configuration ──────┘ (configuration_id NULL = the measurement)
                 └ parent_id → Configuration (lineage)
    ResultCache (key → bytes), independent

A *recording* is one (section, source) pair: the measurement (``configuration_id`` NULL)
or one configuration's simulation. It carries the time axis (``fs``, ``t0``, ``n``: sample
``i`` is at ``t0 + i / fs`` s) and the distance axis as a codec blob (:mod:`railval.db.codec`).
Every *signal* is one channel of one recording, stored as a codec blob with its SHA-256
content hash and a provenance record (units converted on import, file it came from).
Deleting a campaign or a configuration cascades to what hangs below it.
"""

from __future__ import annotations

import datetime as dt
from typing import Any, ClassVar

from sqlalchemy import (
    JSON,
    Boolean,
    DateTime,
    Float,
    ForeignKey,
    Index,
    Integer,
    LargeBinary,
    MetaData,
    String,
    Text,
    UniqueConstraint,
    false,
    text,
)
from sqlalchemy.orm import DeclarativeBase, Mapped, mapped_column, relationship

NAMING = {
    "ix": "ix_%(column_0_label)s",
    "uq": "uq_%(table_name)s_%(column_0_name)s",
    "ck": "ck_%(table_name)s_%(constraint_name)s",
    "fk": "fk_%(table_name)s_%(column_0_name)s_%(referred_table_name)s",
    "pk": "pk_%(table_name)s",
}

#: indexes that exist on SQLite only, made by a migration and not declared here:
#: ``ix_signal_evidence`` (recording, channel, content hash, provenance) covers what a
#: validation reads of its signal rows (migration 0009_signal_evidence_index)
SQLITE_ONLY_INDEXES = frozenset({"ix_signal_evidence"})


#: the condition of the partial unique index ``uq_recording_measured`` (one measurement per
#: section). Its SQLite form is declared on :class:`Recording`; the PostgreSQL form is added by
#: :func:`declare_postgresql_options` when a PostgreSQL engine is made, because declaring a
#: ``postgresql_*`` option imports SQLAlchemy's whole PostgreSQL dialect (its five drivers and
#: asyncio, ≈ 50 ms) into every start on SQLite
MEASURED_WHERE = "configuration_id IS NULL"


def utcnow() -> dt.datetime:
    return dt.datetime.now(dt.UTC)


class Base(DeclarativeBase):
    metadata = MetaData(naming_convention=NAMING)
    type_annotation_map: ClassVar = {dict[str, Any]: JSON, bytes: LargeBinary}


class Campaign(Base):
    __tablename__ = "campaign"

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    name: Mapped[str] = mapped_column(String(200), unique=True)
    description: Mapped[str] = mapped_column(Text, default="")
    zone1_min_radius_m: Mapped[float] = mapped_column(Float, default=5000.0)
    #: the imported campaign manifest (with the synthetic campaign ≈ 0.7 MB of JSON): loaded
    #: only when read (``deferred``), not with every lookup of the campaign by name or id
    manifest: Mapped[dict[str, Any]] = mapped_column(JSON, default=dict, deferred=True)
    created_at: Mapped[dt.datetime] = mapped_column(DateTime(timezone=True), default=utcnow)

    vehicle: Mapped[Vehicle | None] = relationship(
        back_populates="campaign", cascade="all, delete-orphan", passive_deletes=True,
        uselist=False,
    )
    sections: Mapped[list[Section]] = relationship(
        back_populates="campaign", cascade="all, delete-orphan", passive_deletes=True,
        order_by="Section.id",
    )
    channels: Mapped[list[Channel]] = relationship(
        back_populates="campaign", cascade="all, delete-orphan", passive_deletes=True,
        order_by="Channel.id",
    )
    configurations: Mapped[list[Configuration]] = relationship(
        back_populates="campaign", cascade="all, delete-orphan", passive_deletes=True,
        order_by="Configuration.id",
    )

    def __repr__(self) -> str:
        return f"Campaign(id={self.id!r}, name={self.name!r})"


class Vehicle(Base):
    __tablename__ = "vehicle"

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    campaign_id: Mapped[int] = mapped_column(
        ForeignKey("campaign.id", ondelete="CASCADE"), unique=True
    )
    name: Mapped[str] = mapped_column(String(200), default="")
    kind: Mapped[str] = mapped_column(String(20))  # passenger | freight
    secondary_suspension: Mapped[bool] = mapped_column(default=True)
    Q0_kN: Mapped[float] = mapped_column(Float)
    template: Mapped[str] = mapped_column(String(100), default="")
    parameters: Mapped[dict[str, Any]] = mapped_column(JSON, default=dict)

    campaign: Mapped[Campaign] = relationship(back_populates="vehicle")


class Section(Base):
    __tablename__ = "section"
    __table_args__ = (UniqueConstraint("campaign_id", "section_id"),)

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    campaign_id: Mapped[int] = mapped_column(ForeignKey("campaign.id", ondelete="CASCADE"))
    section_id: Mapped[str] = mapped_column(String(100))
    country: Mapped[str] = mapped_column(String(20), default="")
    radius_m: Mapped[float] = mapped_column(Float, default=0.0)  # 0 = straight
    cant_mm: Mapped[float] = mapped_column(Float, default=0.0)
    speed_kmh: Mapped[float] = mapped_column(Float)
    curve_direction: Mapped[int] = mapped_column(Integer, default=1)
    zone_override: Mapped[int | None] = mapped_column(Integer, nullable=True)
    eval_start_m: Mapped[float] = mapped_column(Float)
    eval_end_m: Mapped[float] = mapped_column(Float)
    layout: Mapped[dict[str, Any] | None] = mapped_column(JSON, nullable=True)

    campaign: Mapped[Campaign] = relationship(back_populates="sections")
    recordings: Mapped[list[Recording]] = relationship(
        back_populates="section", cascade="all, delete-orphan", passive_deletes=True
    )


class Channel(Base):
    __tablename__ = "channel"
    __table_args__ = (UniqueConstraint("campaign_id", "name"),)

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    campaign_id: Mapped[int] = mapped_column(ForeignKey("campaign.id", ondelete="CASCADE"))
    name: Mapped[str] = mapped_column(String(100))
    kind: Mapped[str] = mapped_column(String(20))
    position: Mapped[str] = mapped_column(String(20))
    unit: Mapped[str] = mapped_column(String(20))  # canonical unit as stored

    campaign: Mapped[Campaign] = relationship(back_populates="channels")


class Configuration(Base):
    __tablename__ = "configuration"
    __table_args__ = (UniqueConstraint("campaign_id", "name"),)

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    campaign_id: Mapped[int] = mapped_column(ForeignKey("campaign.id", ondelete="CASCADE"))
    name: Mapped[str] = mapped_column(String(200))
    parent_id: Mapped[int | None] = mapped_column(
        ForeignKey("configuration.id", ondelete="SET NULL"), nullable=True, index=True
    )
    effects: Mapped[dict[str, Any]] = mapped_column(JSON, default=dict)
    parameters: Mapped[dict[str, Any]] = mapped_column(JSON, default=dict)
    description: Mapped[str] = mapped_column(Text, default="")
    #: how a calibrated configuration was fitted: ``{"fit_sections": [...], "held_out_sections":
    #: [...], "parameters": [...]}`` (NULL for configurations that were not calibrated); a
    #: validation on fitted sections is in-sample (docs/diagnosis.md)
    calibration: Mapped[dict[str, Any] | None] = mapped_column(JSON, nullable=True, default=None)
    created_at: Mapped[dt.datetime] = mapped_column(DateTime(timezone=True), default=utcnow)

    campaign: Mapped[Campaign] = relationship(back_populates="configurations")
    parent: Mapped[Configuration | None] = relationship(remote_side="Configuration.id")
    recordings: Mapped[list[Recording]] = relationship(
        back_populates="configuration", cascade="all, delete-orphan", passive_deletes=True
    )

    def __repr__(self) -> str:
        return f"Configuration(id={self.id!r}, name={self.name!r}, parent_id={self.parent_id!r})"


class Recording(Base):
    """One (section, source) pair; ``configuration_id`` NULL is the measurement."""

    __tablename__ = "recording"
    __table_args__ = (
        UniqueConstraint("section_id", "configuration_id"),
        # NULLs are distinct in the constraint above: one measurement per section is
        # enforced by this partial unique index.
        Index(
            "uq_recording_measured", "section_id", unique=True,
            sqlite_where=text(MEASURED_WHERE),
        ),  # its PostgreSQL condition: declare_postgresql_options()
        Index("ix_recording_configuration_section", "configuration_id", "section_id"),
    )

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    section_id: Mapped[int] = mapped_column(ForeignKey("section.id", ondelete="CASCADE"))
    configuration_id: Mapped[int | None] = mapped_column(
        ForeignKey("configuration.id", ondelete="CASCADE"), nullable=True
    )
    fs: Mapped[float] = mapped_column(Float)
    t0: Mapped[float] = mapped_column(Float, default=0.0)
    n: Mapped[int] = mapped_column(Integer)
    distance_blob: Mapped[bytes] = mapped_column(LargeBinary)
    distance_sha256: Mapped[str] = mapped_column(String(64))
    source_file: Mapped[str] = mapped_column(String(500), default="")

    section: Mapped[Section] = relationship(back_populates="recordings")
    configuration: Mapped[Configuration | None] = relationship(back_populates="recordings")
    signals: Mapped[list[Signal]] = relationship(
        back_populates="recording", cascade="all, delete-orphan", passive_deletes=True
    )


class Signal(Base):
    __tablename__ = "signal"
    __table_args__ = (
        UniqueConstraint("recording_id", "channel_id"),
        Index("ix_signal_channel", "channel_id"),
        Index("ix_signal_sha256", "sha256"),
    )

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    recording_id: Mapped[int] = mapped_column(ForeignKey("recording.id", ondelete="CASCADE"))
    channel_id: Mapped[int] = mapped_column(ForeignKey("channel.id", ondelete="CASCADE"))
    blob: Mapped[bytes] = mapped_column(LargeBinary)
    dtype: Mapped[str] = mapped_column(String(16))
    sha256: Mapped[str] = mapped_column(String(64))
    provenance: Mapped[dict[str, Any]] = mapped_column(JSON, default=dict)

    recording: Mapped[Recording] = relationship(back_populates="signals")
    channel: Mapped[Channel] = relationship()


class ResultCache(Base):
    __tablename__ = "result_cache"

    key: Mapped[str] = mapped_column(String(200), primary_key=True)
    value: Mapped[bytes] = mapped_column(LargeBinary)
    created_at: Mapped[dt.datetime] = mapped_column(DateTime(timezone=True), default=utcnow)


# -- users, roles, invitations (docs/security.md) ------------------------------------------
class AppUser(Base):
    """A person who signs in. ``password_hash`` is an argon2id hash (NULL: cannot sign in)."""

    __tablename__ = "app_user"

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    username: Mapped[str] = mapped_column(String(100), unique=True)
    display_name: Mapped[str] = mapped_column(String(200), default="")
    password_hash: Mapped[str | None] = mapped_column(String(200), nullable=True)
    disabled: Mapped[bool] = mapped_column(default=False)
    created_at: Mapped[dt.datetime] = mapped_column(DateTime(timezone=True), default=utcnow)

    roles: Mapped[list[UserRole]] = relationship(
        back_populates="user", cascade="all, delete-orphan", passive_deletes=True,
        order_by="UserRole.role",
    )

    @property
    def role_names(self) -> list[str]:
        return [r.role for r in self.roles]

    def __repr__(self) -> str:
        return f"AppUser(id={self.id!r}, username={self.username!r})"


class UserRole(Base):
    """One role (a name of :data:`railval.core.roles.ROLES`) held by one user."""

    __tablename__ = "user_role"

    user_id: Mapped[int] = mapped_column(
        ForeignKey("app_user.id", ondelete="CASCADE"), primary_key=True
    )
    role: Mapped[str] = mapped_column(String(20), primary_key=True)

    user: Mapped[AppUser] = relationship(back_populates="roles")


class AppSession(Base):
    """A signed-in browser session that the server can end (docs/security.md). The session
    cookie carries a random id, only its SHA-256 is stored (``id_sha256``, unique: every
    request reads one row by it). ``ended_at`` is set by sign-out and, for every open
    session of the user, by a disable, password change or role change; ``end_reason`` says
    which. A session past ``expires_at`` or ended is refused."""

    __tablename__ = "app_session"
    __table_args__ = (Index("ix_app_session_user", "user_id"),)

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    id_sha256: Mapped[str] = mapped_column(String(64), unique=True)
    user_id: Mapped[int] = mapped_column(ForeignKey("app_user.id", ondelete="CASCADE"))
    created_at: Mapped[dt.datetime] = mapped_column(DateTime(timezone=True), default=utcnow)
    expires_at: Mapped[dt.datetime] = mapped_column(DateTime(timezone=True))
    ended_at: Mapped[dt.datetime | None] = mapped_column(DateTime(timezone=True), nullable=True)
    end_reason: Mapped[str] = mapped_column(String(40), default="")


class Invitation(Base):
    """A single-use invitation link; only the SHA-256 of its random token is stored."""

    __tablename__ = "invitation"

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    token_sha256: Mapped[str] = mapped_column(String(64), unique=True)
    role: Mapped[str] = mapped_column(String(20), default="panelist")
    #: the workshop the invitee joins (filled by the workshop feature; free-form reference)
    workshop_ref: Mapped[str | None] = mapped_column(String(100), nullable=True, index=True)
    note: Mapped[str] = mapped_column(String(200), default="")
    created_by: Mapped[int | None] = mapped_column(
        ForeignKey("app_user.id", ondelete="SET NULL"), nullable=True
    )
    created_at: Mapped[dt.datetime] = mapped_column(DateTime(timezone=True), default=utcnow)
    expires_at: Mapped[dt.datetime] = mapped_column(DateTime(timezone=True))
    used_at: Mapped[dt.datetime | None] = mapped_column(DateTime(timezone=True), nullable=True)
    used_by: Mapped[int | None] = mapped_column(
        ForeignKey("app_user.id", ondelete="SET NULL"), nullable=True
    )


# -- audit trail and sign-offs (append-only; docs/audit.md) -------------------------------
class AuditEvent(Base):
    """One row of the hash-chained audit trail (UPDATE/DELETE refused by triggers).

    ``row_hash`` = SHA-256(``prev_hash`` ‖ canonical JSON of the row's other fields); see
    :mod:`railval.db.audit`.
    """

    __tablename__ = "audit_event"
    __table_args__ = (
        Index("ix_audit_event_object", "object"),
        Index("ix_audit_event_action_at", "action", "at_utc"),
    )

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    seq: Mapped[int] = mapped_column(Integer, unique=True)
    at_utc: Mapped[str] = mapped_column(String(32))
    actor: Mapped[str] = mapped_column(String(100))
    action: Mapped[str] = mapped_column(String(60))
    object: Mapped[str] = mapped_column(String(400))
    before_sha256: Mapped[str | None] = mapped_column(String(64), nullable=True)
    after_sha256: Mapped[str | None] = mapped_column(String(64), nullable=True)
    reason: Mapped[str] = mapped_column(Text, default="")
    detail: Mapped[dict[str, Any]] = mapped_column(JSON, default=dict)
    prev_hash: Mapped[str] = mapped_column(String(64), unique=True)
    row_hash: Mapped[str] = mapped_column(String(64), unique=True)
    #: Ed25519 signature (hex) of ``{seq, row_hash}`` and its key's fingerprint; NULL for
    #: rows written before signing was enabled (migration ``0007_signatures``)
    signature: Mapped[str | None] = mapped_column(String(128), nullable=True)
    key_fingerprint: Mapped[str | None] = mapped_column(String(64), nullable=True)


class AuditHead(Base):
    """The chain's head (one row, id 1): its UPDATE serialises concurrent appenders."""

    __tablename__ = "audit_head"

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    seq: Mapped[int] = mapped_column(Integer, default=0)
    row_hash: Mapped[str] = mapped_column(String(64))


class Signoff(Base):
    """An independent sign-off of a configuration's validation (append-only).

    Names are stored as text (not foreign keys) so that deleting the evidence leaves the
    sign-off in place — it then shows as stale.
    """

    __tablename__ = "signoff"
    __table_args__ = (Index("ix_signoff_campaign_configuration", "campaign", "configuration"),)

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    campaign: Mapped[str] = mapped_column(String(200))
    configuration: Mapped[str] = mapped_column(String(200))
    user_id: Mapped[int | None] = mapped_column(
        ForeignKey("app_user.id", ondelete="RESTRICT"), nullable=True
    )
    username: Mapped[str] = mapped_column(String(100))
    printed_name: Mapped[str] = mapped_column(String(200))
    signed_at_utc: Mapped[str] = mapped_column(String(32))
    meaning: Mapped[str] = mapped_column(Text)
    decision: Mapped[str] = mapped_column(String(20))
    restrictions: Mapped[str] = mapped_column(Text, default="")
    statement: Mapped[str] = mapped_column(Text, default="")
    justification: Mapped[str] = mapped_column(Text, default="", server_default="")
    contrary_to_objective: Mapped[bool] = mapped_column(
        Boolean, default=False, server_default=false()
    )
    evidence_sha256: Mapped[str] = mapped_column(String(64))
    manifest: Mapped[dict[str, Any]] = mapped_column(JSON, default=dict)
    software_version: Mapped[str] = mapped_column(String(40))
    #: SHA-256 of the canonical record (:func:`railval.core.integrity.signoff_record`), its
    #: Ed25519 signature (hex) and the key's fingerprint; NULL before signing was enabled
    record_sha256: Mapped[str | None] = mapped_column(String(64), nullable=True)
    signature: Mapped[str | None] = mapped_column(String(128), nullable=True)
    key_fingerprint: Mapped[str | None] = mapped_column(String(64), nullable=True)


class AnalysisRun(Base):
    """A stored diagnosis or metrics run of one configuration.

    ``inputs_sha256`` is the SHA-256 over the canonical JSON of everything the result depends
    on (signal content hashes of both sides, section records, settings, processing version):
    a later request with the same inputs reads this row instead of recomputing; when any
    input changes the hash changes and the run is computed afresh. Earlier runs stay listed.
    """

    __tablename__ = "analysis_run"
    __table_args__ = (
        Index("ix_analysis_run_lookup", "configuration_id", "kind", "inputs_sha256"),
    )

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    campaign_id: Mapped[int] = mapped_column(ForeignKey("campaign.id", ondelete="CASCADE"))
    configuration_id: Mapped[int] = mapped_column(
        ForeignKey("configuration.id", ondelete="CASCADE"))
    kind: Mapped[str] = mapped_column(String(32))
    inputs_sha256: Mapped[str] = mapped_column(String(64))
    settings: Mapped[dict[str, Any]] = mapped_column(JSON, default=dict)
    result: Mapped[dict[str, Any]] = mapped_column(JSON, default=dict)
    seconds: Mapped[float] = mapped_column(Float, default=0.0)
    actor: Mapped[str] = mapped_column(String(200), default="")
    created_at: Mapped[dt.datetime] = mapped_column(DateTime(timezone=True), default=utcnow)


# -- review workshops (docs/workshops.md) -------------------------------------------------
class Workshop(Base):
    """An expert review workshop on a campaign: its plot set, scaling, reviewers, answers.

    ``settings``: what the plot set was built from (configurations, sections, kinds, filter,
    seeds); ``scales``: the one axis scaling of each plot kind ({kind: {x, y}}).
    ``status``: ``open`` (reviewers may answer) or ``closed``. Deleting the campaign is
    refused while a workshop refers to it (answers are user input and are never dropped
    silently); configuration and section names are kept as text on the plots.
    """

    __tablename__ = "workshop"

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    name: Mapped[str] = mapped_column(String(200), unique=True)
    campaign_id: Mapped[int] = mapped_column(ForeignKey("campaign.id", ondelete="RESTRICT"),
                                             index=True)
    status: Mapped[str] = mapped_column(String(20), default="open")
    blind: Mapped[bool] = mapped_column(default=False)
    repeat_share: Mapped[float] = mapped_column(Float, default=0.1)
    auto_share: Mapped[float] = mapped_column(Float, default=0.0)
    settings: Mapped[dict[str, Any]] = mapped_column(JSON, default=dict)
    scales: Mapped[dict[str, Any]] = mapped_column(JSON, default=dict)
    created_by: Mapped[int | None] = mapped_column(
        ForeignKey("app_user.id", ondelete="SET NULL"), nullable=True)
    created_at: Mapped[dt.datetime] = mapped_column(DateTime(timezone=True), default=utcnow)

    campaign: Mapped[Campaign] = relationship()


class WorkshopPlot(Base):
    """One review plot: a static PNG rendered once, its render parameters and SHA-256.

    ``scaling``: ``fixed`` (the kind's scaling) or ``auto`` (the presentation experiment's
    per-plot automatic scaling; ``twin_id`` is then the fixed plot of the same signal).
    ``deviation``: largest |D_v| / std limit of the EN quantities of the signal (NULL when
    the signal has none); ``sg_c``: Sprague–Geers C of simulation against measurement.
    """

    __tablename__ = "workshop_plot"
    __table_args__ = (Index("ix_workshop_plot_workshop", "workshop_id", "id"),)

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    workshop_id: Mapped[int] = mapped_column(ForeignKey("workshop.id", ondelete="CASCADE"))
    kind: Mapped[str] = mapped_column(String(40))
    section: Mapped[str] = mapped_column(String(100))
    configuration: Mapped[str] = mapped_column(String(200))
    channel: Mapped[str] = mapped_column(String(100))
    scaling: Mapped[str] = mapped_column(String(10), default="fixed")
    twin_id: Mapped[int | None] = mapped_column(
        ForeignKey("workshop_plot.id", ondelete="SET NULL"), nullable=True)
    deviation: Mapped[float | None] = mapped_column(Float, nullable=True)
    sg_c: Mapped[float | None] = mapped_column(Float, nullable=True)
    render: Mapped[dict[str, Any]] = mapped_column(JSON, default=dict)
    image_sha256: Mapped[str] = mapped_column(String(64))
    image: Mapped[bytes] = mapped_column(LargeBinary, deferred=True)


class WorkshopReviewer(Base):
    """A reviewer's participation: personal link (only the SHA-256 of its token stored),
    order seed and the sequence of plots shown (``sequence``: [[plot id, repeat], …])."""

    __tablename__ = "workshop_reviewer"
    __table_args__ = (UniqueConstraint("workshop_id", "user_id"),)

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    workshop_id: Mapped[int] = mapped_column(ForeignKey("workshop.id", ondelete="CASCADE"))
    user_id: Mapped[int] = mapped_column(ForeignKey("app_user.id", ondelete="RESTRICT"),
                                         index=True)
    seed: Mapped[int] = mapped_column(Integer)
    sequence: Mapped[list[Any]] = mapped_column(JSON, default=list)
    token_sha256: Mapped[str | None] = mapped_column(String(64), unique=True, nullable=True)
    invited_at: Mapped[dt.datetime | None] = mapped_column(DateTime(timezone=True),
                                                           nullable=True)
    finished_at: Mapped[dt.datetime | None] = mapped_column(DateTime(timezone=True),
                                                            nullable=True)
    created_at: Mapped[dt.datetime] = mapped_column(DateTime(timezone=True), default=utcnow)

    user: Mapped[AppUser] = relationship()


class WorkshopAnswer(Base):
    """One answer at one place of a reviewer's sequence (unique per place: a repeated
    submission updates, never duplicates). ``submission`` is the client's id of the last
    accepted submission (a resent one is recognised and ignored); ``seconds`` the time
    spent on the plot over all visits; ``source``: ``web`` or ``import``."""

    __tablename__ = "workshop_answer"
    __table_args__ = (
        UniqueConstraint("reviewer_id", "position"),
        Index("ix_workshop_answer_plot", "plot_id"),
    )

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    reviewer_id: Mapped[int] = mapped_column(
        ForeignKey("workshop_reviewer.id", ondelete="CASCADE"))
    plot_id: Mapped[int] = mapped_column(ForeignKey("workshop_plot.id", ondelete="CASCADE"))
    position: Mapped[int] = mapped_column(Integer)
    repeat: Mapped[bool] = mapped_column(default=False)
    answer: Mapped[bool] = mapped_column()
    comment: Mapped[str] = mapped_column(Text, default="")
    seconds: Mapped[float] = mapped_column(Float, default=0.0)
    changes: Mapped[int] = mapped_column(Integer, default=0)
    submission: Mapped[str] = mapped_column(String(64), default="")
    source: Mapped[str] = mapped_column(String(10), default="web")
    answered_at: Mapped[dt.datetime] = mapped_column(DateTime(timezone=True), default=utcnow)
    updated_at: Mapped[dt.datetime] = mapped_column(DateTime(timezone=True), default=utcnow)


def declare_postgresql_options() -> None:
    """Add the PostgreSQL condition of ``uq_recording_measured`` to the metadata (idempotent;
    :func:`railval.db.engine.connect` calls it for a PostgreSQL URL, before any DDL or
    comparison with the migrated schema)."""
    index = next(i for i in Recording.__table__.indexes if i.name == "uq_recording_measured")
    index.dialect_options["postgresql"]["where"] = text(MEASURED_WHERE)
