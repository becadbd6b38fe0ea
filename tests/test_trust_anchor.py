"""The trust anchor: what the writer of the database's folder (SQLite) or of the database
itself (PostgreSQL) cannot reach (docs/security.md, "Writer of the server's folder").

Set-up as in tests/test_audit_attacker.py: users, a campaign, the reviewer's *not
validated*; the server's configuration directory (``$XDG_CONFIG_HOME``) holds the pin, the
database's identity and its witness. Each attack is made with plain file operations,
``sqlite3`` / psycopg and the ``cryptography`` package (the attacker's own key and
signatures, the canonical record format of docs/audit.md re-implemented here), never with
railval code; ``railval audit verify``, ``signoff list`` and the offline bundle must say
FAILED / not VALID, naming the reason:

| attack | expected |
|---|---|
| attacker's public key in ``<db>.signing-key.pem.retired``, sign-off → validated, re-signed | signed by a key that is not trusted |
| the key file replaced by the attacker's key, same edit | not trusted; the server refuses to sign with it |
| witness deleted / truncated; tail cut; whole trail deleted; every signature stripped | FAILED against the anchor's witnessed head |
| PostgreSQL through ``localhost`` instead of ``127.0.0.1`` | the same anchor and witness |
| an older ``pg_dump`` restored over the database | FAILED |
| an assessor's account, public key only | clean report, seals "not checked (no secret)", no file written |
| a brand-new empty database | OK, nothing to verify |
"""

from __future__ import annotations

import hashlib
import json
import os
import shutil
import subprocess
from pathlib import Path

import pytest
from cryptography.hazmat.primitives import serialization
from cryptography.hazmat.primitives.asymmetric.ed25519 import Ed25519PrivateKey
from sqlalchemy.engine import make_url

from railval.app.cli import main
from railval.app.services.signoff import sign
from railval.db import integrity, users
from railval.db.importer import import_campaign
from tests.factories import write_demo_campaign
from tests.test_audit_attacker import as_dict, canonical, drop_triggers, raw

PW = "reviewer password"
GENESIS = "0" * 64
HEAD_FIELDS = ("seq", "at_utc", "actor", "action", "object", "before_sha256", "after_sha256",
               "reason", "detail")
RECORD_FIELDS = ("id", "campaign", "configuration", "username", "printed_name",
                 "signed_at_utc", "meaning", "decision", "restrictions", "statement",
                 "justification", "evidence_sha256", "software_version")


@pytest.fixture(scope="module")
def campaign_dir(tmp_path_factory):
    folder = tmp_path_factory.mktemp("anchor-campaign")
    write_demo_campaign(folder, n_sections=4, fs=50.0, n_configs=1)
    return folder


@pytest.fixture
def setup(database, campaign_dir, tmp_path, monkeypatch):
    """Users, the campaign, the reviewer's 'not validated'; returns the database."""
    monkeypatch.setenv("XDG_CONFIG_HOME", str(tmp_path / "server-config"))
    monkeypatch.delenv("RAILVAL_TRUST_DIR", raising=False)
    monkeypatch.delenv("RAILVAL_TRUST_ANCHOR_FILE", raising=False)
    integrity.forget_keys()
    with database.session(actor="admin", write=True) as s:
        users.create_user(s, "admin", password="admin password", roles=["admin"], actor="admin")
        users.create_user(s, "rev", display_name="Rita Reviewer", password=PW,
                          roles=["reviewer"], actor="admin")
        users.create_user(s, "ass", password="assessor pw", roles=["assessor"], actor="admin")
    database.actor = "eng"
    import_campaign(database, campaign_dir)
    sign(database, "rev", PW, "demo", "baseline", decision="not-validated",
         statement="Zone 4 guiding forces are not reproduced.",
         justification="The guiding forces differ in shape.")
    yield database
    integrity.forget_keys()


def cli(url, *argv) -> int:
    return main(["--db", url, "--as", "ass", *argv])


def run_cli(capsys, *argv) -> tuple[int, str]:
    capsys.readouterr()
    rc = main(list(argv))
    cap = capsys.readouterr()
    return rc, cap.out + cap.err


def verify(url, capsys, *extra) -> tuple[int, str]:
    return run_cli(capsys, "--db", url, "--as", "ass", "audit", "verify", "--quick", *extra)


