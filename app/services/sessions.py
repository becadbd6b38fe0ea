"""Sign-in, sessions and open mode as units of work (docs/security.md, "Sign-in"): the one door
that ``/login``, ``/logout``, ``/invite``, the workshop pages' own sign-in and every session
check of :mod:`railval.app.auth` go through (docs/design.md §2: services are the only door to
the database).

* :func:`sign_in` — the one sign-in. The user's hash, disabled flag and the rate-limit counts
  are read in a read session; the argon2id hash (0.1–0.5 s) is verified with **no transaction
  open**; the outcome (audit row, server-side session) is written in a short write session that
  re-checks the user and the limit (:func:`railval.db.users.record_login`). On SQLite a write
  session holds the database's write lock (``BEGIN IMMEDIATE``): reviewers' answers no longer
  wait for a hash.
* :func:`is_open` — the one open-mode rule: no sign-in is asked while **no user has a
  password** (nobody could sign in: no users yet, or only the password-less panelists an
  answer import creates) **and** the request comes from the loopback interface without proxy
  headers. A user with a password → every request needs sign-in.
* :func:`principal` — the one read of who is asking (page load, websocket, each action's
  re-check): the session row, else open mode, else nobody.
"""

from __future__ import annotations

from dataclasses import dataclass

from railval.core.errors import InvalidParameter
from railval.core.roles import Principal, open_principal
from railval.db import audit, users, workshops


@dataclass(frozen=True)
class SignIn:
    """Outcome of :func:`sign_in`: ``session_id`` (for the cookie) and ``principal`` on
    success; else ``message`` and ``reason`` (``rate limit``, ``account disabled``, ``account
    changed``, ``wrong user name or password``)."""

    ok: bool
    message: str
    reason: str
    username: str = ""
    principal: Principal | None = None
    session_id: str | None = None


def _open_rule(s, local: bool) -> bool:
    return local and users.count_with_password(s) == 0


def is_open(database, local: bool) -> bool:
    """The open-mode rule (module docstring): ``local`` = the request came from a loopback
    address without proxy headers."""
    if not local:
        return False
    with database.session() as s:
        return _open_rule(s, local)


def sign_in_required(database) -> bool:
    """True when some user has a password: open mode is over on every address."""
    return not is_open(database, True)


def sign_in(database, username: str, password: str, *, source: str = "",
            max_age_s: float | None = None, record_success: bool = True) -> SignIn:
    """Check a password (argon2id, rate limited, every failure and refusal recorded) and, on
    success with ``max_age_s``, open a server-side session of that many seconds."""
    with database.session() as s:
        state = users.login_state(s, username, source)
    right = False if state.limited else users.check_password(state.stored_hash, password)
    new_hash = users.rehash(state.stored_hash, password) if right else None
    with database.session(actor=state.username or "(anonymous)", write=True) as s:
        res = users.record_login(s, state, right, source=source, new_hash=new_hash,
                                 record_success=record_success)
        if not res.ok:
            return SignIn(False, res.message, res.reason, state.username)
        sid = (users.open_session(s, res.user, max_age_s=max_age_s)
               if max_age_s is not None else None)
        return SignIn(True, "", "ok", res.user.username, users.principal(res.user), sid)


def principal(database, session_id: str | None, local: bool) -> Principal | None:
    """Who is asking: the principal of a live session (:func:`railval.db.users.session_principal`),
    else the open-mode principal when :func:`is_open`, else None."""
    with database.session() as s:
        if session_id is not None:
            p = users.session_principal(s, session_id)
            if p is not None:
                return p
        return open_principal() if _open_rule(s, local) else None


def sign_out(database, session_id: str, username: str, *, source: str = "") -> None:
    """End the session on the server (``logout`` in the audit trail)."""
    with database.session(actor=username, write=True) as s:
        users.end_session(s, session_id, "logout")
        audit.record(s, username, "logout", f"user:{username}", detail={"source": source})


def check_invitation(database, token: str):
    """The open invitation of ``token`` as ``(role, workshop_ref)``;
    :class:`railval.db.users.InvitationRefused` says why not."""
    with database.session() as s:
        inv = users.check_invitation(s, token)
        return inv.role, inv.workshop_ref


def refuse_invitation(database, token: str, message: str, *, source: str = "") -> None:
    """Record a refused invitation (``invitation.refused``)."""
    with database.session(actor="(anonymous)", write=True) as s:
        users.record_refusal(s, token, message, source=source)


def redeem(database, token: str, *, username: str, password: str, password2: str,
           display_name: str, max_age_s: float) -> tuple[Principal, str]:
    """Create the invitee's account (:func:`railval.db.workshops.redeem_invitation`) and open
    its session → (principal, session id). Raises ``InvitationRefused`` or
    :class:`railval.core.errors.InvalidParameter` (nothing stored then)."""
    with database.session(actor=username or "(anonymous)", write=True) as s:
        users.check_invitation(s, token)
        if password != password2:
            raise InvalidParameter("the two passwords differ")
        user = workshops.redeem_invitation(s, token, username=username, password=password,
                                           display_name=display_name)
        sid = users.open_session(s, user, max_age_s=max_age_s)
        return users.principal(user), sid


def warm_up() -> None:
    """Make the dummy hash now, so that the first unknown name is answered as slowly as a
    known one."""
    users._dummy_hash()


InvitationRefused = users.InvitationRefused
MIN_PASSWORD_LENGTH = users.MIN_PASSWORD_LENGTH
