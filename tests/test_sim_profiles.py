"""Contact geometry as data (docs/simulator.md "Contact geometry as data"): the rolling-radius
difference table Δr(y) of measured profiles, its equivalent conicity, the file format and its
errors, the simulator running on the table, and the command line that stores it with a
configuration.

Expected values are computed here independently: closed forms of the harmonic linearisation
for a cone, a cubic and a jump, Klingel's wavelength, and the simulator's own linear contact
law written as a table.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from railval.core.errors import InvalidParameter
from railval.core.sim import TrackSection, VehicleModel, simulate_section
from railval.core.sim import kernel as K
from railval.core.sim.model import FLANGE_ROOT_ONSET, LAMBDA_FLANGE_ROOT, assemble, run_assembled
from railval.core.sim.profiles import ContactTable, check_table, equivalent_conicity, linear_table, parse_csv
from tests.test_sim_verification import _flat, _free_wheelsets, _wavelength


def _table(f, y_max=12.0, step=0.01) -> ContactTable:
    y = np.round(np.arange(0.0, y_max + step / 2, step), 6)
    return check_table({"y_mm": list(y), "delta_r_mm": [float(f(v)) for v in y]})


# ----------------------------------------------------------------------------- equivalent conicity
@pytest.mark.parametrize("amp", [0.5, 1.0, 3.0, 6.0])
def test_equivalent_conicity_of_a_cone_is_half_the_slope_at_every_amplitude(amp):
    t = check_table({"y_mm": [-10.0, 0.0, 10.0], "delta_r_mm": [-4.0, 0.0, 4.0]})  # Δr = 0.4·y
    assert equivalent_conicity(t, amp) == pytest.approx(0.2, rel=1e-12)


@pytest.mark.parametrize("amp", [1.0, 3.0, 5.0])
def test_equivalent_conicity_of_a_cubic(amp):
    """Δr = 2λy + c·y³: the first Fourier coefficient of c·(ŷ sin φ)³ is c·ŷ³·3/4, so
    λe = λ + 3·c·ŷ²/8. Tolerance 1e-4: the table's linear interpolation at 0.01 mm."""
    lam, c = 0.05, 0.004  # c in 1/mm²
    t = _table(lambda y: 2 * lam * y + c * y**3)
    assert equivalent_conicity(t, amp) == pytest.approx(lam + 3 * c * amp**2 / 8, rel=1e-4)


@pytest.mark.parametrize("amp", [2.0, 3.0, 4.0, 6.0])
def test_equivalent_conicity_of_a_worn_pair_with_a_contact_jump(amp):
    """Δr = 2λy + h·sign(y) beyond |y| = a (a jump of h): for ŷ > a the jump adds
    (1/(2πŷ))·4·h·∫_{φ0}^{π/2} sin φ dφ = 2h·cos φ0/(πŷ), sin φ0 = a/ŷ; nothing for ŷ ≤ a.
    The table ramps the jump over 0.01 mm: to first order a jump at the ramp's middle
    (tolerance 5e-4 relative)."""
    lam, h, a = 0.025, 2.0, 2.5
    t = _table(lambda y: 2 * lam * y + (h * min(1.0, (y - a) / 0.01) if y > a else 0.0))
    a_mid = a + 0.005
    extra = 2 * h * math.sqrt(1 - (a_mid / amp) ** 2) / (math.pi * amp) if amp > a_mid else 0.0
    assert equivalent_conicity(t, amp) == pytest.approx(lam + extra, rel=5e-4, abs=1e-6)


# ----------------------------------------------------------------------------- the file format
def test_parse_a_good_file_mirrors_a_half_table():
    text = "# measured 2026-11-27, S1002 on 60E1 1:40\n\ny_mm, delta_r_mm ,delta_gamma_rad\n0,0,0\n2,0.4,0.01\n6,3.0,0.2\n"
    t = parse_csv(text, "pair.csv")
    assert t.y_mm == (-6.0, -2.0, 0.0, 2.0, 6.0)
    assert t.delta_r_mm == (-3.0, -0.4, 0.0, 0.4, 3.0)
    assert t.delta_gamma_rad == (-0.2, -0.01, 0.0, 0.01, 0.2)
    assert t.source == "pair.csv"
    assert check_table(t.to_dict()) == t  # stored and read back unchanged


