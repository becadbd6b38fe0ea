"""Sign-in for ``railval serve``: a Bokeh/Tornado auth provider on the user table (docs/security.md).

* ``/login`` (GET form, POST check) signs in through the one sign-in of
  :func:`railval.app.services.sessions.sign_in` (argon2id verified outside any transaction,
  rate limited, every failure recorded in the audit trail; a session on the server, a row
  of ``app_session``) and sets the signed
  session cookie ``railval_session`` = the session's random id (HMAC with the cookie
  secret, HttpOnly, SameSite=Lax). Panel's built-in ``--basic-auth`` is not used: it
  compares plain text.
* Every page load, websocket connection and ``POST`` re-checks the cookie: signature, then
  one indexed read of the session row with its user
  (:func:`railval.app.services.sessions.principal`): not ended, not past :data:`SESSION_MAX_AGE_S`, the user enabled. ``POST /logout`` ends the
  session on the server (a copy of the cookie is refused afterwards); ``user disable``,
  ``user passwd`` and ``user role`` end every session of the user.
* Every state-changing request (``POST``) carries the anti-forgery token bound to the
  session (or, on the sign-in and invitation forms, to a pre-session id in its own signed
  cookie) and comes from the app's own origin (:class:`railval.app.security.SessionBoundXsrf`);
  a page of another origin — another port of the same host included, which can toss cookies —
  is refused 403. ``/invite?token=…`` shows the single-use invitation form and creates the
  invitee's account.
* While **no user has a password** (nobody could sign in) a request from the loopback interface
  without proxy headers passes as the local user (open single-user mode: the one rule of
  :func:`railval.app.services.sessions.is_open`, also used by the workshop pages);
  :func:`check_startup` refuses to serve on any other address then.

This module holds the HTTP side only (forms, cookies, headers); every database read and write
goes through :mod:`railval.app.services.sessions`.

The cookie secret comes from ``$RAILVAL_COOKIE_SECRET`` or the file named by
``$RAILVAL_COOKIE_SECRET_FILE`` (or ``--cookie-secret-file``); without either a random secret
is made at start (sessions then end when the server restarts).
"""

from __future__ import annotations

import html
import ipaddress
import os
import secrets
from pathlib import Path
from typing import Any

from bokeh.server.auth_provider import AuthProvider
from tornado.web import RequestHandler, decode_signed_value

from railval.app.navigation import landing
from railval.app.security import SESSION_COOKIE, SessionBoundXsrf
from railval.app.services import sessions
from railval.core.errors import InvalidParameter, RailvalError
from railval.core.roles import Principal

COOKIE = SESSION_COOKIE
SESSION_MAX_AGE_S = 8 * 3600
LOGIN_URL = "/login"
LOGOUT_URL = "/logout"
INVITE_URL = "/invite"


class StartupRefused(RailvalError):
    """``railval serve`` must not start (no users on a non-loopback address, bad secret)."""


def is_loopback(address: str) -> bool:
    if address in ("localhost", ""):
        return address == "localhost"
    try:
        return ipaddress.ip_address(address).is_loopback
    except ValueError:
        return False


def is_local_request(request) -> bool:
    """True when ``request`` (a Tornado request, or Bokeh's proxy of one) came from a loopback
    address and carries no proxy header (a proxy on the same host connects from loopback)."""
    headers = getattr(request, "headers", None) or {}
    if any(h in headers for h in ("X-Forwarded-For", "X-Real-Ip", "Forwarded")):
        return False
    try:
        return ipaddress.ip_address(getattr(request, "remote_ip", "") or "").is_loopback
    except ValueError:
        return False


def cookie_secret(path: str | None = None) -> tuple[str, str]:
    """(secret, where it came from): ``$RAILVAL_COOKIE_SECRET``, a file, else a random one."""
    env = os.environ.get("RAILVAL_COOKIE_SECRET")  # same names as railval.db.settings
    path = path or os.environ.get("RAILVAL_COOKIE_SECRET_FILE")
    if env:
        secret, origin = env, "$RAILVAL_COOKIE_SECRET"
    elif path:
        try:
            secret = Path(path).read_text(encoding="utf-8").strip()
        except OSError as exc:
            raise StartupRefused(f"cookie secret file {path}: {exc.strerror}") from None
        origin = f"file {path}"
    else:
        return secrets.token_urlsafe(48), "random (sessions end when the server restarts)"
    if len(secret) < 32:
        raise StartupRefused(f"cookie secret from {origin} is {len(secret)} characters; "
                             "use at least 32 random characters")
    return secret, origin


def check_startup(database, address: str) -> bool:
    """True when sign-in is required (some user has a password); raises
    :class:`StartupRefused` when not and ``address`` is not a loopback address (open mode
    serves loopback requests only, and nobody else could sign in)."""
    has = sessions.sign_in_required(database)
    if not has and not is_loopback(address):
        raise StartupRefused(
            f"refusing to serve on {address}: the database {database.safe_url} has no users "
            "with a password, so nobody could sign in. Create the first admin "
            "with `railval user add NAME --role admin` (then engineers, reviewers…), or serve "
            "on 127.0.0.1 for open single-user mode.")
    if has:  # made at start-up, so that the first unknown name is answered as slowly as a known one
        sessions.warm_up()
    return has


