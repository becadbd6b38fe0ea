"""Test data: a small, physically plausible campaign folder in the railval format.

``write_demo_campaign(folder)`` writes ``campaign.json`` plus one table per (section,
source) following ``docs/campaign-format.md``: a passenger coach (Manchester Benchmark
vehicle 1 masses, Q0 ≈ 77 kN), 12 sections covering EN 14363 zones 1–4 with 3 sections
each, channels Y/Q of wheels w1L, w1R, w2L, w2R and car body accelerations ay_cb/az_cb
above both bogies, sampled at 200 Hz for 26–40 s per section (8 s run-in and run-out).

Physics of the synthetic signals (deliberately simple, but with the right magnitudes):

* uncompensated lateral acceleration in the track plane
  a_q = v²/R − g·h/s  (m/s²), h cant, s = 1.5 m the distance between the rail contact
  points (standard-gauge approximation; EN 14363 cant deficiency I = s·a_q/g);
* quasi-static ΣY per wheelset = M·a_q/4 (M the vehicle mass; the flanging leading wheelset
  takes more: ΣY_1 = 1.3·M·a_q/4, ΣY_2 = 0.7·M·a_q/4), plus a guiding term ±k/R on the
  leading wheelset that grows in tight curves;
* quasi-static wheel load transfer ΔQ = Q0·(a_q/g)·(h_cg/b0), h_cg = 1.4 m, b0 = 0.75 m;
* dynamic parts: band-limited Gaussian noise (forces 0.5–20 Hz, accelerations 0.4–10 Hz),
  sensor noise; curvature ramps linearly along the transitions.

The "baseline" configuration reproduces the same sections with its own noise, a 7 %
stiffer quasi-static guiding response, 10 % lower force dynamics and 15 % higher car body
accelerations — close to, but not equal to, the measurement. Further configurations
(``n_configs > 1``) form a lineage ``baseline → variant1 → variant2 …`` each a bit closer.
"""

from __future__ import annotations

import functools
import json
from pathlib import Path

import numpy as np
from scipy import signal as sps

G = 9.80665  # m/s², standard gravity
TRACK_S = 1.5  # m, lateral distance of the contact points (cant ↔ angle)
# Manchester Benchmark vehicle 1 (Iwnicki 1998): 32 000 + 2·2615 + 4·1813 kg gives
# M·g/8 ≈ 48 kN per wheel empty; a loaded coach with equipment and passengers reaches
# ≈ 77 kN per wheel, the value used here.
Q0_KN = 77.0
M_LOADED = Q0_KN * 1000 * 8 / G  # kg, mass that gives Q0 on 8 wheels

FORCE_CHANNELS = [f"{k}_{p}" for p in ("w1L", "w1R", "w2L", "w2R") for k in ("Y", "Q")]
ACC_CHANNELS = [f"{k}_{p}" for p in ("b1", "b2") for k in ("ay_cb", "az_cb")]
CHANNELS = FORCE_CHANNELS + ACC_CHANNELS

# (radius m, cant mm, speed km/h); zones cycle 1,2,3,4 so the first n sections stay spread
_SECTIONS = [
    (0.0, 0.0, 160.0),      # zone 1 straight
    (1200.0, 100.0, 140.0),  # zone 2
    (500.0, 130.0, 100.0),  # zone 3
    (300.0, 150.0, 75.0),   # zone 4
    (8000.0, 20.0, 160.0),  # zone 1 very large radius
    (2500.0, 60.0, 160.0),  # zone 2
    (450.0, 140.0, 95.0),   # zone 3
    (350.0, 150.0, 80.0),   # zone 4
    (0.0, 0.0, 140.0),      # zone 1
    (800.0, 120.0, 120.0),  # zone 2
    (600.0, 110.0, 105.0),  # zone 3
    (260.0, 150.0, 70.0),   # zone 4
]
COUNTRIES = ("DE", "AT", "CZ", "IT", "PL", "CH")


@functools.lru_cache(maxsize=32)
def _band(lo: float, hi: float, fs: float) -> np.ndarray:
    return sps.butter(2, [lo, hi], btype="bandpass", fs=fs, output="sos")


