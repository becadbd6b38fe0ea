"""A test bench for the diagnosis without the inverse crime (docs/diagnosis.md "Trust bench").

The "measurements" come from a truth model that differs in structure from every candidate
model the diagnosis simulates:

* a finer integration step (the truth is simulated at 4 × the output rate and averaged,
  :func:`railval.core.sim.synth.build_campaign` ``oversample``), the true track (the stored
  irregularities are a recording of it with gain 0.96 and noise), asymmetric secondary dampers,
  speed scatter, per-channel gain errors, sensor noise and time offsets (the synth nuisances);
* one hidden cause drawn from four classes:

  (a) a library effect at a value other than the synth default (inside its plausible range),
  (b) a vehicle-template parameter error (a diagnosis candidate parameter),
  (c) a cause outside the library and outside the candidate parameters: one sensor's gain,
      a time shift of one wheelset's vertical force channels, an unsprung-mass error, a
      profile shape (contact angle parameter at unchanged conicity), the centre-of-gravity height,
  (d) nothing,
  (e) a truth whose wheel–rail contact differs from the candidates' (softer flange contact,
      lower creep coefficients; no candidate changes either), alone or with a cause on top
      (worn dampers, a mass, a sensor gain), and two causes at once (two dampers; an effect
      plus a parameter): scored by whether the cause(s) on top appear in the cause set or as
      a family's cause, whether a family is flagged structural, and confident wrong claims
      (a ``cause`` verdict with a wrong top, or a wrong name in the cause set).
  (f) a truth with another creep law (Polach's instead of Shen–Hedrick–Elkins saturation, the
      simulator's ``creep_law`` = 1), alone and with one or two causes on top, scored like (e);

  (g) force-channel gains: one wheel, both transducers of an instrumented wheelset, a bogie's
      four (``gain GROUP`` candidates, docs/diagnosis.md "Model or measurement?");
  (t) two causes at once: a worn damper and a heavier car body;
  (r) a rougher track than the simulated one, the campaign without measured track geometry
      (right answer: the track input, never a vehicle parameter as ``cause``);
  (w) worn secondary dampers, where an implausible candidate (a damper series stiffness) ranks
      ahead (the cause set must carry on past it);
  (p) measured profiles: the truth runs on a nonlinear rolling-radius difference table (new
      pairs with a flange rise, worn pairs with a contact jump) while every candidate model
      uses the template's linear conicity (right answer: the contact-geometry statement; a
      single conicity as the ``cause`` counts as confidently wrong);
  some cases of (g), (t) and (w) with the truth's other creep law of (f).

Every case is synthesised (:func:`~railval.core.sim.synth.build_campaign`), written and
imported (:func:`railval.app.services.synth.write_folder`, :func:`railval.db.importer.import_campaign`)
into a temporary SQLite database and diagnosed with the public service
(:func:`railval.app.services.diagnosis.diagnose`). The report: top-1 accuracy per class, the
share of ``none``/``uncertain`` verdicts on (c) and (d), the share of confident wrong claims
(verdict ``cause`` with a wrong candidate, or any ``cause`` on (c)/(d); and "explained ≥ 0.5
and wrong"), and — with ``--calibrate-wrong`` — whether a wrong candidate's calibration that
passes validation is flagged (plausibility or held-out check).

Per class also (:func:`class_scores`): named as cause, named in the set, ``uncertain`` with the
right top, confidently wrong. With ``--screen K --against-whole`` every case is diagnosed screened
and whole (:func:`whole_of`): where verdict, top or cause set differ, and how the noise floor moved.

``railval bench diagnosis_trust [--cases N] [--classes a b c d e f m g t r w p] [--workers 2] [--sections N] [--screen K [--against-whole]] [--calibrate-wrong]``
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

from railval.app.bench.trust_against_whole import (
    against_whole_lines,
    against_whole_summary,
    whole_of,
)
from railval.app.bench.trust_profiles import profile_cases
from railval.core import lazy

#: deferred (railval.core.lazy): ``railval bench`` (the list) imports every benchmark module for its
#: docstring; what the benchmark runs loads when it runs
calibrate = lazy.function("railval.app.services.calibration", "calibrate")
diagnose = lazy.function("railval.app.services.diagnosis", "diagnose")
write_folder = lazy.function("railval.app.services.synth", "write_folder")
build_campaign = lazy.function("railval.core.sim.synth", "build_campaign")
import_campaign = lazy.function("railval.db.importer", "import_campaign")
connect = lazy.function("railval.db.engine", "connect")

#: the truth-only contact of class (e): flange contact stiffness ÷4, Kalker creep coefficients at
#: the lower end of their range (a different wheel–rail contact than the candidates' model)
_CONTACT = {"k_flange": 2.0e7, "kalker_c11": 3.0, "kalker_c22": 3.0}

#: the cases, per class: (label, build_campaign keyword arguments, the right answer or None)
CASES: dict[str, list[tuple[str, dict[str, Any], str | None]]] = {
    "a": [
        ("friction_damping 2.2 kN", {"hidden": {"friction_damping": {"force_kN": 2.2}}}, "friction_damping"),
        ("conicity 0.45", {"hidden": {"conicity": {"conicity": 0.45}}}, "conicity"),
        ("wheel_rail_friction mu 0.15", {"hidden": {"wheel_rail_friction": {"mu": 0.15}}}, "wheel_rail_friction"),
        ("parasitic_yaw_stiffness 1800", {"hidden": {"parasitic_yaw_stiffness": {"k_yaw_kNm_rad": 1800.0}}},
         "parasitic_yaw_stiffness"),
        ("lateral_bumpstop 10 mm 3 kN/mm", {"hidden": {"lateral_bumpstop": {"clearance_mm": 10.0,
                                                                         "stiffness_kN_mm": 3.0}}},
         "lateral_bumpstop"),
        ("track_flexibility 22/8 MN/m", {"hidden": {"track_flexibility": {"k_vertical_MN_m": 22.0,
                                                                           "k_lateral_MN_m": 8.0}}},
         "track_flexibility"),
        ("friction_damping 3.0 kN", {"hidden": {"friction_damping": {"force_kN": 3.0}}}, "friction_damping"),
        ("carbody_flexibility 7 Hz", {"hidden": {"carbody_flexibility": {"frequency_Hz": 7.0,
                                                                          "damping_ratio": 0.01}}},
         "carbody_flexibility"),
        ("damper_series_stiffness 2 MN/m", {"hidden": {"damper_series_stiffness": {"k_series_MN_m": 2.0}}},
         "damper_series_stiffness"),
        ("conicity 0.5", {"hidden": {"conicity": {"conicity": 0.5}}}, "conicity"),
    ],
    "b": [
        ("secondary vertical damping x0.6", {"truth_parameters": {"c_secondary_z": 12000.0}}, "model.c_secondary_z"),
        ("secondary lateral damping x0.4", {"truth_parameters": {"c_secondary_y": 12800.0}}, "model.c_secondary_y"),
        ("secondary lateral stiffness x1.8", {"truth_parameters": {"k_secondary_y": 288000.0}}, "model.k_secondary_y"),
        ("secondary vertical stiffness x0.6", {"truth_parameters": {"k_secondary_z": 258000.0}}, "model.k_secondary_z"),
        ("yaw damper x0.45", {"truth_parameters": {"c_yaw_damper": 112500.0}}, "model.c_yaw_damper"),
        ("primary lateral stiffness x0.55", {"truth_parameters": {"k_primary_y": 2.14e6}}, "model.k_primary_y"),
        ("car body mass x1.3", {"truth_parameters": {"m_carbody": 41600.0}}, "model.m_carbody"),
        ("primary longitudinal stiffness x0.3", {"truth_parameters": {"k_primary_x": 9.4e6}}, "model.k_primary_x"),
        ("secondary vertical damping x2.2", {"truth_parameters": {"c_secondary_z": 44000.0}}, "model.c_secondary_z"),
        ("primary vertical stiffness x0.55", {"truth_parameters": {"k_primary_z": 660000.0}}, "model.k_primary_z"),
    ],
    "c": [
        # a car body sensor gain is a measurement candidate now (its right answer); the others stay outside
        ("gain of sensor ay_cb_b1 x1.4", {"channel_faults": {"gain": {"ay_cb_b1": 1.4}}}, "gain ay_cb_b1"),
        ("Q of wheelset 1 recorded 0.1 s late", {"channel_faults": {"shift_samples": {"Q_w1L": 20, "Q_w1R": 20}}},
         None),
        ("wheelset mass x1.35", {"truth_parameters": {"m_wheelset": 2447.0}}, None),
        ("profile shape: contact angle parameter 2 -> 10", {"truth_parameters": {"contact_angle_parameter": 10.0}},
         None),
        ("centre of gravity height 1.8 -> 2.3 m", {"truth_parameters": {"h_carbody": 2.3}}, None),
        ("gain of sensor Y_w1L x1.25", {"channel_faults": {"gain": {"Y_w1L": 1.25}}}, "gain Y_w1L"),
        ("gain of sensor az_cb_b2 x0.7", {"channel_faults": {"gain": {"az_cb_b2": 0.7}}}, "gain az_cb_b2"),
        ("Y of wheelset 3 recorded 0.05 s late", {"channel_faults": {"shift_samples": {"Y_w3L": 10, "Y_w3R": 10}}},
         None),
        ("anti-roll bar x0.3", {"truth_parameters": {"k_antiroll": 6.0e5}}, None),
        ("bogie yaw inertia x1.8", {"truth_parameters": {"I_yaw_bogie": 5520.0}}, None),
    ],
    "d": [(f"nothing (seed {s})", {"seed": s}, None) for s in (11, 12, 13, 14, 15, 16, 17, 18, 19, 20)],
    # (e) the truth's wheel–rail contact differs from every candidate model's (softer flange
    # contact and lower creep coefficients in the truth only; no candidate changes either),
    # alone or with causes on top; the right answer is the cause(s) on top ("+"-joined)
    "e": [
        ("contact differs, nothing on top", {"truth_parameters": _CONTACT}, None),
        ("contact differs + secondary vertical dampers x0.5",
         {"truth_parameters": {**_CONTACT, "c_secondary_z": 10000.0}}, "model.c_secondary_z"),
        ("contact differs + car body mass x1.15", {"truth_parameters": {**_CONTACT, "m_carbody": 36800.0}},
         "model.m_carbody"),
        ("contact differs + sensor az_cb_b1 x1.3",
         {"truth_parameters": _CONTACT, "channel_faults": {"gain": {"az_cb_b1": 1.3}}}, "gain az_cb_b1"),
        ("two dampers: secondary vertical x0.5 + lateral x0.5",
         {"truth_parameters": {"c_secondary_z": 10000.0, "c_secondary_y": 16000.0}},
         "model.c_secondary_z+model.c_secondary_y"),
        ("conicity 0.45 + car body mass x1.15",
         {"hidden": {"conicity": {"conicity": 0.45}}, "truth_parameters": {"m_carbody": 36800.0}},
         "conicity+model.m_carbody"),
    ],
    # (f) a second creep law in the truth only (Polach 2005 with reduction factors kA = 1, kS = 0.4:
    # core/sim/kernel.py; no candidate model changes the law), alone, with a cause on top, and with
    # two causes on top; scored like (e)
    "f": [
        ("creep law differs, nothing on top", {"truth_parameters": {"creep_law": 1.0}}, None),
        ("creep law differs + secondary vertical dampers x0.5",
         {"truth_parameters": {"creep_law": 1.0, "c_secondary_z": 10000.0}}, "model.c_secondary_z"),
        ("creep law differs + car body mass x1.15", {"truth_parameters": {"creep_law": 1.0, "m_carbody": 36800.0}},
         "model.m_carbody"),
        ("creep law differs + sensor az_cb_b1 x1.3",
         {"truth_parameters": {"creep_law": 1.0}, "channel_faults": {"gain": {"az_cb_b1": 1.3}}}, "gain az_cb_b1"),
        ("creep law differs + two dampers: secondary vertical x0.5 + lateral x0.5",
         {"truth_parameters": {"creep_law": 1.0, "c_secondary_z": 10000.0, "c_secondary_y": 16000.0}},
         "model.c_secondary_z+model.c_secondary_y"),
        ("creep law differs + car body mass x1.15 + sensor az_cb_b2 x0.7",
         {"truth_parameters": {"creep_law": 1.0, "m_carbody": 36800.0}, "channel_faults": {"gain": {"az_cb_b2": 0.7}}},
         "model.m_carbody+gain az_cb_b2"),
    ],
}

#: the classes whose truth differs in structure (scored by the cause on top and the structural flag)
_STRUCTURAL = "ef"


# ----------------------------------------------------------------------------- class (m)
def measurement_cases() -> list[tuple[str, dict[str, Any], str | None]]:
    """Class (m): faults of the measurement chain that the measurement candidates ``sign``,
    ``swap`` and ``shift`` name (docs/diagnosis.md "Sign, position swap and time shift"), on the
    bench's structurally different truth: a polarity reversed (a wheel force; a car body
    accelerometer, which no EN quantity can see — right answer none), two positions exchanged
    (the wheels of one wheelset; the car body accelerometers of both ends), every channel
    recorded late (a shift the EN quantities hardly see — right answer none), and nothing."""
    acc = [f"{d}_{b}_{e}" for d in ("ay", "az") for b in ("cb", "bg") for e in ("b1", "b2")]
    wheels = [f"{k}_w{n}{s}" for k in ("Y", "Q") for n in range(1, 5) for s in "LR"]
    return [
        ("guiding force Y_w1L polarity reversed", {"channel_faults": {"gain": {"Y_w1L": -1.0}}}, "sign Y_w1L"),
        ("wheel force Q_w2R polarity reversed", {"channel_faults": {"gain": {"Q_w2R": -1.0}}}, "sign Q_w2R"),
        ("wheels of wheelset 1 swapped (Y and Q)",
         {"channel_faults": {"swap": [["Y_w1L", "Y_w1R"], ["Q_w1L", "Q_w1R"]]}}, "swap w1L w1R"),
        ("car body accelerometers of both ends swapped",
         {"channel_faults": {"swap": [["ay_cb_b1", "ay_cb_b2"], ["az_cb_b1", "az_cb_b2"]]}}, "swap b1 b2"),
        ("every channel (bogie frames too) recorded 0.2 s late", {"channel_faults": {"shift_samples": {c: 40 for c in acc + wheels}}},
         None),
        ("car body accelerometer az_cb_b1 polarity reversed", {"channel_faults": {"gain": {"az_cb_b1": -1.0}}}, None),
        ("nothing (seed 21)", {"seed": 21}, None),
    ]


CASES["m"] = measurement_cases()

#: the truth with another creep law (class f): structurally unlike every candidate model
_POLACH = {"creep_law": 1.0}
_W1 = {"Y_w1L": 1.3, "Y_w1R": 1.3}
# (g) force-channel gains: one wheel, one instrumented wheelset (both transducers), one bogie;
# the right answer any one of the " | "-separated alternatives ("+": all of them)
CASES["g"] = [
    ("leading wheelset: both Y transducers x1.3", {"channel_faults": {"gain": _W1}}, "gain Y_w1"),
    ("wheel force Q_w2L x0.8", {"channel_faults": {"gain": {"Q_w2L": 0.8}}}, "gain Q_w2L"),
    ("guiding force Y_w3R x1.25, creep law differs",
     {"truth_parameters": _POLACH, "channel_faults": {"gain": {"Y_w3R": 1.25}}}, "gain Y_w3R"),
    ("rear bogie: all four Y transducers x0.75",
     {"channel_faults": {"gain": {f"Y_w{n}{s}": 0.75 for n in (3, 4) for s in "LR"}}}, "gain Y_bogie2"),
    ("wheelset 1: both Q transducers x1.2, creep law differs",
     {"truth_parameters": _POLACH, "channel_faults": {"gain": {"Q_w1L": 1.2, "Q_w1R": 1.2}}}, "gain Q_w1"),
    ("leading wheelset Y x1.3, seed 5", {"seed": 5, "channel_faults": {"gain": _W1}}, "gain Y_w1"),
]
# (t) two causes at once: a worn damper and a heavier car body
CASES["t"] = [
    ("secondary lateral dampers x0.4 + car body mass x1.2",
     {"truth_parameters": {"c_secondary_y": 12800.0, "m_carbody": 38400.0}}, "model.c_secondary_y+model.m_carbody"),
    ("secondary vertical dampers x0.5 + car body mass x1.2",
     {"truth_parameters": {"c_secondary_z": 10000.0, "m_carbody": 38400.0}}, "model.c_secondary_z+model.m_carbody"),
    ("yaw dampers x0.4 + car body mass x1.2",
     {"truth_parameters": {"c_yaw_damper": 100000.0, "m_carbody": 38400.0}}, "model.c_yaw_damper+model.m_carbody"),
    ("secondary vertical dampers x0.4 + car body mass x1.25, creep law differs",
     {"truth_parameters": {**_POLACH, "c_secondary_z": 8000.0, "m_carbody": 40000.0}},
     "model.c_secondary_z+model.m_carbody"),
    ("secondary lateral dampers x0.4 + car body mass x1.2, seed 5",
     {"seed": 5, "truth_parameters": {"c_secondary_y": 12800.0, "m_carbody": 38400.0}},
     "model.c_secondary_y+model.m_carbody"),
]
# (r) a rougher track than the simulated irregularities, the campaign without measured track
# geometry (the baseline runs on ORE B176 low-level irregularities of another realisation);
# right answer: the track input (either direction), never a vehicle parameter as cause
_TRACK = "track_level_vertical | track_level_lateral"
CASES["r"] = [
    (f"track x{f} rougher, no measured geometry (seed {sd})",
     {"seed": sd, "track_recorded": False, "track_roughness": f}, _TRACK)
    for f, sd in ((1.6, 3), (2.0, 4), (2.5, 5), (1.8, 6), (2.2, 7))
]
# (w) worn secondary dampers in both directions (a worn damper looks like a soft damper series
# stiffness, which is implausible there: the search must carry on to the dampers)
_SEC = "model.c_secondary_y+model.c_secondary_z | model.c_secondary_y | model.c_secondary_z"
CASES["w"] = [
    ("secondary dampers worn x0.35 (both directions)",
     {"truth_parameters": {"c_secondary_y": 11200.0, "c_secondary_z": 7000.0}}, _SEC),
    ("secondary dampers worn x0.3 (both directions)",
     {"truth_parameters": {"c_secondary_y": 9600.0, "c_secondary_z": 6000.0}}, _SEC),
    ("secondary dampers worn x0.4, creep law differs",
     {"truth_parameters": {**_POLACH, "c_secondary_y": 12800.0, "c_secondary_z": 8000.0}}, _SEC),
    ("secondary lateral dampers worn x0.3", {"truth_parameters": {"c_secondary_y": 9600.0}}, "model.c_secondary_y"),
    ("secondary dampers worn x0.35, seed 5",
     {"seed": 5, "truth_parameters": {"c_secondary_y": 11200.0, "c_secondary_z": 7000.0}}, _SEC),
]



CASES["p"] = profile_cases(_POLACH)


def truth_sets(truth: str | None) -> list[list[str]]:
    """The right answers of a case: alternatives separated by " | ", each the "+"-joined names
    that must all be found."""
    return [[n.strip() for n in alt.split("+")] for alt in truth.split("|")] if truth else []


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--cases", type=int, default=10, help="cases per class (default 10, at most 10)")
    parser.add_argument("--classes", nargs="+", default=list(CASES), choices=list(CASES))
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--values", type=int, default=3, help="diagnose: values per effect parameter")
    parser.add_argument("--oversample", type=int, default=4, help="truth simulated at this × the rate (default 4)")
    parser.add_argument("--out", default=None,
                        help="append each case's record to this JSON-lines file as soon as it is done")
    parser.add_argument("--resume", action="store_true",
                        help="take the cases already in --out from there and run only the others")
    parser.add_argument("--screen", type=int, default=None, metavar="K",
                        help="run the screened diagnosis keeping K candidates (docs/diagnosis.md)")
    parser.add_argument("--against-whole", action="store_true",
                        help="with --screen: also the whole diagnosis of every case; print where they differ")
    parser.add_argument("--sections", type=int, default=12, metavar="N", help="sections per campaign (default and "
                        "minimum 12: ≥ 3 per test zone); more per zone put more of them off the screen (--screen)")
    parser.add_argument("--calibrate-wrong", action="store_true",
                        help="calibrate the top candidate where it is wrong (short search, --split) and "
                             "check a pass is flagged")


def run_case(database: Any, name: str, klass: str, label: str, kwargs: dict[str, Any], truth: str | None, *,
             workers: int = 2, values: int = 3, oversample: int = 4, calibrate_wrong: bool = False,
             candidates: list[str] | None = None, n_sections: int = 12, screen: int | None = None,
             against_whole: bool = False) -> dict:
    """Synthesise, import and diagnose one case; return its record. ``candidates``: restrict
    the diagnosis (effect ids and ``model.PARAM``; the CI subset uses a few); ``screen``: the
    screened diagnosis keeping that many candidates (docs/diagnosis.md "Screened diagnosis");
    ``against_whole``: with ``screen``, also the whole diagnosis of the case (:func:`whole_of`)."""

    kw = {"seed": 3, "hidden": {}, **kwargs}
    t0 = time.perf_counter()
    sc = build_campaign(name=name, oversample=oversample, require_cause=False, n_sections=n_sections, **kw)
    with tempfile.TemporaryDirectory(prefix="railval-trust-") as tmp:
        write_folder(sc, Path(tmp) / name)
        import_campaign(database, Path(tmp) / name)
    t_synth = time.perf_counter() - t0
    t0 = time.perf_counter()
    res = diagnose(database, name, "baseline", workers=workers, values_per_parameter=values, effects=candidates,
                   **({"screen": screen} if screen else {}))
    t_diag = time.perf_counter() - t0
    d = res.to_dict()
    top = d["candidates"][0] if d["candidates"] else None
    alts = truth_sets(truth)
    truths = sorted({n for alt in alts for n in alt})
    right = bool(truths and top is not None and top["name"] in truths)
    rec = {"diagnosis": d, "class": klass, "case": label, "truth": truth, "verdict": d["verdict"], "noise_floor": d["noise_floor"],
           "top": top["name"] if top else None, "top_explained": top["explained"] if top else 0.0,
           "top_held_out": top["held_out_explained"] if top else 0.0, "top_plausible": top["plausible"] if top else None,
           "right": right, "baseline_validated": d["validated"], "simulations": d["simulations"],
           "synth_s": round(t_synth, 1), "diagnose_s": round(t_diag, 1),
           "truth_rank": next((i + 1 for i, c in enumerate(d["candidates"]) if c["name"] in truths), None)}
    causes = [c["name"] for c in d.get("causes") or []]
    fam_causes = {f["top"][0]["name"] for f in d.get("families") or [] if f["verdict"] == "cause" and f["top"]}
    rec["causes"] = causes
    rec["cause_found"] = any(all(x in causes or x in fam_causes for x in alt) for alt in alts)
    rec["named_in_set"] = any(all(x in causes for x in alt) for alt in alts)
    rec["named_as_cause"] = d["verdict"] == "cause" and right
    rec["uncertain_right_top"] = d["verdict"] == "uncertain" and right
    rec["statements"] = [x["kind"] for x in d.get("statements") or []]
    rec["vehicle_parameter_cause"] = bool(d["verdict"] == "cause" and top and top["kind"] == "parameter")
    rec["passed_over"] = [x["name"] for x in (d.get("cause_set") or {}).get("passed_over") or []]
    rec["structural_named"] = [f["name"] for f in d.get("families") or [] if f["structural"]["flag"]]
    rec["confident_wrong"] = (d["verdict"] == "cause" and not right) or any(x not in truths for x in causes)
    if klass == "p":  # a profile difference answered by a single conicity as the cause is wrong
        rec["contact_geometry"] = "contact geometry" in rec["statements"]
        rec["conicity_as_cause"] = d["verdict"] == "cause" and right
        rec["confident_wrong"] = rec["confident_wrong"] or rec["conicity_as_cause"]
    rec["explained_wrong"] = bool(top and top["explained"] >= 0.5 and not right)
    if screen and against_whole:
        t0 = time.perf_counter()
        whole = diagnose(database, name, "baseline", workers=workers, values_per_parameter=values,
                         effects=candidates).to_dict()
        rec["whole"] = whole_of(d, whole, time.perf_counter() - t0)
    if calibrate_wrong and top is not None and not right:
        cal = calibrate(database, name, "baseline", [top["name"]], "calibrated", split=True, popsize=3, maxiter=2,
                        polish_maxfev=5, workers=workers, replace=True,
                        start=({top["name"]: top["parameters"]} if top["kind"] == "effect"
                               else {"model": {top["parameter"]: top["fitted"]}}))
        cd = cal.to_dict()
        rec["wrong_calibration_passes"] = bool(cd["validation"]["validated"])
        held = cd.get("validation_held_out") or {}
        rec["wrong_calibration_flagged"] = flagged(cd)
        rec["wrong_calibration_held_out_validated"] = held.get("validated")
        rec["wrong_calibration_flags"] = list(cd["flags"])
    return rec


def flagged(calibration: dict) -> bool:
    """A calibration result warns that its candidate may be wrong: a fitted value implausible
    or at a bound, or a warning (not a ``note:``) from the held-out check or the parent's
    diagnosis ("… the model may be compensating for something else", "… held-out …")."""
    warnings = [f for f in calibration.get("flags") or [] if not f.startswith("note:")]
    return (not calibration.get("plausible", True)) or any("held-out" in f or "compensating" in f for f in warnings)


def _records_in(path: str | None) -> dict[tuple[str, str], dict]:
    """The finished (not failed) cases of an earlier run's JSON-lines file, by (class, case)."""
    if not path or not Path(path).is_file():
        return {}
    recs = [json.loads(line) for line in Path(path).read_text(encoding="utf-8").splitlines() if line.strip()]
    return {(r["class"], r["case"]): r for r in recs if r.get("verdict") != "error"}


