"""HTML and PDF report of a configuration's validation (docs/design.md §1: reviewers, assessors).

One builder serves the Report page and ``railval report``. The HTML is self-contained:
tables, and charts as inline SVG drawn here (no JavaScript, no network), so it prints the
same way it displays. The PDF is the HTML printed by headless Chromium
(``chromium --headless --print-to-pdf``), the browser the app is tested with; when no
Chromium is found a :class:`ReportError` says so and which path was searched.

Contents: verdict; per quantity n, mean, std (sample std, n − 1), limits, normalised values
with bootstrap intervals, pass/fail; coverage and its shortfalls; Polach & Böttcher 2014, Fig. 12/13 bar
charts; plots of the worst cases (largest |D_v|/limit, EN-filtered measurement beneath the
simulation on the distance axis, evaluated range shaded); the lineage; SHA-256 content
hashes of every signal used; software versions.
"""

from __future__ import annotations

import datetime as dt
import hashlib
import html
import json
import math
import os
import platform
from dataclasses import dataclass, field
from importlib import metadata
from pathlib import Path
from typing import Any

import numpy as np

from railval.app.pdf import (  # noqa: F401 - the report's writers, re-exported for callers
    CHROMIUM_ARGS,
    PRINT_CSS,
    ReportError,
    block_cell,
    find_chromium,
    html_to_pdf,
    write_html_or_pdf,
)
from railval.app.scales import (
    FAIL_COLOR,
    MEASURED_COLOR,
    PASS_COLOR,
    SIM_COLORS,
    downsample_xy,
    unit_label,
)
from railval.app.services import overview as overview_service
from railval.app.svg_charts import svg_bars, svg_lines
from railval.app.views import ValidationView, view_of
from railval.core import lazy
from railval.core.coverage import Coverage
from railval.core.diagnosis import where_grid
from railval.core.en14363 import quantity_trace
from railval.core.quantities import QUANTITIES

#: deferred (railval.core.lazy): the workshop cards and Bokeh, when a report shows them
report_section = lazy.function("railval.app.workshop_web.cards", "report_section")
bokeh_palettes = lazy.module("bokeh.palettes")
#: points per trace of the report's line charts
SVG_POINTS = 1200


def _esc(x: Any) -> str:
    return html.escape(str(x))


def _fmt(x: Any, digits: int = 3) -> str:
    if x is None:
        return "–"
    if isinstance(x, bool):
        return "yes" if x else "no"
    if isinstance(x, (int, np.integer)):
        return str(int(x))
    try:
        v = float(x)
    except (TypeError, ValueError):
        return _esc(x)
    if not math.isfinite(v):
        return "–"
    return f"{v:.{digits}g}" if abs(v) >= 1e4 or (v != 0 and abs(v) < 1e-3) else f"{v:.{digits}f}"


# ----------------------------------------------------------------------------- report
@dataclass
class Report:
    """A built report: ``html`` (self-contained) and its metadata."""

    campaign: str
    configuration: str
    html: str
    validated: bool
    generated_at: str
    versions: dict[str, str]
    digest: str = field(default="")

    def to_dict(self) -> dict[str, Any]:
        return {"campaign": self.campaign, "configuration": self.configuration,
                "validated": self.validated, "generated_at": self.generated_at,
                "versions": self.versions, "evidence_digest": self.digest}

    def write(self, path: str | os.PathLike) -> Path:
        """Write ``.html`` or ``.pdf`` (by extension)."""
        return write_html_or_pdf(self.html, path, "report")

    def pdf_bytes(self) -> bytes:
        return html_to_pdf(self.html)


def software_versions() -> dict[str, str]:
    out = {"python": platform.python_version()}
    for dist in ("railval", "numpy", "scipy", "pandas", "sqlalchemy", "panel", "holoviews", "bokeh"):
        try:
            out[dist] = metadata.version(dist)
        except metadata.PackageNotFoundError:
            out[dist] = "not installed"
    return out


