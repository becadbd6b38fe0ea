"""The effect library: ONE registry of the physical effects a user can switch on in the built-in
simulator (docs/design.md §6), with parameters (unit, default, bounds), a plain-language explanation
and the EN 14363 quantities / zones / frequency bands each is expected to move.

``EFFECTS[id]`` is an :class:`Effect`; :func:`resolve_effects` checks a configuration's
``{effect id: {parameter: value}}`` dict and fills defaults. Unknown ids or parameters and
out-of-bounds values raise :class:`railval.core.errors.InvalidParameter` naming the effect, the
parameter, the bounds and the value.

How each effect enters the equations is in :mod:`railval.core.sim.model` (``_apply_effects``) and in
``docs/simulator.md``.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from typing import Any

from railval.core.errors import InvalidParameter
from railval.core.sim.params import Param, resolve

QUANTITY_IDS = ("Y_qst", "Q_qst", "YQ_qst", "SumY_qst", "Y_max", "Q_max", "YQ_max", "SumY_max",
                "ay_rms", "az_rms", "ay_max", "az_max")


@dataclass(frozen=True)
class Effect:
    """One switchable physical effect."""

    id: str
    title: str
    explanation: str
    parameters: dict[str, Param]
    quantities: tuple[str, ...]
    zones: tuple[int, ...]
    bands_hz: tuple[tuple[float, float], ...] = ()
    templates: tuple[str, ...] = ("coach", "wagon")
    calibration: str = "continuous"
    source: str = ""
    notes: str = ""
    extra: dict = field(default_factory=dict)
    #: what the effect needs from every section's layout record, as layout keys
    #: (``"irregularities"``: measured track geometry recorded with the campaign)
    requires_layout: tuple[str, ...] = ()
    #: the effect acts on the wheel–rail interface (contact, track under the wheel, wheelset
    #: steering): a contact difference no candidate models changes the same guiding forces, so
    #: the diagnosis needs support outside them (docs/diagnosis.md "Interface candidates")
    interface: bool = False
    #: layout keys whose presence makes the effect pointless (``"irregularities"``: the
    #: generated track's level is no candidate where measured track geometry exists)
    excludes_layout: tuple[str, ...] = ()
    #: the effect stands for an input of the simulation, not for the vehicle (``"track"``: the
    #: track irregularities; docs/diagnosis.md "Track input")
    input_side: str = ""
    #: parameter values at which the simulator computes exactly what it computes without the
    #: effect (bit for bit; core/sim/model.py: ``friction_damping`` and
    #: ``parasitic_yaw_stiffness`` enter as a force/stiffness read with default 0 when absent,
    #: ``track_level_*`` multiplies the generated irregularities by ``factor``, and 1.0·x = x):
    #: a diagnosis reuses the configuration's own simulation there (:func:`is_neutral`)
    neutral: dict[str, float] | None = None

    def to_dict(self) -> dict:
        return {"id": self.id, "title": self.title, "explanation": self.explanation,
                "parameters": {k: p.to_dict() for k, p in self.parameters.items()},
                "quantities": list(self.quantities), "zones": list(self.zones),
                "bands_hz": [list(b) for b in self.bands_hz], "templates": list(self.templates),
                "calibration": self.calibration, "source": self.source, "notes": self.notes}


def _p(*params: Param) -> dict[str, Param]:
    return {p.name: p for p in params}


_LIST = [
    Effect(
        "friction_damping", "Friction in the suspension (Coulomb / Saint-Venant)",
        "Dry friction in the secondary suspension (coach: vertical and lateral, e.g. sliding "
        "pads, side bearers, air-spring emergency rubbers; wagon: added to the native leaf-spring "
        "and link friction). Below the breakaway force the spring is locked and the car body "
        "rides on the stiffer friction element, so small high-frequency inputs pass to the car "
        "body: the car body accelerations rise, above all in the 2–10 Hz band, while large "
        "low-frequency motions are damped.",
        _p(Param("force_kN", "kN", 1.5, 0.0, 6.0, "breakaway friction force per spring (vertical and lateral)",
                 plausible=(0.0, 3.0),
                 plausible_source="assumption: dry friction of air-spring secondary suspensions (side bearers, "
                                  "emergency springs, sliding pads) of the order of 0.5–2 kN per spring; for the "
                                  "wagon it adds to the native 0.05–0.08 × static load of leaf springs and links")),
        ("ay_rms", "az_rms", "ay_max", "az_max"), (1, 2, 3, 4), ((2.0, 10.0),),
        source="Saint-Venant element (spring k_stick in series with a Coulomb slider); Iwnicki 2006 ch. 7",
        neutral={"force_kN": 0.0}),
    Effect(
        "damper_series_stiffness", "Damper with series stiffness (Maxwell element)",
        "Real hydraulic dampers sit on rubber end bushes and contain compressible oil, so each "
        "damper is a dashpot in series with a spring. Its effective damping falls and it acts "
        "more and more as a spring above the corner frequency k/(2πc). With a series stiffness of "
        "a few MN/m the yaw and lateral dampers pass less high-frequency force from the bogies "
        "to the car body: on good track at high speed the car body lateral accelerations and "
        "guiding-force peaks fall; on rougher track, where the yaw dampers' damping of the bogie "
        "matters more, the lateral accelerations can rise instead. Much lower series stiffness "
        "(≲ 1–2 MN/m, yaw damper corner frequency near the bogie's kinematic frequency) loses the "
        "yaw damping: guiding forces Y_max and ΣY_max rise at speed, and the vertical dampers "
        "lose their effect (car body vertical accelerations rise).",
        _p(Param("k_series_MN_m", "MN/m", 4.0, 0.2, 50.0, "series stiffness of every damper (yaw, lateral, vertical secondary)", scale="log",
                 plausible=(2.0, 20.0),
                 plausible_source="assumption of the order of magnitude of rubber end bushes plus oil "
                                  "compressibility (a few MN/m to ≈ 20 MN/m); Alonso & Giménez, VSD 2008 (yaw "
                                  "damper series stiffness); Polach & Böttcher 2014 §2 (damper models are a "
                                  "dashpot with series stiffness)")),
        ("ay_rms", "ay_max", "Y_max", "SumY_max", "az_rms", "az_max"), (1, 2, 3, 4), ((1.0, 10.0),), templates=("coach",),
        source="Maxwell element: effective damping c/(1 + (ωc/k)²) and stiffness k·(ωc/k)²/(1 + (ωc/k)²) "
               "(standard linear viscoelasticity); exact exponential update; yaw damper series "
               "stiffness in vehicle dynamics: Alonso & Giménez, VSD 2008; Polach & Böttcher 2014 §2. "
               "Directions of change measured with this simulator: tests/test_sim_effects.py"),
    Effect(
        "carbody_flexibility", "Car body first vertical bending mode",
        "The car body is not rigid: its first vertical bending mode (typically 8–12 Hz for a "
        "coach) is excited through the secondary suspension and shows in the car body vertical "
        "accelerations above the bogies as a peak near the bending frequency.",
        _p(Param("frequency_Hz", "Hz", 8.0, 5.0, 16.0, "first vertical bending frequency",
                 plausible=(7.0, 14.0),
                 plausible_source="first vertical bending of passenger car bodies 8–12 Hz (Carlbom, KTH "
                                  "thesis 2000); light modern car bodies down to ≈ 7 Hz (assumption)"),
           Param("damping_ratio", "-", 0.02, 0.005, 0.1, "modal damping ratio",
                 plausible=(0.01, 0.05),
                 plausible_source="structural damping of car bodies with interior 1–3 % (Carlbom 2000), "
                                  "up to 5 % assumed")),
        ("az_rms", "az_max"), (1, 2, 3, 4), ((5.0, 12.0),),
        source="free–free Euler–Bernoulli beam first mode (βL = 4.730), modal mass = car body mass"),
    Effect(
        "track_flexibility", "Vertical and lateral track stiffness and damping",
        "The rails are not rigid: they sit on pads, sleepers and ballast. A flexible track lets "
        "the wheelset move vertically on the track stiffness (changing the dynamic wheel forces) "
        "and each rail deflect laterally under its wheel's lateral force: the flange contact "
        "becomes softer (rail head and fastening deflection, dynamic gauge widening), the "
        "leading wheelset runs further out in tight curves and the guiding forces, Y/Q and ΣY "
        "change in zones 3–4.",
        _p(Param("k_vertical_MN_m", "MN/m", 40.0, 10.0, 300.0, "vertical track stiffness per wheel", scale="log",
                 plausible=(20.0, 200.0),
                 plausible_source="ballasted track on soft formation ≈ 20–40 MN/m per wheel, good ballasted "
                                  "track 50–100 MN/m, slab track up to ≈ 200 MN/m (Knothe & Grassie, VSD 22, "
                                  "1993, magnitudes; the limits are an assumption)"),
           Param("k_lateral_MN_m", "MN/m", 15.0, 1.5, 200.0, "lateral stiffness per rail (rail head, fastening, sleeper)", scale="log",
                 plausible=(5.0, 60.0),
                 plausible_source="assumption: lateral rail-head + fastening + sleeper stiffness per rail of "
                                  "the order of 10–50 MN/m (Knothe & Grassie 1993, magnitudes), lower on "
                                  "worn fastenings")),
        ("Y_max", "YQ_max", "SumY_max", "Q_max"), (3, 4), ((2.0, 20.0),),
        source="massless vertical track spring-damper per wheel (c = 50 kN·s/m, assumption); lateral "
               "track compliance counted once: each rail a massless spring k_rail deflecting under its "
               "wheel's tread force, the flange contact in series with k_rail; Knothe & Grassie, VSD "
               "22, 1993 (magnitudes)", interface=True),
    Effect(
        "wheel_rail_friction", "Wheel–rail friction coefficient",
        "The creep forces saturate at μ·Q. Measurements are often made on wet or contaminated "
        "rails with μ well below the dry value the model assumes; in small-radius curves the "
        "creep forces are saturated, so μ directly sets the lateral force of the inner wheels "
        "and the steering of the leading wheelset: guiding forces, ΣY and Y/Q change in zones 3–4.",
        _p(Param("mu", "-", 0.25, 0.1, 0.6, "friction coefficient",
                 plausible=(0.1, 0.5),
                 plausible_source="wet or contaminated rail 0.1–0.25, dry rail 0.3–0.5 (Iwnicki (ed.), "
                                  "Handbook of Railway Vehicle Dynamics, 2006, wheel–rail contact)")),
        ("Y_qst", "YQ_qst", "SumY_qst", "Y_max", "YQ_max", "SumY_max"), (3, 4), (),
        source="Shen, Hedrick & Elkins 1983 saturation of Kalker's linear creep forces", interface=True),
    Effect(
        "conicity", "Equivalent conicity of the measured (worn) profiles",
        "The model uses the nominal conicity of new profiles; the measured wheel and rail "
        "profiles give another equivalent conicity. Higher conicity shortens the kinematic "
        "wavelength (Klingel), raises the bogie's lateral activity and the car body lateral "
        "accelerations on straight track, and improves steering in curves.",
        _p(Param("conicity", "-", 0.35, 0.015, 0.6, "equivalent conicity", scale="log",
                 plausible=(0.02, 0.5),
                 plausible_source="EN 15302 equivalent conicity at 3 mm amplitude: new S1002/UIC60 1:40 "
                                  "≈ 0.05–0.2, worn wheel–rail pairs from ≈ 0.02 (flat tread cone 1:40 on a "
                                  "worn rail head) up to ≈ 0.4–0.5 (the limits are an assumption)")),
        ("ay_rms", "ay_max", "Y_max", "SumY_max", "Y_qst"), (1, 2, 3, 4), ((1.0, 6.0),),
        source="UIC 519 equivalent conicity; Klingel wavelength 2π·sqrt(r0·b0/λe)", interface=True),
    Effect(
        "measured_irregularities", "Measured instead of generated track irregularities",
        "The baseline model runs on random irregularities generated from a standard spectrum "
        "(ORE B176 low level): statistically plausible, but not the track the vehicle ran on. "
        "Switching to the measured irregularities of every section (recorded with the campaign) "
        "changes the accelerations and dynamic forces section by section; `scale` is the gain "
        "of the track recording (chord/transfer-function uncertainty) and is what calibration fits.",
        _p(Param("scale", "-", 1.0, 0.5, 1.5, "gain applied to the measured irregularities",
                 plausible=(0.9, 1.1),
                 plausible_source="assumption: amplitude uncertainty of track recording cars in the D1 band "
                                  "(chord transfer function, EN 13848-2 accuracy class) of the order of ±10 %")),
        ("ay_rms", "az_rms", "ay_max", "az_max", "Q_max", "Y_max", "YQ_max", "SumY_max"), (1, 2, 3, 4),
        ((0.4, 10.0),),
        source="layout['irregularities'] of each section (see docs/simulator.md)",
        requires_layout=("irregularities",)),
    *[Effect(
        f"track_level_{d}", f"Level of the generated track irregularities, {d}",
        f"A campaign without measured track geometry is simulated on irregularities generated from the "
        f"ORE B176 low-level spectrum. The real track may be rougher or smoother: `factor` scales the "
        f"amplitude of the generated {what} (the spectrum's shape kept). It moves the stochastic "
        f"quantities — r.m.s. and maxima of the accelerations, dynamic wheel forces — not the "
        f"quasi-static ones. Where it explains the residual the track input differs: supply measured "
        f"track geometry rather than tuning the vehicle.",
        _p(Param("factor", "-", 1.0, 0.3, 4.0, f"amplitude factor of the generated {what}", scale="log",
                 plausible=(0.5, 3.0),
                 plausible_source="ERRI B176 RP1 1989: the high level has 1.64 × the low level's amplitude; "
                                  "lines from well kept high-speed track to poorly kept secondary lines "
                                  "span about 0.5–3 × the low level (assumption)")),
        qs, (1, 2, 3, 4), ((0.4, 10.0),),
        source="ERRI B176 RP1 1989 spectra (core/sim/track.py), amplitude scaled per direction",
        excludes_layout=("irregularities",), input_side="track", neutral={"factor": 1.0})
      for d, what, qs in (("vertical", "vertical level and cross level",
                           ("az_rms", "az_max", "Q_max", "ay_rms", "ay_max")),
                          ("lateral", "alignment and gauge",
                           ("ay_rms", "ay_max", "Y_max", "YQ_max", "SumY_max")))],
    Effect(
        "parasitic_yaw_stiffness", "Bogie yaw resistance (parasitic yaw stiffness)",
        "Besides the secondary springs' shear, the bogie's rotation against the car body is "
        "resisted by traction rods, side bearers, damper bushes and cables. In a curve the bogie "
        "must turn by about (bogie distance / 2) / R against the car body; the resisting moment "
        "is reacted by the wheelsets as extra guiding force on the leading outer wheel: "
        "quasi-static Y, Y/Q and ΣY rise in small-radius curves (zones 3–4), much less elsewhere.",
        _p(Param("k_yaw_kNm_rad", "kN*m/rad", 600.0, 0.0, 3000.0, "yaw stiffness per bogie",
                 plausible=(0.0, 2000.0),
                 plausible_source="assumption: traction-rod rubber, side bearers, damper bushes and cables of "
                                  "an air-spring bogie, 0.1–2 MN·m/rad; Polach & Böttcher 2014 §2 name "
                                  "parasitic suspension stiffness an unknown the modellers must estimate")),
        ("Y_qst", "YQ_qst", "SumY_qst", "Y_max", "YQ_max", "SumY_max"), (3, 4), (),
        source="rotational spring between car body and bogie; Iwnicki 2006 ch. 7 (bogie yaw resistance)", interface=True,
        neutral={"k_yaw_kNm_rad": 0.0}),
    Effect(
        "lateral_bumpstop", "Secondary lateral clearance and bump stop",
        "The car body's lateral travel on the secondary suspension is limited by bump stops after "
        "a free clearance. With high cant deficiency the car body moves outward until it hits the "
        "stop: the lateral stiffness jumps, the car body lateral accelerations get peaks and the "
        "quasi-static lateral load shifts between the bogies.",
        _p(Param("clearance_mm", "mm", 20.0, 5.0, 60.0, "free lateral clearance",
                 plausible=(5.0, 60.0),
                 plausible_source="assumption: secondary lateral free play of coaches 20–40 mm, less with "
                                  "moved or worn stops; wagon link stops 5–30 mm"),
           Param("stiffness_kN_mm", "kN/mm", 1.0, 0.2, 10.0, "bump stop stiffness",
                 plausible=(0.5, 5.0),
                 plausible_source="assumption: progressive rubber bump stops, 0.5–5 kN/mm in their working "
                                  "range")),
        ("ay_max", "ay_rms", "Y_max", "SumY_max"), (2, 3, 4), ((0.4, 5.0),),
        source="piecewise-linear bump stop on the secondary lateral displacement"),
]

EFFECTS: dict[str, Effect] = {e.id: e for e in _LIST}
EFFECT_IDS: tuple[str, ...] = tuple(EFFECTS)


def is_neutral(effect: Effect, point: Mapping[str, float]) -> bool:
    """Whether the effect at parameter values ``point`` simulates exactly as without it
    (:attr:`Effect.neutral`; tests/test_effects_neutral.py compares the signals bit for bit)."""
    return effect.neutral is not None and all(
        k in point and float(point[k]) == float(v) for k, v in effect.neutral.items())


def get_effect(effect_id: str) -> Effect:
    try:
        return EFFECTS[effect_id]
    except KeyError:
        raise InvalidParameter(f"unknown effect id {effect_id!r}; known: {list(EFFECT_IDS)}") from None


def unmet_requirement(effect: Effect, layouts: Mapping[str, Mapping[str, Any] | None],
                      measured_quantities: Iterable[str] | None = None) -> str | None:
    """Why ``effect`` cannot apply to a campaign, in one line, or None when it can.

    ``layouts``: the layout record of every section (section id → dict); an effect that
    :attr:`Effect.requires_layout` a key needs it in every section (the simulator refuses a
    section without it). ``measured_quantities``: the EN 14363 quantity ids the campaign
    measures; an effect that moves none of them cannot be seen in its residual."""
    for key in effect.excludes_layout:
        having = sorted(sid for sid, lay in layouts.items() if (lay or {}).get(key))
        if layouts and len(having) == len(layouts):
            return (f"every section carries layout['{key}'] (measured track geometry): the simulator runs "
                    "on it with the measured_irregularities effect, the generated track's level is no candidate")
    for key in effect.requires_layout:
        missing = sorted(sid for sid, lay in layouts.items() if not (lay or {}).get(key))
        if missing:
            where = ", ".join(missing[:3]) + (" …" if len(missing) > 3 else "")
            return (f"needs layout['{key}'] in every section; {len(missing)} of {len(layouts)} sections "
                    f"carry none ({where})")
    if measured_quantities is not None:
        measured = set(measured_quantities)
        if not measured & set(effect.quantities):
            return f"moves {', '.join(effect.quantities)}, none of which the campaign measures"
    return None


def resolve_effects(effects: dict | None) -> dict[str, dict[str, float]]:
    """``{id: {param: value}}`` with defaults filled and every value checked against its bounds."""
    out: dict[str, dict[str, float]] = {}
    for eid, params in (effects or {}).items():
        e = get_effect(eid)
        if params is not None and not isinstance(params, dict):
            raise InvalidParameter(f"effect {eid!r}: parameters must be a mapping, got {params!r}")
        out[eid] = resolve(f"effect {eid!r}", tuple(e.parameters.values()), params)
    return out


def registry_dict() -> dict:
    """The registry as JSON-ready data (for the UI and ``--json`` outputs)."""
    return {eid: e.to_dict() for eid, e in EFFECTS.items()}