def _bandnoise(rng: np.random.Generator, n: int, fs: float, lo: float, hi: float, rms: float) -> np.ndarray:
    sos = _band(lo, hi, fs)
    x = sps.sosfilt(sos, rng.standard_normal(n + 400))[400:]
    return x * (rms / x.std())


def _section_geometry(radius: float, speed_kmh: float, duration_s: float) -> dict:
    v = speed_kmh / 3.6
    total = v * duration_s
    run = 8.0 * v  # 8 s run-in and run-out (filter transients stay outside)
    trans = 0.0 if radius == 0 else min(0.08 * total, 120.0)
    curve = total - 2 * run - 2 * trans
    return {
        "straight_in_m": round(run, 3),
        "transition_in_m": round(trans, 3),
        "curve_m": round(curve, 3),
        "transition_out_m": round(trans, 3),
        "straight_out_m": round(total - run - 2 * trans - curve, 3),
    }


def _curvature_fraction(dist: np.ndarray, layout: dict) -> np.ndarray:
    """0 on straights, 1 on the constant-curvature part, linear along the transitions."""
    a = layout["straight_in_m"]
    b = a + layout["transition_in_m"]
    c = b + layout["curve_m"]
    d = c + layout["transition_out_m"]
    return np.interp(dist, [0.0, a, b, c, d, d + 1e9], [0.0, 0.0, 1.0, 1.0, 0.0, 0.0])


def _signals(rng: np.random.Generator, t: np.ndarray, dist: np.ndarray, fs: float, radius: float,
             cant_mm: float, speed_kmh: float, direction: int, layout: dict,
             model: dict) -> dict[str, np.ndarray]:
    n = t.shape[0]
    frac = _curvature_fraction(dist, layout)
    v = speed_kmh / 3.6
    curv = 0.0 if radius == 0 else 1.0 / radius
    a_q = (v * v * curv - G * (cant_mm / 1000.0) / TRACK_S) * frac  # m/s², uncompensated
    sumy = M_LOADED * a_q / 4 / 1000.0  # kN per wheelset
    guide = model["guide"] * 2500.0 * curv * frac  # kN, flanging term on the leading axle
    dq = Q0_KN * (a_q / G) * (1.4 / 0.75) / 2  # kN per wheel
    out: dict[str, np.ndarray] = {}
    for ws, share, gterm in (("w1", 1.3, guide), ("w2", 0.7, 0.0 * guide)):
        sy = model["qs"] * share * sumy * direction
        outer, inner = ("R", "L") if direction > 0 else ("L", "R")
        y = {outer: 0.5 * sy + direction * gterm, inner: 0.5 * sy - direction * gterm}
        q = {outer: Q0_KN + dq, inner: Q0_KN - dq}
        for side in "LR":
            out[f"Y_{ws}{side}"] = (
                y[side] + _bandnoise(rng, n, fs, 0.5, 20.0, model["fdyn"] * 2.5)
                + 0.2 * rng.standard_normal(n)
            )
            out[f"Q_{ws}{side}"] = (
                q[side] + _bandnoise(rng, n, fs, 0.5, 20.0, model["fdyn"] * 4.0)
                + 0.3 * rng.standard_normal(n)
            )
    for b in ("b1", "b2"):
        out[f"ay_cb_{b}"] = (
            0.9 * a_q * direction + _bandnoise(rng, n, fs, 0.4, 10.0, model["acc"] * 0.25)
            + 0.01 * rng.standard_normal(n)
        )
        out[f"az_cb_{b}"] = (
            _bandnoise(rng, n, fs, 0.4, 10.0, model["acc"] * 0.20) + 0.01 * rng.standard_normal(n)
        )
    return {k: out[k] for k in CHANNELS}


def _write(path: Path, columns: dict[str, np.ndarray]) -> None:
    from railval.db.io import write_table

    write_table(path, columns)


