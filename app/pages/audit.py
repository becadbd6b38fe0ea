"""Audit page (assessors, admins): chain status, the newest audit rows, the audit report.

Reading only: nothing on this page changes the database. The downloads are checked on the
server (``audit.read``) when they are requested.
"""

from __future__ import annotations

import io

import pandas as pd
import panel as pn

from railval.app.pages._common import PageBase, html_table, message
from railval.app.state import AppState
from railval.core import lazy

#: deferred (railval.core.lazy): the audit report's builder (HTML and PDF) and the audit
#: service until the page is shown or a report downloaded, not when the app's pages load
build_audit_report = lazy.function("railval.app.audit_report", "build_audit_report")
audit_service = lazy.module("railval.app.services.audit")

ROWS_SHOWN = 200


def contrary_mark(row: dict) -> str:
    """" — CONTRARY TO THE OBJECTIVE VERDICT" for a ``signoff.create`` row whose decision
    contradicts the objective verdict (the row's signed ``detail``), else ""."""
    if row.get("action") == "signoff.create" and (row.get("detail") or {}).get("contrary_to_objective"):
        return " — CONTRARY TO THE OBJECTIVE VERDICT"
    return ""


class AuditPage(PageBase):
    name_ = "audit"
    watch_app = ("revision",)

    def __init__(self, app: AppState, **params):
        super().__init__(app, **params)
        self.html_dl = pn.widgets.FileDownload(callback=self._html_bytes, filename="railval-audit.html",
                                               label="Audit report (HTML)", color="primary", width=220)
        self.pdf_dl = pn.widgets.FileDownload(callback=self._pdf_bytes, filename="railval-audit.pdf",
                                              label="Audit report (PDF)", color="primary", width=220)

    def _report(self):
        return build_audit_report(self.app.backend.database)

    def _html_bytes(self):
        if not self.app.guard("audit.read"):
            return io.BytesIO(self.app.denial("audit.read").encode("utf-8"))
        return io.BytesIO(self._report().html.encode("utf-8"))

    def _pdf_bytes(self):
        if not self.app.guard("audit.read"):
            return io.BytesIO(self.app.denial("audit.read").encode("utf-8"))
        return io.BytesIO(self._report().pdf_bytes())

    def safe_refresh(self) -> None:  # the audit trail exists without any campaign
        if self.app.campaign is None and self.app.page_allowed(self.name_):
            self._stale = False
            self.refresh()
            return
        super().safe_refresh()

    def refresh(self) -> None:
        check = audit_service.verify_database(self.app.backend.database, signals=False, full=False)
        chain = [f for f in check.findings if f.kind in ("chain", "head", "signature", "witness")]
        rows, n = audit_service.newest(self.app.backend.database, ROWS_SHOWN)
        objs = [message(f"Hash chain intact: {check.rows} rows, head {check.head_hash[:16]}…, "
                        f"{check.signed_rows} signed (key {', '.join(k[:16] for k in check.keys)}…)"
                        if not chain else f"Hash chain BROKEN: {chain[0]}",
                        "success" if not chain else "danger")]
        objs += [message(note, "info") for note in check.notes]
        stale = [f for f in check.findings if f.kind == "signoff"]
        if stale:
            objs.append(message(f"{len(stale)} sign-off(s) stale or unbound: {stale[0]}", "warning"))
        objs.append(pn.Row(self.html_dl, self.pdf_dl))
        df = pd.DataFrame([{"seq": r["seq"], "UTC": r["at_utc"][:19], "actor": r["actor"],
                            "action": r["action"], "object": r["object"] + contrary_mark(r),
                            "reason": r["reason"]} for r in rows])
        objs.append(pn.pane.Markdown(f"Newest {min(n, ROWS_SHOWN)} of {n} audit rows:"))
        if len(df):
            objs.append(html_table(df, "rv-audit-table", max_height=600))
        self.body.objects = objs
