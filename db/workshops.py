"""Storage and queries of review workshops (docs/workshops.md).

Tables (:mod:`railval.db.models`): ``workshop``, ``workshop_plot`` (PNG bytes, render
parameters, SHA-256), ``workshop_reviewer`` (a reviewer's participation: personal link
stored as the SHA-256 of its token, order seed, sequence of plots) and ``workshop_answer``
(one row per place of a reviewer's sequence).

Answers are written the moment they are given, one short transaction each
(:func:`record_answer`): the unique (reviewer, place) key makes a repeated submission an
update, never a second row, and the client's submission id makes a resent submission a
no-op. Organiser actions (create, invite, close, reopen, import) append an audit row
(:func:`railval.db.audit.record`) in the same transaction; single answers do not (each is a
time-stamped row of its own).
"""

from __future__ import annotations

import datetime as dt
import hashlib
import secrets
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

from sqlalchemy import case, func, select, update
from sqlalchemy.exc import IntegrityError as UniqueViolation
from sqlalchemy.orm import Session

from railval.core.errors import InvalidParameter, NotFound, RailvalError
from railval.core.roles import PermissionDenied, Principal, allowed
from railval.core.workshop import review_order
from railval.db import audit, users
from railval.db.models import (
    AppUser,
    Invitation,
    Workshop,
    WorkshopAnswer,
    WorkshopPlot,
    WorkshopReviewer,
    utcnow,
)

STATUSES = ("open", "closed")


class WorkshopClosed(RailvalError):
    """The workshop is closed (or the reviewer has finished): answers are refused."""


def token_hash(token: str) -> str:
    return hashlib.sha256((token or "").encode("utf-8")).hexdigest()


def _aware(when: dt.datetime | None) -> dt.datetime | None:
    if when is not None and when.tzinfo is None:
        return when.replace(tzinfo=dt.UTC)
    return when


def utc_text(when: dt.datetime | None) -> str:
    """ISO 8601 UTC time stamp with a ``Z`` (empty for None)."""
    when = _aware(when)
    return "" if when is None else when.astimezone(dt.UTC).strftime("%Y-%m-%dT%H:%M:%S.%fZ")


# -- workshops ---------------------------------------------------------------------------
#: path segments of the workshop pages (``/workshops/new``, ``/workshops/mine`` …): no
#: workshop may be called so, or its page could not be reached
RESERVED_NAMES = ("new", "plan", "mine", "login", "logout", "scaling-preview")


def check_name(name: str) -> None:
    """Refuse a workshop name that is one of :data:`RESERVED_NAMES`."""
    if str(name).strip().lower() in RESERVED_NAMES:
        raise InvalidParameter(f"workshop name {name!r} is reserved (a page /workshops/{name} "
                               "exists); choose another name")


def list_workshops(session: Session) -> list[Workshop]:
    return list(session.scalars(select(Workshop).order_by(Workshop.name)))


def get_workshop(session: Session, name: str) -> Workshop:
    """The workshop called ``name``; :class:`NotFound` lists the existing names."""
    w = session.scalar(select(Workshop).where(Workshop.name == str(name)))
    if w is None:
        names = list(session.scalars(select(Workshop.name).order_by(Workshop.name)))
        raise NotFound(f"workshop {name!r} not found; workshops: {', '.join(names) or '(none)'}")
    return w


