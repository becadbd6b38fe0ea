"""Built-in simulator speed: real-time factor per core (coach, every effect on) and the wall
time to re-simulate a 12-section configuration on 2 cores.

Baseline measured in the same run: the coach with no effect (the cheapest model), so the cost
of the effects is visible. Figures are wall-clock on this machine; compile cost is excluded
(cache=True, one warm-up call).
"""

from __future__ import annotations

import argparse
import time


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--workers", type=int, default=2, help="processes for the campaign run")
    parser.add_argument("--sections", type=int, default=12, help="sections in the campaign run")


def _all_effects() -> dict:
    from railval.core.sim.synth import HIDDEN_DEFAULTS

    return {k: dict(v) for k, v in HIDDEN_DEFAULTS.items()}


def run(args: argparse.Namespace | None = None) -> dict:
    from railval.core.sim import VehicleModel, simulate_campaign, simulate_section
    from railval.core.sim.synth import build_campaign, parse_hidden

    workers = getattr(args, "workers", 2)
    n_sections = getattr(args, "sections", 12)
    veh = VehicleModel("coach")
    sc = build_campaign(hidden=parse_hidden(["friction_damping"]), seed=11, n_sections=n_sections)
    tracks = [s.track for s in sc.sections]
    one = next(t for t in tracks if t.is_curve and t.speed_kmh < 120)
    out: dict = {}
    for label, eff in (("no_effect", {"measured_irregularities": {}}), ("all_effects", _all_effects())):
        simulate_section(veh, one, eff)  # warm-up (loads the cached compiled kernel)
        t0 = time.perf_counter()
        ss = simulate_section(veh, one, eff)
        wall = time.perf_counter() - t0
        sim_t = float(ss.time_s[-1] - ss.time_s[0])
        out[f"realtime_factor_{label}"] = round(sim_t / wall, 1)
        out[f"section_{label}"] = {"simulated_s": round(sim_t, 1), "wall_s": round(wall, 3),
                                   "speed_kmh": one.speed_kmh}
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
