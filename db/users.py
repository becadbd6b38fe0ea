"""Users, roles and invitations (docs/security.md).

Passwords are hashed with argon2id (argon2-cffi's :class:`PasswordHasher`, whose defaults are
the RFC 9106 §4 second recommended option: t = 3, m = 64 MiB, p = 4) and never stored or
compared in clear. Invitation tokens are 256-bit random strings of which only the SHA-256 is
stored; an invitation is single-use and expires. Every change appends an audit row in the
same transaction (:func:`railval.db.audit.record`). Roles are the names of
:data:`railval.core.roles.ROLES`.

Sign-in (:func:`login_state` read, :func:`check_password` outside any transaction,
:func:`record_login` write; :func:`authenticate` runs the three in one session) is rate
limited from the audit trail itself: after
:data:`MAX_FAILURES_PER_USER` failed sign-ins of one user name (or
:data:`MAX_FAILURES_PER_SOURCE` from one client address) within :data:`FAILURE_WINDOW`,
further attempts are refused until the window has passed; every failure and every refusal
is recorded.
"""

from __future__ import annotations

import datetime as dt
import functools
import hashlib
import re
import secrets
from dataclasses import dataclass
from typing import Any

from argon2 import PasswordHasher
from argon2.exceptions import InvalidHashError, VerificationError, VerifyMismatchError
from sqlalchemy import delete, func, or_, select, update
from sqlalchemy.orm import Session, selectinload

from railval.core.errors import InvalidParameter, NotFound, RailvalError
from railval.core.roles import ROLES, PermissionDenied, Principal, check_roles, require
from railval.db import audit
from railval.db.models import (
    AppSession,
    AppUser,
    AuditEvent,
    Invitation,
    UserRole,
    Workshop,
    utcnow,
)

__all__ = [
    "InvitationRefused",
    "LoginResult",
    "LoginState",
    "authenticate",
    "check_password",
    "create_invitation",
    "create_user",
    "disable",
    "enable",
    "end_session",
    "end_sessions",
    "get_user",
    "has_admin",
    "has_users",
    "list_users",
    "live_principal",
    "login_state",
    "open_session",
    "principal",
    "record_login",
    "redeem_invitation",
    "require_live",
    "session_principal",
    "set_password",
    "set_roles",
    "verify_password",
]

MIN_PASSWORD_LENGTH = 8
MAX_FAILURES_PER_USER = 5
MAX_FAILURES_PER_SOURCE = 20
FAILURE_WINDOW = dt.timedelta(minutes=15)
INVITATION_VALIDITY = dt.timedelta(days=7)
_USERNAME = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.@-]{0,99}$")

_hasher = PasswordHasher()  # argon2id, RFC 9106 defaults


@functools.cache
def _dummy_hash() -> str:
    """Verified against for unknown user names, so that their answer takes as long as a real
    one; made on first use (an argon2 hash costs a third of a second, too much for every start
    of the command line)."""
    return _hasher.hash(secrets.token_hex(16))


class InvitationRefused(RailvalError):
    """An invitation token is unknown, expired or already used."""


def _aware(when: dt.datetime | None) -> dt.datetime | None:
    """SQLite returns naive datetimes for ``DateTime(timezone=True)``: they are UTC."""
    if when is not None and when.tzinfo is None:
        return when.replace(tzinfo=dt.UTC)
    return when


def _check_username(username: str) -> str:
    username = (username or "").strip()
    if not _USERNAME.match(username):
        raise InvalidParameter(
            f"user name {username!r}: use 1–100 letters, digits, '_', '.', '@' or '-', "
            "starting with a letter or digit")
    return username


def _check_password(password: str) -> None:
    if not isinstance(password, str) or len(password) < MIN_PASSWORD_LENGTH:
        raise InvalidParameter(f"password: at least {MIN_PASSWORD_LENGTH} characters are needed")


def hash_password(password: str) -> str:
    """The argon2id hash string (PHC format) of ``password``."""
    _check_password(password)
    return _hasher.hash(password)


def user_state(user: AppUser) -> dict[str, Any]:
    """What an audit row's before/after hash of a user covers (never the password hash)."""
    return {"username": user.username, "display_name": user.display_name,
            "disabled": bool(user.disabled), "roles": sorted(r.role for r in user.roles),
            "password_set": user.password_hash is not None}


