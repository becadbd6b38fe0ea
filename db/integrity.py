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
  :func:`railval.db.repo.verify_seals` checks the seals (and, with ``blobs=True``, the
  content hashes) of what a report or a sign-off rests on; :func:`railval.db.seals.verify_storage`
  checks a whole database (``railval verify``).

**Signing key** (:func:`signing_key`): an Ed25519 private key (RFC 8032, ``cryptography``)
that signs every audit row's head and every sign-off's canonical record
(:mod:`railval.core.integrity`), so an assessor verifies with the public key alone. In this
order: the PEM file named by ``$RAILVAL_SIGNING_KEY_FILE``; for an SQLite file ``railval.db``
the file ``railval.db.signing-key.pem`` beside it; otherwise
``$XDG_CONFIG_HOME/railval/signing-key.pem`` (created 0600 on first use). What verification
*trusts* is not this file: the pinned fingerprints, the database's identity and the witness
(every signed head, and the newest one witnessed) live in the trust directory, by default
``$XDG_CONFIG_HOME/railval/trust/`` (:func:`_config_dir`), out of reach of whoever writes the
database's folder (:mod:`railval.db.trust`; docs/database.md, "Trust anchor").

Signal seals, version 2, also bind the **names**: campaign, section, configuration (empty for
the measurement) and channel, so data moved to another section, configuration or campaign
fails even when the row ids stay. Seals of version 1 (hex without prefix, written before)
are still checked with their own formula.