def write_demo_campaign(
    folder: str | Path,
    n_sections: int = 12,
    fmt: str = "csv",
    seed: int = 0,
    n_configs: int = 1,
    *,
    name: str = "demo",
    fs: float = 200.0,
) -> Path:
    """Write a demo campaign folder and return the path of its ``campaign.json``.

    ``fmt`` is the data-file extension (csv, parquet, h5, mat, mf4, tdms). Deterministic
    for a given ``seed``.
    """
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    rng = np.random.default_rng(seed)
    truth = {"qs": 1.0, "guide": 1.0, "fdyn": 1.0, "acc": 1.0}
    sections, files_by_config = [], {}
    configs = [("baseline", None, {"qs": 1.07, "guide": 1.07, "fdyn": 0.9, "acc": 1.15})]
    for k in range(1, n_configs):
        shrink = 0.5**k  # each variant halves the baseline's error
        configs.append((f"variant{k}", configs[-1][0], {
            key: 1.0 + (val - 1.0) * shrink for key, val in configs[0][2].items()}))
    for name_, _parent, _model in configs:
        files_by_config[name_] = {}
    for i in range(n_sections):
        radius, cant, speed = _SECTIONS[i % len(_SECTIONS)]
        if i >= len(_SECTIONS):  # further sections: same zone, slightly different speed
            speed = speed * (1.0 - 0.03 * (i // len(_SECTIONS)))
        sid = f"S{i + 1:02d}"
        direction = 1 if i % 2 == 0 else -1
        duration = float(rng.uniform(26.0, 40.0))
        layout = _section_geometry(radius, speed, duration)
        n = round(duration * fs)
        t = np.arange(n) / fs
        # measured speed scatters by ±1.5 % and drifts slowly
        v = speed / 3.6 * (1.0 + 0.015 * np.sin(2 * np.pi * t / duration + rng.uniform(0, 6.3)))
        dist = np.concatenate([[0.0], np.cumsum(0.5 * (v[1:] + v[:-1]) / fs)])
        start = layout["straight_in_m"] + layout["transition_in_m"]
        evaluated = {"start_m": round(start, 3), "end_m": round(start + layout["curve_m"], 3)}
        ext = fmt.lstrip(".")
        rel = f"measured/{sid}.{ext}"
        cols = {"time_s": t, "distance_m": dist,
                **_signals(rng, t, dist, fs, radius, cant, speed, direction, layout, truth)}
        _write(folder / rel, cols)
        sections.append({
            "id": sid, "country": COUNTRIES[i % len(COUNTRIES)], "radius_m": radius,
            "cant_mm": cant, "speed_kmh": speed, "curve_direction": direction, "zone": None,
            "evaluated": evaluated, "layout": layout, "measured": rel,
        })
        dist_sim = t * speed / 3.6  # the simulation runs at the nominal speed
        for cname, _parent, model in configs:
            srel = f"sim/{cname}/{sid}.{ext}"
            scols = {"time_s": t, "distance_m": dist_sim,
                     **_signals(rng, t, dist_sim, fs, radius, cant, speed, direction, layout, model)}
            _write(folder / srel, scols)
            files_by_config[cname][sid] = srel
    manifest = {
        "format": {"id": "railval-campaign", "version": 1},
        "name": name,
        "description": f"synthetic demo campaign (seed {seed}) for tests",
        "zone1_min_radius_m": 5000,
        "vehicle": {
            "name": "Demo coach", "kind": "passenger", "secondary_suspension": True,
            "Q0_kN": Q0_KN, "template": "coach",
            "parameters": {"m_carbody": 32000.0, "m_bogie": 2615.0, "m_wheelset": 1813.0,
                           "bogie_centres": 19.0, "wheelbase": 2.56},
        },
        "channels": [
            {"name": ch, "kind": ch.rpartition("_")[0], "position": ch.rpartition("_")[2],
             "unit": "kN" if ch[0] in "YQ" else "m/s^2"}
            for ch in CHANNELS
        ],
        "sections": sections,
        "configurations": [
            {"name": cname, "parent": parent, "effects": {},
             # a template parameter of the built-in simulator, so the demo can be diagnosed;
             # the synthetic signals' own error factors are named in the description
             "parameters": {"c_yaw_damper": round(250e3 * model["fdyn"], 1)},
             "description": ("nominal model" if parent is None else f"refined from {parent}")
             + " (synthetic error factors " + ", ".join(f"{k} {v:g}" for k, v in model.items()) + ")",
             "files": files_by_config[cname]}
            for cname, parent, model in configs
        ],
    }
    path = folder / "campaign.json"
    path.write_text(json.dumps(manifest, indent=2))
    return path
