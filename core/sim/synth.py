"""Synthetic campaigns with a hidden effect (docs/design.md §7 "Data with a hidden effect"). Pure: builds
arrays and manifest records; :mod:`railval.app.services.synth` writes and imports them.

Recipe
------
* ≥ 12 sections, ≥ 3 per EN 14363 zone, several countries; each section carries ≈ 10 s of
  run-in and run-out around its evaluated constant-curvature range.
* "True" track: irregularities from the ORE B176 low-level spectrum scaled by the section's
  speed (:data:`TRUE_TRACK_BANDS`: ≥ 160 km/h × 1.0, 120–160 km/h × 1.3, below × 1.64 = the
  ORE high level) with a few isolated short defects (dipped welds, 2–4 mm over 3–5 m). The campaign
  stores them as the measured irregularities (``layout["irregularities"]``) as a track
  recording car would: gain 0.96 and 0.15 mm noise (so the stored arrays are not exactly
  the truth).
* Measurements = TRUTH model = baseline template + hidden effect(s) run on the true track,
  plus nuisances outside the effect library: asymmetric secondary vertical dampers (+12 % in
  rebound, coach), speed scatter (σ = 1.5 %), per-channel gain errors (σ = 2 %), sensor noise
  (0.3 kN, 0.02 m/s²), time offsets of 1–3 samples per section.
* Baseline configuration ``baseline``: the nominal template. Its irregularities: the measured
  ones (effect ``measured_irregularities`` at scale 1 is part of the baseline) whenever the
  hidden effect is something else — so the residual is the hidden effect's alone; when
  ``measured_irregularities`` itself is hidden, the baseline runs on irregularities generated
  from the ORE B176 low-level spectrum (what a modeller uses without track data), which makes
  the missing effect identifiable.
* The truth (hidden effects and values, nuisances) is returned as ``truth`` for ``--reveal``;
  nothing in the campaign names it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from railval.core.errors import InvalidParameter
from railval.core.sim.effects import EFFECTS, resolve_effects
from railval.core.sim.model import simulate_section
from railval.core.sim.track import (
    DS,
    TrackSection,
    generate_irregularities,
    irregularities_to_layout,
)
from railval.core.sim.vehicles import G, VehicleModel
from railval.core.types import SignalSet, split_channel
from railval.core.zones import zone_for_radius

#: hidden-effect values used when ``--hidden EFFECT`` gives no value: inside each parameter's
#: plausible range (``Param.plausible``), at its end where the effect is weakest to see; whether
#: the baseline then fails the DynoTRAIN limits is checked and tabulated in docs/simulator.md
HIDDEN_DEFAULTS: dict[str, dict[str, float]] = {
    "friction_damping": {"force_kN": 2.5},
    "damper_series_stiffness": {"k_series_MN_m": 3.0},
    "carbody_flexibility": {"frequency_Hz": 7.0, "damping_ratio": 0.01},
    "track_flexibility": {"k_vertical_MN_m": 20.0, "k_lateral_MN_m": 5.0},
    "wheel_rail_friction": {"mu": 0.18},
    "conicity": {"conicity": 0.45},
    "measured_irregularities": {"scale": 1.0},
    "parasitic_yaw_stiffness": {"k_yaw_kNm_rad": 1500.0},
    "lateral_bumpstop": {"clearance_mm": 12.0, "stiffness_kN_mm": 2.0},
}
#: the wagon's values where they differ (freight: acceleration limits doubled, stiffer suspension)
HIDDEN_DEFAULTS_WAGON: dict[str, dict[str, float]] = {
    "wheel_rail_friction": {"mu": 0.1},
    "conicity": {"conicity": 0.5},
    "lateral_bumpstop": {"clearance_mm": 8.0, "stiffness_kN_mm": 2.0},
}


def hidden_defaults(template: str = "coach") -> dict[str, dict[str, float]]:
    """Default hidden-effect values for ``template``.

    Parameters
    ----------
    template : str
        Vehicle template name (``"wagon"`` has its own values).

    Returns
    -------
    dict of str to dict of str to float
        ``{effect: {param: value}}``.
    """
    out = {k: dict(v) for k, v in HIDDEN_DEFAULTS.items()}
    if template == "wagon":
        out.update({k: dict(v) for k, v in HIDDEN_DEFAULTS_WAGON.items()})
    return out


#: which parameter ``--hidden EFFECT=VALUE`` sets
MAIN_PARAMETER = {e: next(iter(EFFECTS[e].parameters)) for e in EFFECTS}

#: amplitude factor of the "true" track over the ORE B176 LOW-level spectrum, by line speed
#: (ERRI B176 RP1 1989 low level ≈ well-kept lines for high speed; the high level has
#: sqrt(1.080/0.4032) = 1.64 × its amplitude): ≥ 160 km/h × 1.0, 120–160 km/h × 1.3, below
#: 120 km/h × 1.64 (= ORE high level, conventional lines and freight lines ≤ 100 km/h). The
#: banding is an ASSUMPTION of this simulator (standard deviations per band in docs/simulator.md)
TRUE_TRACK_BANDS = ((160.0, 1.0), (120.0, 1.3), (0.0, 1.64))
TRUE_TRACK_TEMPLATES = ("coach", "wagon")


def true_track_scale(speed_kmh: float) -> float:
    """Amplitude factor over the ORE B176 low level for a section run at ``speed_kmh``."""
    for v_min, f in TRUE_TRACK_BANDS:
        if speed_kmh >= v_min:
            return f
    return TRUE_TRACK_BANDS[-1][1]

COUNTRIES = ("DE", "AT", "CH", "IT", "FR", "CZ", "SE", "PL")

NUISANCE_DEFAULTS = {"damper_asymmetry": 0.12, "speed_sigma": 0.015, "gain_sigma": 0.02,
                     "noise_force_kN": 0.3, "noise_acc": 0.02, "max_offset_samples": 3,
                     "recording_gain": 0.96, "recording_noise_mm": 0.15}


@dataclass
class SynthSection:
    track: TrackSection  # with the stored (recorded) irregularities
    true_irregularities: dict
    country: str
    zone: int

    def manifest_record(self) -> dict:
        t = self.track
        a, b = t.eval_range
        layout = {"straight_in_m": t.straight_in_m, "transition_in_m": t.transition_in_m,
                  "curve_m": t.curve_m, "transition_out_m": t.transition_out_m,
                  "straight_out_m": t.straight_out_m, "irregularity_level": t.irregularity_level,
                  "seed": t.seed}
        if t.irregularities is not None:  # a campaign without measured track geometry stores none
            layout["irregularities"] = irregularities_to_layout(t.irregularities)
        return {"id": t.id, "country": self.country, "radius_m": t.radius_m if t.is_curve else 0.0,
                "cant_mm": t.cant_mm, "speed_kmh": t.speed_kmh, "curve_direction": t.curve_direction,
                "zone": None, "evaluated": {"start_m": a, "end_m": b}, "layout": layout}


@dataclass
class SynthCampaign:
    name: str
    vehicle: VehicleModel
    sections: list[SynthSection]
    measured: dict[str, SignalSet]
    baseline: dict[str, SignalSet]
    baseline_effects: dict
    truth: dict
    description: str = ""
    extra: dict = field(default_factory=dict)

    def vehicle_record(self) -> dict:
        v = self.vehicle
        return {"name": "Coach (Manchester benchmark vehicle 1 based)" if v.template == "coach"
                else "Two-axle wagon, UIC double-link suspension",
                "kind": v.kind, "secondary_suspension": v.template == "coach",
                "Q0_kN": round(v.q0_kN(), 3), "template": v.template, "parameters": dict(v.parameters)}


def parse_hidden(items: list[str] | None, template: str = "coach") -> dict[str, dict[str, float]]:
    """``["friction_damping", "conicity=0.4", "lateral_bumpstop:clearance_mm=15,stiffness_kN_mm=2"]``
    → checked ``{effect: {param: value}}`` (defaults from :func:`hidden_defaults`).

    Parameters
    ----------
    items : list of str or None
        ``effect``, ``effect=value`` (its main parameter) or ``effect:param=value,...``.
    template : str
        Vehicle template whose defaults fill the gaps.

    Returns
    -------
    dict of str to dict of str to float

    Raises
    ------
    InvalidParameter
        An unknown effect id or a malformed item.
    """
    defaults = hidden_defaults(template)
    out: dict[str, dict[str, float]] = {}
    for item in items or []:
        eff, params = item, {}
        if ":" in item:
            eff, rest = item.split(":", 1)
            for kv in filter(None, rest.split(",")):
                if "=" not in kv:
                    raise InvalidParameter(f"hidden effect {eff!r}: expected k=v, got {kv!r}")
                k, v = kv.split("=", 1)
                params[k.strip()] = float(v)
        elif "=" in item:
            eff, v = item.split("=", 1)
            if eff not in EFFECTS:
                raise InvalidParameter(f"unknown effect id {eff!r}; known: {list(EFFECTS)}")
            params[MAIN_PARAMETER[eff]] = float(v)
        eff = eff.strip()
        if eff not in EFFECTS:
            raise InvalidParameter(f"unknown effect id {eff!r}; known: {list(EFFECTS)}")
        out[eff] = {**defaults.get(eff, {}), **params}
    return resolve_effects(out)


def _plan(template: str, n: int, rng: np.random.Generator) -> list[dict]:
    """Section geometry and speed per zone (coach 160–200 km/h on straight track, wagon
    90–100 km/h); in curves the speed gives a cant deficiency of 70–130 mm (coach, ≤ 200 km/h)
    or 40–90 mm (wagon, ≤ 100 km/h); radii per EN 14363 zones."""
    if n < 12:
        raise InvalidParameter(f"synth needs at least 12 sections (≥ 3 per zone), got {n}")
    per_zone = [n // 4 + (1 if i < n % 4 else 0) for i in range(4)]
    coach = template == "coach"
    out = []
    k = 0
    for zone, count in zip((1, 2, 3, 4), per_zone, strict=True):
        for j in range(count):
            if zone == 1:
                radius, cant = (0.0, 0.0) if j % 2 == 0 else (float(rng.choice([6000, 8000])), 60.0)
                v = float(rng.choice([160, 180, 200])) if coach else float(rng.choice([90, 100]))
            else:
                radius = float({2: rng.choice([700, 900, 1200, 1500]), 3: rng.choice([420, 480, 550, 600]),
                                4: rng.choice([260, 300, 340, 380])}[zone])
                cant = float(rng.choice([100, 120, 140, 150]))
                deficiency = float(rng.uniform(70, 130) if coach else rng.uniform(40, 90)) / 1000.0
                v_ms = math.sqrt(radius * G * (cant / 1000.0 + deficiency) / 1.5)
                v = round(min(v_ms * 3.6, 200.0 if coach else 100.0) / 5.0) * 5.0
            out.append({"id": f"S{k + 1:02d}", "zone": zone, "radius": radius, "cant": cant, "speed": v,
                        "direction": 1 if rng.random() < 0.5 else -1, "country": COUNTRIES[k % len(COUNTRIES)]})
            k += 1
    return out


def _defects(irr: dict, rng: np.random.Generator, length: float) -> None:
    """Add 2–5 isolated short vertical/cross-level defects (dipped welds), 2–4 mm deep."""
    s = irr["s"]
    for _ in range(int(rng.integers(2, 6))):
        x0 = float(rng.uniform(0.2, 0.9) * length)
        w = float(rng.uniform(3.0, 5.0))
        depth = float(rng.uniform(2.0, 4.0)) * 1e-3
        bump = -depth * np.where(np.abs(s - x0) < w / 2, 0.5 * (1 + np.cos(2 * np.pi * (s - x0) / w)), 0.0)
        irr["vertical"] += bump
        irr["cross_level"] += bump * float(rng.choice([-1.0, 1.0]))


def _apply_sensor_nuisance(ss: SignalSet, rng: np.random.Generator, nz: dict, gains: dict) -> SignalSet:
    off = int(rng.integers(1, int(nz["max_offset_samples"]) + 1))
    chans = {}
    for name, x in ss.channels.items():
        kind, _ = split_channel(name)
        sigma = nz["noise_force_kN"] if kind in ("Y", "Q") else nz["noise_acc"]
        y = np.empty_like(x)
        y[off:] = x[:-off]
        y[:off] = x[0]
        chans[name] = gains[name] * y + rng.normal(0.0, sigma, x.size)
    return SignalSet(fs=ss.fs, time_s=ss.time_s - ss.time_s[0], distance_m=ss.distance_m, channels=chans)


def _apply_channel_faults(ss: SignalSet, faults: dict) -> SignalSet:
    """Causes outside the effect library in the measurement chain: ``gain`` ``{channel: factor}``
    (a mis-calibrated sensor; −1: polarity reversed), ``shift_samples`` ``{channel: n}`` (a channel
    recorded n samples late against the others) and ``swap`` ``[[a, b], …]`` (two sensors'
    positions exchanged)."""
    chans = dict(ss.channels)
    for a, b in faults.get("swap") or ():
        if a in chans and b in chans:
            chans[a], chans[b] = chans[b], chans[a]
    for ch, g in (faults.get("gain") or {}).items():
        if ch in chans:
            chans[ch] = chans[ch] * float(g)
    for ch, n in (faults.get("shift_samples") or {}).items():
        if ch in chans and int(n) > 0:
            x, n = chans[ch], int(n)
            y = np.empty_like(x)
            y[n:] = x[:-n]
            y[:n] = x[0]
            chans[ch] = y
    return SignalSet(fs=ss.fs, time_s=ss.time_s, distance_m=ss.distance_m, channels=chans)


def _checked_hidden(template: str, hidden: dict | None, oversample: int, require_cause: bool) -> dict:
    """The hidden effects resolved and checked against the template (default: friction
    damping, :data:`HIDDEN_DEFAULTS`)."""
    if int(oversample) < 1:
        raise InvalidParameter(f"oversample must be an integer ≥ 1, got {oversample!r}")
    hidden = resolve_effects(hidden if hidden is not None else {"friction_damping": HIDDEN_DEFAULTS["friction_damping"]})
    if template not in TRUE_TRACK_TEMPLATES:
        raise InvalidParameter(f"vehicle template {template!r} is unknown; known: {sorted(TRUE_TRACK_TEMPLATES)}")
    if not hidden and require_cause:
        raise InvalidParameter("synth needs at least one hidden effect")
    for e in hidden:
        if template not in EFFECTS[e].templates:
            raise InvalidParameter(f"effect {e!r} does not apply to template {template!r} "
                                   f"(applies to {EFFECTS[e].templates})")
    return hidden


def _baseline_effects(hidden: dict, track_recorded: bool, track_roughness: float) -> dict:
    """The baseline's effects: the measured irregularities at scale 1 unless hidden or not
    recorded (then generated ones); the track options checked."""
    if not track_roughness > 0:
        raise InvalidParameter(f"track_roughness must be > 0, got {track_roughness}")
    if not track_recorded and "measured_irregularities" in hidden:
        raise InvalidParameter("hidden effect 'measured_irregularities' needs recorded track geometry "
                               "(track_recorded=True)")
    return {} if "measured_irregularities" in hidden or not track_recorded else {"measured_irregularities": {"scale": 1.0}}


def _section(sp: dict, rng: np.random.Generator, nz: dict, roughness: float = 1.0,
             recorded: bool = True) -> SynthSection:
    """One planned section: its geometry (run-in ten seconds of travel, transitions, curve),
    the true irregularities with defects and the recorded ones (recording gain × true + noise,
    stored at 0.01 mm)."""
    v = sp["speed"] / 3.6
    run = 10.0 * v
    trans = max(60.0, 0.6 * sp["cant"]) if sp["radius"] else 0.0
    curve = float(np.clip(8.0 * v, 250.0, 450.0))
    geom = {"straight_in_m": max(run - trans, 60.0), "transition_in_m": trans, "curve_m": curve,
            "transition_out_m": trans, "straight_out_m": max(run - trans, 60.0)}
    length = sum(geom.values())
    true_irr = generate_irregularities(length + 120.0, level="low", seed=int(rng.integers(2**31)),
                                       s0=-60.0, scale=roughness * true_track_scale(sp["speed"]))
    _defects(true_irr, rng, length)
    rec = {"s": true_irr["s"]}
    for key in ("vertical", "alignment", "cross_level", "gauge"):
        rec[key] = nz["recording_gain"] * true_irr[key] + rng.normal(0, nz["recording_noise_mm"] * 1e-3,
                                                                     true_irr["s"].size)
    # stored with 0.01 mm resolution, as in the manifest
    rec = {k: (np.round(x * 1e5) / 1e5 if k != "s" else x) for k, x in rec.items()}
    track = TrackSection(sp["id"], speed_kmh=sp["speed"], radius_m=sp["radius"], cant_mm=sp["cant"],
                         curve_direction=sp["direction"], irregularities=rec if recorded else None,
                         irregularity_level="low",
                         seed=int(rng.integers(2**31)), **geom)
    return SynthSection(track, true_irr, sp["country"], zone_for_radius(sp["radius"] or None))


def _truth_signals(truth_veh: VehicleModel, true_track: TrackSection, truth_effects: dict, fs: float, k: int,
                   speed_factor: float, nz: dict) -> SignalSet:
    """The truth's signals on the true track; with ``k`` > 1 simulated at ``k`` × ``fs`` and
    averaged over blocks of ``k`` samples (the kernel's own output averaging at ``fs``)."""
    ss = simulate_section(truth_veh, true_track, truth_effects, fs_out=fs * k, speed_factor=speed_factor,
                          nuisance={"damper_asymmetry": nz["damper_asymmetry"]})
    if k == 1:
        return ss
    n = ss.time_s.size // k * k

    def blk(x: np.ndarray) -> np.ndarray:
        return np.ascontiguousarray(x[:n].reshape(-1, k).mean(axis=1))

    return SignalSet(fs=float(fs), time_s=blk(ss.time_s), distance_m=blk(ss.distance_m),
                     channels={c: blk(x) for c, x in ss.channels.items()})


def build_campaign(*, name: str = "synth", template: str = "coach", hidden: dict | None = None,
                   seed: int = 1, n_sections: int = 12, fs: float = 200.0,
                   nuisance: dict | None = None, progress=None, truth_parameters: dict | None = None,
                   oversample: int = 1, channel_faults: dict | None = None,
                   require_cause: bool = True, track_recorded: bool = True,
                   track_roughness: float = 1.0) -> SynthCampaign:
    """Build the whole synthetic campaign in memory (measured + baseline signals, manifest data
    and the truth).

    Parameters
    ----------
    name, template, seed, n_sections, fs : str, str, int, int, float
        Campaign name, vehicle template, random seed, number of sections, output rate in Hz.
    hidden : dict or None
        ``{effect: {param: value}}`` (checked), default
        ``{"friction_damping": HIDDEN_DEFAULTS[...]}``.
    nuisance : dict or None
        Overrides of :data:`NUISANCE_DEFAULTS`.
    progress : callable or None
        ``progress(done, total)`` per simulation.
    truth_parameters, oversample, channel_faults : dict or None, int, dict or None
        Truth-model options (a truth structurally unlike the candidate models,
        docs/diagnosis.md "test bench"): vehicle-template values of the truth only (the
        baseline keeps the template's); the truth simulated at ``oversample`` × ``fs`` and
        averaged over blocks of ``oversample`` samples (the simulator takes ≥ 2 integration
        steps per output sample, so this is a finer step: coach at 200 Hz 1.67 ms, at
        4 × 200 Hz 0.625 ms); faults, see :func:`_apply_channel_faults`.
    require_cause : bool
        ``False`` allows a campaign with no hidden cause at all (``hidden={}``).
    track_recorded, track_roughness : bool, float
        ``False``: no measured track geometry stored (the baseline runs on ORE B176 low-level
        irregularities of the section's seed); the true track's amplitude × ``track_roughness``.

    Returns
    -------
    SynthCampaign
    """
    veh = VehicleModel(template)
    truth_veh = VehicleModel(template, dict(truth_parameters or {}))
    hidden = _checked_hidden(template, hidden, oversample, require_cause and not truth_parameters
                             and not channel_faults)
    nz = {**NUISANCE_DEFAULTS, **(nuisance or {})}
    if template != "coach":
        nz["damper_asymmetry"] = 0.0
    rng = np.random.default_rng(seed)
    baseline_effects = _baseline_effects(hidden, track_recorded, track_roughness)
    sections = [_section(sp, rng, nz, float(track_roughness), bool(track_recorded))
                for sp in _plan(template, n_sections, rng)]
    truth_effects = {**{k: v for k, v in baseline_effects.items()}, **hidden}
    truth_effects["measured_irregularities"] = dict(hidden.get("measured_irregularities", {"scale": 1.0}))
    gains: dict[str, float] = {}
    measured, baseline = {}, {}
    speed_factors = {}
    total = 2 * len(sections)
    for i, sec in enumerate(sections):
        sf = float(1.0 + rng.normal(0.0, nz["speed_sigma"]))
        speed_factors[sec.track.id] = sf
        true_track = TrackSection(**{**sec.track.__dict__, "irregularities": sec.true_irregularities})
        ss = _truth_signals(truth_veh, true_track, truth_effects, fs, int(oversample), sf, nz)
        for ch in ss.channels:
            gains.setdefault(ch, float(1.0 + rng.normal(0.0, nz["gain_sigma"])))
        measured[sec.track.id] = _apply_sensor_nuisance(ss, rng, nz, gains)
        if channel_faults:
            measured[sec.track.id] = _apply_channel_faults(measured[sec.track.id], channel_faults)
        if progress:
            progress(2 * i + 1, total)
        baseline[sec.track.id] = simulate_section(veh, sec.track, baseline_effects, fs_out=fs)
        if progress:
            progress(2 * i + 2, total)
    truth = {"hidden_effects": hidden, "truth_effects": truth_effects,
             "nuisances": {**nz, "speed_factors": speed_factors, "channel_gains": gains},
             "baseline_effects": baseline_effects, "seed": seed, "template": template,
             "truth_parameters": dict(truth_parameters or {}), "oversample": int(oversample),
             "channel_faults": dict(channel_faults or {}), "track": [bool(track_recorded), float(track_roughness)],
             "note": "measurements = baseline template + hidden effects on the true track "
                     "(stored irregularities = recording gain x true + noise) + nuisances"}
    return SynthCampaign(name, veh, sections, measured, baseline, baseline_effects, truth,
                         description=f"Synthetic on-track test campaign, {len(sections)} sections, "
                                     f"{veh.kind} vehicle ({template} template)")


__all__ = ["DS", "HIDDEN_DEFAULTS", "HIDDEN_DEFAULTS_WAGON", "TRUE_TRACK_BANDS", "SynthCampaign", "SynthSection", "build_campaign", "hidden_defaults", "parse_hidden", "true_track_scale"]