def summarise(records: list[dict]) -> dict:
    """Confusion figures of the bench (module docstring)."""
    out: dict[str, Any] = {"cases": len(records)}
    for k in CASES:
        rs = [r for r in records if r["class"] == k]
        if not rs:
            continue
        item = {"n": len(rs), "verdicts": {v: sum(r["verdict"] == v for r in rs)
                                           for v in ("cause", "uncertain", "none", "error")}}
        if k in "ab":
            item["top1"] = sum(r["right"] for r in rs) / len(rs)
        elif k in _STRUCTURAL:
            on_top = [r for r in rs if r["truth"]]
            item["cause_found"] = sum(r.get("cause_found", False) for r in on_top) / max(1, len(on_top))
            item["structural_named"] = sum(bool(r.get("structural_named")) for r in rs) / len(rs)
        else:
            item["none_or_uncertain"] = sum(r["verdict"] in ("none", "uncertain") for r in rs) / len(rs)
        item.update(class_scores(rs))
        item["tops"] = sorted({r["top"] for r in rs if r["top"]})
        out[k] = item
    out["confident_wrong"] = sum(r["confident_wrong"] for r in records) / max(1, len(records))
    out["explained_ge_0_5_and_wrong"] = sum(r["explained_wrong"] for r in records) / max(1, len(records))
    out.update(against_whole_summary(records))
    passes = [r for r in records if r.get("wrong_calibration_passes")]
    if passes:
        out["wrong_calibrations_passing"] = len(passes)
        out["of_those_flagged"] = sum(r["wrong_calibration_flagged"] for r in passes) / len(passes)
    return out


