"""Diagnosis and calibration speed: diagnose one configuration with effects and template
parameters as candidates (target ≤ 5 s on a quiet machine, issue 41) and calibrate one effect
(target ≤ 10 s and converged, issue 41) on a synthetic 12-section coach campaign, 2 workers.

The same diagnosis is then run on a Dask ``LocalCluster`` with 1 and with 2 worker processes
(one thread each; warmed first, so the figures are the diagnosis and not the workers' start)
and the speed-up printed (``--no-dask``: skipped); the three diagnoses must agree.

Baseline measured in the same run: one simulation + evaluation of the whole campaign (the unit
of work both jobs repeat), so the figures can be read as "number of campaign simulations".
The screened diagnosis (``--screen K``: every candidate on 4 sections first, the K best on the
rest; with K = 8 the default of ``railval diagnose`` and the Diagnose page, so
``diagnose_screened_s`` is what a user waits for and ``diagnose_s`` the whole diagnosis of
``--whole``) is timed beside it and checked against it: verdict, top candidate, cause set, the
kept candidates' held-out shares. The diagnosis's CPU seconds — its calling process's and its pool workers' (forked children,
joined when it ends) — and the cores they kept busy on average: at the machine's core count the
diagnosis is CPU-bound and only less CPU makes it faster.
The campaign is synthesised into a temporary SQLite database (or ``--db``) with a hidden effect.
"""

from __future__ import annotations

import argparse
import os
import resource
import tempfile
import time
from pathlib import Path

from railval.core import lazy

#: deferred (railval.core.lazy): ``railval bench`` (the list) imports every benchmark module for its
#: docstring; what the benchmark runs loads when it runs (in a Dask worker too: ``_warm_worker``)
forkserver_warm = lazy.module("railval.app.services.forkserver_warm")
dask_distributed = lazy.module("dask.distributed")
diagnose = lazy.function("railval.app.services.diagnosis", "diagnose")
calibrate = lazy.function("railval.app.services.calibration", "calibrate")
evaluate_effects = lazy.function("railval.app.services.campaign_context", "evaluate_effects")
load_context = lazy.function("railval.app.services.campaign_context", "load_context")
synth = lazy.function("railval.app.services.synth", "synth")
repo = lazy.module("railval.db.repo")
start_context = lazy.function("railval.app.services.batch", "start_context")
connect = lazy.function("railval.db.engine", "connect")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--effect", default="friction_damping", help="hidden effect (default friction_damping)")
    parser.add_argument("--workers", type=int, default=2, help="process-pool workers (default 2)")
    parser.add_argument("--scheduler", default=None, help="Dask scheduler address instead of the pool")
    parser.add_argument("--values", type=int, default=3, help="diagnose: values per parameter (default 3)")
    parser.add_argument("--no-dask", action="store_true", help="skip the LocalCluster runs with 1 and 2 workers")
    parser.add_argument("--screen", type=int, default=8, metavar="K",
                        help="also the screened diagnosis keeping K candidates (default 8; 0: skip)")


def _warm_worker() -> bool:
    """Run on every Dask worker before it is timed: the simulator's and the EN chain's compiled
    kernels loaded by the same short campaign run the server's forkserver makes
    (:mod:`railval.app.services.forkserver_warm`; its import runs it once, the call once more)."""
    return forkserver_warm.warm_kernels() > 0


def _cpu() -> tuple[float, float]:
    """CPU seconds (user + system) of this process and of its ended child processes: the pool's
    workers are forked children, joined when the diagnosis closes its pool, so the difference
    around a diagnosis is its calling process's and its workers' CPU time."""
    own, kids = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_utime + own.ru_stime, kids.ru_utime + kids.ru_stime


def _timed(call) -> tuple:
    """(result, wall seconds, CPU seconds of the calling process and of its joined forked workers)
    of ``call()`` (:func:`_cpu` before and after)."""
    t0, (own0, kids0) = time.perf_counter(), _cpu()
    out = call()
    wall = time.perf_counter() - t0
    own1, kids1 = _cpu()
    return out, wall, {"calling_process": round(own1 - own0, 2), "workers": round(kids1 - kids0, 2)}


