"""The reviewer's units of work behind a personal link (docs/design.md §5): who the link
belongs to, their answers so far, a plot image, storing an answer, finishing.

Every answer is stored the moment it is given, in its own ``session(write=True)``: on SQLite
that unit of work takes the write lock at ``BEGIN IMMEDIATE`` (waiting up to the busy
timeout for a concurrent answer) instead of failing to upgrade a read snapshot
(:meth:`railval.db.engine.Database.session`).
"""

from __future__ import annotations

from typing import Any

from railval.core.errors import NotFound
from railval.core.roles import PermissionDenied
from railval.db import workshops as wsdb
from railval.db.workshops import AnswerOutcome, ReviewerContext, WorkshopClosed

__all__ = ["AnswerOutcome", "ReviewerContext", "WorkshopClosed", "answers", "context", "finish",
           "plot_image", "record_answer"]


def context(database, token: str) -> ReviewerContext | None:
    """The reviewer, workshop and sequence of a personal link; None for an unknown link."""
    with database.session() as s:
        return wsdb.reviewer_by_token(s, token)


def answers(database, reviewer_id: int) -> dict[int, dict[str, Any]]:
    """place → ``{"answer": bool, "comment": str, "changes": int, "updated_at": str}`` of
    one reviewer's stored answers (``updated_at`` ISO 8601 UTC, when given or last changed)."""
    with database.session() as s:
        return {i: {"answer": bool(a.answer), "comment": a.comment, "changes": int(a.changes or 0),
                    "updated_at": wsdb.utc_text(a.updated_at)}
                for i, a in wsdb.own_answers(s, reviewer_id).items()}


def plot_image(database, workshop_id: int, plot_id: int) -> tuple[bytes, str]:
    """(PNG bytes, SHA-256) of one stored plot (exactly the bytes every reviewer sees)."""
    with database.session() as s:
        return wsdb.plot_image(s, workshop_id, plot_id)


def record_answer(database, ctx: ReviewerContext, position: int, answer: bool, *,
                  seconds: float, comment: str = "", submission: str = "") -> AnswerOutcome:
    """Store one answer (:func:`railval.db.workshops.record_answer`) in a unit of work that
    writes; returns ``"new"``, ``"changed"`` (with the answer it replaced) or
    ``"repeated"``. The reviewer's account is read again inside that unit of work: a
    disable committed before it refuses the answer
    (:class:`railval.core.roles.PermissionDenied`), whatever ``ctx`` says."""
    with database.session(write=True) as s:
        return wsdb.record_answer(s, ctx, position, answer, seconds=seconds, comment=comment,
                                  submission=submission)


def finish(database, token: str, may_answer) -> None:
    """Mark the reviewer of ``token`` finished; ``may_answer(ctx)`` decides whether the link
    still counts (:class:`railval.core.errors.NotFound` when not)."""

    with database.session(write=True) as s:
        ctx = wsdb.reviewer_by_token(s, token)
        if ctx is None or not may_answer(ctx):
            raise NotFound("review link not valid")
        refusal = wsdb.answer_refusal(s, ctx)  # the account as stored now, row locked
        if refusal:
            raise PermissionDenied(refusal)
        wsdb.finish(s, ctx)