CSS = """
body { font-family: 'DejaVu Sans', Arial, sans-serif; font-size: 13px; color: #1d1d1d; margin: 24px; }
h1 { font-size: 22px; margin-bottom: 4px; } h2 { font-size: 17px; margin-top: 26px;
  border-bottom: 1px solid #ccc; padding-bottom: 3px; } h3 { font-size: 14px; }
table { border-collapse: collapse; margin: 8px 0; } th, td { border: 1px solid #ccc; padding: 3px 7px;
  text-align: right; } th { background: #f0f2f5; } td.l, th.l { text-align: left; }
.pass { color: {pass_}; font-weight: bold; } .fail { color: {fail}; font-weight: bold; }
.verdict { padding: 10px 14px; border-radius: 4px; font-size: 15px; margin: 10px 0; }
.verdict.ok { background: #e8f5e9; border: 1px solid {pass_}; }
.verdict.no { background: #ffebee; border: 1px solid {fail}; }
.meta td { text-align: left; border: none; padding: 1px 10px 1px 0; }
.hashes td, td.hash { font-family: 'DejaVu Sans Mono', monospace; font-size: 10px; }
.charts { display: flex; flex-wrap: wrap; gap: 12px; } .note { color: #555; }
@media print { h2 { page-break-after: avoid; } .worst { page-break-inside: avoid; } }
""".replace("{pass_}", PASS_COLOR).replace("{fail}", FAIL_COLOR) + PRINT_CSS


def diverging_color(value: float, limit: float = 2.0) -> str:
    """Cell colour of a signed value on the fixed scale ±``limit`` (ColorBrewer RdBu, 11
    classes, from Bokeh's palettes): red above zero, blue below, white near zero; the app's
    heat maps use the same scale."""
    if not math.isfinite(value):
        return "#ffffff"
    palette = bokeh_palettes.RdBu11  # dark blue … white … dark red
    i = round((min(max(value / limit, -1.0), 1.0) + 1.0) / 2.0 * (len(palette) - 1))
    return palette[i]


def where_table(grid: Any, limit: float = 2.0) -> str:
    """"Where it fails" as an HTML table: mean D_v / std limit per quantity × EN zone, each
    cell coloured on the fixed scale ±``limit`` (white text on the deep colours)."""
    out = ["<h2>Where it fails: quantity × test zone</h2><table class='where'><tr><th class='l'>quantity</th>"
           + "".join(f"<th>{_esc(c)}</th>" for c in grid.cols) + "</tr>"]
    for i, q in enumerate(grid.rows):
        cells = []
        for v in grid.values[i]:
            if not math.isfinite(v):
                cells.append("<td>–</td>")
                continue
            ink = "#ffffff" if abs(v) > 0.55 * limit else "#1d1d1d"
            cells.append(f"<td style='background:{diverging_color(v, limit)};color:{ink}'>{v:+.2f}</td>")
        out.append(f"<tr><td class='l'>{_esc(q)}</td>{''.join(cells)}</tr>")
    out.append(f"</table><p class='note'>Mean of D_v / std limit over the sections and positions of each "
               f"zone; red: the simulation above the measurement, blue: below; colours saturate at ±{limit:g}.</p>")
    return "".join(out)


def contrary_html(d: dict[str, Any]) -> str:
    """The objective verdict a sign-off was bound to and, for a contrary decision, the
    label and the written justification (escaped)."""
    verdict = _esc(d.get("objective_verdict") or "–")
    if not d.get("contrary_to_objective"):
        return f"objective {verdict}; decision agrees"
    return (f"<b class='fail rv-contrary'>CONTRARY TO THE OBJECTIVE VERDICT</b> ({verdict})<br>"
            f"justification: {_esc(d.get('justification') or '–')}")


#: The columns of the sign-off table (its header and each cell's ``data-label``).
SIGNOFF_COLUMNS = ("id", "configuration", "status", "decision", "signed by", "UTC", "meaning",
                   "restrictions", "statement", "against the objective verdict", "evidence SHA-256",
                   "changed since")