def create_workshop(session: Session, name: str, campaign_id: int, *, blind: bool,
                    repeat_share: float, auto_share: float, settings: Mapping[str, Any],
                    scales: Mapping[str, Any], plots: Sequence[Mapping[str, Any]],
                    actor: Any = "system") -> Workshop:
    """Store a workshop and its rendered plots in ``session``'s transaction.

    ``plots``: dicts with ``kind, section, configuration, channel, scaling, deviation, sg_c,
    render, image`` and optionally ``twin`` (index into ``plots`` of the fixed plot an
    ``auto`` plot repeats). The image's SHA-256 is computed here from the bytes stored.
    """
    name = (name or "").strip()
    if not name or len(name) > 200:
        raise InvalidParameter(f"workshop name {name!r}: give 1–200 characters")
    if session.scalar(select(Workshop.id).where(Workshop.name == name)) is not None:
        raise InvalidParameter(f"workshop {name!r} already exists; choose another name")
    if not plots:
        raise InvalidParameter(f"workshop {name!r} would have no plots")
    creator = users.find_user(session, getattr(actor, "username", str(actor)))
    w = Workshop(name=name, campaign_id=campaign_id, status="open", blind=bool(blind),
                 repeat_share=float(repeat_share), auto_share=float(auto_share),
                 settings=dict(settings), scales=dict(scales),
                 created_by=creator.id if creator else None, created_at=utcnow())
    session.add(w)
    session.flush()
    rows: list[WorkshopPlot] = []
    for p in plots:
        row = WorkshopPlot(workshop_id=w.id, kind=p["kind"], section=p["section"],
                           configuration=p["configuration"], channel=p["channel"],
                           scaling=p.get("scaling", "fixed"), deviation=p.get("deviation"),
                           sg_c=p.get("sg_c"), render=dict(p["render"]), image=p["image"],
                           image_sha256=hashlib.sha256(p["image"]).hexdigest())
        rows.append(row)
    session.add_all(rows)
    session.flush()
    for row, p in zip(rows, plots, strict=True):
        if p.get("twin") is not None:
            row.twin_id = rows[int(p["twin"])].id
    session.flush()
    audit.record(session, actor, "workshop.create", f"workshop:{name}", None,
                 {"campaign_id": campaign_id, "settings": dict(settings),
                  "images": sorted(r.image_sha256 for r in rows)},
                 detail={"plots": len(rows), "blind": bool(blind)})
    return w


def set_status(session: Session, workshop: Workshop, status: str, *, actor: Any = "system") -> Workshop:
    if status not in STATUSES:
        raise InvalidParameter(f"workshop status must be one of {STATUSES}, got {status!r}")
    before = workshop.status
    workshop.status = status
    session.flush()
    audit.record(session, actor, "workshop.close" if status == "closed" else "workshop.reopen",
                 f"workshop:{workshop.name}", {"status": before}, {"status": status})
    return workshop


def plots(session: Session, workshop: Workshop) -> list[WorkshopPlot]:
    """The workshop's plots in creation order (image bytes not loaded)."""
    return list(session.scalars(select(WorkshopPlot).where(WorkshopPlot.workshop_id == workshop.id)
                                .order_by(WorkshopPlot.id)))


def plot_image(session: Session, workshop_id: int, plot_id: int) -> tuple[bytes, str]:
    """``(PNG bytes, SHA-256)`` of a plot of this workshop; :class:`NotFound` otherwise."""
    row = session.execute(select(WorkshopPlot.image, WorkshopPlot.image_sha256)
                          .where(WorkshopPlot.id == plot_id,
                                 WorkshopPlot.workshop_id == workshop_id)).first()
    if row is None:
        raise NotFound(f"plot {plot_id} is not part of this workshop")
    return bytes(row[0]), row[1]


# -- reviewers ---------------------------------------------------------------------------
def _reviewer_user(session: Session, username: str, actor: Any) -> AppUser:
    """The workshop participant ``username``: created as a panelist (no password) when
    missing; an existing user must hold the role ``panelist``."""
    user = users.find_user(session, username)
    if user is None:
        return users.create_user(session, username, roles=["panelist"], actor=actor,
                                 reason="workshop panelist")
    if "panelist" not in user.role_names:
        raise InvalidParameter(
            f"user {username!r} holds the roles {', '.join(user.role_names) or '(none)'}, not "
            f"panelist; give them the panelist role first (`railval user role {username} "
            f"{' '.join([*user.role_names, 'panelist'])}`)")
    if user.disabled:
        raise InvalidParameter(f"user {username!r} is disabled")
    return user


