"""DynoTRAIN scale: many configurations evaluated from the database; one new configuration.

Data (built once, reused): ``./bench-data/dynotrain.db`` (SQLite) holding a campaign of
``--sections`` sections (default 17: zones 1–4 with 5/4/4/4 sections) with 20 channels each
(Y and Q of 8 wheels, car body ay/az above both bogies), ``--samples`` samples at ``--fs`` Hz
(default 20 000 at 500 Hz = 40 s), a measurement and ``--configs`` configurations. One
configuration gives sections × 64 values (comparisons); the full DynoTRAIN scale of ≈ 50 000
comparisons is 46 configurations (≈ 2.5 GB of samples). The build imports the measurement and
the first configuration through the campaign importer (HDF5 files under
``./bench-data/campaign``) and stores the others with :func:`railval.db.repo.store_configuration`;
``./bench-data/dynotrain.json`` records what was built, its size and build time. A build with
other parameters is rebuilt.

Figures:

* ``all`` — every configuration validated from the database with an empty result cache
  (:func:`railval.app.services.validation.validate_configurations`, ``--workers`` processes over
  chunks of sections), seconds and comparisons per second (target ≤ 5 s for 50 000 on 2
  cores); when fewer than 50 000 comparisons were built, the time for 50 000 is extrapolated
  linearly and labelled so;
* ``new_config`` — one new configuration stored, then validated including database reads
  and the bootstrap (1000 resamples) with the measured side cached (target ≤ 0.1 s), beside
  the same evaluation with nothing cached (another filter order, so no key matches; target
  ≤ 0.2 s).

Each figure carries its split (``split_s``, :mod:`railval.core.stages`): database (queries,
blob reads, cache writes), decode (inflate, hash check), checks, filter, statistics,
alternatives, supplementary (the EN chain), cache_pack/cache_unpack (cached values as JSON),
aggregation (pairing, normalised errors, verdicts) and bootstrap; in ``all`` also
worker_start (each new worker process loading the compiled kernels) and main_idle (the main
process waiting for a chunk), both also printed on their own, with the main process's CPU
seconds. Stage seconds add up over threads and worker processes (the pipeline overlaps
reading and processing), so their sum may exceed the elapsed time. The 1-minute load
average is printed beside every figure. ``--backend threads`` runs the ``--workers`` as
threads of one process instead of processes.
  ``--part new`` times only this (after validating ``c000`` once, untimed, which caches the
  measured side and warms the process as a running app server would be);
  ``--repeat N`` times it N times. Before every timing the result-cache entries of the new
  configuration (both orders) and of the measured side at the other order are deleted, so
  the figures never profit from an earlier run.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import time
from pathlib import Path

import numpy as np

from railval.core import lazy
from railval.core.types import BODY_POSITIONS, WHEEL_POSITIONS, SectionInfo, SignalSet

#: deferred (railval.core.lazy): ``railval bench`` (the list) imports every benchmark module for its
#: docstring; what the benchmark runs loads when it runs
repo = lazy.module("railval.db.repo")
connect = lazy.function("railval.db.engine", "connect")
import_campaign = lazy.function("railval.db.importer", "import_campaign")
write_table = lazy.function("railval.db.io", "write_table")
validate_configurations = lazy.function("railval.app.services.validation", "validate_configurations")
collect = lazy.function("railval.core.stages", "collect")
validate_configuration = lazy.function("railval.app.services.validation", "validate_configuration")
source_cache_keys = lazy.function("railval.app.services.validation_rows", "source_cache_keys")
codec = lazy.module("railval.db.codec")
evaluate_batch = lazy.function("railval.core.en14363", "evaluate_batch")
#: third-party libraries of the benchmark's own steps, loaded when they run
dask_distributed = lazy.module("dask.distributed")

CHANNELS = [f"{k}_{p}" for p in WHEEL_POSITIONS for k in ("Y", "Q")] + [
    f"{k}_cb_{b}" for b in BODY_POSITIONS for k in ("ay", "az")]
ZONE_RADII = {1: 0.0, 2: 1000.0, 3: 500.0, 4: 300.0}
TARGET_COMPARISONS = 50_000


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--configs", type=int, default=46,
                        help="configurations in the database (46 ≈ 50 000 comparisons)")
    parser.add_argument("--sections", type=int, default=17)
    parser.add_argument("--samples", type=int, default=20_000)
    parser.add_argument("--fs", type=float, default=500.0)
    parser.add_argument("--workers", type=int, default=2, help="processes (default 2)")
    parser.add_argument("--backend", choices=["processes", "threads"], default="processes",
                        help="the --workers are processes (default) or threads of one process")
    parser.add_argument("--boot", type=int, default=200,
                        help="bootstrap resamples in the all-configurations run")
    parser.add_argument("--data", default="bench-data", help="folder of the built data")
    parser.add_argument("--dask", action="store_true",
                        help="also run all configurations on a Dask LocalCluster (--scheduler "
                        "path) and compare time and results with the process pool")
    parser.add_argument("--part", choices=["both", "new"], default="both",
                        help="'new': only the new-configuration figure (the measured side is "
                             "cached first if needed, untimed; the all-configurations run is "
                             "skipped)")
    parser.add_argument("--repeat", type=int, default=1,
                        help="new-configuration timings (each on an uncached configuration)")


def _zones(n_sections: int) -> list[int]:
    base = [1, 1, 2, 3, 4, 1, 2, 3, 4, 1, 2, 3, 4, 1, 2, 3, 4]
    return [base[i % len(base)] for i in range(n_sections)]


def _section_signals(rng: np.random.Generator, n: int, fs: float, zone: int,
                     gain: float) -> tuple[np.ndarray, np.ndarray, dict]:
    t = np.arange(n) / fs
    v = 25.0 * (1 + 0.03 * np.sin(2 * np.pi * t / 25.0 + rng.uniform(0, 6)))
    d = np.concatenate([[0.0], np.cumsum(0.5 * (v[1:] + v[:-1]) / fs)])
    curve = 4.0 * (zone - 1)
    ch = {}
    for p in WHEEL_POSITIONS:
        lead = 1.5 if p.startswith("w1") else 1.0
        side = 1.0 if p.endswith("L") else -0.6
        ch[f"Y_{p}"] = gain * (curve * lead * side + 3.0 * rng.standard_normal(n))
        ch[f"Q_{p}"] = 75.0 + gain * (curve * side + 5.0 * rng.standard_normal(n))
    for b in BODY_POSITIONS:
        ch[f"ay_cb_{b}"] = gain * 0.35 * rng.standard_normal(n)
        ch[f"az_cb_{b}"] = gain * 0.30 * rng.standard_normal(n)
    return t, d, ch


def _config_sets(rng, n_sections, n, fs, gain) -> dict[str, SignalSet]:
    out = {}
    for i, zone in enumerate(_zones(n_sections)):
        t, d, ch = _section_signals(rng, n, fs, zone, gain)
        out[f"S{i + 1:02d}"] = SignalSet(fs, t, d, ch)
    return out


def build(data: Path, n_configs: int, n_sections: int, n: int, fs: float) -> dict:
    """Build (or reuse) the benchmark database; returns the build record."""

    spec = {"configs": n_configs, "sections": n_sections, "samples": n, "fs": fs,
            "channels": len(CHANNELS), "seed": 0}
    marker = data / "dynotrain.json"
    db_path = data / "dynotrain.db"
    if marker.exists() and db_path.exists():
        record = json.loads(marker.read_text())
        if record.get("spec") == spec:
            record["reused"] = True
            return record
    data.mkdir(parents=True, exist_ok=True)
    if db_path.exists():
        db_path.unlink()
    t0 = time.perf_counter()
    rng = np.random.default_rng(0)
    folder = data / "campaign"
    folder.mkdir(exist_ok=True)
    sections = []
    files = {}
    measured = _config_sets(rng, n_sections, n, fs, 1.0)
    first = _config_sets(rng, n_sections, n, fs, 1.05)
    for (sid, ss), zone in zip(measured.items(), _zones(n_sections)):
        run = float(ss.distance_m[int(10 * fs)])  # 10 s run-in / run-out
        write_table(folder / f"m_{sid}.h5", {"time_s": ss.time_s, "distance_m": ss.distance_m,
                                             **ss.channels})
        sim = first[sid]
        write_table(folder / f"c000_{sid}.h5", {"time_s": sim.time_s,
                                                "distance_m": sim.distance_m, **sim.channels})
        files[sid] = f"c000_{sid}.h5"
        sections.append({
            "id": sid, "country": "DE", "radius_m": ZONE_RADII[zone], "cant_mm": 100.0,
            "speed_kmh": 90.0, "curve_direction": 1, "zone": None,
            "evaluated": {"start_m": round(run, 3),
                          "end_m": round(float(ss.distance_m[-1]) - run, 3)},
            "measured": f"m_{sid}.h5"})
    manifest = {
        "format": {"id": "railval-campaign", "version": 1}, "name": "dynotrain-bench",
        "description": "synthetic DynoTRAIN-scale benchmark campaign", "zone1_min_radius_m": 5000,
        "vehicle": {"name": "bench coach", "kind": "passenger", "secondary_suspension": True,
                    "Q0_kN": 75.0, "template": "coach", "parameters": {}},
        "channels": [{"name": c, "kind": c.rpartition("_")[0], "position": c.rpartition("_")[2],
                      "unit": "kN" if c[0] in "YQ" else "m/s^2"} for c in CHANNELS],
        "sections": sections,
        "configurations": [{"name": "c000", "parent": None, "effects": {}, "parameters": {},
                            "description": "", "files": files}],
    }
    (folder / "campaign.json").write_text(json.dumps(manifest, indent=1))
    database = connect(f"sqlite:///{db_path}")
    database.init()
    import_campaign(database, folder)
    for k in range(1, n_configs):
        sets = _config_sets(rng, n_sections, n, fs, 1.0 + 0.1 * rng.standard_normal())
        with database.session(write=True) as session:
            repo.store_configuration(session, "dynotrain-bench", f"c{k:03d}", parent=None,
                                     effects={}, parameters={}, description="",
                                     signalsets=sets)
    database.dispose()
    record = {"spec": spec, "build_s": round(time.perf_counter() - t0, 1),
              "db_bytes": db_path.stat().st_size, "db_path": str(db_path), "reused": False}
    marker.write_text(json.dumps(record, indent=1))
    return record


def _cpu_seconds() -> float:
    """User + system CPU seconds of this process and its terminated children."""
    me = resource.getrusage(resource.RUSAGE_SELF)
    kids = resource.getrusage(resource.RUSAGE_CHILDREN)
    return me.ru_utime + me.ru_stime + kids.ru_utime + kids.ru_stime


#: stages in the order printed (railval.core.stages)
STAGES = ("database", "decode", "checks", "filter", "statistics", "alternatives",
          "supplementary", "cache_pack", "cache_unpack", "aggregation", "bootstrap",
          "worker_start", "main_idle")


def _split(seconds: dict[str, float]) -> dict[str, float]:
    names = [*STAGES, *sorted(set(seconds) - set(STAGES))]
    return {k: round(seconds[k], 4) for k in names if k in seconds}


def _dask_run(database, args: argparse.Namespace, pool_results: dict) -> dict:
    """The all-configurations run again on a Dask ``LocalCluster`` of ``--workers`` worker
    processes (``--scheduler`` path, cache emptied first), in the same run as the process
    pool; the results must be equal."""
    with dask_distributed.LocalCluster(n_workers=args.workers, threads_per_worker=1, processes=True,
                      dashboard_address=":0") as cluster:
        with database.session(write=True) as session:
            repo.cache_delete(session, prefix="en14363:")
        load = os.getloadavg()[0]
        t0 = time.perf_counter()
        res = validate_configurations(database, "dynotrain-bench", list(pool_results),
                                      n_boot=args.boot, scheduler=cluster.scheduler_address)
        seconds = time.perf_counter() - t0
    equal = all(res[k].to_dict() == pool_results[k].to_dict() for k in pool_results)
    return {"seconds": round(seconds, 2), "workers": args.workers, "equal_to_pool": equal,
            "load_average_before": round(load, 2)}


def _all_configurations(database, args: argparse.Namespace) -> dict:
    """Every configuration validated with an empty result cache (``all``)."""

    with database.session(write=True) as session:
        repo.cache_delete(session, prefix="en14363:")
    load_before = os.getloadavg()[0]
    cpu0 = _cpu_seconds()
    main0 = time.process_time()
    t0 = time.perf_counter()
    with collect() as split_all:
        results = validate_configurations(database, "dynotrain-bench",
                                          [f"c{k:03d}" for k in range(args.configs)],
                                          n_boot=args.boot, workers=args.workers,
                                          backend=getattr(args, "backend", "processes"))
    t_all = time.perf_counter() - t0
    cpu_all = _cpu_seconds() - cpu0
    cpu_main = time.process_time() - main0
    comparisons = sum(q.n for r in results.values() for q in r.quantities.values())
    out = {
        "configurations": len(results), "sections": args.sections,
        "signals_per_section": len(CHANNELS), "samples_per_signal": args.samples,
        "fs_hz": args.fs, "comparisons": comparisons, "workers": args.workers,
        "seconds": round(t_all, 2),
        # CPU of this process and its finished workers: what the run needs of the cores
        "cpu_seconds": round(cpu_all, 2), "load_average_before": round(load_before, 2),
        "comparisons_per_s": round(comparisons / t_all, 1), "target_s_for_50000": 5.0,
        "backend": getattr(args, "backend", "processes"),
        # CPU of the main process alone (planning, seals, unpacking, verdicts, cache write)
        "cpu_seconds_main_process": round(cpu_main, 2),
        # loading the compiled kernels in each new worker process, summed over the workers
        "worker_start_s": round(split_all.seconds.get("worker_start", 0.0), 3),
        # the main process waiting for a worker's chunk (nothing else to do)
        "main_idle_s": round(split_all.seconds.get("main_idle", 0.0), 3),
        "split_s": _split(split_all.seconds),
    }
    if comparisons >= TARGET_COMPARISONS:
        out["seconds_for_50000"] = round(t_all * TARGET_COMPARISONS / comparisons, 2)
        out["target_met"] = bool(out["seconds_for_50000"] <= 5.0)
    else:
        out["EXTRAPOLATED_seconds_for_50000"] = round(t_all * TARGET_COMPARISONS / comparisons, 2)
        out["EXTRAPOLATED_cpu_seconds_for_50000"] = round(
            cpu_all * TARGET_COMPARISONS / comparisons, 2)
        out["note"] = (f"scaled run: {comparisons} comparisons measured; the 50 000 "
                       "figure is a linear extrapolation")
    return out, results


def _time_new(database, sets: dict, order: int | None) -> tuple:
    """One new-configuration timing: ``order=None`` with the measured side cached, else
    nothing cached (another filter order). Before it the new configuration is stored again,
    its cache entries (both orders) and the measured side's at the other order deleted, and
    the process's verified-array cache emptied (:data:`railval.db.codec.VERIFIED`), so the
    figure never profits from an earlier run. Returns (elapsed s, split, result, load
    average, CPU s)."""

    if order is None:
        with database.session(write=True) as session:
            repo.store_configuration(session, "dynotrain-bench", "new", parent=None,
                                     effects={}, parameters={}, description="",
                                     signalsets=sets, replace=True)
        with database.session(write=True) as session:
            secs = repo.section_infos(session, "dynotrain-bench")
            stale = [*source_cache_keys(session, "dynotrain-bench", "new", secs).values(),
                     *source_cache_keys(session, "dynotrain-bench", "new", secs,
                                        order=5).values(),
                     *source_cache_keys(session, "dynotrain-bench", None, secs,
                                        order=5).values()]
            repo.cache_delete(session, keys=stale)
    codec.VERIFIED.clear()
    load = os.getloadavg()[0]
    cpu0 = _cpu_seconds()
    t0 = time.perf_counter()
    with collect() as split, database.write_session(deferred=True) as session:
        res = validate_configuration(session, "dynotrain-bench", "new", n_boot=1000,
                                     **({} if order is None else {"order": order}))
    return time.perf_counter() - t0, split.seconds, res, load, _cpu_seconds() - cpu0


def _new_configuration(database, args: argparse.Namespace, repeat: int) -> dict:
    """``new_config``: one new configuration, measured side cached / nothing cached."""
    # warm this process (compiled filter kernel loaded from numba's cache, imports), as in a
    # running app server; the all-configurations run above used the worker processes

    warm = _config_sets(np.random.default_rng(1), 1, 4000, args.fs, 1.0)["S01"]
    evaluate_batch([warm], [SectionInfo("W", 0, 0, 90, 1, 50.0, 150.0)])
    sets = _config_sets(np.random.default_rng(99), args.sections, args.samples, args.fs, 1.02)
    new, cold = [], []
    for _ in range(repeat):
        new.append(_time_new(database, sets, None))
        res_new = new[-1][2]
        assert res_new.info["sections_measured"]["computed"] == 0
        assert res_new.info["sections_simulated"]["cached"] == 0
        cold.append(_time_new(database, sets, 5))
    best_new = min(new, key=lambda x: x[0])
    best_cold = min(cold, key=lambda x: x[0])
    out = {
        "sections": args.sections, "signals": args.sections * len(CHANNELS),
        "values": sum(q.n for q in res_new.quantities.values()),
        "seconds_measured_cached": round(best_new[0], 3),
        "seconds_nothing_cached": round(best_cold[0], 3),
        "cpu_seconds_measured_cached": round(best_new[4], 3),
        "cpu_seconds_nothing_cached": round(best_cold[4], 3),
        "target_s_measured_cached": 0.1, "target_s_nothing_cached": 0.2,
        "target_met": bool(best_new[0] <= 0.1 and best_cold[0] <= 0.2),
        "load_average_1min": [round(x[3], 2) for x in new],
        "split_s_measured_cached": _split(best_new[1]),
        "split_s_nothing_cached": _split(best_cold[1]),
    }
    if repeat > 1:
        out["all_seconds_measured_cached"] = [round(x[0], 3) for x in new]
        out["all_seconds_nothing_cached"] = [round(x[0], 3) for x in cold]
    return out


def run(args: argparse.Namespace) -> dict:
    """The benchmark: build or reuse the data, then the figures of the module docstring."""

    data = Path(args.data)
    record = build(data, args.configs, args.sections, args.samples, args.fs)
    database = connect(f"sqlite:///{data / 'dynotrain.db'}")
    database.init()  # a database built by an earlier version: migrated (untimed)
    only_new = getattr(args, "part", "both") == "new"
    out: dict = {"data": record}
    if not only_new:
        out["all"], results = _all_configurations(database, args)
        if getattr(args, "dask", False):
            out["all_dask"] = _dask_run(database, args, results)
    else:
        # measured side cached (computed here, untimed, if an earlier run left it out) and
        # this process warmed as in a running app server
        with database.write_session(deferred=True) as session:
            validate_configuration(session, "dynotrain-bench", "c000", n_boot=1000)
    out["new_config"] = _new_configuration(database, args, max(1, int(getattr(args, "repeat", 1))))
    database.dispose()
    return out
