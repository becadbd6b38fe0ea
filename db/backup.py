"""Backup and restore of a whole railval database with the seal secret (docs/database.md,
"Backup and restore").

A backup is a folder:

* ``database.sqlite`` — SQLite: a consistent copy made while the server runs, with SQLite's
  online backup API (``sqlite3.Connection.backup``; https://www.sqlite.org/backup.html);
* ``database.pgdump`` — PostgreSQL: ``pg_dump --format=custom`` of the database's schema
  (a consistent snapshot taken in one transaction while the server runs);
* ``secret.key`` (0600) — the secret that seals signals and cached results
  (:mod:`railval.db.integrity`). Without it a restored database holds signals whose seals no
  longer verify: the backup folder must be kept as securely as the key itself;
* ``signing-key.pem`` (0600) — the Ed25519 key that signs audit rows and sign-offs, with
  ``trust-anchor.json`` (the database's pinned keys and newest witnessed head) and
  ``witness.jsonl`` (the signed heads kept outside the database, :mod:`railval.db.trust`)
  when they exist; without them a restored trail would be verified against a new key and
  an empty witness (docs/audit.md);
* ``backup.json`` — format, backend, schema revision, audit head, signal count and the
  SHA-256 of each file (checked before a restore).

:func:`restore` writes a backup into an **empty** database of the same backend (a new SQLite
file; a PostgreSQL database or schema without railval tables), installs the secret
(beside an SQLite file as ``FILE.key``, else where :func:`railval.db.integrity.secret_path`
looks, unless ``$RAILVAL_SECRET_KEY`` already holds the same secret) and migrates to the
newest schema revision; the signing key is installed where
:func:`railval.db.integrity.signing_key_path` looks for the restored database (refused when
another key is already there), the trust anchor and witness in the trust directory under the
database's identity (kept when the server already holds them: the same database, witnessed
at least as far; refused when they disagree). Both
write an audit row (``database.backup`` before the copy, so the
backup holds it; ``database.restore`` after).
"""

from __future__ import annotations

import datetime as dt
import hashlib
import json
import os
import shutil
import sqlite3
import subprocess
from pathlib import Path
from typing import Any

from sqlalchemy import func, inspect, select, text
from sqlalchemy.engine import make_url

from railval.core.errors import RailvalError
from railval.db import audit, integrity, trust
from railval.db.models import Signal
from railval.db.settings import setting

FORMAT = "railval-backup/1"
MANIFEST = "backup.json"
SECRET = "secret.key"
SIGNING_KEY = "signing-key.pem"
ANCHOR = "trust-anchor.json"
WITNESS = "witness.jsonl"
FILES = {"sqlite": "database.sqlite", "postgresql": "database.pgdump"}


class BackupError(RailvalError):
    """A backup could not be written, or a backup folder cannot be restored."""


