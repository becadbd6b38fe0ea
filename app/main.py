"""The engineers' web app: template, navigation, pages (docs/design.md §1, §3–§7).

``build_app(database)`` returns one session's Panel template (each browser session gets its
own :class:`railval.app.state.AppState`); ``serve(database, ...)`` serves it with ``pn.serve``,
together with the review-workshop pages (``/workshops``, ``/review/…``) of
:mod:`railval.app.workshop_web` as plain Tornado handlers.
Pages are one module each under ``app/pages``; their state lives in ``app/state/`` (one module per page).
"""

from __future__ import annotations

import html
import socket
import time
import urllib.request
from collections.abc import Iterator, Mapping
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import panel as pn

from railval.app.pages.compare import ComparePage
from railval.app.pages.dashboard import DashboardPage
from railval.app.pages.diagnose import DiagnosePage
from railval.app.pages.metrics import MetricsPage
from railval.app.pages.overview import OverviewPage
from railval.app.pages.report import ReportPage
from railval.app.state import PAGE_TITLES, PAGES, AppState, Backend

STATIC = Path(__file__).resolve().parent.parent / "static"
CSS_FILE = STATIC / "railval.css"
ACCENT = "#0b5394"

pn.extension("tabulator", notifications=False, design="native", sizing_mode="stretch_width")

PAGE_CLASSES = {
    "overview": OverviewPage, "compare": ComparePage, "dashboard": DashboardPage,
    "metrics": MetricsPage, "diagnose": DiagnosePage, "report": ReportPage,
}


def _css() -> list[str]:
    return [CSS_FILE.read_text(encoding="utf-8")] if CSS_FILE.exists() else []


def status_area(app: AppState) -> pn.Column:
    """Status message (level-coloured) and a progress bar shown while a job runs."""
    kinds = {"info": "info", "success": "success", "warning": "warning", "error": "danger"}

    def alert(status: str, level: str) -> Any:
        if not status:
            return pn.pane.Markdown("Ready.", styles={"color": "#666"}, css_classes=["rv-status"])
        return pn.pane.Alert(html.escape(status), alert_type=kinds[level], css_classes=["rv-status"],
                             sizing_mode="stretch_width", margin=(5, 5))

    bar = pn.indicators.Progress(value=0, max=100, sizing_mode="stretch_width", visible=False,
                                 css_classes=["rv-progress"], bar_color="info")

    def sync(*_):
        bar.visible = app.busy
        bar.value = round(app.progress * 100)
    app.param.watch(sync, ["busy", "progress"])
    return pn.Column(pn.bind(alert, app.param.status, app.param.status_level), bar,
                     sizing_mode="stretch_width")


class Pages(Mapping[str, Any]):
    """The pages of one session, each built on first access (its view, figures and
    watchers cost server time and JavaScript models only once the user opens it)."""

    def __init__(self, app: AppState):
        self.app = app
        self._built: dict[str, Any] = {}

    def __getitem__(self, name: str) -> Any:
        if name not in self._built:
            self._built[name] = PAGE_CLASSES[name](self.app)  # KeyError for unknown names
        return self._built[name]

    def __iter__(self) -> Iterator[str]:
        return iter(PAGE_CLASSES)

    def __len__(self) -> int:
        return len(PAGE_CLASSES)

    def built(self) -> list[str]:
        """Names of the pages built so far."""
        return list(self._built)


def build_app(database: Any, page: str = "overview") -> pn.template.FastListTemplate:
    """One session's app on ``database`` (a ``railval.db.engine.Database``); only the page shown
    is built (:class:`Pages`), the others when first opened."""
    app = AppState(Backend(database))
    if page != "overview":
        app.page = page
    pages = Pages(app)
    nav = pn.widgets.RadioButtonGroup(
        options={PAGE_TITLES[p]: p for p in PAGES}, value=app.page, orientation="vertical",
        color="light", sizing_mode="stretch_width", css_classes=["rv-nav"])
    nav.link(app, value="page", bidirectional=True)
    main = pn.Column(sizing_mode="stretch_width", css_classes=["rv-main"])

    def show(*_):
        view = pages[app.page]
        view.show()  # content first, so the page arrives in the browser whole
        main.objects = [view]
    app.param.watch(show, ["page"])
    show()
    sidebar = [
        pn.widgets.Select.from_param(app.param.campaign, name="Campaign"),
        pn.widgets.Select.from_param(app.param.configuration, name="Configuration"),
        pn.pane.Markdown("**Pages**", margin=(10, 10, 0, 10)),
        nav,
        pn.layout.Divider(),
        status_area(app),
    ]
    template = pn.template.FastListTemplate(
        title="railval — model validation (EN 14363)", sidebar=sidebar, main=[main],
        accent=ACCENT, header_background=ACCENT, sidebar_width=300, main_layout=None,
        raw_css=_css(), theme_toggle=False,
    )
    template.railval_state = app  # for tests and the benchmark
    template.railval_pages = pages
    return template


def serve(database: Any, port: int = 5006, address: str = "127.0.0.1", show: bool = False,
          threaded: bool = False, allow_websocket_origin: list[str] | None = None, **kw: Any):
    """Serve the app at ``http://address:port/`` (``pn.serve``); returns the server."""
    origins = allow_websocket_origin or [f"{address}:{port}", f"localhost:{port}", f"127.0.0.1:{port}"]
    from railval.app.workshop_web import routes

    extra = list(kw.pop("extra_patterns", [])) + routes(database)
    return pn.serve({"app": lambda: build_app(database)}, port=port, address=address, show=show,
                    threaded=threaded, title="railval", allow_websocket_origin=origins,
                    static_dirs={"railval-static": str(STATIC)} if STATIC.exists() else {},
                    extra_patterns=extra, **kw)


def free_port() -> int:
    """A free TCP port on the loopback interface."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@contextmanager
def served(database: Any, timeout_s: float = 60.0) -> Iterator[str]:
    """Serve the app on a free loopback port in a background thread (tests, benchmarks);
    yields its URL once it answers 200, stops the server afterwards."""
    port = free_port()
    server = serve(database, port=port, address="127.0.0.1", threaded=True)
    url = f"http://127.0.0.1:{port}/app"
    deadline = time.monotonic() + timeout_s
    try:
        while True:
            try:
                with urllib.request.urlopen(url, timeout=30) as resp:
                    if resp.status == 200:
                        break
            except OSError:
                if time.monotonic() > deadline:
                    raise
                time.sleep(0.1)
        yield url
    finally:
        server.stop()
        server.join(10)