def class_scores(rs: list[dict]) -> dict[str, float]:
    """Per class (issue 40): of the cases with a right answer, the share named as the ``cause``
    (verdict cause, right top), named in the cause set (every name of one right alternative),
    ``uncertain`` with the right top; of all cases, the share confidently wrong; for the track
    class also the share answering "track input" (the statement, or the top is a track level)
    and the share with a vehicle parameter as the ``cause``."""
    on = [r for r in rs if r["truth"]]
    share = lambda xs, key: sum(bool(r.get(key)) for r in xs) / len(xs) if xs else 0.0
    out = {"named_as_cause": share(on, "named_as_cause"), "named_in_set": share(on, "named_in_set"),
           "uncertain_right_top": share(on, "uncertain_right_top"), "confident_wrong": share(rs, "confident_wrong")}
    if any(r["class"] == "p" for r in rs):
        out["contact_geometry"] = share(rs, "contact_geometry")
        out["conicity_as_cause"] = share(rs, "conicity_as_cause")
    track = [r for r in on if "track_level" in r["truth"]]
    if track:
        out["track_input"] = sum("track input" in (r.get("statements") or []) or
                                 str(r.get("top") or "").startswith("track_level") for r in track) / len(track)
        out["vehicle_parameter_cause"] = share(track, "vehicle_parameter_cause")
    return out


