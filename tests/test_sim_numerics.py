"""Numerical scheme of the built-in simulator (docs/simulator.md "Numerical scheme"): the exact
Maxwell update against its closed form, the friction slider's return map, and step halving —
every effect at both of its bounds moves none of the 12 EN 14363 quantities by more than 2 %.

Step-halving tolerance: 2 % of the quantity's value, or of the DynoTRAIN std limit of the
quantity where the value is smaller than that limit (quasi-static forces near zero on straight
track, where a relative error is meaningless); Polach & Böttcher 2014 §5 Table 2 for the limits.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from railval.core.en14363 import evaluate_batch
from railval.core.quantities import QUANTITIES
from railval.core.sim import EFFECTS, TrackSection, VehicleModel, simulate_section
from railval.core.sim.kernel import maxwell, slider
from railval.core.sim.track import generate_irregularities
from railval.core.types import SectionInfo


def test_maxwell_update_is_the_exact_solution_for_constant_velocity():
    """dΔ/dt = v − (k/c)Δ with Δ(0) = Δ0 has Δ(t) = Δ0·e^(−kt/c) + v·(c/k)(1 − e^(−kt/c)); many
    small steps and one big step give the same value (exactness), and the limits are the plain
    dashpot (k → ∞: force c·v) and the plain spring (c → ∞: force k·v·t)."""
    k, c, v, d0, t = 4e6, 2e4, 0.05, 1e-4, 0.003
    exact = d0 * math.exp(-k * t / c) + v * c / k * (1 - math.exp(-k * t / c))
    d = d0
    for _ in range(1000):
        d = maxwell(d, v, k, c, t / 1000)
    assert d == pytest.approx(exact, rel=1e-12)
    assert maxwell(d0, v, k, c, t) == pytest.approx(exact, rel=1e-12)
    assert 1e12 * maxwell(0.0, v, 1e12, c, 1e-3) == pytest.approx(c * v, rel=1e-6)
    assert k * maxwell(0.0, v, k, 1e15, 1e-3) == pytest.approx(k * v * 1e-3, rel=1e-6)


def test_friction_slider_return_map():
    """Saint-Venant element: elastic below the breakaway force, force held at ±F beyond it."""
    f, s = slider(0.001, 0.0, 1e6, 2e3)
    assert (f, s) == (pytest.approx(1e3), 0.0)
    f, s = slider(0.005, 0.0, 1e6, 2e3)
    assert f == 2e3 and s == pytest.approx(0.003)
    f, s = slider(-0.005, 0.0, 1e6, 2e3)
    assert f == -2e3 and s == pytest.approx(-0.003)


_STRAIGHT = TrackSection("H1", speed_kmh=160.0, straight_in_m=150.0, curve_m=0.0, straight_out_m=250.0,
                         irregularities=generate_irregularities(560.0, level="low", seed=21, s0=-60.0))
_CURVE = TrackSection("H4", speed_kmh=80.0, radius_m=300.0, cant_mm=120.0, straight_in_m=40.0,
                      transition_in_m=50.0, curve_m=160.0, transition_out_m=50.0, straight_out_m=20.0,
                      irregularities=generate_irregularities(400.0, level="low", seed=22, s0=-60.0))


def _info(sec: TrackSection) -> SectionInfo:
    a, b = sec.eval_range if sec.is_curve else (150.0, 390.0)
    return SectionInfo(id=sec.id, radius_m=sec.radius_m or math.inf, cant_mm=sec.cant_mm,
                       speed_kmh=sec.speed_kmh, zone=4 if sec.is_curve else 1, eval_start_m=a, eval_end_m=b)


def _cases():
    for e in EFFECTS.values():
        for p in e.parameters.values():
            for bound in ("lower", "upper"):
                yield e.id, p.name, bound


def _halving_error(effect: str, param: str, bound: str, sec: TrackSection) -> tuple[float, tuple, float, float]:
    veh = VehicleModel("coach")
    val = getattr(EFFECTS[effect].parameters[param], bound)
    eff = {effect: {param: val}}
    if effect != "measured_irregularities":
        eff["measured_irregularities"] = {}
    info = _info(sec)
    a, b = (dict(evaluate_batch([simulate_section(veh, sec, eff, refine=r)], [info])[0]) for r in (1, 2))
    worst = (0.0, None, 0.0, 0.0)
    for key, ref in b.items():
        scale = max(abs(ref), QUANTITIES[key[0]].std_limit(veh.q0_kN(), veh.kind, True))
        err = abs(a[key] - ref) / scale
        if err > worst[0]:
            worst = (err, key, a[key], ref)
    assert len({k[0] for k in b}) == 12
    return worst


@pytest.mark.parametrize(("effect", "param", "bound"), list(_cases()))
def test_step_halving_moves_no_en_quantity_by_more_than_2_percent(effect, param, bound):
    """Every effect at both bounds of every parameter, on the section where the effect acts
    (a straight at 160 km/h for effects of zone 1, a 300 m curve at 80 km/h otherwise)."""
    sec = _STRAIGHT if 1 in EFFECTS[effect].zones else _CURVE
    err, key, got, ref = _halving_error(effect, param, bound, sec)
    assert err <= 0.02, (key, got, ref)


@pytest.mark.slow
@pytest.mark.parametrize(("effect", "param", "bound"), list(_cases()))
def test_step_halving_on_both_sections(effect, param, bound):
    """Exhaustive variant: every effect at both bounds on the straight AND the curve."""
    for sec in (_STRAIGHT, _CURVE):
        err, key, got, ref = _halving_error(effect, param, bound, sec)
        assert err <= 0.02, (sec.id, key, got, ref)


def test_step_halving_baseline_at_200_kmh():
    """The case of the review: the baseline coach on a straight at 200 km/h."""
    sec = TrackSection("H0", speed_kmh=200.0, straight_in_m=200.0, curve_m=0.0, straight_out_m=300.0,
                       irregularities=generate_irregularities(620.0, level="low", seed=23, s0=-60.0))
    veh = VehicleModel("coach")
    info = SectionInfo(id="H0", radius_m=math.inf, cant_mm=0.0, speed_kmh=200.0, zone=1,
                       eval_start_m=200.0, eval_end_m=450.0)
    a, b = (dict(evaluate_batch([simulate_section(veh, sec, {"measured_irregularities": {}}, refine=r)],
                                [info])[0]) for r in (1, 2))
    for key, ref in b.items():
        scale = max(abs(ref), QUANTITIES[key[0]].std_limit(veh.q0_kN(), veh.kind, True))
        assert abs(a[key] - ref) <= 0.02 * scale, (key, a[key], ref)
    assert np.isfinite(list(a.values())).all()


@pytest.mark.parametrize("kv,kl", [(300.0, 1.5), (300.0, 3.0), (10.0, 200.0)])
def test_track_flexibility_corners_stay_finite_and_step_converged(kv, kl):
    """The corners of track_flexibility's search box (stiff vertical with soft lateral track):
    the wheelsets used to start at zero above rails that lie 1–2 mm off at the start, so 300 MN/m
    track springs gave ±400 kN wheel-load jumps and, with 1.5 MN/m lateral rails, a run that was
    non-finite from its first sample (seen in a calibration). Wheelsets now start on the rails:
    the first samples carry the static load and halving the step moves the maxima < 1 %."""
    veh = VehicleModel("coach")
    sec = TrackSection("C1", speed_kmh=85.0, radius_m=480.0, cant_mm=110.0, straight_in_m=60.0,
                       transition_in_m=60.0, curve_m=150.0, transition_out_m=40.0, straight_out_m=20.0,
                       irregularities=generate_irregularities(400.0, level="low", seed=23, s0=-60.0))
    eff = {"track_flexibility": {"k_vertical_MN_m": kv, "k_lateral_MN_m": kl}, "measured_irregularities": {}}
    runs = [simulate_section(veh, sec, eff, refine=r) for r in (1, 2)]
    q0 = veh.q0_kN()
    for ss in runs:
        for ch in ("Y_w1L", "Q_w1L", "Q_w1R", "Y_w4R"):
            x = ss.channels[ch]
            assert np.all(np.isfinite(x)), ch
        assert np.all(np.abs(ss.channels["Q_w1L"][:5] - q0) < 0.25 * q0)  # no start-up shock
    for ch in ("Y_w1L", "Q_w1L", "Y_w4R"):
        a, b = (float(np.max(np.abs(ss.channels[ch]))) for ss in runs)
        assert a == pytest.approx(b, rel=0.01), ch


def test_kernel_freedoms_move_a_run_by_rounding_only():
    """The step's floating-point freedoms (``KERNEL_FASTMATH``, docs/simulator.md "Numerical
    scheme") keep NaN and infinity meaningful (no ``nnan``, ``ninf`` or ``fast``) and move a run
    only by rounding: the same step compiled here with IEEE semantics (numba without fastmath,
    the independent reference) gives every output channel within 10⁻⁹ of its largest value, on
    the 200 km/h straight and on a 300 m curve with flange contact and the wheel loads' cube
    root; the two runs are not the same bits (the freedoms are in effect)."""
    from railval.core.sim import kernel
    from tests.sim_ieee import ieee_kernel

    assert kernel.KERNEL_FASTMATH <= {"contract", "reassoc", "arcp", "nsz"}
    assert not kernel.KERNEL_FASTMATH & {"nnan", "ninf", "fast", "afn"}
    veh = VehicleModel("coach")
    sec = TrackSection("R0", speed_kmh=80.0, straight_in_m=60.0, curve_m=120.0, straight_out_m=60.0,
                       radius_m=300.0, cant_mm=150.0,
                       irregularities=generate_irregularities(320.0, level="low", seed=5, s0=-40.0))
    differs = False
    for section in (sec, TrackSection("H1", speed_kmh=200.0, straight_in_m=150.0, curve_m=0.0, straight_out_m=150.0,
                                      irregularities=generate_irregularities(380.0, level="low", seed=23, s0=-40.0))):
        fast = simulate_section(veh, section, {})
        with ieee_kernel():
            ref = simulate_section(veh, section, {})
        for ch, x in ref.channels.items():
            assert np.isfinite(x).all() and np.isfinite(fast.channels[ch]).all(), ch
            assert np.max(np.abs(fast.channels[ch] - x)) <= 1e-9 * max(np.max(np.abs(x)), 1e-12), (section.id, ch)
            differs |= not np.array_equal(fast.channels[ch], x)
    assert differs
