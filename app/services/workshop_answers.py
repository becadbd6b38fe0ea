"""Review workshops, the answers' side (docs/workshops.md): the answers CSV checked, imported
(all rows or none) and exported with formula-injection escaping, and the analysis of the
answers (:func:`railval.core.review.analyse`: reviewer strictness, agreement, threshold,
Table 1). The plot set is built in :mod:`railval.app.services.workshops`.
"""

from __future__ import annotations

import csv
import io
import math
from pathlib import Path
from typing import Any

from railval.core import lazy
from railval.core.errors import InvalidParameter
from railval.core.roles import Principal, require

#: deferred (railval.core.lazy): the spreadsheet formats, the workshop tables and the
#: review statistics only for the export and the analysis
spreadsheet_text = lazy.function("railval.db.io.formats", "spreadsheet_text")
wsdb = lazy.module("railval.db.workshops")
spreadsheet_safe = lazy.function("railval.db.io.formats", "spreadsheet_safe")
core_analyse = lazy.function("railval.core.review", "analyse")
pd = lazy.module("pandas")

CSV_COLUMNS = ("reviewer", "plot", "answer", "seconds", "comment")
EXPORT_COLUMNS = (*CSV_COLUMNS, "answered_at", "updated_at", "position", "repeat", "scaling",
                  "kind", "source", "changes")

# ------------------------------------------------------------------------- CSV
_YES = {"yes": True, "no": False}


def parse_answers_csv(text: str, source_name: str = "FILE") -> list[dict[str, Any]]:
    """Check an answers CSV (columns ``reviewer,plot,answer,seconds,comment``; an optional
    ``repeat`` column as written by the export; other export columns are ignored). Every
    problem names the line and the column; duplicate (reviewer, plot, repeat) rows are
    refused naming both lines. A comment escaped by :func:`export_answers` against formula
    injection is read back as it was written."""

    reader = csv.reader(io.StringIO(text))
    try:
        header = next(reader)
    except StopIteration:
        raise InvalidParameter(f"{source_name}: the file is empty; expected the header "
                               f"{','.join(CSV_COLUMNS)}") from None
    header = [h.strip().lower() for h in header]
    missing = [c for c in CSV_COLUMNS if c not in header]
    if missing:
        raise InvalidParameter(f"{source_name} line 1: missing column(s) {', '.join(missing)}; "
                               f"expected {','.join(CSV_COLUMNS)}")
    unknown = [h for h in header if h not in EXPORT_COLUMNS]
    if unknown:
        raise InvalidParameter(f"{source_name} line 1: unknown column(s) {', '.join(unknown)}; "
                               f"expected {','.join(CSV_COLUMNS)} (and optionally repeat)")
    col = {h: i for i, h in enumerate(header)}
    rows: list[dict[str, Any]] = []
    seen: dict[tuple[str, int, bool], int] = {}
    for line_no, cells in enumerate(reader, start=2):
        if not cells or all(not c.strip() for c in cells):
            continue
        if len(cells) != len(header):
            raise InvalidParameter(f"{source_name} line {line_no}: {len(cells)} fields, the header "
                                   f"has {len(header)}")

        def cell(name: str, cells: list[str] = cells) -> str:
            return cells[col[name]].strip()

        def bad(name: str, why: str, line_no: int = line_no) -> InvalidParameter:
            return InvalidParameter(f"{source_name} line {line_no}, column {name}: {why}")

        reviewer = cell("reviewer")
        if not reviewer:
            raise bad("reviewer", "empty; give the reviewer's user name")
        try:
            plot = int(cell("plot"))
        except ValueError:
            raise bad("plot", f"{cell('plot')!r} is not a plot id (a whole number)") from None
        ans = cell("answer").lower()
        if ans not in _YES:
            raise bad("answer", f"{cell('answer')!r}; answer must be yes or no")
        sec_text = cell("seconds")
        try:
            seconds = float(sec_text) if sec_text else 0.0
        except ValueError:
            raise bad("seconds", f"{sec_text!r} is not a number") from None
        if not (math.isfinite(seconds) and seconds >= 0):
            raise bad("seconds", f"{sec_text!r}; seconds must be ≥ 0")
        repeat = False
        if "repeat" in col:
            rt = cell("repeat").lower()
            if rt not in ("", "true", "false", "1", "0", "yes", "no"):
                raise bad("repeat", f"{cell('repeat')!r}; use true or false")
            repeat = rt in ("true", "1", "yes")
        key = (reviewer, plot, repeat)
        if key in seen:
            raise InvalidParameter(
                f"{source_name} line {line_no}, column plot: duplicate row — reviewer {reviewer!r} "
                f"answered plot {plot} already on line {seen[key]}")
        seen[key] = line_no
        rows.append({"line": line_no, "reviewer": reviewer, "plot": plot,
                     "answer": _YES[ans], "seconds": seconds,
                     "comment": spreadsheet_text(cells[col["comment"]]), "repeat": repeat})
    if not rows:
        raise InvalidParameter(f"{source_name}: no answer rows after the header")
    return rows


