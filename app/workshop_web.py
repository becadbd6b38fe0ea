"""Workshop pages served by ``railval serve`` next to the Panel app (docs/workshops.md).

Plain Tornado request handlers, not Panel sessions: a reviewer's page is one static HTML
page with a few lines of JavaScript that fetches a PNG and posts each answer as JSON. With
50 reviewers at once this costs the server one short request per answer instead of 50
live Bokeh documents and websockets, keeps no per-reviewer state in server memory (a
restart loses nothing: every answer is in the database the moment the server confirms
it), and serves each plot's stored bytes verbatim.

Routes
------
Reviewer (the personal link is the credential; only its SHA-256 is stored):

* ``GET  /review/{token}``            the review page
* ``GET  /review/{token}/state``      own sequence length, own answers, next unanswered place
* ``GET  /review/{token}/image/{i}``  the PNG at place ``i`` of the own sequence
* ``POST /review/{token}/answer``     ``{position, answer: yes|no, comment, seconds, submission}``
* ``POST /review/{token}/finish``

Organiser (signed-in user with ``workshop.run``; analysis needs ``workshop.results``):

* ``/workshops`` list, ``/workshops/new`` create form (count before creating),
  ``/workshops/{name}`` progress, links, close/reopen, ``/workshops/{name}/analysis``,
  ``/workshops/login``, ``/workshops/logout``.

Roles come from :mod:`railval.core.roles` and are checked on every request. Sign-in uses
:func:`railval.db.users.authenticate` (argon2id, rate-limited, audited) and an HMAC-signed
cookie (secret ``$RAILVAL_COOKIE_SECRET`` or a random one per server process). Open
single-user mode (no user can sign in because none has a password, request from the
loopback interface without proxy headers) acts as :func:`railval.core.roles.open_principal`.
All user text is escaped.
"""

from __future__ import annotations

import base64
import hashlib
import hmac
import html
import io
import ipaddress
import json
import os
import secrets
import threading
import time
from concurrent.futures import ThreadPoolExecutor
from typing import Any
from urllib.parse import quote

import tornado.web
from railval.core.errors import InvalidParameter, NotFound, RailvalError
from railval.core.roles import Principal, allowed, open_principal
from tornado.ioloop import IOLoop

COOKIE = "railval_user"
COOKIE_DAYS = 1
_SECRET = (os.environ.get("RAILVAL_COOKIE_SECRET") or secrets.token_hex(32)).encode()
#: database work runs here, off the server's event loop
_POOL = ThreadPoolExecutor(max_workers=4, thread_name_prefix="railval-workshop")

_CSS = """
body{font-family:'DejaVu Sans',Arial,sans-serif;margin:0;background:#f6f7f9;color:#1b1b1b}
header{background:#0b5394;color:#fff;padding:10px 20px;display:flex;gap:20px;align-items:center}
header a{color:#fff} main{padding:16px 24px;max-width:1200px;margin:auto}
table{border-collapse:collapse;background:#fff} td,th{border:1px solid #ccd;padding:4px 8px;text-align:left}
th{background:#eef1f6} .num{text-align:right;font-variant-numeric:tabular-nums}
button,.btn{font-size:16px;padding:8px 18px;border-radius:4px;border:1px solid #889;background:#fff;cursor:pointer}
button.yes{background:#1a7f37;color:#fff;border-color:#1a7f37} button.no{background:#b42318;color:#fff;border-color:#b42318}
button.chosen{outline:4px solid #f5b700} .muted{color:#666} .err{color:#b42318;font-weight:bold}
#plot{width:100%;max-width:1000px;border:1px solid #ccd;background:#fff;display:block}
.bar{height:10px;background:#dde;border-radius:5px;overflow:hidden;min-width:120px}.bar>div{height:100%;background:#0b5394}
textarea{width:100%;max-width:990px;font-size:15px} .row{display:flex;gap:12px;align-items:center;margin:10px 0;flex-wrap:wrap}
code{background:#eef;padding:2px 4px;word-break:break-all}
"""


def esc(value: Any) -> str:
    return html.escape("" if value is None else str(value), quote=True)


def page(title: str, body: str, *, user: str = "", script: str = "") -> str:
    who = (f'<span>{esc(user)}</span> <a href="/workshops/logout">sign out</a>' if user else "")
    return (f"<!doctype html><html lang='en'><head><meta charset='utf-8'>"
            f"<meta name='viewport' content='width=device-width,initial-scale=1'>"
            f"<title>{esc(title)}</title><style>{_CSS}</style></head><body>"
            f"<header><strong>railval</strong><span>{esc(title)}</span>"
            f"<span style='margin-left:auto'>{who}</span></header><main>{body}</main>"
            f"{'<script>' + script + '</script>' if script else ''}</body></html>")


async def run(fn, *args, **kw):
    """Run blocking database work in the workshop thread pool."""
    return await IOLoop.current().run_in_executor(_POOL, lambda: fn(*args, **kw))


# -------------------------------------------------------------------------- sign-in
def _sign(value: str) -> str:
    mac = hmac.new(_SECRET, value.encode(), hashlib.sha256).hexdigest()
    return base64.urlsafe_b64encode(f"{value}|{mac}".encode()).decode()