@pytest.mark.parametrize("text,match", [
    ("y_mm,dr\n0,0\n1,1\n2,2\n", "line 1: missing column 'delta_r_mm'"),
    ("# c\ny_mm,delta_r_mm,foo\n0,0,0\n1,1,1\n2,2,2\n", "line 2: unknown or repeated column"),
    ("y_mm,delta_r_mm\n0,0\n2,0.5\n1.5,0.7\n3,1\n", "line 4: y_mm = 1.5 does not increase"),
    ("y_mm,delta_r_mm\n0,0\n2,0.5\n2,0.7\n", "line 4: y_mm = 2 does not increase"),
    ("y_mm,delta_r_mm\n0,0\n2,abc\n3,1\n", "line 3: field 'delta_r_mm': 'abc' is not a number"),
    ("y_mm,delta_r_mm\n0,0\n2,0.5\n80,1\n", "line 4: field 'y_mm' = 80.0 is outside [−30, 30] mm"),
    ("y_mm,delta_r_mm\n0,0\n2,0.5\n3,55\n", "line 4: field 'delta_r_mm' = 55.0 is outside"),
    ("y_mm,delta_r_mm\n0,0\n2,nan\n3,1\n", "line 3: field 'delta_r_mm' = nan is outside"),
    ("y_mm,delta_r_mm\n0,0\n2\n3,1\n", "line 3: 1 fields, the header has 2"),
    ("y_mm,delta_r_mm\n0,0\n2,1\n", "2 rows; at least 3"),
    ("y_mm,delta_r_mm\n1,0\n2,1\n3,2\n", "must cover y = 0"),
    ("# only a comment\n", "no header line"),
])
def test_bad_files_are_refused_naming_file_line_and_field(text, match):
    with pytest.raises(InvalidParameter) as exc:
        parse_csv(text, "worn.csv")
    assert str(exc.value).startswith("contact geometry file 'worn.csv'")
    assert match in str(exc.value)


# ----------------------------------------------------------------------------- the simulator
def _model_law(veh: VehicleModel) -> ContactTable:
    """The simulator's linear contact law (conicity + flange-root slope) written as a table."""
    return linear_table(veh["conicity"], 12.0, root_onset_mm=(veh["flange_clearance"] - FLANGE_ROOT_ONSET) * 1e3,
                        root_slope=LAMBDA_FLANGE_ROOT)


def test_a_table_of_the_linear_law_reproduces_the_conicity_run():
    """Straight track at 60 km/h on generated irregularities (the wheelsets reach the flange
    root at ≈ 6 mm): the table path and the conicity path give the same signals to rounding."""
    veh = VehicleModel("coach")
    sec = TrackSection("S", speed_kmh=60.0, radius_m=0.0, cant_mm=0.0, straight_in_m=400.0, transition_in_m=0.0,
                       curve_m=0.0, transition_out_m=0.0, straight_out_m=0.0, irregularity_level="low", seed=3)
    a = simulate_section(veh, sec, {})
    b = simulate_section(VehicleModel("coach", {"contact_geometry": _model_law(veh).to_dict()}), sec, {})
    for ch, x in a.channels.items():
        np.testing.assert_allclose(b.channels[ch], x, rtol=0, atol=1e-9 * max(1.0, float(np.max(np.abs(x)))),
                                   err_msg=ch)
    # a Δγ column equal to the template's contact-angle slope (2·ε/b0·y) changes nothing either
    t = _model_law(veh)
    eps = veh["contact_angle_parameter"] / veh["b0"]
    tg = ContactTable(t.y_mm, t.delta_r_mm, tuple(2 * eps * y * 1e-3 for y in t.y_mm), "with gamma")
    c = simulate_section(VehicleModel("coach", {"contact_geometry": tg.to_dict()}), sec, {})
    np.testing.assert_allclose(c.channels["Y_w1L"], a.channels["Y_w1L"], rtol=0, atol=1e-9 * 50)


def _free_wavelength(table: ContactTable | None, y0: float = 0.002, per_period: bool = False):
    """Kinematic wavelength of the leading free wheelset (as tests/test_sim_verification.py);
    ``per_period``: [(length of each period, its largest |y| in mm)]."""
    veh = VehicleModel("coach", {"contact_geometry": table.to_dict()} if table is not None else {})
    v = 5.0
    asm = assemble(veh, {}, v)
    _free_wheelsets(asm, rigid_bogie=False)
    asm.SC[K.Y_INIT] = y0
    sec = _flat(length=160.0, speed_kmh=v * 3.6)
    ss, st = run_assembled(asm, veh, sec, use_measured=True, states=True)
    y, dist = st[:, 0], ss.distance_m
    if not per_period:
        return _wavelength(y, dist)
    idx = np.nonzero((y[:-1] < 0) & (y[1:] >= 0))[0]
    xs = dist[idx] - y[idx] * (dist[idx + 1] - dist[idx]) / (y[idx + 1] - y[idx])
    return [(float(b - a), float(np.max(np.abs(y[i:j + 1]))) * 1e3)
            for a, b, i, j in zip(xs[:-1], xs[1:], idx[:-1], idx[1:], strict=True)]


