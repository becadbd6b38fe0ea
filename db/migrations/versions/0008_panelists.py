"""Roles: workshop participants become panelists; ``reviewer`` is the independent signer.

Before this revision the role ``reviewer`` covered both the experts of a review workshop and
the independent reviewer who signs off. Now ``panelist`` answers in workshops and
``reviewer`` reads all evidence and signs (docs/security.md, "Roles"). For every user
holding ``reviewer``:

* took part in a workshop (a ``workshop_reviewer`` row) and never signed off → the role
  ``reviewer`` is replaced by ``panelist`` (a workshop-only participant can no longer sign);
* took part in a workshop and also signed off → ``panelist`` is added, ``reviewer`` kept
  (their personal workshop links keep working);
* never took part in a workshop → unchanged.

Unused invitations with role ``reviewer`` to a workshop become ``panelist`` invitations.
Every change is one audit row (``user.roles`` / ``invitation.role``, actor ``migration``,
reason naming this revision), so ``railval audit log --actor migration`` lists who was
changed. The user's before/after state hashes the same fields as
:func:`railval.db.users.user_state`.

Revision ID: 0008_panelists
Revises: 0007_signatures
"""
from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op

from railval.db import audit

revision: str = "0008_panelists"
down_revision: str | Sequence[str] | None = "0007_signatures"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None

ACTOR = "migration"
REASON = ("migration 0008_panelists: workshop participants hold the role panelist; reviewer "
          "is the independent signer")


def _state(conn, user_id: int) -> dict:
    u = conn.execute(sa.text("SELECT username, display_name, disabled, password_hash "
                             "FROM app_user WHERE id = :i"), {"i": user_id}).one()
    roles = sorted(r for (r,) in conn.execute(
        sa.text("SELECT role FROM user_role WHERE user_id = :i"), {"i": user_id}))
    return {"username": u[0], "display_name": u[1], "disabled": bool(u[2]), "roles": roles,
            "password_set": u[3] is not None}


def upgrade() -> None:
    from sqlalchemy.orm import Session

    conn = op.get_bind()
    session = Session(bind=conn)
    rows = conn.execute(sa.text(
        "SELECT u.id, u.username, "
        "  EXISTS (SELECT 1 FROM workshop_reviewer w WHERE w.user_id = u.id), "
        "  EXISTS (SELECT 1 FROM signoff s WHERE s.user_id = u.id OR s.username = u.username) "
        "FROM app_user u JOIN user_role r ON r.user_id = u.id "
        "WHERE r.role = 'reviewer' ORDER BY u.id")).all()
    for user_id, username, took_part, signed in rows:
        if not took_part:
            continue
        before = _state(conn, user_id)
        if not signed:
            conn.execute(sa.text("DELETE FROM user_role WHERE user_id = :i AND role = 'reviewer'"),
                         {"i": user_id})
        if "panelist" not in before["roles"]:
            conn.execute(sa.text("INSERT INTO user_role (user_id, role) VALUES (:i, 'panelist')"),
                         {"i": user_id})
        after = _state(conn, user_id)
        audit.record(session, ACTOR, "user.roles", f"user:{username}", before, after, REASON,
                     detail={"roles": after["roles"], "was": before["roles"],
                             "kept_reviewer": bool(signed)})
    for inv_id, ref in conn.execute(sa.text(
            "SELECT id, workshop_ref FROM invitation WHERE role = 'reviewer' "
            "AND workshop_ref IS NOT NULL AND used_at IS NULL ORDER BY id")).all():
        conn.execute(sa.text("UPDATE invitation SET role = 'panelist' WHERE id = :i"),
                     {"i": inv_id})
        audit.record(session, ACTOR, "invitation.role", f"invitation:{inv_id}",
                     {"role": "reviewer"}, {"role": "panelist"}, REASON,
                     detail={"workshop_ref": ref, "role": "panelist"})
    session.flush()
    session.close()


def downgrade() -> None:
    """Roles are data: a downgrade leaves them (a panelist role is unknown to older code and
    grants nothing there)."""