class RailvalAuth(AuthProvider):
    """The auth provider: login/logout handlers and the per-request user check."""

    def __init__(self, database, secret: str, *, max_age_s: int = SESSION_MAX_AGE_S):
        self.database = database
        self.secret = secret
        self.max_age_s = max_age_s
        super().__init__()

    # -- cookie -------------------------------------------------------------------------
    def issue(self, handler: RequestHandler, session_id: str, username: str) -> None:
        """Set the session cookie of ``session_id`` (made by :meth:`open_session`)."""
        secure = handler.request.protocol == "https"
        handler.set_signed_cookie(COOKIE, session_id, expires_days=None, httponly=True,
                                  samesite="Lax", secure=secure)
        # Panel's pn.state.user reads the signed cookie "user" with the same secret
        handler.set_signed_cookie("user", username, expires_days=None, httponly=True,
                                  samesite="Lax", secure=secure)

    def session_id(self, raw: str | None) -> str | None:
        """The session id of a raw cookie value when its signature holds, else None."""
        if not raw:
            return None
        decoded = decode_signed_value(self.secret, COOKIE, raw, max_age_days=1)
        return None if decoded is None else decoded.decode("utf-8", "replace")

    def principal_from_cookie(self, raw: str | None, local: bool = False) -> Principal | None:
        """The principal of a raw cookie value: its session is read on the server (one
        indexed read) and must be open, unexpired and its user enabled; else the open-mode
        principal when ``local`` (:func:`is_local_request`) and no user has a password
        (:func:`railval.app.services.sessions.principal`); else None."""
        return sessions.principal(self.database, self.session_id(raw), local)

    def principal_of(self, request) -> Principal | None:
        """The principal of a request (Tornado's, or Bokeh's session request): its cookie
        and whether it came from the loopback interface."""
        cookies = getattr(request, "cookies", None) or {}
        raw = cookies.get(COOKIE)
        raw = getattr(raw, "value", raw)
        return self.principal_from_cookie(raw, is_local_request(request))

    @property
    def get_user(self):
        def get_user(handler: RequestHandler):
            raw = handler.get_cookie(COOKIE)
            p = self.principal_from_cookie(raw, is_local_request(handler.request))
            return None if p is None else p.username
        return get_user

    @property
    def login_url(self):
        return LOGIN_URL

    @property
    def login_handler(self):
        provider = self

        class Login(LoginHandler):
            auth = provider
        return Login

    @property
    def logout_url(self):
        return LOGOUT_URL

    @property
    def logout_handler(self):
        provider = self

        class Logout(LogoutHandler):
            auth = provider
        return Logout

    def extra_patterns(self) -> list[tuple[str, Any, dict]]:
        return [(INVITE_URL, InviteHandler, {"auth": self})]


# -- pages ---------------------------------------------------------------------------------
_PAGE = """<!doctype html><html lang="en"><head><meta charset="utf-8">
<title>railval — {title}</title>
<style>
body{{font-family:system-ui,sans-serif;background:#f4f6f8;margin:0}}
.box{{max-width:380px;margin:8vh auto;background:#fff;padding:28px 32px;border-radius:8px;
box-shadow:0 2px 8px rgba(0,0,0,.12)}}
h1{{font-size:20px;color:#0b5394;margin:0 0 4px}} p.sub{{color:#555;margin:0 0 18px}}
label{{display:block;margin:12px 0 4px;font-size:14px}}
input{{width:100%;box-sizing:border-box;padding:8px;font-size:15px}}
button{{margin-top:18px;width:100%;padding:9px;background:#0b5394;color:#fff;border:0;
border-radius:4px;font-size:15px;cursor:pointer}}
.msg{{background:#fdecea;color:#8a1f11;padding:9px;border-radius:4px;margin-bottom:8px}}
.ok{{background:#e8f4ea;color:#1e5a2a;padding:9px;border-radius:4px;margin-bottom:8px}}
</style></head><body><div class="box">{body}</div></body></html>"""


def _page(title: str, body: str) -> str:
    return _PAGE.format(title=html.escape(title), body=body)


def _client(handler: RequestHandler) -> str:
    return handler.request.remote_ip or ""


