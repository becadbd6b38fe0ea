"""The trust anchor of the signed audit trail: kept where the database's writer cannot write.

Whoever can write the folder of an SQLite database (every SQLite writer must, for the
journal) or the PostgreSQL database itself can also write anything railval keeps *beside*
the database. So what verification trusts is kept in the **trust directory** —
``$RAILVAL_TRUST_DIR``, else the server's configuration directory
``$XDG_CONFIG_HOME/railval/`` (default ``~/.config/railval``), :func:`trust_dir` — one
**anchor** per database, ``trust/<database id>.json`` (:func:`anchor_file`)::

    {"format": "railval-trust-anchor/1", "database_id": "…",
     "locations": ["sqlite:/srv/railval.db"],            # where it was met (configured path)
     "pins": [{"fingerprint": "…", "public_key": "…", "pinned_at_utc": "…",
               "how": "first use (railval audit verify)"}],
     "witnessed": {"seq": N, "row_hash": "…", "signature": "…", "key_fingerprint": "…"}}

and beside it ``trust/<database id>.witness.jsonl`` (:func:`witness_file`, every signed head
the server committed; ``$RAILVAL_WITNESS_FILE`` moves it). ``witnessed`` is the newest head
the server committed: once it is set, a chain that no longer holds row N with that hash, or
a witness file that is missing, shorter or rewound, fails ``railval audit verify``.

**Database identity.** The first audit row railval writes into a database (at ``init``, or
at the first signed row of an older database) is a signed ``database.identity`` row whose
detail names a random ``database_id`` (and the public key that signs, and how many
earlier rows were written unsigned). The anchor is found by that id — the same whatever
spelling of the URL (``localhost`` or ``127.0.0.1``) reaches it — and, when the trail holds
no identity row any more (deleted), by the configured location (:func:`location`: the
resolved file of an SQLite database; loopback host names folded together, port, database
and search path of a PostgreSQL one).

**Pins.** The fingerprints trusted for a database: ``$RAILVAL_TRUST_ANCHOR_FILE`` (a
read-only file, one fingerprint a line — the deploy secret ``trust_anchor``, deploy/README.md)
when set, else the anchor's ``pins``. With no pin yet, the server pins the key it signs with
on first use and says so (trust on first use). A new key is trusted only through a
``key.rotate`` row signed by a key already trusted (:mod:`railval.app.services.audit_checks`);
a ``.retired`` file or a replaced key file trusts nothing. The server refuses to sign with
a key its anchor does not pin (:func:`check_signer`).

Nothing here is written by a verification that is given its trust on the command line
(``--public-key``, ``--trust-fingerprint``, a bundle's key): an assessor's account gets no
file.
"""

from __future__ import annotations

import contextlib
import datetime as dt
import functools
import ipaddress
import json
import os
import secrets
import socket
import threading
from pathlib import Path
from typing import Any

from sqlalchemy.engine import make_url

from railval.core.integrity import (
    IDENTITY_ACTION,
    ROTATE_ACTION,
    KeyRing,
    key_fingerprint,
    known_public_keys,
    public_key_from_hex,
)
from railval.db import integrity
from railval.db.integrity import IntegrityError

__all__ = ["ANCHOR_FORMAT", "IDENTITY_ACTION", "ROTATE_ACTION", "check_signer", "find_anchor",
           "server_ring", "update_anchor", "witness_file"]

ANCHOR_FORMAT = "railval-trust-anchor/1"
_lock = threading.Lock()


def trust_dir() -> Path:
    """``$RAILVAL_TRUST_DIR`` or the server's configuration directory."""
    env = os.environ.get("RAILVAL_TRUST_DIR")
    return Path(env) if env else integrity._config_dir()


def anchor_file(database_id: str) -> Path:
    return trust_dir() / "trust" / f"{database_id}.json"


def witness_file(database_id: str | None) -> Path | None:
    """The witness file of the database ``database_id`` (``None``: id not known yet)."""
    env = os.environ.get("RAILVAL_WITNESS_FILE")
    if env:
        return Path(env)
    if not database_id:
        return None
    return trust_dir() / "trust" / f"{database_id}.witness.jsonl"


def _loopback(host: str) -> bool:
    if host in ("", "localhost", "localhost.localdomain"):
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        pass
    try:
        return all(ipaddress.ip_address(a[4][0]).is_loopback
                   for a in socket.getaddrinfo(host, None))
    except (OSError, ValueError):
        return False


