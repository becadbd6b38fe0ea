"""Shared pieces of the workshop pages: page frame, escaping, worker pool, sign-in (cookie,
principal, login/logout pages) and the base handlers."""

from __future__ import annotations

import base64
import hashlib
import hmac
import html
import json
import os
import secrets
import time
from concurrent.futures import ThreadPoolExecutor
from typing import Any
from urllib.parse import quote

import tornado.web
from tornado.ioloop import IOLoop

from railval.app.security import SessionBoundXsrf, with_xsrf
from railval.app.services import users as users_service
from railval.core import lazy
from railval.core.roles import Principal, allowed

#: deferred (railval.core.lazy): the navigation and the jobs list import the Panel app's side
#: (≈ 1 280 modules more than these pages), the app's sign-in 32; loaded on first use
navigation = lazy.module("railval.app.navigation")
jobs_state = lazy.module("railval.app.state.jobs")
app_auth = lazy.module("railval.app.auth")

COOKIE = "railval_user"
COOKIE_DAYS = 1
_SECRET = (os.environ.get("RAILVAL_COOKIE_SECRET") or secrets.token_hex(32)).encode()
#: database work runs here, off the server's event loop
_POOL = ThreadPoolExecutor(max_workers=4, thread_name_prefix="railval-workshop")

_CSS = """
body{font-family:'DejaVu Sans',Arial,sans-serif;margin:0;background:#f6f7f9;color:#1b1b1b}
header{background:#0b5394;color:#fff;padding:10px 20px;display:flex;gap:20px;align-items:center;flex-wrap:wrap}
header a{color:#fff} header .rv-home{text-decoration:none;font-size:18px}
.rv-who{font-size:14px} main{padding:16px 24px;max-width:1200px;margin:auto}
table{border-collapse:collapse;background:#fff} td,th{border:1px solid #ccd;padding:4px 8px;text-align:left}
th{background:#eef1f6} .num{text-align:right;font-variant-numeric:tabular-nums}
button,.btn{font-size:16px;padding:8px 18px;border-radius:4px;border:1px solid #889;background:#fff;cursor:pointer}
button.yes{background:#1a7f37;color:#fff;border-color:#1a7f37} button.no{background:#b42318;color:#fff;border-color:#b42318}
button.chosen{outline:4px solid #f5b700} .muted{color:#666} .err{color:#b42318;font-weight:bold}
#plot{width:100%;max-width:1000px;border:1px solid #ccd;background:#fff;display:block}
.bar{height:10px;background:#dde;border-radius:5px;overflow:hidden;min-width:120px}.bar>div{height:100%;background:#0b5394}
textarea{width:100%;max-width:990px;font-size:15px} .row{display:flex;gap:12px;align-items:center;margin:10px 0;flex-wrap:wrap}
code{background:#eef;padding:2px 4px;word-break:break-all}
.rv-changed:not(:empty){background:#fff4e5;border:1px solid #e0a030;padding:6px 10px;border-radius:4px;display:inline-block}
"""


def esc(value: Any) -> str:
    return html.escape("" if value is None else str(value), quote=True)


def _fmt(x: Any, digits: int = 2) -> str:
    """A number with ``digits`` decimals, a pair as ``a … b``, ``—`` for none (escaped)."""
    if x is None:
        return "—"
    if isinstance(x, (list, tuple)) and len(x) == 2:
        return f"{_fmt(x[0], digits)} … {_fmt(x[1], digits)}"
    try:
        return f"{float(x):.{digits}f}"
    except (TypeError, ValueError):
        return esc(x)


def _pct(x: Any) -> str:
    """A share in [0, 1] as per cent with one decimal, ``—`` for none."""
    return "—" if x is None else f"{100 * float(x):.1f} %"


def nav_html(principal: Principal | None, current: str = "") -> str:
    """The one navigation (:func:`railval.app.navigation.nav_html`, every entry a link) in
    the header, the signed-in user and the sign-out link; empty without a principal (a
    reviewer's personal link)."""
    if principal is None:
        return ""
    links = navigation.nav_html(principal, current)
    who = ("open single-user mode" if principal.open_mode else
           f"{principal.printed_name} ({', '.join(sorted(principal.roles)) or 'no role'})")
    out = "" if principal.open_mode else " <a class='rv-logout' href='/logout'>Sign out</a>"
    return (f"{links}"
            f"<span class='rv-who' style='margin-left:auto'>{esc(who)}{out}</span>")