def signoff_rows_html(items: list[tuple[dict[str, Any], Any]]) -> str:
    """The sign-off table (escaped) of the validation report and the audit report
    (:mod:`railval.app.audit_report`): a table on screen, one block per sign-off in print
    (class ``blocks`` of :data:`CSS`), every field in both."""
    if not items:
        return "<p class='note'>No sign-off.</p>"
    rows = []
    for d, st in items:
        cls = "pass" if st.status == "valid" else "fail"
        why = "<br>".join(_esc(r) for r in st.reasons[:5]) or "–"
        cells = (
            (str(d["id"]), ""), (f"{_esc(d['campaign'])} / {_esc(d['configuration'])}", "l"),
            (_esc(st.status), f"l {cls}"), (_esc(d["decision_text"]), "l"),
            (f"{_esc(d['printed_name'])} ({_esc(d['username'])})", "l"), (_esc(d["signed_at_utc"]), "l"),
            (_esc(d["meaning"]), "l"), (_esc(d["restrictions"] or "–"), "l"), (_esc(d["statement"] or "–"), "l"),
            (contrary_html(d), "l"), (_esc(d["evidence_sha256"]), "l hash"), (why, "l"))
        rows.append("<tr>" + "".join(block_cell(v, c, label)
                                     for (v, c), label in zip(cells, SIGNOFF_COLUMNS, strict=True)) + "</tr>")
    head = "".join(f"<th class='{'l' if i else ''}'>{_esc(c)}</th>" for i, c in enumerate(SIGNOFF_COLUMNS))
    return "<table class='blocks signoffs'><tr class='head'>" + head + "</tr>" + "".join(rows) + "</table>"


def _verdict_document(d: dict) -> dict:
    """The parts of a validation result the evidence digest covers: verdict, coverage and
    every quantity's values, limits, intervals and section pairs (no time stamps)."""
    def clean(x):
        if isinstance(x, float):
            return repr(x) if not math.isfinite(x) else x
        if isinstance(x, dict):
            return {str(k): clean(v) for k, v in x.items()}
        if isinstance(x, list | tuple):
            return [clean(v) for v in x]
        return x
    return clean({k: d.get(k) for k in ("validated", "coverage", "quantities")})


@dataclass
class ReportInputs:
    """What a report is built from, gathered in one step (:func:`gather_report`)."""

    campaign: str
    configuration: str
    result: Any  # railval.core.validation.ValidationResult
    view: ValidationView
    overview: Any  # railval.app.services.overview.CampaignOverview
    lineage: list[str]
    measured_hashes: dict[str, dict[str, str]]
    simulated_hashes: dict[str, dict[str, str]]
    signoffs: list[tuple[dict[str, Any], Any]] | None
    versions: dict[str, str]
    generated_at: str


def gather_report(backend: Any, campaign: str, config: str) -> ReportInputs:
    """Check every blob of the evidence against its hash and seal, then read the validation
    (through ``backend``, exactly as the dashboard shows it), the campaign, the lineage, the
    content hashes and the sign-offs."""
    overview_service.require_sealed(backend.database, campaign, config)
    result = backend.validation(campaign, config)
    signoffs = (overview_service.signoff_items(backend.database, campaign, config)
                if hasattr(backend, "session") else None)
    return ReportInputs(
        campaign, config, result, view_of(result), backend.overview(campaign),
        backend.lineage(campaign, config), backend.hashes(campaign, None),
        backend.hashes(campaign, config), signoffs, software_versions(),
        dt.datetime.now(dt.UTC).strftime("%Y-%m-%d %H:%M:%S UTC"))


def evidence_digest(inputs: ReportInputs) -> tuple[str, list[tuple[str, str, str, str]]]:
    """SHA-256 over every (section, channel, measured hash, simulated hash) line, then the
    verdict and the values of every quantity; returns the digest and the lines."""
    meas, sim = inputs.measured_hashes, inputs.simulated_hashes
    digest = hashlib.sha256()
    lines = []
    for sid in sorted(set(meas) | set(sim)):
        for ch in sorted(set(meas.get(sid, {})) | set(sim.get(sid, {}))):
            a, b = meas.get(sid, {}).get(ch, ""), sim.get(sid, {}).get(ch, "")
            digest.update(f"{sid}\t{ch}\t{a}\t{b}\n".encode())
            lines.append((sid, ch, a, b))
    # the digest covers the verdict and every value it rests on, not only the inputs' hashes
    digest.update(json.dumps(_verdict_document(inputs.result.to_dict()), sort_keys=True,
                             allow_nan=False, default=str).encode())
    return digest.hexdigest(), lines