def signoff_list(url, capsys) -> str:
    rc, out = run_cli(capsys, "--db", url, "--as", "ass", "signoff", "list")
    assert rc == 0, out
    return out


def bundle_verdict(url, capsys, folder: Path) -> tuple[int, str]:
    """Export on the server after the attack, verify offline (no database, the bundle's
    key.json)."""
    assert cli(url, "audit", "export", str(folder)) == 0
    return run_cli(capsys, "audit", "verify", "--bundle", str(folder))


# -- the attacker's tools: plain SQL, files and the cryptography package -------------------
def _message(kind: str, doc) -> bytes:
    return b"railval/" + kind.encode() + b"/1\0" + canonical(doc)


def _rows(run) -> list[dict]:
    cur = run("SELECT * FROM audit_event ORDER BY seq")
    cols = [d[0] for d in cur.description]
    out = [dict(zip(cols, r, strict=True)) for r in cur.fetchall()]
    for r in out:
        r["detail"] = as_dict(r["detail"])
    return out


def rewrite_trail(run, rows: list[dict], key: Ed25519PrivateKey | None) -> None:
    """Store ``rows`` as the trail: the chain recomputed (docs/audit.md), every head signed
    with ``key`` (``None``: no signature), the head table moved."""
    fp = None
    if key is not None:
        raw_pk = key.public_key().public_bytes(serialization.Encoding.Raw,
                                               serialization.PublicFormat.Raw)
        fp = hashlib.sha256(raw_pk).hexdigest()
    prev = GENESIS
    for r in rows:  # unique columns: move every row out of the way first
        run("UPDATE audit_event SET prev_hash = ?, row_hash = ? WHERE seq = ?",
            (f"p{r['seq']:063d}", f"r{r['seq']:063d}", r["seq"]))
    for r in rows:
        h = hashlib.sha256(prev.encode() + canonical({k: r[k] for k in HEAD_FIELDS})).hexdigest()
        sig = None if key is None else key.sign(_message(
            "audit-head", {"format": "railval-audit-head/1", "seq": r["seq"], "row_hash": h})).hex()
        run("UPDATE audit_event SET after_sha256 = ?, prev_hash = ?, row_hash = ?, "
            "signature = ?, key_fingerprint = ? WHERE seq = ?",
            (r["after_sha256"], prev, h, sig, fp if key is not None else None, r["seq"]))
        prev = h
    run("UPDATE audit_head SET seq = ?, row_hash = ? WHERE id = 1",
        (rows[-1]["seq"] if rows else 0, prev))


def forge_validated(database, key: Ed25519PrivateKey | None) -> None:
    """Sign-off 1 turned into 'validated', its record re-signed with ``key`` (or its
    signature stripped), its audit row and the whole chain re-signed to match."""
    with raw(database) as (run, backend):
        drop_triggers(run, backend)
        cur = run("SELECT * FROM signoff WHERE id = 1")
        cols = [d[0] for d in cur.description]
        so = dict(zip(cols, cur.fetchone(), strict=True))
        so["decision"] = "validated"
        so["meaning"] = so["meaning"].replace("not validated", "validated")
        record = {"format": "railval-signoff/1", **{k: (so[k] or "") if k in (
            "justification", "restrictions", "statement") else so[k] for k in RECORD_FIELDS},
            "contrary_to_objective": bool(so["contrary_to_objective"])}
        rec_hash = hashlib.sha256(canonical(record)).hexdigest()
        if key is None:
            sig, fp = None, None
        else:
            sig = key.sign(_message("signoff", record)).hex()
            raw_pk = key.public_key().public_bytes(serialization.Encoding.Raw,
                                                   serialization.PublicFormat.Raw)
            fp = hashlib.sha256(raw_pk).hexdigest()
        run("UPDATE signoff SET decision = ?, meaning = ?, record_sha256 = ?, signature = ?, "
            "key_fingerprint = ? WHERE id = 1", (so["decision"], so["meaning"], rec_hash, sig, fp))
        rows = _rows(run)
        for r in rows:
            if r["action"] == "signoff.create":
                r["after_sha256"] = rec_hash
                r["detail"] = {**r["detail"], "decision": "validated"}
                run("UPDATE audit_event SET detail = ? WHERE seq = ?",
                    (json.dumps(r["detail"]), r["seq"]))
        rewrite_trail(run, rows, key)