# -- queries -----------------------------------------------------------------------------
def has_users(session: Session) -> bool:
    """True when at least one user exists (then the web app requires sign-in)."""
    return session.scalar(select(func.count()).select_from(AppUser)) > 0


def has_admin(session: Session) -> bool:
    """True when an enabled user holds the role ``admin`` (someone can manage users)."""
    return session.scalar(
        select(func.count()).select_from(AppUser).join(UserRole, UserRole.user_id == AppUser.id)
        .where(UserRole.role == "admin", AppUser.disabled.is_(False))) > 0


def list_users(session: Session) -> list[AppUser]:
    return list(session.scalars(select(AppUser).options(selectinload(AppUser.roles))
                                .order_by(AppUser.username)))


def get_user(session: Session, username: str, *, lock: bool = False) -> AppUser:
    """The user ``username`` (:class:`NotFound` when missing). ``lock``: its row is locked
    ``FOR UPDATE`` until the transaction ends (PostgreSQL; SQLite's write transaction holds
    the whole database): a write that re-reads the user ``FOR SHARE``
    (:func:`live_principal`) waits for the change and then sees it."""
    query = select(AppUser).options(selectinload(AppUser.roles)).where(AppUser.username == username)
    user = session.scalar(query.with_for_update() if lock else query)
    if user is None:
        raise NotFound(f"user {username!r} not found")
    return user


def find_user(session: Session, username: str) -> AppUser | None:
    return session.scalar(select(AppUser).options(selectinload(AppUser.roles))
                          .where(AppUser.username == username))


def principal(user: AppUser) -> Principal:
    """The :class:`railval.core.roles.Principal` of a user (no roles when disabled)."""
    roles = frozenset() if user.disabled else frozenset(user.role_names)
    return Principal(user.username, roles, display_name=user.display_name, user_id=user.id)


# -- changes (each audited) --------------------------------------------------------------
def create_user(session: Session, username: str, *, display_name: str = "",
                password: str | None = None, roles: tuple[str, ...] | list[str] = (),
                actor: Any = "system", reason: str = "") -> AppUser:
    """Add a user (password optional: NULL cannot sign in until one is set)."""
    username = _check_username(username)
    roles = check_roles(roles)
    if find_user(session, username) is not None:
        raise InvalidParameter(f"user {username!r} already exists")
    user = AppUser(username=username, display_name=(display_name or "").strip()[:200],
                   password_hash=hash_password(password) if password is not None else None,
                   disabled=False)
    user.roles = [UserRole(role=r) for r in roles]
    session.add(user)
    session.flush()
    audit.record(session, actor, "user.add", f"user:{username}", None, user_state(user), reason)
    return user


def set_roles(session: Session, username: str, roles: list[str] | tuple[str, ...], *,
              actor: Any = "system", reason: str = "") -> AppUser:
    """Replace the user's roles by ``roles``."""
    user = get_user(session, username, lock=True)
    roles = check_roles(roles)
    before = user_state(user)
    user.roles = [UserRole(role=r) for r in roles]
    session.flush()
    end_sessions(session, user.id, "user.roles")
    audit.record(session, actor, "user.roles", f"user:{username}", before, user_state(user),
                 reason, detail={"roles": roles})
    return user


def disable(session: Session, username: str, *, actor: Any = "system", reason: str = "") -> AppUser:
    """Disable a user: they can no longer sign in and hold no permission."""
    user = get_user(session, username, lock=True)
    before = user_state(user)
    user.disabled = True
    session.flush()
    end_sessions(session, user.id, "user.disable")
    audit.record(session, actor, "user.disable", f"user:{username}", before, user_state(user),
                 reason)
    return user


def enable(session: Session, username: str, *, actor: Any = "system", reason: str = "") -> AppUser:
    user = get_user(session, username)
    before = user_state(user)
    user.disabled = False
    session.flush()
    audit.record(session, actor, "user.enable", f"user:{username}", before, user_state(user),
                 reason)
    return user


def set_password(session: Session, username: str, password: str, *, actor: Any = "system",
                 reason: str = "") -> AppUser:
    user = get_user(session, username, lock=True)
    before = user_state(user)
    user.password_hash = hash_password(password)
    session.flush()
    end_sessions(session, user.id, "user.password")
    audit.record(session, actor, "user.password", f"user:{username}", before, user_state(user),
                 reason)
    return user


