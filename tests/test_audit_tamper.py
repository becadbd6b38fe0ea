"""Tamper tests: ``railval audit verify`` names each break, sign-offs turn stale.

Every attack is a database-level attacker: the append-only triggers are dropped first
(they refuse the change otherwise, which ``test_audit_chain`` checks), then a row is
changed or removed directly in SQL. Run on SQLite and PostgreSQL.
"""

from __future__ import annotations

import json

import pytest
from sqlalchemy import text

from railval.app.cli import main
from railval.app.services import audit as audit_svc
from railval.app.services.signoff import SignoffRefused, sign, status
from railval.db import audit, codec, repo, users
from railval.db import signoff as db_signoff
from railval.db.importer import import_campaign
from tests.factories import write_demo_campaign

PW = "reviewer password"


@pytest.fixture(scope="module")
def campaign_dir(tmp_path_factory):
    folder = tmp_path_factory.mktemp("tamper-campaign")
    write_demo_campaign(folder, n_sections=12, fs=100.0, n_configs=2)
    return folder


@pytest.fixture
def signed(database, campaign_dir):
    """Demo campaign imported, a reviewer who signed ``baseline`` off."""
    database.actor = "eng"
    import_campaign(database, campaign_dir)
    with database.session(actor="admin", write=True) as s:
        users.create_user(s, "rev", display_name="Rita Reviewer", password=PW,
                          roles=["reviewer"], actor="admin")
        users.create_user(s, "ass", password="assessor pw", roles=["assessor"], actor="admin")
    rec = sign(database, "rev", PW, "demo", "baseline", decision="validated",
               statement="Evidence reviewed.")
    return database, rec


def drop_triggers(database) -> None:
    """What a database-level attacker does before rewriting history."""
    with database.session(write=True) as s:
        for table in ("audit_event", "signoff"):
            if database.dialect == "sqlite":
                s.execute(text(f"DROP TRIGGER {table}_no_update"))
                s.execute(text(f"DROP TRIGGER {table}_no_delete"))
            else:
                s.execute(text(f"DROP TRIGGER {table}_no_change ON {table}"))


def verify(database, checkpoint=None):
    return audit_svc.verify_database(database, checkpoint, signals=True, full=True)


def test_untouched_database_verifies_and_signoff_is_valid(signed):
    database, rec = signed
    report = verify(database)
    assert report.ok, [str(f) for f in report.findings]
    assert report.signoffs == 1 and report.signals > 0 and report.rows == 5
    with database.session() as s:
        assert [(r["actor"], r["action"]) for r in audit.iter_rows(s)] == [
            ("system", "database.identity"), ("eng", "campaign.import"), ("admin", "user.add"), ("admin", "user.add"),
            ("rev", "signoff.create")]
    assert rec["printed_name"] == "Rita Reviewer" and rec["signed_at_utc"].endswith("Z")
    assert rec["evidence_sha256"] in rec["meaning"] and "validated" in rec["meaning"]
    with database.write_session(deferred=True) as s:
        assert status(s, db_signoff.get(s, rec["id"])).status == "valid"


def test_flipped_byte_in_an_audit_row_is_named(signed):
    database, _ = signed
    drop_triggers(database)
    with database.session(write=True) as s:
        s.execute(text("UPDATE audit_event SET actor = 'evx' WHERE seq = 2"))
    report = verify(database)
    assert not report.ok
    first = report.findings[0]
    assert first.kind == "chain" and "row seq 2" in first.where and "campaign:demo" in first.where
    assert "row_hash" in first.where and first.expected != first.found


def test_deleted_row_is_named(signed):
    database, _ = signed
    with pytest.raises(Exception, match="append-only"):
        with database.session(write=True) as s:
            s.execute(text("DELETE FROM audit_event WHERE seq = 2"))
    drop_triggers(database)
    with database.session(write=True) as s:
        s.execute(text("DELETE FROM audit_event WHERE seq = 2"))
    first = verify(database).findings[0]
    assert first.kind == "chain" and "row seq 3" in first.where and "field seq" in first.where
    assert (first.expected, first.found) == ("2", "3")


def test_truncated_tail_is_caught_with_a_checkpoint(signed, tmp_path):
    database, _ = signed
    cp_file = tmp_path / "head.json"
    assert main(["--db", database.url, "--as", "ass", "audit", "checkpoint", str(cp_file)]) == 0
    cp = json.loads(cp_file.read_text())
    drop_triggers(database)
    with database.session(write=True) as s:  # a careful attacker also rewinds the head
        s.execute(text("DELETE FROM audit_event WHERE seq >= :n"), {"n": cp["seq"] - 1})
        prev = s.execute(text("SELECT row_hash FROM audit_event WHERE seq = :n"),
                         {"n": cp["seq"] - 2}).scalar_one()
        s.execute(text("UPDATE audit_head SET seq = :n, row_hash = :h"),
                  {"n": cp["seq"] - 2, "h": prev})
    alone = audit_svc.verify_database(database, None, use_witness=False).findings
    assert alone == [] or all(f.kind == "signoff" for f in alone)  # chain alone looks whole
    (wit, *_) = [f for f in verify(database).findings if f.kind == "witness"]  # not the witness
    assert f"{cp['seq'] - 2} rows: the rows after seq {cp['seq'] - 2} were removed" in wit.found
    report = verify(database, audit_svc.read_checkpoint(cp_file))
    (cpf,) = [f for f in report.findings if f.kind == "checkpoint"]
    assert f"at least {cp['seq']} rows" in cpf.expected and f"{cp['seq'] - 2} rows" in cpf.found
    assert main(["--db", database.url, "--as", "ass", "audit", "verify", "--checkpoint", str(cp_file)]) == 1


