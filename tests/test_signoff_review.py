"""The independent reviewer and the panelist, contrary decisions and the first admin, through
the real CLI on both database backends (docs/security.md "Roles", docs/audit.md
"Sign-off").

The CLI contract checked here: ``user add NAME --role panelist``; a panelist's ``signoff
create`` exits non-zero; a reviewer's ``report`` works; ``signoff create --decision
validated`` on a NOT VALIDATED configuration exits 2 without ``--justification`` and with
it is stored ``contrary_to_objective: true``; after open-mode ``workshop import-answers``,
``user add boss --role admin --password-stdin`` succeeds.
"""

from __future__ import annotations

import csv
import io
import json
import sys

import pytest
from sqlalchemy import func, select, text

from railval.app.cli import main as cli
from railval.db import audit, users
from railval.db.importer import import_campaign
from railval.db.models import Signoff
from tests.factories import write_demo_campaign

PW = {"boss": "boss password", "eng": "engineer pw", "rev": "reviewer pw", "pan": "panelist pw"}


def run(capsys, monkeypatch, *argv, stdin: str = "") -> tuple[int, str, str]:
    capsys.readouterr()
    monkeypatch.setattr(sys, "stdin", io.StringIO(stdin))
    code = cli(list(argv))
    out, err = capsys.readouterr()
    return code, out, err


@pytest.fixture
def demo(database, tmp_path):
    # 11 sections: one zone has 2 sections, so the objective verdict is NOT VALIDATED
    write_demo_campaign(tmp_path / "demo", n_sections=11, fs=100.0, n_configs=1)
    import_campaign(database, tmp_path / "demo")
    with database.session(write=True) as s:
        users.create_user(s, "boss", password=PW["boss"], roles=["admin"])
        users.create_user(s, "eng", password=PW["eng"], roles=["engineer"])
        users.create_user(s, "rev", password=PW["rev"], roles=["reviewer"],
                          display_name="Rita Reviewer")
        users.create_user(s, "pan", password=PW["pan"], roles=["panelist"])
    return database


def _signoffs(db) -> int:
    with db.session() as s:
        return s.scalar(select(func.count()).select_from(Signoff))


