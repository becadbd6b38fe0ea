"""CLI verbs ``diagnose``, ``calibrate`` and ``modal`` (docs/design.md §7, §8).

``railval diagnose CAMPAIGN --config NAME [--json] [--scheduler ADDR]``
    rank the effects missing from a configuration by the share of its residual they explain.
``railval calibrate CAMPAIGN --config NAME --effect E [--effect …] --as NEW [--params P …]``
    add and fit effects, store NEW (parent NAME) and print its validation and the lineage.
``railval modal CAMPAIGN [--section S …] [--calibrate PARAM …] [--json]``
    SSI-COV car body modes and [ref 3] modal calibration (before/after frequency errors).

Progress goes to stderr; ``--json`` prints one JSON document on stdout.
"""

from __future__ import annotations

import argparse
import sys
from typing import Any

from railval.app.cli import emit_json


def _progress(stage: str, fraction: float, info: dict[str, Any]) -> None:
    extra = ""
    if "best" in info:
        extra = f" best objective {info['best']:.4g}"
    elif "done" in info:
        extra = f" {info['done']}/{info['total']}"
    print(f"[{fraction * 100:5.1f} %] {stage}{extra}", file=sys.stderr, flush=True)


def _db(args: argparse.Namespace):
    from railval.db.engine import connect

    database = connect(args.db)
    database.ensure_initialised()
    return database


def _cmd_diagnose(args: argparse.Namespace) -> int:
    from railval.app.services.diagnosis import diagnose

    res = diagnose(_db(args), args.campaign, args.config, progress=_progress, scheduler=args.scheduler,
                   values_per_parameter=args.values, effects=args.candidates)
    if args.json:
        emit_json(res.to_dict())
        return 0
    print(f"diagnosis of {args.campaign}/{args.config}: {res.note}")
    print(f"{'rank':>4}  {'effect':<26} {'explained':>9}  parameters / fixes / worsens")
    for k, c in enumerate(res.candidates, 1):
        params = ", ".join(f"{n}={v:.4g}" for n, v in c.parameters.items())
        print(f"{k:>4}  {c.effect:<26} {c.explained:9.2f}  {params}")
        print(f"{'':>42}fixes {', '.join(c.fixes) or '-'}; worsens {', '.join(c.worsens) or '-'}")
    if not res.separable:
        print("not separable; evidence: " + "; ".join(e["component"] for e in res.evidence))
    return 0


def _cmd_calibrate(args: argparse.Namespace) -> int:
    from railval.app.services.calibration import calibrate

    start: dict[str, dict[str, float]] = {}
    for item in args.start or []:
        key, sep, value = item.partition("=")
        effect, dot, pname = key.partition(".")
        if not (sep and dot):
            from railval.core.errors import InvalidParameter

            raise InvalidParameter(f"--start expects EFFECT.PARAM=VALUE, got {item!r}")
        start.setdefault(effect, {})[pname] = float(value)
    res = calibrate(_db(args), args.campaign, args.config, args.effect, args.new_name, params=args.params,
                    progress=_progress, scheduler=args.scheduler, seed=args.seed, replace=args.replace,
                    start=start or None)
    d = res.to_dict()
    if args.json:
        emit_json(d)
        return 0
    print(f"stored configuration {args.new_name} (parent {args.config}); objective "
          f"{d['objective_start']} → {d['objective']:.4g} in {d['n_evaluations']} simulations")
    for k, v in d["parameters"].items():
        print(f"  {k} = {v:.5g} {d['units'].get(k, '')}")
    print("lineage (largest normalised error): " + " → ".join(
        f"{x['configuration']} {x['max_error']:.2f}" for x in d["lineage"] if x["max_error"] is not None))
    print(f"validated: {d['validation']['validated']}")
    return 0


def _cmd_modal(args: argparse.Namespace) -> int:
    from railval.app.services.modal import modal

    d = modal(_db(args), args.campaign, sections=args.section, calibrate_params=args.calibrate,
              progress=_progress)
    if args.json:
        emit_json(d)
        return 0
    print(f"{'mode':>4} {'f [Hz]':>8} {'damping':>8} {'stable poles':>12}  shape")
    for k, m in enumerate(d["identification"]["modes"], 1):
        shape = ", ".join(f"{x:+.2f}" for x in m["shape"])
        print(f"{k:>4} {m['freq_hz']:8.3f} {m['damping']:8.3f} {m['n_stable']:>12}  [{shape}]")
    cal = d.get("calibration")
    if cal:
        print(f"\n{'mode':>4} {'f_exp':>8} {'f_before':>9} {'err %':>7} {'f_after':>8} {'err %':>7} {'MAC':>6}")
        for r in cal["modes"]:
            print(f"{r['mode']:>4} {r['freq_exp_hz']:8.3f} {r['freq_before_hz']:9.3f} {r['error_before_pct']:7.2f}"
                  f" {r['freq_after_hz']:8.3f} {r['error_after_pct']:7.2f} {r['mac_after']:6.3f}")
        print(f"mean |error| {cal['mean_abs_error_before_pct']:.2f} % → {cal['mean_abs_error_after_pct']:.2f} %")
        for k, v in cal["parameters_after"].items():
            print(f"  {k}: {cal['parameters_before'].get(k, float('nan')):.5g} → {v:.5g}")
    return 0


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser("diagnose", help="rank the physical effects missing from a configuration")
    p.add_argument("campaign")
    p.add_argument("--config", required=True, metavar="NAME")
    p.add_argument("--scheduler", metavar="ADDR", default=None,
                   help="Dask scheduler address (default: local process pool, 2 workers)")
    p.add_argument("--values", type=int, default=3, help="simulated values per effect parameter besides its default (default 3)")
    p.add_argument("--candidates", nargs="+", default=None, metavar="E",
                   help="consider only these effects (default: every effect of the library not in NAME)")
    p.add_argument("--json", action="store_true")
    p.set_defaults(func=_cmd_diagnose)

    c = subparsers.add_parser("calibrate", help="add effects, fit their parameters, store a new configuration")
    c.add_argument("campaign")
    c.add_argument("--config", required=True, metavar="NAME", help="parent configuration")
    c.add_argument("--effect", action="append", required=True, metavar="E")
    c.add_argument("--as", dest="new_name", required=True, metavar="NEW")
    c.add_argument("--params", nargs="+", default=None, metavar="P",
                   help="calibrate only these (effect.param, param or model.NAME)")
    c.add_argument("--scheduler", metavar="ADDR", default=None)
    c.add_argument("--seed", type=int, default=0)
    c.add_argument("--replace", action="store_true", help="overwrite NEW if it exists")
    c.add_argument("--start", nargs="+", default=None, metavar="EFFECT.PARAM=VALUE",
                   help="start values of the search (e.g. the values diagnose fitted)")
    c.add_argument("--json", action="store_true")
    c.set_defaults(func=_cmd_calibrate)

    m = subparsers.add_parser("modal", help="SSI-COV car body modes and modal calibration ([ref 3])")
    m.add_argument("campaign")
    m.add_argument("--section", action="append", default=None, metavar="S")
    m.add_argument("--calibrate", nargs="+", default=None, metavar="PARAM",
                   help="coach modal parameters to fit, e.g. k_secondary_z I_pitch_carbody")
    m.add_argument("--json", action="store_true")
    m.set_defaults(func=_cmd_modal)