def build_report(backend: Any, campaign: str, config: str, worst_cases: int = 3,
                 cards: list[dict[str, Any]] | None = None) -> Report:
    """Build the report of ``configuration`` of ``campaign`` from the database: gather
    (:func:`gather_report`), compute the evidence digest (:func:`evidence_digest`), render.

    ``cards``: plot cards of an expert review workshop chosen for this report
    (:func:`railval.app.services.workshops.report_cards`), shown after the worst cases with
    the reviewed image embedded and its SHA-256.

    ``backend`` is an :class:`railval.app.state.backend.Backend` (or anything with its
    methods); the validation comes from ``railval.app.services.validation`` through it,
    exactly as the dashboard shows it.
    """
    inputs = gather_report(backend, campaign, config)
    digest, hash_lines = evidence_digest(inputs)
    view = inputs.view
    h: list[str] = [_head_html(inputs), _verdict_html(view), _quantities_html(view),
                    where_table(where_grid(view.pairs)), definition_html(view),
                    supplementary_html(view), _coverage_html(view.coverage)]
    if worst_cases > 0:
        h.append("<h2>Worst cases</h2><p class='note'>Pairs with the largest |D_v| / std limit over all "
                 "quantities; EN-filtered signals on the distance axis, measurement (grey) beneath the "
                 "simulation (blue), evaluated range shaded.</p>")
        h.extend(_worst_case_plots(backend, campaign, config, inputs.result, inputs.overview,
                                   worst_cases))
    if cards:
        h.append(report_section(cards))
    if inputs.signoffs is not None:  # independent sign-offs of this configuration, with their status
        h.append("<h2>Sign-offs</h2><p class='note'>Each sign-off is bound to the SHA-256 of its "
                 "evidence (docs/audit.md); <b>stale</b> means the evidence changed after signing.</p>")
        h.append(signoff_rows_html(inputs.signoffs))
    h.append(_hashes_html(digest, hash_lines))
    h.append("<h2>Software</h2><table>" + "".join(
        f"<tr><td class='l'>{_esc(k)}</td><td class='l'>{_esc(val)}</td></tr>"
        for k, val in inputs.versions.items()) + "</table></body></html>")
    return Report(campaign, config, "".join(h), view.validated, inputs.generated_at,
                  inputs.versions, digest)


def _head_html(inputs: ReportInputs) -> str:
    """Document head, title and the meta table (campaign, vehicle, configuration, lineage)."""
    campaign, configuration, ov = inputs.campaign, inputs.configuration, inputs.overview
    conf = next((c for c in ov.configurations if c.name == configuration), None)
    v = ov.vehicle
    return (f"<!DOCTYPE html><html lang='en'><head><meta charset='utf-8'>"
            f"<title>railval report — {_esc(campaign)} / {_esc(configuration)}</title>"
            f"<style>{CSS}</style></head><body>"
            f"<h1>Validation report: {_esc(configuration)}</h1>"
            "<table class='meta'>"
            f"<tr><td>Campaign</td><td><b>{_esc(campaign)}</b> {_esc(ov.description)}</td></tr>"
            f"<tr><td>Vehicle</td><td>{_esc(v.get('name', ''))} — {_esc(v.get('kind', ''))}, secondary "
            f"suspension {'yes' if v.get('secondary_suspension') else 'no'}, Q0 = {_fmt(v.get('Q0_kN'))} kN</td></tr>"
            f"<tr><td>Configuration</td><td>{_esc(configuration)}; effects: "
            f"{_esc(', '.join(conf.effects) if conf and conf.effects else 'none')}</td></tr>"
            f"<tr><td>Lineage</td><td>{' → '.join(_esc(x) for x in inputs.lineage)}</td></tr>"
            f"<tr><td>Generated</td><td>{inputs.generated_at}</td></tr>"
            f"<tr><td>Processing</td><td>{_esc(inputs.view.processing_version)}; std: "
            f"{_esc(inputs.view.std_definition)}</td></tr>"
            "</table>")