def _unsign(cookie: str | None) -> str | None:
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
    return username


def _is_local(handler: tornado.web.RequestHandler) -> bool:
    if any(h in handler.request.headers for h in ("X-Forwarded-For", "X-Real-Ip", "Forwarded")):
        return False
    try:
        return ipaddress.ip_address(handler.request.remote_ip).is_loopback
    except ValueError:
        return False


def _principal_for(database, username: str | None, local: bool) -> Principal | None:
    from railval.db import users
    from railval.db.models import AppUser
    from sqlalchemy import func, select

    with database.session() as s:
        if username:
            user = users.find_user(s, username)
            if user is not None and not user.disabled:
                return users.principal(user)
        if local:
            n_pw = s.scalar(select(func.count()).select_from(AppUser)
                            .where(AppUser.password_hash.is_not(None)))
            if n_pw == 0:
                return open_principal()
    return None


class _Base(tornado.web.RequestHandler):
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

    def check_xsrf_cookie(self) -> None:  # SameSite=Strict cookie; reviewer token in the URL
        return None


class _OrganiserBase(_Base):
    """Pages for signed-in users; :meth:`principal` resolves who is asking."""

    async def principal(self) -> Principal | None:
        """Who is asking: a user signed in to the app (its session cookie, with the app's
        expiry and password-change checks) is recognised here too; else this page's own
        sign-in cookie."""
        if self.auth is not None:
            from railval.app.auth import COOKIE as APP_COOKIE

            raw = self.get_cookie(APP_COOKIE)
            if raw:
                p = await run(self.auth.principal_from_cookie, raw)
                if p is not None:
                    return p
        name = _unsign(self.get_cookie(COOKIE))
        return await run(_principal_for, self.database, name, _is_local(self))

    async def require(self, action: str) -> Principal | None:
        p = await self.principal()
        if p is None:
            self.redirect(f"/workshops/login?next={quote(self.request.uri or '/workshops')}")
            return None
        if not allowed(p, action):
            self.set_status(403)
            self.finish(page("Not allowed", f"<p class='err'>{esc(p.username)} may not open "
                             f"this page (needs permission {esc(action)}).</p>", user=p.username))
            return None
        return p


# -------------------------------------------------------------------------- reviewer
#: seconds a personal link's context (reviewer, workshop status, sequence) is reused before
#: it is read again; closing or reopening on the organiser page clears it at once, a change
#: made elsewhere (CLI, another server) is seen within this time
CONTEXT_TTL_S = 5.0
#: bytes of plot images kept in memory (images never change once stored)
IMAGE_CACHE_BYTES = 64 * 1024 * 1024
_contexts: dict[str, tuple[float, Any]] = {}
_images: dict[tuple[int, int], tuple[bytes, str]] = {}
_image_bytes = [0]
_cache_lock = threading.Lock()


def clear_contexts() -> None:
    with _cache_lock:
        _contexts.clear()


def _ctx(database, token: str):
    from railval.db import workshops as wsdb

    key = hashlib.sha256(token.encode()).hexdigest()
    now = time.monotonic()
    with _cache_lock:
        hit = _contexts.get(key)
    if hit is not None and now - hit[0] < CONTEXT_TTL_S:
        return hit[1]
    with database.session() as s:
        ctx = wsdb.reviewer_by_token(s, token)
    with _cache_lock:
        if len(_contexts) > 10_000:
            _contexts.clear()
        _contexts[key] = (now, ctx)
    return ctx


def _state(database, ctx) -> dict[str, Any]:
    from railval.db import workshops as wsdb

    with database.session() as s:
        own = wsdb.own_answers(s, ctx.reviewer_id)
    total = len(ctx.sequence)
    nxt = next((i for i in range(total) if i not in own), total)
    return {"total": total, "answered": len(own), "next": nxt, "finished": ctx.finished,
            "status": ctx.workshop_status, "blind": ctx.blind,
            "workshop": None if ctx.blind else ctx.workshop_name,
            "answers": {str(i): {"answer": "yes" if a.answer else "no", "comment": a.comment}
                        for i, a in own.items()}}


class _ReviewerBase(_Base):
    async def context(self, token: str):
        ctx = await run(_ctx, self.database, token)
        if ctx is None or not allowed(ctx.principal, "workshop.answer"):
            self.set_status(404)
            self.finish(page("Review", "<p class='err'>This review link is not valid (or no longer "
                             "valid); ask the organiser for a new one.</p>"))
            return None
        return ctx