# -- sessions the server can end (docs/security.md, "Sessions") --------------------------
def session_hash(session_id: str) -> str:
    """The stored form of a session id: its SHA-256 (hex)."""
    return hashlib.sha256((session_id or "").encode("utf-8")).hexdigest()


#: how long a session row is kept after it ended or expired (who was signed in when, for an
#: inquiry); older rows of a user are deleted when that user signs in again
SESSION_KEEP_DAYS = 30


def open_session(session: Session, user: AppUser, *, max_age_s: float) -> str:
    """A new session of ``user`` valid for ``max_age_s`` seconds → its random id (256 bits;
    returned once for the cookie, only its SHA-256 is stored). The user's session rows that
    ended or expired more than :data:`SESSION_KEEP_DAYS` ago are deleted (the table holds the
    live sessions and a month of history, not every sign-in ever made)."""
    session_id = secrets.token_urlsafe(32)
    now = utcnow()
    cutoff = now - dt.timedelta(days=SESSION_KEEP_DAYS)
    session.execute(delete(AppSession).where(
        AppSession.user_id == user.id,
        or_(AppSession.expires_at < cutoff, AppSession.ended_at < cutoff)))
    session.add(AppSession(id_sha256=session_hash(session_id), user_id=user.id, created_at=now,
                           expires_at=now + dt.timedelta(seconds=max_age_s), end_reason=""))
    session.flush()
    return session_id


def session_principal(session: Session, session_id: str) -> Principal | None:
    """The principal of a live session: one read by the unique hash (joined with the user and
    its roles, plain columns: no ORM objects are built); None when the id is unknown, the
    session ended or expired, or the user is disabled or has no password."""
    rows = session.execute(
        select(AppSession.expires_at, AppSession.ended_at, AppUser.id, AppUser.username,
               AppUser.display_name, AppUser.disabled, AppUser.password_hash.is_not(None),
               UserRole.role)
        .join(AppUser, AppUser.id == AppSession.user_id)
        .outerjoin(UserRole, UserRole.user_id == AppUser.id)
        .where(AppSession.id_sha256 == session_hash(session_id))).all()
    if not rows:
        return None
    expires_at, ended_at, user_id, username, display, disabled, has_password, _ = rows[0]
    if ended_at is not None or _aware(expires_at) <= dt.datetime.now(dt.UTC):
        return None
    if disabled or not has_password:
        return None
    return Principal(username, frozenset(r[-1] for r in rows if r[-1]), display_name=display,
                     user_id=user_id)


def end_session(session: Session, session_id: str, reason: str = "logout") -> bool:
    """End one session (sign-out); True when it was open."""
    n = session.execute(update(AppSession).where(
        AppSession.id_sha256 == session_hash(session_id), AppSession.ended_at.is_(None))
        .values(ended_at=utcnow(), end_reason=reason[:40])).rowcount
    return bool(n)


def end_sessions(session: Session, user_id: int, reason: str) -> int:
    """End every open session of a user (disable, password or role change) → how many."""
    return int(session.execute(update(AppSession).where(
        AppSession.user_id == user_id, AppSession.ended_at.is_(None))
        .values(ended_at=utcnow(), end_reason=reason[:40])).rowcount or 0)


def live_principal(session: Session, user_id: int) -> Principal | None:
    """The user as stored now, read inside the caller's write transaction with a shared
    row lock (``FOR SHARE OF app_user`` on PostgreSQL): a disable, password or role change
    (:func:`get_user` with ``lock``) either commits before it — and is seen — or waits
    until this transaction has committed. None when the user no longer exists; a disabled
    user's principal holds no role. One read of plain columns (user and roles)."""
    rows = session.execute(
        select(AppUser.username, AppUser.display_name, AppUser.disabled, UserRole.role)
        .outerjoin(UserRole, UserRole.user_id == AppUser.id)
        .where(AppUser.id == user_id).with_for_update(read=True, of=AppUser)).all()
    if not rows:
        return None
    username, display, disabled, _ = rows[0]
    roles = frozenset() if disabled else frozenset(r[-1] for r in rows if r[-1])
    return Principal(username, roles, display_name=display, user_id=user_id)


