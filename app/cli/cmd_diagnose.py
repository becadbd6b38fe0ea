"""CLI verbs ``diagnose``, ``calibrate`` and ``modal`` (docs/design.md §7, §8).

``railval diagnose CAMPAIGN --config NAME [--json] [--scheduler ADDR] [--candidates E|model.P …] [--screen K | --whole]``
    rank the effects missing from a configuration and the template parameters that may be
    mis-set by the share of its residual they explain on held-out sections; verdict
    cause / uncertain / none against the noise floor; the next step. Screened by default
    (every candidate on a few sections first, the best K on all: docs/diagnosis.md "Screened
    diagnosis"); ``--whole`` simulates every candidate on every section.
``railval calibrate CAMPAIGN --config NAME --effect E|model.P [--effect …] --as NEW [--params P …]
[--fit-sections S … | --holdout S … | --split]``
    add and fit effects or parameters, store NEW (parent NAME) and print its validation (in-sample
    or on held-out sections), plausibility flags, the lineage and the next step.
``railval modal CAMPAIGN [--section S …] [--calibrate PARAM …] [--json]``
    SSI-COV car body modes and [ref 3] modal calibration (before/after frequency errors).

Progress goes to stderr; ``--json`` prints one JSON document on stdout.
"""

from __future__ import annotations

import argparse

from railval.app.cli import Progress, emit_json
from railval.core import lazy
from railval.core.errors import InvalidParameter

# the services and records this module's verbs call, imported when a verb first uses
# them (railval.core.lazy): `railval --help` and the other verbs never load them
app_views = lazy.module("railval.app.views")
calibration_service = lazy.module("railval.app.services.calibration")
calibration_plan = lazy.module("railval.app.services.calibration_plan")
connect = lazy.function("railval.db.engine", "connect")  # the --db URL → its connection
diagnosis_service = lazy.module("railval.app.services.diagnosis")
modal_service = lazy.module("railval.app.services.modal")
screen_rules = lazy.module("railval.core.diagnosis.screen")  # SCREEN_KEEP: the default K


def _db(args: argparse.Namespace):
    database = connect(args.db)
    database.ensure_initialised()
    return database


def _cmd_diagnose(args: argparse.Namespace) -> int:
    res = diagnosis_service.diagnose(_db(args), args.campaign, args.config, progress=Progress(), scheduler=args.scheduler,
                                     values_per_parameter=args.values, effects=args.candidates,
                                     **({"include_parameters": False} if args.no_parameters else {}),
                                     **({} if args.whole else {"screen": screen_rules.SCREEN_KEEP
                                                               if args.screen is None else args.screen}))
    if args.json:
        emit_json(res.to_dict())
        return 0
    view = app_views.diagnosis_view_of(res)
    print(f"diagnosis of {args.campaign}/{args.config}: verdict {view.verdict.upper()} — {view.note}")
    print(f"noise floor (share of pure section scatter the candidates explain, 95 %): {view.noise_floor:.2f}")
    _print_lineage(view)
    for kind, text in view.statements:
        print(f"input ({kind}): {text}")
    print(f"{'rank':>4}  {'candidate':<28} {'kind':<9} {'held-out':>8} {'explained':>9}  fitted")
    for k, c in enumerate(view.candidates, 1):
        print(f"{k:>4}  {c.name:<28} {c.kind:<9} {c.held_out_explained:8.2f} {c.explained:9.2f}  {c.summary}")
        print(f"{'':>6}fixes {', '.join(c.fixes) or '-'}; worsens {', '.join(c.worsens) or '-'}")
        for f in c.flags:
            print(f"{'':>6}! {f}")
    _print_causes(view)
    for f in view.families:
        print(f"family {f.title} ({f.share:.0%} of the residual): {f.verdict}"
              + (f", best {f.best} {f.best_held_out:.2f} held-out" if f.best is not None else "")
              + (f" — STRUCTURAL: {f.structural_reason}" if f.structural else ""))
    for s in view.skipped:
        print(f"left out: {s.name} ({s.kind}) — {s.reason}")
    if view.screened_out:
        print("screened: the candidates below are not ranked and count in the noise floor; --whole simulates "
              "every candidate on every section")
    for s in view.screened_out:
        print(f"screened out (simulated on {', '.join(view.screen_sections)} only): {s.name} ({s.kind}) — {s.reason}")
    if view.verdict == "none" and view.unexplained:
        print("unexplained (largest components): " + "; ".join(
            f"{component} {residual:+.2f}" for component, residual in view.unexplained))
    if view.next_text:
        print(f"next: {view.next_text}")
    return 0


