"""Vehicle templates of the built-in simulator: a passenger ``coach`` and a two-axle freight
``wagon``.

Coach
-----
Car body (y, z, roll, pitch, yaw + first vertical bending mode when ``carbody_flexibility`` is
on), two bogie frames (y, z, roll, pitch, yaw), four wheelsets (lateral y and yaw; vertical and
roll follow the rail, or are free on the track springs with ``track_flexibility``). Primary and
secondary suspension with springs in x/y/z per side, vertical and lateral dampers, yaw dampers,
anti-roll bar.

Defaults marked **[MB]** are the Manchester Benchmark vehicle 1 defining values (Iwnicki S.,
*The Manchester Benchmarks for rail vehicle simulation*, Vehicle System Dynamics 30(3–4),
1998, as listed in docs/design.md §6): car body 32 000 kg, pitch inertia 1.97e6 kg·m², bogie
centres 19 m; bogie 2615 kg, pitch 1476 kg·m², wheelbase 2.56 m; wheelset 1813 kg; per
position primary vertical 1.2 MN/m and 4 kN·s/m, secondary vertical 430 kN/m and 20 kN·s/m.
Values marked **[MB?]** are ASSUMPTIONS believed to be the benchmark's further figures (car
body roll/yaw inertia, bogie roll/yaw inertia, primary x/y and secondary x/y stiffnesses,
wheel radius 0.46 m, contact distance 1.5 m, attachment spacings and heights) but not checked
against the paper here; values marked **[typ]** are ASSUMED typical engineering values for a
bogie coach (Iwnicki (ed.), *Handbook of Railway Vehicle Dynamics*, CRC 2006), notably the
yaw dampers, which the benchmark vehicle does not carry but every coach for > 160 km/h does.

Every parameter also carries a physically plausible range (``Param.plausible``) with its source
(``PLAUSIBLE_COACH`` / ``PLAUSIBLE_WAGON`` below): the range a real vehicle of the kind has,
narrower than the validation bounds; diagnosis uses it to flag implausible fitted values.

Wagon
-----
Two-axle freight wagon with UIC double-link suspension and parabolic/leaf springs (UIC 517):
car body (y, z, roll, pitch, yaw) directly on two wheelsets, wheelbase 9 m. Each leaf spring is
a vertical spring with Coulomb friction (native: friction coefficient × static spring load,
Saint-Venant element); the double links give a lateral and longitudinal pendulum stiffness
k = F_static / L_link with friction (Piotrowski J., *Smoothing dry friction damping by
kinematically excited oscillations and its effect on drag forces*, VSD 2003; Hecht M., *Ride
quality of freight wagons with double-link suspension*, 2001 — magnitudes only). Tare body
mass and payload are separate parameters; Q0 ≈ 93 kN (22.5 t/axle class, loaded) by default.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

from railval.core.errors import InvalidParameter
from railval.core.sim.params import Param, resolve
from railval.core.sim.profiles import ContactTable, check_table

#: the template parameter that carries a measured profile pair's Δr(y) table (not a scalar)
CONTACT_PARAMETER = "contact_geometry"

G = 9.81  #: gravitational acceleration, m/s²

#: the creep force law, the same for both templates (docs/simulator.md)
_CREEP_LAW: tuple[Param, ...] = (
    Param("creep_law", "-", 0.0, 0.0, 1.0,
          "creep force law: 0 = linear Kalker saturated by Shen-Hedrick-Elkins, 1 = Polach with reduction "
          "factors polach_kA, polach_kS (a different contact law; no diagnosis candidate changes it)",
          "Shen, Hedrick & Elkins 1983; Polach 2005 (Wear 258)"),
    Param("polach_kA", "-", 1.0, 0.1, 1.0, "Polach reduction factor in the adhesion area (creep_law = 1)",
          "Polach 2005 (Wear 258), dry rail"),
    Param("polach_kS", "-", 0.4, 0.05, 1.0, "Polach reduction factor in the slip area (creep_law = 1)",
          "Polach 2005 (Wear 258), dry rail"),
)

_COACH: tuple[Param, ...] = (
    Param("m_carbody", "kg", 32000.0, 15000.0, 70000.0, "car body mass", "[MB]"),
    Param("I_roll_carbody", "kg*m^2", 56800.0, 2e4, 2e5, "car body roll inertia", "[MB?] assumption"),
    Param("I_pitch_carbody", "kg*m^2", 1.97e6, 5e5, 5e6, "car body pitch inertia", "[MB]"),
    Param("I_yaw_carbody", "kg*m^2", 1.97e6, 5e5, 5e6, "car body yaw inertia", "[MB?] assumption"),
    Param("h_carbody", "m", 1.8, 1.0, 2.5, "car body centre of gravity height above rail", "[MB?] assumption"),
    Param("L_carbody", "m", 24.5, 18.0, 30.0, "car body length (for the bending mode shape)", "[typ] assumption"),
    Param("h_sensor", "m", 1.2, 0.8, 2.0, "car body accelerometer (floor) height above rail", "[typ] assumption"),
    Param("bogie_centres", "m", 19.0, 10.0, 22.0, "distance between bogie centres", "[MB]"),
    Param("m_bogie", "kg", 2615.0, 1500.0, 6000.0, "bogie frame mass", "[MB]"),
    Param("I_roll_bogie", "kg*m^2", 1722.0, 800.0, 5000.0, "bogie frame roll inertia", "[MB?] assumption"),
    Param("I_pitch_bogie", "kg*m^2", 1476.0, 800.0, 5000.0, "bogie frame pitch inertia", "[MB]"),
    Param("I_yaw_bogie", "kg*m^2", 3067.0, 1500.0, 8000.0, "bogie frame yaw inertia", "[MB?] assumption"),
    Param("h_bogie", "m", 0.6, 0.4, 0.9, "bogie frame centre of gravity height", "[MB?] assumption"),
    Param("wheelbase", "m", 2.56, 1.8, 3.2, "bogie wheelbase", "[MB]"),
    Param("m_wheelset", "kg", 1813.0, 1000.0, 2500.0, "wheelset mass", "[MB]"),
    Param("I_roll_wheelset", "kg*m^2", 1120.0, 600.0, 1600.0, "wheelset roll inertia", "[MB?] assumption"),
    Param("I_yaw_wheelset", "kg*m^2", 1120.0, 600.0, 1600.0, "wheelset yaw inertia", "[MB?] assumption"),
    Param("r0", "m", 0.46, 0.3, 0.55, "nominal rolling radius", "[MB?] assumption"),
    Param("b0", "m", 0.75, 0.7, 0.8, "half distance between contact points", "[MB?] assumption"),
    # primary suspension (per axle box)
    Param("k_primary_x", "N/m", 31.391e6, 1e6, 6e7, "primary longitudinal stiffness per axle box", "[MB?] assumption"),
    Param("k_primary_y", "N/m", 3.884e6, 5e5, 2e7, "primary lateral stiffness per axle box", "[MB?] assumption"),
    Param("k_primary_z", "N/m", 1.2e6, 4e5, 4e6, "primary vertical stiffness per axle box", "[MB]"),
    Param("c_primary_z", "N*s/m", 4.0e3, 0.0, 4e4, "primary vertical damping per axle box", "[MB]"),
    Param("b_primary", "m", 1.0, 0.8, 1.2, "lateral semi-spacing of the primary springs", "[MB?] assumption"),
    # secondary suspension (per air/coil spring, two per bogie)
    Param("k_secondary_x", "N/m", 160e3, 5e4, 1e6, "secondary longitudinal stiffness per spring", "[MB?] assumption"),
    Param("k_secondary_y", "N/m", 160e3, 5e4, 1e6, "secondary lateral stiffness per spring", "[MB?] assumption"),
    Param("k_secondary_z", "N/m", 430e3, 2e5, 1.5e6, "secondary vertical stiffness per spring", "[MB]"),
    Param("c_secondary_z", "N*s/m", 20e3, 0.0, 1e5, "secondary vertical damping per spring", "[MB]"),
    Param("c_secondary_y", "N*s/m", 32e3, 0.0, 1e5, "secondary lateral damper per bogie", "[typ] assumption"),
    Param("b_secondary", "m", 1.0, 0.8, 1.3, "lateral semi-spacing of the secondary springs", "[MB?] assumption"),
    Param("k_antiroll", "N*m/rad", 2.0e6, 0.0, 5e6, "anti-roll bar stiffness per bogie", "[typ] assumption"),
    Param("c_yaw_damper", "N*s/m", 250e3, 0.0, 8e5, "yaw damper damping (linearised) per damper", "[typ] assumption"),
    Param("b_yaw_damper", "m", 1.3, 1.0, 1.5, "lateral semi-spacing of the yaw dampers", "[typ] assumption"),
    Param("k_traction", "N/m", 5e6, 5e5, 5e7,
          "traction rod (longitudinal restraint car body - bogie) stiffness per bogie, at the secondary "
          "attachment height", "[typ] assumption"),
    Param("yaw_damper_blowoff", "N", 12e3, 2e3, 5e4,
          "yaw damper force limit (blow-off valve) per damper: force saturates at this value", "[typ] assumption"),
    # wheel–rail
    Param("conicity", "-", 0.15, 0.02, 0.6, "nominal equivalent conicity (new S1002 on UIC60 1:40)", "[typ] assumption"),
    Param("flange_clearance", "m", 0.007, 0.003, 0.012, "flangeway clearance per side", "[typ] assumption"),
    Param("k_flange", "N/m", 80e6, 5e6, 2e8, "lateral contact stiffness in flange contact", "[typ] assumption"),
    Param("contact_angle", "rad", 0.04, 0.0, 0.1, "tread contact angle at the centred position", "[typ] assumption"),
    Param("contact_angle_parameter", "-", 2.0, 0.0, 20.0,
          "Wickens contact angle parameter epsilon (gravitational stiffness W*eps/b0)", "[typ] assumption"),
    Param("kalker_c11", "-", 4.12, 3.0, 6.0, "Kalker coefficient C11 (a/b = 1, nu = 0.25)", "Kalker 1967 table"),
    Param("kalker_c22", "-", 3.67, 3.0, 6.0, "Kalker coefficient C22 (a/b = 1, nu = 0.25)", "Kalker 1967 table"),
    Param("contact_area", "m^2", 1.2e-4, 3e-5, 3e-4, "contact patch area pi*a*b at Q0 (Hertz)", "[typ] assumption"),
    Param("shear_modulus", "Pa", 8.0e10, 7e10, 9e10, "steel shear modulus G", "steel"),
    Param("mu_nominal", "-", 0.45, 0.1, 0.7, "friction coefficient used without the wheel_rail_friction effect", "[typ] assumption"),
    *_CREEP_LAW,
)

_WAGON: tuple[Param, ...] = (
    Param("m_body_tare", "kg", 10000.0, 5000.0, 20000.0, "empty car body mass", "[typ] assumption"),
    Param("payload", "kg", 25000.0, 0.0, 35000.0, "payload (0 = tare)", "[typ] assumption"),
    Param("h_carbody", "m", 1.5, 0.8, 2.5, "car body + payload centre of gravity height", "[typ] assumption"),
    Param("L_carbody", "m", 14.0, 10.0, 18.0, "car body length", "[typ] assumption"),
    Param("h_sensor", "m", 1.2, 0.8, 2.0, "accelerometer height above rail", "[typ] assumption"),
    Param("wheelbase", "m", 9.0, 6.0, 10.0, "wheelbase", "UIC 517 (max 9 m for 1:40 links)"),
    Param("m_wheelset", "kg", 1400.0, 1000.0, 2000.0, "wheelset mass incl. axle boxes", "[typ] assumption"),
    Param("I_roll_wheelset", "kg*m^2", 800.0, 500.0, 1500.0, "wheelset roll inertia", "[typ] assumption"),
    Param("I_yaw_wheelset", "kg*m^2", 800.0, 500.0, 1500.0, "wheelset yaw inertia", "[typ] assumption"),
    Param("r0", "m", 0.46, 0.3, 0.55, "nominal rolling radius", "[typ] assumption"),
    Param("b0", "m", 0.75, 0.7, 0.8, "half distance between contact points", "[typ] assumption"),
    Param("k_leaf_z", "N/m", 1.2e6, 3e5, 4e6, "leaf spring vertical stiffness per spring", "[typ] assumption"),
    Param("leaf_friction", "-", 0.08, 0.0, 0.3, "leaf spring friction coefficient (x static spring load)", "[typ] assumption"),
    Param("link_length", "m", 0.16, 0.05, 0.4, "effective double-link pendulum length, lateral", "[typ] assumption"),
    Param("link_length_x", "m", 0.04, 0.02, 0.4, "effective double-link pendulum length, longitudinal (estimate: keeps the loaded wagon stable below 100 km/h)", "[typ] assumption"),
    Param("link_friction", "-", 0.05, 0.0, 0.3, "double-link friction coefficient (x static spring load)", "[typ] assumption"),
    Param("b_spring", "m", 1.0, 0.8, 1.2, "lateral semi-spacing of the leaf springs", "UIC 517"),
    Param("conicity", "-", 0.15, 0.02, 0.6, "nominal equivalent conicity", "[typ] assumption"),
    Param("flange_clearance", "m", 0.007, 0.003, 0.012, "flangeway clearance per side", "[typ] assumption"),
    Param("k_flange", "N/m", 80e6, 5e6, 2e8, "lateral contact stiffness in flange contact", "[typ] assumption"),
    Param("contact_angle", "rad", 0.04, 0.0, 0.1, "tread contact angle at the centred position", "[typ] assumption"),
    Param("contact_angle_parameter", "-", 2.0, 0.0, 20.0, "Wickens contact angle parameter epsilon", "[typ] assumption"),
    Param("kalker_c11", "-", 4.12, 3.0, 6.0, "Kalker coefficient C11 (a/b = 1, nu = 0.25)", "Kalker 1967 table"),
    Param("kalker_c22", "-", 3.67, 3.0, 6.0, "Kalker coefficient C22 (a/b = 1, nu = 0.25)", "Kalker 1967 table"),
    Param("contact_area", "m^2", 1.4e-4, 3e-5, 3e-4, "contact patch area pi*a*b at Q0 (Hertz)", "[typ] assumption"),
    Param("shear_modulus", "Pa", 8.0e10, 7e10, 9e10, "steel shear modulus G", "steel"),
    Param("mu_nominal", "-", 0.45, 0.1, 0.7, "friction coefficient used without the wheel_rail_friction effect", "[typ] assumption"),
    *_CREEP_LAW,
)

_CAT = "assumption: typical range for European bogie passenger coaches (Iwnicki (ed.) 2006)"
_WAG = "assumption: typical range for two-axle UIC freight wagons (UIC 517; Iwnicki (ed.) 2006)"
_WR = "assumption: wheel–rail range for standard gauge S1002/UIC60 (EN 15302, Kalker 1967 tables)"

#: plausible (lower, upper, source) of every coach template parameter
PLAUSIBLE_COACH: dict[str, tuple[float, float, str]] = {
    "m_carbody": (25000.0, 45000.0, _CAT + "; MB vehicle 1: 32 t"),
    "I_roll_carbody": (3e4, 1.5e5, _CAT + " (m·(w² + h²)/12 of a 2.8 m × 3 m section)"),
    "I_pitch_carbody": (1.0e6, 3.0e6, _CAT + " (≈ m·L²/12); MB vehicle 1: 1.97e6"),
    "I_yaw_carbody": (1.0e6, 3.0e6, _CAT + " (≈ m·L²/12)"),
    "h_carbody": (1.4, 2.1, _CAT),
    "L_carbody": (22.0, 27.0, _CAT + " (UIC coaches 24.5–26.4 m)"),
    "h_sensor": (1.0, 1.4, _CAT + " (floor height)"),
    "bogie_centres": (15.0, 20.0, _CAT + "; MB vehicle 1: 19 m"),
    "m_bogie": (2000.0, 4000.0, _CAT + " (frame with secondary parts); MB vehicle 1: 2615 kg"),
    "I_roll_bogie": (1000.0, 3500.0, _CAT),
    "I_pitch_bogie": (1000.0, 3500.0, _CAT + "; MB vehicle 1: 1476 kg·m²"),
    "I_yaw_bogie": (1500.0, 5000.0, _CAT),
    "h_bogie": (0.5, 0.75, _CAT),
    "wheelbase": (2.3, 2.8, _CAT + "; MB vehicle 1: 2.56 m"),
    "m_wheelset": (1200.0, 2000.0, _CAT + " (with axle boxes and discs); MB vehicle 1: 1813 kg"),
    "I_roll_wheelset": (700.0, 1400.0, _CAT),
    "I_yaw_wheelset": (700.0, 1400.0, _CAT),
    "r0": (0.42, 0.5, "wheel diameter 840–1000 mm, new to worn (UIC 510-2)"),
    "b0": (0.745, 0.76, "standard gauge: contact points ≈ 1.5 m apart (EN 13715 / EN 13674-1 geometry)"),
    "k_primary_x": (5e6, 5e7, _CAT + " (guidance bushes, steering vs stability)"),
    "k_primary_y": (2e6, 1.5e7, _CAT),
    "k_primary_z": (6e5, 2.0e6, _CAT + "; MB vehicle 1: 1.2 MN/m"),
    "c_primary_z": (2e3, 2e4, _CAT + "; MB vehicle 1: 4 kN·s/m"),
    "b_primary": (0.95, 1.1, _CAT),
    "k_secondary_x": (1e5, 3e5, _CAT + " (air-spring shear)"),
    "k_secondary_y": (1e5, 3e5, _CAT + " (air-spring shear)"),
    "k_secondary_z": (2.5e5, 8e5, _CAT + "; MB vehicle 1: 430 kN/m"),
    "c_secondary_z": (1e4, 5e4, _CAT + "; MB vehicle 1: 20 kN·s/m"),
    "c_secondary_y": (1e4, 6e4, _CAT),
    "b_secondary": (0.9, 1.1, _CAT),
    "k_antiroll": (5e5, 3e6, _CAT),
    "c_yaw_damper": (1e5, 5e5, _CAT + " (linearised, per damper, > 160 km/h)"),
    "b_yaw_damper": (1.2, 1.4, _CAT),
    "k_traction": (2e6, 2e7, _CAT + " (traction rod with rubber bushes)"),
    "yaw_damper_blowoff": (6e3, 2e4, _CAT + " (yaw damper force limit per damper)"),
    "conicity": (0.03, 0.5, _WR),
    "flange_clearance": (0.004, 0.01, _WR + " (gauge 1435 mm, wheelset back-to-back 1360 mm)"),
    "k_flange": (3e7, 1.5e8, _WR + " (Hertzian flange contact + rail head bending)"),
    "contact_angle": (0.02, 0.06, _WR + " (1:40 rail inclination, tread slope)"),
    "contact_angle_parameter": (0.5, 20.0, _WR + " (Wickens ε: 0 for cones, large for worn profiles)"),
    "kalker_c11": (3.5, 5.0, "Kalker 1967 tables, a/b 0.5–2, ν = 0.25"),
    "kalker_c22": (3.0, 4.5, "Kalker 1967 tables, a/b 0.5–2, ν = 0.25"),
    "contact_area": (6e-5, 2e-4, "Hertz contact area of a 50–60 kN wheel load on S1002/UIC60 (assumption)"),
    "shear_modulus": (7.9e10, 8.2e10, "wheel and rail steel"),
    "mu_nominal": (0.3, 0.5, "dry rail (Iwnicki (ed.) 2006, wheel–rail contact)"),
    "creep_law": (0.0, 1.0, "either law is a physical contact model (Shen, Hedrick & Elkins 1983; Polach 2005)"),
    "polach_kA": (0.3, 1.0, "Polach 2005 (Wear 258): kA 1 on dry rail, lower with contamination"),
    "polach_kS": (0.1, 1.0, "Polach 2005 (Wear 258): kS 0.4 on dry rail, lower with contamination"),
}

#: plausible (lower, upper, source) of every wagon template parameter
PLAUSIBLE_WAGON: dict[str, tuple[float, float, str]] = {
    "m_body_tare": (7000.0, 14000.0, _WAG),
    "payload": (0.0, 30000.0, _WAG + " (22.5 t axle load class)"),
    "h_carbody": (1.0, 2.2, _WAG),
    "L_carbody": (10.0, 16.0, _WAG),
    "h_sensor": (1.0, 1.4, _WAG),
    "wheelbase": (6.0, 9.0, "UIC 517 (max 9 m for 1:40 links)"),
    "m_wheelset": (1200.0, 1600.0, _WAG),
    "I_roll_wheelset": (600.0, 1000.0, _WAG),
    "I_yaw_wheelset": (600.0, 1000.0, _WAG),
    "r0": (0.42, 0.5, "wheel diameter 840–1000 mm, new to worn (UIC 510-2)"),
    "b0": (0.745, 0.76, "standard gauge: contact points ≈ 1.5 m apart"),
    "k_leaf_z": (6e5, 2.5e6, _WAG + " (parabolic/leaf springs, loaded)"),
    "leaf_friction": (0.04, 0.15, _WAG + " (leaf spring friction 4–15 % of the load)"),
    "link_length": (0.1, 0.3, _WAG + " (effective double-link pendulum)"),
    "link_length_x": (0.03, 0.2, _WAG + " (effective double-link pendulum)"),
    "link_friction": (0.02, 0.1, _WAG),
    "b_spring": (0.95, 1.05, "UIC 517 leaf spring spacing"),
    "conicity": (0.03, 0.5, _WR),
    "flange_clearance": (0.004, 0.01, _WR),
    "k_flange": (3e7, 1.5e8, _WR),
    "contact_angle": (0.02, 0.06, _WR),
    "contact_angle_parameter": (0.5, 20.0, _WR),
    "kalker_c11": (3.5, 5.0, "Kalker 1967 tables, a/b 0.5–2, ν = 0.25"),
    "kalker_c22": (3.0, 4.5, "Kalker 1967 tables, a/b 0.5–2, ν = 0.25"),
    "contact_area": (8e-5, 2.5e-4, "Hertz contact area of an 80–110 kN wheel load (assumption)"),
    "shear_modulus": (7.9e10, 8.2e10, "wheel and rail steel"),
    "mu_nominal": (0.3, 0.5, "dry rail (Iwnicki (ed.) 2006, wheel–rail contact)"),
    "creep_law": (0.0, 1.0, "either law is a physical contact model (Shen, Hedrick & Elkins 1983; Polach 2005)"),
    "polach_kA": (0.3, 1.0, "Polach 2005 (Wear 258): kA 1 on dry rail, lower with contamination"),
    "polach_kS": (0.1, 1.0, "Polach 2005 (Wear 258): kS 0.4 on dry rail, lower with contamination"),
}


def _with_plausible(params: tuple[Param, ...], table: dict) -> tuple[Param, ...]:
    missing = {p.name for p in params} ^ set(table)
    if missing:
        raise ValueError(f"plausible ranges missing or unknown for {sorted(missing)}")
    return tuple(replace(p, plausible=table[p.name][:2], plausible_source=table[p.name][2]) for p in params)


_COACH = _with_plausible(_COACH, PLAUSIBLE_COACH)
_WAGON = _with_plausible(_WAGON, PLAUSIBLE_WAGON)

TEMPLATES: dict[str, tuple[Param, ...]] = {"coach": _COACH, "wagon": _WAGON}
TEMPLATE_KIND = {"coach": "passenger", "wagon": "freight"}


@dataclass
class VehicleModel:
    """A vehicle template with (checked) parameter values.

    ``VehicleModel("coach", {"m_carbody": 35000})``; unknown names or out-of-bounds values raise
    :class:`railval.core.errors.InvalidParameter`.
    """

    template: str = "coach"
    parameters: dict[str, float] = field(default_factory=dict)
    #: the measured profiles' contact geometry (template parameter ``contact_geometry``, a
    #: table: :mod:`railval.core.sim.profiles`); ``None``: the linear conicity
    contact: ContactTable | None = None

    def __post_init__(self):
        if self.template not in TEMPLATES:
            raise InvalidParameter(f"vehicle template {self.template!r} is unknown; known: {sorted(TEMPLATES)}")
        params = dict(self.parameters)
        table = params.pop(CONTACT_PARAMETER, None)
        if table is not None:
            self.contact = table if isinstance(table, ContactTable) else check_table(table, CONTACT_PARAMETER)
        self.parameters = resolve(f"vehicle template {self.template!r}", TEMPLATES[self.template], params)

    @classmethod
    def from_any(cls, obj, overrides: dict | None = None) -> VehicleModel:
        """From a :class:`VehicleModel`, a db vehicle record ``{template, parameters, ...}`` or a
        template name; ``overrides`` (e.g. ``model.NAME`` calibration values) win."""
        if isinstance(obj, VehicleModel):
            tmpl, params = obj.template, dict(obj.parameters)
            if obj.contact is not None:
                params[CONTACT_PARAMETER] = obj.contact
        elif isinstance(obj, str):
            tmpl, params = obj, {}
        else:
            get = obj.get if hasattr(obj, "get") else (lambda k, d=None: getattr(obj, k, d))
            tmpl = template_for(obj)
            params = dict(get("parameters") or {})
        params.update({k.removeprefix("model."): v for k, v in (overrides or {}).items()})
        return cls(str(tmpl), params)

    def __getitem__(self, name: str) -> float:
        return self.parameters[name]

    @property
    def kind(self) -> str:
        return TEMPLATE_KIND[self.template]

    @property
    def n_bogies(self) -> int:
        return 2 if self.template == "coach" else 0

    @property
    def n_wheelsets(self) -> int:
        return 4 if self.template == "coach" else 2

    def masses(self) -> dict[str, float]:
        """Car body, bogie and wheelset masses in kg."""
        p = self.parameters
        if self.template == "coach":
            return {"carbody": p["m_carbody"], "bogie": p["m_bogie"], "wheelset": p["m_wheelset"]}
        return {"carbody": p["m_body_tare"] + p["payload"], "bogie": 0.0, "wheelset": p["m_wheelset"]}

    def total_mass(self) -> float:
        m = self.masses()
        return m["carbody"] + self.n_bogies * m["bogie"] + self.n_wheelsets * m["wheelset"]

    def q0_kN(self) -> float:
        """Static vertical wheel force Q0 = M·g / (2·n_wheelsets) in kN (symmetric vehicle)."""
        return self.total_mass() * G / (2 * self.n_wheelsets) / 1000.0

    def wheelset_x(self) -> list[float]:
        """Longitudinal positions of the wheelsets relative to the car body centre (m, + = forward),
        leading first."""
        p = self.parameters
        if self.template == "coach":
            c, a = p["bogie_centres"] / 2, p["wheelbase"] / 2
            return [c + a, c - a, -c + a, -c - a]
        a = p["wheelbase"] / 2
        return [a, -a]

    def sensor_x(self) -> list[float]:
        """Car body sensor positions (above bogie 1/2, or above the wheelsets for the wagon)."""
        if self.template == "coach":
            c = self.parameters["bogie_centres"] / 2
            return [c, -c]
        a = self.parameters["wheelbase"] / 2
        return [a, -a]

    def to_dict(self) -> dict:
        return {"template": self.template, "kind": self.kind, "parameters": dict(self.parameters),
                "Q0_kN": self.q0_kN(), "total_mass_kg": self.total_mass()}


def template_parameters(template: str) -> tuple[Param, ...]:
    if template not in TEMPLATES:
        raise InvalidParameter(f"vehicle template {template!r} is unknown; known: {sorted(TEMPLATES)}")
    return TEMPLATES[template]


def unknown_parameters(template: str, names) -> list[str]:
    """The names among ``names`` that are not parameters of vehicle template ``template``
    (the contact-geometry table counts as one; docs/simulator.md "Contact geometry as data")."""
    known = {p.name for p in template_parameters(template)} | {CONTACT_PARAMETER}
    return sorted(str(n) for n in names if str(n).removeprefix("model.") not in known)


def template_for(vehicle) -> str:
    """The template the built-in simulator uses for a vehicle record: its ``template``, else
    ``wagon`` for freight and ``coach`` otherwise (as :meth:`VehicleModel.from_any`)."""
    get = vehicle.get if hasattr(vehicle, "get") else (lambda k, d=None: getattr(vehicle, k, d))
    return str(get("template") or ("wagon" if get("kind") == "freight" else "coach"))
