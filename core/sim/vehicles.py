"""Vehicle templates of the built-in simulator: a passenger ``coach`` and a two-axle freight
``wagon``.

Coach
-----
Car body (y, z, roll, pitch, yaw + first vertical bending mode when ``carbody_flexibility`` is
on), two bogie frames (y, z, roll, pitch, yaw), four wheelsets (lateral y and yaw; vertical and
roll follow the rail, or are free on the track springs with ``track_flexibility``). Primary and
secondary suspension with springs in x/y/z per side, vertical and lateral dampers, yaw dampers,
anti-roll bar.

Defaults marked **[MB]** are the Manchester Benchmark vehicle 1 values quoted in docs/design.md §6
(Iwnicki S., *The Manchester Benchmarks for rail vehicle simulation*, Vehicle System Dynamics
30(3–4), 1998): car body 32 000 kg, pitch inertia 1.97e6 kg·m², bogie centres 19 m; bogie
2615 kg, pitch 1476 kg·m², wheelbase 2.56 m; wheelset 1813 kg; primary 1.2 MN/m and 4 kN·s/m,
secondary 430 kN/m and 20 kN·s/m vertically per position. Values marked **[MB*]** are the
benchmark's published figures as the author recalls them (car body roll/yaw inertia, bogie
roll/yaw inertia, primary x/y and secondary x/y stiffnesses, wheel radius 0.46 m, contact
distance 1.5 m); values marked **[typ]** are typical engineering values for a bogie coach
(Iwnicki (ed.), *Handbook of Railway Vehicle Dynamics*, CRC 2006, ch. 4 and 7), notably the yaw
dampers, which the benchmark vehicle does not carry but every coach for > 160 km/h does.

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

from dataclasses import dataclass, field

from railval.core.errors import InvalidParameter
from railval.core.sim.params import Param, resolve

G = 9.81  #: gravitational acceleration, m/s²

_COACH: tuple[Param, ...] = (
    Param("m_carbody", "kg", 32000.0, 15000.0, 70000.0, "car body mass", "[MB]"),
    Param("I_roll_carbody", "kg*m^2", 56800.0, 2e4, 2e5, "car body roll inertia", "[MB*]"),
    Param("I_pitch_carbody", "kg*m^2", 1.97e6, 5e5, 5e6, "car body pitch inertia", "[MB]"),
    Param("I_yaw_carbody", "kg*m^2", 1.97e6, 5e5, 5e6, "car body yaw inertia", "[MB*]"),
    Param("h_carbody", "m", 1.8, 1.0, 2.5, "car body centre of gravity height above rail", "[MB*]"),
    Param("L_carbody", "m", 24.5, 18.0, 30.0, "car body length (for the bending mode shape)", "[typ]"),
    Param("h_sensor", "m", 1.2, 0.8, 2.0, "car body accelerometer (floor) height above rail", "[typ]"),
    Param("bogie_centres", "m", 19.0, 10.0, 22.0, "distance between bogie centres", "[MB]"),
    Param("m_bogie", "kg", 2615.0, 1500.0, 6000.0, "bogie frame mass", "[MB]"),
    Param("I_roll_bogie", "kg*m^2", 1722.0, 800.0, 5000.0, "bogie frame roll inertia", "[MB*]"),
    Param("I_pitch_bogie", "kg*m^2", 1476.0, 800.0, 5000.0, "bogie frame pitch inertia", "[MB]"),
    Param("I_yaw_bogie", "kg*m^2", 3067.0, 1500.0, 8000.0, "bogie frame yaw inertia", "[MB*]"),
    Param("h_bogie", "m", 0.6, 0.4, 0.9, "bogie frame centre of gravity height", "[MB*]"),
    Param("wheelbase", "m", 2.56, 1.8, 3.2, "bogie wheelbase", "[MB]"),
    Param("m_wheelset", "kg", 1813.0, 1000.0, 2500.0, "wheelset mass", "[MB]"),
    Param("I_roll_wheelset", "kg*m^2", 1120.0, 600.0, 1600.0, "wheelset roll inertia", "[MB*]"),
    Param("I_yaw_wheelset", "kg*m^2", 1120.0, 600.0, 1600.0, "wheelset yaw inertia", "[MB*]"),
    Param("r0", "m", 0.46, 0.3, 0.55, "nominal rolling radius", "[MB*]"),
    Param("b0", "m", 0.75, 0.7, 0.8, "half distance between contact points", "[MB*]"),
    # primary suspension (per axle box)
    Param("k_primary_x", "N/m", 31.391e6, 1e6, 6e7, "primary longitudinal stiffness per axle box", "[MB*]"),
    Param("k_primary_y", "N/m", 3.884e6, 5e5, 2e7, "primary lateral stiffness per axle box", "[MB*]"),
    Param("k_primary_z", "N/m", 1.22e6, 4e5, 4e6, "primary vertical stiffness per axle box", "[MB]"),
    Param("c_primary_z", "N*s/m", 4.0e3, 0.0, 4e4, "primary vertical damping per axle box", "[MB]"),
    Param("b_primary", "m", 1.0, 0.8, 1.2, "lateral semi-spacing of the primary springs", "[MB*]"),
    # secondary suspension (per air/coil spring, two per bogie)
    Param("k_secondary_x", "N/m", 160e3, 5e4, 1e6, "secondary longitudinal stiffness per spring", "[MB*]"),
    Param("k_secondary_y", "N/m", 160e3, 5e4, 1e6, "secondary lateral stiffness per spring", "[MB*]"),
    Param("k_secondary_z", "N/m", 430e3, 2e5, 1.5e6, "secondary vertical stiffness per spring", "[MB]"),
    Param("c_secondary_z", "N*s/m", 20e3, 0.0, 1e5, "secondary vertical damping per spring", "[MB]"),
    Param("c_secondary_y", "N*s/m", 32e3, 0.0, 1e5, "secondary lateral damper per bogie", "[typ]"),
    Param("b_secondary", "m", 1.0, 0.8, 1.3, "lateral semi-spacing of the secondary springs", "[MB*]"),
    Param("k_antiroll", "N*m/rad", 2.0e6, 0.0, 5e6, "anti-roll bar stiffness per bogie", "[typ]"),
    Param("c_yaw_damper", "N*s/m", 250e3, 0.0, 8e5, "yaw damper damping (linearised) per damper", "[typ]"),
    Param("b_yaw_damper", "m", 1.3, 1.0, 1.5, "lateral semi-spacing of the yaw dampers", "[typ]"),
    # wheel–rail
    Param("conicity", "-", 0.15, 0.02, 0.6, "nominal equivalent conicity (new S1002 on UIC60 1:40)", "[typ]"),
    Param("flange_clearance", "m", 0.007, 0.003, 0.012, "flangeway clearance per side", "[typ]"),
    Param("k_flange", "N/m", 80e6, 5e6, 2e8, "lateral contact stiffness in flange contact", "[typ]"),
    Param("contact_angle", "rad", 0.04, 0.0, 0.1, "tread contact angle at the centred position", "[typ]"),
    Param("contact_angle_parameter", "-", 2.0, 0.0, 20.0,
          "Wickens contact angle parameter epsilon (gravitational stiffness W*eps/b0)", "[typ]"),
    Param("kalker_c11", "-", 4.12, 3.0, 6.0, "Kalker coefficient C11 (a/b = 1, nu = 0.25)", "Kalker 1967 table"),
    Param("kalker_c22", "-", 3.67, 3.0, 6.0, "Kalker coefficient C22 (a/b = 1, nu = 0.25)", "Kalker 1967 table"),
    Param("contact_area", "m^2", 1.2e-4, 3e-5, 3e-4, "contact patch area pi*a*b at Q0 (Hertz)", "[typ]"),
    Param("shear_modulus", "Pa", 8.0e10, 7e10, 9e10, "steel shear modulus G", "steel"),
    Param("mu_nominal", "-", 0.45, 0.1, 0.7, "friction coefficient used without the wheel_rail_friction effect", "[typ]"),
)

_WAGON: tuple[Param, ...] = (
    Param("m_body_tare", "kg", 10000.0, 5000.0, 20000.0, "empty car body mass", "[typ]"),
    Param("payload", "kg", 25000.0, 0.0, 35000.0, "payload (0 = tare)", "[typ]"),
    Param("h_carbody", "m", 1.5, 0.8, 2.5, "car body + payload centre of gravity height", "[typ]"),
    Param("L_carbody", "m", 14.0, 10.0, 18.0, "car body length", "[typ]"),
    Param("h_sensor", "m", 1.2, 0.8, 2.0, "accelerometer height above rail", "[typ]"),
    Param("wheelbase", "m", 9.0, 6.0, 10.0, "wheelbase", "UIC 517 (max 9 m for 1:40 links)"),
    Param("m_wheelset", "kg", 1400.0, 1000.0, 2000.0, "wheelset mass incl. axle boxes", "[typ]"),
    Param("I_roll_wheelset", "kg*m^2", 800.0, 500.0, 1500.0, "wheelset roll inertia", "[typ]"),
    Param("I_yaw_wheelset", "kg*m^2", 800.0, 500.0, 1500.0, "wheelset yaw inertia", "[typ]"),
    Param("r0", "m", 0.46, 0.3, 0.55, "nominal rolling radius", "[typ]"),
    Param("b0", "m", 0.75, 0.7, 0.8, "half distance between contact points", "[typ]"),
    Param("k_leaf_z", "N/m", 1.2e6, 3e5, 4e6, "leaf spring vertical stiffness per spring", "[typ]"),
    Param("leaf_friction", "-", 0.08, 0.0, 0.3, "leaf spring friction coefficient (x static spring load)", "[typ]"),
    Param("link_length", "m", 0.16, 0.05, 0.4, "effective double-link pendulum length, lateral", "[typ]"),
    Param("link_length_x", "m", 0.04, 0.02, 0.4, "effective double-link pendulum length, longitudinal (estimate: keeps the loaded wagon stable below 100 km/h)", "[typ]"),
    Param("link_friction", "-", 0.05, 0.0, 0.3, "double-link friction coefficient (x static spring load)", "[typ]"),
    Param("b_spring", "m", 1.0, 0.8, 1.2, "lateral semi-spacing of the leaf springs", "UIC 517"),
    Param("conicity", "-", 0.15, 0.02, 0.6, "nominal equivalent conicity", "[typ]"),
    Param("flange_clearance", "m", 0.007, 0.003, 0.012, "flangeway clearance per side", "[typ]"),
    Param("k_flange", "N/m", 80e6, 5e6, 2e8, "lateral contact stiffness in flange contact", "[typ]"),
    Param("contact_angle", "rad", 0.04, 0.0, 0.1, "tread contact angle at the centred position", "[typ]"),
    Param("contact_angle_parameter", "-", 2.0, 0.0, 20.0, "Wickens contact angle parameter epsilon", "[typ]"),
    Param("kalker_c11", "-", 4.12, 3.0, 6.0, "Kalker coefficient C11 (a/b = 1, nu = 0.25)", "Kalker 1967 table"),
    Param("kalker_c22", "-", 3.67, 3.0, 6.0, "Kalker coefficient C22 (a/b = 1, nu = 0.25)", "Kalker 1967 table"),
    Param("contact_area", "m^2", 1.4e-4, 3e-5, 3e-4, "contact patch area pi*a*b at Q0 (Hertz)", "[typ]"),
    Param("shear_modulus", "Pa", 8.0e10, 7e10, 9e10, "steel shear modulus G", "steel"),
    Param("mu_nominal", "-", 0.45, 0.1, 0.7, "friction coefficient used without the wheel_rail_friction effect", "[typ]"),
)

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

    def __post_init__(self):
        if self.template not in TEMPLATES:
            raise InvalidParameter(f"vehicle template {self.template!r} is unknown; known: {sorted(TEMPLATES)}")
        self.parameters = resolve(f"vehicle template {self.template!r}", TEMPLATES[self.template],
                                  self.parameters)

    @classmethod
    def from_any(cls, obj, overrides: dict | None = None) -> VehicleModel:
        """From a :class:`VehicleModel`, a db vehicle record ``{template, parameters, ...}`` or a
        template name; ``overrides`` (e.g. ``model.NAME`` calibration values) win."""
        if isinstance(obj, VehicleModel):
            tmpl, params = obj.template, dict(obj.parameters)
        elif isinstance(obj, str):
            tmpl, params = obj, {}
        else:
            get = obj.get if hasattr(obj, "get") else (lambda k, d=None: getattr(obj, k, d))
            tmpl = get("template") or ("wagon" if get("kind") == "freight" else "coach")
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