def import_answers(database, name: str, path: str | Path, *,
                   actor: Principal | str = "system") -> dict[str, int]:
    """Import an answers CSV into workshop ``name``: all rows or none."""

    if isinstance(actor, Principal):
        require(actor, "workshop.run")
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8-sig")
    except OSError as exc:
        raise InvalidParameter(f"{path}: cannot read: {exc.strerror or exc}") from None
    except UnicodeDecodeError as exc:
        raise InvalidParameter(f"{path}: not UTF-8 text ({exc.reason} at byte {exc.start})") from None
    rows = parse_answers_csv(text, str(path))
    with database.session(write=True) as session:
        w = wsdb.get_workshop(session, name)
        return wsdb.import_answers(session, w, rows, actor=actor, source_name=str(path))


def export_answers(database, name: str, path: str | Path) -> int:
    """Write every answer of workshop ``name`` to a CSV (:data:`EXPORT_COLUMNS`).

    Text cells are quoted, and those a spreadsheet would read as a formula (a comment
    ``=HYPERLINK(…)``) get a leading single quote (:func:`railval.db.io.formats.spreadsheet_safe`,
    OWASP CSV injection); numbers stay unquoted numbers. :func:`parse_answers_csv` reads the
    comment back unchanged."""

    with database.session() as session:
        rows = wsdb.answer_rows(session, wsdb.get_workshop(session, name))
    path = Path(path)
    with path.open("w", newline="", encoding="utf-8") as fh:
        wr = csv.writer(fh, quoting=csv.QUOTE_NONNUMERIC)
        wr.writerow(EXPORT_COLUMNS)
        for r in rows:
            wr.writerow([spreadsheet_safe("" if r[c] is None else
                                          str(r[c]).lower() if isinstance(r[c], bool) else r[c])
                         for c in EXPORT_COLUMNS])
    return len(rows)


# ------------------------------------------------------------------------- analysis
def analysis_frames(session, name: str):
    """``(answers_df, plots_df)`` of workshop ``name`` for :func:`railval.core.review.analyse`.

    answers: ``reviewer, plot, answer`` (bool), ``repeat, scaling, seconds, position``; an
    answer on a twin (automatic scaling, or the other consistent scaling) is reported on its
    fixed plot with ``scaling`` = ``auto`` (the pairing the scaling effect needs). plots: the fixed plots, ``plot, kind,
    deviation, sg_c`` (NaN where none).
    """

    w = wsdb.get_workshop(session, name)
    rows = wsdb.answer_rows(session, w)
    # pandas loads at its first use, after the look-up: an unknown workshop is answered at once
    answers = pd.DataFrame(
        [{"reviewer": r["reviewer"],
          "plot": r["twin"] if r["scaling"] != "fixed" and r["twin"] is not None else r["plot"],
          "answer": r["answer"] == "yes", "repeat": r["repeat"],
          "scaling": "fixed" if r["scaling"] == "fixed" else "auto",
          "seconds": r["seconds"], "position": r["position"]} for r in rows],
        columns=["reviewer", "plot", "answer", "repeat", "scaling", "seconds", "position"])
    answers = answers[~((answers["scaling"] == "auto") & answers["repeat"])]
    plots = pd.DataFrame(
        [{"plot": p.id, "kind": p.kind,
          "deviation": float("nan") if p.deviation is None else p.deviation,
          "sg_c": float("nan") if p.sg_c is None else p.sg_c}
         for p in wsdb.plots(session, w) if p.scaling == "fixed"],
        columns=["plot", "kind", "deviation", "sg_c"])
    return answers.reset_index(drop=True), plots


def analyse(database, name: str, *, actor: Principal | str = "system",
            with_plots: bool = False) -> dict[str, Any]:
    """The ``workshop analyse NAME --json`` document (railval.core.review.analyse);
    ``with_plots`` adds the per-plot rows (share of Yes, objective values) for the page."""
    if isinstance(actor, Principal):
        require(actor, "workshop.results")
    with database.session() as session:
        answers, plots = analysis_frames(session, name)
    if answers.empty:
        raise InvalidParameter(f"workshop {name!r} has no answers yet")
    result = core_analyse(answers, plots)
    doc = {"workshop": name, **result.to_dict()}
    if with_plots:
        doc["plots"] = result.plots
    return doc


__all__ = ["CSV_COLUMNS", "EXPORT_COLUMNS", "analyse", "analysis_frames", "export_answers", "import_answers",
           "parse_answers_csv"]