def test_cli_contract_reviewer_panelist_contrary(demo, capsys, monkeypatch, tmp_path):
    db, url = demo, demo.url
    monkeypatch.delenv("RAILVAL_USER", raising=False)
    code, out, err = run(capsys, monkeypatch, "--db", url, "--as", "boss", "user", "add", "p2",
                         "--role", "panelist", "--password-stdin", stdin="panelist two\n")
    assert code == 0 and "roles: panelist" in out, err
    # the objective verdict of the demo's baseline
    code, out, _ = run(capsys, monkeypatch, "--db", url, "--as", "eng", "validate", "demo",
                       "--config", "baseline", "--json")
    assert code == 0 and json.loads(out)["validated"] is False
    # a stored diagnosis run shows in the summary (its data are current: same signals)
    from railval.app.services.diagnosis import DIAGNOSIS_VERSION
    from railval.app.services.stored_runs import data_inputs, digests
    from railval.db import repo, runs

    with db.session(write=True) as s:
        conf = repo.get_configuration(s, "demo", "baseline")
        data_sha, _ = digests(data_inputs(s, "demo", "baseline"), {}, DIAGNOSIS_VERSION)
        run_id = runs.store_run(s, campaign_id=conf.campaign_id, configuration_id=conf.id,
                                kind="diagnosis", inputs_sha256="0" * 64,
                                settings={"data_sha256": data_sha},
                                result={"verdict": "cause", "separable": True, "candidates": [
                                    {"effect": "friction_damping", "explained": 0.81}]}).id
    code, out, _ = run(capsys, monkeypatch, "--db", url, "--as", "rev", "signoff", "summary",
                       "demo", "--config", "baseline", "--json")
    summ = json.loads(out)
    assert code == 0 and summ["diagnosis"] == {
        "run": run_id, "created_at": summ["diagnosis"]["created_at"], "top": "friction_damping",
        "explained": 0.81, "separable": True, "current": True, "verdict": "cause"}
    assert summ["objective"]["coverage"]["ok"] is False and summ["contrary_if"]["not-validated"] is None
    assert summ["links"]["report"] == "/app?campaign=demo&configuration=baseline&page=report"
    # a panelist cannot sign off (refused before the password is asked)
    code, out, err = run(capsys, monkeypatch, "--db", url, "--as", "pan", "signoff", "create",
                         "demo", "--config", "baseline", "--decision", "not-validated",
                         "--statement", "x", "--password-stdin", stdin=PW["pan"] + "\n")
    assert code != 0 and "pan (panelist) may not sign off" in err
    # the reviewer reads every campaign's evidence: report, signoff summary, list
    out_html = tmp_path / "x.html"
    code, _, err = run(capsys, monkeypatch, "--db", url, "--as", "rev", "report", "demo",
                       "--config", "baseline", "--out", str(out_html))
    assert code == 0 and out_html.stat().st_size > 10_000, err
    assert run(capsys, monkeypatch, "--db", url, "--as", "rev", "list")[0] == 0
    # … and changes nothing
    for verb in (["import", str(tmp_path / "demo")], ["simulate", "demo", "--config", "x"],
                 ["calibrate", "demo", "--config", "baseline", "--effect", "friction_damping",
                  "--as", "c2"], ["validate", "demo", "--config", "baseline"],
                 ["export", "demo", str(tmp_path / "out")]):
        code, _, err = run(capsys, monkeypatch, "--db", url, "--as", "rev", *verb)
        assert code == 2 and "rev (reviewer) may not" in err, (verb, err)
    # a contrary decision without justification: exit 2, summary printed, no password read
    code, out, err = run(capsys, monkeypatch, "--db", url, "--as", "rev", "signoff", "create",
                         "demo", "--config", "baseline", "--decision", "validated",
                         "--statement", "looks fine", "--password-stdin", stdin=PW["rev"] + "\n")
    assert code == 2, err
    assert "needs --justification TEXT" in err and "NOT VALIDATED" in err
    assert "objective verdict  NOT VALIDATED" in out and "Y_qst" in out and "az_max" in out
    assert f"newest diagnosis   run {run_id}" in out and "cause, top friction_damping" in out
    assert _signoffs(db) == 0
    # with the justification it is signed and marked
    why = "track geometry of zone 4 was measured with a faulty trolley; see memo 17"
    code, out, err = run(capsys, monkeypatch, "--db", url, "--as", "rev", "signoff", "create",
                         "demo", "--config", "baseline", "--decision", "validated",
                         "--statement", "looks fine", "--justification", why,
                         "--password-stdin", stdin=PW["rev"] + "\n")
    assert code == 0, err
    assert "CONTRARY TO OBJECTIVE VERDICT" in out and why in out
    code, out, _ = run(capsys, monkeypatch, "--db", url, "--as", "rev", "signoff", "show", "1",
                       "--json")
    rec = json.loads(out)
    assert code == 0 and rec["contrary_to_objective"] is True and rec["justification"] == why
    assert rec["objective_verdict"] == "NOT VALIDATED" and "CONTRARY TO THE OBJECTIVE" in rec["meaning"]
    # an agreeing decision needs no justification and is not marked
    code, out, err = run(capsys, monkeypatch, "--db", url, "--as", "rev", "signoff", "create",
                         "demo", "--config", "baseline", "--decision", "not-validated",
                         "--statement", "fails Y/Q", "--password-stdin", "--json",
                         stdin=PW["rev"] + "\n")
    assert code == 0, err
    doc = json.loads(out)
    assert "objective verdict  NOT VALIDATED" in err  # the summary, read before the password
    assert doc["contrary_to_objective"] is False and doc["summary"]["objective"]["verdict"] == "NOT VALIDATED"
    assert len(doc["summary"]["quantities"]) == 12 and doc["summary"]["signoffs"][0]["id"] == 1
    code, out, _ = run(capsys, monkeypatch, "--db", url, "--as", "rev", "signoff", "list", "--json")
    marks = {d["id"]: d["contrary_to_objective"] for d in json.loads(out)["signoffs"]}
    assert marks == {1: True, 2: False}
    code, out, _ = run(capsys, monkeypatch, "--db", url, "--as", "rev", "signoff", "list")
    lines = out.splitlines()
    assert "CONTRARY TO OBJECTIVE VERDICT" in lines[0] and "CONTRARY" not in lines[1]
    # the report and the audit report say it, with the justification
    code, _, err = run(capsys, monkeypatch, "--db", url, "--as", "rev", "report", "demo",
                       "--config", "baseline", "--out", str(out_html))
    body = out_html.read_text(encoding="utf-8")
    assert code == 0 and "CONTRARY TO THE OBJECTIVE VERDICT" in body and why in body
    aud = tmp_path / "audit.html"
    code, _, err = run(capsys, monkeypatch, "--db", url, "--as", "boss", "audit", "report",
                       "--out", str(aud))
    body = aud.read_text(encoding="utf-8")
    assert code == 0 and "CONTRARY TO THE OBJECTIVE VERDICT" in body and why in body, err
    with db.session() as s:
        rows = [r for r in audit.iter_rows(s) if r["action"] == "signoff.create"]
    assert [r["detail"]["contrary_to_objective"] for r in rows] == [True, False]