def _verdict_html(view: ValidationView) -> str:
    """The verdict box and, for an in-sample verdict, the note that says so."""
    ok = view.validated
    out = (f"<div class='verdict {'ok' if ok else 'no'}'><b>{'VALIDATED' if ok else 'NOT VALIDATED'}</b>"
           + ("" if ok else f" — failing quantities: {_esc(', '.join(view.failing) or 'none')}"
              + ("" if view.coverage.ok else "; coverage not met")) + "</div>")
    ins = view.in_sample
    if ins is not None:
        held = ins.held_out_sections
        out += ("<div class='verdict insample'><b>In-sample</b> — "
                f"{_esc(ins.note())}, so this verdict is partly on the data the fit used"
                + (f"; held out: {_esc(', '.join(held))}" if held else "; no section was held out")
                + f". {_esc(ins.held_out_check[:1].upper() + ins.held_out_check[1:])}.</div>")
    return out


def _quantities_html(view: ValidationView) -> str:
    """Per quantity table (D_v statistics, limits, normalised values with intervals) and the
    Fig. 12/13 bar charts."""
    rows = view.quantities
    h = [("<h2>Quantities (Polach & Böttcher 2014 §5, EN 14363)</h2><table><tr><th class='l'>quantity</th>"
          "<th>unit</th><th>n</th><th>mean D_v</th><th>std D_v</th><th>mean limit</th><th>std limit</th>"
          "<th>mean/limit</th><th>95 % CI</th><th>std/limit</th><th>95 % CI</th><th>verdict</th></tr>")]
    for r in rows:
        mci, sci = r["mean_norm_ci"], r["std_norm_ci"]
        h.append(f"<tr><td class='l'>{_esc(r['quantity'])}</td><td>{_esc(unit_label(r['unit']))}</td>"
                 f"<td>{_fmt(r['n'])}</td><td>{_fmt(r['mean'])}</td><td>{_fmt(r['std'])}</td>"
                 f"<td>{_fmt(r['mean_limit'])}</td><td>{_fmt(r['std_limit'])}</td>"
                 f"<td>{_fmt(r['mean_norm'])}</td><td>{_fmt(mci[0])} … {_fmt(mci[1])}</td>"
                 f"<td>{_fmt(r['std_norm'])}</td><td>{_fmt(sci[0])} … {_fmt(sci[1])}</td>"
                 f"<td class='{'pass' if r['pass'] else 'fail'}'>{'pass' if r['pass'] else 'FAIL'}"
                 f"{' (definition-sensitive)' if r['definition_sensitive'] else ''}</td></tr>")
    h.append("</table><p class='note'>D_v = (S_v − M_v)·M_v/|M_v| (positive: the simulation overestimates). "
             "Mean limit = 2/3 of the std limit; intervals: percentile bootstrap over the pairs.</p>")
    labels = [r["quantity"] for r in rows]
    h.append("<div class='charts'>")
    h.append(svg_bars(labels, [r["mean_norm"] for r in rows], title="Normalised mean (mean / limit)",
                      ylabel="mean / limit (–)", limits=(1.0, -1.0), intervals=[r["mean_norm_ci"] for r in rows]))
    h.append(svg_bars(labels, [r["std_norm"] for r in rows], title="Normalised std (std / limit, n − 1)",
                      ylabel="std / limit (–)", limits=(1.0,), intervals=[r["std_norm_ci"] for r in rows]))
    h.append("</div>")
    return "".join(h)


def _coverage_html(cov: Coverage) -> str:
    """The coverage rules, what was found and the shortfalls."""
    h = ["<h2>Coverage</h2>"]
    h.append("<table><tr><th class='l'>rule</th><th>found</th><th>required</th></tr>"
             f"<tr><td class='l'>sections with comparisons</td><td>{_fmt(cov.n_sections)}</td>"
             f"<td>{_fmt(cov.sections_required)}</td></tr>"
             + "".join(f"<tr><td class='l'>zone {_esc(z)}</td><td>{_fmt(n)}</td>"
                       f"<td>{_fmt(cov.sections_per_zone_required)}</td></tr>" for z, n in cov.zones.items())
             + "</table>")
    short = cov.shortfalls
    h.append("<p class='pass'>Coverage holds.</p>" if not short else
             "<ul>" + "".join(f"<li class='fail'>{_esc(s)}</li>" for s in short) + "</ul>")
    return "".join(h)


