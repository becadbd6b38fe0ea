"""CLI verb ``validate`` (docs/design.md §3, §8).

``railval validate CAMPAIGN --config NAME [--json] [--order N] [--boot N] [--seed N] [--scheduler ADDR]``
    EN 14363 processing of measurement and configuration, the DynoTRAIN verdict per quantity
    (mean and sample standard deviation of D_v against the Table 2 limits) and the coverage.

Human output: one table row per quantity with pass/fail, the normalised mean and standard
deviation as bars (``█`` blocks, the limit 1.0 marked ``│``) and their bootstrap intervals,
then the coverage lines, the supplementary results and which quantities are
definition-sensitive (pass/fail changes under another reading of the open percentile or
sliding-mean definitions). ``--json`` prints one JSON document (``validated``, ``coverage``,
``quantities`` with ``definition_sensitive`` and ``definition_alternatives`` each,
``definitions``, ``supplementary`` …, ``in_sample`` and ``in_sample_provenance``: the fit
that makes the verdict in-sample — fitted configurations, calibration or diagnosis, fit and
held-out sections — and the held-out check, or null). The exit code is 0 whether or not the configuration is validated; 2 on
errors (unknown campaign/configuration, bad data).
"""

from __future__ import annotations

import argparse
from typing import TYPE_CHECKING

from railval.app.cli import emit_json
from railval.core import lazy

# the services and records this module's verbs call, imported when a verb first uses
# them (railval.core.lazy): `railval --help` and the other verbs never load them
app_views = lazy.module("railval.app.views")
core_quantities = lazy.module("railval.core.quantities")
connect = lazy.function("railval.db.engine", "connect")  # the --db URL → its connection
overview_service = lazy.module("railval.app.services.overview")
validation_service = lazy.module("railval.app.services.validation")

if TYPE_CHECKING:
    from railval.core.coverage import Coverage
    from railval.core.validation import ValidationResult

BAR_CELLS = 20  # cells for 0 … 2 × limit
_BLOCKS = " ▏▎▍▌▋▊▉█"


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "validate", help="validate a configuration against the measurement (DynoTRAIN method)",
        description="EN 14363 processing and DynoTRAIN validation of one configuration "
                    "(Polach & Böttcher 2014 §5). Exit code 0 whether validated or not.")
    p.add_argument("campaign", metavar="CAMPAIGN", help="campaign name or id")
    p.add_argument("--config", required=True, metavar="NAME", help="configuration name")
    p.add_argument("--json", action="store_true", help="print one JSON document")
    p.add_argument("--order", type=int, default=4, metavar="N",
                   help="Butterworth prototype order of the 20 Hz low-pass and the 0.4–10 Hz "
                        "band-pass (default 4)")
    p.add_argument("--boot", type=int, default=1000, metavar="N",
                   help="bootstrap resamples for the confidence intervals (default 1000; 0 off)")
    p.add_argument("--seed", type=int, default=0, help="bootstrap seed (default 0)")
    p.add_argument("--scheduler", metavar="ADDR", default=None,
                   help="process the sections on the Dask scheduler at ADDR (tcp://host:8786); "
                   "results equal the local run")
    p.set_defaults(func=cmd_validate)


def bar(value: float | None, cells: int = BAR_CELLS) -> str:
    """A bar of |value| (normalised, limit = 1.0 at the middle) with eighth-block resolution;
    the limit cell is marked ``│`` when the bar does not reach it."""
    if value is None:
        return "n/a".ljust(cells + 1)
    width = min(abs(value), 2.0) / 2.0 * cells
    full = int(width)
    frac = round((width - full) * 8)
    if frac == 8:
        full, frac = full + 1, 0
    chars = ["█"] * full + ([_BLOCKS[frac]] if frac and full < cells else [])
    chars += [" "] * (cells - len(chars))
    mid = cells // 2
    if chars[mid] == " ":
        chars[mid] = "│"
    return "".join(chars[:cells]) + ("+" if abs(value) > 2.0 else " ")


def _fmt(x: float | None, spec: str = ".3g") -> str:
    return "n/a" if x is None else format(x, spec)


def format_result(result: ValidationResult) -> str:
    """Human-readable table of a validation (the view model of :mod:`railval.app.views`)."""
    view = app_views.view_of(result)
    lines = []
    info = view.info
    lines.append(f"validation of {info.get('campaign', '?')} / {info.get('configuration', '?')}")
    lines.append("D_v = (S − M)·sign(M) (Polach & Böttcher 2014 eq. 4); std is the sample standard deviation "
                 "(n − 1); norm = value / limit; bars: |norm| from 0 to 2, │ = limit")
    lines.append(f"{'quantity':<9} {'unit':<6} {'n':>4} {'mean':>9} {'limit':>7} "
                 f"{'std':>9} {'limit':>7}  {'|mean|/limit':<21} {'std/limit':<21} "
                 f"{'95 % CI mean':>15} {'95 % CI std':>13}  result")
    for q in view.quantities:
        lines += _quantity_lines(q, core_quantities.QUANTITIES[q["quantity"]].unit)
    lines += _coverage_lines(view.coverage)
    for w in view.warnings:
        lines.append(f"warning: {w}")
    lines += format_supplementary(view.supplementary_rows())
    sensitive = view.sensitive_quantities
    if sensitive:
        lines.append("definition-sensitive (pass/fail changes under another reading of the "
                     "percentile or sliding-mean definition, docs/validation.md): "
                     + ", ".join(sensitive))
    verdict = "VALIDATED" if view.validated else "NOT VALIDATED"
    if view.verdict_sensitive:
        verdict += " (definition-sensitive: another reading gives the opposite verdict)"
    if view.in_sample is not None:
        verdict += f" (in-sample: {view.in_sample.note()})"
        if view.in_sample.held_out_check:
            verdict += f"\n{view.in_sample.held_out_check}"
    lines.append(verdict)
    return "\n".join(lines)


