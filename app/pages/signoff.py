"""Sign-off page: sign-offs of the campaign with their status; the reviewer's signing form.

Every sign-off shows its printed name, UTC time, meaning, decision, restrictions, statement
and evidence hash, and whether it is still *valid* (the evidence is unchanged) or *stale*
(docs/audit.md). A reviewer signs the selected configuration: decision, restrictions,
statement and the password again (21 CFR 11.200(a)); the check and the signing run on the
server (:func:`railval.app.services.signoff.sign`). User text is shown as text.
"""

from __future__ import annotations

import html

import pandas as pd
import panel as pn

from railval.app.pages._common import PageBase, html_table, make_dispatch, message
from railval.app.state import AppState
from railval.db import signoff as db_signoff


def signoff_card(rec: dict, status: str, reasons: list[str]) -> pn.pane.HTML:
    """One sign-off as an escaped HTML card (also used by the dashboard)."""
    e = html.escape
    colour = "#1e7b34" if status == "valid" else "#b3261e"
    rows = [("Signed by", f"{rec['printed_name']} ({rec['username']})"),
            ("Date and time (UTC)", rec["signed_at_utc"]),
            ("Meaning of the signature", rec["meaning"]),
            ("Decision", rec["decision_text"]),
            ("Restrictions", rec["restrictions"] or "–"),
            ("Statement", rec["statement"] or "–"),
            ("Evidence SHA-256", rec["evidence_sha256"]),
            ("Software", f"railval {rec['software_version']}")]
    body = "".join(f"<tr><th>{e(k)}</th><td class='rv-so-{e(k.split()[0].lower())}'>{e(str(v))}</td></tr>"
                   for k, v in rows)
    stale = "".join(f"<li>{e(r)}</li>" for r in reasons)
    return pn.pane.HTML(
        f"<div class='rv-signoff' style='border-left:4px solid {colour};padding:4px 10px;margin:6px 0'>"
        f"<b>Sign-off {rec['id']}: {e(rec['campaign'])} / {e(rec['configuration'])} — "
        f"<span class='rv-signoff-status' style='color:{colour}'>{e(status.upper())}</span></b>"
        f"<table style='font-size:13px'>{body}</table>"
        + (f"<div>Evidence changed since signing:<ul>{stale}</ul></div>" if stale else "")
        + "</div>", sizing_mode="stretch_width")


def signoff_banner(app: AppState, config: str | None) -> pn.pane.HTML:
    """One line per sign-off of ``config`` with its status (dashboard), escaped."""
    from railval.app.services.signoff import statuses

    with app.backend.session() as s:
        items = [(db_signoff.as_dict(so), st) for so, st in statuses(s, app.campaign, config)]
    if not items:
        return pn.pane.HTML("<div class='rv-signoff-banner' style='color:#555;font-size:13px'>"
                            "Not signed off.</div>", sizing_mode="stretch_width")
    e = html.escape
    lines = []
    for d, st in items:
        colour = "#1e7b34" if st.valid else "#b3261e"
        why = f" — evidence changed: {e(st.reasons[0])}" if st.reasons else ""
        lines.append(f"<div style='border-left:4px solid {colour};padding:2px 8px;margin:2px 0'>"
                     f"Sign-off {d['id']} <b style='color:{colour}'>{e(st.status.upper())}</b>: "
                     f"{e(d['decision_text'])} by {e(d['printed_name'])}, {e(d['signed_at_utc'])} "
                     f"UTC, evidence {e(d['evidence_sha256'][:16])}…{why}</div>")
    return pn.pane.HTML("<div class='rv-signoff-banner' style='font-size:13px'>" + "".join(lines)
                        + "</div>", sizing_mode="stretch_width")


class SignoffPage(PageBase):
    name_ = "signoff"

    def __init__(self, app: AppState, **params):
        super().__init__(app, **params)
        self.decision = pn.widgets.Select(name="Decision", options={
            "validated": "validated", "validated with restrictions": "restricted",
            "not validated": "not-validated"}, width=260)
        self.restrictions = pn.widgets.TextAreaInput(name="Restrictions (required for 'with restrictions')",
                                                     height=70, css_classes=["rv-restrictions"])
        self.statement = pn.widgets.TextAreaInput(name="Statement", height=90,
                                                  css_classes=["rv-statement"])
        self.password = pn.widgets.PasswordInput(name="Your password (signature)", width=260,
                                                 css_classes=["rv-sign-password"])
        self.sign_btn = pn.widgets.Button(name="Sign", button_type="primary", width=160,
                                          css_classes=["rv-sign"])
        self.sign_btn.on_click(lambda e: self.sign(dispatch=make_dispatch()))

    def sign(self, dispatch=None, background: bool = True):
        """Run the signing as a background job (the validation may take seconds)."""
        app = self.app
        if not app.guard("signoff.create"):
            return None
        password, self.password.value = self.password.value, ""
        campaign, config = app.campaign, app.configuration
        decision, restrictions, statement = (self.decision.value, self.restrictions.value,
                                             self.statement.value)
        username = app.principal.username
        database = app.backend.database

        def work(progress):
            from railval.app.services.signoff import sign

            progress(0.1, "checking the password and building the evidence")
            return sign(database, username, password, campaign, config, decision=decision,
                        restrictions=restrictions, statement=statement, source="web")

        def done(rec):
            self.restrictions.value = ""
            self.statement.value = ""
            app.set_status(f"sign-off {rec['id']} recorded: {campaign}/{config} "
                           f"{rec['decision_text']}", "success")
            self._stale = True
            self.safe_refresh()
        return app.run_job("sign-off", work, done, dispatch=dispatch, background=background,
                           action="signoff.create")

    def items(self):
        from railval.app.services.signoff import statuses

        with self.app.backend.session() as s:
            return [(db_signoff.as_dict(so), st) for so, st in statuses(s, self.app.campaign)]

    def refresh(self) -> None:
        items = self.items()
        objs: list = []
        if self.app.allowed("signoff.create") and self.app.configuration is not None:
            if self.app.principal.open_mode:
                objs.append(message("Signing needs a user account (identity and password); "
                                    "this server runs in open single-user mode.", "warning"))
            else:
                objs += [pn.pane.HTML(
                    f"<b>Sign configuration <code>{html.escape(self.app.configuration)}</code></b> "
                    f"as {html.escape(self.app.principal.printed_name)}. The signature is bound "
                    "to the SHA-256 of the evidence (every signal hash of both sides, the "
                    "configuration's effects and parameters, processing version and settings, "
                    "the validation result, the software version).", sizing_mode="stretch_width"),
                    pn.Row(self.decision, self.password),
                    self.restrictions, self.statement, self.sign_btn]
        if not items:
            objs.append(message(f"No sign-off of campaign {self.app.campaign!r} yet."))
        else:
            df = pd.DataFrame([{"id": d["id"], "configuration": d["configuration"],
                                "status": st.status, "decision": d["decision_text"],
                                "signed by": d["printed_name"], "UTC": d["signed_at_utc"],
                                "evidence": d["evidence_sha256"][:16] + "…"} for d, st in items])
            objs.append(html_table(df, "rv-signoff-table"))
            objs += [signoff_card(d, st.status, st.reasons) for d, st in reversed(items)]
        self.body.objects = objs
