"""Reports as files: HTML written as is, PDF printed by headless Chromium
(``chromium --headless --print-to-pdf``), the browser the app is tested with. When no Chromium
is found a :class:`ReportError` says so and which paths were searched. The one writer of the
validation report (:mod:`railval.app.report`) and the audit report
(:mod:`railval.app.audit_report`).
"""

from __future__ import annotations

import os
import shutil
import subprocess
import tempfile
from pathlib import Path

from railval.core.errors import RailvalError

#: where Chromium is looked for, in this order
CHROMIUM_CANDIDATES = ("/usr/bin/chromium", "chromium", "chromium-browser", "google-chrome")
#: flags that let Debian's Chromium run headless in containers and CI
CHROMIUM_ARGS = ("--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
                 "--disable-background-networking", "--disable-component-update", "--disable-sync")
PDF_TIMEOUT_S = 120


class ReportError(RailvalError):
    """The report could not be produced (e.g. no browser for the PDF)."""


def write_html_or_pdf(document: str, path: str | os.PathLike, what: str = "report") -> Path:
    """Write an HTML document as ``.html`` or, printed by headless Chromium, as ``.pdf``
    (chosen by the extension); the one writer of the validation and audit reports."""
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix in (".html", ".htm"):
        path.write_text(document, encoding="utf-8")
    elif suffix == ".pdf":
        path.write_bytes(html_to_pdf(document))
    else:
        raise ReportError(f"{what} file {path}: extension must be .html or .pdf, got {suffix or '(none)'}")
    return path


def find_chromium() -> str:
    for c in CHROMIUM_CANDIDATES:
        p = c if os.path.isabs(c) else shutil.which(c)
        if p and os.path.exists(p):
            return p
    raise ReportError(f"PDF needs headless Chromium; none found among {', '.join(CHROMIUM_CANDIDATES)} "
                      "(install Debian's `chromium`, or write .html)")


def html_to_pdf(document: str, timeout_s: float = PDF_TIMEOUT_S) -> bytes:
    """Print an HTML document to PDF with headless Chromium (A4, background colours kept)."""
    exe = find_chromium()
    with tempfile.TemporaryDirectory(prefix="railval-report-") as tmp:
        src = Path(tmp) / "report.html"
        out = Path(tmp) / "report.pdf"
        src.write_text(document, encoding="utf-8")
        cmd = [exe, *CHROMIUM_ARGS, f"--user-data-dir={tmp}/profile", "--no-pdf-header-footer",
               "--print-to-pdf-no-header", f"--print-to-pdf={out}", src.as_uri()]
        try:
            proc = subprocess.run(cmd, capture_output=True, timeout=timeout_s, check=False)
        except subprocess.TimeoutExpired as exc:
            raise ReportError(f"Chromium did not print the PDF within {timeout_s:g} s") from exc
        if not out.exists() or out.stat().st_size == 0:
            raise ReportError(f"Chromium ({exe}) produced no PDF (exit {proc.returncode}): "
                              f"{proc.stderr.decode(errors='replace')[-400:]}")
        return out.read_bytes()
