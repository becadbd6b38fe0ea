"""The engineers' web app: template, navigation, pages (docs/design.md §1, §3–§7).

``build_app(database)`` returns one session's Panel template (each browser session gets its
own :class:`railval.app.state.AppState`); ``serve(database, ...)`` serves it with ``pn.serve``,
together with the review-workshop pages (``/workshops``, ``/review/…``) of
:mod:`railval.app.workshop_web` (package) as plain Tornado handlers.
Pages are one module each under ``app/pages``; their state lives in ``app/state/`` (one module per page).
"""

from __future__ import annotations

import functools
import html
import socket
import time
import urllib.request
from collections.abc import Iterator, Mapping
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import panel as pn
import param
from bokeh.settings import settings as bokeh_settings
from panel.io import resources as panel_resources
from panel.reactive import ReactiveHTML

from railval.app import security
from railval.app.auth import SESSION_MAX_AGE_S, RailvalAuth, check_startup, cookie_secret
from railval.app.health import HealthHandler, admin_only
from railval.app.navigation import NAV_CSS, jobs_html, nav_items
from railval.app.pages.audit import AuditPage
from railval.app.pages.compare import ComparePage
from railval.app.pages.dashboard import DashboardPage
from railval.app.pages.diagnose import DiagnosePage
from railval.app.pages.importer import ImportPage
from railval.app.pages.metrics import MetricsPage
from railval.app.pages.overview import OverviewPage
from railval.app.pages.report import ReportPage
from railval.app.pages.signoff import SignoffPage
from railval.app.services.web_import import MAX_UPLOAD_MB
from railval.app.state import PAGE_TITLES, AppState, Backend
from railval.app.state.jobs import jobs_of
from railval.app.upkeep import freeze_startup_objects, release_memory
from railval.app.workshop_web import routes
from railval.core.errors import InvalidParameter
from railval.core.roles import PAGE_ACTIONS, Principal

STATIC = Path(__file__).resolve().parent.parent / "static"
CSS_FILE = STATIC / "railval.css"
ACCENT = "#0b5394"


def no_math_typesetting() -> None:
    """User text is shown as text: no pane typesets ``$$…$$``. Panel's Markdown panes (and
    ``Alert``, a Markdown pane) typeset it with MathJax by default, and MathJax's ``\\href``
    makes links — a campaign description ``$$\\href{javascript:…}{the report}$$`` was a link
    that ran script in the app's origin when clicked (docs/security.md, threat model). The
    Markdown pane's ``disable_math`` default is set (``HTML`` has it on already), and the
    pages' resources are built without Bokeh's MathJax bundle: Panel adds it whenever a page
    holds an HTML model, Bokeh when a model asks for math; both checks answer no. (Markdown's
    model does not take ``disable_math``: without the bundle nothing typesets there.)"""
    pn.pane.Markdown.param.disable_math.default = True
    panel_resources._panel_use_mathjax = lambda roots: False
    panel_resources._use_mathjax = lambda roots: False


security.use_local_fonts()
no_math_typesetting()
# browser_info off: nothing reads it, and it is one more model and document root per session
pn.extension("tabulator", notifications=False, design="native", sizing_mode="stretch_width",
             browser_info=False)

PAGE_CLASSES = {
    "overview": OverviewPage, "compare": ComparePage, "dashboard": DashboardPage,
    "metrics": MetricsPage, "diagnose": DiagnosePage, "report": ReportPage,
    "signoff": SignoffPage, "audit": AuditPage, "import": ImportPage,
}


class DeniedPage(pn.viewable.Viewer):
    """What a page the session's user may not open shows (it is never built)."""

    def __init__(self, app: AppState, name: str):
        super().__init__()
        self.name_ = name
        self.view = pn.Column(pn.pane.Markdown(f"## {html.escape(PAGE_TITLES[name])}"),
                              pn.pane.Alert(html.escape(app.denial(PAGE_ACTIONS[name])),
                                            alert_type="danger", css_classes=["rv-denied"]),
                              sizing_mode="stretch_width")

    def show(self) -> None:
        pass

    def __panel__(self):
        return self.view