def test_changed_signal_byte_is_named_and_signoff_stays_bound(signed):
    database, rec = signed
    with database.session(write=True) as s:
        sid, blob = s.execute(text(
            "SELECT signal.id, signal.blob FROM signal JOIN recording ON "
            "signal.recording_id = recording.id WHERE recording.configuration_id IS NULL "
            "ORDER BY signal.id LIMIT 1")).one()
        blob = bytearray(blob)
        blob[-1] ^= 0x01
        s.execute(text("UPDATE signal SET blob = :b WHERE id = :i"), {"b": bytes(blob), "i": sid})
    report = verify(database)
    (sig,) = [f for f in report.findings if f.kind == "signal"]
    assert "campaign 'demo', measurement, section" in sig.where and "channel" in sig.where
    assert "does not decompress" in sig.found  # the flipped byte broke a zlib stream
    # an attacker who re-encodes changed samples produces a valid blob: the hash catches it
    with database.session(write=True) as s:
        a = codec.decode(s.execute(text("SELECT blob FROM signal WHERE id = :i"),
                                   {"i": sid + 1}).scalar_one())
        a[10] += 1e-3
        s.execute(text("UPDATE signal SET blob = :b WHERE id = :i"),
                  {"b": codec.encode(a)[0], "i": sid + 1})
    sigs = [f for f in verify(database).findings if f.kind == "signal"]
    assert len(sigs) == 2 and "content hash" in sigs[1].found and "differs" in sigs[1].found
    (so,) = [f for f in verify(database).findings if f.kind == "signoff"]
    assert f"sign-off {rec['id']}" in so.where and "stale" in so.where
    assert "measurement section S01 Q_w1L" in so.found and "Y_w1L" in so.found


def test_parameter_changed_after_signoff_makes_it_stale(signed, capsys):
    database, rec = signed
    with database.session(write=True) as s:
        conf = repo.get_configuration(s, "demo", "baseline")
        params = dict(conf.parameters or {})
        key = sorted(params)[0] if params else "k_y"
        params[key] = (params.get(key) or 1.0) * 1.01 if isinstance(params.get(key, 1.0), float) else 1.0
        s.execute(text("UPDATE configuration SET parameters = :p WHERE id = :i"),
                  {"p": json.dumps(params), "i": conf.id})
    with database.write_session(deferred=True) as s:
        st = status(s, db_signoff.get(s, rec["id"]))
    assert st.status == "stale"
    assert any(r.startswith("configuration_record.parameters") for r in st.reasons), st.reasons
    report = verify(database)
    (f,) = [f for f in report.findings if f.kind == "signoff"]
    assert f"sign-off {rec['id']}" in f.where and "stale" in f.where
    assert "configuration_record.parameters" in f.found
    assert main(["--db", database.url, "--as", "ass", "signoff", "list"]) == 0
    assert "STALE" in capsys.readouterr().out


def test_rewritten_signoff_decision_is_named(signed):
    database, rec = signed
    drop_triggers(database)
    with database.session(write=True) as s:
        s.execute(text("UPDATE signoff SET evidence_sha256 = :h"), {"h": "f" * 64})
    (f,) = [f for f in verify(database).findings if f.kind == "signoff"]
    assert "manifest" in f.where and f.expected == "f" * 64


def test_bundle_verifies_offline_and_names_a_break(signed, tmp_path):
    database, rec = signed
    out = tmp_path / "bundle"
    assert main(["--db", database.url, "--as", "ass", "audit", "export", str(out)]) == 0
    database.dispose()
    assert main(["audit", "verify", "--bundle", str(out)]) == 0
    lines = (out / "audit.jsonl").read_text(encoding="utf-8").splitlines()
    row = json.loads(lines[1])
    row["reason"] = "rewritten"
    lines[1] = json.dumps(row)
    (out / "audit.jsonl").write_text("\n".join(lines) + "\n", encoding="utf-8")
    report = audit_svc.verify_bundle(out)
    assert report.findings[0].kind == "chain" and "row seq 2" in report.findings[0].where


def test_signing_needs_the_password_the_role_and_independence(signed):
    database, _ = signed
    with database.session(write=True) as s:
        users.create_user(s, "eng2", password="engineer pw", roles=["engineer", "reviewer"])
    with pytest.raises(SignoffRefused, match="Wrong user name or password"):
        sign(database, "rev", "not the password", "demo", "variant1", decision="validated")
    with database.session(actor="eng2", write=True) as s:
        conf = repo.get_configuration(s, "demo", "variant1")
        sets = repo.load_signalsets(s, "demo", "variant1")
        repo.store_configuration(s, "demo", "variant1", parent="baseline", effects=conf.effects,
                                 parameters=conf.parameters, description="re-stored",
                                 signalsets=sets, replace=True)
    with pytest.raises(SignoffRefused, match="eng2 stored configuration 'variant1'.*independent"):
        sign(database, "eng2", "engineer pw", "demo", "variant1", decision="validated")
    with pytest.raises(Exception, match="restrictions"):
        sign(database, "rev", PW, "demo", "variant1", decision="restricted")
    with database.session() as s:
        assert [r["action"] for r in audit.iter_rows(s, action="login.failed")] == ["login.failed"]
        assert len(db_signoff.list_signoffs(s)) == 1
