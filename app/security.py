"""HTTP hardening of the served web app: security headers on every response, no external
requests, signed session ids.

* :class:`SecurityHeaders` is a Tornado output transform (``tornado.web.Application``'s
  ``transforms``) that adds to every response of the Bokeh/Panel server:

  - ``Content-Security-Policy`` :data:`CSP`: scripts, styles, fonts and connections only
    from the app's own origin (``'self'``; ``ws:``/``wss:`` to the same host for Bokeh's
    websocket); images only from the app or ``data:``/``blob:`` URLs (Bokeh draws its
    toolbar icons and exports from them), so a Markdown image pointing elsewhere is never
    requested; ``frame-ancestors 'none'`` (no framing: clickjacking); ``object-src 'none'``;
    ``base-uri 'self'``. Bokeh and Panel write inline ``<script>`` blocks (the document
    model) and evaluate model code, so ``'unsafe-inline'`` and ``'unsafe-eval'`` stay on for
    scripts; user text is escaped where it is shown (``railval.core.names`` keeps names to
    a safe set in the first place).
  - ``X-Content-Type-Options: nosniff``, ``X-Frame-Options: DENY`` (older browsers),
    ``Referrer-Policy: no-referrer``.

* Cross-site request forgery (:class:`SessionBoundXsrf`, on every handler that takes a
  ``POST``): the anti-forgery token is an HMAC-SHA256 under the cookie secret of the
  signed-in session's id (:data:`SESSION_COOKIE`), or — on the sign-in and invitation forms
  and a review link opened without signing in — of a pre-session id held in its own signed
  cookie :data:`PRESESSION_COOKIE`. No value a page of the same *site* can set makes a valid
  token: another port of the same host may toss cookies (browsers do not separate them by
  port), but it can neither read the session id nor sign a cookie. Every ``POST`` must carry
  the token (form field ``_xsrf`` or header ``X-XSRFToken``), and a browser's request must
  come from the app's own origin (:func:`foreign_origin`): ``Sec-Fetch-Site`` other than
  ``same-origin``, or without it an ``Origin`` whose host:port differs from the request's
  ``Host``, is refused with 403 before any handler runs (a client that sends neither — not a
  browser — is judged by the token alone). Pages hand the token to their forms and scripts (:func:`with_xsrf`). Panel's own
  callbacks travel over the websocket, whose Origin is checked against
  ``--allow-websocket-origin``.

* :class:`NoAutoload` refuses Bokeh's ``<app>/autoload.js`` (404, no body from Bokeh):
  railval is never embedded in another page, and that script — which another page may
  include with ``<script src>``, the browser sending the SameSite=Lax session cookie along
  to a same-site page — would carry a Bokeh session token whose payload holds the request's
  cookies, the HttpOnly ``railval_session`` among them (docs/security.md, threat model).

* :func:`use_local_fonts` removes the Fast design's Google Fonts stylesheet: the page uses the system sans-serif fonts (``static/railval.css``) and makes no request
  to another host.

* :func:`session_secret` reads ``$BOKEH_SECRET_KEY`` (else ``$RAILVAL_SESSION_SECRET``)
  for ``railval serve``: Bokeh then signs session ids and refuses a forged one
  (``--session-ids signed``; Bokeh docs "Deployment: security"). Without it the server
  generates a random secret at start (sessions of a single server process only).
"""

from __future__ import annotations

import hashlib
import hmac
import html as _html
import logging
import os
import re
import secrets
from urllib.parse import urlsplit

from railval.core import lazy
from railval.core.errors import RailvalError

#: deferred (railval.core.lazy): the CLI's database messages use this module; the
#: static-file cache (Tornado, ~130 more modules) and the settings only when the server runs
static_cache = lazy.module("railval.app.static_cache")
setting = lazy.function("railval.db.settings", "setting")
#: Tornado, Panel and SQLAlchemy: loaded by the server (and a database error) that uses them
tornado_web = lazy.module("tornado.web")
panel_fast = lazy.module("panel.theme.fast")
sa_exc = lazy.module("sqlalchemy.exc")

CSP = ("default-src 'self'; "
       "script-src 'self' 'unsafe-inline' 'unsafe-eval'; "
       "style-src 'self' 'unsafe-inline'; "
       "img-src 'self' data: blob:; "
       "font-src 'self' data:; "
       "connect-src 'self' ws: wss:; "
       "frame-ancestors 'none'; object-src 'none'; base-uri 'self'; form-action 'self'")

HEADERS = {
    "Content-Security-Policy": CSP,
    "X-Content-Type-Options": "nosniff",
    "X-Frame-Options": "DENY",
    "Referrer-Policy": "no-referrer",
}


#: the signed-in session's cookie (:mod:`railval.app.auth`): a random session id, signed
SESSION_COOKIE = "railval_session"
#: the signed pre-session id of a browser that is not signed in (sign-in and invitation
#: forms, review links): the anti-forgery token of those forms is bound to it
PRESESSION_COOKIE = "railval_presession"