def participation(session: Session, workshop: Workshop, username: str, *,
                  actor: Any = "system", seed: int | None = None) -> WorkshopReviewer:
    """The reviewer's participation in ``workshop``, created when missing (the user too, as
    a panelist without password): a random seed (stored) and the sequence it gives."""
    user = _reviewer_user(session, username, actor)
    r = session.scalar(select(WorkshopReviewer).where(WorkshopReviewer.workshop_id == workshop.id,
                                                      WorkshopReviewer.user_id == user.id))
    if r is not None:
        return r
    plot_ids = [p.id for p in plots(session, workshop)]
    seed = secrets.randbits(31) if seed is None else int(seed)
    seq = [[plot_ids[i], rep] for i, rep in review_order(len(plot_ids), seed,
                                                         workshop.repeat_share)]
    r = WorkshopReviewer(workshop_id=workshop.id, user_id=user.id, seed=seed, sequence=seq,
                         created_at=utcnow())
    session.add(r)
    session.flush()
    return r


def invite(session: Session, workshop: Workshop, username: str, *, actor: Any = "system",
           seed: int | None = None) -> str:
    """A new personal link token for ``username`` (returned once; only its SHA-256 is
    stored; an earlier link of the same reviewer stops working)."""
    r = participation(session, workshop, username, actor=actor, seed=seed)
    token = secrets.token_urlsafe(32)
    r.token_sha256 = token_hash(token)
    r.invited_at = utcnow()
    session.flush()
    audit.record(session, actor, "workshop.invite", f"workshop:{workshop.name}",
                 detail={"reviewer": username})
    return token


def redeem_invitation(session: Session, token: str, *, username: str, password: str,
                      display_name: str = "") -> AppUser:
    """:func:`railval.db.users.redeem_invitation` (the account, the link used), and a panelist
    invited to a workshop takes part in it at once (:func:`join_invited`): the ``/invite``
    form's one call, in the caller's transaction."""
    inv = users.check_invitation(session, token)
    user = users.redeem_invitation(session, token, username=username, password=password,
                                   display_name=display_name)
    join_invited(session, inv, user.username)
    return user


def join_invited(session: Session, inv: Invitation, username: str) -> WorkshopReviewer | None:
    """The panelist ``username``, whose account the invitation ``inv`` has just created,
    takes part in the workshop it names: their participation (seed and plot sequence) is
    stored, so "My workshops" lists the workshop with its "Open review" button (a personal
    link issued on the spot, :func:`own_link`). Audited as ``workshop.join``. ``None`` when
    the invitation names no workshop (or, made by an older version, is not a panelist's)."""
    if inv.workshop_ref is None or inv.role != "panelist":
        return None
    w = get_workshop(session, inv.workshop_ref)
    r = participation(session, w, username, actor=username)
    audit.record(session, username, "workshop.join", f"workshop:{w.name}",
                 detail={"reviewer": username, "via": f"invitation:{inv.id}"})
    return r


@dataclass(frozen=True)
class ReviewerContext:
    """Who a personal link belongs to (plain values, usable after the session closed)."""

    reviewer_id: int
    workshop_id: int
    workshop_name: str
    workshop_status: str
    blind: bool
    username: str
    principal: Principal
    sequence: tuple[tuple[int, bool], ...]
    finished: bool


def reviewer_by_token(session: Session, token: str) -> ReviewerContext | None:
    """The participation a personal link token opens, or None for an unknown token."""
    if not token or len(token) > 200:
        return None
    row = session.execute(
        select(WorkshopReviewer, Workshop, AppUser)
        .join(Workshop, WorkshopReviewer.workshop_id == Workshop.id)
        .join(AppUser, WorkshopReviewer.user_id == AppUser.id)
        .where(WorkshopReviewer.token_sha256 == token_hash(token))).first()
    if row is None:
        return None
    r, w, u = row
    return ReviewerContext(r.id, w.id, w.name, w.status, bool(w.blind), u.username,
                           users.principal(u), tuple((int(p), bool(rep)) for p, rep in r.sequence),
                           r.finished_at is not None)


