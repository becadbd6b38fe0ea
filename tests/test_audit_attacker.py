"""A database writer without the signing key, with plain SQL only (docs/security.md).

Set-up as an assessor would meet it: admin, engineer and reviewer; the engineer imports a
campaign; the reviewer signs *not validated*; an assessor writes a checkpoint. Then each
change of the threat table is made with the ``sqlite3`` module or psycopg — no railval code
touches the database — and the named check must fail, naming the sign-off or the section:

| change | ``railval verify`` | ``audit verify`` |
|---|---|---|
| a byte of a measured signal flipped, its SHA-256 recomputed | fails | fails |
| the sign-off's decision changed | – | fails, names the sign-off |
| the sign-off deleted | – | fails, names the sign-off |
| a forged sign-off with a chained ``signoff.create`` row, head moved | – | fails |
| sections S01 and S02 swapped | fails, names the section | fails |
| the tail removed and the head rewound | – | fails without a checkpoint (witness) |

The attacker's own code (blob format, hash chain) follows docs/database.md and docs/audit.md.
"""

from __future__ import annotations

import hashlib
import json
import pathlib
import re
import shutil
import sqlite3
import struct
import zlib
from contextlib import contextmanager

import pytest
from sqlalchemy.engine import make_url

from railval.app.cli import main
from railval.app.services.signoff import sign
from railval.db import users
from railval.db.importer import import_campaign
from tests.factories import write_demo_campaign

PW = "reviewer password"


@pytest.fixture(scope="module")
def campaign_dir(tmp_path_factory):
    folder = tmp_path_factory.mktemp("attacker-campaign")
    write_demo_campaign(folder, n_sections=12, fs=100.0, n_configs=2)
    return folder


@pytest.fixture
def setup(database, campaign_dir, tmp_path, monkeypatch):
    """Users, the campaign, the reviewer's 'not validated', a checkpoint; returns
    (database, checkpoint path)."""
    monkeypatch.setenv("XDG_CONFIG_HOME", str(tmp_path / "config"))  # key + witness (PG)
    from railval.db import integrity

    integrity.forget_keys()
    with database.session(actor="admin", write=True) as s:
        users.create_user(s, "admin", password="admin password", roles=["admin"], actor="admin")
        users.create_user(s, "eng", password="engineer password", roles=["engineer"],
                          actor="admin")
        users.create_user(s, "rev", display_name="Rita Reviewer", password=PW,
                          roles=["reviewer"], actor="admin")
        users.create_user(s, "ass", password="assessor pw", roles=["assessor"], actor="admin")
    database.actor = "eng"
    import_campaign(database, campaign_dir)
    sign(database, "rev", PW, "demo", "baseline", decision="not-validated",
         statement="Zone 4 guiding forces are not reproduced.",
         justification="The limits pass, but the zone 4 guiding forces differ in shape.")
    cp = tmp_path / "cp.json"
    assert cli(database, "audit", "checkpoint", str(cp)) == 0
    yield database, cp
    integrity.forget_keys()


def cli(database, *argv) -> int:
    return main(["--db", database.url, "--as", "ass", *argv])


@contextmanager
def raw(database):
    """A plain DB-API connection (sqlite3 / psycopg) and a function running ``?`` SQL."""
    url = make_url(database.url)
    if url.get_backend_name() == "sqlite":
        conn = sqlite3.connect(url.database)

        def run(sql, params=()):
            return conn.execute(sql, params)
    else:
        import psycopg

        conn = psycopg.connect(database.url.replace("postgresql+psycopg://", "postgresql://"))

        def run(sql, params=()):
            return conn.execute(sql.replace("?", "%s"), params)
    try:
        yield run, url.get_backend_name()
        conn.commit()
    finally:
        conn.close()


def drop_triggers(run, backend) -> None:
    for table in ("audit_event", "signoff"):
        if backend == "sqlite":
            run(f"DROP TRIGGER {table}_no_update")
            run(f"DROP TRIGGER {table}_no_delete")
        else:
            run(f"DROP TRIGGER {table}_no_change ON {table}")


def canonical(doc) -> bytes:
    return json.dumps(doc, sort_keys=True, separators=(",", ":"), ensure_ascii=False,
                      allow_nan=False).encode()


def as_dict(v):
    return v if isinstance(v, dict) else json.loads(v or "{}")


def audit_verify(database, capsys, *extra) -> tuple[int, str]:
    capsys.readouterr()
    rc = cli(database, "audit", "verify", *extra)
    cap = capsys.readouterr()
    return rc, cap.out + cap.err