def _hashes_html(digest: str, lines: list[tuple[str, str, str, str]]) -> str:
    """The evidence digest and the table of every signal's content hashes."""
    rows = "".join(f"<tr><td class='l'>{_esc(sid)}</td><td class='l'>{_esc(ch)}</td><td class='l'>{a}</td>"
                   f"<td class='l'>{b}</td></tr>" for sid, ch, a, b in lines)
    return ("<h2>Evidence: signal content hashes (SHA-256)</h2>"
            f"<p>Evidence digest (SHA-256 over every line below, then the verdict and the "
            f"values of every quantity): <code>{digest}</code></p>"
            "<table class='hashes'><tr><th class='l'>section</th><th class='l'>channel</th>"
            "<th class='l'>measurement</th><th class='l'>simulation</th></tr>" + rows + "</table>")


def _worst_case_plots(backend: Any, campaign: str, config: str, result: Any, ov: Any,
                      n: int) -> list[str]:
    pairs = result.pairs
    if len(pairs) == 0:
        return ["<p>No pairs.</p>"]
    order = pairs.reindex(pairs["D_norm"].abs().sort_values(ascending=False).index).head(n)
    channels = [c["name"] for c in ov.channels]
    secs = {s.id: s for s in ov.sections}
    out = []
    for r in order.itertuples(index=False):
        q = QUANTITIES.get(r.quantity)
        sec = secs.get(r.section)
        if q is None or sec is None or r.position not in q.positions():
            continue
        names = [c for c in q.channels(r.position) if c in channels]
        if len(names) < len(q.channels(r.position)):
            continue
        traces, marks, trace = [], [], None
        for label, cfg, color in (("measurement", None, MEASURED_COLOR),
                                  (config, config, SIM_COLORS[0])):
            ss = backend.signals(campaign, cfg, r.section, names)
            trace = quantity_trace(ss, sec, r.quantity, r.position)
            if trace.sliding_means is not None:  # the 2 m sliding means are what is evaluated
                x, y = trace.sliding_centres_m, trace.sliding_means
            else:
                x, y = downsample_xy(np.asarray(trace.distance_m, float), np.asarray(trace.values, float),
                                     n_out=SVG_POINTS)
            traces.append((label, np.asarray(x, float), np.asarray(y, float), color))
            for stat, v in trace.marks.items():
                marks.append((f"{label}: {stat} = {v:.4g}", v, color))
        unit = unit_label(q.unit if q.unit != "-" else "")
        short = {"YQ": f"Y/Q {r.position}", "SumY": f"ΣY {r.position}"}.get(q.signal, names[0])
        sliding = trace.sliding_means is not None
        title = (f"{r.quantity} at {r.position}, section {r.section} (zone {r.zone}): "
                 f"D_v/limit = {r.D_norm:+.2f}")
        caption = (f"Plotted: {trace.signal_label}{', 2 m sliding mean every 0.5 m' if sliding else ''}; "
                   f"statistic: {q.processing_text} over the evaluated range (shaded).")
        out.append("<div class='worst'>" + svg_lines(
            traces, title=title, xlabel="distance (m)",
            ylabel=f"{short}{' (2 m mean)' if sliding else ''}{f' ({unit})' if unit else ' (–)'}",
            shade=(sec.eval_start_m, sec.eval_end_m), marks=marks)
            + f"<p class='note'>{_esc(caption)}</p></div>")
    return out