def reviewers(session: Session, workshop: Workshop) -> list[WorkshopReviewer]:
    return list(session.scalars(select(WorkshopReviewer)
                                .where(WorkshopReviewer.workshop_id == workshop.id)
                                .order_by(WorkshopReviewer.id)))


def own_answers(session: Session, reviewer_id: int) -> dict[int, WorkshopAnswer]:
    """place → answer of one reviewer."""
    return {a.position: a for a in session.scalars(
        select(WorkshopAnswer).where(WorkshopAnswer.reviewer_id == reviewer_id))}


class AnswerOutcome(str):
    """What :func:`record_answer` did — ``"new"``, ``"changed"`` or ``"repeated"`` — with
    the answer stored before a change (``previous``: True/False, None when unknown) and
    when it was given or last changed (``previous_at``)."""

    previous: bool | None = None
    previous_at: dt.datetime | None = None

    @classmethod
    def of(cls, outcome: str, previous: Any = None) -> AnswerOutcome:
        out = cls(outcome)
        if previous is not None:
            out.previous, out.previous_at = bool(previous[0]), _aware(previous[1])
        return out


def answer_refusal(session: Session, ctx: ReviewerContext) -> str:
    """Why the reviewer's user may not answer now ("" when they may), read in the write
    transaction with a shared lock on the user row (:func:`railval.db.users.live_principal`):
    a disable or role change committed before this answer is seen; one in progress waits
    for the answer's commit or is waited for. Never the principal of ``ctx``, which the
    caller may have cached."""
    user_id = ctx.principal.user_id
    if user_id is None:
        return ""
    now = users.live_principal(session, user_id)
    if now is None or not allowed(now, "workshop.answer"):
        return (f"the account {ctx.username!r} is disabled or may no longer answer in "
                "workshops; answers are not taken")
    return ""


