"""CLI verbs ``user …``: the administrator's user management (docs/security.md).

``railval user add NAME [--display-name TEXT] [--role R ...] [--password-stdin | --password-file F]``
``railval user list [--json]``
``railval user disable NAME [--reason TEXT]`` / ``railval user enable NAME``
``railval user passwd NAME [--password-stdin | --password-file F]``
``railval user role NAME ROLE [ROLE ...]`` (replaces the user's roles)
``railval user invite [--role panelist] [--workshop NAME] [--days 7] [--base-url URL]``
    (with ``--workshop``, the panelist takes part in that workshop once the account is made)

Passwords are never command-line arguments (they would stay in the shell history and the
process list): they come from a prompt (asked twice), one line of standard input
(``--password-stdin``) or the first line of a file (``--password-file``). While the database
holds no user, anyone with access to it may add the first one (make it an admin).
"""

from __future__ import annotations

import argparse
import getpass
import sys
from pathlib import Path

from railval.app.cli import emit_json
from railval.core.errors import RailvalError
from railval.core.roles import ROLES
from railval.core import lazy

# the services and records this module's verbs call, imported when a verb first uses
# them (railval.core.lazy): `railval --help` and the other verbs never load them
database_service = lazy.module("railval.app.services.database")
users_service = lazy.module("railval.app.services.users")


def _password_options(p: argparse.ArgumentParser) -> None:
    g = p.add_mutually_exclusive_group()
    g.add_argument("--password-stdin", action="store_true",
                   help="read the password from the first line of standard input")
    g.add_argument("--password-file", metavar="FILE",
                   help="read the password from the first line of FILE")


def read_password(args: argparse.Namespace, *, confirm: bool = True, prompt: str = "Password: ") -> str:
    """The password from ``--password-stdin``, ``--password-file`` or a prompt."""
    if getattr(args, "password_stdin", False):
        line = sys.stdin.readline()
        if not line:
            raise RailvalError("--password-stdin: standard input is empty")
        return line.rstrip("\r\n")
    if getattr(args, "password_file", None):
        path = Path(args.password_file)
        try:
            lines = path.read_text(encoding="utf-8").splitlines()
        except OSError as exc:
            raise RailvalError(f"--password-file {path}: {exc.strerror}") from None
        if not lines:
            raise RailvalError(f"--password-file {path}: the file is empty")
        return lines[0]
    if not sys.stdin.isatty():
        raise RailvalError("no terminal to ask the password: use --password-stdin or "
                           "--password-file")
    pw = getpass.getpass(prompt)
    if confirm and getpass.getpass("Repeat: ") != pw:
        raise RailvalError("the two passwords differ")
    return pw


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("user", help="manage users and roles (admin)")
    us = p.add_subparsers(dest="subverb", metavar="SUBVERB")
    us.required = True

    a = us.add_parser("add", help="add a user")
    a.add_argument("name", help="user name (letters, digits, _ . @ -)")
    a.add_argument("--display-name", default="", help="printed name (shown with signatures)")
    a.add_argument("--role", action="append", default=[], choices=list(ROLES),
                   help="a role (repeatable)")
    a.add_argument("--no-password", action="store_true",
                   help="create without a password (cannot sign in until `user passwd`)")
    a.add_argument("--reason", default="", help="reason recorded in the audit trail")
    _password_options(a)
    a.set_defaults(func=_cmd_add)

    ls = us.add_parser("list", help="list users with roles and state")
    ls.add_argument("--json", action="store_true", help="print JSON")
    ls.set_defaults(func=_cmd_list)

    for name, helptext, func in (("disable", "disable a user (no sign-in, no permission)", _cmd_disable),
                                 ("enable", "enable a disabled user", _cmd_enable)):
        d = us.add_parser(name, help=helptext)
        d.add_argument("name")
        d.add_argument("--reason", default="", help="reason recorded in the audit trail")
        d.set_defaults(func=func)

    pw = us.add_parser("passwd", help="set a user's password")
    pw.add_argument("name")
    pw.add_argument("--reason", default="", help="reason recorded in the audit trail")
    _password_options(pw)
    pw.set_defaults(func=_cmd_passwd)

    r = us.add_parser("role", help="replace a user's roles")
    r.add_argument("name")
    r.add_argument("roles", nargs="*", choices=list(ROLES), metavar="ROLE",
                   help=f"roles: {', '.join(ROLES)} (none = no role)")
    r.add_argument("--reason", default="", help="reason recorded in the audit trail")
    r.set_defaults(func=_cmd_role)

    inv = us.add_parser("invite", help="create a single-use invitation link")
    inv.add_argument("--role", default="panelist", choices=list(ROLES),
                     help="role of the invitee (default panelist: a workshop participant)")
    inv.add_argument("--workshop", default=None, metavar="NAME",
                     help="workshop the invitee takes part in once the account is made "
                          "(with --role panelist; the workshop must exist)")
    inv.add_argument("--days", type=float, default=7.0, help="validity in days (default 7)")
    inv.add_argument("--base-url", default="http://127.0.0.1:5006",
                     help="server address printed in the link")
    inv.add_argument("--json", action="store_true", help="print JSON")
    inv.set_defaults(func=_cmd_invite)


def _database(args):
    return database_service.open_database(args.db, upgrade=True)


def _cmd_add(args) -> int:
    password = None if args.no_password else read_password(args)
    name, roles = users_service.add(_database(args), args.name, display_name=args.display_name,
                                    password=password, roles=args.role, reason=args.reason)
    print(f"user {name} added (roles: {', '.join(roles) or 'none'})")
    return 0


def _cmd_list(args) -> int:
    rows = users_service.rows(_database(args))
    if args.json:
        emit_json({"users": rows})
        return 0
    if not rows:
        print("no users: `railval serve` runs in open single-user mode on 127.0.0.1 only; "
              "add the first admin with `railval user add NAME --role admin`")
        return 0
    width = max(len(r["username"]) for r in rows)
    for r in rows:
        state = "disabled" if r["disabled"] else ("no password" if not r["password_set"] else "active")
        print(f"{r['username']:<{width}}  {state:<11}  {', '.join(r['roles']) or '-':<30}  "
              f"{r['display_name']}")
    return 0


def _cmd_disable(args) -> int:
    users_service.set_disabled(_database(args), args.name, True, reason=args.reason)
    print(f"user {args.name} disabled")
    return 0


def _cmd_enable(args) -> int:
    users_service.set_disabled(_database(args), args.name, False, reason=args.reason)
    print(f"user {args.name} enabled")
    return 0


def _cmd_passwd(args) -> int:
    database = _database(args)
    users_service.require_user(database, args.name)
    password = read_password(args)
    users_service.set_password(database, args.name, password, reason=args.reason)
    print(f"password of {args.name} set")
    return 0


def _cmd_role(args) -> int:
    name, roles = users_service.set_roles(_database(args), args.name, args.roles, reason=args.reason)
    print(f"user {name}: roles {', '.join(roles) or 'none'}")
    return 0


def _cmd_invite(args) -> int:
    if args.days <= 0:
        raise RailvalError(f"--days {args.days}: must be positive")
    token, expires = users_service.invite(_database(args), role=args.role, workshop=args.workshop,
                                  days=args.days)
    link = f"{args.base_url.rstrip('/')}/invite?token={token}"
    if args.json:
        emit_json({"link": link, "role": args.role, "workshop": args.workshop,
                   "expires_at_utc": expires})
    else:
        joins = f" to workshop {args.workshop}" if args.workshop else ""
        print(f"single-use invitation ({args.role}{joins}), valid until {expires[:16]} UTC:\n{link}")
    return 0
