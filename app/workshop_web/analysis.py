"""Analysis page: Table 1, reviewers, agreement, the 50 % deviation beside the limit 1.0."""

from __future__ import annotations

import base64
import io
from typing import Any

from railval.app.workshop_web.common import (
    _OrganiserBase,
    esc,
    page,
    run,
)
from railval.core.errors import RailvalError


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


def _sensitivity_html(sens: dict | None) -> str:
    """One sentence: the 50 % deviation under every parametric link and their spread."""
    if not sens:
        return ""
    links = ", ".join(f"{esc(r['link'])} {_fmt(r.get('at_50'))}" for r in sens.get("links", []))
    spread = sens.get("relative_spread")
    return (f"Link sensitivity (logistic fits): {links}; likeliest {esc(sens.get('chosen'))}; spread "
            f"{'—' if spread is None else f'{100 * spread:.0f} %'} of the reported value.")


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
        ax.plot(xs, yes_curve(xs, fit["intercept"], fit["slope"], power=fit.get("power") or 0.0),
                color="#0072B2", label=f"fitted P(Yes), typical reviewer ({fit.get('link', 'log')} link)",
                zorder=3)
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


def _cards(database, name: str, groups: list[str], actor) -> dict[str, Any]:
    from railval.app.services.workshops import cards
    from railval.db import workshops as wsdb

    doc = cards(database, name, groups=groups, actor=actor)
    with database.session() as s:
        w = wsdb.get_workshop(s, name)
        doc["others"] = [x.name for x in wsdb.list_workshops(s)
                         if x.campaign_id == w.campaign_id and x.name != name]
    return doc


class WorkshopAnalysis(_OrganiserBase):
    async def get(self, name: str) -> None:
        p = await self.require("workshop.results")
        if p is None:
            return
        groups = [g for g in self.get_arguments("groups") if g]
        try:
            doc = await run(_analysis, self.database, name, p)
            card_doc = await run(_cards, self.database, name, groups, p)
        except RailvalError as exc:
            self.finish(page(f"Analysis {name}", f"<p class='err'>{esc(exc)}</p>", user=p.username))
            return
        self.finish(page(f"Analysis {name}", analysis_html(doc) + cards_html(card_doc),
                         user=p.username, script=_CARDS_JS))


class WorkshopPlotImage(_OrganiserBase):
    """A stored plot image for the organiser's and assessor's cards (exactly the reviewed bytes)."""

    async def get(self, name: str, plot_id: str) -> None:
        p = await self.require("workshop.results")
        if p is None:
            return
        try:
            data, sha = await run(_plot_image, self.database, name, int(plot_id))
        except RailvalError:
            self.set_status(404)
            self.finish("no such plot")
            return
        self.set_header("Content-Type", "image/png")
        self.set_header("X-Image-SHA256", sha)
        self.set_header("Cache-Control", "private, max-age=86400")
        self.finish(data)


def _plot_image(database, name: str, plot_id: int) -> tuple[bytes, str]:
    from railval.db import workshops as wsdb

    with database.session() as s:
        return wsdb.plot_image(s, wsdb.get_workshop(s, name).id, plot_id)


#: the cards' filters: show a card when it matches every chosen value
_CARDS_JS = r"""
const filters = document.querySelectorAll('#cardfilter select');
function apply() {
  let shown = 0;
  for (const c of document.querySelectorAll('.card')) {
    let ok = true;
    for (const f of filters) if (f.value && c.dataset[f.name] !== f.value) ok = false;
    c.style.display = ok ? '' : 'none'; if (ok) shown++;
  }
  document.getElementById('cardcount').textContent = shown;
}
for (const f of filters) f.onchange = apply;
apply();
"""


#: the layout of a card: image left, tables right (also used by the validation report)
CARD_CSS = (".card{display:flex;gap:16px;align-items:flex-start;border-top:1px solid #ccc;padding:10px 0;"
            "break-inside:avoid}.card img{width:560px;max-width:55%;height:auto;border:1px solid #ddd}"
            ".card h4{margin:0 0 6px}.card table{margin-bottom:8px}")


def agreement_of(card: dict[str, Any]) -> str:
    """Whether the majority of the reviewers agrees with the objective verdict of the plot
    (deviation ≤ 1.0 ↔ Yes): ``agree``, ``disagree``, ``split`` (exactly half) or ``n/a``
    (no answers or no objective value)."""
    share, dev = card.get("yes_share"), card.get("deviation")
    if share is None or dev is None:
        return "n/a"
    if share == 0.5:
        return "split"
    return "agree" if (share > 0.5) == (dev <= 1.0) else "disagree"


_AGREEMENT_TEXT = {"agree": "reviewers agree with the limit", "disagree": "reviewers disagree with the limit",
                   "split": "reviewers split half and half", "n/a": "no answers or no objective value"}