def forgery_token(secret: str | bytes, kind: str, ident: str) -> str:
    """The anti-forgery token of a session (``kind`` ``session``) or pre-session
    (``pre``) id: HMAC-SHA256 (RFC 2104) of ``railval-xsrf|kind|id`` under the cookie
    secret, hex."""
    key = secret.encode() if isinstance(secret, str) else secret
    return hmac.new(key, f"railval-xsrf|{kind}|{ident}".encode(), hashlib.sha256).hexdigest()


def foreign_origin(headers, host: str) -> str:
    """Why a request's browser headers show that another origin started it ("" when they do
    not). ``Sec-Fetch-Site`` (W3C Fetch Metadata; sent by current browsers to
    potentially trustworthy origins: https and loopback) decides when present: only
    ``same-origin`` passes — the pages' ``Referrer-Policy: no-referrer`` makes the browser
    send ``Origin: null`` even on the app's own forms (Fetch standard, "serializing a request
    origin"). Without it an ``Origin`` must name ``host`` (the request's ``Host``, host:port;
    the scheme is left out, a proxy may end TLS); ``null`` is refused."""
    site = headers.get("Sec-Fetch-Site")
    if site is not None:
        return "" if site == "same-origin" else f"Sec-Fetch-Site is {site!r}"
    origin = headers.get("Origin")
    if origin is not None:
        netloc = urlsplit(origin).netloc if origin != "null" else "null"
        if netloc.lower() != (host or "").lower():
            return f"Origin {origin!r} is not this server ({host})"
    return ""


class SessionBoundXsrf:
    """Tornado ``RequestHandler`` mixin: Tornado's ``xsrf_token`` and
    ``check_xsrf_cookie`` replaced by a token bound to the session (module docstring).
    ``accepts_presession_token``: the handler acts on the authority of something other
    than the session (a review link), so the pre-session token is accepted as well."""

    accepts_presession_token = False

    def _rv_secret(self) -> str | bytes | None:
        return self.application.settings.get("cookie_secret")

    def _rv_session_id(self) -> str | None:
        raw = self.get_signed_cookie(SESSION_COOKIE, max_age_days=1)
        return raw.decode("utf-8", "replace") if raw else None

    def _rv_presession_id(self, create: bool) -> str | None:
        raw = self.get_signed_cookie(PRESESSION_COOKIE, max_age_days=1)
        if raw:
            return raw.decode("utf-8", "replace")
        pending = getattr(self, "_rv_new_presession", None)
        if pending is None and create:
            pending = self._rv_new_presession = secrets.token_urlsafe(24)
            self.set_signed_cookie(PRESESSION_COOKIE, pending, expires_days=None, httponly=True,
                                   samesite="Strict",
                                   secure=self.request.protocol == "https")
        return pending

    @property
    def xsrf_token(self) -> bytes:
        secret = self._rv_secret()
        if secret is None:  # served without a cookie secret: Tornado's own token
            return super().xsrf_token  # type: ignore[misc]
        sid = self._rv_session_id()
        if sid:
            return forgery_token(secret, "session", sid).encode("ascii")
        return forgery_token(secret, "pre", self._rv_presession_id(create=True)).encode("ascii")

    def check_xsrf_cookie(self) -> None:
        secret = self._rv_secret()
        if secret is None:
            return super().check_xsrf_cookie()  # type: ignore[misc]
        why = foreign_origin(self.request.headers, self.request.host)
        if why:
            raise tornado_web.HTTPError(403, "XSRF refused: %s", why)
        given = (self.get_argument("_xsrf", None) or self.request.headers.get("X-Xsrftoken")
                 or self.request.headers.get("X-Csrftoken"))
        if not given:
            raise tornado_web.HTTPError(403, "XSRF refused: the anti-forgery token is missing")
        sid = self._rv_session_id()
        expected = [forgery_token(secret, "session", sid)] if sid else []
        if not sid or self.accepts_presession_token:
            pre = self._rv_presession_id(create=False)
            if pre:
                expected.append(forgery_token(secret, "pre", pre))
        if not any(hmac.compare_digest(given.encode("utf-8", "replace"), e.encode("ascii"))
                   for e in expected):
            raise tornado_web.HTTPError(403, "XSRF refused: the anti-forgery token does not belong to "
                                 "this session")


#: Tornado ``xsrf_cookie_kwargs`` of a handler without :class:`SessionBoundXsrf` (none of
#: railval's own takes a ``POST``): the token cookie is never read by scripts and never sent
#: with a request another site starts
XSRF_COOKIE = {"httponly": True, "samesite": "Strict"}

_POST_FORM = re.compile(r"(<form\b[^>]*\bmethod\s*=\s*['\"]?post['\"]?[^>]*>)", re.IGNORECASE)


