"""Authentication of what the database holds: a server secret and HMAC-SHA256 seals.

Content hashes (SHA-256) show that a blob was not damaged; they do not show that nobody with
write access to the database replaced it and recomputed the hash, or copied one source's
rows onto another's. Two seals, both HMAC-SHA256 (RFC 2104, FIPS 198-1) with a secret that is
*not* in the database, close that gap:

* **result cache** (:func:`railval.db.repo.cache_put_many`): the stored value is
  ``mac ‖ payload`` with ``mac = HMAC(secret, "cache\\0" ‖ key ‖ "\\0" ‖ payload)``. A value
  copied from another key, edited, or written without the secret fails the check and is
  treated as absent (computed again) — it never reaches a verdict.
* **signals** (:func:`seal_signal`): each signal row's provenance carries
  ``seal = HMAC(secret, recording id, channel id, content hash, the recording's distance
  hash, fs, t0, n)``; a rescaled signal with a recomputed SHA-256, a blob moved to another
  recording, or a changed distance axis no longer matches its seal.
  :func:`railval.db.repo.verify_evidence` checks the seals (and, with ``blobs=True``, the
  content hashes) of what a report or a sign-off rests on; :func:`railval.db.repo.verify_database`
  checks a whole database (``railval verify``).

The secret, in this order: ``$RAILVAL_SECRET_KEY`` or the file ``$RAILVAL_SECRET_KEY_FILE``
(any text of at least 32 characters; :mod:`railval.db.settings`); for
an SQLite file ``railval.db``, the file ``railval.db.key`` beside it (created 0600 with 32
random bytes on first use); otherwise ``$XDG_CONFIG_HOME/railval/secret.key`` (default
``~/.config/railval``, created likewise). Whoever can read the secret can forge seals: keep
it out of reach of the database's users (docs/database.md, "Integrity").
"""

from __future__ import annotations

import hashlib
import hmac
import os
import secrets
import threading
from pathlib import Path

from sqlalchemy.engine import make_url

from railval.core.errors import RailvalError

MAC_BYTES = 32
MIN_SECRET_CHARS = 32
_lock = threading.Lock()
_secrets: dict[str, bytes] = {}


class IntegrityError(RailvalError):
    """Stored evidence failed its content hash or its seal."""


def _read_or_create(path: Path) -> bytes:
    path.parent.mkdir(parents=True, exist_ok=True)
    try:
        fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
    except FileExistsError:
        text = path.read_text().strip()
        if len(text) < MIN_SECRET_CHARS:
            raise IntegrityError(f"secret key file {path} holds {len(text)} characters, at "
                                 f"least {MIN_SECRET_CHARS} are needed") from None
        return text.encode()
    with os.fdopen(fd, "w") as fh:
        fh.write(secrets.token_hex(32) + "\n")
    return path.read_text().strip().encode()


def secret_path(url: str) -> Path | None:
    """The key file used for database ``url`` (``None`` for an in-memory database)."""
    parsed = make_url(url)
    if parsed.get_backend_name() == "sqlite":
        if parsed.database in (None, "", ":memory:") or str(parsed.database).startswith("file:"):
            return None
        return Path(str(parsed.database) + ".key")
    base = Path(os.environ.get("XDG_CONFIG_HOME") or Path.home() / ".config")
    return base / "railval" / "secret.key"


def secret_for(url: str) -> bytes:
    """The server secret for database ``url`` (see the module docstring)."""
    from railval.db.settings import setting

    env = setting("RAILVAL_SECRET_KEY")
    if env is not None:
        if len(env) < MIN_SECRET_CHARS:
            raise IntegrityError(f"RAILVAL_SECRET_KEY holds {len(env)} characters, at least "
                                 f"{MIN_SECRET_CHARS} are needed")
        return env.encode()
    path = secret_path(url)
    cache_key = str(path) if path is not None else f"memory:{url}"
    with _lock:
        if cache_key not in _secrets:
            _secrets[cache_key] = (secrets.token_bytes(32) if path is None
                                   else _read_or_create(path))
        return _secrets[cache_key]


def session_secret(session) -> bytes:
    """The secret of the database a :class:`sqlalchemy.orm.Session` is bound to."""
    return secret_for(session.get_bind().url.render_as_string(hide_password=False))


def _mac(secret: bytes, *parts: bytes) -> bytes:
    return hmac.new(secret, b"\0".join(parts), hashlib.sha256).digest()


def seal_cache_value(secret: bytes, key: str, payload: bytes) -> bytes:
    """``mac ‖ payload`` as stored in ``result_cache.value``."""
    return _mac(secret, b"cache", key.encode(), payload) + payload


def open_cache_value(secret: bytes, key: str, stored: bytes) -> bytes | None:
    """The payload of a stored cache value, or ``None`` when its seal does not match."""
    if len(stored) < MAC_BYTES:
        return None
    mac, payload = stored[:MAC_BYTES], stored[MAC_BYTES:]
    if not hmac.compare_digest(mac, _mac(secret, b"cache", key.encode(), payload)):
        return None
    return payload


def seal_signal(secret: bytes, recording_id: int, channel_id: int, sha256: str,
                distance_sha256: str, fs: float, t0: float, n: int) -> str:
    """Hex seal of one signal row (see the module docstring)."""
    return _mac(secret, b"signal", str(int(recording_id)).encode(), str(int(channel_id)).encode(),
                sha256.encode(), distance_sha256.encode(), repr(float(fs)).encode(),
                repr(float(t0)).encode(), str(int(n)).encode()).hex()