def test_free_wheelset_on_a_table_follows_klingel_with_the_tables_conicity():
    """Klingel λ = 2π·sqrt(r0·b0/λe) (tolerance 1 % as in tests/test_sim_verification.py): a
    cone table of 0.3 gives the wavelength of 0.3, shorter than the template's 0.15; a nonlinear
    table (0.1 up to 1 mm, 0.4 beyond) released at 2 mm runs at the wavelength of the nonlinear
    pure-rolling equations (1 %), close to that of its equivalent conicity at 2 mm."""
    veh = VehicleModel("coach")
    klingel = lambda lam: 2 * math.pi * math.sqrt(veh["r0"] * veh["b0"] / lam)
    cone = check_table({"y_mm": [0.0, 6.0, 12.0], "delta_r_mm": [0.0, 3.6, 7.2]})  # Δr = 2·0.3·y
    got = _free_wavelength(cone)
    assert got == pytest.approx(klingel(0.3), rel=0.01)
    assert got < _free_wavelength(None)
    kinked = check_table({"y_mm": [0.0, 1.0, 12.0], "delta_r_mm": [0.0, 0.2, 0.2 + 0.8 * 11.0]})
    lam_e = equivalent_conicity(kinked, 2.0)
    assert 0.2 < lam_e < 0.4
    # the free wheelset's amplitude grows slowly (2 → 3 mm over 160 m): each period against the
    # pure-rolling wavelength at that period's amplitude
    periods = _free_wavelength(kinked, per_period=True)
    assert len(periods) >= 10
    for length, amp in periods:
        assert length == pytest.approx(_kinematic_wavelength(kinked, amp, veh["r0"] * veh["b0"]), rel=0.01)
    # a larger amplitude reaches more of the steep part: a shorter wavelength (a cone's does not change)
    assert periods[-1][0] < 0.95 * periods[0][0]
    # harmonic linearisation: near the wavelength of the equivalent conicity at that amplitude,
    # within the error of a one-harmonic approximation of a 1:4 kinked characteristic
    length, amp = periods[0]
    assert length == pytest.approx(klingel(equivalent_conicity(kinked, amp)), rel=0.08)


def _kinematic_wavelength(table: ContactTable, y0_mm: float, r0b0: float) -> float:
    """Wavelength of the pure-rolling wheelset y'' = −Δr(y)/(2·r0·b0) (Klingel's equations in
    distance, nonlinear Δr; Wickens 2003 ch. 2) released at y0 with ψ = 0: a quarter period is
    the distance to the first zero of y, integrated here with classical Runge–Kutta at 1 mm."""
    y_t = np.asarray(table.y_mm) * 1e-3
    dr_t = np.asarray(table.delta_r_mm) * 1e-3
    f = lambda y: -np.interp(y, y_t, dr_t) / (2 * r0b0)
    h, x, y, p = 1e-3, 0.0, y0_mm * 1e-3, 0.0
    while True:
        k1y, k1p = p, f(y)
        k2y, k2p = p + h / 2 * k1p, f(y + h / 2 * k1y)
        k3y, k3p = p + h / 2 * k2p, f(y + h / 2 * k2y)
        k4y, k4p = p + h * k3p, f(y + h * k3y)
        yn = y + h / 6 * (k1y + 2 * k2y + 2 * k3y + k4y)
        pn = p + h / 6 * (k1p + 2 * k2p + 2 * k3p + k4p)
        if yn <= 0.0:
            return 4 * (x + h * y / (y - yn))
        x, y, p = x + h, yn, pn


def test_conicity_effect_and_a_table_together_are_refused():
    veh = VehicleModel("coach", {"contact_geometry": _model_law(VehicleModel("coach")).to_dict()})
    with pytest.raises(InvalidParameter, match="effect 'conicity' and the measured profiles' table"):
        assemble(veh, {"conicity": {"conicity": 0.2}}, 20.0)