_REVIEW_JS = r"""
const base = location.pathname.replace(/\/+$/, '');
let st = null, pos = 0, shownAt = performance.now(), busy = false;
const $ = (id) => document.getElementById(id);
function uid() { return (self.crypto && crypto.randomUUID) ? crypto.randomUUID()
  : Date.now().toString(36) + Math.random().toString(36).slice(2); }
function firstOpen(from) { for (let i = from; i < st.total; i++) if (!st.answers[i]) return i;
  for (let i = 0; i < st.total; i++) if (!st.answers[i]) return i; return st.total; }
function show() {
  const done = Object.keys(st.answers).length;
  $('answered').textContent = done;
  $('bar').style.width = (100 * done / Math.max(1, st.total)) + '%';
  if (st.finished || st.status !== 'open') {
    $('review').hidden = true; $('end').hidden = false;
    $('endtext').textContent = st.finished ? 'You have finished this review. Thank you!'
      : 'This workshop is closed; answers are not taken at the moment.';
    $('finish').hidden = true; $('back').hidden = true; return; }
  if (pos >= st.total) {
    $('review').hidden = true; $('end').hidden = false; $('back').hidden = false;
    $('endtext').textContent = 'All ' + st.total + ' plots answered. You can go back and change '
      + 'answers, or finish (answers are then final).';
    $('finish').hidden = false; return; }
  $('review').hidden = false; $('end').hidden = true;
  $('progress').textContent = (pos + 1) + ' of ' + st.total;
  const a = st.answers[pos];
  $('yes').classList.toggle('chosen', !!a && a.answer === 'yes');
  $('no').classList.toggle('chosen', !!a && a.answer === 'no');
  $('comment').value = a ? a.comment : '';
  $('prevnote').textContent = a ? ('Your answer: ' + a.answer + ' (press Yes or No to change it)') : '';
  $('backbtn').disabled = pos === 0;
  const img = $('plot');
  img.dataset.position = pos;
  img.src = base + '/image/' + pos;
  if (pos + 1 < st.total) { new Image().src = base + '/image/' + (pos + 1); }
}
$('plot').addEventListener('load', () => { shownAt = performance.now(); });
async function post(path, body) {
  for (let attempt = 0; ; attempt++) {
    try {
      const r = await fetch(base + path, {method: 'POST', headers: {'Content-Type': 'application/json'},
                                          body: JSON.stringify(body)});
      const doc = await r.json();
      if (r.ok) { $('msg').textContent = ''; return doc; }
      $('msg').textContent = doc.error || ('error ' + r.status); return null;
    } catch (e) {
      $('msg').textContent = 'Saving… the server does not answer, retrying (your answer is kept).';
      await new Promise(res => setTimeout(res, Math.min(5000, 500 * (attempt + 1))));
    }
  }
}
async function answer(value) {
  if (busy || pos >= st.total) return;
  busy = true;
  const body = {position: pos, answer: value, comment: $('comment').value,
                seconds: Math.max(0, (performance.now() - shownAt) / 1000), submission: uid()};
  const doc = await post('/answer', body);
  busy = false;
  if (!doc) return;
  st.answers[pos] = {answer: value, comment: body.comment};
  pos = firstOpen(pos + 1);
  show();
}
async function finish() {
  const doc = await post('/finish', {});
  if (doc) { st.finished = true; show(); }
}
$('yes').onclick = () => answer('yes');
$('no').onclick = () => answer('no');
$('backbtn').onclick = () => { if (pos > 0) { pos -= 1; show(); } };
$('back').onclick = () => { pos = st.total - 1; show(); };
$('finish').onclick = finish;
document.addEventListener('keydown', (e) => {
  if (e.target && e.target.tagName === 'TEXTAREA') return;
  if (e.key === 'y' || e.key === 'Y') { e.preventDefault(); answer('yes'); }
  else if (e.key === 'n' || e.key === 'N') { e.preventDefault(); answer('no'); }
  else if (e.key === 'ArrowLeft') { $('backbtn').click(); }
});
(async () => {
  const r = await fetch(base + '/state', {cache: 'no-store'});
  st = await r.json();
  pos = firstOpen(st.next);
  document.body.dataset.ready = '1';
  show();
})();
"""


class ReviewPage(_ReviewerBase):
    async def get(self, token: str) -> None:
        ctx = await self.context(token)
        if ctx is None:
            return
        title = "Expert review" if ctx.blind else f"Expert review — {ctx.workshop_name}"
        body = """
<p class='muted'>Question for every plot: <strong>is the model validated for this signal?</strong>
Answer with the buttons or the keys <kbd>y</kbd> / <kbd>n</kbd>; <kbd>←</kbd> goes back.
Every answer is saved at once; you can close the page and come back with the same link.</p>
<div class='row'><span>Answered <span id='answered'>0</span></span>
<div class='bar' style='width:300px'><div id='bar' style='width:0'></div></div></div>
<section id='review'>
<div class='row'><strong>Plot <span id='progress'>…</span></strong>
<span id='prevnote' class='muted'></span></div>
<img id='plot' alt='review plot' src='data:,'>
<div class='row'><button id='yes' class='yes'>Yes — validated (y)</button>
<button id='no' class='no'>No — not validated (n)</button>
<button id='backbtn'>← previous</button></div>
<label for='comment' class='muted'>Comment (optional)</label><br>
<textarea id='comment' rows='2' maxlength='2000'></textarea>
</section>
<section id='end' hidden><p id='endtext'></p>
<button id='back' hidden>← go back</button> <button id='finish' class='yes' hidden>Finish</button></section>
<p id='msg' class='err'></p>"""
        self.set_header("Cache-Control", "no-store")
        self.finish(page(title, body, user=ctx.username, script=_REVIEW_JS))


class ReviewState(_ReviewerBase):
    async def get(self, token: str) -> None:
        ctx = await self.context(token)
        if ctx is not None:
            self.json(await run(_state, self.database, ctx))


