"""Analysis page: Table 1, reviewers, agreement, the 50 % deviation beside the limit 1.0."""

from __future__ import annotations

import base64
import io
from typing import Any

import numpy as np

from railval.app.services.workshop_answers import analyse
from railval.app.services.workshop_cards import cards
from railval.app.workshop_web.cards import CARDS_JS, cards_html
from railval.app.workshop_web.common import (
    _fmt,
    _OrganiserBase,
    _pct,
    esc,
    page,
    run,
)
from railval.core import lazy
from railval.core import workshop as workshop_core
from railval.core.errors import RailvalError

#: deferred (railval.core.lazy): the workshop administration (20 modules more than these pages),
#: the review statistics and matplotlib load on the first page that uses them
workshop_admin = lazy.module("railval.app.services.workshop_admin")
yes_curve = lazy.function("railval.core.review", "yes_curve")
Figure = lazy.function("matplotlib.figure", "Figure")


# -------------------------------------------------------------------------- analysis
def _analysis(database, name: str, actor) -> dict[str, Any]:
    return analyse(database, name, actor=actor, with_plots=True)


def _sensitivity_html(sens: dict | None) -> str:
    """One sentence: the 50 % deviation under every parametric link and their spread (left out
    when no 50 % deviation is reported: no number where the page says there is none)."""
    if not sens:
        return ""
    links = ", ".join(f"{esc(r['link'])} {_fmt(r.get('at_50'))}" for r in sens.get("links", []))
    spread = sens.get("relative_spread")
    return (f"Link sensitivity (logistic fits): {links}; likeliest {esc(sens.get('chosen'))}; spread "
            f"{'—' if spread is None else f'{100 * spread:.0f} %'} of the reported value.")


def _n_text(n: dict | None) -> str:
    """``12 answers by 1 reviewer on 12 plots`` — the n a 50 % value rests on."""
    n = n or {}
    a, r, q = n.get("answers", 0), n.get("reviewers", 0), n.get("plots", 0)
    return (f"{a} answer{'s' * (a != 1)} by {r} reviewer{'s' * (r != 1)} "
            f"on {q} plot{'s' * (q != 1)}")


def at50_html(thr: dict[str, Any], column: str, what: str) -> str:
    """The sentence of one 50 % value (``column`` ``deviation`` or ``sg_c``): the number with
    its interval and n, or where it lies ("above/below the observed range"), or "too few
    answers to estimate" with the n and the stated minimum — never a bare number."""
    key, ci_key = ("deviation_at_50", "ci") if column == "deviation" else ("sg_c_at_50", "sg_c_ci")
    status = thr.get(f"{key}_status") or ("estimated" if thr.get(key) is not None else "too few answers to estimate")
    n = _n_text(thr.get(f"{column}_n"))
    head = f"{what} at which a typical reviewer says Yes half of the time: "
    if status == "too few answers to estimate":
        return (f"<p class='at50'>{head}<strong>too few answers to estimate</strong> ({esc(n)}; "
                f"at least {thr.get('min_answers')} answers on {thr.get('min_plots')} plots with a value "
                f"are needed).</p>")
    if status != "estimated":
        curve = thr.get(f"{column}_curve") or {}
        vals = [v for v in curve.get("value") or [] if v is not None]
        span = f" (observed {_fmt(min(vals))} … {_fmt(max(vals))})" if vals else ""
        return (f"<p class='at50'>{head}<strong>{esc(status)}</strong>{span}: the monotone fit does not "
                f"cross 50 % there, and no value is extrapolated — from {esc(n)}.</p>")
    ci_status = thr.get(f"{ci_key}_status")
    interval = f"interval reaches {esc(ci_status)}" if ci_status else f"interval {_fmt(thr.get(ci_key))}"
    return (f"<p class='at50'>{head}<strong>{_fmt(thr.get(key))}</strong> ({interval}; bootstrap over "
            f"plots) — from {esc(n)}; the point where the drawn monotone fit crosses 50 %.</p>")


def threshold_png(doc: dict[str, Any], column: str, label: str, limit: float | None) -> str:
    """The answers against an objective value (``deviation`` or ``sg_c``): each plot's share
    of Yes (points), the monotone fit of a typical reviewer that gives the reported value
    (solid), the likeliest logistic link's curve (:func:`railval.core.review.yes_curve`,
    dashed: the sensitivity), the value at 50 % with its interval, and the limit; returned
    as a PNG data URL."""
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
    curve = thr.get(f"{column}_curve") or {}
    if curve.get("value"):
        ax.plot(curve["value"], curve["yes"], color="#0072B2", linewidth=2,
                label="monotone fit, typical reviewer (reported)", zorder=3)
    if fit.get("intercept") is not None and fit.get("slope") is not None:
        xs = np.linspace(top / 400, top * 1.05, 400)
        ax.plot(xs, yes_curve(xs, fit["intercept"], fit["slope"], power=fit.get("power") or 0.0),
                color="#56B4E9", linestyle="--",
                label=f"logistic fit, {fit.get('link', 'log')} link (sensitivity)", zorder=3)
    status = thr.get("deviation_at_50_status" if column == "deviation" else "sg_c_at_50_status")
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
    ax.set_title(f"{_n_text(thr.get(f'{column}_n'))}"
                 f"{'' if status in (None, 'estimated') else ' — 50 % point: ' + status}", fontsize=9)
    ax.legend(loc="upper right", fontsize=8)
    fig.tight_layout()
    buf = io.BytesIO()
    fig.savefig(buf, format="png", metadata={"Software": None})
    return "data:image/png;base64," + base64.b64encode(buf.getvalue()).decode()


