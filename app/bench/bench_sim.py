"""Built-in simulator speed: real-time factor per core (coach, every effect on) and the wall
time to re-simulate a 12-section configuration on 2 cores, optionally side by side with an
earlier version of the simulator (``--reference-commit``) in the same run.

Real-time factor: simulated seconds / wall seconds (and / CPU seconds of the process, the
per-core figure on a machine shared with other jobs) of ``simulate_section`` on one section (a
curve below 120 km/h of a synthetic campaign, and a straight at 200 km/h), best of ``--repeat``
calls after a warm-up (compile cost excluded: numba ``cache=True``). With a reference commit
the same timing code runs in a child process that imports the simulator of that commit
(``git archive COMMIT core`` into a temporary package), alternating current / reference, with
identical sections and effect values, so machine-load drift hits both alike.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from railval.core import lazy

#: deferred (railval.core.lazy): ``railval bench`` (the list) imports every benchmark module for its
#: docstring; what the benchmark runs loads when it runs
VehicleModel = lazy.function("railval.core.sim", "VehicleModel")
simulate_campaign = lazy.function("railval.core.sim", "simulate_campaign")
sim_synth = lazy.module("railval.core.sim.synth")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--workers", type=int, default=2, help="processes for the campaign run")
    parser.add_argument("--sections", type=int, default=12, help="sections in the campaign run")
    parser.add_argument("--repeat", type=int, default=3, help="timed calls per figure (best is kept)")
    parser.add_argument("--reference-commit", default=None,
                        help="git commit of an earlier simulator to time side by side (e.g. 82818b4)")
    parser.add_argument("--rounds", type=int, default=2, help="alternating current/reference rounds")


def _all_effects() -> dict:
    return {k: dict(v) for k, v in sim_synth.HIDDEN_DEFAULTS.items()}


#: timing code run by the current and the reference interpreter alike (public API only)
_TIMING_CODE = r'''
import json, sys, time
from railval.core.sim import TrackSection, VehicleModel, simulate_section
spec = json.loads(sys.stdin.read())
veh = VehicleModel("coach")
out = {}
for name, sec_kw in spec["sections"].items():
    sec = TrackSection(**sec_kw)
    for label, eff in spec["effects"].items():
        simulate_section(veh, sec, eff)  # warm-up: loads the cached compiled kernel
        best = None
        best_cpu = None
        for _ in range(spec["repeat"]):
            t0 = time.perf_counter()
            c0 = time.process_time()
            ss = simulate_section(veh, sec, eff)
            w = time.perf_counter() - t0
            c = time.process_time() - c0
            best = w if best is None or w < best else best
            best_cpu = c if best_cpu is None or c < best_cpu else best_cpu
        sim_t = float(ss.time_s[-1] - ss.time_s[0])
        out[f"{name}/{label}"] = {"simulated_s": round(sim_t, 2), "wall_s": round(best, 4),
                                   "realtime_factor": round(sim_t / best, 1),
                                   "realtime_factor_cpu": round(sim_t / max(best_cpu, 1e-9), 1)}
print(json.dumps(out))
'''


def _run_timing(spec: dict, pythonpath: str | None = None) -> dict:
    env = dict(os.environ)
    if pythonpath:
        env["PYTHONPATH"] = pythonpath + os.pathsep + env.get("PYTHONPATH", "")
    res = subprocess.run([sys.executable, "-c", _TIMING_CODE], input=json.dumps(spec), capture_output=True,
                         text=True, env=env, check=True)
    return json.loads(res.stdout.strip().splitlines()[-1])


def _reference_package(commit: str, tmp: Path) -> str:
    """Extract ``core`` of ``commit`` as the package ``railval`` under ``tmp``; return the path
    to put on PYTHONPATH."""
    repo = Path(__file__).resolve().parents[2]
    pkg = tmp / "railval"
    pkg.mkdir(parents=True)
    archive = subprocess.run(["git", "-C", str(repo), "archive", commit, "core"], capture_output=True, check=True)
    subprocess.run(["tar", "-x", "-C", str(pkg)], input=archive.stdout, check=True)
    (pkg / "__init__.py").write_text("")
    return str(tmp)


def run(args: argparse.Namespace | None = None) -> dict:
    workers = getattr(args, "workers", 2)
    n_sections = getattr(args, "sections", 12)
    repeat = getattr(args, "repeat", 3)
    ref_commit = getattr(args, "reference_commit", None)
    rounds = getattr(args, "rounds", 2)
    veh = VehicleModel("coach")
    sc = sim_synth.build_campaign(hidden=sim_synth.parse_hidden(["friction_damping"]), seed=11, n_sections=n_sections)
    tracks = [s.track for s in sc.sections]
    curve = next(t for t in tracks if t.is_curve and t.speed_kmh < 120)
    straight = next(t for t in tracks if not t.is_curve and t.speed_kmh >= 180)

    def kw(t):
        d = {k: getattr(t, k) for k in ("id", "speed_kmh", "radius_m", "cant_mm", "curve_direction",
                                        "straight_in_m", "transition_in_m", "curve_m", "transition_out_m",
                                        "straight_out_m", "seed")}
        d["irregularity_level"] = "low"
        return d

    effects = {"no_effect": {}, "all_effects": {k: v for k, v in _all_effects().items()
                                                if k != "measured_irregularities"}}
    spec = {"sections": {f"curve_{curve.speed_kmh:g}kmh": kw(curve), f"straight_{straight.speed_kmh:g}kmh": kw(straight)},
            "effects": effects, "repeat": repeat}
    out: dict = {"conditions": {"effects_all": effects["all_effects"], "repeat": repeat,
                                "load_average": os.getloadavg()[0] if hasattr(os, "getloadavg") else None}}
    with tempfile.TemporaryDirectory() as tmp:
        ref_path = _reference_package(ref_commit, Path(tmp)) if ref_commit else None
        cur_rounds, ref_rounds = [], []
        for _ in range(max(1, rounds)):
            cur_rounds.append(_run_timing(spec))
            if ref_path:
                ref_rounds.append(_run_timing(spec, ref_path))
    for key in cur_rounds[0]:
        for fig in ("realtime_factor", "realtime_factor_cpu"):
            cur = max(r[key][fig] for r in cur_rounds)
            out[f"{fig}/{key}"] = cur
            if ref_rounds:
                ref = max(r[key][fig] for r in ref_rounds)
                out[f"{fig}_reference_{ref_commit}/{key}"] = ref
                out[f"{fig}_speedup_vs_reference/{key}"] = round(cur / ref, 2)
    sim_total = sum(t.length_m / t.speed_ms for t in tracks)
    for label, eff in (("no_effect", {"measured_irregularities": {}}), ("all_effects", _all_effects())):
        t0 = time.perf_counter()
        simulate_campaign(veh, tracks, effects=eff, workers=1)
        serial = time.perf_counter() - t0
        t0 = time.perf_counter()
        simulate_campaign(veh, tracks, effects=eff, workers=workers)
        first = time.perf_counter() - t0
        t0 = time.perf_counter()
        simulate_campaign(veh, tracks, effects=eff, workers=workers)
        warm = time.perf_counter() - t0
        out[f"campaign_{label}"] = {"sections": len(tracks), "simulated_s": round(sim_total, 1),
                                    "serial_wall_s": round(serial, 2),
                                    f"wall_s_{workers}_workers_first_call": round(first, 2),
                                    f"wall_s_{workers}_workers_warm_pool": round(warm, 2)}
    return out