def attacker_key() -> Ed25519PrivateKey:
    return Ed25519PrivateKey.generate()


def pub_hex(key: Ed25519PrivateKey) -> str:
    return key.public_key().public_bytes(serialization.Encoding.Raw,
                                         serialization.PublicFormat.Raw).hex()


def sqlite_file(database) -> Path:
    return Path(make_url(database.url).database)


def assert_failed_everywhere(database, capsys, tmp_path, *needles: str) -> str:
    """audit verify FAILED naming ``needles``, signoff list not VALID for sign-off 1, the
    bundle exported after the attack FAILED offline."""
    rc, out = verify(database.url, capsys)
    assert rc == 1 and "FAILED" in out, out
    for n in needles:
        assert n in out, out
    listed = signoff_list(database.url, capsys)
    assert not [ln for ln in listed.splitlines() if ln.split()[:2] == ["1", "VALID"]], listed
    rc, bout = bundle_verdict(database.url, capsys, tmp_path / "bundle-after")
    assert rc == 1 and "FAILED" in bout, bout
    return out


# -- the attacks ---------------------------------------------------------------------------
def test_untouched_database_verifies_and_says_where_the_trust_comes_from(setup, capsys,
                                                                         tmp_path):
    rc, out = verify(setup.url, capsys)
    assert rc == 0, out
    anchor = next((tmp_path / "server-config" / "railval" / "trust").glob("*.json"))
    assert f"(pin in {anchor}" in out and "trusted key " in out
    assert "VALID" in signoff_list(setup.url, capsys)
    rc, bout = bundle_verdict(setup.url, capsys, tmp_path / "bundle")
    assert rc == 0, bout


@pytest.mark.parametrize("db_url", ["sqlite"], indirect=True)  # the key file is beside it
def test_attacker_key_in_the_retired_file_is_not_trusted(setup, capsys, tmp_path):
    database = setup
    evil = attacker_key()
    retired = Path(str(sqlite_file(database)) + ".signing-key.pem.retired")
    retired.write_text(f"# rotated\n{pub_hex(evil)}\n")
    forge_validated(database, evil)
    witness = Path(str(sqlite_file(database)) + ".witness.jsonl")  # the old place: rewritten
    witness.write_text("")
    integrity.forget_keys()
    assert_failed_everywhere(database, capsys, tmp_path, "signed by a key that is not trusted")
    out = signoff_list(database.url, capsys)
    assert "STALE" in out and "demo/baseline  validated" in out


@pytest.mark.parametrize("db_url", ["postgresql"], indirect=True)
def test_postgresql_trail_re_signed_with_the_attackers_key_is_not_trusted(setup, capsys,
                                                                          tmp_path):
    forge_validated(setup, attacker_key())
    integrity.forget_keys()
    assert_failed_everywhere(setup, capsys, tmp_path, "signed by a key that is not trusted")


@pytest.mark.parametrize("db_url", ["sqlite"], indirect=True)
def test_replaced_key_file_is_not_trusted_and_signs_nothing(setup, capsys, tmp_path):
    database = setup
    evil = attacker_key()
    key_file = Path(str(sqlite_file(database)) + ".signing-key.pem")
    key_file.write_bytes(evil.private_bytes(serialization.Encoding.PEM,
                                            serialization.PrivateFormat.PKCS8,
                                            serialization.NoEncryption()))
    forge_validated(database, evil)
    integrity.forget_keys()
    assert_failed_everywhere(database, capsys, tmp_path, "signed by a key that is not trusted")
    # the server refuses to sign with the replaced key
    rc, out = run_cli(capsys, "--db", database.url, "--as", "admin", "audit", "seal")
    assert rc != 0 and "is not pinned in" in out and "it was replaced" in out, out
    # an assessor who explicitly trusts the new key sees its signatures hold, and the
    # server's anchor still names the cut: the rewritten chain differs from the witnessed head
    rc, out = verify(database.url, capsys, "--public-key", pub_hex(evil))
    assert "signed by a key that is not trusted" not in out
    assert rc == 1 and "(the chain was rewritten)" in out, out


def _witness_file(tmp_path) -> Path:
    return next((tmp_path / "server-config" / "railval" / "trust").glob("*.witness.jsonl"))


