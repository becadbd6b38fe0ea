"""Users, roles, sign-in and invitations as units of work (docs/security.md): what the
``user`` verbs, the CLI's permission check and the workshop pages' sign-in call instead of
:mod:`railval.db.users` (docs/design.md §2: services are the only door to the database).

Every change is one ``session(write=True)`` audited by :mod:`railval.db.users`; sign-in writes
too (a failed attempt is recorded and counts towards the rate limit).
"""

from __future__ import annotations

import datetime as dt
from dataclasses import dataclass
from typing import Any

from railval.core import lazy
from railval.core.errors import RailvalError
from railval.core.roles import Principal, open_principal, require
from railval.db import audit, users

#: deferred (railval.core.lazy): the sign-in service (92 more modules) only for the calls
#: that reach it, not for `railval user list`
sessions = lazy.module("railval.app.services.sessions")


def add(database, name: str, *, display_name: str = "", password: str | None,
        roles: list[str], reason: str = "") -> tuple[str, list[str]]:
    """Create a user; returns their stored name and role names."""
    with database.session(write=True) as s:
        u = users.create_user(s, name, display_name=display_name, password=password,
                              roles=roles, actor=database.actor, reason=reason)
        return u.username, list(u.role_names)


def rows(database) -> list[dict[str, Any]]:
    """Every user as ``{username, display_name, roles, disabled, password_set, created_at}``."""
    with database.session() as s:
        return [{"username": u.username, "display_name": u.display_name,
                 "roles": u.role_names, "disabled": bool(u.disabled),
                 "password_set": u.password_hash is not None,
                 "created_at": u.created_at.isoformat()} for u in users.list_users(s)]


def set_disabled(database, name: str, disabled: bool, *, reason: str = "") -> None:
    """Disable (no sign-in, no permission) or enable a user."""
    change = users.disable if disabled else users.enable
    with database.session(write=True) as s:
        change(s, name, actor=database.actor, reason=reason)


def require_user(database, name: str) -> None:
    """:class:`railval.core.errors.NotFound` unless user ``name`` exists."""
    with database.session() as s:
        users.get_user(s, name)


def set_password(database, name: str, password: str, *, reason: str = "") -> None:
    with database.session(write=True) as s:
        users.set_password(s, name, password, actor=database.actor, reason=reason)


def set_roles(database, name: str, roles: list[str], *, reason: str = "") -> tuple[str, list[str]]:
    """Replace a user's roles; returns the user's name and stored role names."""
    with database.session(write=True) as s:
        u = users.set_roles(s, name, roles, actor=database.actor, reason=reason)
        return u.username, list(u.role_names)


def invite(database, *, role: str, workshop: str | None, days: float) -> tuple[str, str]:
    """A single-use invitation → (token, expiry as UTC stamp); the token is shown once."""
    with database.session(write=True) as s:
        inv, token = users.create_invitation(s, role=role, workshop_ref=workshop,
                                             valid_for=dt.timedelta(days=days),
                                             actor=database.actor)
        return token, audit.utc_stamp(users._aware(inv.expires_at))


def sign_in(database, username: str, password: str, *, source: str = "") -> tuple[bool, str]:
    """Check a password through the one sign-in (:func:`railval.app.services.sessions.sign_in`:
    argon2id outside any transaction, rate-limited) → (ok, message). A failed attempt is
    recorded."""

    res = sessions.sign_in(database, username, password, source=source)
    return res.ok, res.message


def cookie_principal(database, signed: tuple[str, float] | None, local: bool) -> Principal | None:
    """The user of a signed cookie ``(user, issued at)``, re-read on every request: disabled,
    or password changed after the cookie was issued → nobody; on the loopback while no user
    has a password: the open single-user principal (the one open-mode rule,
    :func:`railval.app.services.sessions.is_open`)."""

    with database.session() as s:
        if signed:
            username, issued = signed
            user = users.find_user(s, username)
            if (user is not None and not user.disabled
                    and users.password_changed_at(s, username) <= issued):
                return users.principal(user)
    return open_principal() if sessions.is_open(database, local) else None


def principal_of(database, actor: str) -> Principal | str:
    """The principal of user ``actor`` when the database holds users and knows them, else
    ``actor`` itself (the single-user mode)."""
    with database.session() as s:
        if users.has_users(s) and (u := users.find_user(s, actor)) is not None:
            return users.principal(u)
    return actor


@dataclass(frozen=True)
class CliPermission:
    """The outcome of :func:`check_cli`: ``first_admin`` when the verb runs because the
    database has users but no enabled admin (``user add NAME --role admin``)."""

    first_admin: bool = False


def check_cli(database, who: str | None, action: str, verb: str, *,
              adds_admin: bool) -> CliPermission:
    """May ``who`` run ``verb`` (permission ``action``) on this database? Without users
    every verb runs; while no enabled user holds ``admin``, ``adds_admin`` verbs run for
    whoever can write the database. Raises :class:`RailvalError` or
    :class:`railval.core.errors.PermissionDenied` otherwise."""
    with database.session() as s:
        if not users.has_users(s):
            return CliPermission()
        if adds_admin and not users.has_admin(s):
            return CliPermission(first_admin=True)
        if not who:
            raise RailvalError(
                f"this database has users: name the user you act as with --as USER or "
                f"RAILVAL_USER (`{verb}` needs the permission to {action})")
        user = users.find_user(s, who)
        if user is None:
            raise RailvalError(f"--as {who!r}: no such user in {database.safe_url}")
        if user.disabled:
            raise RailvalError(f"--as {who!r}: this account is disabled")
        require(users.principal(user), action)
    return CliPermission()
