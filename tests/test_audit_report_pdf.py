"""The assessor's PDF audit report holds every field of its HTML (issue 39, part 2).

A real SQLite database with the demo campaign and two sign-offs — one contrary to the
objective verdict with a 2 000-character justification full of characters that need
escaping (``<``, ``&``, quotes) and non-ASCII text — is turned into the audit report; the PDF
is printed by headless Chromium (:mod:`railval.app.pdf`) and its text extracted with pypdf.
Every text of every cell, heading and paragraph of the HTML must be in the PDF's text, and
the pages must be A4. The validation report, which prints the same sign-off table, is
checked the same way for the sign-off fields.
"""

from __future__ import annotations

import html.parser
import json
import re

import pypdf  # a test dependency (pyproject [test])
import pytest
from sqlalchemy import text

from railval.app.audit_report import build_audit_report
from railval.app.services.signoff import sign
from railval.db import repo, users
from railval.db.importer import import_campaign
from tests.factories import write_demo_campaign

_SENTENCE = ("Prüfung der Querkräfte: Y < 0,8·Y_lim & Q > 10 kN bei „Bogen R 300 m“ — l'écart "
             "dépasse 15 % (Σ ≈ 1,2); <b>not bold</b> & \"quoted\" ≤ 'single'. ")
JUSTIFICATION = (_SENTENCE * 20)[:1985] + " END-OF-REASON"
RESTRICTIONS = "only up to 160 km/h & curve radius ≥ 600 m <strictly>"
A4_PT = (595.3, 841.9)


@pytest.fixture(scope="module")
def signed(tmp_path_factory):
    from railval.db.engine import connect

    root = tmp_path_factory.mktemp("audit-pdf")
    write_demo_campaign(root / "demo", n_sections=12, fs=100.0, n_configs=2)
    db = connect(f"sqlite:///{root / 'a.db'}")
    db.init()
    db.actor = "eng"
    import_campaign(db, root / "demo")
    with db.session(actor="admin", write=True) as s:
        users.create_user(s, "rev", display_name="Zoë <Reviewer> & Söhne", password="reviewer pw",
                          roles=["reviewer"], actor="admin")
    sign(db, "rev", "reviewer pw", "demo", "baseline", decision="restricted", restrictions=RESTRICTIONS,
         statement="fine within the restrictions")
    # variant1 passes the objective limits: rejecting it is contrary and needs a justification
    sign(db, "rev", "reviewer pw", "demo", "variant1", decision="not-validated",
         statement="yaw damper & <b>lateral</b> mismatch", justification=JUSTIFICATION)
    with db.session(write=True) as s:  # the engineer changes variant1's parameters afterwards: stale
        conf = repo.get_configuration(s, "demo", "variant1")
        params = {**(conf.parameters or {}), "changed_after_signing": 1.0}
        s.execute(text("UPDATE configuration SET parameters = :p WHERE id = :i"),
                  {"p": json.dumps(params), "i": conf.id})
    yield db
    db.dispose()


class _Fields(html.parser.HTMLParser):
    """The texts of an HTML report's fields: every td, th, heading, paragraph and verdict box
    (the innermost element's own text, tags removed, entities decoded)."""

    BLOCKS = {"td", "th", "h1", "h2", "h3", "p", "div", "code", "b"}

    def __init__(self) -> None:
        super().__init__(convert_charrefs=True)
        self.stack: list[list[str]] = []
        self.fields: list[str] = []
        self.in_head = 0

    def handle_starttag(self, tag, attrs):
        if tag in ("style", "title"):
            self.in_head += 1
        if tag in self.BLOCKS:
            self.stack.append([])

    def handle_endtag(self, tag):
        if tag in ("style", "title"):
            self.in_head -= 1
        if tag in self.BLOCKS and self.stack:
            text = "".join(self.stack.pop()).strip()
            if text:
                self.fields.append(text)
                if self.stack:
                    self.stack[-1].append(text)

    def handle_data(self, data):
        if not self.in_head and self.stack:
            self.stack[-1].append(data)


def _fields(document: str) -> list[str]:
    p = _Fields()
    p.feed(document)
    return p.fields


def _squash(text: str) -> str:
    """Text without whitespace (a PDF breaks lines where the page is full)."""
    return re.sub(r"\s+", "", text)


def _pdf_text(data: bytes, tmp_path) -> tuple[str, list]:
    path = tmp_path / "report.pdf"
    path.write_bytes(data)
    reader = pypdf.PdfReader(str(path))
    return "".join(page.extract_text() for page in reader.pages), list(reader.pages)


def test_audit_report_pdf_holds_every_field_of_its_html(signed, tmp_path):
    rep = build_audit_report(signed)
    fields = _fields(rep.html)
    assert any(JUSTIFICATION in f for f in fields)                       # the HTML is complete
    assert any(RESTRICTIONS in f for f in fields)
    text, pages = _pdf_text(rep.pdf_bytes(), tmp_path)
    squashed = _squash(text)
    missing = [f for f in fields if _squash(f) not in squashed]
    assert missing == [], f"{len(missing)} of {len(fields)} HTML fields not in the PDF: {missing[:5]}"
    # the fields the issue found cut off, by name
    for needle in (JUSTIFICATION, RESTRICTIONS, "yaw damper & <b>lateral</b> mismatch",
                   "CONTRARY TO THE OBJECTIVE VERDICT", "Zoë <Reviewer> & Söhne", "evidence SHA-256",
                   "changed since: configuration_record.parameters", "Who did what", "signoff.create",
                   "campaign.import"):
        assert _squash(needle) in squashed, needle
    for page in pages:                                                   # A4, not US letter
        w, h = float(page.mediabox.width), float(page.mediabox.height)
        assert (w, h) == pytest.approx(A4_PT, abs=1.0)


def test_validation_report_pdf_holds_the_signoff_fields(signed, tmp_path):
    from railval.app.report import build_report
    from railval.app.state import Backend

    rep = build_report(Backend(signed), "demo", "variant1", worst_cases=0)
    text, pages = _pdf_text(rep.pdf_bytes(), tmp_path)
    squashed = _squash(text)
    for needle in (JUSTIFICATION, "CONTRARY TO THE OBJECTIVE VERDICT", "evidence SHA-256",
                   "changed since: configuration_record.parameters"):
        assert _squash(needle) in squashed, needle[:40]
    assert all((float(p.mediabox.width), float(p.mediabox.height)) == pytest.approx(A4_PT, abs=1.0)
               for p in pages)