def _cards(database, name: str, groups: list[str], actor) -> dict[str, Any]:
    doc = cards(database, name, groups=groups, actor=actor)
    doc["others"] = workshop_admin.sibling_workshops(database, name)
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
            self.finish(page(f"Analysis {name}", f"<p class='err'>{esc(exc)}</p>", user=p))
            return
        self.finish(page(f"Analysis {name}", analysis_html(doc) + cards_html(card_doc),
                         user=p, script=CARDS_JS))


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
    return workshop_admin.plot_image(database, name, plot_id)


def _share_of(row: dict[str, Any], end: str) -> str:
    """``100.0 % (2 of 2)``: a Table 1 share of Yes with the Yes count and answers it rests on."""
    share, k, n = row.get(f"{end}_yes"), row.get(f"{end}_yes_count"), row.get(f"{end}_yes_answers")
    return _pct(share) if share is None or n is None else f"{_pct(share)} ({k} of {n})"


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
    kinds = workshop_core.PLOT_KINDS
    t1 = "".join(f"<tr><td>{esc(kinds[r['kind']].label if r['kind'] in kinds else r['kind'])}"
                 f" <span class='muted'>({esc(r['kind'])})</span></td><td class='num'>{r['plots']}</td>"
                 f"<td class='num'>{r.get('answers', '—')}</td><td class='num'>{r.get('reviewers', '—')}</td>"
                 f"<td class='num'>{_share_of(r, 'min')}</td><td class='num'>{_share_of(r, 'max')}</td></tr>"
                 for r in doc.get("table1", []))
    rv = "".join(f"<tr><td>{esc(r['reviewer'])}</td><td class='num'>{r['answers']}</td>"
                 f"<td class='num'>{_pct(r.get('yes_share'))}</td>"
                 f"<td class='num'>{_pct_ci(r.get('yes_share_ci'))}</td>"
                 + (f"<td colspan='2' class='muted'>{esc(r['strictness_note'])}</td>" if r.get("strictness_note")
                    else f"<td class='num'>{_fmt(r.get('strictness'))}</td>"
                         f"<td class='num'>{_fmt(r.get('strictness_ci'))}</td>")
                 + f"<td class='num'>{_fmt(r.get('consistency'))} ({r.get('repeats', 0)} repeats)</td></tr>"
                 for r in doc.get("reviewers", []))
    ag = doc.get("agreement") or {}
    agr = "".join(f"<tr><td>{esc(k)}</td><td class='num'>{_fmt(v.get('value'))}</td>"
                  f"<td class='num'>{_fmt(v.get('ci'))}</td><td class='num'>{v.get('plots', '—')}</td>"
                  f"<td class='num'>{v.get('reviewers', '—')}</td></tr>"
                  for k, v in ag.items() if isinstance(v, dict))
    thr = doc.get("threshold") or {}
    sc = doc.get("scaling_effect")
    charts = (f"<h4>Against the normalised deviation (largest |D_v| / std limit)</h4>"
              f"<img alt='answers against the normalised deviation' "
              f"src='{threshold_png(doc, 'deviation', 'normalised deviation: largest |D_v| / std limit (1)', 1.0)}'>"
              f"{at50_html(thr, 'sg_c', 'Sprague–Geers C')}"
              f"<img alt='answers against Sprague–Geers C' "
              f"src='{threshold_png(doc, 'sg_c', 'Sprague–Geers comprehensive error C (1)', None)}'>")
    return f"""
<h2>{esc(doc.get('workshop', ''))}</h2>
<h3>Table 1 — share of Yes per plot kind (min and max over reviewers, Yes of answers)</h3>
<table><tr><th>plot kind</th><th>plots</th><th>answers</th><th>reviewers</th><th>min Yes</th><th>max Yes</th></tr>{t1}
</table>
<h3>Reviewers</h3>
<table><tr><th>reviewer</th><th>answers</th><th>share of Yes</th><th>Wilson 95 % interval</th>
<th>strictness</th><th>interval</th><th>consistency on repeats</th></tr>{rv}</table>
<h3>Agreement</h3><table><tr><th>statistic</th><th>value</th><th>interval</th><th>plots</th><th>reviewers</th></tr>
{agr}</table>
<h3>Threshold</h3>
{at50_html(thr, 'deviation', 'Deviation')}
<p>The validation limit is 1.0. Method: {esc(thr.get('method', ''))}.
{_sensitivity_html(thr.get('link_sensitivity') if thr.get('deviation_at_50') is not None else None)}</p>{charts}
<h3>Scaling effect (same reviewer, same plot: fixed against automatic scaling)</h3>{_scaling_html(sc)}
"""