def record_answer(session: Session, ctx: ReviewerContext, position: int, answer: bool, *,
                  seconds: float, comment: str = "", submission: str = "") -> AnswerOutcome:
    """Store the reviewer's answer at ``position`` of their sequence; returns ``"new"``,
    ``"changed"`` or ``"repeated"`` (the same submission seen before: nothing written) as an
    :class:`AnswerOutcome` that also holds the answer a change replaced.

    Refused (:class:`WorkshopClosed`) when the workshop is closed or the reviewer has
    finished, and (:class:`railval.core.errors.PermissionDenied`) when the reviewer's
    account is disabled or lost the panelist role — read again in this transaction
    (:func:`answer_refusal`); :class:`InvalidParameter` for a position outside the sequence.

    Call it in a unit of work of its own opened with ``session(write=True)`` (``ctx`` read in
    an earlier one; :func:`railval.app.services.workshop_review.record_answer`): on SQLite
    that transaction takes the write lock at ``BEGIN IMMEDIATE`` (waiting up to the busy
    timeout) instead of failing to upgrade a read snapshot that a concurrent answer has made
    stale.
    """
    if ctx.workshop_status != "open":
        raise WorkshopClosed(f"workshop {ctx.workshop_name!r} is closed; answers are not taken")
    if not (0 <= position < len(ctx.sequence)):
        raise InvalidParameter(f"place {position} is outside this reviewer's {len(ctx.sequence)} plots")
    if not (seconds >= 0 and seconds < 1e7):
        raise InvalidParameter(f"seconds must be ≥ 0, got {seconds!r}")
    comment = (comment or "")[:2000]
    submission = (submission or "")[:64]
    refusal = answer_refusal(session, ctx)
    if refusal:
        raise PermissionDenied(refusal)
    plot_id, rep = ctx.sequence[position]
    now = utcnow()
    where = [WorkshopAnswer.reviewer_id == ctx.reviewer_id, WorkshopAnswer.position == position]
    # the stored answer (row locked until commit): what a change replaces, for the reviewer
    previous = session.execute(select(WorkshopAnswer.answer, WorkshopAnswer.updated_at)
                               .where(*where).with_for_update()).first()

    def change() -> str | None:
        # one atomic UPDATE (row lock / write lock): concurrent changes of one place never
        # lose an increment; a resent submission matches no row
        cond = [*where, WorkshopAnswer.submission != submission] if submission else where
        for _ in range(3):
            n = session.execute(
                update(WorkshopAnswer).where(*cond).values(
                    answer=bool(answer), comment=comment,
                    seconds=WorkshopAnswer.seconds + float(seconds),
                    changes=WorkshopAnswer.changes + 1, submission=submission, updated_at=now)
                .execution_options(synchronize_session=False)).rowcount
            if n:
                return "changed"
            stored = session.execute(select(WorkshopAnswer.submission).where(*where)).first()
            if stored is None:
                return None
            if submission and stored[0] == submission:
                return "repeated"
            # the row was committed by a concurrent first submission between the UPDATE and
            # this read (read committed): update it now instead of dropping this answer
        return "repeated"

    outcome = change()
    if outcome is None:
        try:
            with session.begin_nested():
                session.add(WorkshopAnswer(
                    reviewer_id=ctx.reviewer_id, plot_id=plot_id, position=position, repeat=rep,
                    answer=bool(answer), comment=comment, seconds=float(seconds),
                    submission=submission, source="web", answered_at=now, updated_at=now))
            outcome = "new"
        except UniqueViolation:  # a concurrent first submission of the same place won
            outcome = change() or "repeated"
    # the stored state decides, not ``ctx`` (which a caller may have cached): checked after
    # the write, inside the same transaction, so a refusal rolls the write back
    status, finished = session.execute(
        select(Workshop.status, WorkshopReviewer.finished_at)
        .join(WorkshopReviewer, WorkshopReviewer.workshop_id == Workshop.id)
        .where(WorkshopReviewer.id == ctx.reviewer_id)).one()
    if status != "open":
        raise WorkshopClosed(f"workshop {ctx.workshop_name!r} is closed; answers are not taken")
    if finished is not None:
        raise WorkshopClosed("you have finished this review; answers are final")
    return AnswerOutcome.of(outcome, previous if outcome == "changed" else None)


def finish(session: Session, ctx: ReviewerContext) -> None:
    """Mark the reviewer finished (their answers are final); every place must be answered."""
    n = session.scalar(select(func.count()).select_from(WorkshopAnswer)
                       .where(WorkshopAnswer.reviewer_id == ctx.reviewer_id))
    if n < len(ctx.sequence):
        raise InvalidParameter(f"{len(ctx.sequence) - n} plots are not answered yet")
    r = session.get(WorkshopReviewer, ctx.reviewer_id)
    if r.finished_at is None:
        r.finished_at = utcnow()


def progress(session: Session, workshop: Workshop) -> list[dict[str, Any]]:
    """Per reviewer: ``reviewer, answered, total, yes, finished, last_answer_at``."""
    counts = {rid: (n, yes, last) for rid, n, yes, last in session.execute(
        select(WorkshopAnswer.reviewer_id, func.count(),
               func.sum(case((WorkshopAnswer.answer, 1), else_=0)),
               func.max(WorkshopAnswer.updated_at))
        .join(WorkshopReviewer, WorkshopAnswer.reviewer_id == WorkshopReviewer.id)
        .where(WorkshopReviewer.workshop_id == workshop.id)
        .group_by(WorkshopAnswer.reviewer_id))}
    out = []
    for r, username in session.execute(
            select(WorkshopReviewer, AppUser.username)
            .join(AppUser, WorkshopReviewer.user_id == AppUser.id)
            .where(WorkshopReviewer.workshop_id == workshop.id).order_by(AppUser.username)):
        n, yes, last = counts.get(r.id, (0, 0, None))
        out.append({"reviewer": username, "answered": int(n), "total": len(r.sequence),
                    "yes": int(yes or 0), "finished": r.finished_at is not None,
                    "invited": r.token_sha256 is not None,
                    "last_answer_at": utc_text(last) if last else None})
    return out


