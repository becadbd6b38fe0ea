"""Calibration speed and quality, old method against new in the same run:
``railval calibrate … --split`` of one hidden effect's parameter on a synthetic 12-section
coach campaign (fit on 8 sections, judge on 4), once with ``--global`` (differential evolution
+ Powell polish) and once with the default scan + trust-region least squares
(:func:`railval.core.calibration.calibrate_local`, Branch, Coleman & Li 1999).

Reported per method: fitted value against the hidden truth, held-out largest normalised error,
objective evaluations (campaign simulations), wall time, the optimizer's stopping message and
the 1-minute load average at the start (the machine may be shared). Target: ≤ 10 s for the new
method on a quiet 2-core machine.

``railval bench calibrate [--effect friction_damping] [--param friction_damping.force_kN] [--workers 2] [--seed 7]``
"""

from __future__ import annotations

import argparse
import json
import os
import tempfile
import time
from pathlib import Path

from railval.core import lazy

#: deferred (railval.core.lazy): ``railval bench`` (the list) imports every benchmark module for its
#: docstring; what the benchmark runs loads when it runs
calibrate = lazy.function("railval.app.services.calibration", "calibrate")
synth = lazy.function("railval.app.services.synth", "synth")
connect = lazy.function("railval.db.engine", "connect")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--effect", default="friction_damping", help="hidden effect (default friction_damping)")
    parser.add_argument("--param", default=None, help="fit only this parameter (effect.param; default: all)")
    parser.add_argument("--workers", type=int, default=2, help="process-pool workers (default 2)")
    parser.add_argument("--seed", type=int, default=7, help="synthetic campaign seed (default 7)")


def run(args: argparse.Namespace) -> dict:
    effect = getattr(args, "effect", "friction_damping")
    param = getattr(args, "param", None)
    workers = getattr(args, "workers", 2)
    seed = getattr(args, "seed", 7)
    rows = []
    with tempfile.TemporaryDirectory(prefix="railval-bench-cal-") as tmp:
        database = connect(f"sqlite:///{Path(tmp) / 'bench.db'}")
        database.init()
        synth(database, name="bench", hidden=[effect], seed=seed, reveal=Path(tmp) / "truth.json")
        truth = _truth(Path(tmp) / "truth.json", effect)
        for method in ("global", "local"):
            load = os.getloadavg()[0]
            t0 = time.perf_counter()
            cal = calibrate(database, "bench", "baseline", [effect], f"cal_{method}", workers=workers,
                            split=True, method=method, params=[param] if param else None)
            wall = time.perf_counter() - t0
            d = cal.to_dict()
            held = (d["lineage"][-1].get("held_out") or {}).get("max_error")
            rows.append({"method": method, "fitted": d["parameters"],
                         "held_out_max_error": None if held is None else round(held, 3),
                         "evaluations": d["n_evaluations"], "wall_s": round(wall, 2),
                         "message": d["message"], "tolerance": d["tolerance"], "load_1min": round(load, 2)})
        database.dispose()
    return {"hidden_effect": effect, "truth": truth, "sections": 12, "workers": workers,
            "target_local_s": 10, "methods": rows}


def _truth(path: Path, effect: str) -> dict:
    data = json.loads(path.read_text(encoding="utf-8"))
    return dict(data.get("hidden_effects", {}).get(effect, {}))
