"""Analysis page: Table 1, reviewers, agreement, the 50 % deviation beside the limit 1.0."""

from __future__ import annotations

import base64
import io
from typing import Any

from railval.app.workshop_web.cards import CARDS_JS, cards_html
from railval.app.workshop_web.common import (
    _fmt,
    _OrganiserBase,
    _pct,
    esc,
    page,
    run,
)
from railval.core.errors import RailvalError


# -------------------------------------------------------------------------- analysis
def _analysis(database, name: str, actor) -> dict[str, Any]:
    from railval.app.services.workshops import analyse

    return analyse(database, name, actor=actor, with_plots=True)


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
    of Yes (points), the monotone fit of a typical reviewer that gives the reported value
    (solid), the likeliest logistic link's curve (:func:`railval.core.review.yes_curve`,
    dashed: the sensitivity), the value at 50 % with its interval, and the limit; returned
    as a PNG data URL."""
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
    curve = thr.get(f"{column}_curve") or {}
    if curve.get("value"):
        ax.plot(curve["value"], curve["yes"], color="#0072B2", linewidth=2,
                label="monotone fit, typical reviewer (reported)", zorder=3)
    if fit.get("intercept") is not None and fit.get("slope") is not None:
        xs = np.linspace(top / 400, top * 1.05, 400)
        ax.plot(xs, yes_curve(xs, fit["intercept"], fit["slope"], power=fit.get("power") or 0.0),
                color="#56B4E9", linestyle="--",
                label=f"logistic fit, {fit.get('link', 'log')} link (sensitivity)", zorder=3)
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
    from railval.app.services.workshop_admin import sibling_workshops
    from railval.app.services.workshop_cards import cards

    doc = cards(database, name, groups=groups, actor=actor)
    doc["others"] = sibling_workshops(database, name)
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
    from railval.app.services.workshop_admin import plot_image

    return plot_image(database, name, plot_id)


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