@functools.cache
def _css_text() -> str | None:
    return CSS_FILE.read_text(encoding="utf-8") if CSS_FILE.exists() else None


def _css() -> list[str]:
    """The app's stylesheet, read once per process and shared by every session."""
    text = _css_text()
    return [text] if text is not None else []


#: colours of the status message per level (background, text, border: Bootstrap 4's alerts,
#: the look of ``pn.pane.Alert`` that the status area used before)
STATUS_COLOURS = {"info": ("#d1ecf1", "#0c5460", "#bee5eb"), "success": ("#d4edda", "#155724", "#c3e6cb"),
                  "warning": ("#fff3cd", "#856404", "#ffeeba"), "error": ("#f8d7da", "#721c24", "#f5c6cb")}


def status_markup(status: str, level: str) -> str:
    """The status message as markup (escaped), coloured by its level; "Ready." when empty."""
    if not status:
        return "<div class='rv-status' style='color:#666'>Ready.</div>"
    bg, fg, border = STATUS_COLOURS[level]
    return (f"<div class='rv-status rv-status-{level}' role='status' style='background:{bg};"
            f"color:{fg};border:1px solid {border};border-radius:4px;padding:8px 10px'>"
            f"{html.escape(status)}</div>")


def status_area(app: AppState) -> pn.Column:
    """Status message (level-coloured) and a progress bar with a cancel button while a job
    runs. The message is one HTML pane rewritten on change; the bar and the button are made
    when the session's first job starts (most sessions never run one)."""
    pane = pn.pane.HTML(status_markup(app.status, app.status_level), sizing_mode="stretch_width",
                        margin=(5, 5))
    area = pn.Column(pane, sizing_mode="stretch_width")
    job_widgets: list[Any] = []

    def message(*_) -> None:
        pane.object = status_markup(app.status, app.status_level)

    def sync(*_) -> None:
        if not job_widgets:
            if not app.busy:
                return
            bar = pn.indicators.Progress(value=0, max=100, sizing_mode="stretch_width", visible=False,
                                         css_classes=["rv-progress"], bar_color="info")
            cancel = pn.widgets.Button(name="Cancel job", button_type="warning", visible=False,
                                       width=120, css_classes=["rv-cancel"])
            cancel.on_click(lambda _: app.cancel_job())
            job_widgets.extend([bar, cancel])
            area.extend(job_widgets)
        bar, cancel = job_widgets
        bar.visible = cancel.visible = app.busy
        bar.value = round(app.progress * 100)
    app.param.watch(message, ["status", "status_level"])
    app.param.watch(sync, ["busy", "progress"])
    sync()
    return area


class Pages(Mapping[str, Any]):
    """The pages of one session, each built on first access (its view, figures and
    watchers cost server time and JavaScript models only once the user opens it)."""

    def __init__(self, app: AppState):
        self.app = app
        self._built: dict[str, Any] = {}

    def __getitem__(self, name: str) -> Any:
        if name not in self._built:
            cls = PAGE_CLASSES[name]  # KeyError for unknown names
            self._built[name] = (cls(self.app) if self.app.page_allowed(name)
                                 else DeniedPage(self.app, name))
        return self._built[name]

    def __iter__(self) -> Iterator[str]:
        return iter(PAGE_CLASSES)

    def __len__(self) -> int:
        return len(PAGE_CLASSES)

    def built(self) -> list[str]:
        """Names of the pages built so far."""
        return list(self._built)


def user_box(app: AppState) -> pn.pane.HTML:
    """Who is signed in (escaped) with the sign-out link, or the open-mode note."""
    p = app.principal
    if p.open_mode:
        return pn.pane.HTML(
            "<div class='rv-open-mode' style='background:#fff4e5;border:1px solid #e0a030;"
            "padding:6px 8px;border-radius:4px;font-size:13px'><b>Open single-user mode</b>: "
            "no user of this database has a password, so every request from this computer "
            "(loopback only) acts as the local user and nothing asks for a password. Add a "
            "user with a password (<code>railval user add NAME --role admin</code>) to "
            "require sign-in.</div>",
            sizing_mode="stretch_width")
    roles = ", ".join(sorted(p.roles)) or "no role"
    return pn.pane.HTML(
        f"<div class='rv-user' style='font-size:13px'>Signed in as <b>{html.escape(p.printed_name)}"
        f"</b> ({html.escape(p.username)}; {html.escape(roles)}) · "
        f"<a href='/logout' class='rv-logout'>Sign out</a></div>", sizing_mode="stretch_width")


