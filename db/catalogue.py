"""The campaign catalogue (``railval list``) read with the database driver alone.

``railval list`` must print at once (issue 26: ≤ 0.3 s). Importing SQLAlchemy, its ORM, the
models, Alembic and the audit trail costs several tenths of a second before the first query,
so this module reads the few tables the catalogue needs through the DB-API driver directly
(:mod:`sqlite3` from the standard library, psycopg 3 for PostgreSQL) and forms the same
document as :func:`railval.db.repo.campaign_summary`.

It is a fast path, not a second implementation of the rules: :func:`read_catalogue` answers
only in the plain case — the schema is at the newest revision and either the database has no
users or the acting user exists, is enabled and holds the permission to read data
(:data:`railval.core.roles.CLI_ACTIONS`). In every other case (missing file, older schema,
unknown driver, missing or refused user, any driver error) it returns None and the caller
runs the ordinary path (SQLAlchemy session, migrations, :func:`railval.app.cli.authorize`),
which gives the usual messages and behaviour.

The newest revision is read from the migration scripts (``revision``/``down_revision`` of
``db/migrations/versions/*.py``: the head is the revision no other script names as its
parent), as Alembic's ``ScriptDirectory.get_current_head`` does for a linear history.
"""

from __future__ import annotations

import json
import re
from pathlib import Path
from typing import Any
from urllib.parse import urlsplit, urlunsplit

from railval.core.roles import CLI_ACTIONS, Principal, allowed
from railval.core.zones import zone_for_radius
from railval.db.settings import setting

_VERSIONS = Path(__file__).with_name("migrations") / "versions"
_REV = re.compile(r"^(down_revision|revision)\b[^=]*=\s*(?:['\"]([^'\"]*)['\"]|None)", re.MULTILINE)


def head_revision(versions: Path = _VERSIONS) -> str | None:
    """The newest migration revision of the scripts in ``versions`` (this code's by default;
    None when the scripts do not form one linear head)."""
    revisions: set[str] = set()
    parents: set[str] = set()
    for path in versions.glob("*.py"):
        found = {m.group(1): m.group(2) for m in _REV.finditer(path.read_text("utf-8"))}
        if found.get("revision"):
            revisions.add(found["revision"])
            if found.get("down_revision"):
                parents.add(found["down_revision"])
    heads = revisions - parents
    return heads.pop() if len(heads) == 1 else None


def safe_url(url: str) -> str:
    """``url`` with its password shown as ``***`` (as :attr:`railval.db.engine.Database.safe_url`)."""
    parts = urlsplit(url)
    if parts.password is None:
        return url
    user = parts.username or ""
    host = parts.hostname or ""
    if ":" in host:
        host = f"[{host}]"
    netloc = f"{user}:***@{host}" + (f":{parts.port}" if parts.port else "")
    return urlunsplit((parts.scheme, netloc, parts.path, parts.query, parts.fragment))


class _Driver:
    """One DB-API connection; ``q(sql, *params)`` with ``?`` placeholders on both drivers."""

    def __init__(self, url: str):
        if url.startswith("sqlite:///"):
            import sqlite3
            from urllib.parse import quote, unquote

            path = unquote(url[len("sqlite:///"):])  # as SQLAlchemy's make_url reads it
            if not path or path == ":memory:" or path.startswith("file:") or "?" in path:
                raise LookupError("not a plain SQLite file")
            if not Path(path).is_file():
                raise LookupError("no such file")
            self.conn = sqlite3.connect(f"file:{quote(str(Path(path).resolve()))}?mode=ro",
                                        uri=True, timeout=30.0)
            self.mark = "?"
        elif url.startswith("postgresql+psycopg://"):
            import psycopg

            self.conn = psycopg.connect("postgresql://" + url.split("://", 1)[1],
                                        autocommit=True)
            self.mark = "%s"
        else:
            raise LookupError("unknown driver")

    def q(self, sql: str, *params) -> list[tuple]:
        cur = self.conn.cursor()
        try:
            cur.execute(sql.replace("?", self.mark), params)
            return list(cur.fetchall())
        finally:
            cur.close()

    def close(self) -> None:
        self.conn.close()


def _json(value) -> Any:
    return json.loads(value) if isinstance(value, (str, bytes)) else value


