"""Import page (engineers, ``data.import``): upload a campaign folder as a zip file, or a
configuration's simulated files for the selected campaign; they are checked and stored by
the code of ``railval import`` (:mod:`railval.app.services.web_import`).

The file travels over the session's websocket (Bokeh's signed session, origin-checked), not
as a form post, so no cross-site form can submit it; the import runs as a background job of
the session with progress in the status area and is recorded in the audit trail as the
signed-in user.
"""

from __future__ import annotations

import html

import panel as pn

from railval.app.pages._common import PageBase, make_dispatch, message
from railval.app.services.web_import import MAX_UPLOAD_MB, import_configuration_zip, import_zip
from railval.app.state import AppState
from railval.core.errors import RailvalError
from railval.core.roles import PAGE_ACTIONS


class ImportPage(PageBase):
    name_ = "import"
    watch_app = ("revision",)

    def __init__(self, app: AppState, **params):
        super().__init__(app, **params)
        self.kind = pn.widgets.RadioButtonGroup(
            options={"A campaign": "campaign", "A configuration of the selected campaign":
                     "configuration"}, value="campaign", css_classes=["rv-import-kind"])
        self.file = pn.widgets.FileInput(accept=".zip", multiple=False, css_classes=["rv-import-file"],
                                         width=420)
        self.button = pn.widgets.Button(label="Check and import", color="primary", width=200,
                                        css_classes=["rv-import-go"])
        self.button.on_click(lambda _: self.start())
        self.result = pn.pane.HTML("", sizing_mode="stretch_width", css_classes=["rv-import-result"])

    def safe_refresh(self) -> None:  # an empty database is this page's normal case
        self._stale = False
        if not self.app.page_allowed(self.name_):
            self.body.objects = [message(self.app.denial(PAGE_ACTIONS[self.name_]), "danger")]
            return
        self.refresh()

    def refresh(self) -> None:
        self.body.objects = [
            pn.pane.Markdown(
                "Upload a **campaign folder as a zip file** (`campaign.json` at the top of the zip "
                f"or in its one top-level folder; format in docs/campaign-format.md). **Largest "
                f"upload: {MAX_UPLOAD_MB} MB** — import larger campaigns with `railval import DIR` "
                "on the server. Everything is checked before anything is stored (the same checks "
                "as `railval import`); a rejected upload stores nothing and the message names the "
                "file, field or line.", css_classes=["rv-import-help"]),
            pn.pane.Markdown(
                "Or a **configuration's simulated files** for the campaign selected in the sidebar: "
                "a zip holding `configuration.json` (one entry of campaign.json's "
                "`configurations`; its `parent` names a stored configuration) and the data files "
                "it lists — the same as `railval import DIR --into CAMPAIGN`."),
            self.kind,
            pn.Row(self.file, self.button),
            self.result,
        ]

    def _show(self, level: str, text_html: str) -> None:
        """The outcome under the upload box: success, refusal and a missing choice alike
        (the sidebar's status area says it too)."""
        style, role = _RESULT_STYLES[level]
        self.result.object = (f"<div class='rv-import-{level}' role='{role}' style='{style};"
                              "padding:8px 10px;border-radius:4px;font-size:14px;"
                              f"line-height:1.4'>{text_html}</div>")

    def _warn(self, text: str) -> None:
        self.app.set_status(f"Import: {text}", "warning")
        self._show("warning", html.escape(text[:1].upper() + text[1:]) + ".")

    def start(self) -> None:
        data, name = self.file.value, self.file.filename or "upload.zip"
        if not data:
            self._warn("choose a zip file first")
            return
        principal, database = self.app.principal, self.app.backend.database
        into = self.app.campaign if self.kind.value == "configuration" else None
        if self.kind.value == "configuration" and into is None:
            self._warn("no campaign selected to add the configuration to")
            return
        self.result.object = ""
        dispatch = make_dispatch()

        def work(progress):
            def step(done: int, total: int, what: str) -> None:
                progress(done / max(total, 1), f"checked {done}/{total} files ({what})")
            try:
                if into is not None:
                    return into, import_configuration_zip(database, principal, into, data, name,
                                                          progress=step)
                return import_zip(database, principal, data, name, progress=step), None
            except Exception as exc:  # shown under the upload box; the job reports it too
                why = (str(exc) if isinstance(exc, RailvalError) else
                       f"internal error ({type(exc).__name__}); the details are in the server log")
                dispatch(lambda: self._show("error", f"Not imported: {html.escape(why)}<br>"
                                            f"Nothing of {html.escape(name)} was stored."))
                raise

        def done(result: tuple[str, str | None]) -> None:
            campaign, conf = result
            self.file.value = None
            what = (f"configuration <b>{html.escape(conf)}</b> into campaign "
                    f"<b>{html.escape(campaign)}</b>" if conf else
                    f"campaign <b>{html.escape(campaign)}</b>")
            self._show("ok", f"Imported {what} from {html.escape(name)}.")
            self.app.refresh_campaigns()
            self.app.campaign = campaign
            if conf:
                self.app.reload_configurations(select=conf)

        self.app.run_job(f"Import {name}", work, on_done=done, dispatch=dispatch,
                         action="data.import")


#: look of the outcome under the upload box per level: (inline style, ARIA role); the pane
#: renders in its own shadow root, so the style travels with the element
_RESULT_STYLES = {
    "ok": ("color:#1b4d1b;background:#e8f5e9;border:1px solid #2e7d32", "status"),
    "warning": ("color:#5c4300;background:#fff8e1;border:1px solid #b8860b", "status"),
    "error": ("color:#7a1010;background:#fdecea;border:1px solid #c62828", "alert"),
}
