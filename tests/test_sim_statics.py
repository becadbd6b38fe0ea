"""Statics of the built-in simulator's load paths (docs/simulator.md "Static load path"): lateral
weight shift of car body and bogies in the wheel loads, and the longitudinal restraint that
keeps the yaw dampers from damping car body pitch."""

from __future__ import annotations

import math

import numpy as np
import pytest

from railval.core.sim import TrackSection, VehicleModel
from railval.core.sim import kernel as K
from railval.core.sim.model import assemble, run_assembled
from railval.core.sim.track import DS, S_TRACK

G = 9.81


def _flat_irr(length: float) -> dict:
    s = np.arange(-100.0, length + 200.0, DS)
    z = np.zeros_like(s)
    return {"s": s, "vertical": z, "alignment": z, "cross_level": z, "gauge": z}


def test_lateral_weight_shift_in_wheel_loads_matches_statics():
    """Coach standing (10 km/h) on 150 mm cant of a R = 100 km curve (curvature negligible):
    cant excess a_q = v²/R − g·h/s ≈ −0.98 m/s², the car body and bogies move to the low side
    (the inner rail of this left-hand curve, +y).
    Roll-moment balance of the whole vehicle about the track centreline at rail level, computed
    here by hand from the simulated body offsets:

        Σ_wheelsets [b0·(Q_L − Q_R) + y_w·(Q_L + Q_R)] = Σ_bodies m·g·y − a_q·Σ_bodies m·h

    (wheel loads at y_w ± b0, gravity at each body's lateral offset y, the track-plane
    pseudo-force −m·a_q at each centre of gravity height h; lateral rail forces act at rail
    level). The weight-shift share m·g·y is what a model without lateral weight shift misses:
    for a 38 mm car body offset it is 32 000·9.81·0.038 / (4 wheelsets · 2·b0) ≈ 1.99 kN per
    wheel. Tolerance 1 % of the total moment (curvature offsets x²/(2R) ≤ 0.6 mm over the
    vehicle)."""
    veh = VehicleModel("coach")
    p = veh.parameters
    v = 10 / 3.6
    radius, cant = 100000.0, 150.0
    sec = TrackSection("W", speed_kmh=10.0, radius_m=radius, cant_mm=cant, straight_in_m=10.0, transition_in_m=20.0,
                       curve_m=120.0, transition_out_m=0.0, straight_out_m=0.0, irregularities=_flat_irr(150.0))
    asm = assemble(veh, {}, v)
    ss, st = run_assembled(asm, veh, sec, use_measured=True, states=True)
    m = ss.distance_m > 120.0
    med = {k: float(np.median(x[m])) for k, x in ss.channels.items()}
    y_ws = np.median(st[m, :4], axis=0)
    y_cb = float(np.median(st[m, 6]))
    y_bg = np.median(st[m, 7:9], axis=0)
    aq = v**2 / radius - G * cant / 1000 / S_TRACK
    lhs = sum(p["b0"] * (med[f"Q_w{i}L"] - med[f"Q_w{i}R"]) * 1e3
              + y_ws[i - 1] * (med[f"Q_w{i}L"] + med[f"Q_w{i}R"]) * 1e3 for i in range(1, 5))
    masses = [(p["m_carbody"], y_cb, p["h_carbody"])] + [(p["m_bogie"], y, p["h_bogie"]) for y in y_bg] + \
             [(p["m_wheelset"], y, p["r0"]) for y in y_ws]
    rhs = sum(mi * G * yi for mi, yi, _ in masses) - aq * sum(mi * hi for mi, _, hi in masses)
    assert lhs == pytest.approx(rhs, rel=0.01)
    # the car body moved to the low (inner, left = +y) side by tens of mm and its weight shift
    # is a large part of the transfer (far beyond the 1 % tolerance): a model without it misses
    # m·g·y_cb in the balance
    assert y_cb > 0.02
    assert abs(p["m_carbody"] * G * y_cb) > 0.05 * abs(rhs)
    # the worked example of the docstring
    assert 32000 * G * 0.038 / (4 * 2 * 0.75) == pytest.approx(1987.4, rel=1e-3)


def _pitch_damping_ratio(theta: np.ndarray, fs: float) -> float:
    """Damping ratio from the logarithmic decrement of successive positive peaks."""
    x = theta - np.median(theta[-len(theta) // 4:])
    pk = [i for i in range(1, len(x) - 1) if x[i] > x[i - 1] and x[i] >= x[i + 1] and x[i] > 0]
    amps = x[pk]
    n = min(len(amps) - 1, 8)
    assert n >= 3, "too few pitch oscillations"
    delta = math.log(amps[0] / amps[n]) / n
    return delta / math.sqrt(4 * math.pi**2 + delta**2)


def test_yaw_dampers_do_not_damp_car_body_pitch():
    """With every vertical damper removed (primary and secondary) the car body pitch mode is
    undamped except for the yaw dampers' share; the traction rods hold the car body
    longitudinally at the yaw dampers' height, so car body pitch gives no yaw damper stroke:
    damping ratio ≈ 0 (< 0.002; it was ≈ 0.025 without longitudinal freedom). The same run with
    the secondary vertical dampers in place is clearly damped (> 0.05), so the estimate can
    tell the two apart."""
    zeta = {}
    for label, params in (("no vertical dampers", {"c_secondary_z": 0.0, "c_primary_z": 0.0}),
                          ("with dampers", {})):
        veh = VehicleModel("coach", params)
        asm = assemble(veh, {}, 10.0)
        asm.SC[K.TH_INIT] = 0.002
        sec = TrackSection("P", speed_kmh=36.0, straight_in_m=300.0, curve_m=0.0, straight_out_m=0.0,
                           irregularities=_flat_irr(300.0))
        ss, st = run_assembled(asm, veh, sec, use_measured=True, states=True)
        zeta[label] = _pitch_damping_ratio(st[:, 5], ss.fs)
    assert abs(zeta["no vertical dampers"]) < 0.002, zeta
    assert zeta["with dampers"] > 0.05, zeta