def railval_verify(database, capsys) -> tuple[int, str]:
    capsys.readouterr()
    rc = cli(database, "verify")
    cap = capsys.readouterr()
    return rc, cap.out + cap.err


def signoff_list(database, capsys) -> str:
    capsys.readouterr()
    assert cli(database, "signoff", "list") == 0
    return capsys.readouterr().out


def test_untouched_everything_holds(setup, capsys):
    database, cp = setup
    rc, out = audit_verify(database, capsys, "--checkpoint", str(cp))
    assert rc == 0, out
    assert "signed rows" in out and "witness" in out
    assert railval_verify(database, capsys)[0] == 0
    assert "VALID" in signoff_list(database, capsys)


def _planes_decode(blob: bytes) -> tuple[bytes, bytes, int]:
    """(header with codec 0, element bytes, element count) of a codec-2 blob (docs)."""
    magic, codec, _lvl, dlen, ndim = struct.unpack_from("<4sBBBB", blob, 0)
    assert magic == b"RVA1" and codec == 2 and ndim == 1
    pos = 8
    dtype = blob[pos:pos + dlen]
    (n,) = struct.unpack_from("<Q", blob, pos + dlen)
    pos += dlen + 8
    header = struct.pack("<4sBBBB", magic, 0, 0, dlen, ndim) + dtype + struct.pack("<Q", n)
    planes = []
    for _ in range(8):
        flag, length = struct.unpack_from("<BI", blob, pos)
        pos += 5
        data = blob[pos:pos + length]
        pos += length
        planes.append(zlib.decompress(data) if flag else data)
    elements = bytes(b for i in range(n) for b in (p[i] for p in planes))
    return header, elements, n


def test_flipped_signal_byte_with_recomputed_hash(setup, capsys):
    database, cp = setup
    with raw(database) as (run, _backend):
        sig_id, blob = run(
            "SELECT signal.id, signal.blob FROM signal JOIN recording ON "
            "signal.recording_id = recording.id WHERE recording.configuration_id IS NULL "
            "ORDER BY signal.id LIMIT 1").fetchone()
        header, elements, n = _planes_decode(bytes(blob))
        changed = bytearray(elements)
        changed[8 * 10 + 6] ^= 0x10  # a high byte of sample 10
        sha = hashlib.sha256(f"dtype=<f8;shape={n};".encode() + bytes(changed)).hexdigest()
        run("UPDATE signal SET blob = ?, sha256 = ? WHERE id = ?",
            (header + bytes(changed), sha, sig_id))
    rc, out = railval_verify(database, capsys)
    assert rc == 3 and "fails its seal" in out
    rc, out = audit_verify(database, capsys, "--checkpoint", str(cp))
    assert rc == 1, out
    assert "FAILED" in out and "fails its seal" in out
    assert "STALE" in signoff_list(database, capsys)


def test_decision_changed(setup, capsys):
    database, cp = setup
    with raw(database) as (run, backend):
        drop_triggers(run, backend)
        run("UPDATE signoff SET decision = 'validated', meaning = replace(meaning, "
            "'not validated', 'validated') WHERE id = 1")
    assert railval_verify(database, capsys)[0] == 0  # the samples are untouched
    rc, out = audit_verify(database, capsys, "--checkpoint", str(cp))
    assert rc == 1
    assert "sign-off 1 (demo/baseline, validated, by Rita Reviewer" in out
    assert "edited or forged: its signature does not verify" in out
    assert "decision: signed 'not-validated', now 'validated'" in out
    assert "STALE" in signoff_list(database, capsys)  # the quick status checks it too


def test_signoff_deleted(setup, capsys):
    database, cp = setup
    with raw(database) as (run, backend):
        drop_triggers(run, backend)
        run("DELETE FROM signoff WHERE id = 1")
    rc, out = audit_verify(database, capsys, "--checkpoint", str(cp))
    assert rc == 1
    assert "sign-off 1 (demo/baseline, not-validated, by rev" in out
    assert "none: the sign-off was deleted" in out


