"""Sign-off page: sign-offs of the campaign with their status; the reviewer's signing form.

Every sign-off shows its printed name, UTC time, meaning, decision, restrictions, statement
and evidence hash, whether it is still *valid* (the evidence is unchanged) or *stale*
(docs/audit.md), and — for a decision contrary to the objective verdict — that label with
the written justification. Before the form the reviewer sees what is signed
(:func:`railval.app.services.signoff.signing_summary`): the objective verdict with its 12
quantities against the limits, coverage, definition-sensitive and in-sample marks,
supplementary results, the newest diagnosis, workshop results on the configuration, links to
dashboard, compare and report, and earlier sign-offs. A reviewer signs the selected
configuration: decision, restrictions, statement, justification (required when contrary)
and the password again (21 CFR 11.200(a)); the check and the signing run on the server
(:func:`railval.app.services.signoff.sign`). User text is shown as text.
"""

from __future__ import annotations

import html
import re

import pandas as pd
import panel as pn

from railval.app.pages._common import PageBase, html_table, make_dispatch, message
from railval.app.state import PAGE_TITLES, AppState
from railval.core import lazy
from railval.core.errors import RailvalError

#: deferred (railval.core.lazy): the sign-off service (records, evidence, signing: 14 more
#: modules) until a sign-off is listed or signed, not when the app's pages load; read as
#: ``signoff_service.sign`` at each call, so a test's stand-in on the real module is seen
signoff_service = lazy.module("railval.app.services.signoff")

#: the decision list's first entry: nothing chosen yet
NO_DECISION = "— choose a decision —"

#: the label of a decision contrary to the objective verdict (cards, banner, table)
CONTRARY_TAG = ("<span class='rv-contrary' style='background:#b3261e;color:#fff;padding:1px 6px;"
                "border-radius:3px;margin-left:8px;font-size:12px'>CONTRARY TO THE OBJECTIVE "
                "VERDICT</span>")


def status_label(status: str) -> str:
    """A sign-off's status as a reader must take it: the *signature*'s state ("SIGNATURE
    VALID": the evidence is unchanged), never a bare "VALID" that reads as "validated"."""
    return f"SIGNATURE {status.upper()}"


#: what the reviewer must do, in the page's words, for each refusal of the signing rules
#: (railval.db.signoff.create words them for the CLI: a flag name means nothing here)
_REFUSALS = (
    ("justification:", "A decision contrary to the objective verdict needs a justification"),
    ("restrictions: a decision 'restricted'", "The decision 'validated with restrictions' needs "
     "the restrictions: write them in the Restrictions box"),
    ("restrictions: only the decision", "Only the decision 'validated with restrictions' takes "
     "restrictions: empty the Restrictions box or choose that decision"),
    ("decision ", "Choose a decision: validated, validated with restrictions or not validated"),
)


def refusal_text(message_text: str) -> str:
    """A refusal of the signing as the page says it: the rule in plain words (with the
    reason the decision is contrary, when that is the rule), no CLI flag."""
    text = re.sub(r"^sign-off refused:\s*", "", str(message_text).strip())
    for prefix, plain in _REFUSALS:
        if text.startswith(prefix):
            if prefix == "justification:":
                reason = text[len(prefix):].split(";", 1)[0].strip()
                return (f"{plain}: {reason}. Write it in the Justification box; the sign-off is "
                        "stored and shown marked contrary to the objective verdict.")
            return plain + "."
    text = re.sub(r"\s*\(--[a-z][a-z-]*[^)]*\)", "", text)  # a CLI flag in any other rule
    return text[:1].upper() + text[1:]


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
            ("Objective verdict", rec.get("objective_verdict") or "–"),
            *([("Contrary to the objective verdict", "YES — justification: "
                + (rec.get("justification") or "–"))] if rec.get("contrary_to_objective") else []),
            ("Evidence SHA-256", rec["evidence_sha256"]),
            ("Software", f"railval {rec['software_version']}")]
    body = "".join(f"<tr><th>{e(k)}</th><td class='rv-so-{e(k.split()[0].lower())}'>{e(str(v))}</td></tr>"
                   for k, v in rows)
    stale = "".join(f"<li>{e(r)}</li>" for r in reasons)
    return pn.pane.HTML(
        f"<div class='rv-signoff' style='border-left:4px solid {colour};padding:4px 10px;margin:6px 0'>"
        f"<b>Sign-off {rec['id']}: {e(rec['campaign'])} / {e(rec['configuration'])} — "
        f"<span class='rv-signoff-status' style='color:{colour}'>{e(status_label(status))}</span></b>"
        + (CONTRARY_TAG if rec.get("contrary_to_objective") else "")
        + f"<table style='font-size:13px'>{body}</table>"
        + (f"<div>Evidence changed since signing:<ul>{stale}</ul></div>" if stale else "")
        + "</div>", sizing_mode="stretch_width")


