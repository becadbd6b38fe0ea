"""The effect library: registry contents, parameter checking, and that every effect moves the
outputs it claims to move (and, within tolerance, not unrelated ones)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.signal import butter, sosfiltfilt

from railval.core.errors import InvalidParameter
from railval.core.sim import (
    EFFECT_IDS,
    EFFECTS,
    TrackSection,
    VehicleModel,
    resolve_effects,
    simulate_section,
)
from railval.core.sim.effects import QUANTITY_IDS
from railval.core.sim.synth import HIDDEN_DEFAULTS
from railval.core.sim.track import generate_irregularities

EXPECTED_IDS = ("friction_damping", "damper_series_stiffness", "carbody_flexibility", "track_flexibility",
                "wheel_rail_friction", "conicity", "measured_irregularities", "track_level_vertical",
                "track_level_lateral", "parasitic_yaw_stiffness",
                "lateral_bumpstop")


def test_registry_has_the_nine_effects_with_complete_metadata():
    assert tuple(EFFECT_IDS) == EXPECTED_IDS
    for e in EFFECTS.values():
        assert len(e.explanation) > 80
        assert e.quantities and set(e.quantities) <= set(QUANTITY_IDS)
        assert set(e.zones) <= {1, 2, 3, 4}
        for p in e.parameters.values():
            assert p.lower <= p.default <= p.upper and p.unit
        d = e.to_dict()
        assert d["id"] == e.id and set(d["parameters"]) == set(e.parameters)


def test_unknown_effect_and_out_of_bounds_parameter_raise_precise_errors():
    with pytest.raises(InvalidParameter, match="unknown effect id 'frictoin'"):
        resolve_effects({"frictoin": {}})
    with pytest.raises(InvalidParameter, match=r"effect 'conicity'.*'conicity' = 0\.9.*\[0\.015, 0\.6\]"):
        resolve_effects({"conicity": {"conicity": 0.9}})
    with pytest.raises(InvalidParameter, match="unknown parameter 'mu_x'"):
        resolve_effects({"wheel_rail_friction": {"mu_x": 0.3}})
    with pytest.raises(InvalidParameter, match="m_carbody"):
        VehicleModel("coach", {"m_carbody": 1.0})
    with pytest.raises(InvalidParameter, match="template 'tram'"):
        VehicleModel("tram")
    assert resolve_effects({"lateral_bumpstop": {"clearance_mm": 30}})["lateral_bumpstop"] == {
        "clearance_mm": 30.0, "stiffness_kN_mm": 1.0}


_IRR = generate_irregularities(900.0, level="high", seed=21, s0=-60.0)
SECTIONS = {
    "straight": TrackSection("A", speed_kmh=160.0, straight_in_m=350.0, curve_m=0.0, straight_out_m=350.0,
                             irregularities=_IRR),
    "curve": TrackSection("B", speed_kmh=75.0, radius_m=320.0, cant_mm=120.0, straight_in_m=100.0,
                          transition_in_m=70.0, curve_m=250.0, transition_out_m=40.0, straight_out_m=40.0,
                          irregularities=_IRR),
}
WINDOW = {"straight": (250.0, 650.0), "curve": (200.0, 410.0)}


def _stats(ss, key) -> dict[str, float]:
    a, b = WINDOW[key]
    m = (ss.distance_m > a) & (ss.distance_m < b)
    c = ss.channels
    sos = butter(4, [0.4, 10.0], "bandpass", fs=ss.fs, output="sos")
    out = {
        "Y_qst": float(np.median(np.abs(c["Y_w1L"][m])) + np.median(np.abs(c["Y_w1R"][m]))),
        "Y_max": float(max(np.abs(c["Y_w1L"][m]).max(), np.abs(c["Y_w1R"][m]).max())),
        "Q_max": float(max(np.abs(c["Q_w1L"][m]).max(), np.abs(c["Q_w1R"][m]).max())),
    }
    for ch in ("ay_cb_b1", "az_cb_b1"):
        x = sosfiltfilt(sos, c[ch])[m]
        out[ch[:2] + "_rms"] = float(np.std(x))
        out[ch[:2] + "_max"] = float(np.abs(x).max())
    return out


@pytest.fixture(scope="module")
def base_stats():
    veh = VehicleModel("coach")
    return {k: _stats(simulate_section(veh, s, {"measured_irregularities": {}}), k) for k, s in SECTIONS.items()}


# effect → (section, metrics that must change by more than the relative amount,
#           metrics that must stay within the relative tolerance)
CLAIMS = {
    "friction_damping": ("straight", {"ay_rms": 0.2, "az_max": 0.05}, {"Y_qst": 0.05}),
    "damper_series_stiffness": ("straight", {"ay_rms": 0.03}, {"Y_qst": 0.05}),
    "carbody_flexibility": ("straight", {"az_max": 0.05}, {"ay_rms": 0.01, "Y_qst": 0.01}),
    "track_flexibility": ("curve", {"Y_max": 0.05}, {"az_rms": 0.05}),
    "wheel_rail_friction": ("curve", {"Y_qst": 0.1}, {"az_rms": 0.02}),
    "conicity": ("curve", {"Y_qst": 0.05}, {"az_rms": 0.05}),
    "measured_irregularities": ("straight", {"az_rms": 0.2, "ay_rms": 0.1}, {}),
    "parasitic_yaw_stiffness": ("curve", {"Y_qst": 0.05}, {"az_rms": 0.02}),
    "lateral_bumpstop": ("curve", {"ay_max": 0.1}, {"az_rms": 0.02}),
}


# the generated track's level (track_level_*) is tested in tests/test_diagnosis_inputs.py
@pytest.mark.parametrize("effect", [e for e in EXPECTED_IDS if not e.startswith("track_level_")])
def test_effect_changes_what_it_claims(effect, base_stats):
    key, must, keep = CLAIMS[effect]
    veh = VehicleModel("coach")
    if effect == "measured_irregularities":
        eff = {}  # the baseline of this test runs on the measured arrays; "off" = generated
    else:
        eff = {"measured_irregularities": {}, effect: HIDDEN_DEFAULTS[effect]}
    got = _stats(simulate_section(veh, SECTIONS[key], eff), key)
    ref = base_stats[key]
    for q, rel in must.items():
        assert abs(got[q] - ref[q]) > rel * abs(ref[q]), (q, got[q], ref[q])
    for q, rel in keep.items():
        assert abs(got[q] - ref[q]) <= rel * abs(ref[q]) + 1e-9, (q, got[q], ref[q])
    if effect in ("parasitic_yaw_stiffness", "lateral_bumpstop"):
        # curve-only effects leave straight-track running (within clearance) almost unchanged
        straight = _stats(simulate_section(veh, SECTIONS["straight"], eff), "straight")
        assert straight["az_rms"] == pytest.approx(base_stats["straight"]["az_rms"], rel=0.02)


def test_effects_are_deterministic_and_wagon_runs_with_its_effects():
    veh = VehicleModel("wagon")
    sec = TrackSection("W", speed_kmh=80.0, radius_m=500.0, cant_mm=100.0, straight_in_m=80.0,
                       transition_in_m=60.0, curve_m=120.0, transition_out_m=0.0, straight_out_m=0.0,
                       irregularity_level="low", seed=4)
    a = simulate_section(veh, sec, {"friction_damping": {"force_kN": 1.0}})
    b = simulate_section(veh, sec, {"friction_damping": {"force_kN": 1.0}})
    assert set(a.channels) == {f"{k}_w{i}{s}" for k in "YQ" for i in (1, 2) for s in "LR"} | {
        "ay_cb_b1", "ay_cb_b2", "az_cb_b1", "az_cb_b2"}
    for ch in a.channels:
        np.testing.assert_array_equal(a.channels[ch], b.channels[ch])
    assert all(np.isfinite(x).all() for x in a.channels.values())


def test_linear_effect_scales_linearly_for_small_values():
    """A linear effect (parasitic yaw stiffness: a moment k·Δψ with the curve-imposed bogie yaw
    Δψ ≈ (bogie distance / 2)/R) changes the quasi-static guiding force in proportion to k for
    small k: ΔY(200) / ΔY(100) = 2 within 5 % (the curving equilibrium is nearly linear there)."""
    veh = VehicleModel("coach")
    s = np.arange(-100.0, 900.0, 0.5)
    z = np.zeros_like(s)
    sec = TrackSection("Q", speed_kmh=70.0, radius_m=400.0, cant_mm=100.0, straight_in_m=60.0,
                       transition_in_m=60.0, curve_m=250.0, transition_out_m=0.0, straight_out_m=0.0,
                       irregularities={"s": s, "vertical": z, "alignment": z, "cross_level": z, "gauge": z})
    m = None
    vals = []
    for k in (0.0, 100.0, 200.0):
        ss = simulate_section(veh, sec, {"measured_irregularities": {}, "parasitic_yaw_stiffness": {"k_yaw_kNm_rad": k}})
        if m is None:
            m = (ss.distance_m > 250.0) & (ss.distance_m < 365.0)
        vals.append(np.median(ss.channels["Y_w1L"][m] + ss.channels["Y_w1R"][m]))
    d1, d2 = vals[1] - vals[0], vals[2] - vals[0]
    assert abs(d1) > 0.05
    assert d2 / d1 == pytest.approx(2.0, rel=0.05)


def test_damper_series_stiffness_moves_quantities_as_its_explanation_says():
    """The effect's explanation: a few MN/m of series stiffness LOWERS car body lateral
    accelerations and guiding-force peaks on straight track (dampers pass less high-frequency
    force); much lower series stiffness RAISES Y_max, ΣY_max (yaw damping lost) and car body
    vertical accelerations (vertical dampers lose their effect). Straight, 200 km/h, ORE B176
    low level; EN 14363 processing (core.en14363)."""
    import math

    from railval.core.en14363 import evaluate_batch
    from railval.core.types import SectionInfo

    sec = TrackSection("D", speed_kmh=200.0, straight_in_m=250.0, curve_m=0.0, straight_out_m=400.0,
                       irregularities=generate_irregularities(900.0, level="low", seed=21, s0=-60.0))
    info = SectionInfo(id="D", radius_m=math.inf, cant_mm=0.0, speed_kmh=200.0, zone=1,
                       eval_start_m=250.0, eval_end_m=600.0)
    veh = VehicleModel("coach")

    def worst(k):
        eff = {"measured_irregularities": {}}
        if k is not None:
            eff["damper_series_stiffness"] = {"k_series_MN_m": k}
        r = dict(evaluate_batch([simulate_section(veh, sec, eff)], [info])[0])
        return {q: max(v for key, v in r.items() if key[0] == q) for q in ("ay_rms", "ay_max", "Y_max", "SumY_max", "az_rms")}

    plain, moderate, low = worst(None), worst(4.0), worst(0.5)
    for q in ("ay_rms", "ay_max", "Y_max", "SumY_max"):
        assert moderate[q] < 0.95 * plain[q], (q, moderate[q], plain[q])
    for q in ("Y_max", "SumY_max"):
        assert low[q] > 1.1 * moderate[q], (q, low[q], moderate[q])
    assert low["az_rms"] > 1.05 * plain["az_rms"]


def test_yaw_damper_force_limit_caps_the_yaw_damping():
    """Yaw damper blow-off (template parameter ``yaw_damper_blowoff``): a 2 kN force limit leaves
    the bogie with little yaw damping at 200 km/h — guiding forces rise by more than 20 % over
    an unlimited (50 kN) damper; the default 12 kN limit is not reached on good track (within
    1 % of the unlimited damper)."""
    import math

    from railval.core.en14363 import evaluate_batch
    from railval.core.types import SectionInfo

    sec = TrackSection("D", speed_kmh=200.0, straight_in_m=250.0, curve_m=0.0, straight_out_m=400.0,
                       irregularities=generate_irregularities(900.0, level="low", seed=21, s0=-60.0))
    info = SectionInfo(id="D", radius_m=math.inf, cant_mm=0.0, speed_kmh=200.0, zone=1,
                       eval_start_m=250.0, eval_end_m=600.0)

    def worst(blowoff):
        veh = VehicleModel("coach", {"yaw_damper_blowoff": blowoff})
        r = dict(evaluate_batch([simulate_section(veh, sec, {"measured_irregularities": {}})], [info])[0])
        return {q: max(v for key, v in r.items() if key[0] == q) for q in ("Y_max", "SumY_max")}

    weak, default, unlimited = worst(2e3), worst(12e3), worst(5e4)
    for q in ("Y_max", "SumY_max"):
        assert weak[q] > 1.2 * unlimited[q], (q, weak[q], unlimited[q])
        assert default[q] == pytest.approx(unlimited[q], rel=0.01)