@functools.lru_cache(maxsize=256)
def location(url: str) -> str | None:
    """The configured place of a database, spelled one way (``None``: in-memory SQLite)."""
    parsed = make_url(url)
    if parsed.get_backend_name() == "sqlite":
        db = parsed.database
        if db in (None, "", ":memory:") or str(db).startswith("file:"):
            return None
        return "sqlite:" + str(Path(db).resolve())
    host = (parsed.host or "").lower()
    host = "loopback" if _loopback(host) else host
    query = "&".join(f"{k}={v}" for k, v in sorted(parsed.query.items()))
    return f"{parsed.get_backend_name()}://{host}:{parsed.port or 5432}/{parsed.database}?{query}"


def deploy_pins() -> tuple[Path, list[str]] | None:
    """(file, fingerprints) of ``$RAILVAL_TRUST_ANCHOR_FILE``, or ``None`` when unset."""
    env = os.environ.get("RAILVAL_TRUST_ANCHOR_FILE")
    if not env:
        return None
    path = Path(env)
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as exc:
        raise IntegrityError(f"RAILVAL_TRUST_ANCHOR_FILE {path}: {exc.strerror}") from None
    fps = []
    for line_no, line in enumerate(text.splitlines(), 1):
        fp = line.split("#", 1)[0].strip().lower()
        if not fp:
            continue
        if len(fp) != 64 or any(c not in "0123456789abcdef" for c in fp):
            raise IntegrityError(f"{path} line {line_no}: {fp[:20]!r} is not a SHA-256 key "
                                 "fingerprint (64 hexadecimal characters)")
        fps.append(fp)
    return path, fps


def read_anchor(path: Path) -> dict[str, Any]:
    """An anchor file; a damaged one raises naming the file."""
    try:
        doc = json.loads(path.read_text(encoding="utf-8"))
        if doc.get("format") != ANCHOR_FORMAT:
            raise ValueError(f"format {doc.get('format')!r}, expected {ANCHOR_FORMAT!r}")
        str(doc["database_id"])
        [str(p["fingerprint"]) for p in doc.get("pins", [])]
        if doc.get("witnessed") is not None:
            int(doc["witnessed"]["seq"]), str(doc["witnessed"]["row_hash"])
    except (ValueError, KeyError, TypeError, AttributeError) as exc:
        raise IntegrityError(f"trust anchor {path}: not a railval trust anchor: {exc}") from None
    return doc


def find_anchor(url: str, database_id: str | None) -> tuple[Path, dict[str, Any]] | None:
    """The anchor of the database with ``database_id``, else the one met at ``url``'s
    location; ``None`` when there is none. Reads only."""
    if database_id:
        path = anchor_file(database_id)
        if path.is_file():
            return path, read_anchor(path)
    loc = location(url)
    if loc is None:
        return None
    pointer = _pointer(loc)
    if not pointer.is_file():
        return None
    found_id = pointer.read_text(encoding="utf-8").strip()
    path = anchor_file(found_id)
    if not path.is_file() or (database_id and found_id != database_id):
        return None  # another database lives there now
    return path, read_anchor(path)


def _pointer(loc: str) -> Path:
    """The file naming the database id last met at location ``loc``."""
    import hashlib

    return trust_dir() / "trust" / f"at-{hashlib.sha256(loc.encode()).hexdigest()[:32]}.id"


@contextlib.contextmanager
def _locked():
    """An exclusive lock on the trust directory (every process of the server)."""
    import fcntl

    folder = trust_dir() / "trust"
    folder.mkdir(parents=True, exist_ok=True, mode=0o700)
    fd = os.open(folder / ".lock", os.O_WRONLY | os.O_CREAT, 0o600)
    try:
        with _lock:
            fcntl.flock(fd, fcntl.LOCK_EX)
            yield
    finally:
        os.close(fd)


def _write(path: Path, doc: dict[str, Any]) -> None:
    tmp = path.with_name(path.name + f".{os.getpid()}.tmp")
    fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
    with os.fdopen(fd, "w", encoding="utf-8") as fh:
        fh.write(json.dumps(doc, indent=1, sort_keys=True) + "\n")
    os.replace(tmp, path)


def _now() -> str:
    return dt.datetime.now(dt.UTC).strftime("%Y-%m-%dT%H:%M:%S.%fZ")