def answer_rows(session: Session, workshop: Workshop) -> list[dict[str, Any]]:
    """Every answer of the workshop with its plot's facts (export and analysis)."""
    q = (select(AppUser.username, WorkshopAnswer, WorkshopPlot.kind, WorkshopPlot.scaling,
                WorkshopPlot.twin_id)
         .join(WorkshopReviewer, WorkshopAnswer.reviewer_id == WorkshopReviewer.id)
         .join(AppUser, WorkshopReviewer.user_id == AppUser.id)
         .join(WorkshopPlot, WorkshopAnswer.plot_id == WorkshopPlot.id)
         .where(WorkshopReviewer.workshop_id == workshop.id)
         .order_by(AppUser.username, WorkshopAnswer.position))
    return [{"reviewer": u, "plot": a.plot_id, "answer": "yes" if a.answer else "no",
             "seconds": float(a.seconds), "comment": a.comment,
             "answered_at": utc_text(a.answered_at), "updated_at": utc_text(a.updated_at),
             "position": a.position, "repeat": bool(a.repeat), "scaling": scaling,
             "twin": twin, "kind": kind, "source": a.source, "changes": int(a.changes)}
            for u, a, kind, scaling, twin in session.execute(q)]


def import_answers(session: Session, workshop: Workshop,
                   rows: Iterable[Mapping[str, Any]], *, actor: Any = "system",
                   source_name: str = "") -> dict[str, int]:
    """Store answers gathered elsewhere: ``rows`` are checked dicts ``reviewer, plot,
    answer (bool), seconds, comment, repeat (bool), line``. Unknown reviewers become
    panelist users without password. A plot a reviewer already answered in the workshop is
    refused with the line. Everything happens in ``session``'s transaction: the caller's
    unit of work stores all rows or none."""
    rows = list(rows)
    plot_ids = {p.id for p in plots(session, workshop)}
    by_reviewer: dict[str, list[Mapping[str, Any]]] = {}
    for row in rows:
        if row["plot"] not in plot_ids:
            raise InvalidParameter(f"{source_name} line {row['line']}, column plot: plot "
                                   f"{row['plot']} is not part of workshop {workshop.name!r}")
        by_reviewer.setdefault(row["reviewer"], []).append(row)
    created = 0
    for username, items in by_reviewer.items():
        if users.find_user(session, username) is None:
            created += 1
        try:
            user = _reviewer_user(session, username, actor)
        except InvalidParameter as exc:
            raise InvalidParameter(f"{source_name} line {items[0]['line']}, column reviewer: "
                                   f"{exc}") from None
        r = session.scalar(select(WorkshopReviewer).where(
            WorkshopReviewer.workshop_id == workshop.id, WorkshopReviewer.user_id == user.id))
        done: dict[tuple[int, bool], int] = {}
        if r is None:
            r = WorkshopReviewer(workshop_id=workshop.id, user_id=user.id, seed=0, sequence=[],
                                 created_at=utcnow())
            session.add(r)
            session.flush()
        else:
            for a in own_answers(session, r.id).values():
                done[(a.plot_id, bool(a.repeat))] = a.position
        seq = [list(x) for x in r.sequence]
        now = utcnow()
        for row in items:
            key = (row["plot"], bool(row["repeat"]))
            if key in done:
                raise InvalidParameter(
                    f"{source_name} line {row['line']}, column plot: reviewer {username!r} has "
                    f"already answered plot {row['plot']}{' (repeat)' if row['repeat'] else ''} "
                    "in this workshop")
            pos = next((i for i, (p, rep) in enumerate(seq)
                        if p == row["plot"] and bool(rep) == bool(row["repeat"])), None)
            if pos is None:
                seq.append([row["plot"], bool(row["repeat"])])
                pos = len(seq) - 1
            done[key] = pos
            session.add(WorkshopAnswer(
                reviewer_id=r.id, plot_id=row["plot"], position=pos, repeat=bool(row["repeat"]),
                answer=bool(row["answer"]), comment=row.get("comment", "") or "",
                seconds=float(row.get("seconds") or 0.0), submission="", source="import",
                answered_at=now, updated_at=now))
        r.sequence = seq
    session.flush()
    audit.record(session, actor, "workshop.import", f"workshop:{workshop.name}",
                 detail={"answers": len(rows), "reviewers": len(by_reviewer),
                         "new_users": created, "file": source_name[:200]})
    return {"answers": len(rows), "reviewers": len(by_reviewer), "new_users": created}