class LoginHandler(SessionBoundXsrf, RequestHandler):
    auth: RailvalAuth

    def _form(self, message: str = "", username: str = "", ok: str = "") -> None:
        msg = f'<div class="msg" role="alert">{html.escape(message)}</div>' if message else ""
        okm = f'<div class="ok">{html.escape(ok)}</div>' if ok else ""
        nxt = html.escape(self.get_argument("next", "/app"), quote=True)
        self.write(_page("sign in", f"""<h1>railval</h1><p class="sub">Sign in to continue</p>
{msg}{okm}<form method="post" action="{LOGIN_URL}">{self.xsrf_form_html()}
<input type="hidden" name="next" value="{nxt}">
<label for="username">User name</label>
<input id="username" name="username" autocomplete="username" value="{html.escape(username, quote=True)}" autofocus>
<label for="password">Password</label>
<input id="password" name="password" type="password" autocomplete="current-password">
<button type="submit" id="signin">Sign in</button></form>"""))

    def get(self) -> None:
        self.set_header("Cache-Control", "no-store")
        self._form(ok="You are signed out." if self.get_argument("out", "") else "")

    def post(self) -> None:
        self.set_header("Cache-Control", "no-store")
        username = self.get_argument("username", "")
        password = self.get_argument("password", "")
        result = sessions.sign_in(self.auth.database, username, password,
                                  source=_client(self), max_age_s=self.auth.max_age_s)
        if not result.ok:
            self.set_status({"account disabled": 403, "rate limit": 429}.get(result.reason, 401))
            self._form(result.message, username)
            return
        self.auth.issue(self, result.session_id, result.username)
        nxt = self.get_argument("next", "/app")
        if nxt in ("/app", "/", "") or not nxt.startswith("/") or nxt.startswith("//"):
            nxt = landing(result.principal)
        self.redirect(nxt)


class LogoutHandler(SessionBoundXsrf, RequestHandler):
    """``GET /logout`` asks to confirm (a form with the anti-forgery token); ``POST``
    signs out: the session ends on the server (a copied cookie is refused afterwards). A
    link or a page elsewhere cannot sign a user out."""

    auth: RailvalAuth

    def get(self) -> None:
        self.set_header("Cache-Control", "no-store")
        self.write(_page("sign out", f"""<h1>railval</h1><p class="sub">Sign out of railval?</p>
<form method="post" action="{LOGOUT_URL}">{self.xsrf_form_html()}
<button type="submit" id="signout">Sign out</button></form>
<p style="margin-top:14px"><a href="/app">Back to the app</a></p>"""))

    def post(self) -> None:
        sid = self.auth.session_id(self.get_cookie(COOKIE))
        p = self.auth.principal_from_cookie(self.get_cookie(COOKIE))
        if sid is not None and p is not None and not p.open_mode:
            sessions.sign_out(self.auth.database, sid, p.username, source=_client(self))
        self.clear_cookie(COOKIE)
        self.clear_cookie("user")
        self.redirect(f"{LOGIN_URL}?out=1")


class InviteHandler(SessionBoundXsrf, RequestHandler):
    """``/invite?token=…``: the invitee chooses a user name and password (single use)."""

    def initialize(self, auth: RailvalAuth) -> None:
        self.auth = auth

    def _refuse(self, token: str, message: str) -> None:
        sessions.refuse_invitation(self.auth.database, token, message, source=_client(self))
        self.set_status(403)
        self.write(_page("invitation", f'<h1>railval</h1><div class="msg" role="alert">'
                                       f'{html.escape(message)}</div>'
                                       f'<p><a href="{LOGIN_URL}">Sign in</a></p>'))

    def _form(self, token: str, inv: tuple[str, str | None], message: str = "",
              username: str = "", display: str = "") -> None:
        msg = f'<div class="msg" role="alert">{html.escape(message)}</div>' if message else ""
        role, workshop_ref = inv
        ws = (f" to workshop {html.escape(str(workshop_ref))}" if workshop_ref else "")
        self.write(_page("invitation", f"""<h1>railval</h1>
<p class="sub">You are invited as <b>{html.escape(role)}</b>{ws}. Choose your sign-in.</p>
{msg}<form method="post" action="{INVITE_URL}">{self.xsrf_form_html()}
<input type="hidden" name="token" value="{html.escape(token, quote=True)}">
<label for="username">User name</label><input id="username" name="username" value="{html.escape(username, quote=True)}">
<label for="display_name">Printed name</label><input id="display_name" name="display_name" value="{html.escape(display, quote=True)}">
<label for="password">Password (at least {sessions.MIN_PASSWORD_LENGTH} characters)</label>
<input id="password" name="password" type="password" autocomplete="new-password">
<label for="password2">Repeat password</label>
<input id="password2" name="password2" type="password" autocomplete="new-password">
<button type="submit" id="join">Create account</button></form>"""))

    def get(self) -> None:
        self.set_header("Cache-Control", "no-store")
        token = self.get_argument("token", "")
        try:
            inv = sessions.check_invitation(self.auth.database, token)
        except sessions.InvitationRefused as exc:
            self._refuse(token, str(exc))
            return
        self._form(token, inv)

    def post(self) -> None:
        self.set_header("Cache-Control", "no-store")
        token = self.get_argument("token", "")
        username = self.get_argument("username", "").strip()
        display = self.get_argument("display_name", "").strip()
        pw, pw2 = self.get_argument("password", ""), self.get_argument("password2", "")
        try:
            p, sid = sessions.redeem(self.auth.database, token, username=username, password=pw,
                                     password2=pw2, display_name=display,
                                     max_age_s=self.auth.max_age_s)
        except sessions.InvitationRefused as exc:
            self._refuse(token, str(exc))
            return
        except InvalidParameter as exc:
            inv = sessions.check_invitation(self.auth.database, token)
            self.set_status(400)
            self._form(token, inv, str(exc), username, display)
            return
        self.auth.issue(self, sid, p.username)
        self.redirect(landing(p))
