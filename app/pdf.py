"""Reports as files: HTML written as is, PDF printed by headless Chromium
(``chromium --headless --print-to-pdf``), the browser the app is tested with. When no Chromium
is found a :class:`ReportError` says so and which paths were searched. The one writer of the
validation report (:mod:`railval.app.report`) and the audit report
(:mod:`railval.app.audit_report`).
"""

from __future__ import annotations

import html
import os
import shutil
import subprocess
import tempfile
from pathlib import Path

from railval.core.errors import RailvalError

#: where Chromium is looked for, in this order
CHROMIUM_CANDIDATES = ("/usr/bin/chromium", "chromium", "chromium-browser", "google-chrome")
#: the omnibox popup's WebUI features: headless Chromium 156 builds the address bar's dropdown
#: as two hidden pages (``chrome://omnibox-popup.top-chrome``) for every new window — 1.0–1.8 s
#: of its own renderer's tasks per new browser context (six traced loads), on the cores the
#: served app and the page share (docs/app.md, "The browser's own address bar")
OMNIBOX_WEBUI_FEATURES = ("WebUIOmniboxPopup", "WebUIOmniboxFullPopup", "WebUIOmniboxAimPopup")
#: the features Playwright turns off in the browsers it starts (its ``chromiumSwitches``,
#: read off Playwright 1.65.2): Chromium reads only the last ``--disable-features`` switch,
#: and Playwright puts its own before the caller's, so railval's switch repeats them
#: (``tests/test_browser_flags.py`` reads both off ``chrome://version``)
PLAYWRIGHT_OFF_FEATURES = (
    "AvoidUnnecessaryBeforeUnloadCheckSync", "DestroyProfileOnBrowserClose", "HttpsUpgrades",
    "HttpsFirstBalancedModeAutoEnable", "LensOverlay", "MediaRouter", "PaintHolding",
    "ThirdPartyStoragePartitioning", "AvoidCorsURLLoaderRestartOnRedirect", "TcpPortRandomizationWin",
    "OptimizationHints", "NetworkTimeServiceQuerying", "AimEnabled", "PreconnectToSearch",
    "msForceBrowserSignIn", "msEdgeUpdateLaunchServicesPreferredVersion")
#: flags that let Debian's Chromium run headless in containers and CI, without the omnibox
#: popup's WebUI; the one list for the PDF printer, the benchmarks' and the tests' browsers
CHROMIUM_ARGS = ("--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
                 "--disable-background-networking", "--disable-component-update", "--disable-sync",
                 "--disable-features=" + ",".join((*PLAYWRIGHT_OFF_FEATURES, *OMNIBOX_WEBUI_FEATURES)))
PDF_TIMEOUT_S = 120

#: Print rules of the reports (appended to their CSS): A4 pages, and a wide table of class
#: ``blocks`` laid out as one block per row, each cell on its own line headed by its
#: ``data-label`` (its column's name) — so the PDF holds every field of the HTML, wrapped,
#: and pages break between and inside blocks as needed (the header row, class ``head``, is
#: left out: each line names its column). Ligatures are off so the PDF's text is the HTML's.
PRINT_CSS = """
@page { size: A4; margin: 14mm 12mm; }
@media print {
  body { margin: 0; font-size: 11px; font-variant-ligatures: none; }  /* fi, ff stay searchable text */
  td, th { overflow-wrap: break-word; }  /* a long word breaks only where it would overflow */
  td:last-child { overflow-wrap: anywhere; }  /* the free-text column gives way first */
  table.blocks, table.blocks tbody, table.blocks tr, table.blocks td { display: block; border: none;
    text-align: left; padding: 1px 0; }
  table.blocks tr.head { display: none; }
  table.blocks tr { border: 1px solid #ccc; margin: 0 0 8px; padding: 4px 8px; }
  table.blocks td:empty { display: none; }
  table.blocks td::before { content: attr(data-label) ": "; font-weight: bold; color: #444; }
}
"""


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


def block_cell(value: str, cls: str, label: str) -> str:
    """A cell of a ``blocks`` table (:data:`PRINT_CSS`): ``value`` (already escaped HTML)
    with its column's name as ``data-label``, the heading of its line in print."""
    return f"<td data-label='{html.escape(label, quote=True)}' class='{cls}'>{value}</td>"
