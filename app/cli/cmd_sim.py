"""CLI verbs ``simulate`` and ``synth`` (docs/design.md §6, §7).

``railval simulate CAMPAIGN --config NAME [--parent P] [--effect ID[:k=v,...]]... [--param k=v]... [--rrd FILE] [--replace]``
    simulate every section with the built-in simulator and store the configuration (``--rrd``:
    measured profiles' rolling-radius difference table instead of the conicity).
``railval synth [--name N] [--vehicle coach|wagon] [--hidden EFFECT[=VALUE]]... [--seed S]
[--reveal FILE] [--out DIR] [--sections N]``
    build a synthetic campaign with hidden effect(s) and import it.

Progress goes to stderr; ``--json`` prints one JSON document on stdout.
"""

from __future__ import annotations

import argparse

from railval.app.cli import Progress, emit_json
from railval.core.errors import InvalidParameter
from railval.core import lazy

# the services and records this module's verbs call, imported when a verb first uses
# them (railval.core.lazy): `railval --help` and the other verbs never load them
core_effects = lazy.module("railval.core.sim.effects")
core_vehicles = lazy.module("railval.core.sim.vehicles")
database_service = lazy.module("railval.app.services.database")
simulation_service = lazy.module("railval.app.services.simulation")
synth_service = lazy.module("railval.app.services.synth")


def _db(args: argparse.Namespace):
    return database_service.open_database(args.db)


def parse_effect(item: str) -> tuple[str, dict[str, float]]:
    """``"friction_damping:force_kN=2"`` → ``("friction_damping", {"force_kN": 2.0})``."""
    eff, _, rest = item.partition(":")
    params = {}
    for kv in filter(None, rest.split(",")):
        k, sep, v = kv.partition("=")
        if not sep:
            raise InvalidParameter(f"--effect {item!r}: expected k=v after ':', got {kv!r}")
        try:
            params[k.strip()] = float(v)
        except ValueError:
            raise InvalidParameter(f"--effect {item!r}: value of {k!r} must be a number, got {v!r}") from None
    return eff.strip(), params


def parse_param(item: str) -> tuple[str, float]:
    k, sep, v = item.partition("=")
    if not sep:
        raise InvalidParameter(f"--param expects k=v, got {item!r}")
    try:
        return k.strip(), float(v)
    except ValueError:
        raise InvalidParameter(f"--param {k!r}: value must be a number, got {v!r}") from None


def _cmd_simulate(args: argparse.Namespace) -> int:
    effects = dict(parse_effect(e) for e in args.effect or [])
    params: dict = dict(parse_param(p) for p in args.param or [])
    if args.rrd:
        params[core_vehicles.CONTACT_PARAMETER] = simulation_service.contact_geometry_file(args.rrd)
    res = simulation_service.simulate_configuration(_db(args), args.campaign, args.config, parent=args.parent, effects=effects,
                                                    parameters=params, replace=args.replace, workers=args.workers,
                                                    scheduler=args.scheduler, progress=Progress())
    if args.json:
        emit_json(res)
    else:
        table = res["parameters"].get("contact_geometry")
        print(f"stored configuration {res['configuration']!r} of {res['campaign']!r} "
              f"({res['sections']} sections; effects: {', '.join(res['effects']) or 'none'}"
              + (f"; measured profiles {table['source']!r}, equivalent conicity "
                 f"{res['equivalent_conicity']:.3f} at 3 mm" if table else "") + ")")
    return 0


def _cmd_synth(args: argparse.Namespace) -> int:
    res = synth_service.synth(_db(args), name=args.name, template=args.vehicle, hidden=args.hidden, seed=args.seed,
                              n_sections=args.sections, out=args.out, reveal=args.reveal, progress=Progress())
    if args.json:
        emit_json(res)
    else:
        print(f"imported synthetic campaign {res['campaign']!r}: {res['sections']} sections, "
              f"{res['template']} template, configuration 'baseline'"
              + (f"; truth written to {res['reveal']}" if res["reveal"] else ""))
    return 0


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("simulate", help="simulate a configuration with the built-in simulator and store it",
                       description="Simulate every section of CAMPAIGN and store configuration NAME.")
    p.add_argument("campaign", metavar="CAMPAIGN")
    p.add_argument("--config", required=True, metavar="NAME", help="name of the configuration to store")
    p.add_argument("--parent", metavar="P", default=None, help="parent configuration (its effects are kept)")
    p.add_argument("--effect", action="append", metavar="ID[:k=v,...]",
                   help=f"switch an effect on (repeatable); ids: {', '.join(core_effects.EFFECT_IDS)}")
    p.add_argument("--param", action="append", metavar="k=v", help="vehicle template parameter override")
    p.add_argument("--rrd", metavar="FILE", default=None,
                   help="measured profiles: rolling-radius difference table (CSV y_mm,delta_r_mm[,delta_gamma_rad], "
                        "EN 15302) used instead of the conicity; stored with the configuration")
    p.add_argument("--replace", action="store_true", help="overwrite an existing configuration NAME")
    p.add_argument("--workers", type=int, default=None,
                   help="processes (default: 2 for long runs above 1500 s simulated, else 1)")
    p.add_argument("--scheduler", metavar="ADDR", default=None,
                   help="simulate on the Dask scheduler at ADDR (tcp://host:8786); results equal "
                   "the local run")
    p.add_argument("--json", action="store_true", help="print one JSON document")
    p.set_defaults(func=_cmd_simulate)

    q = sub.add_parser("synth", help="build and import a synthetic campaign with hidden effect(s)",
                       description="Build a campaign whose measurements come from the model plus hidden "
                                   "effect(s) and nuisances; the truth is written only with --reveal.")
    q.add_argument("--name", default="synth", help="campaign name (default synth)")
    q.add_argument("--vehicle", choices=["coach", "wagon"], default="coach")
    q.add_argument("--hidden", action="append", metavar="EFFECT[=VALUE]",
                   help="hidden effect (repeatable); EFFECT:k=v,... sets several parameters; "
                        "default friction_damping")
    q.add_argument("--seed", type=int, default=1)
    q.add_argument("--sections", type=int, default=12, help="number of sections (>= 12)")
    q.add_argument("--reveal", metavar="FILE", default=None, help="write the truth (JSON) to FILE")
    q.add_argument("--out", metavar="DIR", default=None, help="keep the campaign folder in DIR")
    q.add_argument("--json", action="store_true", help="print one JSON document")
    q.set_defaults(func=_cmd_synth)