def _print_causes(view) -> None:
    """The cause set (greedy, joint refit) and the candidates it left out or passed over."""
    if view.causes:
        print("causes (greedy, joint refit; share added on held-out sections): " + ", ".join(
            f"{c.name} {c.held_out_share:.2f}" for c in view.causes)
              + f" — together {view.cause_set.held_out_explained:.2f}")
    for x in view.cause_set.left_out:
        print(f"not in the cause set: {x.name} — {x.reason}")
    for x in view.cause_set.passed_over:
        print(f"passed over (the search carried on): {x.name} — {x.reason}")


def _print_lineage(view) -> None:
    """The lineage of diagnoses (root first) and what is left after the calibration
    (a :class:`railval.app.views.DiagnosisView`)."""
    if not view.has_lineage:
        return
    print("lineage of diagnoses: " + " → ".join(
        f"{a.configuration} " + (f"#{a.diagnosis} {str(a.verdict).upper()}"
                                 + (f" {a.top}" if a.top else "") if a.diagnosis else "(not diagnosed)")
        for a in view.ancestors) + f" → {view.lineage_configuration}")
    if view.lineage_statement:
        print(f"after calibration: {view.lineage_statement}")


def _cmd_calibrate(args: argparse.Namespace) -> int:
    start: dict[str, dict[str, float]] = {}
    for item in args.start or []:
        key, sep, value = item.partition("=")
        effect, dot, pname = key.partition(".")
        if not (sep and dot):
            raise InvalidParameter(f"--start expects EFFECT.PARAM=VALUE or model.NAME=VALUE, got {item!r}")
        start.setdefault(effect, {})[pname] = float(value)
    res = calibration_service.calibrate(_db(args), args.campaign, args.config, args.effect, args.new_name, params=args.params,
                                        progress=Progress(), scheduler=args.scheduler, seed=args.seed, replace=args.replace,
                                        start=start or None, fit_sections=args.fit_sections, holdout=args.holdout, split=args.split,
                                        method="global" if args.global_search else "local")
    d = res.to_dict()
    if args.json:
        emit_json(d)
        return 0
    print(f"stored configuration {args.new_name} (parent {args.config}); objective "
          f"{d['objective_start']} → {d['objective']:.4g} in {d['n_evaluations']} simulations")
    print(f"optimizer ({d['method']}): {d['message']}")
    print(calibration_plan.tolerance_text(d))
    if calibration_plan.start_text(d):
        print(calibration_plan.start_text(d))
    for k, v in d["parameters"].items():
        print(f"  {k} = {v:.5g} {d['units'].get(k, '')}")
    print("lineage (largest normalised error): " + " → ".join(
        f"{x['configuration']} {x['max_error']:.2f}" for x in d["lineage"] if x["max_error"] is not None))
    if d["held_out_sections"]:
        print(f"fitted on {len(d['fit_sections'])} sections, held out {', '.join(d['held_out_sections'])}")
        last = d["lineage"][-1].get("held_out") or {}
        if last.get("max_error") is not None:
            parent = last.get("parent_max_error")
            print("held-out sections: largest normalised error "
                  + (f"{parent:.2f} → " if parent is not None else "") + f"{last['max_error']:.2f}")
    print(f"validated: {d['validation']['validated']}" + (" (in-sample)" if d["in_sample"] else ""))
    print(f"plausible: {d['plausible']}")
    for f in d["flags"]:
        print(f"  ! {f}")
    print(f"next: {d['next']['text']}")
    return 0