def page(title: str, body: str, *, user: Principal | str = "", script: str = "",
         current: str = "") -> str:
    """A workshop page in the app's frame: the same header colour, title and navigation
    as the Panel app (:func:`nav_html` when ``user`` is a principal), then ``body``."""
    jobs = ""
    if isinstance(user, Principal):
        head = nav_html(user, current)
        jobs = f"<div id='rv-jobs-box'>{navigation.jobs_html(jobs_state.jobs_of(user.username))}</div>"
        script = _JOBS_JS + script
    else:
        head = (f"<span style='margin-left:auto'>{esc(user)}</span>" if user else "")
    return (f"<!doctype html><html lang='en'><head><meta charset='utf-8'>"
            f"<meta name='viewport' content='width=device-width,initial-scale=1'>"
            f"<title>railval — {esc(title)}</title><style>{_CSS}{navigation.NAV_CSS}</style></head><body>"
            f"<header><a class='rv-home' href='/app'><strong>railval</strong></a>"
            f"<span class='rv-title'>{esc(title)}</span>{head}</header><main>{jobs}{body}</main>"
            f"{'<script>' + script + '</script>' if script else ''}</body></html>")


#: keeps the "Your jobs" box of a workshop page current while one of the user's jobs runs
_JOBS_JS = r"""
(function () {
  const box = document.getElementById('rv-jobs-box');
  function esc(t) { const d = document.createElement('div'); d.textContent = String(t); return d.innerHTML.replace(/"/g, '&quot;').replace(/'/g, '&#39;'); }
  function line(j) {
    let what = j.state === 'running' ? (j.total ? (j.done || 0) + ' of ' + j.total : Math.round(100 * j.fraction) + ' %') : j.state;
    let t = j.title + ': ' + what + ' · ' + Math.round(j.elapsed_s) + ' s';
    if (j.state === 'failed' && j.error) t += ' — ' + (j.error.length <= 160 ? j.error : j.error.slice(0, 159) + '…');
    return t;
  }
  async function refresh() {
    try {
      const r = await fetch('/workshops/mine/jobs', {cache: 'no-store'});
      if (!r.ok) return;
      const jobs = (await r.json()).jobs;
      box.innerHTML = jobs.length ? '<div class="rv-jobs"><b>Your jobs</b><ul>' + jobs.map(j =>
        '<li class="rv-job rv-job-' + esc(j.state) + '" data-state="' + esc(j.state) + '"><a href="' +
        esc(j.link) + '">' + esc(line(j)) + '</a></li>').join('') + '</ul></div>' : '';
      if (jobs.some(j => j.state === 'running' || j.state === 'queued')) setTimeout(refresh, 1500);
    } catch (e) { setTimeout(refresh, 5000); }
  }
  if (box && box.querySelector('[data-state="running"], [data-state="queued"]')) setTimeout(refresh, 1500);
})();
"""


async def run(fn, *args, **kw):
    """Run blocking database work in the workshop thread pool."""
    return await IOLoop.current().run_in_executor(_POOL, lambda: fn(*args, **kw))


# -------------------------------------------------------------------------- sign-in
def _sign(value: str) -> str:
    mac = hmac.new(_SECRET, value.encode(), hashlib.sha256).hexdigest()
    return base64.urlsafe_b64encode(f"{value}|{mac}".encode()).decode()


def _unsign(cookie: str | None) -> tuple[str, float] | None:
    if not cookie:
        return None
    try:
        value, mac = base64.urlsafe_b64decode(cookie.encode()).decode().rsplit("|", 1)
    except (ValueError, UnicodeDecodeError):
        return None
    good = hmac.new(_SECRET, value.encode(), hashlib.sha256).hexdigest()
    if not hmac.compare_digest(mac, good):
        return None
    username, _, expiry = value.partition("|")
    try:
        if float(expiry) < time.time():
            return None
    except ValueError:
        return None
    return username, float(expiry) - COOKIE_DAYS * 86400  # (user, issued at)


def _is_local(handler: tornado.web.RequestHandler) -> bool:
    """Loopback and no proxy header: the same test as the app's (open-mode rule of
    :func:`railval.app.services.sessions.is_open`)."""
    return app_auth.is_local_request(handler.request)


def _principal_for(database, signed: tuple[str, float] | None, local: bool) -> Principal | None:
    """The user of a workshop cookie (user, issued at), re-read from the database on every
    request (:func:`railval.app.services.users.cookie_principal`)."""
    return users_service.cookie_principal(database, signed, local)


