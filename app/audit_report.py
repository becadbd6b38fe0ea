"""The assessor's audit report, HTML and PDF (same builder style as :mod:`railval.app.report`).

Contents: the chain status (``railval audit verify`` without decoding blobs or recomputing
the validation — run the CLI for the full check), every sign-off with its printed name, UTC
time, meaning, decision, evidence hash and status (valid / stale, with what changed), the
timeline of changes per configuration, and who did what (actions per actor). Self-contained
HTML, every user-entered text escaped; the PDF is the HTML printed by headless Chromium.
"""

from __future__ import annotations

import datetime as dt
import os
from collections import Counter, defaultdict
from dataclasses import dataclass
from pathlib import Path

from railval.app.report import CSS, _esc, html_to_pdf, signoff_rows_html, write_html_or_pdf
from railval.app.services.audit import key_info, verify_database
from railval.app.services.overview import audit_and_signoffs


@dataclass
class AuditReport:
    html: str
    chain_status: str
    generated_at: str
    signoffs: int
    stale: int

    def write(self, path: str | os.PathLike) -> Path:
        return write_html_or_pdf(self.html, path, "audit report")

    def pdf_bytes(self) -> bytes:
        return html_to_pdf(self.html)


def build_audit_report(database) -> AuditReport:
    """Build the report from the database (chain checked quickly, sign-off statuses)."""

    check = verify_database(database, signals=False, full=False)
    chain_findings = [f for f in check.findings
                      if f.kind in ("chain", "head", "signature", "witness")]
    key = key_info(database)
    chain_status = ("intact" if not chain_findings else f"BROKEN — {chain_findings[0]}")
    now = dt.datetime.now(dt.UTC).strftime("%Y-%m-%d %H:%M:%S UTC")
    items, rows = audit_and_signoffs(database)
    stale = sum(1 for _, st in items if st.status != "valid")
    h: list[str] = [("<!DOCTYPE html><html lang='en'><head><meta charset='utf-8'>"
                     f"<title>railval audit report</title><style>{CSS}</style></head><body>"),
                    "<h1>Audit report</h1>",
                    (f"<table class='meta'><tr><td>database</td><td>{_esc(database.safe_url)}</td></tr>"
                     f"<tr><td>generated</td><td>{now}</td></tr>"
                     f"<tr><td>audit rows</td><td>{check.rows}</td></tr>"
                     f"<tr><td>head</td><td><code>{_esc(check.head_hash)}</code></td></tr>"
                     f"<tr><td>signing key (Ed25519)</td><td><code>{_esc(key['public_key'])}"
                     f"</code></td></tr><tr><td>key fingerprint (SHA-256)</td><td><code>"
                     f"{_esc(key['fingerprint'])}</code></td></tr>"
                     f"<tr><td>signed rows</td><td>{check.signed_rows} of {check.rows}"
                     f"</td></tr></table>")]
    ok = not chain_findings
    h.append(f"<div class='verdict {'ok' if ok else 'no'}'>Hash chain and signatures: "
             f"{_esc(chain_status)}</div>")
    for note in check.notes:
        h.append(f"<p class='note'>{_esc(note)}</p>")
    h.append("<p class='note'>This report checks the chain and each sign-off's evidence without "
             "decoding the stored signals. The complete check is <code>railval audit verify "
             "--checkpoint FILE</code>; offline: <code>railval audit verify --bundle DIR</code> "
             "(docs/audit.md).</p>")
    h.append(f"<h2>Sign-offs ({len(items)}, {stale} stale)</h2>")
    h.append(signoff_rows_html(items))
    # timeline per configuration
    h.append("<h2>Timeline of changes per configuration</h2>")
    per: dict[str, list[dict]] = defaultdict(list)
    for r in rows:
        if r["object"].startswith(("configuration:", "campaign:")):
            per[r["object"]].append(r)
    if not per:
        h.append("<p class='note'>No data change recorded.</p>")
    for obj in sorted(per):
        h.append(f"<h3>{_esc(obj)}</h3><table><tr><th>seq</th><th class='l'>UTC</th>"
                 "<th class='l'>actor</th><th class='l'>action</th><th class='l'>before</th>"
                 "<th class='l'>after</th><th class='l'>reason</th></tr>")
        for r in per[obj]:
            h.append(f"<tr><td>{r['seq']}</td><td class='l'>{_esc(r['at_utc'])}</td>"
                     f"<td class='l'>{_esc(r['actor'])}</td><td class='l'>{_esc(r['action'])}</td>"
                     f"<td class='l'><code>{_esc((r['before_sha256'] or '–')[:16])}</code></td>"
                     f"<td class='l'><code>{_esc((r['after_sha256'] or '–')[:16])}</code></td>"
                     f"<td class='l'>{_esc(r['reason'])}</td></tr>")
        h.append("</table>")
    # who did what
    h.append("<h2>Who did what</h2>")
    counts: Counter = Counter((r["actor"], r["action"]) for r in rows)
    actors = sorted({a for a, _ in counts})
    actions = sorted({b for _, b in counts})
    # one block per actor in print (class ``blocks`` of report.CSS): no column cut off on A4
    h.append("<table class='blocks'><tr class='head'><th class='l'>actor</th>"
             + "".join(f"<th>{_esc(a)}</th>" for a in actions) + "</tr>" + "".join(
                 f"<tr><td class='l' data-label='actor'>{_esc(a)}</td>" + "".join(
                     f"<td data-label='{_esc(b)}'>{counts.get((a, b), '') or ''}</td>" for b in actions) + "</tr>"
                 for a in actors) + "</table>")
    h.append("</body></html>")
    return AuditReport("".join(h), chain_status, now, len(items), stale)