def definition_html(view: ValidationView) -> str:
    """Report section: which verdicts rest on an open choice of the definitions (percentile
    method, sliding-window grid and mean; docs/validation.md)."""
    rows = view.definition_rows()
    out = [("<h2>Definition sensitivity</h2><p class='note'>Chosen reading: percentiles by the inverted "
           "CDF (the smallest sample with F_n ≥ p), sliding-mean grid from the evaluated range's start, "
           "distance-weighted 2 m mean. Alternatives evaluated on the same filtered signals: linear "
           "percentiles (Hyndman–Fan type 7); grid from the first evaluated sample; arithmetic means of "
           "the samples in closed or half-open windows (docs/validation.md).</p>")]
    if not rows:
        out.append("<p>Not available for this result.</p>")
        return "".join(out)
    sensitive = [r["quantity"] for r in rows if r["definition_sensitive"]]
    out.append(f"<p class='{'fail' if sensitive else 'pass'}'>"
               + (("definition-sensitive: " + _esc(", ".join(sensitive))
                   + ("; the verdict itself changes under another reading" if view.verdict_sensitive
                      else "")) if sensitive
                  else "No verdict changes under the alternative readings.") + "</p>")
    out.append("<table><tr><th class='l'>quantity</th><th>verdict</th><th>definition-sensitive</th>"
               "<th>readings</th><th>mean/limit</th><th>other readings</th><th>std/limit, other readings</th>"
               "<th class='l'>flipped by</th></tr>")
    for r in rows:
        mr, sr = r["mean/limit other readings"], r["std/limit other readings"]
        out.append(f"<tr><td class='l'>{_esc(r['quantity'])}</td><td>{_esc(r['verdict'])}</td>"
                   f"<td class='{'fail' if r['definition_sensitive'] else ''}'>"
                   f"{'yes' if r['definition_sensitive'] else 'no'}</td><td>{r['readings']}</td>"
                   f"<td>{_fmt(r['mean/limit'])}</td>"
                   f"<td>{'' if not mr else _fmt(mr[0]) + ' … ' + _fmt(mr[1])}</td>"
                   f"<td>{'' if not sr else _fmt(sr[0]) + ' … ' + _fmt(sr[1])}</td>"
                   f"<td class='l'>{_esc(r['flipped by'])}</td></tr>")
    out.append("</table>")
    return "".join(out)


def supplementary_html(view: ValidationView) -> str:
    """Report section: bogie-frame and PSD-band quantities next to the verdict."""
    rows = view.supplementary_rows()
    out = [("<h2>Supplementary results (do not change the verdict)</h2><p class='note'>Bogie-frame "
           "accelerations: band-pass 0.4–10 Hz of the whole section, evaluated range, rms and max(|0.15 %|, "
           "|99.85 %|) (EN 14363 acceleration processing). PSD bands: band rms √(Σ G(f)·Δf) of the Welch PSD "
           "(Hann, 50 % overlap, linear detrend, 10 s segments) of the unfiltered evaluated samples, bands "
           "0.4–1, 1–2, 2–5, 5–10 Hz. D_v statistics as for the verdict (Polach & Böttcher 2014 eq. 4, std with "
           "n − 1); rel = value / mean |M_v|; log2 S/M = mean log₂ ratio. No validation limits exist for "
           "these quantities (Polach & Böttcher 2014 §3.1 compared them before settling on the 12).</p>")]
    if not rows:
        out.append("<p>No supplementary channels in this campaign.</p>")
        return "".join(out)
    out.append("<table><tr><th class='l'>quantity</th><th class='l'>group</th><th>unit</th><th>n</th>"
               "<th>mean D_v</th><th>std D_v</th><th>mean rel</th><th>std rel</th><th>log2 S/M</th></tr>")
    for r in rows:
        out.append(f"<tr><td class='l'>{_esc(r['quantity'])}</td><td class='l'>{_esc(r['group'])}</td>"
                   f"<td>{_esc(unit_label(r['unit']))}</td><td>{_fmt(r['n'])}</td>"
                   f"<td>{_fmt(r['mean'])}</td><td>{_fmt(r['std'])}</td><td>{_fmt(r['mean_rel'])}</td>"
                   f"<td>{_fmt(r['std_rel'])}</td><td>{_fmt(r['log2_ratio_mean'])}</td></tr>")
    out.append("</table>")
    return "".join(out)
