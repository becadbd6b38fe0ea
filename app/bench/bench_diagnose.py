"""Diagnosis and calibration speed: diagnose one configuration with effects and template
parameters as candidates (target ≤ 30 s) and calibrate one effect (target ≤ 120 s) on a
synthetic 12-section coach campaign, 2 workers.

Baseline measured in the same run: one simulation + evaluation of the whole campaign (the unit
of work both jobs repeat), so the figures can be read as "number of campaign simulations".
The campaign is synthesised into a temporary SQLite database (or ``--db``) with a hidden effect.
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--effect", default="friction_damping", help="hidden effect (default friction_damping)")
    parser.add_argument("--workers", type=int, default=2, help="process-pool workers (default 2)")
    parser.add_argument("--scheduler", default=None, help="Dask scheduler address instead of the pool")
    parser.add_argument("--values", type=int, default=3, help="diagnose: values per parameter (default 3)")


def run(args: argparse.Namespace) -> dict:
    from railval.app.services.calibration import calibrate
    from railval.app.services.campaign_context import evaluate_effects, load_context
    from railval.app.services.diagnosis import diagnose
    from railval.app.services.synth import synth
    from railval.db import repo
    from railval.db.engine import connect

    effect = getattr(args, "effect", "friction_damping")
    workers = getattr(args, "workers", 2)
    scheduler = getattr(args, "scheduler", None)
    values = getattr(args, "values", 3)
    with tempfile.TemporaryDirectory(prefix="railval-bench-diag-") as tmp:
        database = connect(f"sqlite:///{Path(tmp) / 'bench.db'}")
        database.init()
        t0 = time.perf_counter()
        synth(database, name="bench", hidden=[effect], seed=7)
        t_synth = time.perf_counter() - t0
        with database.session() as s:
            ctx = load_context(s, "bench")
            conf = repo.get_configuration(s, "bench", "baseline")
            effects = dict(conf.effects or {})
        evaluate_effects((ctx, effects, {}))  # warm the compiled kernels
        t0 = time.perf_counter()
        evaluate_effects((ctx, effects, {}))
        t_one = time.perf_counter() - t0
        t0 = time.perf_counter()
        diag = diagnose(database, "bench", "baseline", scheduler=scheduler, workers=workers,
                        values_per_parameter=values)
        t_diag = time.perf_counter() - t0
        first = diag.candidates[0]
        hidden = next((c for c in diag.candidates if c.name == effect), first)
        t0 = time.perf_counter()
        cal = calibrate(database, "bench", "baseline", [effect], "calibrated", scheduler=scheduler,
                        workers=workers, start={effect: hidden.parameters})
        t_cal = time.perf_counter() - t0
        database.dispose()
    return {
        "hidden_effect": effect,
        "sections": len(ctx.sections),
        "workers": workers if scheduler is None else f"dask {scheduler}",
        "synth_s": round(t_synth, 2),
        "baseline_one_campaign_simulation_s": round(t_one, 2),
        "diagnose_s": round(t_diag, 2),
        "diagnose_simulations": diag.simulations,
        "diagnose_target_s": 30,
        "diagnose_simulations_per_s": round(diag.simulations / t_diag, 2),
        "diagnose_candidates": len(diag.candidates),
        "diagnose_verdict": diag.verdict,
        "diagnose_top": first.name,
        "diagnose_explained": round(first.explained, 3),
        "diagnose_held_out": round(first.held_out_explained, 3),
        "calibrate_s": round(t_cal, 2),
        "calibrate_simulations": cal.n_evaluations + 1,
        "calibrate_target_s": 120,
        "calibrated_parameters": cal.parameters,
        "objective_before_after": [cal.objective_start, cal.objective],
    }