def require_live(session: Session, actor: Any, action: str) -> None:
    """Refuse a write (:class:`railval.core.errors.PermissionDenied`) unless ``actor`` — a
    principal of a stored user — may still do ``action`` as the database says now (re-read
    by :func:`live_principal` in the caller's write transaction, never a cached principal).
    Actors that are no stored user (open single-user mode, the CLI's ``system``) pass."""
    user_id = getattr(actor, "user_id", None)
    if user_id is None or getattr(actor, "open_mode", False):
        return
    now = live_principal(session, user_id)
    if now is None:
        raise PermissionDenied(f"user {actor.username!r} no longer exists")
    require(now, action)


# -- passwords and sign-in ---------------------------------------------------------------
def verify_password(session: Session, username: str, password: str) -> AppUser | None:
    """The user when ``password`` matches its argon2id hash and the user is enabled, else None.

    Unknown users take as long as known ones (a dummy hash is verified). Rehashes the stored
    hash when the hasher's parameters changed since it was made.
    """
    user = find_user(session, username)
    stored = user.password_hash if user is not None else None
    try:
        _hasher.verify(stored or _dummy_hash(), password or "")
    except (VerifyMismatchError, VerificationError, InvalidHashError):
        return None
    if user is None or stored is None or user.disabled:
        return None
    if _hasher.check_needs_rehash(stored):
        user.password_hash = _hasher.hash(password)
    return user


def password_changed_at(session: Session, username: str) -> float:
    """POSIX time of the user's last password change or disabling (0 if never): sessions
    issued before it end (:mod:`railval.app.auth`)."""
    last = session.scalar(select(func.max(AuditEvent.at_utc)).where(
        AuditEvent.object == f"user:{username}",
        AuditEvent.action.in_(("user.password", "user.disable"))))
    if not last:
        return 0.0
    return dt.datetime.strptime(last, "%Y-%m-%dT%H:%M:%S.%fZ").replace(tzinfo=dt.UTC).timestamp()


@dataclass(frozen=True)
class LoginResult:
    """Outcome of :func:`authenticate` / :func:`record_login`: ``user`` on success, else a
    message to show; ``reason``: ``ok``, ``rate limit``, ``account disabled``, ``account
    changed`` or ``wrong user name or password``."""

    user: AppUser | None
    message: str
    reason: str = "ok"

    @property
    def ok(self) -> bool:
        return self.user is not None


@dataclass(frozen=True)
class LoginState:
    """What a sign-in reads before the password is verified (:func:`login_state`): the user's
    id, stored hash and disabled flag as they were, and whether the rate limit already
    refuses. :func:`record_login` re-checks them in the write transaction."""

    username: str
    user_id: int | None
    stored_hash: str | None
    disabled: bool
    limited: bool


def _failures(session: Session, username: str, source: str) -> tuple[int, int]:
    since = audit.utc_stamp(dt.datetime.now(dt.UTC) - FAILURE_WINDOW)
    per_user = audit.count_since(session, "login.failed", since, object=f"user:{username}")
    per_source = (audit.count_since(session, "login.failed", since, source=source)
                  if source else 0)
    return per_user, per_source


def _limited(session: Session, username: str, source: str) -> tuple[bool, int]:
    per_user, per_source = _failures(session, username, source)
    return (per_user >= MAX_FAILURES_PER_USER
            or bool(source and per_source >= MAX_FAILURES_PER_SOURCE)), per_user


def login_state(session: Session, username: str, source: str = "") -> LoginState:
    """The read half of a sign-in (a read session: no write lock is taken)."""
    username = (username or "").strip()[:100]
    limited, _ = _limited(session, username, source)
    row = session.execute(select(AppUser.id, AppUser.password_hash, AppUser.disabled)
                          .where(AppUser.username == username)).first()
    if row is None:
        return LoginState(username, None, None, False, limited)
    return LoginState(username, row[0], row[1], bool(row[2]), limited)


def check_password(stored_hash: str | None, password: str) -> bool:
    """True when ``password`` matches ``stored_hash`` (argon2id). With no hash (unknown user,
    no password) a dummy hash is verified, so that the answer takes as long. Touches no
    database: call it with no transaction open (the hash costs 0.1–0.5 s)."""
    try:
        _hasher.verify(stored_hash or _dummy_hash(), password or "")
    except (VerifyMismatchError, VerificationError, InvalidHashError):
        return False
    return stored_hash is not None