def configuration_results(session: Session, campaign_id: int, config: str
                          ) -> list[dict[str, Any]]:
    """Per workshop of the campaign with plots of configuration ``config``: name, status, blind,
    plots of the configuration, answers on them and the share of Yes (first showings with
    the fixed scaling; hidden repeats and automatic-scaling plots left out)."""
    out = []
    for w in session.scalars(select(Workshop).where(Workshop.campaign_id == campaign_id)
                             .order_by(Workshop.name)):
        n_plots = session.scalar(select(func.count()).select_from(WorkshopPlot).where(
            WorkshopPlot.workshop_id == w.id, WorkshopPlot.configuration == config))
        if not n_plots:
            continue
        n, yes = session.execute(
            select(func.count(), func.coalesce(func.sum(case((WorkshopAnswer.answer, 1), else_=0)), 0))
            .select_from(WorkshopAnswer)
            .join(WorkshopPlot, WorkshopAnswer.plot_id == WorkshopPlot.id)
            .where(WorkshopPlot.workshop_id == w.id, WorkshopPlot.configuration == config,
                   WorkshopPlot.scaling == "fixed", WorkshopAnswer.repeat.is_(False))).one()
        out.append({"workshop": w.name, "status": w.status, "blind": bool(w.blind),
                    "plots": int(n_plots), "answers": int(n), "yes": int(yes),
                    "yes_share": (int(yes) / int(n)) if n else None})
    return out


def participations(session: Session, username: str) -> list[dict[str, Any]]:
    """The workshops ``username`` takes part in: ``workshop, status, blind, answered, total,
    finished, invited`` (a panelist's "my workshops")."""
    rows = session.execute(
        select(WorkshopReviewer, Workshop).join(Workshop, WorkshopReviewer.workshop_id == Workshop.id)
        .join(AppUser, WorkshopReviewer.user_id == AppUser.id)
        .where(AppUser.username == username).order_by(Workshop.name)).all()
    out = []
    for r, w in rows:
        n = session.scalar(select(func.count()).select_from(WorkshopAnswer)
                           .where(WorkshopAnswer.reviewer_id == r.id))
        out.append({"workshop": w.name, "status": w.status, "blind": bool(w.blind),
                    "answered": int(n), "total": len(r.sequence),
                    "finished": r.finished_at is not None, "invited": r.invited_at is not None})
    return out


def own_link(session: Session, workshop_name: str, username: str) -> str:
    """A new personal link token for ``username``'s existing participation in the workshop
    (the signed-in panelist opening it from "my workshops"; the earlier link stops
    working). :class:`NotFound` when they take no part in it."""
    w = get_workshop(session, workshop_name)
    took_part = session.scalar(
        select(func.count()).select_from(WorkshopReviewer)
        .join(AppUser, WorkshopReviewer.user_id == AppUser.id)
        .where(WorkshopReviewer.workshop_id == w.id, AppUser.username == username))
    if not took_part:
        raise NotFound(f"{username} takes no part in workshop {workshop_name!r}")
    return invite(session, w, username, actor=username)