class NavBar(ReactiveHTML):
    """The one navigation in the app's header: the bar of
    :func:`railval.app.navigation.nav_html` (same elements, classes and :data:`NAV_CSS
    <railval.app.navigation.NAV_CSS>` as on the workshop pages), built in the browser from
    :func:`~railval.app.navigation.nav_items` with text nodes only (no markup from the
    server). An app page's entry is a button that sets :attr:`page` (the session switches
    page without reloading); the workshop areas are links. A ReactiveHTML component: its
    scripts run under the app's content security policy (no ``blob:`` module)."""

    items = param.List(default=[], doc="the entries (nav_items)")
    page = param.String(default="", doc="the page the user clicked")

    _template = '<div id="bar" class="rv-navbox"></div>'
    _scripts = {
        "render": """bar.addEventListener('click', (e) => {
  const b = e.target.closest('button[data-page]');
  if (b) { data.page = b.dataset.page; }
});
self.items();""",
        "items": """bar.textContent = '';
const nav = document.createElement('nav');
nav.className = 'rv-nav';
nav.setAttribute('aria-label', 'railval');
let areas = null;
for (const it of data.items) {
  const el = document.createElement(it.kind === 'page' ? 'button' : 'a');
  el.className = 'rv-nav-link' + (it.current ? ' rv-current' : '') + (it.kind === 'area' ? ' rv-area' : '');
  el.textContent = it.title;
  if (it.current) el.setAttribute('aria-current', 'page');
  if (it.kind === 'page') { el.type = 'button'; el.dataset.page = it.name; }
  else { el.href = it.href; }
  if (it.kind === 'area') {
    if (areas === null) { areas = document.createElement('span'); areas.className = 'rv-areas'; }
    areas.appendChild(el);
  } else { nav.appendChild(el); }
}
if (areas !== null) nav.appendChild(areas);
bar.appendChild(nav);""",
    }


def nav_bar(app: AppState) -> NavBar:
    """The header's navigation of ``app``'s user, the current page marked, kept in step
    with the session's page both ways."""
    bar = NavBar(items=nav_items(app.principal, app.page), page=app.page,
                 stylesheets=[NAV_CSS], sizing_mode="stretch_width", margin=(4, 10))

    def clicked(event) -> None:
        if event.new in PAGE_CLASSES and app.page_allowed(event.new):
            app.page = event.new

    def moved(*_) -> None:
        bar.items = nav_items(app.principal, app.page)
        bar.page = app.page
    bar.param.watch(clicked, ["page"])
    app.param.watch(moved, ["page"])
    return bar


def jobs_box(app: AppState) -> pn.pane.HTML:
    """The user's running and recently finished jobs (:func:`railval.app.state.jobs.jobs_of`),
    each with the link to its result — also those started before a reload or in another
    tab; refreshed every 2 s in a served session and whenever the status changes."""
    pane = pn.pane.HTML(jobs_html(jobs_of(app.principal.username)), stylesheets=[NAV_CSS],
                        css_classes=["rv-jobs-pane"], sizing_mode="stretch_width", margin=(0, 10))

    def refresh(*_) -> None:
        text = jobs_html(jobs_of(app.principal.username))
        if text != pane.object:
            pane.object = text
    app.param.watch(refresh, ["status", "busy"])
    doc = pn.state.curdoc
    if doc is not None and doc.session_context is not None:
        pn.state.add_periodic_callback(refresh, period=2000)
    return pane


def _session_args() -> dict[str, str]:
    """The query arguments of the session's page request (``/app?page=…&campaign=…``)."""
    args = getattr(pn.state, "session_args", None) or {}
    return {k: (v[0].decode("utf-8", "replace") if isinstance(v[0], bytes) else str(v[0]))
            for k, v in args.items() if v}