def rehash(stored_hash: str | None, password: str) -> str | None:
    """A new hash of a verified ``password`` when the hasher's parameters changed since
    ``stored_hash`` was made, else None (no transaction needed)."""
    if stored_hash is not None and _hasher.check_needs_rehash(stored_hash):
        return _hasher.hash(password)
    return None


def record_login(session: Session, state: LoginState, right: bool, *, source: str = "",
                 new_hash: str | None = None, record_success: bool = True) -> LoginResult:
    """The write half of a sign-in: ``right`` is the outcome of :func:`check_password` on
    ``state.stored_hash``. In the caller's write transaction, re-reads the rate-limit counts
    and the user (row locked ``FOR UPDATE`` on PostgreSQL): a limit reached meanwhile refuses
    (``login.refused``); a password, disabled flag or user changed since :func:`login_state`
    refuses (``login.refused``, reason ``account changed``) — the verified hash is no longer
    the stored one. Records every failure and refusal in the audit trail; the caller commits
    whatever the outcome."""
    username = state.username
    obj = f"user:{username or '(empty)'}"
    actor = username or "(anonymous)"
    limited, per_user = _limited(session, username, source)
    if limited:
        minutes = int(FAILURE_WINDOW.total_seconds() // 60)
        audit.record(session, actor, "login.refused", obj, reason="rate limit",
                     detail={"source": source, "failures": per_user})
        return LoginResult(None, f"Too many failed sign-ins; try again in {minutes} minutes.",
                           "rate limit")
    user = session.scalar(select(AppUser).options(selectinload(AppUser.roles))
                          .where(AppUser.username == username).with_for_update())
    now = ((user.id, user.password_hash, bool(user.disabled)) if user is not None
           else (None, None, False))
    if now != (state.user_id, state.stored_hash, state.disabled):
        audit.record(session, actor, "login.refused", obj, reason="account changed",
                     detail={"source": source})
        return LoginResult(None, "Your account changed while you were signing in; "
                                 "sign in again.", "account changed")
    if right and user is not None and not user.disabled:
        if new_hash is not None:
            user.password_hash = new_hash
        if record_success:
            audit.record(session, username, "login.ok", obj, detail={"source": source})
        return LoginResult(user, "")
    if right:  # the right password of a disabled account
        audit.record(session, username, "login.failed", obj, reason="account disabled",
                     detail={"source": source})
        return LoginResult(None, "This account is disabled; ask an administrator.",
                           "account disabled")
    audit.record(session, actor, "login.failed", obj,
                 reason="wrong user name or password", detail={"source": source})
    return LoginResult(None, "Wrong user name or password.", "wrong user name or password")


def authenticate(session: Session, username: str, password: str, *, source: str = "",
                 record_success: bool = True) -> LoginResult:
    """Check a sign-in in one transaction (:func:`login_state`, :func:`check_password`,
    :func:`record_login`); records every failure and refusal in the audit trail.

    The web sign-in does not use it: :mod:`railval.app.services.sessions` verifies the hash
    between a read and a short write session, so that no write lock is held for the hash.
    The caller commits ``session`` whatever the outcome (the audit row of a failure must
    persist). Messages say what to do without revealing whether a user name exists — except
    for a disabled account, which is only reported after the right password.
    """
    state = login_state(session, username, source)
    right = False if state.limited else check_password(state.stored_hash, password)
    new_hash = rehash(state.stored_hash, password) if right else None
    return record_login(session, state, right, source=source, new_hash=new_hash,
                        record_success=record_success)


# -- invitations -------------------------------------------------------------------------
def token_hash(token: str) -> str:
    return hashlib.sha256((token or "").encode("utf-8")).hexdigest()


def create_invitation(session: Session, *, role: str = "panelist", workshop_ref: str | int | None = None,
                      valid_for: dt.timedelta = INVITATION_VALIDITY, note: str = "",
                      actor: Any = "system") -> tuple[Invitation, str]:
    """A new single-use invitation → (row, token). The token is returned once, never stored.
    ``workshop_ref``: the workshop the invitee joins (:func:`railval.db.workshops.redeem_invitation`);
    it must exist, and only a panelist joins a workshop this way."""
    check_roles([role])
    if workshop_ref is not None:
        if role != "panelist":
            raise InvalidParameter(
                f"--workshop {workshop_ref!r}: an invitation joins its invitee to a workshop only "
                f"with the role panelist, not {role!r}; invite with --role panelist")
        if _workshop_id(session, str(workshop_ref)) is None:
            raise NotFound(f"workshop {str(workshop_ref)!r} not found; create it first "
                           "(`railval workshop create`)")
    if valid_for <= dt.timedelta(0):
        raise InvalidParameter(f"invitation validity {valid_for} must be positive")
    token = secrets.token_urlsafe(32)
    creator = find_user(session, getattr(actor, "username", str(actor)))
    inv = Invitation(token_sha256=token_hash(token), role=role,
                     workshop_ref=None if workshop_ref is None else str(workshop_ref),
                     note=(note or "")[:200], created_by=creator.id if creator else None,
                     created_at=utcnow(), expires_at=utcnow() + valid_for)
    session.add(inv)
    session.flush()
    audit.record(session, actor, "invitation.create", f"invitation:{inv.id}", None,
                 {"role": role, "workshop_ref": inv.workshop_ref,
                  "expires_at": audit.utc_stamp(inv.expires_at)},
                 detail={"role": role, "workshop_ref": inv.workshop_ref})
    return inv, token


def check_invitation(session: Session, token: str) -> Invitation:
    """The open invitation of ``token``; :class:`InvitationRefused` says why not."""
    inv = session.scalar(select(Invitation).where(Invitation.token_sha256 == token_hash(token)))
    if inv is None:
        raise InvitationRefused("This invitation link is not valid; ask the organiser for a new one.")
    if inv.used_at is not None:
        raise InvitationRefused("This invitation link has already been used; sign in instead, "
                                "or ask the organiser for a new one.")
    if _aware(inv.expires_at) <= dt.datetime.now(dt.UTC):
        raise InvitationRefused(
            f"This invitation link expired on {audit.utc_stamp(_aware(inv.expires_at))[:16]} UTC; "
            "ask the organiser for a new one.")
    if inv.workshop_ref is not None and inv.role == "panelist" \
            and _workshop_id(session, inv.workshop_ref) is None:  # other names not shown
        raise InvitationRefused(f"The workshop {inv.workshop_ref!r} of this invitation no longer "
                                "exists; ask the organiser for a new one.")
    return inv


def _workshop_id(session: Session, name: str) -> int | None:
    """The id of the workshop ``name`` (``None`` when there is none); :mod:`railval.db.workshops`
    imports this module, so the row is read here directly."""
    return session.scalar(select(Workshop.id).where(Workshop.name == name))


def redeem_invitation(session: Session, token: str, *, username: str, password: str,
                      display_name: str = "") -> AppUser:
    """Create the invitee's account with the invitation's role and mark the link used
    (:func:`railval.db.workshops.redeem_invitation` also makes a panelist invited to a
    workshop take part in it: what the ``/invite`` form calls).

    Raises :class:`InvitationRefused` (unknown, used, expired) — the caller records the
    refusal with :func:`record_refusal` in its own transaction — or
    :class:`InvalidParameter` (bad user name or password, name taken).
    """
    inv = check_invitation(session, token)
    user = create_user(session, username, display_name=display_name, password=password,
                       roles=[inv.role], actor=username,
                       reason=f"invitation {inv.id}")
    inv.used_at = utcnow()
    inv.used_by = user.id
    session.flush()
    audit.record(session, username, "invitation.redeem", f"invitation:{inv.id}",
                 detail={"role": inv.role, "workshop_ref": inv.workshop_ref, "user": username})
    return user


def record_refusal(session: Session, token: str, message: str, *, source: str = "") -> None:
    """Audit a refused invitation (only the first 8 hex digits of the token's hash)."""
    audit.record(session, "(anonymous)", "invitation.refused",
                 f"invitation:{token_hash(token)[:8]}", reason=message, detail={"source": source})


def role_names() -> list[str]:
    """The role registry's names (for forms and CLI choices)."""
    return list(ROLES)


def count_with_password(session: Session) -> int:
    """Users that have a password (none: the loopback-only open mode of the web pages)."""
    return int(session.scalar(select(func.count()).select_from(AppUser)
                              .where(AppUser.password_hash.is_not(None))) or 0)
