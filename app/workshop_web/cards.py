"""Plot cards on the analysis page and in the validation report (Polach & Böttcher 2014
Figs. 3–5; docs/workshops.md "Plot cards"): the reviewed image, beside it the EN values with
their differences, the share of Yes of every reviewer group and the Sprague–Geers errors."""

from __future__ import annotations

import html
from typing import Any
from urllib.parse import quote

from railval.app.services.workshop_documents import kind_labels
from railval.app.workshop_web.common import _fmt, _pct, esc

#: the cards' filters: show a card when it matches every chosen value
CARDS_JS = r"""
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
    en = "".join(f"<tr><td>{esc(e['quantity'])} <span class='muted'>({esc(e.get('unit', ''))})</span>"
                 f"</td><td class='num'>{_fmt(e['measured'])}</td>"
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
    base = f"/workshops/{quote(doc['workshop'], safe='')}/plot/"
    body = "".join(card_html(c, f"{base}{int(c['plot'])}", labels) for c in cards)
    return (f"<h3>Plot cards</h3><style>{CARD_CSS}</style>{compare}"
            f"<p id='cardfilter'>{select('kind', 'plot kind', kinds, lambda k: labels.get(k, k))}"
            f"{select('zone', 'test zone', zones)}{select('configuration', 'configuration', cfgs)}"
            f"{select('agreement', 'agreement', agrees, lambda a: _AGREEMENT_TEXT[a])}"
            f"— <span id='cardcount'>{len(cards)}</span> of {len(cards)} cards</p>{body}")


def report_section(cards: list[dict[str, Any]]) -> str:
    """The chosen cards (:func:`railval.app.services.workshop_cards.report_cards`) as a
    self-contained section of the validation report (images embedded)."""

    labels = kind_labels()
    out = [f"<h2>Expert review: plot cards</h2><style>{CARD_CSS}</style>"
           "<p class='note'>Plots as the reviewers saw them (workshop, plot id and SHA-256 of the "
           "image below each); EN 14363 values of measurement and simulation in the evaluated part, "
           "the share of Yes of each reviewer group, Sprague–Geers errors of the whole section.</p>"]
    for c in cards:
        out.append(card_html(c, f"data:image/png;base64,{c['image_png']}", labels, lazy=False))
        out.append(f"<p class='note'>workshop {html.escape(c['workshop'])}, plot {int(c['plot'])}, "
                   f"image SHA-256 <code>{html.escape(c['image_sha256'])}</code></p>")
    return "".join(out)


__all__ = ["CARDS_JS", "CARD_CSS", "agreement_of", "card_html", "cards_html", "report_section"]