def with_xsrf(page_html: str, token: str) -> str:
    """``page_html`` with the anti-forgery token in every ``POST`` form (hidden field
    ``_xsrf``) and in ``<meta name="xsrf-token">`` for scripts (they send it as
    ``X-XSRFToken``). ``token`` is Tornado's ``RequestHandler.xsrf_token``."""
    tok = _html.escape(token, quote=True)
    out = _POST_FORM.sub(lambda m: m.group(1) + f'<input type="hidden" name="_xsrf" value="{tok}">',
                         page_html)
    return out.replace("<head>", f'<head><meta name="xsrf-token" content="{tok}">', 1)


class SecurityHeaders:
    """Tornado output transform adding :data:`HEADERS` to every response."""

    def __init__(self, request) -> None:
        self.request = request

    def transform_first_chunk(self, status_code, headers, chunk, finishing):
        for name, value in HEADERS.items():
            headers[name] = value
        return status_code, headers, chunk

    def transform_chunk(self, chunk, finishing):
        return chunk


AUTOLOAD_REFUSED = (b"// railval is not embeddable: autoload.js is not served "
                    b"(docs/security.md)\n")


class NoAutoload:
    """Tornado output transform replacing every ``*/autoload.js`` response by a 404 whose
    body is :data:`AUTOLOAD_REFUSED` (the session token Bokeh wrote never leaves)."""

    def __init__(self, request) -> None:
        self.refuse = request.path.rstrip("/").endswith("/autoload.js")

    def transform_first_chunk(self, status_code, headers, chunk, finishing):
        if not self.refuse:
            return status_code, headers, chunk
        for name in ("Etag", "Content-Encoding", "Set-Cookie"):
            headers.pop(name, None)
        headers["Content-Type"] = "text/javascript; charset=utf-8"
        headers["Content-Length"] = str(len(AUTOLOAD_REFUSED))
        headers["Cache-Control"] = "no-store"
        return 404, headers, AUTOLOAD_REFUSED

    def transform_chunk(self, chunk, finishing):
        return b"" if self.refuse else chunk


def transforms() -> list:
    """The server's output transforms: autoload.js refused, Tornado's gzip (static files
    compressed once per process, :class:`railval.app.static_cache.CachedGZip`), then the
    security headers."""
    return [NoAutoload, static_cache.CachedGZip, SecurityHeaders]


def use_local_fonts() -> None:
    """Drop the Google Fonts stylesheet from Panel's Fast design (the FastListTemplate's):
    the page then uses the system fonts of ``static/railval.css``. (Panel resolves a design's
    resources by its class name, so a subclass cannot simply leave the font out.)"""
    fast = panel_fast.Fast
    fast._resources = {k: v for k, v in fast._resources.items() if k != "font"}


def session_secret() -> str:
    """Secret for signing Bokeh session ids: ``$BOKEH_SECRET_KEY`` (or the file
    ``$BOKEH_SECRET_KEY_FILE``), ``$RAILVAL_SESSION_SECRET`` or a random one for this server
    process. Several app processes behind one proxy need the same one."""

    return (setting("BOKEH_SECRET_KEY") or os.environ.get("RAILVAL_SESSION_SECRET")
            or secrets.token_urlsafe(32))


_log = logging.getLogger("railval.app")


def database_message(exc: BaseException) -> str:
    """A plain sentence for a database driver error: no SQL, no parameters, no paths."""
    orig = getattr(exc, "orig", None) or exc
    text = str(orig).strip()
    first = text.splitlines()[0] if text else type(orig).__name__
    if "locked" in first or "busy" in first:
        return ("the database is busy: another process held its write lock for longer than "
                "the 30 s wait; try again when it has finished")
    if "could not connect" in first or "Connection refused" in first or "unable to open" in first:
        return f"cannot open the database ({first})"
    return f"database error ({type(orig).__name__}: {first[:200]})"


def plain_message(exc: BaseException, context: str = "") -> str:
    """What the status area shows of an error: railval's own message (it names the input at
    fault), a plain sentence for database errors, else only the error's kind. The full
    error with its traceback goes to the server log (logger ``railval.app``)."""
    _log.error("%s%s", f"{context}: " if context else "", type(exc).__name__, exc_info=exc)
    if isinstance(exc, RailvalError):
        return str(exc)
    if isinstance(exc, sa_exc.SQLAlchemyError):
        return database_message(exc)
    return f"internal error ({type(exc).__name__}); the details are in the server log"


_MD_IMAGE = re.compile(r"!\[([^\]]*)\]\(\s*<?([^)\s>]+)>?[^)]*\)")


def no_external_images(markdown: str) -> str:
    """Markdown with every image that points to another host (``http:``, ``https:``, ``//``)
    replaced by its alt text: the page never requests a tracking pixel. (The CSP's
    ``img-src`` blocks such requests too; this keeps the text readable.)"""
    def repl(m: re.Match) -> str:
        alt, url = m.group(1), m.group(2)
        if re.match(r"(?i)(https?:)?//", url):
            return f"[image not shown: {alt or 'external'}]"
        return m.group(0)
    return _MD_IMAGE.sub(repl, markdown)
