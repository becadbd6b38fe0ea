"""The one registry of roles and what each role may do (docs/security.md).

A user holds any number of :data:`ROLES`; a permission is granted when one of the user's
roles lists it in :data:`PERMISSIONS`. Pages, widget callbacks, downloads, background jobs
and CLI verbs all ask :func:`allowed` / :func:`require` with one of the :data:`ACTIONS`
names — there is no second list anywhere.

* **admin** — manages users, roles and invitations; reads everything.
* **organiser** — runs review workshops (creates them, invites panelists, closes them).
* **engineer** — imports campaigns, runs simulate / diagnose / calibrate / validate, stores
  and deletes configurations, writes reports.
* **panelist** — takes part in the workshops they are invited to (sees only that workshop's
  plots and their own answers); nothing else, no sign-off.
* **reviewer** — the independent reviewer: reads all the evidence of every campaign (data,
  results, reports, diagnoses, workshop results, earlier sign-offs), changes nothing and
  signs off a configuration.
* **assessor** — reads everything (data, results, reports, sign-offs, the audit trail) and
  changes nothing.

Pure data and functions: no database or UI import.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass

from railval.core.errors import RailvalError

#: role name → one-line meaning (the order is the display order)
ROLES: dict[str, str] = {
    "admin": "manages users, roles and invitations",
    "organiser": "runs review workshops",
    "engineer": "imports data, runs simulate / diagnose / calibrate / validate",
    "panelist": "answers in the own workshops only (expert panel); no sign-off",
    "reviewer": "independent reviewer: reads all evidence, changes nothing, signs off",
    "assessor": "reads everything, changes nothing; verifies the audit trail",
}

#: action name → one-line meaning
ACTIONS: dict[str, str] = {
    "data.read": "see campaigns, configurations, signals, validation results and plots",
    "data.import": "import a campaign or a configuration",
    "data.delete": "delete a campaign or a configuration",
    "data.export": "export a campaign to files",
    "simulate": "run the simulator and store a configuration",
    "diagnose": "run the diagnosis of a configuration",
    "calibrate": "calibrate and store a configuration",
    "validate": "run (and cache) the validation of a configuration",
    "report.download": "write or download a validation report",
    "workshop.run": "create, open, close workshops and invite panelists",
    "workshop.answer": "see the own workshop's plots and give own answers",
    "workshop.results": "see all answers of a workshop",
    "signoff.create": "sign off a configuration (independent reviewer)",
    "signoff.read": "see sign-offs and their status",
    "audit.read": "read the audit trail, verify it, export it, write the audit report",
    "audit.checkpoint": "write the audit head to a checkpoint file",
    "user.manage": "add users, change roles, disable users, invite",
    "data.backup": "back up the whole database with its seal secret",
}

_READ_ALL = ("data.read", "report.download", "signoff.read")

#: role → the actions it grants
PERMISSIONS: dict[str, frozenset[str]] = {
    "admin": frozenset({*_READ_ALL, "user.manage", "audit.read", "audit.checkpoint",
                        "data.backup"}),
    "organiser": frozenset({*_READ_ALL, "workshop.run", "workshop.results"}),
    "engineer": frozenset({*_READ_ALL, "data.import", "data.delete", "data.export", "simulate",
                           "diagnose", "calibrate", "validate"}),
    "panelist": frozenset({"workshop.answer"}),
    "reviewer": frozenset({*_READ_ALL, "workshop.results", "signoff.create"}),
    "assessor": frozenset({*_READ_ALL, "workshop.results", "audit.read", "audit.checkpoint"}),
}

#: web app page → the action needed to open it (pages list themselves here when added)
PAGE_ACTIONS: dict[str, str] = {
    "overview": "data.read", "compare": "data.read", "dashboard": "data.read",
    "metrics": "data.read", "diagnose": "data.read", "report": "data.read",
    "signoff": "signoff.read", "audit": "audit.read", "import": "data.import",
}

#: CLI verb (``railval VERB`` or ``railval VERB SUBVERB``) → the action it needs when the
#: database holds users; None = no data access checked (schema, server, benchmarks)
CLI_ACTIONS: dict[str, str | None] = {
    "init": None, "serve": None, "nginx-static": None, "bench": None,
    "backup": "data.backup", "restore": None,  # restore: into an empty database only
    "list": "data.read", "metrics": "data.read", "report": "report.download",
    "import": "data.import", "synth": "data.import", "export": "data.export",
    "simulate": "simulate", "diagnose": "diagnose", "calibrate": "calibrate",
    "modal": "calibrate", "validate": "validate", "verify": "audit.read",
    "user add": "user.manage", "user list": "user.manage", "user disable": "user.manage",
    "user enable": "user.manage", "user passwd": "user.manage", "user role": "user.manage",
    "user invite": "user.manage",
    "signoff create": "signoff.create", "signoff list": "signoff.read",
    "signoff show": "signoff.read", "signoff summary": "data.read",
    "audit verify": "audit.read", "audit export": "audit.read", "audit report": "audit.read",
    "audit checkpoint": "audit.checkpoint", "audit log": "audit.read",
    "audit key": "audit.read", "audit seal": "user.manage", "audit rotate-key": "user.manage",
    "workshop kinds": None,
    "workshop create": "workshop.run", "workshop invite": "workshop.run",
    "workshop status": "workshop.run", "workshop close": "workshop.run",
    "workshop reopen": "workshop.run", "workshop import-answers": "workshop.run",
    "workshop plots": "workshop.results", "workshop export": "workshop.results",
    "workshop analyse": "workshop.results", "workshop cards": "workshop.results",
}

#: the identity of open single-user mode (no users in the database, loopback only): it may
#: do everything a product user may do, as before users existed
LOCAL_ACTOR = "local"


class PermissionDenied(RailvalError, PermissionError):
    """The acting user's roles do not grant the action."""