def test_forged_signoff_with_a_chained_audit_row(setup, capsys):
    database, cp = setup
    with raw(database) as (run, _backend):
        cols = [d[0] for d in run("SELECT * FROM signoff WHERE id = 1").description]
        row = dict(zip(cols, run("SELECT * FROM signoff WHERE id = 1").fetchone(), strict=True))
        forged = {**row, "id": 2, "decision": "validated",
                  "meaning": row["meaning"].replace("not validated", "validated"),
                  "statement": "All limits met.", "signed_at_utc": "2026-11-26T09:00:00.000000Z"}
        forged["manifest"] = json.dumps(as_dict(row["manifest"]))
        record = {"format": "railval-signoff/1", **{k: forged[k] for k in (
            "id", "campaign", "configuration", "username", "printed_name", "signed_at_utc",
            "meaning", "decision", "restrictions", "statement", "justification",
            "evidence_sha256", "software_version")},
            "contrary_to_objective": bool(forged["contrary_to_objective"])}
        forged["record_sha256"] = hashlib.sha256(canonical(record)).hexdigest()
        # the attacker has no key: an old signature is all there is to copy
        names = ", ".join(forged)
        run(f"INSERT INTO signoff ({names}) VALUES ({', '.join('?' for _ in forged)})",
            tuple(forged.values()))
        seq, prev = run("SELECT seq, row_hash FROM audit_head WHERE id = 1").fetchone()
        new = {"seq": seq + 1, "at_utc": forged["signed_at_utc"], "actor": "rev",
               "action": "signoff.create", "object": "configuration:demo/baseline",
               "before_sha256": None, "after_sha256": forged["record_sha256"],
               "reason": "All limits met.",
               "detail": {"signoff": 2, "decision": "validated",
                          "evidence_sha256": forged["evidence_sha256"]}}
        h = hashlib.sha256(prev.encode() + canonical(new)).hexdigest()
        run("INSERT INTO audit_event (seq, at_utc, actor, action, object, before_sha256, "
            "after_sha256, reason, detail, prev_hash, row_hash) VALUES "
            "(?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?)",
            (new["seq"], new["at_utc"], "rev", new["action"], new["object"], None,
             new["after_sha256"], new["reason"], json.dumps(new["detail"]), prev, h))
        run("UPDATE audit_head SET seq = ?, row_hash = ? WHERE id = 1", (new["seq"], h))
    rc, out = audit_verify(database, capsys, "--checkpoint", str(cp))
    assert rc == 1
    assert f"row seq {seq + 1} (signoff.create" in out and "written without the signing key" in out
    assert "sign-off 2 (demo/baseline, validated, by Rita Reviewer" in out
    assert "edited or forged" in out


def test_sections_swapped(setup, capsys):
    database, cp = setup
    with raw(database) as (run, _backend):
        run("UPDATE section SET section_id = 'tmp' WHERE section_id = 'S01'")
        run("UPDATE section SET section_id = 'S01' WHERE section_id = 'S02'")
        run("UPDATE section SET section_id = 'S02' WHERE section_id = 'tmp'")
    rc, out = railval_verify(database, capsys)
    assert rc == 3
    assert "section S01, measurement" in out and "section S02, measurement" in out
    rc, out = audit_verify(database, capsys)  # no checkpoint needed
    assert rc == 1 and "section S01" in out and "fails its seal" in out


def test_tail_removed_and_head_rewound_found_without_checkpoint(setup, capsys):
    database, _cp = setup
    with raw(database) as (run, backend):
        drop_triggers(run, backend)
        (top,) = run("SELECT max(seq) FROM audit_event").fetchone()
        run("DELETE FROM signoff")
        run("DELETE FROM audit_event WHERE seq = ?", (top,))
        (prev,) = run("SELECT row_hash FROM audit_event WHERE seq = ?", (top - 1,)).fetchone()
        run("UPDATE audit_head SET seq = ?, row_hash = ? WHERE id = 1", (top - 1, prev))
    rc, out = audit_verify(database, capsys)
    assert rc == 1
    assert f"the chain to hold at least {top} rows" in out
    assert f"the rows after seq {top - 1} were removed" in out