def _image_at(database, ctx, position: int) -> tuple[bytes, str]:
    from railval.db import workshops as wsdb

    key = (ctx.workshop_id, ctx.sequence[position][0])
    with _cache_lock:
        hit = _images.get(key)
    if hit is not None:
        return hit
    with database.session() as s:
        data, sha = wsdb.plot_image(s, *key)
    with _cache_lock:
        if _image_bytes[0] + len(data) > IMAGE_CACHE_BYTES:
            _images.clear()
            _image_bytes[0] = 0
        _images[key] = (data, sha)
        _image_bytes[0] += len(data)
    return data, sha


class ReviewImage(_ReviewerBase):
    async def get(self, token: str, position: str) -> None:
        ctx = await self.context(token)
        if ctx is None:
            return
        i = int(position)
        if not (0 <= i < len(ctx.sequence)):
            self.set_status(404)
            self.finish("no such plot")
            return
        data, sha = await run(_image_at, self.database, ctx, i)
        self.set_header("Content-Type", "image/png")
        self.set_header("ETag", f'"{sha}"')
        self.set_header("X-Image-SHA256", sha)
        self.set_header("Cache-Control", "private, max-age=86400")
        self.finish(data)


def _answer(database, token: str, body: dict[str, Any]) -> dict[str, Any]:
    from railval.db import workshops as wsdb

    ctx = _ctx(database, token)
    if ctx is None or not allowed(ctx.principal, "workshop.answer"):
        raise NotFound("review link not valid")
    if ctx.finished:
        raise wsdb.WorkshopClosed("you have finished this review; answers are final")
    ans = str(body.get("answer", "")).lower()
    if ans not in ("yes", "no"):
        raise InvalidParameter(f"answer must be yes or no, got {body.get('answer')!r}")
    try:
        position = int(body.get("position"))
        seconds = float(body.get("seconds", 0.0))
    except (TypeError, ValueError):
        raise InvalidParameter("position must be a whole number and seconds a number") from None
    with database.session() as s:  # the write comes first in its own unit of work
        outcome = wsdb.record_answer(s, ctx, position, ans == "yes", seconds=seconds,
                                     comment=str(body.get("comment") or ""),
                                     submission=str(body.get("submission") or ""))
    return {"stored": outcome, "position": position}


def _finish(database, token: str) -> dict[str, Any]:
    from railval.db import workshops as wsdb

    with database.session() as s:
        ctx = wsdb.reviewer_by_token(s, token)
        if ctx is None or not allowed(ctx.principal, "workshop.answer"):
            raise NotFound("review link not valid")
        wsdb.finish(s, ctx)
    clear_contexts()
    return {"finished": True}


class ReviewAnswer(_Base):
    async def post(self, token: str) -> None:
        from railval.db.workshops import WorkshopClosed

        try:
            body = json.loads(self.request.body or b"{}")
        except ValueError:
            body = None
        if not isinstance(body, dict):
            self.json({"error": "the request body must be a JSON object"}, 400)
            return
        try:
            self.json(await run(_answer, self.database, token, body))
        except NotFound as exc:
            self.json({"error": str(exc)}, 404)
        except WorkshopClosed as exc:
            self.json({"error": str(exc)}, 409)
        except RailvalError as exc:
            self.json({"error": str(exc)}, 400)


class ReviewFinish(_Base):
    async def post(self, token: str) -> None:
        try:
            self.json(await run(_finish, self.database, token))
        except NotFound as exc:
            self.json({"error": str(exc)}, 404)
        except RailvalError as exc:
            self.json({"error": str(exc)}, 400)


# -------------------------------------------------------------------------- sign-in pages
class Login(_Base):
    def get(self) -> None:
        nxt = self.get_argument("next", "/workshops")
        self.finish(page("Sign in", _login_form(nxt, "")))

    async def post(self) -> None:
        from railval.db import users

        nxt = self.get_argument("next", "/workshops")
        if not nxt.startswith("/") or nxt.startswith("//"):
            nxt = "/workshops"
        username = self.get_argument("username", "")
        password = self.get_argument("password", "")

        def check():
            with self.database.session() as s:
                res = users.authenticate(s, username, password, source=self.request.remote_ip or "")
                return res.ok, res.message
        ok, message = await run(check)
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


# -------------------------------------------------------------------------- organiser
def _list_doc(database) -> list[dict[str, Any]]:
    from railval.db import workshops as wsdb

    with database.session() as s:
        out = []
        for w in wsdb.list_workshops(s):
            prog = wsdb.progress(s, w)
            out.append({"name": w.name, "campaign": w.campaign.name, "status": w.status,
                        "blind": w.blind, "reviewers": len(prog),
                        "answers": sum(r["answered"] for r in prog)})
        return out


class WorkshopList(_OrganiserBase):
    async def get(self) -> None:
        p = await self.require("workshop.run")
        if p is None:
            return
        rows = await run(_list_doc, self.database)
        trs = "".join(
            f"<tr><td><a href='/workshops/{quote(r['name'], safe='')}'>{esc(r['name'])}</a></td>"
            f"<td>{esc(r['campaign'])}</td><td>{esc(r['status'])}</td>"
            f"<td>{'yes' if r['blind'] else 'no'}</td><td class='num'>{r['reviewers']}</td>"
            f"<td class='num'>{r['answers']}</td></tr>" for r in rows)
        body = (f"<p><a class='btn' href='/workshops/new'>New workshop</a></p>"
                f"<table><tr><th>workshop</th><th>campaign</th><th>status</th><th>blind</th>"
                f"<th>reviewers</th><th>answers</th></tr>{trs}</table>")
        self.finish(page("Workshops", body, user=p.username))


