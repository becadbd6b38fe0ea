"""Report page: preview and download the HTML/PDF report of a configuration (``railval.app.report``,
the same builder as ``railval report``)."""

from __future__ import annotations

import html
import io

import panel as pn

from railval.app.pages._common import PageBase, bounded_input
from railval.app.security import plain_message
from railval.app.state import AppState, ReportState


def _slug(text: str) -> str:
    return "".join(c if c.isalnum() or c in "-_." else "_" for c in text)


class ReportPage(PageBase):
    name_ = "report"

    def __init__(self, app: AppState, **params):
        super().__init__(app, **params)
        self.state = ReportState(app)
        self.worst = bounded_input(self.state.param.worst_cases, "Worst cases plotted", app, width=160)
        self.html_dl = pn.widgets.FileDownload(callback=self._html_bytes, filename="report.html",
                                               label="Download HTML", color="primary", width=200)
        self.pdf_dl = pn.widgets.FileDownload(callback=self._pdf_bytes, filename="report.pdf",
                                              label="Download PDF", color="primary", width=200)
        self.preview = pn.pane.HTML("", sizing_mode="stretch_width", height=900)
        self.cards = pn.widgets.MultiChoice(name="Workshop plot cards in the report", options=[],
                                            placeholder="choose plots of this configuration's workshops",
                                            width=620)
        self.cards.param.watch(lambda e: setattr(self.state, "cards", list(e.new)), "value")
        self.state.param.watch(lambda *e: self._on_app_change(), ["worst_cases", "cards"])
        self._report = None

    def _build(self):
        self._report = self.state.build()
        return self._report

    def _html_bytes(self):
        if not self.app.guard("report.download"):
            return io.BytesIO(self.app.denial("report.download").encode("utf-8"))
        rep = self._report or self._build()
        return io.BytesIO(rep.html.encode("utf-8"))

    def _pdf_bytes(self):
        if not self.app.guard("report.download"):
            return io.BytesIO(self.app.denial("report.download").encode("utf-8"))
        rep = self._report or self._build()
        try:
            return io.BytesIO(rep.pdf_bytes())
        except Exception as exc:
            self.app.set_status(f"PDF failed: {plain_message(exc, 'PDF')}", "error")
            raise

    def refresh(self) -> None:
        choices = list(self.state.card_choices())
        if self.cards.options != choices:
            self.cards.options = choices
            kept = [c for c in self.state.cards if c in choices]
            if kept != list(self.cards.value):
                self.cards.value = kept
        rep = self._build()
        stem = f"railval-{_slug(rep.campaign)}-{_slug(rep.configuration)}"
        self.html_dl.filename = f"{stem}.html"
        self.pdf_dl.filename = f"{stem}.pdf"
        srcdoc = html.escape(rep.html, quote=True)
        self.preview.object = (f'<iframe title="report preview" srcdoc="{srcdoc}" '
                               'style="width:100%;height:880px;border:1px solid #ccc;background:#fff"></iframe>')
        self.body.objects = [
            pn.Row(self.worst, self.html_dl, self.pdf_dl),
            *([self.cards] if self.cards.options else []),
            pn.pane.Markdown(f"Evidence digest `{rep.digest[:16]}…` — generated {rep.generated_at}.",
                             styles={"color": "#555"}),
            self.preview,
        ]