def test_deleted_or_truncated_witness_fails(setup, capsys, tmp_path):
    w = _witness_file(tmp_path)
    lines = w.read_text().splitlines(keepends=True)
    w.write_text("".join(lines[:-1]))  # truncated: the newest head gone
    rc, out = verify(setup.url, capsys)
    assert rc == 1 and "the witness file was truncated or rewound" in out, out
    rc, bout = bundle_verdict(setup.url, capsys, tmp_path / "bundle-after")
    assert rc == 1 and "the witness file was truncated or rewound" in bout, bout
    w.unlink()
    rc, out = verify(setup.url, capsys)
    assert rc == 1 and "no witness file: it was deleted" in out, out


def test_tail_cut_with_the_witness_beside_it_deleted_fails(setup, capsys, tmp_path):
    database = setup
    with raw(database) as (run, backend):
        drop_triggers(run, backend)
        (top,) = run("SELECT max(seq) FROM audit_event").fetchone()
        run("DELETE FROM signoff")
        run("DELETE FROM audit_event WHERE seq = ?", (top,))
        (prev,) = run("SELECT row_hash FROM audit_event WHERE seq = ?", (top - 1,)).fetchone()
        run("UPDATE audit_head SET seq = ?, row_hash = ? WHERE id = 1", (top - 1, prev))
    if database.dialect == "sqlite":
        Path(str(sqlite_file(database)) + ".witness.jsonl").unlink(missing_ok=True)
    rc, out = verify(database.url, capsys)
    assert rc == 1 and f"the rows after seq {top - 1} were removed" in out, out
    rc, bout = bundle_verdict(database.url, capsys, tmp_path / "bundle-after")
    assert rc == 1 and f"the rows after seq {top - 1} were removed" in bout, bout


def test_whole_trail_deleted_fails(setup, capsys, tmp_path):
    database = setup
    with raw(database) as (run, backend):
        drop_triggers(run, backend)
        run("DELETE FROM signoff")
        run("DELETE FROM audit_event")
        run("UPDATE audit_head SET seq = 0, row_hash = ? WHERE id = 1", (GENESIS,))
    rc, out = verify(database.url, capsys)
    assert rc == 1 and "the chain to hold at least" in out and "0 rows" in out, out
    rc, bout = bundle_verdict(database.url, capsys, tmp_path / "bundle-after")
    assert rc == 1 and "the chain to hold at least" in bout, bout


def test_every_signature_stripped_and_signoff_edited_fails(setup, capsys, tmp_path):
    forge_validated(setup, None)
    if setup.dialect == "sqlite":
        Path(str(sqlite_file(setup)) + ".witness.jsonl").unlink(missing_ok=True)
    out = assert_failed_everywhere(setup, capsys, tmp_path,
                                   "none: the row was written without the signing key")
    assert "(the chain was rewritten)" in out


# -- PostgreSQL: the same anchor whatever the URL spelling ---------------------------------
@pytest.mark.parametrize("db_url", ["postgresql"], indirect=True)
def test_localhost_finds_the_same_anchor_and_witness(setup, capsys, tmp_path):
    other = setup.url.replace("@127.0.0.1:", "@localhost:")
    assert other != setup.url
    rc, out = verify(other, capsys)
    assert rc == 0, out
    w = _witness_file(tmp_path)
    assert f"witness {w}" in out
    with raw(setup) as (run, backend):
        drop_triggers(run, backend)
        run("DELETE FROM signoff")
        run("DELETE FROM audit_event")
        run("UPDATE audit_head SET seq = 0, row_hash = ? WHERE id = 1", (GENESIS,))
    rc, out = verify(other, capsys)  # no identity row left: found by the location
    assert rc == 1 and "the chain to hold at least" in out, out


@pytest.mark.parametrize("db_url", ["postgresql"], indirect=True)
def test_an_older_pg_dump_restored_fails(setup, capsys, tmp_path):
    url = make_url(setup.url)
    schema = url.query["options"].split("=", 1)[1]
    conninfo = url.set(drivername="postgresql", query={}).render_as_string(hide_password=False)
    dump = tmp_path / "old.pgdump"
    subprocess.run([shutil.which("pg_dump"), "--format=custom", f"--schema={schema}",
                    f"--file={dump}", f"--dbname={conninfo}"], check=True)
    assert main(["--db", setup.url, "--as", "admin", "audit", "seal", "--reason",
                 "a later change"]) == 0
    setup.dispose()
    subprocess.run([shutil.which("pg_restore"), "--clean", "--if-exists",
                    "--single-transaction", f"--dbname={conninfo}", str(dump)], check=True)
    rc, out = verify(setup.url, capsys)
    assert rc == 1 and "(or an older copy restored)" in out, out