def test_offline_bundle_with_the_public_key_only(setup, capsys, tmp_path):
    database, cp = setup
    capsys.readouterr()
    assert cli(database, "audit", "key", "--json") == 0
    key = json.loads(capsys.readouterr().out)
    assert len(key["public_key"]) == 64 and len(key["fingerprint"]) == 64
    (tmp_path / "key.pub").write_text(key["public_key"])
    assert cli(database, "audit", "export", str(tmp_path / "bundle")) == 0
    copy = tmp_path / "elsewhere"
    shutil.copytree(tmp_path / "bundle", copy)
    # offline: no database given at all
    capsys.readouterr()
    assert main(["audit", "verify", "--bundle", str(copy), "--public-key",
                 str(tmp_path / "key.pub")]) == 0, capsys.readouterr().out
    # the sign-off's decision changed in the bundle → named
    sods = json.loads((copy / "signoffs.json").read_text())
    sods[0]["decision"] = "validated"
    (copy / "signoffs.json").write_text(json.dumps(sods))
    capsys.readouterr()
    assert main(["audit", "verify", "--bundle", str(copy), "--public-key", key["public_key"]]) == 1
    assert "sign-off 1 (demo/baseline" in capsys.readouterr().out
    # another key does not verify the untouched bundle
    from cryptography.hazmat.primitives.asymmetric.ed25519 import Ed25519PrivateKey

    from railval.core.integrity import public_key_hex

    other = public_key_hex(Ed25519PrivateKey.generate().public_key())
    capsys.readouterr()
    assert main(["audit", "verify", "--bundle", str(tmp_path / "bundle"), "--public-key",
                 other]) == 1
    assert "a key this verifier trusts" in capsys.readouterr().out


def _make_legacy(database) -> None:
    """Turn the set-up into what a database written before signing looks like: no
    signatures, the ``signoff.create`` row naming the evidence hash, no witness file."""
    from railval.core.integrity import GENESIS, chain_hash
    from railval.db import integrity

    with raw(database) as (run, backend):
        drop_triggers(run, backend)
        run("UPDATE signoff SET signature = NULL, key_fingerprint = NULL, record_sha256 = NULL")
        cols = [d[0] for d in run("SELECT * FROM audit_event").description]
        rows = [dict(zip(cols, r, strict=True))
                for r in run("SELECT * FROM audit_event ORDER BY seq").fetchall()]
        (ev_hash,) = run("SELECT evidence_sha256 FROM signoff WHERE id = 1").fetchone()
        prev = GENESIS
        for r in rows:
            r["detail"] = as_dict(r["detail"])
            if r["action"] == "signoff.create":
                r["after_sha256"] = ev_hash
            h = chain_hash(prev, r)
            run("UPDATE audit_event SET after_sha256 = ?, prev_hash = ?, row_hash = ?, "
                "signature = NULL, key_fingerprint = NULL WHERE seq = ?",
                (r["after_sha256"], "p" * 63 + str(r["seq"] % 10), "r" * 63 + str(r["seq"] % 10),
                 r["seq"]))  # unique columns: move out of the way first
            r["prev_hash"], r["row_hash"] = prev, h
            prev = h
        for r in rows:
            run("UPDATE audit_event SET prev_hash = ?, row_hash = ? WHERE seq = ?",
                (r["prev_hash"], r["row_hash"], r["seq"]))
        run("UPDATE audit_head SET row_hash = ? WHERE id = 1", (prev,))
    integrity.forget_keys()


def test_rows_and_signoffs_written_before_signing_are_reported_honestly(setup, capsys,
                                                                       tmp_path, monkeypatch):
    """A database from before signing (and before trust anchors: a new configuration
    directory): unsigned rows fail until a signed row declares them (`audit seal`)."""
    database, _cp = setup
    _make_legacy(database)
    monkeypatch.setenv("RAILVAL_TRUST_DIR", str(tmp_path / "trust-before-signing"))
    rc, out = audit_verify(database, capsys)
    assert rc == 1, out  # not silently passed …
    assert "note: no row is signed" in out and "run `railval audit seal`" in out
    assert "a signed row declaring the rows written before signing" in out
    capsys.readouterr()
    assert main(["--db", database.url, "--as", "admin", "audit", "seal", "--reason",
                 "signing enabled"]) == 0
    rc, out = audit_verify(database, capsys)
    assert rc == 0, out  # … and sealed, it holds
    assert "are unsigned, written before signing was enabled; the signed row seq" in out
    assert "its record is bound by the seal" in out
    with raw(database) as (run, backend):  # an edit after the seal is found
        run("UPDATE signoff SET decision = 'validated' WHERE id = 1")
    rc, out = audit_verify(database, capsys)
    assert rc == 1 and "sign-off 1 (demo/baseline, validated" in out
    assert "edited after the seal" in out