def _sha256(path: Path) -> str:
    h = hashlib.sha256()
    with path.open("rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def _libpq(database) -> tuple[str, dict[str, str]]:
    """(libpq connection URI without password, environment with PGPASSWORD)."""
    url = make_url(database.url)
    env = dict(os.environ)
    if url.password:
        env["PGPASSWORD"] = str(url.password)
    uri = url.set(drivername="postgresql", password=None).render_as_string(hide_password=False)
    return uri, env


def _pg_tool(name: str) -> str:
    path = shutil.which(name)
    if path is None:
        raise BackupError(f"{name} not found: install the PostgreSQL client programs "
                          "(Debian: apt-get install postgresql-client) of the server's major "
                          "version or newer")
    return path


def _run(cmd: list[str], env: dict[str, str]) -> None:
    done = subprocess.run(cmd, env=env, capture_output=True, text=True, check=False)
    if done.returncode != 0:
        raise BackupError(f"{Path(cmd[0]).name} failed (exit {done.returncode}): "
                          f"{done.stderr.strip()[-2000:]}")


def _facts(database) -> dict[str, Any]:
    with database.session() as s:
        seq, row_hash = audit.head(s)
        signals = s.scalar(select(func.count()).select_from(Signal))
    return {"audit_head": {"seq": seq, "row_hash": row_hash}, "signals": int(signals or 0)}


def backup(database, folder: str | Path, *, actor: Any = "system") -> dict[str, Any]:
    """Write a backup of ``database`` (a :class:`railval.db.engine.Database`) into the new or
    empty ``folder``; returns the manifest."""
    out = Path(folder)
    if out.exists() and any(out.iterdir()):
        raise BackupError(f"backup folder {out} is not empty")
    if database.current_revision() is None:
        raise BackupError(f"{database.safe_url} holds no railval database")
    out.mkdir(parents=True, exist_ok=True)
    os.chmod(out, 0o700)
    backend = database.engine.dialect.name
    secret = integrity.secret_for(database.url)
    with database.session(write=True) as s:
        audit.record(s, actor, "database.backup", f"database:{backend}",
                     detail={"folder": out.name})
    facts = _facts(database)
    target = out / FILES[backend]
    if backend == "sqlite":
        src = sqlite3.connect(make_url(database.url).database)
        dst = sqlite3.connect(target)
        try:
            with dst:
                src.backup(dst)  # online backup API: pages copied while writers continue
        finally:
            dst.close()
            src.close()
    else:
        uri, env = _libpq(database)
        with database.engine.connect() as conn:
            schema = conn.execute(text("SELECT current_schema()")).scalar_one()
        _run([_pg_tool("pg_dump"), "--format=custom", "--no-owner", "--no-privileges",
              f"--schema={schema}", f"--file={target}", f"--dbname={uri}"], env)
        facts["schema"] = schema
    key = out / SECRET
    _write_private(key, secret + b"\n")
    with database.session() as s:
        ident = audit.identity(s)
    files = [target, key, *_copy_signing_files(database.url, out,
                                               ident["database_id"] if ident else None)]
    manifest = {"format": FORMAT, "backend": backend, "revision": database.current_revision(),
                "created_utc": dt.datetime.now(dt.UTC).isoformat(timespec="seconds"),
                "source": database.safe_url, **facts,
                "files": {p.name: _sha256(p) for p in files}}
    (out / MANIFEST).write_text(json.dumps(manifest, indent=2) + "\n", encoding="utf-8")
    return manifest


def _write_private(path: Path, data: bytes) -> None:
    """Create ``path`` readable by its owner only (0600) and write ``data``; an existing file
    is never overwritten."""
    fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
    with os.fdopen(fd, "wb") as fh:
        fh.write(data)


def _copy_signing_files(url: str, out: Path, database_id: str | None) -> list[Path]:
    """Copy the signing key (made now if the database has none yet), the trust anchor and
    the witness of ``url`` into the backup folder ``out``; returns the copies."""
    integrity.signing_key(url)
    found = trust.find_anchor(url, database_id)
    sources = {SIGNING_KEY: integrity.signing_key_path(url),
               ANCHOR: found[0] if found else None,
               WITNESS: trust.witness_file(database_id)}
    copies = []
    for name, src in sources.items():
        if src is None or not src.is_file():
            continue
        dst = out / name
        _write_private(dst, src.read_bytes())
        copies.append(dst)
    return copies


def _install_signing_files(url: str, root: Path) -> None:
    """Install the backup's signing key, trust anchor and witness for the restored ``url``:
    a key file with other content is refused (it belongs to another database); an anchor or
    witness the server already holds for this database is kept when it reaches at least as
    far as the backup's (the backup is older), refused otherwise."""
    key_path = integrity.signing_key_path(url)
    db_id = None
    if (root / ANCHOR).is_file():
        db_id = trust.read_anchor(root / ANCHOR)["database_id"]
    targets = {SIGNING_KEY: key_path,
               ANCHOR: trust.anchor_file(db_id) if db_id else None,
               WITNESS: trust.witness_file(db_id) if db_id else None}
    for name, dst in targets.items():
        src = root / name
        if not src.is_file() or dst is None:
            if src.is_file() and name == SIGNING_KEY:
                raise BackupError("an in-memory database cannot be restored into")
            continue
        data = src.read_bytes()
        if dst.exists():
            held = dst.read_bytes()
            if held == data or (name == WITNESS and held.startswith(data)):
                continue
            if name == ANCHOR and _anchor_reaches(trust.read_anchor(dst), trust.read_anchor(src)):
                continue
            raise BackupError(f"{dst} exists with other content; move it away or point "
                              f"RAILVAL_SIGNING_KEY_FILE / RAILVAL_TRUST_DIR at another place")
        dst.parent.mkdir(parents=True, exist_ok=True)
        _write_private(dst, data)
    integrity.forget_keys()


def _anchor_reaches(held: dict[str, Any], backup_anchor: dict[str, Any]) -> bool:
    """Does the anchor the server holds pin the backup's keys and witness at least as far?"""
    pins = {p["fingerprint"] for p in held.get("pins", [])}
    want = {p["fingerprint"] for p in backup_anchor.get("pins", [])}
    hw, bw = held.get("witnessed") or {}, backup_anchor.get("witnessed") or {}
    return want <= pins and int(hw.get("seq", 0)) >= int(bw.get("seq", 0))


def read_manifest(folder: str | Path) -> dict[str, Any]:
    """The manifest of a backup folder, every file checked against its SHA-256."""
    root = Path(folder)
    try:
        manifest = json.loads((root / MANIFEST).read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise BackupError(f"{root}: no {MANIFEST} (not a railval backup folder)") from None
    except ValueError as exc:
        raise BackupError(f"{root / MANIFEST}: not JSON: {exc}") from None
    if manifest.get("format") != FORMAT:
        raise BackupError(f"{root / MANIFEST}: format {manifest.get('format')!r}, expected {FORMAT!r}")
    for name, sha in manifest.get("files", {}).items():
        path = root / name
        if not path.exists():
            raise BackupError(f"{path}: missing")
        if _sha256(path) != sha:
            raise BackupError(f"{path}: SHA-256 differs from {MANIFEST} (damaged or altered)")
    return manifest


def _install_secret(database, secret: bytes) -> str:
    """Make ``secret`` the seal secret of ``database``; returns where it lives."""
    current = setting("RAILVAL_SECRET_KEY")
    if current is not None:
        if current.encode() != secret:
            raise BackupError("RAILVAL_SECRET_KEY (or its _FILE) differs from the backup's "
                              f"{SECRET}: the restored signals would not verify; point "
                              f"RAILVAL_SECRET_KEY_FILE at the backup's {SECRET}")
        return "$RAILVAL_SECRET_KEY"
    path = integrity.secret_path(database.url)
    if path is None:
        raise BackupError("an in-memory database cannot be restored into")
    if path.exists():
        if path.read_text().strip().encode() != secret:
            raise BackupError(f"{path} holds another secret; move it away (other databases "
                              "sealed with it need it) or set RAILVAL_SECRET_KEY_FILE to the "
                              f"backup's {SECRET}")
        return str(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    _write_private(path, secret + b"\n")
    return str(path)


def restore(database, folder: str | Path, *, actor: Any = "system") -> dict[str, Any]:
    """Restore the backup in ``folder`` into the empty ``database``; returns a summary."""
    root = Path(folder)
    manifest = read_manifest(root)
    backend = database.engine.dialect.name
    if manifest["backend"] != backend:
        raise BackupError(f"the backup holds a {manifest['backend']} database; "
                          f"{database.safe_url} is {backend} (restore into the same backend)")
    tables = inspect(database.engine).get_table_names()
    if tables:
        raise BackupError(f"{database.safe_url} is not empty ({len(tables)} tables, e.g. "
                          f"{min(tables)!r}); restore into a new database")
    secret = (root / SECRET).read_bytes().strip()
    where = _install_secret(database, secret)
    _install_signing_files(database.url, root)
    src = root / FILES[backend]
    if backend == "sqlite":
        database.engine.dispose()
        s_conn = sqlite3.connect(src)
        d_conn = sqlite3.connect(make_url(database.url).database)
        try:
            with d_conn:
                s_conn.backup(d_conn)
        finally:
            d_conn.close()
            s_conn.close()
    else:
        uri, env = _libpq(database)
        with database.engine.connect() as conn:
            schema = conn.execute(text("SELECT current_schema()")).scalar_one_or_none()
        if schema is not None and schema != manifest.get("schema"):
            raise BackupError(f"the backup holds schema {manifest.get('schema')!r}; the target's "
                              f"search path selects {schema!r}: restore into a database (or "
                              "search path) whose first schema has the backup's name")
        database.engine.dispose()
        _run([_pg_tool("pg_restore"), "--no-owner", "--no-privileges", "--clean", "--if-exists",
              "--exit-on-error", "--single-transaction", f"--dbname={uri}", str(src)], env)
    database.engine.dispose()
    database.init()  # a backup of an older release migrates to this one
    facts = _facts(database)
    if facts["audit_head"] != manifest["audit_head"] or facts["signals"] != manifest["signals"]:
        raise BackupError(f"restored database differs from {MANIFEST}: audit head "
                          f"{facts['audit_head']} vs {manifest['audit_head']}, signals "
                          f"{facts['signals']} vs {manifest['signals']}")
    with database.session(write=True) as s:
        audit.record(s, actor, "database.restore", f"database:{backend}",
                     detail={"backup_created_utc": manifest["created_utc"],
                             "audit_head_seq": manifest["audit_head"]["seq"]})
    return {"restored": str(root), "database": database.safe_url, "secret": where,
            "revision": database.current_revision(), **facts}
