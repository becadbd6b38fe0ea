"""Organiser pages: workshop list, create form with the plot count, progress, links,
close/reopen."""

from __future__ import annotations

import json
from typing import Any
from urllib.parse import quote

import tornado.web

from railval.app.workshop_web.common import (
    _OrganiserBase,
    esc,
    page,
    run,
)
from railval.app.workshop_web.reviewer import clear_contexts
from railval.core.errors import InvalidParameter, NotFound, RailvalError
from railval.core.roles import allowed


# -------------------------------------------------------------------------- organiser
def _list_doc(database) -> list[dict[str, Any]]:
    from railval.app.services.workshop_admin import overview

    return overview(database)


class WorkshopList(_OrganiserBase):
    async def get(self) -> None:
        p = await self.require("workshop.run", "workshop.results")
        if p is None:
            return
        rows = await run(_list_doc, self.database)
        runs = allowed(p, "workshop.run")  # else results only: the analysis pages
        tail = "" if runs else "/analysis"
        trs = "".join(
            f"<tr><td><a href='/workshops/{quote(r['name'], safe='')}{tail}'>{esc(r['name'])}</a></td>"
            f"<td>{esc(r['campaign'])}</td><td>{esc(r['status'])}</td>"
            f"<td>{'yes' if r['blind'] else 'no'}</td><td class='num'>{r['reviewers']}</td>"
            f"<td class='num'>{r['answers']}</td></tr>" for r in rows)
        new = "<p><a class='btn' href='/workshops/new'>New workshop</a></p>" if runs else ""
        body = (f"{new}"
                f"<table><tr><th>workshop</th><th>campaign</th><th>status</th><th>blind</th>"
                f"<th>reviewers</th><th>answers</th></tr>{trs}</table>")
        self.finish(page("Workshops", body, user=p, current="/workshops"))


def _form_choices(database) -> dict[str, Any]:
    from railval.app.services.workshop_admin import campaign_choices
    from railval.app.services.workshops import describe_kinds

    return {"campaigns": campaign_choices(database), "kinds": describe_kinds()}


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
  document.getElementById('count').textContent += ' — rendering, please wait…'; };
fill();
"""


def _plan_doc(database, args: dict[str, list[str]]) -> dict[str, Any]:
    from railval.app.services.workshop_admin import plan_counts

    # the form sends the ticked boxes only: a group with none ticked gives no plot
    if not all(args.get(g) for g in ("configurations", "sections", "kinds")):
        return {"plots": 0, "by_kind": {}}
    return plan_counts(database, (args.get("campaign") or [""])[0], args["configurations"],
                       args["sections"], args["kinds"])


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
    from railval.app.services import workshops as ws

    if not all(args.get(g) for g in ("configurations", "sections", "kinds")):
        return {"plots": 0, "scalings": {}}
    return ws.scaling_preview(database, (args.get("campaign") or [""])[0], args["configurations"],
                              args["sections"], args["kinds"], actor=actor)


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
                      auto_share=float((a.get("auto_share") or ["0"])[0]),
                      scaling=(a.get("scaling") or ["zone"])[0], actor=p)
        except (RailvalError, ValueError) as exc:
            self.set_status(400)
            await self.get(message=str(exc))
            return
        self.redirect(f"/workshops/{quote(name, safe='')}")


def _status_doc(database, name: str) -> dict[str, Any]:
    from railval.app.services.workshop_admin import status

    return status(database, name)


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
    from railval.app.services.workshop_admin import invite

    return invite(database, name, reviewer, actor=actor)


def _set_status(database, name: str, status: str, actor) -> None:
    from railval.app.services.workshop_admin import set_status

    set_status(database, name, status, actor=actor)
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
    from railval.app.services.workshop_admin import participations

    return participations(database, username)


def _own_link(database, name: str, username: str) -> str:
    from railval.app.services.workshop_admin import own_link

    return own_link(database, name, username)


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
