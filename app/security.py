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

* Cross-site request forgery: ``railval serve`` turns on Tornado's ``xsrf_cookies``, so
  every ``POST`` (sign-in, sign-out, invitation, workshop forms, the reviewer's answers)
  must carry the token of the ``_xsrf`` cookie as the form field ``_xsrf`` or the header
  ``X-XSRFToken``. The cookie is :data:`XSRF_COOKIE` (HttpOnly, SameSite=Strict); pages
  hand the token to their forms and scripts (:func:`with_xsrf`). A page of another origin —
  also another port of the same host, which browsers count as the same *site* and so send
  SameSite cookies to — cannot read the token: its requests are refused with 403 before
  any handler runs. Panel's own callbacks travel over the websocket, whose Origin is
  checked against ``--allow-websocket-origin``.

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

import logging
import os
import re
import secrets

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


#: Tornado ``xsrf_cookie_kwargs``: the token cookie is never read by scripts (pages carry the
#: token themselves) and never sent with a request another site starts
XSRF_COOKIE = {"httponly": True, "samesite": "Strict"}

_POST_FORM = re.compile(r"(<form\b[^>]*\bmethod\s*=\s*['\"]?post['\"]?[^>]*>)", re.IGNORECASE)


def with_xsrf(page_html: str, token: str) -> str:
    """``page_html`` with the anti-forgery token in every ``POST`` form (hidden field
    ``_xsrf``) and in ``<meta name="xsrf-token">`` for scripts (they send it as
    ``X-XSRFToken``). ``token`` is Tornado's ``RequestHandler.xsrf_token``."""
    import html as _html

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
    """The server's output transforms: autoload.js refused, Tornado's default gzip, then
    the security headers."""
    from tornado.web import GZipContentEncoding

    return [NoAutoload, GZipContentEncoding, SecurityHeaders]


def use_local_fonts() -> None:
    """Drop the Google Fonts stylesheet from Panel's Fast design (the FastListTemplate's):
    the page then uses the system fonts of ``static/railval.css``. (Panel resolves a design's
    resources by its class name, so a subclass cannot simply leave the font out.)"""
    from panel.theme.fast import Fast

    Fast._resources = {k: v for k, v in Fast._resources.items() if k != "font"}


def session_secret() -> str:
    """Secret for signing Bokeh session ids: ``$BOKEH_SECRET_KEY`` (or the file
    ``$BOKEH_SECRET_KEY_FILE``), ``$RAILVAL_SESSION_SECRET`` or a random one for this server
    process. Several app processes behind one proxy need the same one."""
    from railval.db.settings import setting

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
    from sqlalchemy.exc import SQLAlchemyError

    from railval.core.errors import RailvalError

    _log.error("%s%s", f"{context}: " if context else "", type(exc).__name__, exc_info=exc)
    if isinstance(exc, RailvalError):
        return str(exc)
    if isinstance(exc, SQLAlchemyError):
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