def _form_choices(database) -> dict[str, Any]:
    from railval.app.services.workshops import describe_kinds
    from railval.db import repo

    with database.session() as s:
        camps = {c.name: {"configurations": [x.name for x in repo.list_configurations(s, c)],
                          "sections": [x.id for x in repo.section_infos(s, c)]}
                 for c in repo.list_campaigns(s)}
    return {"campaigns": camps, "kinds": describe_kinds()}


_NEW_JS = r"""
const form = document.getElementById('f');
const choices = JSON.parse(document.getElementById('choices').textContent);
function boxes(id, name, items, labels) {
  const el = document.getElementById(id); el.innerHTML = '';
  for (const it of items) { const l = document.createElement('label'); l.style.marginRight = '12px';
    const b = document.createElement('input'); b.type = 'checkbox'; b.name = name; b.value = it; b.checked = true;
    b.onchange = count; l.appendChild(b); l.appendChild(document.createTextNode(' ' + (labels ? labels[it] : it)));
    el.appendChild(l); } }
function fill() { const c = choices.campaigns[form.campaign.value] || {configurations: [], sections: []};
  boxes('cfgs', 'configurations', c.configurations); boxes('secs', 'sections', c.sections); count(); }
async function count() {
  const q = new URLSearchParams(new FormData(form));
  const r = await fetch('/workshops/plan?' + q.toString());
  const d = await r.json();
  document.getElementById('count').textContent = r.ok ? (d.plots + ' plots: ' +
    Object.entries(d.by_kind).map(([k, n]) => k + ' ' + n).join(', ')) : d.error;
}
const kl = {}; for (const k of choices.kinds) kl[k.id] = k.label + ' (' + k.domain + ')';
boxes('kinds', 'kinds', choices.kinds.map(k => k.id), kl);
form.campaign.onchange = fill; form.onsubmit = () => { document.getElementById('create').disabled = true;
  document.getElementById('count').textContent += ' — rendering, please wait…'; };
fill();
"""


def _plan_doc(database, args: dict[str, list[str]]) -> dict[str, Any]:
    from railval.app.services import workshops as ws

    # the form sends the ticked boxes only: a group with none ticked gives no plot
    if not all(args.get(g) for g in ("configurations", "sections", "kinds")):
        return {"plots": 0, "by_kind": {}}
    with database.session() as s:
        planned = ws.plan(s, (args.get("campaign") or [""])[0], args["configurations"],
                          args["sections"], args["kinds"])
    return {"plots": len(planned), "by_kind": ws.count_by_kind(planned)}


def _args(handler: tornado.web.RequestHandler) -> dict[str, list[str]]:
    return {k: [v.decode() for v in vs] for k, vs in handler.request.arguments.items()}


class WorkshopPlan(_OrganiserBase):
    async def get(self) -> None:
        p = await self.require("workshop.run")
        if p is None:
            return
        try:
            self.json(await run(_plan_doc, self.database, _args(self)))
        except RailvalError as exc:
            self.json({"error": str(exc)}, 400)


class WorkshopNew(_OrganiserBase):
    async def get(self, message: str = "") -> None:
        p = await self.require("workshop.run")
        if p is None:
            return
        ch = await run(_form_choices, self.database)
        opts = "".join(f"<option>{esc(c)}</option>" for c in ch["campaigns"])
        choices_json = json.dumps(ch).replace("</", "<\\/")
        body = f"""
<form id='f' method='post' action='/workshops/new'>
<p><label>Name <input name='name' required maxlength='200'></label>
<label>Campaign <select name='campaign'>{opts}</select></label></p>
<p><strong>Configurations</strong><br><span id='cfgs'></span></p>
<p><strong>Sections</strong><br><span id='secs'></span></p>
<p><strong>Plot kinds</strong><br><span id='kinds'></span></p>
<p><label><input type='checkbox' name='blind' value='1'> blind (no vehicle, configuration or
section names)</label> <label>hidden repeats <input name='repeats' value='0.1' size='4'></label>
<label>share also shown with automatic scaling <input name='auto_share' value='0' size='4'></label></p>
<p>Count: <strong id='count'>…</strong></p>
<p><button id='create' type='submit'>Create workshop</button></p>
<p class='err'>{esc(message)}</p></form>
<script type='application/json' id='choices'>{choices_json}</script>"""
        self.finish(page("New workshop", body, user=p.username, script=_NEW_JS))

    async def post(self) -> None:
        from railval.app.services import workshops as ws

        p = await self.require("workshop.run")
        if p is None:
            return
        a = _args(self)
        try:
            name = (a.get("name") or [""])[0]
            await run(ws.create, self.database, name, (a.get("campaign") or [""])[0],
                      configurations=a.get("configurations") or ["(none chosen)"],
                      sections=a.get("sections") or ["(none chosen)"],
                      kinds=a.get("kinds") or ["(none chosen)"], blind=bool(a.get("blind")),
                      repeats=float((a.get("repeats") or ["0.1"])[0]),
                      auto_share=float((a.get("auto_share") or ["0"])[0]), actor=p)
        except (RailvalError, ValueError) as exc:
            self.set_status(400)
            await self.get(message=str(exc))
            return
        self.redirect(f"/workshops/{quote(name, safe='')}")


