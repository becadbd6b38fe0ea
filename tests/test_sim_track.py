"""Track geometry, irregularity generation, contact coefficients and campaign-level simulation."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.integrate import quad

from railval.core.errors import InvalidParameter
from railval.core.sim import TrackSection, VehicleModel, simulate_campaign
from railval.core.sim.model import bending_mode_shape, kalker_coefficients
from railval.core.sim.track import generate_irregularities, irregularities_to_layout, ore_b176_psd


@pytest.mark.parametrize("kind", ["vertical", "alignment", "cross_level", "gauge"])
def test_generated_irregularity_variance_matches_psd_integral(kind):
    """Variance of the generated signal = ∫ S(Ω) dΩ over the 3–70 m band (scipy quad of the ORE
    B176 formula). Averaged over 6 long realisations; tolerance 10 % (random-phase estimate on
    ≈ 6 × 4 km, dominated by the long wavelengths)."""
    lo, hi = 2 * math.pi / 70.0, 2 * math.pi / 3.0
    expected = quad(lambda w: float(ore_b176_psd(np.array([w]), kind, "high")[0]), lo, hi, limit=200)[0]
    var = np.mean([np.var(generate_irregularities(4000.0, level="high", seed=s, taper_m=0.0)[kind])
                   for s in range(6)])
    assert var == pytest.approx(expected, rel=0.10)


def test_ore_levels_and_band_checks():
    w = np.array([0.1, 0.5, 1.0])
    assert np.all(ore_b176_psd(w, "vertical", "high") / ore_b176_psd(w, "vertical", "low") == pytest.approx(1.080 / 0.4032))
    with pytest.raises(InvalidParameter, match="level 'medium'"):
        ore_b176_psd(w, "vertical", "medium")
    with pytest.raises(InvalidParameter, match="lambda_min < lambda_max"):
        generate_irregularities(100.0, lambda_min=70.0, lambda_max=3.0)


def test_layout_geometry_curvature_and_cant_ramps():
    sec = TrackSection("G", speed_kmh=100, radius_m=800, cant_mm=120, curve_direction=-1, straight_in_m=100,
                       transition_in_m=100, curve_m=200, transition_out_m=100, straight_out_m=100)
    kap, phi = sec.geometry(np.array([50.0, 150.0, 300.0, 450.0, 550.0]))
    np.testing.assert_allclose(kap, [0, -0.5 / 800, -1 / 800, -0.5 / 800, 0])
    np.testing.assert_allclose(phi, [0, -0.06 / 1.5, -0.12 / 1.5, -0.06 / 1.5, 0])
    assert sec.eval_range == (200.0, 400.0)
    assert sec.cant_deficiency_acc() == pytest.approx((100 / 3.6) ** 2 / 800 - 9.81 * 0.12 / 1.5)
    with pytest.raises(InvalidParameter, match="curve_direction"):
        TrackSection("G", speed_kmh=100, curve_direction=0)


def test_layout_record_round_trip():
    irr = generate_irregularities(50.0, seed=1)
    rec = irregularities_to_layout(irr)
    assert rec["ds_m"] == 0.5 and len(rec["vertical_mm"]) == irr["s"].size
    np.testing.assert_allclose(np.array(rec["alignment_mm"]) / 1000, irr["alignment"], atol=5e-6)


def test_kalker_coefficients_by_hand():
    """f11 = G·(area/π)·C11: 8e10 · 1.2e-4/π · 4.12 = 12.59 MN; f22 with C22 = 3.67: 11.21 MN."""
    f11, f22 = kalker_coefficients(VehicleModel("coach"))
    assert f11 == pytest.approx(8e10 * 1.2e-4 / math.pi * 4.12)
    assert f22 == pytest.approx(8e10 * 1.2e-4 / math.pi * 3.67)


def test_bending_mode_shape_free_free():
    """First free–free mode: nodes at ξ = 0.2242 and 0.7758 (Blevins), symmetric, mean φ² = 1."""
    L = 24.5
    x = (np.array([0.2242, 0.7758]) - 0.5) * L
    assert np.max(np.abs(bending_mode_shape(x, L))) < 2e-3
    grid = np.linspace(-L / 2, L / 2, 4001)
    phi = bending_mode_shape(grid, L)
    assert np.mean(phi**2) == pytest.approx(1.0, rel=1e-3)
    np.testing.assert_allclose(phi, phi[::-1], atol=1e-6)  # σ is given to 9 digits


def test_simulate_campaign_identical_serial_and_parallel():
    veh = VehicleModel("coach")
    secs = [TrackSection(f"P{i}", speed_kmh=120.0, radius_m=0.0 if i == 0 else 900.0, cant_mm=0.0 if i == 0 else 80.0,
                         straight_in_m=80.0, transition_in_m=0.0 if i == 0 else 40.0, curve_m=60.0,
                         transition_out_m=0.0, straight_out_m=20.0, seed=i) for i in range(3)]
    eff = {"friction_damping": {"force_kN": 1.0}}
    a = simulate_campaign(veh, secs, effects=eff, workers=1)
    b = simulate_campaign(veh, secs, effects=eff, workers=2)
    assert list(a) == ["P0", "P1", "P2"] == list(b)
    for sid in a:
        for ch in a[sid].channels:
            np.testing.assert_array_equal(a[sid].channels[ch], b[sid].channels[ch])