def test_contrary_rule():
    from railval.db.signoff import contrary_reason

    assert contrary_reason("validated", False, False)
    assert contrary_reason("restricted", False, False)
    assert contrary_reason("not-validated", True, False)
    assert contrary_reason("validated", True, True) and "in-sample" in contrary_reason("validated", True, True)
    assert contrary_reason("validated", True, False) is None
    assert contrary_reason("not-validated", False, True) is None
    assert contrary_reason("not-validated", False, False) is None


def _workshop(db, tmp_path) -> list[int]:
    from railval.app.services import workshops as ws
    from railval.db import workshops as wsdb

    ws.create(db, "W", "demo", sections=["S01"], kinds=["Y_time"], repeats=0.0)
    with db.session() as s:
        return [p.id for p in wsdb.plots(s, wsdb.get_workshop(s, "W"))]


def test_open_mode_import_answers_then_first_admin(database, tmp_path, capsys, monkeypatch):
    monkeypatch.delenv("RAILVAL_USER", raising=False)
    write_demo_campaign(tmp_path / "demo", n_sections=12, fs=100.0, n_configs=1)
    import_campaign(database, tmp_path / "demo")
    plots = _workshop(database, tmp_path)
    path = tmp_path / "answers.csv"
    with path.open("w", newline="", encoding="utf-8") as f:
        w = csv.writer(f)
        w.writerow(["reviewer", "plot", "answer", "seconds", "comment"])
        for who in ("expert1", "expert2"):
            for p in plots:
                w.writerow([who, p, "yes", 3, ""])
    url = database.url
    code, out, err = run(capsys, monkeypatch, "--db", url, "workshop", "import-answers", "W",
                         str(path))
    assert code == 0, err
    with database.session() as s:
        assert [u.role_names for u in users.list_users(s)] == [["panelist"], ["panelist"]]
    # the database has users now: verbs need --as …
    code, _, err = run(capsys, monkeypatch, "--db", url, "list")
    assert code == 2 and "name the user you act as" in err
    # … but nobody can manage users, so the first admin may be added from the CLI
    code, out, err = run(capsys, monkeypatch, "--db", url, "user", "add", "boss", "--role",
                         "admin", "--password-stdin", stdin="boss password\n")
    assert code == 0 and "roles: admin" in out, err
    assert run(capsys, monkeypatch, "--db", url, "--as", "boss", "user", "list")[0] == 0
    # once an admin exists that door is shut
    code, _, err = run(capsys, monkeypatch, "--db", url, "user", "add", "boss2", "--role",
                       "admin", "--password-stdin", stdin="another password\n")
    assert code == 2 and "name the user you act as" in err
    code, _, err = run(capsys, monkeypatch, "--db", url, "--as", "expert1", "user", "add", "x",
                       "--role", "admin", "--password-stdin", stdin="another password\n")
    assert code == 2 and "expert1 (panelist) may not add users" in err
    with database.session() as s:
        row = [r for r in audit.iter_rows(s) if r["action"] == "user.add"
               and r["object"] == "user:boss"]
        assert row and "first admin" in row[0]["reason"]
        assert users.find_user(s, "boss2") is None and users.find_user(s, "x") is None
    # a disabled admin is no admin: the first-admin door opens again
    with database.session(write=True) as s:
        users.disable(s, "boss", actor="boss")
    code, _, err = run(capsys, monkeypatch, "--db", url, "user", "add", "boss3", "--role",
                       "admin", "--password-stdin", stdin="third password\n")
    assert code == 0, err