def select_from_query(app: AppState, args: Mapping[str, str]) -> None:
    """Open the page and select the campaign/configuration named in the URL's query, when
    they exist and the page is allowed (links of the navigation and the sign-off summary);
    anything else is ignored."""
    camp, conf, page = args.get("campaign"), args.get("configuration"), args.get("page")
    if camp and camp in (app.param.campaign.objects or []):
        app.campaign = camp
    if conf and conf in (app.param.configuration.objects or []):
        app.configuration = conf
    if page and page in PAGE_CLASSES and app.page_allowed(page):
        app.page = page


def _session_request() -> Any:
    """The request of the current Bokeh session (its cookies, headers and client address)."""
    ctx = pn.state.curdoc.session_context if pn.state.curdoc is not None else None
    return getattr(ctx, "request", None)


def session_principal(auth: Any) -> Principal | None:
    """The principal of the current Bokeh session, from its request's session cookie."""
    return auth.principal_of(_session_request())


def build_app(database: Any, page: str = "overview", principal: Principal | None = None,
              auth: Any = None) -> pn.template.FastListTemplate:
    """One session's app on ``database`` (a ``railval.db.engine.Database``); only the page shown
    is built (:class:`Pages`), the others when first opened. ``auth``: the server's
    :class:`railval.app.auth.RailvalAuth` (the session's user comes from its cookie); else
    ``principal`` (tests), else open single-user mode."""
    recheck = None
    if auth is not None:
        principal = session_principal(auth)
        if principal is None:  # the cookie expired between the page and its websocket
            return pn.Column(pn.pane.Alert("Your session has ended. <a href='/login'>Sign in</a>.",
                                           alert_type="warning"))
        # access ends at the next action: the user is re-read from this cookie (docs/security.md)
        recheck = functools.partial(auth.principal_of, _session_request())
    app = AppState(Backend(database), principal=principal, recheck=recheck)
    if page != "overview":
        app.page = page
    select_from_query(app, _session_args())
    pages = Pages(app)
    allowed_pages = app.pages_allowed()
    if not allowed_pages:  # e.g. a panelist: no app page, only their workshop areas
        return pn.Column(pn.Row(nav_bar(app), styles={"background": ACCENT}), user_box(app),
                         jobs_box(app), css_classes=["rv-no-pages"], sizing_mode="stretch_width")
    main = pn.Column(sizing_mode="stretch_width", css_classes=["rv-main"])

    def show(*_):
        view = pages[app.page]
        view.show()  # content first, so the page arrives in the browser whole
        main.objects = [view]
    app.param.watch(show, ["page"])
    show()
    sidebar = [
        user_box(app),
        pn.widgets.Select.from_param(app.param.campaign, name="Campaign"),
        pn.widgets.Select.from_param(app.param.configuration, name="Configuration"),
        jobs_box(app),
        pn.layout.Divider(),
        status_area(app),
    ]
    template = pn.template.FastListTemplate(
        # the sidebar as one root: the template adds every item as a root of the document, and
        # Bokeh walks all of the document's models again for each root (Document.add_root)
        title="railval", sidebar=[pn.Column(*sidebar, sizing_mode="stretch_width", margin=0)], main=[main],
        header=[nav_bar(app)],
        accent=ACCENT, header_background=ACCENT, sidebar_width=300, main_layout=None,
        raw_css=_css(), theme_toggle=False,
        # no busy spinner: Panel keeps every session's spinner in one process-wide list and
        # sets all of them on any session's callback (panel/io/state.py, _update_busy), a
        # websocket message to every open session each time another one's jobs list refreshes
        busy_indicator=None,
    )
    template.railval_state = app  # for tests and the benchmark
    template.railval_pages = pages
    return template