def _status_doc(database, name: str) -> dict[str, Any]:
    from railval.app.services.workshops import status_document

    with database.session() as s:
        return status_document(s, name)


_STATUS_JS = r"""
const name = document.body.dataset.workshop;
async function refresh() {
  try {
    const r = await fetch('/workshops/' + encodeURIComponent(name) + '/status', {cache: 'no-store'});
    if (!r.ok) return;
    const d = await r.json();
    document.getElementById('wstatus').textContent = d.status;
    document.getElementById('nanswers').textContent = d.answers;
    const tb = document.getElementById('progress'); tb.innerHTML = '';
    for (const rv of d.reviewers) {
      const tr = document.createElement('tr');
      const cells = [rv.reviewer, rv.answered + ' of ' + rv.total, '', rv.finished ? 'finished' : '',
                     rv.last_answer_at ? rv.last_answer_at.slice(0, 19).replace('T', ' ') : '—'];
      cells.forEach((c, i) => { const td = document.createElement('td');
        if (i === 2) { td.innerHTML = '<div class="bar"><div></div></div>';
          td.firstChild.firstChild.style.width = (100 * rv.answered / Math.max(1, rv.total)) + '%'; }
        else td.textContent = c; tr.appendChild(td); });
      tb.appendChild(tr);
    }
    document.body.dataset.refreshed = String(Date.now());
  } catch (e) { }
}
refresh(); setInterval(refresh, 3000);
"""


class WorkshopStatus(_OrganiserBase):
    async def get(self, name: str) -> None:
        p = await self.require("workshop.run")
        if p is None:
            return
        try:
            self.json(await run(_status_doc, self.database, name))
        except NotFound as exc:
            self.json({"error": str(exc)}, 404)


def _invite(database, name: str, reviewer: str, actor) -> str:
    from railval.db import workshops as wsdb

    with database.session() as s:
        return wsdb.invite(s, wsdb.get_workshop(s, name), reviewer, actor=actor)


def _set_status(database, name: str, status: str, actor) -> None:
    from railval.db import workshops as wsdb

    with database.session() as s:
        wsdb.set_status(s, wsdb.get_workshop(s, name), status, actor=actor)
    clear_contexts()


class WorkshopPage(_OrganiserBase):
    async def get(self, name: str, link: str = "", message: str = "") -> None:
        p = await self.require("workshop.run")
        if p is None:
            return
        try:
            d = await run(_status_doc, self.database, name)
        except NotFound as exc:
            self.set_status(404)
            self.finish(page("Workshop", f"<p class='err'>{esc(exc)}</p>", user=p.username))
            return
        q = quote(name, safe="")
        toggle = ("close", "Close workshop") if d["status"] == "open" else ("reopen", "Reopen workshop")
        link_html = (f"<p>Personal link (shown once; send it to the reviewer): <code id='link'>{esc(link)}</code></p>"
                     if link else "")
        analysis = (f"<a class='btn' href='/workshops/{q}/analysis'>Analysis</a>"
                    if allowed(p, "workshop.results") else "")
        body = f"""
<h2>{esc(d['workshop'])}</h2>
<p>Campaign {esc(d['campaign'])} · {d['plots']} plots · blind: {'yes' if d['blind'] else 'no'} ·
hidden repeats {100 * d['repeats']:.0f} % · status <strong id='wstatus'>{esc(d['status'])}</strong> ·
answers <strong id='nanswers'>{d['answers']}</strong></p>
<div class='row'><form method='post' action='/workshops/{q}/status'>
<input type='hidden' name='status' value='{toggle[0]}'><button type='submit' id='toggle'>{toggle[1]}</button></form>
{analysis}</div>
<h3>Reviewers (live)</h3>
<table><thead><tr><th>reviewer</th><th>answered</th><th>progress</th><th></th><th>last answer (UTC)</th></tr></thead>
<tbody id='progress'></tbody></table>
<h3>Invite a reviewer</h3>
<form method='post' action='/workshops/{q}/invite' class='row'>
<label>User name <input name='reviewer' required maxlength='100'></label>
<button type='submit' id='invite'>Create personal link</button></form>
{link_html}<p class='err'>{esc(message)}</p>
<p class='muted'>A new link replaces the reviewer's earlier one. Answers stay with the reviewer.</p>"""
        html_page = page(f"Workshop {name}", body, user=p.username, script=_STATUS_JS)
        self.finish(html_page.replace("<body>", f"<body data-workshop='{esc(name)}'>", 1))

    async def post(self, name: str, action: str) -> None:
        p = await self.require("workshop.run")
        if p is None:
            return
        try:
            if action == "invite":
                reviewer = self.get_argument("reviewer", "").strip()
                token = await run(_invite, self.database, name, reviewer, p)
                base = f"{self.request.protocol}://{self.request.host}"
                await WorkshopPage.get(self, name, link=f"{base}/review/{token}")
                return
            status = {"close": "closed", "reopen": "open"}.get(self.get_argument("status", ""))
            if status is None:
                raise InvalidParameter("status must be close or reopen")
            await run(_set_status, self.database, name, status, p)
        except RailvalError as exc:
            self.set_status(400)
            await WorkshopPage.get(self, name, message=str(exc))
            return
        self.redirect(f"/workshops/{quote(name, safe='')}")