class _Base(SessionBoundXsrf, tornado.web.RequestHandler):
    """Every ``POST`` carries the anti-forgery token bound to the session and comes from
    this server's origin (:class:`railval.app.security.SessionBoundXsrf`)."""

    def initialize(self, database, auth=None) -> None:
        self.database = database
        self.auth = auth  # the app's sign-in (railval.app.auth.RailvalAuth) when served with it

    def set_default_headers(self) -> None:
        self.set_header("X-Content-Type-Options", "nosniff")
        self.set_header("Referrer-Policy", "no-referrer")
        self.set_header("X-Frame-Options", "DENY")

    def json(self, doc: Any, status: int = 200) -> None:
        self.set_status(status)
        self.set_header("Content-Type", "application/json; charset=utf-8")
        self.set_header("Cache-Control", "no-store")
        self.finish(json.dumps(doc, allow_nan=False))

    def finish(self, chunk: Any = None):
        """Finish the response; an HTML page gets the anti-forgery token in its ``POST``
        forms and for its scripts (:func:`railval.app.security.with_xsrf`)."""
        if isinstance(chunk, str) and chunk.startswith("<!doctype html>"):
            chunk = with_xsrf(chunk, self.xsrf_token.decode("ascii"))
        return super().finish(chunk)

    def write_error(self, status_code: int, **kwargs: Any) -> None:
        """A refused forgery (403 from the token or origin check) answers in the request's
        language: JSON for scripts, a page for forms; other errors as Tornado does."""
        exc = kwargs.get("exc_info", (None, None))[1]
        if status_code == 403 and "XSRF" in str(getattr(exc, "log_message", "") or ""):
            msg = ("refused: this request did not come from a railval page of this server "
                   "(another origin, or an anti-forgery token missing or not of this "
                   "session); reload the page and try again")
            if "json" in (self.request.headers.get("Content-Type") or ""):
                self.json({"error": msg}, 403)
            else:
                self.finish(page("Refused", f"<p class='err'>{esc(msg)}</p>"))
            return
        super().write_error(status_code, **kwargs)


class _OrganiserBase(_Base):
    """Pages for signed-in users; :meth:`principal` resolves who is asking."""

    async def principal(self) -> Principal | None:
        """Who is asking: a user signed in to the app (its session cookie, with the app's
        expiry and password-change checks) is recognised here too; else this page's own
        sign-in cookie."""
        if self.auth is not None:
            raw = self.get_cookie(app_auth.COOKIE)
            if raw:
                p = await run(self.auth.principal_from_cookie, raw)
                if p is not None:
                    return p
        signed = _unsign(self.get_cookie(COOKIE))
        return await run(_principal_for, self.database, signed, _is_local(self))

    async def require(self, action: str, *alternatives: str) -> Principal | None:
        """The principal when it may do ``action`` (or one of ``alternatives``); else the
        sign-in redirect or a 403 page, and None."""
        p = await self.principal()
        if p is None:
            login = "/login" if self.auth is not None else "/workshops/login"
            self.redirect(f"{login}?next={quote(self.request.uri or '/workshops')}")
            return None
        if not any(allowed(p, a) for a in (action, *alternatives)):
            self.set_status(403)
            self.finish(page("Not allowed", f"<p class='err'>{esc(p.username)} may not open "
                             f"this page (needs permission {esc(action)}).</p>", user=p))
            return None
        return p



# -------------------------------------------------------------------------- sign-in pages
class Login(_Base):
    def get(self) -> None:
        nxt = self.get_argument("next", "/workshops")
        self.finish(page("Sign in", _login_form(nxt, "")))

    async def post(self) -> None:
        nxt = self.get_argument("next", "/workshops")
        if not nxt.startswith("/") or nxt.startswith("//"):
            nxt = "/workshops"
        username = self.get_argument("username", "")
        password = self.get_argument("password", "")

        ok, message = await run(users_service.sign_in, self.database, username, password,
                                source=self.request.remote_ip or "")
        if not ok:
            self.set_status(401)
            self.finish(page("Sign in", _login_form(nxt, message)))
            return
        expiry = time.time() + COOKIE_DAYS * 86400
        self.set_cookie(COOKIE, _sign(f"{username.strip()}|{expiry}"), httponly=True,
                        samesite="Strict", expires_days=COOKIE_DAYS)
        self.redirect(nxt)


def _login_form(nxt: str, message: str) -> str:
    return (f"<form method='post' action='/workshops/login'>"
            f"<input type='hidden' name='next' value='{esc(nxt)}'>"
            f"<p><label>User name<br><input name='username' autocomplete='username'></label></p>"
            f"<p><label>Password<br><input name='password' type='password' "
            f"autocomplete='current-password'></label></p>"
            f"<p><button type='submit'>Sign in</button></p>"
            f"<p class='err'>{esc(message)}</p></form>")


class Logout(_Base):
    def get(self) -> None:
        self.clear_cookie(COOKIE)
        self.redirect("/workshops/login")