def screened_diagnosis(database, whole, keep: int, scheduler, workers: int, values: int, forked: bool) -> dict:
    """The screened diagnosis (``screen=keep``, docs/diagnosis.md "Screened diagnosis") of the
    same configuration: seconds, CPU, section runs against the whole diagnosis's, and whether its
    verdict, top candidate, cause set and the kept candidates' held-out shares equal ``whole``'s."""
    if not keep:
        return {}
    d, wall, cpu = _timed(lambda: diagnose(database, "bench", "baseline", scheduler=scheduler, workers=workers,
                                           values_per_parameter=values, screen=keep))
    held = {c.name: c.held_out_explained for c in whole.candidates}
    causes = [[c["name"] for c in r.causes or []] for r in (whole, d)]
    return {"diagnose_screened_s": round(wall, 2), "diagnose_screened_kept": keep,
            "diagnose_screened_cpu_s": cpu if forked else {"calling_process": cpu["calling_process"]},
            "diagnose_screened_section_runs": [d.screen.get("section_runs"), d.screen.get("section_runs_whole")],
            "diagnose_screened_same_verdict_top_causes": (d.verdict, d.candidates[0].name, causes[1])
            == (whole.verdict, whole.candidates[0].name, causes[0]),
            "diagnose_screened_kept_shares_equal": all(held[c.name] == c.held_out_explained for c in d.candidates)}


def dask_scaling(database, values: int) -> tuple[dict, list]:
    """The diagnosis on a LocalCluster of 1 and of 2 worker processes: seconds, speed-up and
    whether the rankings equal each other."""
    out: dict = {}
    ranks = []
    for n in (1, 2):
        with dask_distributed.LocalCluster(n_workers=n, threads_per_worker=1, dashboard_address=":0", processes=True) as cluster, \
                dask_distributed.Client(cluster) as client:
            client.run(_warm_worker)
            t0 = time.perf_counter()
            d = diagnose(database, "bench", "baseline", scheduler=client, values_per_parameter=values,
                         refresh=True, store=False)
            out[f"dask_{n}_worker_s"] = round(time.perf_counter() - t0, 2)
            ranks.append([(c.name, round(c.held_out_explained, 9)) for c in d.candidates])
    out["dask_speed_up_2_vs_1"] = round(out["dask_1_worker_s"] / out["dask_2_worker_s"], 2)
    out["dask_rankings_equal"] = ranks[0] == ranks[1]
    return out, ranks[0]


def run(args: argparse.Namespace) -> dict:
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
        # the workers' CPU is read as this process's ended children's: true for forked workers only
        # (a forkserver's workers are its children, not this process's)
        forked = scheduler is None and start_context().get_start_method() == "fork"
        diag, t_diag, cpu_diag = _timed(lambda: diagnose(database, "bench", "baseline", scheduler=scheduler,
                                                         workers=workers, values_per_parameter=values))
        first = diag.candidates[0]
        hidden = next((c for c in diag.candidates if c.name == effect), first)
        screened = screened_diagnosis(database, diag, getattr(args, "screen", 8), scheduler, workers, values, forked)
        t0 = time.perf_counter()
        cal = calibrate(database, "bench", "baseline", [effect], "calibrated", scheduler=scheduler,
                        workers=workers, start={effect: hidden.parameters})
        t_cal = time.perf_counter() - t0
        scaling, dask_rank = ({}, None) if getattr(args, "no_dask", False) else dask_scaling(database, values)
        if dask_rank is not None:
            scaling["dask_ranking_equals_pool"] = dask_rank == [(c.name, round(c.held_out_explained, 9))
                                                               for c in diag.candidates]
        database.dispose()
    return {
        "hidden_effect": effect,
        "sections": len(ctx.sections),
        "workers": workers if scheduler is None else f"dask {scheduler}",
        "synth_s": round(t_synth, 2),
        "baseline_one_campaign_simulation_s": round(t_one, 2),
        "diagnose_s": round(t_diag, 2),
        "diagnose_simulations": diag.simulations,
        "diagnose_target_s": 5,
        "diagnose_simulations_per_s": round(diag.simulations / t_diag, 2),
        # CPU-bound when cores_busy ≈ the machine's cores: then only less CPU makes it faster
        "diagnose_cpu_s": cpu_diag if forked else {"calling_process": cpu_diag["calling_process"]},
        "diagnose_cores_busy": round(sum(cpu_diag.values()) / t_diag, 2) if forked else None,
        "diagnose_candidates": len(diag.candidates),
        "diagnose_verdict": diag.verdict,
        "diagnose_top": first.name,
        "diagnose_explained": round(first.explained, 3),
        "diagnose_held_out": round(first.held_out_explained, 3),
        **screened,
        "calibrate_s": round(t_cal, 2),
        "calibrate_simulations": cal.n_evaluations + 1,
        "calibrate_target_s": 10,
        "calibrate_converged": cal.converged,
        "calibrate_stopped_by": cal.message,
        "calibrate_tolerance": cal.tolerance,
        "calibrated_parameters": cal.parameters,
        "objective_before_after": [cal.objective_start, cal.objective],
        **scaling,
        "load_1min": round(os.getloadavg()[0], 2),
    }