# -------------------------------------------------------------------------- analysis
def _analysis(database, name: str, actor) -> dict[str, Any]:
    from railval.app.services.workshops import analyse

    return analyse(database, name, actor=actor, with_plots=True)


def _fmt(x: Any, digits: int = 2) -> str:
    if x is None:
        return "—"
    if isinstance(x, (list, tuple)) and len(x) == 2:
        return f"{_fmt(x[0], digits)} … {_fmt(x[1], digits)}"
    try:
        return f"{float(x):.{digits}f}"
    except (TypeError, ValueError):
        return esc(x)


def threshold_png(doc: dict[str, Any], column: str, label: str, limit: float | None) -> str:
    """The answers against an objective value (``deviation`` or ``sg_c``): each plot's share
    of Yes (points), the fitted curve of a typical reviewer
    (:func:`railval.core.review.yes_curve`), the value at 50 % with its interval, and the
    limit; returned as a PNG data URL."""
    import numpy as np
    from matplotlib.figure import Figure
    from railval.core.review import yes_curve

    thr = doc.get("threshold") or {}
    at50 = thr.get("deviation_at_50" if column == "deviation" else "sg_c_at_50")
    ci = thr.get("ci" if column == "deviation" else "sg_c_ci")
    fit = thr.get(f"{column}_fit") or {}
    pts = [(r[column], r["yes_share"]) for r in doc.get("plots", [])
           if r.get(column) is not None and r.get("yes_share") is not None]
    fig = Figure(figsize=(7.5, 3.4), dpi=100)
    ax = fig.add_subplot(1, 1, 1)
    top = max([1.5 if limit else 0.5] + [x for x, _ in pts] + [at50 or 0.0] + list(ci or [0.0]))
    if pts:
        ax.scatter([x for x, _ in pts], [y for _, y in pts], s=14, color="#999999",
                   label="share of Yes of one plot", zorder=2)
    if fit.get("intercept") is not None and fit.get("slope") is not None:
        xs = np.linspace(top / 400, top * 1.05, 400)
        ax.plot(xs, yes_curve(xs, fit["intercept"], fit["slope"]), color="#0072B2",
                label="fitted P(Yes), typical reviewer", zorder=3)
    if at50 is not None:
        if ci and None not in ci:
            ax.errorbar([at50], [0.5], xerr=[[at50 - ci[0]], [ci[1] - at50]], fmt="o",
                        color="#0072B2", capsize=5, label=f"50 % Yes at {at50:.2f} (interval)",
                        zorder=4)
        else:
            ax.plot([at50], [0.5], "o", color="#0072B2", label=f"50 % Yes at {at50:.2f}")
    if limit is not None:
        ax.axvline(limit, color="#D55E00", linewidth=2, label=f"validation limit {limit:g}")
    ax.axhline(0.5, color="#bbbbbb", linewidth=0.8, zorder=1)
    ax.set_xlim(0, top * 1.05)
    ax.set_ylim(-0.02, 1.02)
    ax.set_xlabel(label)
    ax.set_ylabel("share of Yes")
    ax.legend(loc="upper right", fontsize=8)
    fig.tight_layout()
    buf = io.BytesIO()
    fig.savefig(buf, format="png", metadata={"Software": None})
    return "data:image/png;base64," + base64.b64encode(buf.getvalue()).decode()


class WorkshopAnalysis(_OrganiserBase):
    async def get(self, name: str) -> None:
        p = await self.require("workshop.results")
        if p is None:
            return
        try:
            doc = await run(_analysis, self.database, name, p)
        except RailvalError as exc:
            self.finish(page(f"Analysis {name}", f"<p class='err'>{esc(exc)}</p>", user=p.username))
            return
        self.finish(page(f"Analysis {name}", analysis_html(doc), user=p.username))


def _pct(x: Any) -> str:
    return "—" if x is None else f"{100 * float(x):.1f} %"


def _pct_ci(ci: Any) -> str:
    if not ci or None in ci:
        return "—"
    return f"{100 * ci[0]:.1f} … {100 * ci[1]:.1f} %"


def _scaling_html(sc: dict[str, Any] | None) -> str:
    if not sc:
        return "<p>not measured (no plots with automatic scaling, or no answers to them)</p>"
    return (f"<table><tr><th>pairs</th><th>answer changed</th><th>interval</th>"
            f"<th>Yes at fixed scaling</th><th>Yes at automatic scaling</th><th>test</th>"
            f"<th>p</th></tr><tr><td class='num'>{sc.get('pairs')}</td>"
            f"<td class='num'>{_pct(sc.get('changed_share'))}</td>"
            f"<td class='num'>{_pct_ci(sc.get('changed_share_ci'))}</td>"
            f"<td class='num'>{_pct(sc.get('fixed_yes_share'))}</td>"
            f"<td class='num'>{_pct(sc.get('auto_yes_share'))}</td><td>{esc(sc.get('test'))}</td>"
            f"<td class='num'>{_fmt(sc.get('p_value'), 3)}</td></tr></table>")