# -- verification from outside the server --------------------------------------------------
def _files(*folders: Path) -> set[Path]:
    return {p for f in folders if f.exists() for p in f.rglob("*")}


def test_assessor_with_the_public_key_only_gets_a_clean_report_and_writes_nothing(
        setup, capsys, tmp_path, monkeypatch):
    rc, out = run_cli(capsys, "--db", setup.url, "--as", "ass", "audit", "key", "--json")
    key = json.loads(out)
    assessor = tmp_path / "assessor-config"
    assessor.mkdir()
    monkeypatch.setenv("XDG_CONFIG_HOME", str(assessor))
    for name in ("RAILVAL_SECRET_KEY", "RAILVAL_SECRET_KEY_FILE", "RAILVAL_SIGNING_KEY_FILE"):
        monkeypatch.delenv(name, raising=False)
    integrity.forget_keys()
    db_folder = sqlite_file(setup).parent if setup.dialect == "sqlite" else tmp_path
    before = _files(assessor, db_folder)
    rc, out = run_cli(capsys, "--db", setup.url, "--as", "ass", "audit", "verify",
                      "--public-key", key["public_key"])
    assert rc == 0, out
    assert f"trusted key {key['fingerprint']} (--public-key)" in out
    assert "fails its seal" not in out
    if setup.dialect == "postgresql":  # the secret is in the server's configuration only
        assert "seals: not checked (no secret)" in out
    assert _files(assessor, db_folder) == before  # no secret, key, anchor or witness written
    # the fingerprint alone (its public key is in the trail's identity row) does as well
    rc, out = run_cli(capsys, "--db", setup.url, "--as", "ass", "audit", "verify", "--quick",
                      "--trust-fingerprint", key["fingerprint"])
    assert rc == 0 and "(--trust-fingerprint)" in out, out
    assert _files(assessor, db_folder) == before


def test_empty_database_has_nothing_to_verify(database, capsys, tmp_path, monkeypatch):
    monkeypatch.setenv("XDG_CONFIG_HOME", str(tmp_path / "fresh-config"))
    integrity.forget_keys()
    rc, out = verify(database.url, capsys)
    assert rc == 0 and "OK, nothing to verify" in out, out
    assert not (tmp_path / "fresh-config").exists()  # nothing pinned, no key made


def test_first_use_pins_the_servers_key_and_says_so(setup, capsys, tmp_path, monkeypatch):
    monkeypatch.setenv("RAILVAL_TRUST_DIR", str(tmp_path / "new-trust-dir"))
    rc, out = verify(setup.url, capsys)
    assert rc == 0 and "trust on first use" in out and "pinned key" in out, out
    rc, out = verify(setup.url, capsys)
    assert rc == 0 and "(pin in " in out and "trust on first use" not in out, out


def test_deploy_trust_anchor_file_is_the_only_trust(setup, capsys, tmp_path, monkeypatch):
    rc, out = run_cli(capsys, "--db", setup.url, "--as", "ass", "audit", "key", "--json")
    key = json.loads(out)
    anchor = tmp_path / "trust_anchor"
    other = hashlib.sha256(bytes.fromhex(pub_hex(attacker_key()))).hexdigest()
    anchor.write_text(f"# read-only deploy secret\n{other}\n")
    monkeypatch.setenv("RAILVAL_TRUST_ANCHOR_FILE", str(anchor))
    integrity.forget_keys()
    rc, out = verify(setup.url, capsys)
    assert rc == 1 and "signed by a key that is not trusted" in out, out
    rc, out = run_cli(capsys, "--db", setup.url, "--as", "admin", "audit", "seal")
    assert rc != 0 and f"is not in the trust anchor {anchor}" in out, out
    anchor.write_text(f"# read-only deploy secret\n{key['fingerprint']}\n")
    integrity.forget_keys()
    rc, out = verify(setup.url, capsys)
    assert rc == 0 and f"(trust anchor file {anchor} ($RAILVAL_TRUST_ANCHOR_FILE))" in out, out
