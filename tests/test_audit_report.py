"""Assessor's audit report (HTML, PDF) and the stale sign-off in dashboard, report and CLI."""

from __future__ import annotations

import json

import pytest
from sqlalchemy import text

from railval.app.audit_report import build_audit_report
from railval.app.cli import main
from railval.app.pages.signoff import signoff_banner
from railval.app.report import build_report
from railval.app.services.signoff import sign
from railval.app.state import AppState, Backend
from railval.core.roles import Principal
from railval.db import repo, users
from railval.db.importer import import_campaign
from tests.factories import write_demo_campaign


@pytest.fixture(scope="module")
def signed_db(tmp_path_factory):
    from railval.db.engine import connect

    root = tmp_path_factory.mktemp("audit-report")
    write_demo_campaign(root / "demo", n_sections=12, fs=100.0, n_configs=2)
    db = connect(f"sqlite:///{root / 'a.db'}")
    db.init()
    db.actor = "eng"
    import_campaign(db, root / "demo")
    with db.session(actor="admin", write=True) as s:
        users.create_user(s, "rev", display_name="Rita <Reviewer>", password="reviewer pw",
                          roles=["reviewer"], actor="admin")
        users.create_user(s, "ass", password="assessor pw", roles=["assessor"], actor="admin")
    sign(db, "rev", "reviewer pw", "demo", "baseline", decision="validated",
         statement="fine")
    # variant1 passes the objective limits: rejecting it is contrary and needs a justification
    sign(db, "rev", "reviewer pw", "demo", "variant1", decision="not-validated",
         statement="yaw damper & <b>lateral</b> mismatch",
         justification="workshop <i>panel</i> rejected the lateral plots")
    with db.session(write=True) as s:  # the engineer changes variant1's parameters afterwards
        conf = repo.get_configuration(s, "demo", "variant1")
        params = {**(conf.parameters or {}), "changed_after_signing": 1.0}
        s.execute(text("UPDATE configuration SET parameters = :p WHERE id = :i"),
                  {"p": json.dumps(params), "i": conf.id})
    yield db
    db.dispose()


def test_audit_report_lists_signoffs_with_status_timeline_and_actors(signed_db):
    rep = build_audit_report(signed_db)
    assert rep.chain_status == "intact" and (rep.signoffs, rep.stale) == (2, 1)
    h = rep.html
    assert "Hash chain and signatures: intact" in h and "key fingerprint (SHA-256)" in h
    assert "Rita &lt;Reviewer&gt;" in h and "<Reviewer>" not in h
    assert "yaw damper &amp; &lt;b&gt;lateral&lt;/b&gt; mismatch" in h
    assert h.count("rv-contrary") == 1  # the label (the meaning says it too)
    assert "justification: workshop &lt;i&gt;panel&lt;/i&gt; rejected the lateral plots" in h
    assert "class='l pass'>valid<" in h and "class='l fail'>stale<" in h
    assert "configuration_record.parameters" in h
    assert "<h3>campaign:demo</h3>" in h and "configuration:demo/variant1" in h
    assert "<h2>Who did what</h2>" in h and "signoff.create" in h and "campaign.import" in h


def test_audit_report_pdf_and_cli(signed_db, tmp_path, capsys):
    pdf = build_audit_report(signed_db).pdf_bytes()
    assert pdf.startswith(b"%PDF") and len(pdf) > 2000
    out = tmp_path / "audit.html"
    assert main(["--db", signed_db.url, "--as", "ass", "audit", "report", "--out", str(out)]) == 0
    assert "audit report (intact)" in capsys.readouterr().out and out.read_text().startswith("<!DOCTYPE")
    assert main(["--db", signed_db.url, "--as", "ass", "audit", "report", "--out",
                 str(tmp_path / "a.txt")]) == 2


def test_stale_shows_in_dashboard_report_and_cli(signed_db, capsys):
    app = AppState(Backend(signed_db), principal=Principal("ass", frozenset({"assessor"})))
    app.configuration = "variant1"
    banner = signoff_banner(app, "variant1").object
    assert "STALE" in banner and "configuration_record.parameters" in banner
    assert "VALID" in signoff_banner(app, "baseline").object
    assert "Not signed off." in signoff_banner(app, "nonexistent").object
    rep = build_report(Backend(signed_db), "demo", "variant1", worst_cases=0)
    assert "<h2>Sign-offs</h2>" in rep.html and "class='l fail'>stale<" in rep.html
    assert main(["--db", signed_db.url, "--as", "ass", "signoff", "show", "2"]) == 0
    out = capsys.readouterr().out
    assert "NOT VALIDATED  [STALE]" in out and "stale: configuration_record.parameters" in out
    assert "signed by   Rita <Reviewer> (rev)" in out and "(UTC)" in out
    assert main(["--db", signed_db.url, "--as", "ass", "signoff", "list", "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert [d["status"] for d in doc["signoffs"]] == ["valid", "stale"]
    assert main(["--db", signed_db.url, "--as", "ass", "audit", "verify", "--quick"]) == 1
    assert "sign-off 2 (demo/variant1, Rita <Reviewer>) is stale" in capsys.readouterr().out