@dataclass(frozen=True)
class Principal:
    """Who is acting: a user name and its roles (``open_mode`` = single-user loopback mode)."""

    username: str
    roles: frozenset[str]
    display_name: str = ""
    user_id: int | None = None
    open_mode: bool = False

    @property
    def printed_name(self) -> str:
        return self.display_name or self.username


def open_principal() -> Principal:
    """The principal of open single-user mode: every role except user management."""
    return Principal(LOCAL_ACTOR, frozenset(r for r in ROLES if r != "admin"),
                     display_name="local user (open single-user mode)", open_mode=True)


def check_roles(roles: Iterable[str]) -> list[str]:
    """The roles sorted in registry order; raises on an unknown name (listing the known)."""
    roles = list(roles)
    unknown = [r for r in roles if r not in ROLES]
    if unknown:
        raise RailvalError(f"unknown role(s) {', '.join(map(repr, unknown))}; "
                           f"roles are {', '.join(ROLES)}")
    return [r for r in ROLES if r in set(roles)]


def permissions(roles: Iterable[str]) -> frozenset[str]:
    """Every action granted by any of ``roles``."""
    out: set[str] = set()
    for r in roles:
        out |= PERMISSIONS.get(r, frozenset())
    return frozenset(out)


def allowed(principal: Principal | Iterable[str], action: str) -> bool:
    """True when ``principal`` (or a set of roles) may do ``action``."""
    if action not in ACTIONS:
        raise KeyError(f"unknown action {action!r}; actions are {', '.join(ACTIONS)}")
    roles = principal.roles if isinstance(principal, Principal) else principal
    return action in permissions(roles)


def require(principal: Principal, action: str) -> None:
    """Raise :class:`PermissionDenied` with a readable message unless ``action`` is allowed."""
    if not allowed(principal, action):
        who = principal.username
        held = ", ".join(sorted(principal.roles)) or "no role"
        granting = [r for r in ROLES if action in PERMISSIONS[r]]
        raise PermissionDenied(
            f"{who} ({held}) may not {ACTIONS[action]}; this needs the role "
            f"{' or '.join(granting)}"
        )
