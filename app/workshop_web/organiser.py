"""Organiser pages: workshop list, create form with the plot count, creation as a job with
its progress, links, close/reopen.

Length: the organiser's path through one workshop — form, creation job, the page that shows
the job and then the workshop — reads as one flow; the creation job's pieces are small
helpers of these handlers.
"""

from __future__ import annotations

import json
from typing import Any
from urllib.parse import quote

import tornado.web

from railval.app.services import workshops as workshops_service
from railval.app.services.workshop_documents import describe_kinds
from railval.app.workshop_web.common import (
    _OrganiserBase,
    esc,
    page,
    run,
)
from railval.app.workshop_web.reviewer import clear_contexts
from railval.core import lazy
from railval.core.errors import InvalidParameter, NotFound, RailvalError
from railval.core.roles import allowed

#: deferred (railval.core.lazy): the jobs list imports the Panel app's side (≈ 1 280 modules more
#: than these pages), the workshop administration 20; loaded on first use
jobs_state = lazy.module("railval.app.state.jobs")
workshop_admin = lazy.module("railval.app.services.workshop_admin")


# -------------------------------------------------------------------------- organiser
def _list_doc(database) -> list[dict[str, Any]]:
    return workshop_admin.overview(database)


class WorkshopList(_OrganiserBase):
    async def get(self) -> None:
        p = await self.require("workshop.run", "workshop.results")
        if p is None:
            return
        rows = await run(_list_doc, self.database)
        runs = allowed(p, "workshop.run")  # else results only: the analysis pages
        tail = "" if runs else "/analysis"
        trs = _creating_rows(p.username, {r["name"] for r in rows}) if runs else ""
        trs += "".join(
            f"<tr><td><a href='/workshops/{quote(r['name'], safe='')}{tail}'>{esc(r['name'])}</a></td>"
            f"<td>{esc(r['campaign'])}</td><td>{esc(r['status'])}</td>"
            f"<td>{'yes' if r['blind'] else 'no'}</td><td class='num'>{r['reviewers']}</td>"
            f"<td class='num'>{r['answers']}</td></tr>" for r in rows)
        new = "<p><a class='btn' href='/workshops/new'>New workshop</a></p>" if runs else ""
        if not trs:  # an empty table says nothing: say what there is and how to begin
            hint = ("Create one with “New workshop” (or <code>railval workshop create</code>)."
                    if runs else "An organiser creates them.")
            body = f"{new}<p class='rv-empty muted'>No workshop yet. {hint}</p>"
        else:
            body = (f"{new}"
                    f"<table><tr><th>workshop</th><th>campaign</th><th>status</th><th>blind</th>"
                    f"<th>reviewers</th><th>answers</th></tr>{trs}</table>")
        self.finish(page("Workshops", body, user=p, current="/workshops"))


def _creation_text(job: dict[str, Any]) -> str:
    """A creation job's state in words: ``being created, 240 of 576`` (plots rendered)."""
    if job["state"] == "failed":
        return f"creation failed: {job['error']}"
    if job["state"] == "queued":
        return "being created (queued)"
    if job.get("total"):
        return f"being created, {job.get('done') or 0} of {job['total']}"
    return f"being created ({job.get('message') or 'starting'})"


def _creating_rows(username: str, stored: set[str]) -> str:
    """Table rows of ``username``'s workshops being created (or whose creation failed)."""
    out = []
    for j in jobs_state.jobs_of(username):
        name = j.get("workshop")
        if not name or name in stored or j["state"] in ("done", "cancelled"):
            continue
        out.append(f"<tr class='rv-creating' data-state='{esc(j['state'])}'><td><a href='"
                   f"/workshops/{quote(name, safe='')}'>{esc(name)}</a></td><td></td>"
                   f"<td class='rv-creating-state'>{esc(_creation_text(j))}</td>"
                   f"<td></td><td class='num'></td><td class='num'></td></tr>")
    return "".join(out)


