"""The second creep law of the simulator (docs/simulator.md "Wheel–rail contact"): Polach's law
with reduction factors, selected by the template parameter ``creep_law`` = 1 (used by the trust
bench's truth only). The default (Shen–Hedrick–Elkins saturation) is unchanged."""

from __future__ import annotations

import math

import numpy as np
import pytest

from railval.core.sim import TrackSection, simulate_section
from railval.core.sim.kernel import _polach_factor, _sat_factor
from railval.core.sim.track import generate_irregularities
from railval.core.sim.vehicles import template_parameters

_CURVE = TrackSection("H4", speed_kmh=80.0, radius_m=300.0, cant_mm=120.0, straight_in_m=40.0,
                      transition_in_m=50.0, curve_m=160.0, transition_out_m=50.0, straight_out_m=20.0,
                      irregularities=generate_irregularities(400.0, level="low", seed=22, s0=-60.0))


def test_polach_factor_limits():
    """Small creep: (kA + kS)/2 of Kalker's slope; kA = kS = 1 recovers Kalker's slope; far beyond
    saturation the force tends to μQ (Polach 2005, Wear 258, §2)."""
    mu_q = 30e3
    assert _polach_factor(1.0, 0.0, mu_q, 1.0, 0.4) == pytest.approx(0.7, rel=1e-6)
    assert _polach_factor(1.0, 0.0, mu_q, 1.0, 1.0) == pytest.approx(1.0, rel=1e-6)
    f = 1e4 * mu_q
    assert f * _polach_factor(f, 0.0, mu_q, 1.0, 0.4) == pytest.approx(mu_q, rel=1e-3)
    # the closed form at ε = 1 (kA = kS = 1): (1/2 + π/4)/2
    f1 = 4 * mu_q / math.pi
    assert _polach_factor(0.6 * f1, 0.8 * f1, mu_q, 1.0, 1.0) == pytest.approx((0.5 + math.pi / 4) / 2, rel=1e-9)
    # the default law is a different curve: at the same creep force the factors differ
    assert abs(_polach_factor(f1, 0.0, mu_q, 1.0, 0.4) - _sat_factor(f1, 0.0, mu_q)) > 0.05
    assert _polach_factor(1.0, 0.0, 0.0, 1.0, 0.4) == 0.0


def test_creep_law_is_a_template_parameter_defaulting_to_the_old_law():
    for t in ("coach", "wagon"):
        p = {x.name: x for x in template_parameters(t)}
        assert p["creep_law"].default == 0.0 and p["polach_kS"].default == 0.4


def test_default_is_unchanged_and_the_polach_law_changes_the_guiding_forces():
    """creep_law = 0 given explicitly reproduces the default bit for bit; creep_law = 1 changes the
    quasi-static guiding forces in a tight curve (lower creep forces: more flange force)."""
    a = simulate_section("coach", _CURVE, {})
    b = simulate_section("coach", _CURVE, {}, parameters={"creep_law": 0.0, "polach_kS": 0.2})
    for k in a.channels:
        assert np.array_equal(a.channels[k], b.channels[k]), k
    c = simulate_section("coach", _CURVE, {}, parameters={"creep_law": 1.0})
    assert all(np.isfinite(x).all() for x in c.channels.values())
    diff = max(float(np.max(np.abs(c.channels[k] - a.channels[k]))) for k in a.channels if k.startswith("Y_w"))
    assert diff > 1.0  # kN