def signoff_banner(app: AppState, config: str | None) -> pn.pane.HTML:
    """One line per sign-off of ``config`` with its status (dashboard), escaped."""
    items = signoff_service.records(app.backend.database, app.campaign, config)
    if not items:
        return pn.pane.HTML("<div class='rv-signoff-banner' style='color:#555;font-size:13px'>"
                            "Not signed off.</div>", sizing_mode="stretch_width")
    e = html.escape
    lines = []
    for d, st in items:
        colour = "#1e7b34" if st.valid else "#b3261e"
        why = f" — evidence changed: {e(st.reasons[0])}" if st.reasons else ""
        lines.append(f"<div style='border-left:4px solid {colour};padding:2px 8px;margin:2px 0'>"
                     f"Sign-off {d['id']} <b style='color:{colour}'>{e(status_label(st.status))}</b>: "
                     f"{e(d['decision_text'])} by {e(d['printed_name'])}, {e(d['signed_at_utc'])} "
                     f"UTC, evidence {e(d['evidence_sha256'][:16])}…{why}"
                     + (f"{CONTRARY_TAG} justification: {e(d['justification'])}"
                        if d["contrary_to_objective"] else "") + "</div>")
    return pn.pane.HTML("<div class='rv-signoff-banner' style='font-size:13px'>" + "".join(lines)
                        + "</div>", sizing_mode="stretch_width")


def _n(v, fmt: str) -> str:
    return "–" if v is None else format(v, fmt)


def summary_html(summ: dict) -> str:
    """What is signed, as escaped HTML: verdict and marks, the 12 quantities against their
    limits, coverage, supplementary results, newest diagnosis, workshops, evidence links and
    earlier sign-offs (the same document as ``railval signoff summary --json``)."""
    e = html.escape
    o = summ["objective"]
    ok = o["validated"]
    colour = "#1e7b34" if ok else "#b3261e"
    marks = []
    if o["in_sample"]:
        marks.append("<span class='rv-mark rv-in-sample'>IN-SAMPLE</span> "
                     + e(o.get("in_sample_note") or "calibrated") + " (sections "
                     + e(", ".join(o["fit_sections"])) + ") — the verdict is not an independent test"
                     + (f"<br><span class='rv-held-out-check'>{e(o['held_out_check'])}.</span>"
                        if o.get("held_out_check") else ""))
    if o["definition_sensitive"]:
        marks.append("<span class='rv-mark rv-definition'>DEFINITION-SENSITIVE</span> another "
                     "reading of the open definitions flips the verdict ("
                     + e(", ".join(o["sensitive_quantities"])) + ")")
    cov = o["coverage"]
    cov_txt = ("complete: {} sections, per zone {}".format(
        cov["sections"], ", ".join(f"{z}: {n}" for z, n in (cov["zones"] or {}).items()))
        if cov["ok"] else "SHORT — " + "; ".join(cov["shortfalls"]))
    rows = []
    for q in summ["quantities"]:
        cls = "pass" if q["pass"] else "fail"
        flag = "pass" if q["pass"] else "FAIL"
        if q.get("definition_sensitive"):
            flag += " · definition-sensitive"
        rows.append(f"<tr><td>{e(q['quantity'])}</td><td>{e(q['unit'] or '–')}</td><td class='n'>{q['n']}</td>"
                    f"<td class='n'>{_n(q['mean'], '+.3g')}</td><td class='n'>{_n(q['mean_limit'], '.3g')}</td>"
                    f"<td class='n'>{_n(q['mean_norm'], '+.2f')}</td>"
                    f"<td class='n'>{_n(q['std'], '.3g')}</td><td class='n'>{_n(q['std_limit'], '.3g')}</td>"
                    f"<td class='n'>{_n(q['std_norm'], '.2f')}</td>"
                    f"<td class='rv-q-{cls}' style='color:{'#1e7b34' if q['pass'] else '#b3261e'};"
                    f"font-weight:600'>{e(flag)}</td></tr>")
    qtable = ("<table class='rv-summary-q'><tr><th>quantity</th><th>unit</th><th>n</th>"
              "<th>mean D<sub>v</sub></th><th>mean limit</th><th>mean / limit</th>"
              f"<th>std D<sub>v</sub> (n−{o['std_ddof']})</th><th>std limit</th><th>std / limit</th>"
              "<th>verdict</th></tr>" + "".join(rows) + "</table>")
    supp = "".join(f"<li>{e(q['quantity'])} ({e(q['name'] or '')}): mean {_n(q['mean'], '+.3g')} "
                   f"{e(q['unit'] or '')}, std {_n(q['std'], '.3g')}, n {q['n']}</li>"
                   for q in summ["supplementary"])
    dg = summ["diagnosis"]
    diag = ("never run" if dg is None else
            f"run {dg['run']} ({e(dg['created_at'])} UTC): <b>{e(str(dg['verdict'] or '?'))}</b>, "
            f"top candidate {e(dg['top'] or '–')} explains {_n(dg['explained'], '.2f')}"
            + ("" if dg.get("current", True) else " — <b>the data changed since this run</b>"))
    ws = "".join(f"<li>workshop <b>{e(w['workshop'])}</b> ({e(w['status'])}{', blind' if w['blind'] else ''}): "
                 f"{w['plots']} plots of this configuration, {w['answers']} answers"
                 + ("" if w["yes_share"] is None else f", {w['yes_share']:.0%} “validated”")
                 + "</li>"
                 for w in summ["workshops"]) or "<li>no workshop shows this configuration</li>"
    links = " · ".join(f"<a class='rv-evidence-link' href='{e(url, quote=True)}' target='_blank' "
                       f"rel='noopener'>{e(PAGE_TITLES.get(name, name))}</a>"
                       for name, url in summ["links"].items())
    earlier = "".join(
        f"<li>sign-off {so['id']} <b>{e(status_label(so['status']))}</b>: {e(so['decision_text'])} by "
        f"{e(so['printed_name'])}, {e(so['signed_at_utc'])} UTC"
        + (CONTRARY_TAG if so["contrary_to_objective"] else "") + "</li>"
        for so in summ["signoffs"]) or "<li>none</li>"
    return (
        "<div class='rv-summary' style='font-size:13px'>"
        "<style>.rv-summary table{border-collapse:collapse}.rv-summary td,.rv-summary th{border:1px solid #ccd;"
        "padding:2px 6px}.rv-summary th{background:#eef1f6}.rv-summary td.n{text-align:right;"
        "font-variant-numeric:tabular-nums}.rv-mark{background:#e0a030;color:#1b1b1b;padding:1px 5px;"
        "border-radius:3px;font-weight:600}</style>"
        f"<h3 style='margin:4px 0'>What you sign: {e(summ['campaign'])} / {e(summ['configuration'])}</h3>"
        f"<div class='rv-objective' style='font-size:16px'>Objective verdict (DynoTRAIN, EN 14363): "
        f"<b style='color:{colour}'>{e(o['verdict'])}</b></div>"
        + "".join(f"<div>{m}</div>" for m in marks)
        + f"<div>Coverage: {e(cov_txt)}</div>{qtable}"
        + (f"<div>Supplementary results (no limits, not part of the verdict):<ul>{supp}</ul></div>" if supp else "")
        + f"<div>Newest diagnosis: {diag}</div><div>Workshops:<ul>{ws}</ul></div>"
        f"<div>Evidence pages: {links}</div><div>Earlier sign-offs of this configuration:<ul>{earlier}</ul></div>"
        "</div>")