def _form_choices(database) -> dict[str, Any]:
    return {"campaigns": workshop_admin.campaign_choices(database), "kinds": describe_kinds()}


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
function fmt(x) { return Math.abs(x) >= 1e4 || (x !== 0 && Math.abs(x) < 1e-2) ? x.toExponential(0) : String(x); }
async function preview() {
  const out = document.getElementById('preview'); out.textContent = 'reading and filtering the signals…';
  const q = new URLSearchParams(new FormData(form));
  const r = await fetch('/workshops/scaling-preview?' + q.toString());
  const d = await r.json();
  if (!r.ok) { out.textContent = d.error; return; }
  if (!d.plots) { out.textContent = 'no plot'; return; }
  let html = '';
  for (const [sc, v] of Object.entries(d.scalings)) {
    html += '<h4>' + (sc === 'zone' ? 'by test zone' : 'whole workshop') + (sc === d.default ? ' (default)' : '') + '</h4>';
    html += '<table class="preview" data-scaling="' + sc + '"><tr><th>plot kind</th><th>zone</th><th>y axis</th><th>y range</th><th>x range</th><th>plots</th><th>flat (signal &lt; 10 % of the y range)</th></tr>';
    for (const g of v.ranges) {
      html += '<tr><td>' + kl[g.kind] + '</td><td>' + (g.zone === null ? 'all' : g.zone) + '</td><td>' + g.y_label + '</td><td class="num">' +
        fmt(g.y[0]) + ' … ' + fmt(g.y[1]) + ' ' + (g.log ? '(log) ' : '') + '</td><td class="num">' + fmt(g.x[0]) + ' … ' + fmt(g.x[1]) + ' ' + (g.x_label.includes(' in ') ? g.x_label.split(' in ').pop() : '') +
        '</td><td class="num">' + g.plots + '</td><td class="num">' + g.flat + '</td></tr>'; }
    html += '</table><p>Share of flat plots per kind: ' + Object.entries(v.flat_share).map(([k, s]) =>
      k + ' ' + Math.round(100 * s) + ' %').join(', ') + '</p>'; }
  out.innerHTML = html;
}
document.getElementById('previewbtn').onclick = preview;
form.campaign.onchange = fill; form.onsubmit = () => { document.getElementById('create').disabled = true;
  document.getElementById('count').textContent += ' — starting the creation…'; };