def _allowed(db: _Driver, who: str | None) -> bool:
    """The database has no users, or ``who`` is an enabled user permitted to run ``list``."""
    if db.q("SELECT COUNT(*) FROM app_user")[0][0] == 0:
        return True
    if not who:
        return False
    rows = db.q("SELECT id, username, display_name, disabled FROM app_user WHERE username = ?",
                who)
    if not rows or rows[0][3]:
        return False
    uid, username, display, _ = rows[0]
    roles = frozenset(r for (r,) in db.q("SELECT role FROM user_role WHERE user_id = ?", uid))
    return allowed(Principal(username, roles, display_name=display, user_id=uid),
                   CLI_ACTIONS["list"])


def _summary(db: _Driver, cid: int, name: str, description: str, zone1: float) -> dict:
    """What :func:`railval.db.repo.campaign_summary` returns, from plain queries."""
    secs = db.q("SELECT section_id, radius_m, speed_kmh, zone_override FROM section "
                "WHERE campaign_id = ? ORDER BY id", cid)
    infos = [{"id": s, "zone": zone_for_radius(r, zone1, z), "radius_m": r, "speed_kmh": v}
             for s, r, v, z in secs]
    zones: dict[int, int] = {}
    for i in infos:
        zones[i["zone"]] = zones.get(i["zone"], 0) + 1
    veh = db.q("SELECT name, kind, secondary_suspension, \"Q0_kN\", template, parameters "
               "FROM vehicle WHERE campaign_id = ?", cid)
    if not veh:
        raise LookupError("no vehicle record")  # the ordinary path reports it
    vname, kind, secondary, q0, template, params = veh[0]
    confs = db.q("SELECT id, name, parent_id, effects FROM configuration "
                 "WHERE campaign_id = ? ORDER BY id", cid)
    parent = {i: n for i, n, _, _ in confs}
    n_signals = db.q("SELECT COUNT(signal.id) FROM signal JOIN recording ON "
                     "recording.id = signal.recording_id JOIN section ON "
                     "section.id = recording.section_id WHERE section.campaign_id = ?", cid)[0][0]
    return {
        "name": name, "id": cid, "description": description,
        "vehicle": {"name": vname, "kind": kind, "secondary_suspension": bool(secondary),
                    "Q0_kN": float(q0), "template": template,
                    "parameters": dict(_json(params) or {})},
        "n_sections": len(infos),
        "zones": {str(z): n for z, n in sorted(zones.items())},
        "sections": infos,
        "channels": [n for (n,) in db.q("SELECT name FROM channel WHERE campaign_id = ? "
                                         "ORDER BY id", cid)],
        "configurations": [{"name": n, "parent": parent.get(p), "effects": sorted(_json(e) or {})}
                           for _, n, p, e in confs],
        "n_signals": int(n_signals or 0),
    }


def read_catalogue(url: str, who: str | None) -> list[dict] | None:
    """The summaries of all campaigns (ordered by name) of the database at ``url`` (already
    resolved, :func:`resolve_url`), or None when the ordinary path must answer (see the
    module docstring)."""
    try:
        db = _Driver(url)
    except Exception:  # noqa: BLE001 - any failure: the ordinary path reports it
        return None
    try:
        head = head_revision()
        current = db.q("SELECT version_num FROM alembic_version")
        if head is None or [r for (r,) in current] != [head] or not _allowed(db, who):
            return None
        return [_summary(db, cid, name, desc or "", zone1)
                for cid, name, desc, zone1 in db.q(
                    "SELECT id, name, description, zone1_min_radius_m FROM campaign "
                    "ORDER BY name")]
    except Exception:  # noqa: BLE001 - any failure: the ordinary path reports it
        return None
    finally:
        db.close()


def resolve_url(url: str | None) -> str:
    """The database URL as :func:`railval.db.engine.resolve_url` forms it, without
    SQLAlchemy: argument, else ``$RAILVAL_DB``, else ``sqlite:///railval.db``; PostgreSQL
    URLs get the psycopg driver and ``$RAILVAL_DB_PASSWORD`` when they hold no password."""
    from urllib.parse import quote

    url = url or setting("RAILVAL_DB") or "sqlite:///railval.db"
    if url.startswith(("postgresql://", "postgres://")):
        url = "postgresql+psycopg://" + url.split("://", 1)[1]
    if url.startswith("postgresql") and urlsplit(url).password is None:
        password = setting("RAILVAL_DB_PASSWORD")
        if password:
            parts = urlsplit(url)
            user, _, host = parts.netloc.rpartition("@")
            netloc = f"{user}:{quote(password, safe='')}@{host}"
            url = urlunsplit((parts.scheme, netloc, parts.path, parts.query, parts.fragment))
    return url