def update_anchor(url: str, database_id: str, *, pin: dict[str, str] | None = None,
                  head: dict[str, Any] | None = None) -> dict[str, Any]:
    """Create or extend the anchor of ``database_id``: add the location of ``url``, the
    ``pin`` ({fingerprint, public_key, how}) and raise ``witnessed`` to ``head`` when it is
    newer. Under the directory lock; the file is replaced whole (never half written)."""
    with _locked():
        path = anchor_file(database_id)
        doc = (read_anchor(path) if path.is_file() else
               {"format": ANCHOR_FORMAT, "database_id": database_id, "locations": [],
                "pins": [], "witnessed": None, "created_at_utc": _now()})
        loc = location(url)
        if loc is not None and loc not in doc["locations"]:
            doc["locations"].append(loc)
        if loc is not None and not _pointer(loc).is_file():
            _pointer(loc).write_text(database_id + "\n", encoding="utf-8")
        known = {p["fingerprint"] for p in doc["pins"]}
        if pin is not None and pin["fingerprint"] not in known and (
                not known or pin["how"].startswith("rotation")):
            doc["pins"].append({**pin, "pinned_at_utc": _now()})
        if head is not None and (doc.get("witnessed") is None
                                 or int(head["seq"]) > int(doc["witnessed"]["seq"])):
            doc["witnessed"] = dict(head)
        _write(path, doc)
        return doc


def new_database_id() -> str:
    return secrets.token_hex(16)


def pinned_fingerprints(anchor: dict[str, Any] | None) -> list[str]:
    """The fingerprints the server trusts: the deploy file's, else the anchor's pins."""
    dep = deploy_pins()
    if dep is not None:
        return dep[1]
    return [p["fingerprint"] for p in (anchor or {}).get("pins", [])]


def check_signer(url: str, database_id: str, fingerprint: str) -> None:
    """Refuse to sign with a key the anchor (or the deploy file) does not pin: a key file
    replaced by someone who can write the database's folder signs nothing."""
    dep = deploy_pins()
    if dep is not None:
        if fingerprint not in dep[1]:
            raise IntegrityError(
                f"the signing key {integrity.signing_key_path(url)} (fingerprint "
                f"{fingerprint[:16]}…) is not in the trust anchor {dep[0]}: nothing is signed")
        return
    found = find_anchor(url, database_id)
    if found is None or not found[1].get("pins"):
        return  # first use: the key is pinned when the transaction commits
    path, doc = found
    if fingerprint not in {p["fingerprint"] for p in doc["pins"]}:
        raise IntegrityError(
            f"the signing key {integrity.signing_key_path(url)} (fingerprint "
            f"{fingerprint[:16]}…) is not pinned in {path}: it was replaced; restore the "
            "pinned key (a new key is trusted only through `railval audit rotate-key`)")


def _ring_from(fps: list[str], known: dict[str, Any], source: str) -> KeyRing:
    """A ring of the fingerprints ``fps`` whose public keys are ``known``; a fingerprint
    with no key at hand is listed with no key (it verifies nothing)."""
    return KeyRing({fp: known[fp] for fp in fps if fp in known}, source)


def server_ring(url: str, rows: dict[int, dict[str, Any]]
                ) -> tuple[KeyRing, str, tuple[Path, dict[str, Any]] | None]:
    """The server's trust → (ring, how, anchor found): ``$RAILVAL_TRUST_ANCHOR_FILE``
    ("deploy"), else the anchor's pins ("pin"), else — no pin yet — the current key file
    ("first use"; pinned by the first commit or verification), else nothing ("none").
    ``rows``: audit rows naming keys (identity and rotation rows at least). Reads only."""
    ident = next((r["detail"] for _, r in sorted(rows.items())
                  if r["action"] == IDENTITY_ACTION), None) or {}
    db_id = ident.get("database_id")
    found = find_anchor(url, db_id)
    known = known_public_keys(rows)
    current = integrity.current_public_key(url)
    if current is not None:
        known.setdefault(key_fingerprint(current), current)
    dep = deploy_pins()
    if dep is not None:
        return _ring_from(dep[1], known, f"trust anchor file {dep[0]} "
                          "($RAILVAL_TRUST_ANCHOR_FILE)"), "deploy", found
    if found is not None and found[1].get("pins"):
        for p in found[1]["pins"]:
            try:
                known.setdefault(p["fingerprint"], public_key_from_hex(p["public_key"]))
            except (KeyError, ValueError):
                continue
        return _ring_from([p["fingerprint"] for p in found[1]["pins"]], known,
                          f"pin in {found[0]}"), "pin", found
    if current is None:
        return KeyRing(), "none", found
    return KeyRing({key_fingerprint(current): current}, "first use"), "first use", found