fill();
"""


def _plan_doc(database, args: dict[str, list[str]]) -> dict[str, Any]:
    # the form sends the ticked boxes only: a group with none ticked gives no plot
    if not all(args.get(g) for g in ("configurations", "sections", "kinds")):
        return {"plots": 0, "by_kind": {}}
    return workshop_admin.plan_counts(database, (args.get("campaign") or [""])[0],
                                      args["configurations"], args["sections"], args["kinds"])


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


def _preview_doc(database, args: dict[str, list[str]], actor) -> dict[str, Any]:
    if not all(args.get(g) for g in ("configurations", "sections", "kinds")):
        return {"plots": 0, "scalings": {}}
    return workshops_service.scaling_preview(database, (args.get("campaign") or [""])[0],
                                             args["configurations"], args["sections"], args["kinds"],
                                             actor=actor)


class WorkshopScalingPreview(_OrganiserBase):
    """The ranges each scaling would give and the share of flat plots (the form's preview)."""

    async def get(self) -> None:
        p = await self.require("workshop.run")
        if p is None:
            return
        try:
            self.json(await run(_preview_doc, self.database, _args(self), p))
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
section names)</label> <label>hidden repeats <input name='repeats' value='0.1' size='4'
aria-describedby='repeats-help'></label>
<label>share also shown with automatic scaling <input name='auto_share' value='0' size='4'
aria-describedby='auto-help'></label></p>
<p class='help' style='color:#555;font-size:13px;margin-top:-6px'><span id='repeats-help'><b>Hidden
repeats</b> (0 to 0.5): the share of plots shown a second time, unannounced among the others, to
measure whether each reviewer gives the same answer twice; 0.1 = one plot in ten is repeated.</span><br>
<span id='auto-help'><b>Share also shown with automatic scaling</b> (0 to 1): the share of plots shown
a second time with each plot's own y range instead of the common range, to measure how the scaling
changes the answers; 0 = every plot uses the common range only.</span></p>
<p><label>Scaling <select name='scaling'><option value='zone' selected>same range per kind within each
EN 14363 test zone</option><option value='workshop'>same range per kind over the whole workshop</option></select></label>
<button id='previewbtn' type='button'>Preview ranges</button></p>
<div id='preview'></div>
<p>Count: <strong id='count'>…</strong></p>
<p><button id='create' type='submit'>Create workshop</button></p>
<p class='err'>{esc(message)}</p></form>
<script type='application/json' id='choices'>{choices_json}</script>"""
        self.finish(page("New workshop", body, user=p, script=_NEW_JS))

    async def post(self) -> None:
        """Check the choices, start the creation as a job of this user (plots rendered n of
        N on the workshop's page and in the list) and go to the workshop's page at once."""
        p = await self.require("workshop.run")
        if p is None:
            return
        a = _args(self)
        try:
            name = (a.get("name") or [""])[0]
            campaign = (a.get("campaign") or [""])[0]
            opts = _create_options(a)
            planned = await run(_check_new, self.database, name, campaign, opts, p)
            _start_creation(self.database, name, campaign, opts, p, planned)
        except (RailvalError, ValueError) as exc:
            self.set_status(400)
            await self.get(message=str(exc))
            return
        self.redirect(f"/workshops/{quote(name, safe='')}")


def _create_options(a: dict[str, list[str]]) -> dict[str, Any]:
    """The form's choices as :func:`railval.app.services.workshops.create` takes them."""
    def number(field: str, default: str) -> float:
        raw = (a.get(field) or [default])[0]
        try:
            return float(raw)
        except ValueError:
            raise InvalidParameter(f"{field}: {raw!r} is not a number") from None
    return {"configurations": a.get("configurations") or ["(none chosen)"],
            "sections": a.get("sections") or ["(none chosen)"],
            "kinds": a.get("kinds") or ["(none chosen)"], "blind": bool(a.get("blind")),
            "repeats": number("repeats", "0.1"), "auto_share": number("auto_share", "0"),
            "scaling": (a.get("scaling") or ["zone"])[0]}


def _check_new(database, name: str, campaign: str, opts: dict[str, Any], actor) -> int:
    return workshop_admin.check_new(database, name, campaign, configurations=opts["configurations"],
                                    sections=opts["sections"], kinds=opts["kinds"], scaling=opts["scaling"],
                                    repeats=opts["repeats"], auto_share=opts["auto_share"], actor=actor)


def _start_creation(database, name: str, campaign: str, opts: dict[str, Any], actor,
                    planned: int | None = None) -> None:
    """Create the workshop in a job of ``actor``'s (:func:`railval.app.state.jobs.start_tracked`):
    nothing is stored until every plot is rendered, so a failure leaves nothing behind.
    ``planned``: the plots :func:`_check_new` counted (the render workers start at once)."""
    def work(progress):
        return workshops_service.create(database, name, campaign, **opts, actor=actor, progress=progress,
                                        planned_plots=planned)

    jobs_state.start_tracked(actor.username, f"Create workshop {name}", work,
                             link=f"/workshops/{quote(name, safe='')}", workshop=name)


def _status_doc(database, name: str) -> dict[str, Any]:
    return workshop_admin.status(database, name)


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
      const rep = rv.total - d.plots;  // the hidden repeats count in the reviewer's total
      const cells = [rv.reviewer, rv.answered + ' of ' + rv.total + (rep > 0 ? ' (' + d.plots
                     + ' plots + ' + rep + ' hidden repeats)' : ''), '', rv.finished ? 'finished' : '',
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


_CREATION_JS = r"""
const wname = document.body.dataset.workshop;
async function poll() {
  try {
    const r = await fetch('/workshops/' + encodeURIComponent(wname) + '/creation', {cache: 'no-store'});
    if (!r.ok) { location.reload(); return; }
    const j = await r.json();
    const box = document.getElementById('creation');
    box.dataset.state = j.state;
    if (j.state === 'done') { location.reload(); return; }
    let t = j.state === 'failed' ? 'creation failed: ' + j.error :
            j.state === 'queued' ? 'being created (queued)' :
            j.total ? 'being created, ' + (j.done || 0) + ' of ' + j.total : 'being created (' + (j.message || 'starting') + ')';
    document.getElementById('creation-text').textContent = t + ' · ' + Math.round(j.elapsed_s) + ' s';
    document.getElementById('creation-bar').style.width = (100 * j.fraction) + '%';
    if (j.state !== 'failed') setTimeout(poll, 700);
  } catch (e) { setTimeout(poll, 2000); }
}
setTimeout(poll, 300);
"""


class WorkshopCreation(_OrganiserBase):
    """``GET /workshops/{name}/creation``: the signed-in user's job creating ``name`` (JSON:
    state, fraction, done, total, elapsed_s, error); 404 when the user creates none."""

    async def get(self, name: str) -> None:
        p = await self.require("workshop.run")
        if p is None:
            return
        job = jobs_state.workshop_job(p.username, name)
        if job is None:
            self.json({"error": f"you are creating no workshop {name!r}"}, 404)
            return
        self.json(job)


class MyJobs(_OrganiserBase):
    """``GET /workshops/mine/jobs``: the signed-in user's running and recently finished jobs
    (:func:`railval.app.state.jobs.jobs_of`; never another user's)."""

    async def get(self) -> None:
        p = await self.principal()
        if p is None:
            self.json({"error": "not signed in"}, 401)
            return
        self.json({"jobs": jobs_state.jobs_of(p.username)})


def _invite(database, name: str, reviewer: str, actor) -> str:
    return workshop_admin.invite(database, name, reviewer, actor=actor)


def _set_status(database, name: str, status: str, actor) -> None:
    workshop_admin.set_status(database, name, status, actor=actor)
    clear_contexts()


class WorkshopPage(_OrganiserBase):
    async def get(self, name: str, link: str = "", message: str = "") -> None:
        p = await self.require("workshop.run")
        if p is None:
            return
        try:
            d = await run(_status_doc, self.database, name)
        except NotFound as exc:
            if not self._creation_page(p, name):
                self.set_status(404)
                self.finish(page("Workshop", f"<p class='err'>{esc(exc)}</p>", user=p))
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
hidden repeats {100 * d['repeats']:.0f} % · scaling: {'by test zone' if d.get('scaling') == 'zone'
else 'whole workshop'} · status <strong id='wstatus'>{esc(d['status'])}</strong> ·
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
        html_page = page(f"Workshop {name}", body, user=p, script=_STATUS_JS)
        self.finish(html_page.replace("<body>", f"<body data-workshop='{esc(name)}'>", 1))

    def _creation_page(self, p, name: str) -> bool:
        """The page of a workshop this user is creating: its progress, live (or the error of
        a failed creation); False when the user creates no workshop of that name."""
        job = jobs_state.workshop_job(p.username, name)
        if job is None or job["state"] == "done":
            return False
        failed = job["state"] == "failed"
        body = (f"<h2>{esc(name)}</h2><div id='creation' data-state='{esc(job['state'])}'>"
                f"<p id='creation-text'>{esc(_creation_text(job))} · {job['elapsed_s']:.0f} s</p>"
                f"<div class='bar' style='max-width:600px'><div id='creation-bar' style='width:"
                f"{100 * job['fraction']:.0f}%'></div></div>"
                + ("<p class='err'>Nothing was stored. <a href='/workshops/new'>Try again</a></p>"
                   if failed else
                   "<p class='muted'>You can leave this page: the workshop is created in the "
                   "background and listed under Workshops; nothing is stored until every plot "
                   "is rendered.</p>") + "</div>")
        html_page = page(f"Workshop {name}", body, user=p, script="" if failed else _CREATION_JS)
        self.finish(html_page.replace("<body>", f"<body data-workshop='{esc(name)}'>", 1))
        return True

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


# -------------------------------------------------------------------------- my workshops
def _mine(database, username: str) -> list[dict[str, Any]]:
    return workshop_admin.participations(database, username)


def _own_link(database, name: str, username: str) -> str:
    return workshop_admin.own_link(database, name, username)


class MyWorkshops(_OrganiserBase):
    """``/workshops/mine``: a signed-in panelist's workshops with their progress; "Open"
    (a ``POST``) issues a fresh personal link of the own participation and opens it."""

    async def get(self, message: str = "") -> None:
        p = await self.require("workshop.answer")
        if p is None:
            return
        rows = await run(_mine, self.database, p.username)
        trs = "".join(
            f"<tr><td>{esc(r['workshop'])}</td><td>{esc(r['status'])}</td>"
            f"<td class='num'>{r['answered']} of {r['total']}</td>"
            f"<td>{'finished' if r['finished'] else ''}</td><td>"
            + (f"<form method='post' action='/workshops/mine/{quote(r['workshop'], safe='')}/open'>"
               f"<button type='submit' class='rv-open-review'>Open review</button></form>"
               if r["status"] == "open" and not r["finished"] else "")
            + "</td></tr>" for r in rows)
        body = ("<h2>My workshops</h2>"
                + (f"<table id='mine'><tr><th>workshop</th><th>status</th><th>answered</th>"
                   f"<th>state</th><th></th></tr>{trs}</table>" if rows else
                   "<p>You take part in no workshop yet; the organiser invites you.</p>")
                + "<p class='muted'>Opening a review here replaces the personal link you were "
                  "sent; your answers stay.</p>"
                + (f"<p class='err'>{esc(message)}</p>" if message else ""))
        self.finish(page("My workshops", body, user=p, current="/workshops/mine"))

    async def post(self, name: str) -> None:
        p = await self.require("workshop.answer")
        if p is None:
            return
        try:
            token = await run(_own_link, self.database, name, p.username)
        except RailvalError as exc:
            self.set_status(404 if isinstance(exc, NotFound) else 400)
            await self.get(message=str(exc))
            return
        clear_contexts()
        self.redirect(f"/review/{token}")