def test_migration_turns_workshop_only_reviewers_into_panelists(db_url, tmp_path):
    """An existing database at the revision before panelists: workshop-only reviewers become
    panelists, a reviewer who also signed keeps ``reviewer`` and gains ``panelist``, a
    reviewer without workshops is unchanged; each change is one audit row; the chain holds."""
    from alembic import command

    from railval.db import signoff as db_signoff
    from railval.db import workshops as wsdb
    from railval.db.engine import connect
    from railval.db.models import Invitation

    db = connect(db_url)
    cfg = db._alembic_config()
    with db.engine.begin() as conn:
        cfg.attributes["connection"] = conn
        command.upgrade(cfg, "0007_signatures")  # the revision before panelists
    write_demo_campaign(tmp_path / "demo", n_sections=12, fs=100.0, n_configs=1)
    import_campaign(db, tmp_path / "demo")
    _workshop(db, tmp_path)
    with db.session(write=True) as s:
        for name in ("only_ws", "signer_ws", "plain_rev"):
            users.create_user(s, name, password="password " + name, roles=["panelist"])
        w = wsdb.get_workshop(s, "W")
        wsdb.invite(s, w, "only_ws")
        wsdb.invite(s, w, "signer_ws")
        inv, _ = users.create_invitation(s, role="panelist", workshop_ref="W", actor="org")
        db_signoff.create(s, user=users.get_user(s, "signer_ws"), campaign="demo",
                          config="baseline", decision="not-validated", restrictions="",
                          statement="old", manifest={"result": {"validated": False}},
                          software_version="old")
        inv_id = inv.id
    with db.engine.begin() as conn:  # the roles as the earlier version stored them
        conn.execute(text("UPDATE user_role SET role = 'reviewer' WHERE role = 'panelist'"))
        conn.execute(text("UPDATE invitation SET role = 'reviewer'"))
    db.init()
    assert db.current_revision() == db.head_revision()
    with db.session() as s:
        roles = {u.username: u.role_names for u in users.list_users(s)}
        assert roles == {"only_ws": ["panelist"], "signer_ws": ["panelist", "reviewer"],
                         "plain_rev": ["reviewer"]}
        assert s.get(Invitation, inv_id).role == "panelist"
        rows = [r for r in audit.iter_rows(s) if r["actor"] == "migration"]
    assert [(r["action"], r["object"]) for r in rows] == [
        ("user.roles", "user:only_ws"), ("user.roles", "user:signer_ws"),
        ("invitation.role", f"invitation:{inv_id}")]
    assert rows[0]["detail"] == {"roles": ["panelist"], "was": ["reviewer"], "kept_reviewer": False}
    assert all("0008_panelists" in r["reason"] for r in rows)
    from railval.app.services.audit import verify_database

    report = verify_database(db, None, signals=False, full=False)
    # the chain holds; only the hand-made sign-off of this test is stale (its manifest is
    # not the configuration's evidence)
    assert {f.kind for f in report.findings} <= {"signoff"}, report.findings
    db.dispose()


def test_validated_decision_on_an_in_sample_verdict_is_contrary(sqlite_database, tmp_path, capsys,
                                                                monkeypatch):
    """The configuration passes, but it was calibrated on sections the verdict evaluates:
    accepting it needs a justification, rejecting it does not."""
    db = sqlite_database
    monkeypatch.delenv("RAILVAL_USER", raising=False)
    write_demo_campaign(tmp_path / "demo", n_sections=12, fs=100.0, n_configs=1)
    import_campaign(db, tmp_path / "demo")
    with db.session(write=True) as s:
        users.create_user(s, "rev", password=PW["rev"], roles=["reviewer"])
    with db.engine.begin() as conn:  # as `railval calibrate` records the fit's sections
        conn.execute(text("UPDATE configuration SET calibration = :c WHERE name = 'baseline'"),
                     {"c": json.dumps({"fit_sections": ["S01", "S02"],
                                       "held_out_sections": ["S03"]})})
    code, out, _ = run(capsys, monkeypatch, "--db", db.url, "--as", "rev", "signoff", "summary",
                       "demo", "--config", "baseline", "--json")
    summ = json.loads(out)
    assert summ["objective"]["validated"] is True and summ["objective"]["in_sample"] is True
    assert summ["objective"]["fit_sections"] == ["S01", "S02"]
    assert "in-sample" in summ["contrary_if"]["validated"] and summ["contrary_if"]["not-validated"]
    args = ["--db", db.url, "--as", "rev", "signoff", "create", "demo", "--config", "baseline",
            "--decision", "validated", "--statement", "ok", "--password-stdin"]
    code, out, err = run(capsys, monkeypatch, *args, stdin=PW["rev"] + "\n")
    assert code == 2 and "accepts an in-sample verdict" in err and "IN-SAMPLE" in out
    code, out, err = run(capsys, monkeypatch, *args, "--justification", "held-out S03 passes too",
                         "--json", stdin=PW["rev"] + "\n")
    assert code == 0 and json.loads(out)["contrary_to_objective"] is True, err