@pytest.mark.parametrize("db_url", ["sqlite"], indirect=True)  # a file copy: SQLite's matter
def test_a_copy_is_verified_with_the_public_key_and_the_witness(setup, capsys, tmp_path,
                                                                monkeypatch):
    database, _cp = setup
    url = make_url(database.url)
    from railval.db import integrity

    capsys.readouterr()
    assert cli(database, "audit", "key", "--json") == 0
    key = json.loads(capsys.readouterr().out)
    copy = tmp_path / "copy" / "railval.db"
    copy.parent.mkdir()
    with sqlite3.connect(url.database) as src, sqlite3.connect(copy) as dst:
        src.backup(dst)  # WAL included
    copy_url = f"sqlite:///{copy}"
    # the seal secret travels with the copy as the server's secret does (docs/database.md)
    monkeypatch.setenv("RAILVAL_SECRET_KEY", (pathlib.Path(url.database + ".key")).read_text().strip())
    # on the server the copy is the same database (its identity row): the pin verifies it
    capsys.readouterr()
    assert main(["--db", copy_url, "--as", "ass", "audit", "verify", "--quick"]) == 0, \
        capsys.readouterr().out
    assert not integrity.signing_key_path(copy_url).exists()  # verifying made no key
    # an assessor's account (no configuration directory) verifies with the public key
    monkeypatch.setenv("XDG_CONFIG_HOME", str(tmp_path / "assessor"))
    integrity.forget_keys()
    assert main(["--db", copy_url, "--as", "ass", "audit", "verify", "--quick",
                 "--public-key", key["public_key"], "--witness", key["witness_file"]]) == 0
    assert not (tmp_path / "assessor").exists() and not integrity.signing_key_path(
        copy_url).exists()


def test_stripping_every_signature_does_not_pass_as_written_before_signing(setup, capsys):
    """Signatures removed from every row and sign-off, then a forged sign-off appended
    unsigned: the witness shows signing was on, so nothing passes as 'before signing'."""
    database, _cp = setup
    with raw(database) as (run, backend):
        drop_triggers(run, backend)
        run("UPDATE audit_event SET signature = NULL, key_fingerprint = NULL")
        run("UPDATE signoff SET signature = NULL, key_fingerprint = NULL, record_sha256 = NULL")
    rc, out = audit_verify(database, capsys)
    assert rc == 1
    assert re.search(r"expected a signature \(rows are signed from seq \d\), found none", out)
    assert "sign-off 1 (demo/baseline" in out and "written without the signing key" in out


def test_key_rotation_as_documented_keeps_old_rows_verifiable(setup, capsys, tmp_path):
    """docs/audit.md, "Key rotation": `railval audit rotate-key` writes a key.rotate row
    signed by the old key and countersigned by the new one; old rows, the old sign-off and
    the witness still verify, online and offline from the bundle, trusting either key."""
    database, _cp = setup
    capsys.readouterr()
    assert cli(database, "audit", "key", "--json") == 0
    old = json.loads(capsys.readouterr().out)
    assert main(["--db", database.url, "--as", "admin", "audit", "rotate-key", "--reason",
                 "key rotation"]) == 0
    capsys.readouterr()
    assert cli(database, "audit", "key", "--json") == 0
    new = json.loads(capsys.readouterr().out)
    assert new["fingerprint"] != old["fingerprint"] and new["retired"] == [old["fingerprint"]]
    assert new["key_file_fingerprint"] == new["fingerprint"]
    rc, out = audit_verify(database, capsys)
    assert rc == 0, out
    assert f"trusted key {old['fingerprint']}" in out and f"trusted key {new['fingerprint']}" in out
    (tmp_path / "key.json").write_text(json.dumps(new))
    assert cli(database, "audit", "export", str(tmp_path / "bundle")) == 0
    for trusted in (str(tmp_path / "key.json"), new["public_key"], old["public_key"]):
        capsys.readouterr()
        assert main(["audit", "verify", "--bundle", str(tmp_path / "bundle"), "--public-key",
                     trusted]) == 0, capsys.readouterr().out
    # the key.rotate row removed from the bundle (chain re-linked by hand is not needed:
    # the chain break is named, and the old key's rows are no longer trusted from the new)
    lines = (tmp_path / "bundle" / "audit.jsonl").read_text().splitlines()
    kept = [ln for ln in lines if json.loads(ln)["action"] != "key.rotate"]
    (tmp_path / "bundle" / "audit.jsonl").write_text("\n".join(kept) + "\n")
    capsys.readouterr()
    assert main(["audit", "verify", "--bundle", str(tmp_path / "bundle"), "--public-key",
                 new["public_key"]]) == 1
    assert f"key {old['fingerprint'][:16]}" in capsys.readouterr().out