def _quantity_lines(q: dict, unit: str) -> list[str]:
    """The table row of one quantity (a row of the view model), the readings that flip its
    pass/fail and, when it fails, its largest pair."""
    ci_m = q["mean_norm_ci"]
    ci_s = q["std_norm_ci"]
    ci_m_txt = "n/a" if ci_m[0] is None else f"[{ci_m[0]:+.2f},{ci_m[1]:+.2f}]"
    ci_s_txt = "n/a" if ci_s[0] is None else f"[{ci_s[0]:.2f},{ci_s[1]:.2f}]"
    verdict = "PASS" if q["pass"] else "FAIL"
    if q["n"] and not q["robust"]:
        verdict += " (not robust)"
    if q["definition_sensitive"]:
        verdict += " (definition-sensitive)"
    lines = [(f"{q['quantity']:<9} {unit:<6} {q['n']:>4} "
             f"{_fmt(q['mean'], '+.3g'):>9} {q['mean_limit']:>7.3g} {_fmt(q['std']):>9} "
             f"{q['std_limit']:>7.3g}  {bar(q['mean_norm'])} {bar(q['std_norm'])} "
             f"{ci_m_txt:>15} {ci_s_txt:>13}  {verdict}")]
    for alt in q["definition_alternatives"]:
        if alt["flips"]:
            lines.append(f"{'':<9} {'passes' if alt['pass'] else 'fails'} with "
                         f"{alt['description']}: mean {_fmt(alt['mean'], '+.4g')}, "
                         f"std {_fmt(alt['std'], '.4g')}")
    if not q["pass"] and q["drilldown"]:
        worst = q["drilldown"][0]
        lines.append(f"{'':<9} largest: section {worst['section']} (zone {worst['zone']}) "
                     f"position {worst['position']}: D_v = {worst['D']:+.3g}, "
                     f"{worst['share_of_sum_of_squares'] * 100:.0f} % of ΣD²")
    return lines


def _coverage_lines(cov: Coverage) -> list[str]:
    zones = ", ".join(f"zone {z}: {n}" for z, n in cov.zones.items())
    lines = [(f"coverage: {cov.n_sections} sections (needs {cov.sections_required}); "
             f"{zones} (each needs {cov.sections_per_zone_required})")]
    if cov.shortfalls:
        lines += [f"coverage shortfall: {s}" for s in cov.shortfalls]
    else:
        lines.append("coverage: all rules met")
    return lines


def format_supplementary(rows: list[dict]) -> list[str]:
    """Lines of the supplementary block (bogie-frame and PSD-band quantities, the rows of
    :meth:`railval.app.views.ValidationView.supplementary_rows`)."""
    if not rows:
        return []
    lines = [("supplementary results (shown next to the verdict, they do not change it): "
              "D_v statistics, rel = value / mean |M_v|, log2 S/M = mean log2 ratio"),
             (f"{'quantity':<20} {'unit':<6} {'n':>4} {'mean':>9} {'std':>9} {'mean rel':>9} "
              f"{'std rel':>8} {'log2 S/M':>9}  processing")]
    for r in rows:
        lines.append(f"{r['quantity']:<20} {r['unit']:<6} {r['n']:>4} "
                     f"{_fmt(r['mean'], '+.3g'):>9} {_fmt(r['std'], '.3g'):>9} "
                     f"{_fmt(r['mean_rel'], '+.2f'):>9} {_fmt(r['std_rel'], '.2f'):>8} "
                     f"{_fmt(r['log2_ratio_mean'], '+.2f'):>9}  {r['processing']}")
    return lines


def cmd_validate(args: argparse.Namespace) -> int:
    database = connect(args.db)
    database.ensure_initialised()
    if args.scheduler:
        (result,) = validation_service.validate_configurations(database, args.campaign, [args.config],
                                                               order=args.order, n_boot=args.boot, seed=args.seed,
                                                               scheduler=args.scheduler).values()
    else:
        result = overview_service.validation(database, args.campaign, args.config, order=args.order,
                                             n_boot=args.boot, seed=args.seed)
    if args.json:
        doc = result.to_dict()
        ins = app_views.view_of(result).in_sample
        doc["in_sample"] = ins is not None
        # which fit makes it in-sample and the held-out check (None when not in-sample)
        doc["in_sample_provenance"] = ins.to_dict() if ins is not None else None
        emit_json(doc)
    else:
        print(format_result(result))
    return 0