def card_html(c: dict[str, Any], src: str, labels: dict[str, str], *, lazy: bool = True) -> str:
    """One plot card (Polach & Böttcher 2014 Figs. 3–5): the stored plot (``src``: its URL
    or data URL), beside it the EN values with their differences, the shares of Yes of every
    group and the Sprague–Geers errors (all text escaped). ``lazy``: the browser loads the
    image when it scrolls into view (the page; a printed report needs every image now)."""
    en = "".join(f"<tr><td>{esc(e['quantity'])} <span class='muted'>({esc(e.get('unit', ''))})</span></td><td class='num'>{_fmt(e['measured'])}</td>"
                 f"<td class='num'>{_fmt(e['simulated'])}</td><td class='num'>{_fmt(e['abs_diff'])}</td>"
                 f"<td class='num'>{_pct(e['rel_diff'])}</td></tr>" for e in c["en"]) \
        or "<tr><td colspan='5' class='muted'>no EN 14363 quantity for this signal</td></tr>"
    groups = "".join(f"<tr><td>{esc(g['workshop'])}</td><td class='num'>{_pct(g['yes_share'])}</td>"
                     f"<td class='num'>{g['answers']}</td></tr>" for g in c["groups"])
    sg = c.get("sg") or {}
    sg_txt = ("not computed (Y/Q is not a recorded channel)" if not sg else
              f"M {_fmt(sg.get('M'), 3)}, P {_fmt(sg.get('P'), 3)}, C {_fmt(sg.get('C'), 3)}")
    agree = agreement_of(c)
    return (f"<div class='card' data-kind='{esc(c['kind'])}' data-zone='{c['zone']}' "
            f"data-configuration='{esc(c['configuration'])}' data-agreement='{agree}'>"
            f"<img{' loading=lazy' if lazy else ''} alt='plot {int(c['plot'])}' src='{src}'>"
            f"<div><h4>{esc(labels.get(c['kind'], c['kind']))}, {esc(c['channel'])} — section "
            f"{esc(c['section'])} (zone {c['zone']}), configuration {esc(c['configuration'])}</h4>"
            f"<table><tr><th>EN 14363 value</th><th>measurement</th><th>simulation</th>"
            f"<th>S − M</th><th>(S − M)/|M|</th></tr>{en}</table>"
            f"<table><tr><th>reviewer group</th><th>share of Yes</th><th>answers</th></tr>{groups}</table>"
            f"<p>Sprague–Geers: {sg_txt}<br>normalised deviation (largest |D_v| / std limit): "
            f"{_fmt(c.get('deviation'))} — {_AGREEMENT_TEXT[agree]}</p></div></div>")


def cards_html(doc: dict[str, Any]) -> str:
    """The plot cards with their filters (kind, zone, configuration, agreement) and the
    choice of a second reviewer group (a GET form: it changes nothing)."""
    from railval.app.services.workshops import kind_labels

    labels = kind_labels()
    cards = doc.get("cards", [])

    def select(name: str, label: str, values, text=None) -> str:
        opts = "".join(f"<option value='{esc(v)}'>{esc(text(v) if text else v)}</option>" for v in values)
        return f"<label>{label} <select name='{name}'><option value=''>all</option>{opts}</select></label> "

    kinds = list(dict.fromkeys(c["kind"] for c in cards))
    zones = sorted({c["zone"] for c in cards})
    cfgs = list(dict.fromkeys(c["configuration"] for c in cards))
    agrees = [a for a in _AGREEMENT_TEXT if any(agreement_of(c) == a for c in cards)]
    chosen = set(doc.get("groups", [])[1:])
    others = "".join(f"<label><input type='checkbox' name='groups' value='{esc(o)}'"
                     f"{' checked' if o in chosen else ''}> {esc(o)}</label> " for o in doc.get("others", []))
    compare = (f"<form method='get' id='groupform'>Other reviewer groups (workshops over the same plots): "
               f"{others}<button type='submit'>Show their shares</button></form>") if others else ""
    from urllib.parse import quote

    base = f"/workshops/{quote(doc['workshop'], safe='')}/plot/"
    body = "".join(card_html(c, f"{base}{int(c['plot'])}", labels) for c in cards)
    return (f"<h3>Plot cards</h3><style>{CARD_CSS}</style>{compare}"
            f"<p id='cardfilter'>{select('kind', 'plot kind', kinds, lambda k: labels.get(k, k))}"
            f"{select('zone', 'test zone', zones)}{select('configuration', 'configuration', cfgs)}"
            f"{select('agreement', 'agreement', agrees, lambda a: _AGREEMENT_TEXT[a])}"
            f"— <span id='cardcount'>{len(cards)}</span> of {len(cards)} cards</p>{body}")


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
validation limit is 1.0.</p>
<p>Method: {esc(thr.get('method', ''))}. {_sensitivity_html(thr.get('link_sensitivity'))}</p>{charts}
<h3>Scaling effect (same reviewer, same plot: fixed against automatic scaling)</h3>{_scaling_html(sc)}
"""