def analysis_html(doc: dict[str, Any]) -> str:
    """The analysis document as HTML tables and charts (all values escaped)."""
    from railval.core.workshop import PLOT_KINDS

    t1 = "".join(f"<tr><td>{esc(PLOT_KINDS[r['kind']].label if r['kind'] in PLOT_KINDS else r['kind'])}"
                 f" <span class='muted'>({esc(r['kind'])})</span></td><td class='num'>{r['plots']}</td>"
                 f"<td class='num'>{_pct(r.get('min_yes'))}</td>"
                 f"<td class='num'>{_pct(r.get('max_yes'))}</td></tr>"
                 for r in doc.get("table1", []))
    rv = "".join(f"<tr><td>{esc(r['reviewer'])}</td><td class='num'>{r['answers']}</td>"
                 f"<td class='num'>{_pct(r.get('yes_share'))}</td>"
                 f"<td class='num'>{_pct_ci(r.get('yes_share_ci'))}</td>"
                 f"<td class='num'>{_fmt(r.get('strictness'))}</td>"
                 f"<td class='num'>{_fmt(r.get('strictness_ci'))}</td>"
                 f"<td class='num'>{_fmt(r.get('consistency'))}</td></tr>"
                 for r in doc.get("reviewers", []))
    ag = doc.get("agreement") or {}
    agr = "".join(f"<tr><td>{esc(k)}</td><td class='num'>{_fmt((v or {}).get('value') if isinstance(v, dict) else v)}</td>"
                  f"<td class='num'>{_fmt((v or {}).get('ci')) if isinstance(v, dict) else '—'}</td></tr>"
                  for k, v in ag.items())
    thr = doc.get("threshold") or {}
    sc = doc.get("scaling_effect")
    charts = (f"<h4>Against the normalised deviation (largest |D_v| / std limit)</h4>"
              f"<img alt='answers against the normalised deviation' "
              f"src='{threshold_png(doc, 'deviation', 'largest |D_v| / std limit', 1.0)}'>"
              f"<p>Sprague–Geers C at 50 % Yes: <strong>{_fmt(thr.get('sg_c_at_50'))}</strong> "
              f"(interval {_fmt(thr.get('sg_c_ci'))})</p>"
              f"<img alt='answers against Sprague–Geers C' "
              f"src='{threshold_png(doc, 'sg_c', 'Sprague–Geers C', None)}'>")
    return f"""
<h2>{esc(doc.get('workshop', ''))}</h2>
<h3>Table 1 — share of Yes per plot kind (min and max over reviewers)</h3>
<table><tr><th>plot kind</th><th>plots</th><th>min Yes</th><th>max Yes</th></tr>{t1}</table>
<h3>Reviewers</h3>
<table><tr><th>reviewer</th><th>answers</th><th>share of Yes</th><th>Wilson 95 % interval</th>
<th>strictness</th><th>interval</th><th>consistency on repeats</th></tr>{rv}</table>
<h3>Agreement</h3><table><tr><th>statistic</th><th>value</th><th>interval</th></tr>{agr}</table>
<h3>Threshold</h3>
<p>Deviation at which a typical reviewer says Yes half of the time:
<strong>{_fmt(thr.get('deviation_at_50'))}</strong> (interval {_fmt(thr.get('ci'))}); the
validation limit is 1.0.</p>{charts}
<h3>Scaling effect (same reviewer, same plot: fixed against automatic scaling)</h3>{_scaling_html(sc)}
"""


def routes(database, auth=None) -> list[tuple]:
    """Tornado URL patterns of the workshop pages (``pn.serve(extra_patterns=…)``);
    ``auth``: the app's sign-in, whose session the organiser pages accept."""
    kw = {"database": database, "auth": auth}
    tok = r"([A-Za-z0-9_\-]{20,100})"
    name = r"([^/]+)"
    return [
        (rf"/review/{tok}/?", ReviewPage, kw),
        (rf"/review/{tok}/state", ReviewState, kw),
        (rf"/review/{tok}/image/(\d+)", ReviewImage, kw),
        (rf"/review/{tok}/answer", ReviewAnswer, kw),
        (rf"/review/{tok}/finish", ReviewFinish, kw),
        (r"/workshops/login", Login, kw),
        (r"/workshops/logout", Logout, kw),
        (r"/workshops/?", WorkshopList, kw),
        (r"/workshops/new", WorkshopNew, kw),
        (r"/workshops/plan", WorkshopPlan, kw),
        (rf"/workshops/{name}/status", _StatusOrPost, kw),
        (rf"/workshops/{name}/invite", _InvitePost, kw),
        (rf"/workshops/{name}/analysis", WorkshopAnalysis, kw),
        (rf"/workshops/{name}", WorkshopPage, kw),
    ]


class _StatusOrPost(WorkshopStatus):
    async def post(self, name: str) -> None:
        await WorkshopPage.post(self, name, "status")


class _InvitePost(WorkshopPage):
    async def post(self, name: str) -> None:  # type: ignore[override]
        await WorkshopPage.post(self, name, "invite")