def format_table(records: list[dict], summary: dict) -> str:
    lines = [(f"{'cls':<3} {'case':<44} {'verdict':<9} {'top candidate':<26} {'expl':>5} {'held':>5} "
              f"{'nf':>5} {'ok':>3}")]
    for r in records:
        lines.append(f"{r['class']:<3} {r['case'][:44]:<44} {r['verdict']:<9} {str(r['top'])[:26]:<26} "
                     f"{r['top_explained']:5.2f} {r['top_held_out']:5.2f} {r['noise_floor']:5.2f} "
                     f"{('yes' if r['right'] else '-') if r['truth'] else '':>3}")
    lines.append("")
    for k in CASES:
        if k in summary:
            s = summary[k]
            fig = (f"top-1 {100 * s['top1']:.0f} %" if "top1" in s else
                   f"cause on top found {100 * s['cause_found']:.0f} %, structural difference named "
                   f"{100 * s['structural_named']:.0f} %" if k in _STRUCTURAL
                   else f"none/uncertain {100 * s['none_or_uncertain']:.0f} %")
            fig += (f"; named as cause {100 * s['named_as_cause']:.0f} %, in the set {100 * s['named_in_set']:.0f} %, "
                    f"uncertain with the right top {100 * s['uncertain_right_top']:.0f} %, confidently wrong "
                    f"{100 * s['confident_wrong']:.0f} %")
            if "contact_geometry" in s:
                fig += (f"; contact geometry stated {100 * s['contact_geometry']:.0f} %, a single conicity as "
                        f"cause {100 * s['conicity_as_cause']:.0f} %")
            if "track_input" in s:
                fig += (f"; track input {100 * s['track_input']:.0f} %, vehicle parameter as cause "
                        f"{100 * s['vehicle_parameter_cause']:.0f} %")
            lines.append(f"class ({k}) n={s['n']}: {fig}; verdicts {s['verdicts']}")
    lines.append(f"confident wrong (verdict cause and wrong): {100 * summary['confident_wrong']:.0f} %; "
                 f"explained ≥ 0.5 and wrong: {100 * summary['explained_ge_0_5_and_wrong']:.0f} %")
    lines += against_whole_lines(records, summary)
    if "wrong_calibrations_passing" in summary:
        lines.append(f"wrong calibrations that pass: {summary['wrong_calibrations_passing']}, flagged "
                     f"{100 * summary['of_those_flagged']:.0f} %")
    return "\n".join(lines)