def serve(database: Any, port: int = 5006, address: str = "127.0.0.1", show: bool = False,
          threaded: bool = False, allow_websocket_origin: list[str] | None = None,
          cookie_secret_file: str | None = None, session_max_age_s: int | None = None,
          behind_proxy: bool = False, admin: bool = False, **kw: Any):
    """Serve the app at ``http://address:port/`` (``pn.serve``) behind the sign-in of
    :mod:`railval.app.auth`; returns the server. Raises
    :class:`railval.app.auth.StartupRefused` when the database has no users and ``address``
    is not a loopback address. ``behind_proxy``: take the client address from the proxy's
    X-Forwarded-For / X-Real-Ip headers (Tornado ``xheaders``), so the sign-in rate limit per
    address counts clients, not the proxy; only behind a proxy that sets these headers.
    Every response carries the security headers of :mod:`railval.app.security`; every
    ``POST`` of the sign-in and workshop pages must come from this server's origin and carry
    the anti-forgery token bound to the session (Tornado ``xsrf_cookies`` with
    :class:`railval.app.security.SessionBoundXsrf` on the handlers); Bokeh
    session ids are signed (a forged one is refused); websockets are accepted only from
    ``allow_websocket_origin`` — never from any origin (``*``). ``GET /health`` reports whether
    this process reaches its database; ``admin``: Panel's admin page at ``/admin``, for users
    with the ``admin`` role only (:mod:`railval.app.health`)."""
    origins = allow_websocket_origin or [f"{address}:{port}", f"localhost:{port}", f"127.0.0.1:{port}"]
    if any(o.strip() == "*" or o.strip().startswith("*:") for o in origins):
        # checked before anything else starts: '*' lets any web site drive a session
        raise InvalidParameter("--allow-websocket-origin '*' would let any web site drive a "
                               "session (cross-site websocket hijacking); name the host[:port] "
                               "the users' browsers connect to")
    check_startup(database, address)
    secret, _origin = cookie_secret(cookie_secret_file)
    auth = RailvalAuth(database, secret, max_age_s=session_max_age_s or SESSION_MAX_AGE_S)
    extra = (list(kw.pop("extra_patterns", [])) + auth.extra_patterns() + routes(database, auth)
             + [(r"/health", HealthHandler, {"database": database})])
    # Bokeh checks every model of a new session's document for layout warnings, which it only
    # logs (bokeh.application.Application.initialize_document, setting ``validate_doc``): 11 %
    # of a session's build in a profile (docs/app.md, "Cheap sessions"); off in served processes
    bokeh_settings.perform_document_validation.set_value(False)
    if release_memory not in getattr(pn.state, "_on_session_destroyed", []):
        pn.state.on_session_destroyed(release_memory)
    if admin:
        pn.config.authorize_callback = admin_only(lambda: session_principal(auth))
        kw["admin"] = True
    # the Import page's zip travels base64-encoded in one websocket message (4/3 of its size)
    kw.setdefault("websocket_max_message_size", (MAX_UPLOAD_MB * 4 // 3 + 8) * 1024 * 1024)
    if behind_proxy:
        kw["http_server_kwargs"] = {**kw.get("http_server_kwargs", {}), "xheaders": True}
    if not threaded:  # a process that serves (railval serve); not a test serving in a thread
        freeze_startup_objects()
    return pn.serve({"app": lambda: build_app(database, auth=auth)}, port=port, address=address,
                    show=show, threaded=threaded, title="railval", allow_websocket_origin=origins,
                    static_dirs={"railval-static": str(STATIC)} if STATIC.exists() else {},
                    auth_provider=auth, cookie_secret=secret,
                    extra_patterns=extra, transforms=security.transforms(),
                    sign_sessions=True, secret_key=security.session_secret().encode(),
                    xsrf_cookies=True, xsrf_cookie_kwargs=security.XSRF_COOKIE, **kw)


def free_port() -> int:
    """A free TCP port on the loopback interface."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@contextmanager
def served(database: Any, timeout_s: float = 60.0, **kw: Any) -> Iterator[str]:
    """Serve the app on a free loopback port in a background thread (tests, benchmarks);
    yields its URL once it answers 200 (the sign-in page when the database has users),
    stops the server afterwards."""
    port = free_port()
    server = serve(database, port=port, address="127.0.0.1", threaded=True, **kw)
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
