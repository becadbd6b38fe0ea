"""CLI verb ``metrics`` (docs/design.md §4, §8).

``railval metrics CAMPAIGN --config NAME [--section S …] [--channel C …] [--family F …]
[--max-lag SECONDS] [--lowpass HZ | --no-lowpass] [--part section|evaluated] [--json]``
    curve-comparison metrics of a configuration against the measurement, one row per
    (section, channel), every metric raw and synchronised.
``railval metrics --list``
    the metric registry (name, unit, range, best value, source).

``--json`` prints one document: ``campaign``, ``config``, ``settings``, ``metrics`` (the
registry entries used), ``rows`` and ``summary`` (median/mean per column).
"""

from __future__ import annotations

import argparse
import math
from typing import Any

from railval.app.cli import LazyChoices, emit_json
from railval.core import lazy

# the services and records this module's verbs call, imported when a verb first uses
# them (railval.core.lazy): `railval --help` and the other verbs never load them
core_errors = lazy.module("railval.core.errors")
core_metrics = lazy.module("railval.core.metrics")
connect = lazy.function("railval.db.engine", "connect")  # the --db URL → its connection
metrics_service = lazy.module("railval.app.services.metrics")
overview_service = lazy.module("railval.app.services.overview")

#: headline columns of the text table: (metric, width, format)
_TABLE = (("sg_M", "SG M", 6, "+.3f"), ("sg_P", "SG P", 5, ".3f"), ("sg_C", "SG C", 5, ".3f"),
          ("russell_C", "Russell C", 5, ".3f"), ("ks_D", "KS D", 5, ".3f"),
          ("ks_p_eff", "KS p(n_eff)", 5, ".3f"), ("area", "area", 7, ".4g"),
          ("iso_rating", "ISO R", 5, ".3f"))


def _fmt(v: Any, spec: str) -> str:
    if v is None or (isinstance(v, float) and not math.isfinite(v)):
        return "-"
    if isinstance(v, str):
        return v
    return format(v, spec)


def _clean(v: Any) -> Any:
    if hasattr(v, "item"):
        v = v.item()
    if isinstance(v, float) and not math.isfinite(v):
        return None
    return v


def _cmd_metrics(args: argparse.Namespace) -> int:
    if args.list:
        rows = core_metrics.registry_table()
        if args.json:
            emit_json({"metrics": rows})
            return 0
        print(f"{'name':<14} {'unit':<8} {'range':<15} {'best':<10} {'label'} — source")
        for r in rows:
            print(f"{r['name']:<14} {r['unit']:<8} {r['range']:<15} {r['best']!s:<10} "
                  f"{r['label']} — {r['source']}")
        return 0
    if not args.campaign or not args.config:
        raise core_errors.InvalidParameter("metrics needs CAMPAIGN and --config NAME (or --list)")

    database = connect(args.db)
    database.ensure_initialised()
    lowpass_hz = None if args.no_lowpass else args.lowpass
    df = overview_service.metrics(database, args.campaign, args.config, args.section, args.channel,
                                  lowpass_hz=lowpass_hz, max_lag_s=args.max_lag, families=args.family,
                                  part=args.part, subsample=args.subsample)
    names = core_metrics.metric_names(args.family)
    if args.json:
        rows = [{k: _clean(v) for k, v in rec.items()} for rec in df.to_dict(orient="records")]
        emit_json({
            "campaign": args.campaign, "config": args.config,
            "settings": {"lowpass_hz": lowpass_hz, "max_lag_s": args.max_lag, "part": args.part,
                         "subsample": args.subsample, "families": args.family},
            "metrics": [core_metrics.METRICS[n].to_dict() for n in names],
            "rows": rows,
            "summary": metrics_service.summary(df),
        })
        return 0
    cols = [c for c in _TABLE if c[0] in names]
    filt = f"low-pass {lowpass_hz:g} Hz" if lowpass_hz else "unfiltered"
    print(f"metrics of {args.campaign}/{args.config} ({args.part}, {filt}, sync window "
          f"±{args.max_lag:g} s); each cell raw/synchronised")
    head = f"{'section':<8} {'channel':<10} {'lag s':>6} "
    head += " ".join(f"{label:^{2 * w + 1}}" for _, label, w, _ in cols)
    if "iso_grade" in names:
        head += f"  {'ISO grade':<20}"
    print(head)
    for rec in df.to_dict(orient="records"):
        lag_txt = _fmt(rec['lag_s'], '+.2f') + ("" if rec.get("lag_reliable", True) else "!")
        line = f"{rec['section']:<8} {rec['channel']:<10} {lag_txt:>6} "
        line += " ".join(f"{_fmt(rec[n], f):>{w}}/{_fmt(rec[n + '_sync'], f):<{w}}" for n, _, w, f in cols)
        if "iso_grade" in names:
            line += f"  {_fmt(rec['iso_grade'], 's')}/{_fmt(rec['iso_grade_sync'], 's')}"
        if rec.get("error"):
            line += f"  error: {rec['error']}"
        print(line)
    print(f"{len(df)} comparisons; units: area in the channel unit (kN or m/s^2); "
          f"`railval metrics --list` explains every metric")
    if "lag_reliable" in df.columns and not df["lag_reliable"].astype(bool).all():
        print(f"! lag at or within 5 % of the ±{args.max_lag:g} s search bound: unreliable "
              f"(the true lag may lie outside the window; the synchronised values are doubtful)")
    return 0


def _families() -> list[str]:
    return sorted(core_metrics.FAMILIES)


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "metrics", help="curve-comparison metrics (Sprague–Geers, Russell, KS, area, AD, ISO 18571)",
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("campaign", nargs="?", help="campaign name or id")
    p.add_argument("--config", help="configuration name")
    p.add_argument("--section", action="append", metavar="S", help="section id (repeatable; default all)")
    p.add_argument("--channel", action="append", metavar="C", help="channel (repeatable; default all)")
    p.add_argument("--family", action="append", choices=LazyChoices(_families), metavar="FAMILY",
                   help="metric family: %(choices)s (repeatable; default all)")
    p.add_argument("--max-lag", type=float, default=2.0, metavar="SECONDS",
                   help="synchronisation window ±SECONDS (default 2)")
    p.add_argument("--subsample", action="store_true", help="refine the lag below one sample")
    p.add_argument("--lowpass", type=float, default=20.0, metavar="HZ",
                   help="zero-phase Butterworth low-pass before comparing (default 20 Hz)")
    p.add_argument("--no-lowpass", action="store_true", help="compare unfiltered signals")
    p.add_argument("--part", choices=("section", "evaluated"), default="section",
                   help="whole recorded section (default) or only the evaluated constant-curvature part")
    p.add_argument("--list", action="store_true", help="print the metric registry and exit")
    p.add_argument("--json", action="store_true", help="print one JSON document")
    p.set_defaults(func=_cmd_metrics)
