"""Reviewer pages: one plot at a time behind a personal link, answers stored at once."""

from __future__ import annotations

import datetime as dt
import hashlib
import json
import threading
import time
from typing import Any

from railval.app.services import workshop_review
from railval.app.workshop_web.common import (
    _Base,
    page,
    run,
)
from railval.core import lazy
from railval.core.errors import InvalidParameter, NotFound, RailvalError
from railval.core.roles import PermissionDenied, allowed

#: deferred (railval.core.lazy): the app's sign-in (32 modules more than these pages), loaded on
#: the first request that carries its cookie
app_auth = lazy.module("railval.app.auth")

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
    key = hashlib.sha256(token.encode()).hexdigest()
    now = time.monotonic()
    with _cache_lock:
        hit = _contexts.get(key)
    if hit is not None and now - hit[0] < CONTEXT_TTL_S:
        return hit[1]
    ctx = workshop_review.context(database, token)
    with _cache_lock:
        if len(_contexts) > 10_000:
            _contexts.clear()
        _contexts[key] = (now, ctx)
    return ctx


def _state(database, ctx) -> dict[str, Any]:
    own = workshop_review.answers(database, ctx.reviewer_id)
    total = len(ctx.sequence)
    nxt = next((i for i in range(total) if i not in own), total)
    return {"total": total, "answered": len(own), "next": nxt, "finished": ctx.finished,
            "status": ctx.workshop_status, "blind": ctx.blind,
            "workshop": None if ctx.blind else ctx.workshop_name,
            "answers": {str(i): {"answer": "yes" if a["answer"] else "no", "comment": a["comment"],
                                 "changes": a["changes"], "at": a["updated_at"]}
                        for i, a in own.items()}}


class _ReviewerBase(_Base):
    #: the personal link is the credential: a page opened by link alone carries the
    #: pre-session anti-forgery token (railval.app.security.SessionBoundXsrf)
    accepts_presession_token = True

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
function cap(a) { return a === 'yes' ? 'Yes' : 'No'; }
function hhmm(iso) { const d = iso ? new Date(iso) : new Date();
  return String(d.getHours()).padStart(2, '0') + ':' + String(d.getMinutes()).padStart(2, '0'); }
async function refresh() {
  const r = await fetch(base + '/state', {cache: 'no-store'});
  if (r.ok) { st = await r.json(); return true; } return false; }
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
  $('prevnote').textContent = a ? ('Your answer: ' + a.answer + (a.changes ? ' (changed, last at '
    + hhmm(a.at) + ')' : '') + ' (press Yes or No to change it)') : '';
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
      const r = await fetch(base + path, {method: 'POST', headers: {'Content-Type': 'application/json',
                                          'X-XSRFToken': document.querySelector('meta[name=xsrf-token]').content},
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
  const at = pos;
  const doc = await post('/answer', body);
  busy = false;
  if (!doc) return;
  // another tab (or an earlier visit) had answered this plot otherwise: say so, keep both
  if (doc.stored === 'changed' && doc.previous && doc.previous !== value) {
    $('changed').textContent = 'Plot ' + (at + 1) + ': you changed your answer from '
      + cap(doc.previous) + ' to ' + cap(value) + ' at ' + hhmm(doc.at) + ' (the answer '
      + cap(doc.previous) + ' was stored at ' + hhmm(doc.previous_at) + ').';
  } else { $('changed').textContent = ''; }
  st.answers[at] = {answer: value, comment: body.comment,
                    changes: doc.stored === 'changed' ? 1 : 0, at: doc.at};
  pos = firstOpen(at + 1);
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
// a tab coming back to the front shows what other tabs stored meanwhile
document.addEventListener('visibilitychange', async () => {
  if (document.visibilityState === 'visible' && st && !busy && await refresh()) show(); });
(async () => {
  await refresh();
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
<p id='changed' class='rv-changed' role='status'></p>
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
        html_page = page(title, body, user=ctx.username, script=_REVIEW_JS)
        if await self.signed_in():  # one click ends the session on the server (POST /logout)
            html_page = html_page.replace("</header>", _SIGN_OUT + "</header>", 1)
        self.finish(html_page)

    async def signed_in(self) -> bool:
        """True when the request carries a live session of the app's sign-in."""
        raw = self.get_cookie(app_auth.COOKIE) if self.auth is not None else None
        if not raw:
            return False
        p = await run(self.auth.principal_from_cookie, raw)
        return p is not None and not p.open_mode


_SIGN_OUT = ("<form method='post' action='/logout' class='rv-review-signout' style='margin:0'>"
             "<button type='submit' id='review-signout' style='font-size:14px;padding:3px 10px'>"
             "Sign out</button></form>")


class ReviewState(_ReviewerBase):
    async def get(self, token: str) -> None:
        ctx = await self.context(token)
        if ctx is not None:
            self.json(await run(_state, self.database, ctx))


def _image_at(database, ctx, position: int) -> tuple[bytes, str]:
    key = (ctx.workshop_id, ctx.sequence[position][0])
    with _cache_lock:
        hit = _images.get(key)
    if hit is not None:
        return hit
    data, sha = workshop_review.plot_image(database, *key)
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
    ctx = _ctx(database, token)
    if ctx is None or not allowed(ctx.principal, "workshop.answer"):
        raise NotFound("review link not valid")
    if ctx.finished:
        raise workshop_review.WorkshopClosed("you have finished this review; answers are final")
    ans = str(body.get("answer", "")).lower()
    if ans not in ("yes", "no"):
        raise InvalidParameter(f"answer must be yes or no, got {body.get('answer')!r}")
    try:
        position = int(body.get("position"))
        seconds = float(body.get("seconds", 0.0))
    except (TypeError, ValueError):
        raise InvalidParameter("position must be a whole number and seconds a number") from None
    outcome = workshop_review.record_answer(database, ctx, position, ans == "yes", seconds=seconds,
                                            comment=str(body.get("comment") or ""),
                                            submission=str(body.get("submission") or ""))
    doc = {"stored": str(outcome), "position": position, "at": _utc_now()}
    if outcome.previous is not None:  # the answer this one replaced (another tab's, maybe)
        doc["previous"] = "yes" if outcome.previous else "no"
        doc["previous_at"] = _iso(outcome.previous_at)
    return doc


def _utc_now() -> str:
    return _iso(dt.datetime.now(dt.UTC))


def _iso(when) -> str | None:
    """ISO 8601 UTC with a ``Z`` (the browser shows it in local time)."""
    if when is None:
        return None
    return when.strftime("%Y-%m-%dT%H:%M:%SZ")


def _finish(database, token: str) -> dict[str, Any]:
    workshop_review.finish(database, token, lambda ctx: allowed(ctx.principal, "workshop.answer"))
    clear_contexts()
    return {"finished": True}


class ReviewAnswer(_Base):
    accepts_presession_token = True

    async def post(self, token: str) -> None:
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
        except PermissionDenied as exc:
            self.json({"error": str(exc)}, 403)
        except workshop_review.WorkshopClosed as exc:
            self.json({"error": str(exc)}, 409)
        except RailvalError as exc:
            self.json({"error": str(exc)}, 400)


class ReviewFinish(_Base):
    accepts_presession_token = True

    async def post(self, token: str) -> None:
        try:
            self.json(await run(_finish, self.database, token))
        except NotFound as exc:
            self.json({"error": str(exc)}, 404)
        except PermissionDenied as exc:
            self.json({"error": str(exc)}, 403)
        except RailvalError as exc:
            self.json({"error": str(exc)}, 400)