The secret, in this order: ``$RAILVAL_SECRET_KEY`` or the file ``$RAILVAL_SECRET_KEY_FILE``
(any text of at least 32 characters; :mod:`railval.db.settings`); for
an SQLite file ``railval.db``, the file ``railval.db.key`` beside it (created 0600 with 32
random bytes on first use); otherwise ``$XDG_CONFIG_HOME/railval/secret.key`` (default
``~/.config/railval``, created likewise). Whoever can read the secret can forge seals: keep
it out of reach of the database's users (docs/database.md, "Integrity").
"""

from __future__ import annotations

import hmac
import os
import secrets
import threading
from pathlib import Path

from sqlalchemy.engine import make_url

from railval.core import lazy
from railval.core.errors import RailvalError
from railval.db.settings import setting

#: deferred (railval.core.lazy): the signing key's fingerprint needs the cryptography
#: package, which only a signing or a key check loads
key_fingerprint = lazy.function("railval.core.integrity", "key_fingerprint")

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
    # one-shot HMAC-SHA256 (Python docs, hmac.digest: the same bytes as hmac.new(...).digest(),
    # computed by OpenSSL in one call)
    return hmac.digest(secret, b"\0".join(parts), "sha256")


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


SEAL_V2 = "v2:"


def seal_signal(secret: bytes, recording_id: int, channel_id: int, sha256: str,
                distance_sha256: str, fs: float, t0: float, n: int, *,
                names: tuple[str, str, str, str] | None = None) -> str:
    """Seal of one signal row (see the module docstring).

    ``names``: (campaign, section id, configuration name or "" for the measurement,
    channel name) — given, the seal is version 2 (``v2:`` + hex) and binds them too;
    ``None`` computes the version 1 seal of rows written before.
    """
    parts = [str(int(recording_id)).encode(), str(int(channel_id)).encode(),
             sha256.encode(), distance_sha256.encode(), repr(float(fs)).encode(),
             repr(float(t0)).encode(), str(int(n)).encode()]
    if names is None:
        return _mac(secret, b"signal", *parts).hex()
    name_bytes = [str(x).encode("utf-8").replace(b"\\", b"\\\\").replace(b"\0", b"\\0")
                  for x in names]
    return SEAL_V2 + _mac(secret, b"signal2", *parts, *name_bytes).hex()


def _name_bytes(x) -> bytes:
    return str(x).encode("utf-8").replace(b"\\", b"\\\\").replace(b"\0", b"\\0")


#: channel name → :func:`_name_bytes` (the few channel names of a database, encoded once)
_CHANNEL_BYTES: dict = {}

try:  # OpenSSL's keyed HMAC object (the C object ``hmac.new`` wraps): copy, update, hexdigest
    from _hashlib import hmac_new as _hmac_new
except ImportError:  # pragma: no cover - Python without OpenSSL's HMAC
    def _hmac_new(key: bytes, msg: bytes, digestmod: str):
        return hmac.new(key, msg, digestmod)


def check_signal_seals(secret: bytes, recording: tuple, names: tuple[str, str, str],
                       rows) -> list[bool]:
    """:func:`check_signal_seal` of every signal row of one recording: ``recording`` =
    (recording id, distance hash, fs, t0, n), ``names`` = (campaign, section id,
    configuration name or ""), ``rows`` = (channel, channel id, content hash, seal) with a
    seal (not ``None``). The same message and HMAC per row as :func:`seal_signal` (the
    recording's parts encoded once, not once per signal); the secret is keyed into the
    HMAC once per recording and copied for each row (RFC 2104: the keyed inner and outer
    states do not depend on the message — the same digest as ``hmac.digest``, without the
    key set-up per row). Seals of version 1 go through :func:`check_signal_seal`."""
    rid, dsha, fs, t0, n = recording
    head = b"signal2\0" + str(int(rid)).encode() + b"\0"
    tail = b"\0".join([dsha.encode(), repr(float(fs)).encode(), repr(float(t0)).encode(),
                       str(int(n)).encode(), *map(_name_bytes, names), b""])
    out = []
    keyed = None
    for chan, cid, sha, seal in rows:
        seal = str(seal)
        if seal.startswith(SEAL_V2):
            chan_bytes = _CHANNEL_BYTES.get(chan)
            if chan_bytes is None:
                if len(_CHANNEL_BYTES) > 4096:
                    _CHANNEL_BYTES.clear()
                chan_bytes = _CHANNEL_BYTES[chan] = _name_bytes(chan)
            if keyed is None:
                keyed = _hmac_new(secret, b"", "sha256")
            mac = keyed.copy()
            mac.update(b"%b%d\0%b\0%b%b" % (head, int(cid), sha.encode(), tail, chan_bytes))
            out.append(hmac.compare_digest(seal, SEAL_V2 + mac.hexdigest()))
        else:
            out.append(check_signal_seal(secret, seal, rid, cid, sha, dsha, fs, t0, n,
                                         (*names, chan)))
    return out


def check_signal_seal(secret: bytes, seal: str, recording_id: int, channel_id: int,
                      sha256: str, distance_sha256: str, fs: float, t0: float, n: int,
                      names: tuple[str, str, str, str]) -> bool:
    """Does ``seal`` (version 1 or 2) match the row?"""
    seal = str(seal)
    v2 = seal.startswith(SEAL_V2)
    expected = seal_signal(secret, recording_id, channel_id, sha256, distance_sha256, fs, t0,
                           n, names=names if v2 else None)
    return hmac.compare_digest(seal, expected)


# -- signing key and witness -------------------------------------------------------------
_keys: dict[str, object] = {}


def _config_dir() -> Path:
    return Path(os.environ.get("XDG_CONFIG_HOME") or Path.home() / ".config") / "railval"


def signing_key_path(url: str) -> Path | None:
    """The PEM file of the signing key for database ``url`` (``None``: in-memory SQLite)."""
    env = os.environ.get("RAILVAL_SIGNING_KEY_FILE")
    if env:
        return Path(env)
    parsed = make_url(url)
    if parsed.get_backend_name() == "sqlite":
        if parsed.database in (None, "", ":memory:") or str(parsed.database).startswith("file:"):
            return None
        return Path(str(parsed.database) + ".signing-key.pem")
    return _config_dir() / "signing-key.pem"


def _load_or_create_key(path: Path):
    from cryptography.hazmat.primitives import serialization
    from cryptography.hazmat.primitives.asymmetric.ed25519 import (
        Ed25519PrivateKey,
    )

    path.parent.mkdir(parents=True, exist_ok=True)
    try:
        fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
    except FileExistsError:
        data = path.read_bytes()
        try:
            key = serialization.load_pem_private_key(data, password=None)
        except (ValueError, TypeError) as exc:
            raise IntegrityError(f"signing key file {path}: not an unencrypted PEM private "
                                 f"key: {exc}") from None
        if not isinstance(key, Ed25519PrivateKey):
            raise IntegrityError(f"signing key file {path}: holds a {type(key).__name__}, "
                                 "railval signs with Ed25519") from None
        return key
    key = Ed25519PrivateKey.generate()
    pem = key.private_bytes(serialization.Encoding.PEM, serialization.PrivateFormat.PKCS8,
                            serialization.NoEncryption())
    with os.fdopen(fd, "wb") as fh:
        fh.write(pem)
    return key


def signing_key(url: str):
    """The Ed25519 private key that signs for database ``url`` (created on first use)."""
    path = signing_key_path(url)
    cache_key = str(path) if path is not None else f"memory:{url}"
    with _lock:
        if cache_key not in _keys:
            if path is None:
                from cryptography.hazmat.primitives.asymmetric.ed25519 import (
                    Ed25519PrivateKey,
                )

                _keys[cache_key] = Ed25519PrivateKey.generate()
            else:
                _keys[cache_key] = _load_or_create_key(path)
        return _keys[cache_key]


_signers: dict[tuple, tuple] = {}
#: functions called by :func:`forget_keys` (other modules' caches of keys and identities)
FORGET_HOOKS: list = []


def signer_for(url: str) -> tuple:
    """(private key, its fingerprint) for database ``url``, cached per URL and key
    settings (the per-row cost of signing is then the signature alone)."""
    ck = (url, os.environ.get("RAILVAL_SIGNING_KEY_FILE"), os.environ.get("XDG_CONFIG_HOME"))
    got = _signers.get(ck)
    if got is None:
        key = signing_key(url)
        got = (key, key_fingerprint(key.public_key()))
        with _lock:
            _signers[ck] = got
    return got


def forget_keys() -> None:
    """Drop cached keys (after a rotation, or in tests that change the key files)."""
    with _lock:
        _keys.clear()
        _secrets.clear()
        _signers.clear()
    for hook in FORGET_HOOKS:
        hook()


def session_url(session) -> str:
    """The database URL of ``session``, also when it is bound to a connection (a migration
    writes its audit rows through the migration's connection)."""
    bind = session.get_bind()
    engine = getattr(bind, "engine", bind)
    return engine.url.render_as_string(hide_password=False)


def current_public_key(url: str):
    """The public key of the signing key file of ``url``, or ``None`` when there is no key
    file (a key is never created here: verifying a copied database must not make one)."""
    path = signing_key_path(url)
    if path is None or path.is_file() or str(path) in _keys:
        return signing_key(url).public_key()
    return None


def secret_exists(url: str) -> bool:
    """Is the seal secret of ``url`` at hand without creating it?"""
    if setting("RAILVAL_SECRET_KEY") is not None:
        return True
    path = secret_path(url)
    return path is None or path.is_file()


def append_witness(path: Path, line: dict) -> None:
    """Append one signed head to the witness file (one JSON line, one ``write``). Runs after
    the commit: a failure is logged (the change is stored; the witness misses one head)."""
    import json
    import logging

    data = (json.dumps(line, sort_keys=True, separators=(",", ":")) + "\n").encode()
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_APPEND, 0o600)
        try:
            os.write(fd, data)
        finally:
            os.close(fd)
    except OSError as exc:
        logging.getLogger("railval.db").error("witness file %s: cannot append signed head "
                                              "seq %s: %s", path, line.get("seq"), exc)


def read_witness(path: Path) -> list[dict]:
    """The signed heads of a witness file, in file order; a damaged line raises."""
    import json

    out = []
    with path.open(encoding="utf-8") as fh:
        for line_no, line in enumerate(fh, 1):
            if not line.strip():
                continue
            try:
                doc = json.loads(line)
                int(doc["seq"]), str(doc["row_hash"])
            except (ValueError, KeyError, TypeError) as exc:
                raise IntegrityError(f"witness file {path} line {line_no}: not a signed head: "
                                     f"{exc}") from None
            out.append(doc)
    return out