def run(args: argparse.Namespace, progress=None) -> dict:
    n = max(1, min(int(getattr(args, "cases", 10)), 10))
    classes = list(getattr(args, "classes", ["a", "b", "c", "d"]))
    records = []
    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="railval-bench-trust-") as tmp:
        database = connect(f"sqlite:///{Path(tmp) / 'bench.db'}")
        database.init()
        todo = [(k, i, case) for k in classes for i, case in enumerate(CASES[k][:n])]
        done = _records_in(getattr(args, "out", None)) if getattr(args, "resume", False) else {}
        for j, (k, i, (label, kwargs, truth)) in enumerate(todo):
            if (k, label) in done:  # --resume: measured in an earlier run of the same bench
                records.append(done[(k, label)])
                continue
            try:
                rec = run_case(database, f"trust_{k}{i}", k, label, kwargs, truth,
                               workers=getattr(args, "workers", 2), values=getattr(args, "values", 3),
                               oversample=getattr(args, "oversample", 4),
                               calibrate_wrong=getattr(args, "calibrate_wrong", False),
                               screen=getattr(args, "screen", None),
                               against_whole=getattr(args, "against_whole", False),
                               n_sections=getattr(args, "sections", 12))
            except Exception as exc:  # noqa: BLE001 - one failing case is a finding, not the end of the bench
                rec = {"class": k, "case": label, "truth": truth, "verdict": "error", "error": str(exc),
                       "noise_floor": 0.0, "top": None, "top_explained": 0.0, "top_held_out": 0.0,
                       "right": False, "confident_wrong": False, "explained_wrong": False, "diagnose_s": 0.0}
            records.append(rec)
            if getattr(args, "out", None):
                with open(args.out, "a", encoding="utf-8") as fh:
                    fh.write(json.dumps(rec, default=str) + "\n")
            if progress is not None:
                progress(j + 1, len(todo), rec)
            else:
                print(f"[{j + 1}/{len(todo)}] ({k}) {label}: {rec['verdict']}, top {rec['top']} "
                      f"explained {rec['top_explained']:.2f} held-out {rec['top_held_out']:.2f} "
                      f"(noise floor {rec['noise_floor']:.2f}; {rec['diagnose_s']} s)", file=sys.stderr, flush=True)
        database.dispose()
    summary = summarise(records)
    summary["elapsed_s"] = round(time.perf_counter() - t0, 1)
    return {"records": records, "summary": summary, "table": format_table(records, summary)}