def _cmd_modal(args: argparse.Namespace) -> int:
    d = modal_service.modal(_db(args), args.campaign, sections=args.section, calibrate_params=args.calibrate,
                            progress=Progress())
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
                   help="consider only these candidates: effect ids, model.PARAM template parameters and "
                        "measurement gains 'gain CHANNEL' and offsets 'offset CHANNEL' (one argument, quoted) "
                        "(default: every effect of the library not in NAME and the template's parameters)")
    p.add_argument("--no-parameters", action="store_true",
                   help="try the effects only, not the vehicle template's parameters")
    how = p.add_mutually_exclusive_group()
    how.add_argument("--screen", type=int, default=None, metavar="K",
                     help="simulate every effect and parameter candidate on a few sections (one per test zone "
                          "first), then only the K that explain most there on the whole campaign; the others are "
                          "listed, not ranked, and counted in the noise floor (about half the simulation; "
                          "default: the Diagnose page's K; docs/diagnosis.md \"Screened diagnosis\")")
    how.add_argument("--whole", action="store_true",
                     help="simulate every candidate on every section (no screen; about twice the time)")
    p.add_argument("--json", action="store_true")
    p.set_defaults(func=_cmd_diagnose)

    c = subparsers.add_parser("calibrate", help="add effects, fit their parameters, store a new configuration")
    c.add_argument("campaign")
    c.add_argument("--config", required=True, metavar="NAME", help="parent configuration")
    c.add_argument("--effect", action="append", required=True, metavar="E",
                   help="effect id, or model.PARAM for a template parameter candidate (as diagnose names it)")
    c.add_argument("--as", dest="new_name", required=True, metavar="NEW")
    c.add_argument("--params", nargs="+", default=None, metavar="P",
                   help="calibrate only these (effect.param, param or model.NAME)")
    c.add_argument("--scheduler", metavar="ADDR", default=None)
    c.add_argument("--seed", type=int, default=0)
    c.add_argument("--replace", action="store_true", help="overwrite NEW if it exists")
    c.add_argument("--start", nargs="+", default=None, metavar="EFFECT.PARAM=VALUE",
                   help="start values of the search (model.PARAM=VALUE too); an effect or parameter "
                        "without one starts from the values the newest stored diagnosis of --config fitted")
    split = c.add_mutually_exclusive_group()
    split.add_argument("--fit-sections", nargs="+", default=None, metavar="S",
                       help="fit on these sections only; validate on the others (held-out)")
    split.add_argument("--holdout", nargs="+", default=None, metavar="S",
                       help="hold these sections out of the fit and validate on them")
    split.add_argument("--split", action="store_true",
                       help="hold out one section per zone and fold (every zone on both sides where possible)")
    c.add_argument("--global", dest="global_search", action="store_true",
                   help="differential evolution + Powell polish (multi-modal cases) instead of the default "
                        "scan + trust-region least squares")
    c.add_argument("--json", action="store_true")
    c.set_defaults(func=_cmd_calibrate)

    m = subparsers.add_parser("modal", help="SSI-COV car body modes and modal calibration: model frequencies fitted to "
                                   "the identified modes, paired by MAC (docs/design.md §7)")
    m.add_argument("campaign")
    m.add_argument("--section", action="append", default=None, metavar="S")
    m.add_argument("--calibrate", nargs="+", default=None, metavar="PARAM",
                   help="coach modal parameters to fit, e.g. k_secondary_z I_pitch_carbody")
    m.add_argument("--json", action="store_true")
    m.set_defaults(func=_cmd_modal)