class SignoffPage(PageBase):
    name_ = "signoff"

    def __init__(self, app: AppState, **params):
        super().__init__(app, **params)
        # no default decision: the reviewer chooses one (a preset "validated" was signed
        # by whoever did not look)
        self.decision = pn.widgets.Select(name="Decision (choose one)", options={
            NO_DECISION: "", "validated": "validated", "validated with restrictions": "restricted",
            "not validated": "not-validated"}, value="", width=300, css_classes=["rv-decision"])
        self.restrictions = pn.widgets.TextAreaInput(name="Restrictions (required for 'with restrictions')",
                                                     height=70, css_classes=["rv-restrictions"])
        self.statement = pn.widgets.TextAreaInput(name="Statement", height=90,
                                                  css_classes=["rv-statement"])
        self.justification = pn.widgets.TextAreaInput(
            name="Justification (required when the decision contradicts the objective verdict)",
            height=90, css_classes=["rv-justification"])
        self.contrary_note = pn.pane.HTML("", sizing_mode="stretch_width",
                                          css_classes=["rv-contrary-note"])
        self.password = pn.widgets.PasswordInput(name="Your password (signature)", width=260,
                                                 css_classes=["rv-sign-password"])
        self.sign_btn = pn.widgets.Button(name="Sign", button_type="primary", width=160,
                                          css_classes=["rv-sign"])
        self.sign_btn.on_click(lambda e: self.sign(dispatch=make_dispatch()))
        self.refusal = pn.pane.HTML("", sizing_mode="stretch_width", css_classes=["rv-signoff-refusal"])
        self.summary: dict | None = None
        self.decision.param.watch(lambda e: self._show_contrary(), ["value"])

    def _show_contrary(self) -> None:
        reason = (self.summary or {}).get("contrary_if", {}).get(self.decision.value)
        self.contrary_note.object = (
            f"<div class='rv-contrary-warning' style='background:#fdecea;color:#8a1f11;padding:6px 8px;"
            f"border-radius:4px'><b>Contrary to the objective verdict</b>: {html.escape(reason)}. "
            "Write your justification; the sign-off is stored and shown with this mark.</div>"
            if reason else "")

    def show_refusal(self, text: str) -> None:
        """A refusal next to the form (and in the status line), escaped."""
        self.refusal.object = (
            "<div class='rv-refusal' role='alert' style='background:#fdecea;color:#8a1f11;"
            f"border-left:4px solid #b3261e;padding:6px 8px;margin:4px 0'><b>Not signed.</b> "
            f"{html.escape(text)}</div>" if text else "")
        if text:
            self.app.set_status(f"sign-off refused: {text}", "error")

    def precheck(self) -> str:
        """The refusal the form's values get before anything is sent ("" when none): no
        decision chosen, or a contrary decision without a justification. The server checks
        the same rules again (``railval.db.signoff.create``)."""
        decision = self.decision.value
        if not decision:
            return ("Choose a decision: validated, validated with restrictions or not validated. "
                    "There is no default.")
        reason = (self.summary or {}).get("contrary_if", {}).get(decision)
        if reason and not (self.justification.value or "").strip():
            return refusal_text(f"justification: {reason}; needs a justification")
        return ""

    def sign(self, dispatch=None, background: bool = True):
        """Run the signing as a background job (the validation may take seconds); a form
        the rules refuse is refused next to the form, without a job."""
        app = self.app
        if not app.guard("signoff.create"):
            return None
        problem = self.precheck()
        self.show_refusal(problem)
        if problem:
            self.password.value = ""  # the password is typed again for every attempt
            return None
        password, self.password.value = self.password.value, ""
        campaign, config = app.campaign, app.configuration
        decision, restrictions, statement, justification = (
            self.decision.value, self.restrictions.value, self.statement.value,
            self.justification.value)
        show = dispatch or (lambda fn: fn())
        username = app.principal.username
        database = app.backend.database

        def work(progress):
            progress(0.1, "checking the password and building the evidence")
            try:
                return signoff_service.sign(database, username, password, campaign, config,
                                            decision=decision, restrictions=restrictions,
                                            statement=statement, justification=justification,
                                            source="web")
            except RailvalError as exc:  # a refusal: next to the form, in the page's words
                text = refusal_text(str(exc))
                show(lambda: self.show_refusal(text))
                raise signoff_service.SignoffRefused(text) from None

        def done(rec):
            self.restrictions.value = ""
            self.statement.value = ""
            self.justification.value = ""
            self.decision.value = ""
            self.refusal.object = ""
            mark = " — CONTRARY TO THE OBJECTIVE VERDICT" if rec["contrary_to_objective"] else ""
            app.set_status(f"sign-off {rec['id']} recorded: {campaign}/{config} "
                           f"{rec['decision_text']}{mark}", "success")
            self._stale = True
            self.safe_refresh()
        return app.run_job("sign-off", work, done, dispatch=dispatch, background=background,
                           action="signoff.create")

    def items(self):
        return signoff_service.records(self.app.backend.database, self.app.campaign)

    def load_summary(self) -> dict | None:
        if self.app.campaign is None or self.app.configuration is None:
            return None
        return signoff_service.summary_of(self.app.backend.database, self.app.campaign,
                                          self.app.configuration)

    def refresh(self) -> None:
        items = self.items()
        objs: list = []
        if self.app.allowed("signoff.create") and self.app.configuration is not None:
            self.summary = self.load_summary()
            self._show_contrary()
            objs.append(pn.pane.HTML(summary_html(self.summary), sizing_mode="stretch_width",
                                     css_classes=["rv-signoff-summary"]))
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
                    self.decision, self.contrary_note,
                    self.restrictions, self.statement, self.justification,
                    pn.Row(self.password, self.sign_btn), self.refusal]
        if not items:
            objs.append(message(f"No sign-off of campaign {self.app.campaign!r} yet."))
        else:
            df = pd.DataFrame([{"id": d["id"], "configuration": d["configuration"],
                                "status": status_label(st.status), "decision": d["decision_text"],
                                "against objective": ("CONTRARY" if d["contrary_to_objective"]
                                                      else "agrees"),
                                "signed by": d["printed_name"], "UTC": d["signed_at_utc"],
                                "evidence": d["evidence_sha256"][:16] + "…"} for d, st in items])
            objs.append(html_table(df, "rv-signoff-table"))
            objs += [signoff_card(d, st.status, st.reasons) for d, st in reversed(items)]
        self.body.objects = objs
