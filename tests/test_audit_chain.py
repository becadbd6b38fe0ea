"""The hash-chained audit trail: append path, append-only triggers, chain arithmetic."""

from __future__ import annotations

import hashlib
import json

import pytest
from sqlalchemy import text
from sqlalchemy.exc import DBAPIError

from railval.core.integrity import GENESIS, canonical_json, chain_hash, verify_chain
from railval.db import audit


def test_canonical_json_is_sorted_compact_utf8_and_refuses_nan():
    assert canonical_json({"b": 1, "a": [1.5, "é"]}) == '{"a":[1.5,"é"],"b":1}'.encode()
    with pytest.raises(ValueError, match=r"\$.x.*nan"):
        canonical_json({"x": float("nan")})


def test_chain_hash_matches_an_independent_computation():
    row = {"seq": 1, "at_utc": "2026-11-23T11:00:00.000000Z", "actor": "a", "action": "x",
           "object": "o", "before_sha256": None, "after_sha256": None, "reason": "",
           "detail": {}}
    doc = json.dumps(row, sort_keys=True, separators=(",", ":"), ensure_ascii=False)
    expected = hashlib.sha256(("0" * 64 + doc).encode("utf-8")).hexdigest()
    assert chain_hash(GENESIS, row) == expected


def test_record_appends_a_verifiable_chain(database):
    with database.session(write=True) as s:
        for i in range(5):
            audit.record(s, "tester", "thing.change", f"thing:{i}", {"v": i}, {"v": i + 1},
                         reason=f"step {i}")
    with database.session() as s:
        rows = list(audit.iter_rows(s))
        n, head, brk = verify_chain(rows)
        assert (n, brk) == (6, None)  # the database's identity row first (docs/audit.md)
        assert audit.head(s) == (6, head)
        assert rows[0]["prev_hash"] == GENESIS and rows[0]["action"] == "database.identity"
        assert rows[3]["before_sha256"] == hashlib.sha256(b'{"v":2}').hexdigest()
        assert [r["seq"] for r in rows] == [1, 2, 3, 4, 5, 6]


def test_audit_row_rolls_back_with_the_change(database):
    with pytest.raises(RuntimeError):
        with database.session(write=True) as s:
            audit.record(s, "tester", "thing.change", "thing:1")
            raise RuntimeError("the change failed")
    with database.session(write=True) as s:
        assert audit.count(s) == 0 and audit.head(s) == (0, GENESIS)
        audit.record(s, "tester", "thing.change", "thing:1")
    with database.session() as s:
        assert verify_chain(audit.iter_rows(s))[2] is None


@pytest.mark.parametrize("statement", [
    "UPDATE audit_event SET actor = 'mallory'",
    "DELETE FROM audit_event WHERE seq = 1",
    "TRUNCATE audit_event",  # PostgreSQL; SQLite has no TRUNCATE: DELETE without WHERE
    "UPDATE signoff SET decision = 'validated'",
    "DELETE FROM signoff",
])
def test_database_refuses_update_and_delete_of_audit_rows(database, statement):
    if statement.startswith("TRUNCATE") and database.dialect == "sqlite":
        statement = "DELETE FROM audit_event"
    with database.session(write=True) as s:
        audit.record(s, "tester", "thing.change", "thing:1")
        s.execute(text(
            "INSERT INTO signoff (campaign, configuration, username, printed_name, signed_at_utc,"
            " meaning, decision, restrictions, statement, evidence_sha256, manifest,"
            " software_version) VALUES ('c', 'k', 'u', 'U', 't', 'm', 'not-validated', '', '',"
            " :h, '{}', '0')"), {"h": "0" * 64})
    with pytest.raises(DBAPIError, match="append-only"):
        with database.session(write=True) as s:
            s.execute(text(statement))
    with database.session() as s:
        assert [r["actor"] for r in audit.iter_rows(s)] == ["system", "tester"]
        assert s.execute(text("SELECT decision FROM signoff")).scalars().all() == ["not-validated"]


def test_import_store_and_delete_are_audited_with_content_hashes(database, tmp_path):
    from railval.db import repo
    from railval.db.importer import import_campaign
    from tests.factories import write_demo_campaign

    write_demo_campaign(tmp_path / "c", n_sections=12, fs=50.0, n_configs=2)
    database.actor = "importer"
    import_campaign(database, tmp_path / "c")
    with database.session(actor="eng", write=True) as s:
        conf = repo.get_configuration(s, "demo", "variant1")
        state = repo.configuration_state(s, conf)
        repo.delete_configuration(s, "demo", "variant1", reason="superseded")
    with database.session(actor="eng", write=True) as s:
        repo.delete_campaign(s, "demo", reason="test over")
    with database.session() as s:
        every = list(audit.iter_rows(s))
        assert every[0]["action"] == "database.identity"  # written before the first change
        rows = every[1:]
        assert [(r["actor"], r["action"], r["object"]) for r in rows] == [
            ("importer", "campaign.import", "campaign:demo"),
            ("eng", "configuration.delete", "configuration:demo/variant1"),
            ("eng", "campaign.delete", "campaign:demo")]
        assert rows[1]["before_sha256"] == hashlib.sha256(canonical_json(state)).hexdigest()
        assert rows[1]["after_sha256"] is None and rows[1]["reason"] == "superseded"
        assert state["signals"] and all(len(h) == 64 for sec in state["signals"].values()
                                        for h in sec.values())
        assert verify_chain(every)[2] is None
        assert repo.list_campaigns(s) == []
