"""Assembly of the simulator's arrays from a vehicle template, a section and effects, and the
public simulation API (:func:`simulate_section`, :func:`simulate_campaign`).

Wheel–rail contact (per wheel, :mod:`railval.core.sim.kernel`)
-----------------------------------------------------
* Rolling radius difference from the equivalent conicity λe (UIC 519): r_L − r0 = λe·y_rel, plus
  a flange-root term 1.5·(y_rel − g/2 − (clearance − 2 mm)) beyond it (steeper radius growth of
  real profiles near the flange).
* Creepages (Kalker; Iwnicki 2006 ch. 7): ξx,L = −Δr_L/r0 − b0·ψ̇/v − b0·κ,
  ξx,R = −Δr_R/r0 + b0·ψ̇/v + b0·κ, ξy = ẏ/v − ψ (spin neglected).
* Linear creep forces F = −f·ξ with f11 = G·c²·C11, f22 = G·c²·C22, c² = a·b = area/π at Q0
  (Kalker 1967, C11 = 4.12, C22 = 3.67 for a/b = 1, ν = 0.25), scaled with (Q/Q0)^(2/3) (Hertz),
  saturated at μ·Q (Shen, Hedrick & Elkins 1983); with the template parameter ``creep_law`` = 1
  Polach's law instead (Polach 2005, reduction factors kA, kS: initial slope (kA + kS)/2 of
  Kalker's, a smoother approach to μQ) — a second contact law the trust bench's truth uses.
* Lateral component of the normal force (gravitational stiffness): Y_n,L = −Q_L·(γ0 + e·y_rel),
  Y_n,R = +Q_R·(γ0 − e·y_rel), e = ε/b0 with Wickens' contact angle parameter ε, so the
  wheelset's gravitational stiffness is W·ε/b0 (Wickens, *Fundamentals of rail vehicle
  dynamics*, 2003, ch. 2).
* Measured profiles (template parameter ``contact_geometry``, :mod:`railval.core.sim.profiles`):
  Δr(y_rel) interpolated linearly in the EN 15302 table replaces 2·λe·y_rel and the flange-root
  term, r_L − r0 = Δr/2 = −(r_R − r0); a Δγ column replaces 2·e·y_rel in the normal forces.
* Flange contact: lateral spring k_flange beyond the clearance (+ half the gauge deviation).
* Rigid track: wheelset vertical position and roll follow the rail (level ± cross level/2);
  Q_L + Q_R and Q_L − Q_R follow from the wheelset's vertical and roll equilibrium including the
  moment r0·ΣY of the lateral contact forces.
* Quasi-static acceleration in the track plane a_q = v²·κ − g·h/s (s = 1500 mm) acts on every
  body as a pseudo-force −m·a_q; an accelerometer measures ÿ + a_q + g·φ_body.
"""

from __future__ import annotations

import math
import multiprocessing as mp
import os
import threading
from collections.abc import Mapping, Sequence
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass, field

import numpy as np

from railval.core.errors import InvalidParameter
from railval.core.sim import kernel as K
from railval.core.sim.effects import resolve_effects
from railval.core.sim.track import DS, TrackSection
from railval.core.sim.vehicles import G, VehicleModel
from railval.core.types import SignalSet
from railval.core.workers import pool_kwargs

H_SECONDARY = 0.9  # m above rail: secondary spring / yaw damper attachment height (coach)
H_LEAF = 0.8  # m above rail: leaf spring attachment (wagon)
LAMBDA_FLANGE_ROOT = 1.5  # additional rolling-radius slope near the flange (-)
FLANGE_ROOT_ONSET = 0.002  # m before flange contact where the flange-root term starts
TRACK_CZ = 50e3  # N*s/m per wheel, vertical track damping (track_flexibility; assumption)
K_STICK_Z = 2.0e6  # N/m stick stiffness of the vertical friction element (coach)
K_STICK_Y = 1.0e6  # N/m stick stiffness of the lateral friction element (coach)
BETA_L, SIGMA_FF = 4.730040745, 0.982502215  # free–free beam, first bending mode


def bending_mode_shape(x: np.ndarray | float, length: float) -> np.ndarray:
    """First free–free Euler–Bernoulli bending mode at ``x`` (m from the centre), normalised so
    that the mean of φ² over the length is 1 (modal mass = beam mass). Blevins, *Formulas for
    natural frequency and mode shape*, table 8-1: βL = 4.7300, σ = 0.9825."""
    xi = 0.5 + np.asarray(x, float) / length
    a = BETA_L * xi
    phi = np.cosh(a) + np.cos(a) - SIGMA_FF * (np.sinh(a) + np.sin(a))
    grid = np.linspace(0, 1, 2001) * BETA_L
    ref = np.cosh(grid) + np.cos(grid) - SIGMA_FF * (np.sinh(grid) + np.sin(grid))
    return phi / math.sqrt(np.mean(ref**2))


def kalker_coefficients(vehicle: VehicleModel) -> tuple[float, float]:
    """f11, f22 (N) at Q0: G·c²·C11, G·c²·C22 with c² = area/π (Kalker 1967)."""
    p = vehicle.parameters
    c2 = p["contact_area"] / math.pi
    return p["shear_modulus"] * c2 * p["kalker_c11"], p["shear_modulus"] * c2 * p["kalker_c22"]


@dataclass
class Assembly:
    SC: np.ndarray
    massd: np.ndarray
    free: np.ndarray
    xabs: np.ndarray
    CONN: np.ndarray
    ws_body: np.ndarray
    bogie_body: np.ndarray
    names: list = field(default_factory=list)
    #: contact geometry table for the kernel (``SC[RRD_ON]`` says whether it is used)
    RRD: np.ndarray = field(default_factory=lambda: np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0]]))


def _conn_row(**kw) -> np.ndarray:
    row = np.zeros(K.NCC)
    for k, v in kw.items():
        row[getattr(K, "C_" + k.upper())] = v
    return row


def assemble(vehicle: VehicleModel, effects: Mapping[str, Mapping[str, float]], speed_ms: float,
             nuisance: Mapping[str, float] | None = None) -> Assembly:
    """Kernel arrays for ``vehicle`` with ``effects`` (already resolved) at ``speed_ms``:
    bodies (:func:`_bodies`), suspension connections (:func:`_connections`) and the kernel's
    scalars (:func:`_scalars`)."""
    ef = dict(effects)
    massd, free, hcb = _bodies(vehicle, "track_flexibility" in ef)
    xabs = np.zeros(massd.shape[0])
    rows = _connections(vehicle, ef, dict(nuisance or {}), hcb, massd, free, xabs)
    CONN = np.array(rows)
    SC = _scalars(vehicle, ef, speed_ms, hcb, CONN)
    nb, nw = vehicle.n_bogies, vehicle.n_wheelsets
    bogie_body = np.arange(1, 1 + nb, dtype=np.int64)
    ws_body = np.arange(1 + nb, 1 + nb + nw, dtype=np.int64)
    RRD = np.zeros((2, 3))
    RRD[1, 0] = 1.0
    if vehicle.contact is not None:
        if "conicity" in ef:
            raise InvalidParameter(f"effect 'conicity' and the measured profiles' table "
                                   f"({vehicle.contact.source or 'contact_geometry'}) both set the contact "
                                   "geometry; give one of them")
        # measured profiles (core/sim/profiles.py): Δr(y) (and Δγ(y)) replace the conicity
        # and the flange-root slope; the flange contact stays the spring beyond the clearance
        RRD = vehicle.contact.kernel_array()
        SC[K.RRD_ON] = 1.0
        SC[K.RRD_GAM] = 1.0 if vehicle.contact.delta_gamma_rad is not None else 0.0
    return Assembly(SC, massd, free, xabs, CONN, ws_body, bogie_body, RRD=RRD)


def _bodies(vehicle: VehicleModel, tflex: bool) -> tuple[np.ndarray, np.ndarray, float]:
    """(mass/inertia per body and degree of freedom, which degrees are free, car body centre of
    gravity height) for the car body and the wheelsets; the bogies are filled by
    :func:`_connections`."""
    p = vehicle.parameters
    nb, nw = vehicle.n_bogies, vehicle.n_wheelsets
    nbody = 1 + nb + nw
    m = vehicle.masses()
    massd = np.ones((nbody, K.NDOF))
    free = np.zeros((nbody, K.NDOF), dtype=np.bool_)
    if vehicle.template == "coach":
        massd[0] = [m["carbody"], m["carbody"], p["I_roll_carbody"], p["I_pitch_carbody"], p["I_yaw_carbody"],
                    m["carbody"]]
    else:
        mb = m["carbody"]
        # box body of length L, width 2.8 m, height 2.5 m (uniform), payload included
        lx, wy, hz = p["L_carbody"], 2.8, 2.5
        massd[0] = [mb, mb, mb * (wy**2 + hz**2) / 12, mb * (lx**2 + hz**2) / 12, mb * (lx**2 + wy**2) / 12, mb]
    free[0] = True
    for i in range(nw):
        k = 1 + nb + i
        massd[k] = [m["wheelset"], m["wheelset"], p["I_roll_wheelset"], 1.0, p["I_yaw_wheelset"], m["wheelset"]]
        free[k, 0] = True
        free[k, 4] = True
        if tflex:
            free[k, 1] = True
            free[k, 2] = True
    return massd, free, p["h_carbody"]


def _connections(vehicle: VehicleModel, ef: Mapping[str, Mapping[str, float]], nz: Mapping[str, float],
                 hcb: float, massd: np.ndarray, free: np.ndarray, xabs: np.ndarray) -> list[np.ndarray]:
    """The suspension connection rows (secondary and primary for the coach, links and leaf
    springs for the two-axle wagon) with the effects that act on them; sets the bogies' masses,
    free degrees and every body's longitudinal position ``xabs``."""
    p = vehicle.parameters
    m = vehicle.masses()
    nb = vehicle.n_bogies
    xw = vehicle.wheelset_x()
    rows = []
    fr = ef.get("friction_damping", {}).get("force_kN", 0.0) * 1e3
    kser = ef.get("damper_series_stiffness", {}).get("k_series_MN_m", 0.0) * 1e6
    kpy = ef.get("parasitic_yaw_stiffness", {}).get("k_yaw_kNm_rad", 0.0) * 1e3
    bs = ef.get("lateral_bumpstop")
    bs_cl = bs["clearance_mm"] * 1e-3 if bs else 0.0
    bs_k = bs["stiffness_kN_mm"] * 1e6 if bs else 0.0
    asym = float(nz.get("damper_asymmetry", 0.0))
    if vehicle.template == "coach":
        c = p["bogie_centres"] / 2
        for j, xb in enumerate((c, -c)):
            k = 1 + j
            massd[k] = [p["m_bogie"], p["m_bogie"], p["I_roll_bogie"], p["I_pitch_bogie"], p["I_yaw_bogie"],
                        p["m_bogie"]]
            free[k] = True
            xabs[k] = xb
            rows.append(_conn_row(
                p=0, c=k, x=xb, b=p["b_secondary"], zp=H_SECONDARY - hcb, zc=H_SECONDARY - p["h_bogie"],
                kx=p["k_secondary_x"], ky=p["k_secondary_y"], kz=p["k_secondary_z"], cz=p["c_secondary_z"],
                cy=p["c_secondary_y"], byd=p["b_yaw_damper"], cyd=p["c_yaw_damper"], ksyd=kser, ksz=kser,
                ksy=kser, kroll=p["k_antiroll"], kpyaw=kpy, bscl=bs_cl, bsk=bs_k, fz=fr, fy=fr,
                kstz=K_STICK_Z, ksty=K_STICK_Y, asym=asym, w=m["carbody"] * G / 2,
                ktr=p["k_traction"], fyd=p["yaw_damper_blowoff"]))
        for i, x in enumerate(xw):
            k = 1 + nb + i
            parent = 1 if i < 2 else 2
            xabs[k] = x
            rows.append(_conn_row(
                p=parent, c=k, x=x - xabs[parent], b=p["b_primary"], zp=p["r0"] - p["h_bogie"], zc=0.0,
                kx=p["k_primary_x"], ky=p["k_primary_y"], kz=p["k_primary_z"], cz=p["c_primary_z"],
                w=(m["carbody"] / 2 + m["bogie"]) * G / 2))
        return rows
    w_spring = m["carbody"] * G / 4
    k_link = w_spring / p["link_length"]
    k_link_x = w_spring / p["link_length_x"]
    for i, x in enumerate(xw):
        k = 1 + i
        xabs[k] = x
        rows.append(_conn_row(
            p=0, c=k, x=x, b=p["b_spring"], zp=H_LEAF - hcb, zc=H_LEAF - p["r0"],
            kx=k_link_x, ky=k_link, kz=p["k_leaf_z"], kpyaw=kpy, bscl=bs_cl, bsk=bs_k,
            fz=p["leaf_friction"] * w_spring + fr, fy=p["link_friction"] * w_spring + fr,
            fx=p["link_friction"] * w_spring, kstz=3.0 * p["k_leaf_z"], ksty=3.0 * k_link,
            kstx=3.0 * k_link_x, w=m["carbody"] * G / 2))
    return rows


def _scalars(vehicle: VehicleModel, ef: Mapping[str, Mapping[str, float]], speed_ms: float, hcb: float,
             CONN: np.ndarray) -> np.ndarray:
    """The kernel's scalar vector: speed, wheel–rail contact (conicity, flange, creep
    coefficients and law, friction), track flexibility, sensor positions and the car body's
    bending mode (which also sets the mode shape at the secondary connections in ``CONN``)."""
    p = vehicle.parameters
    SC = np.zeros(K.NSC)
    lam = ef["conicity"]["conicity"] if "conicity" in ef else p["conicity"]
    f11, f22 = kalker_coefficients(vehicle)
    SC[K.V] = speed_ms
    SC[K.GRAV] = G
    SC[K.NW] = vehicle.n_wheelsets
    SC[K.R0] = p["r0"]
    SC[K.B0] = p["b0"]
    SC[K.LAM] = lam
    SC[K.LAM2] = LAMBDA_FLANGE_ROOT
    SC[K.CLEAR] = p["flange_clearance"]
    SC[K.YFR] = p["flange_clearance"] - FLANGE_ROOT_ONSET
    SC[K.KFL] = p["k_flange"]
    SC[K.GAM0] = p["contact_angle"]
    SC[K.EPSG] = _contact_slope(p["contact_angle_parameter"], p["b0"])
    SC[K.F11] = f11
    SC[K.F22] = f22
    SC[K.Q0] = vehicle.q0_kN() * 1e3
    SC[K.MU] = ef["wheel_rail_friction"]["mu"] if "wheel_rail_friction" in ef else p["mu_nominal"]
    # creep law (docs/simulator.md): 1 = Shen–Hedrick–Elkins saturation, 2 = Polach
    SC[K.SAT] = 2.0 if p.get("creep_law", 0.0) >= 0.5 else 1.0
    SC[K.POL_KA] = p.get("polach_kA", 1.0)
    SC[K.POL_KS] = p.get("polach_kS", 0.4)
    if "track_flexibility" in ef:
        SC[K.TFLEX] = 1.0
        SC[K.KTZ] = ef["track_flexibility"]["k_vertical_MN_m"] * 1e6
        SC[K.CTZ] = TRACK_CZ
        SC[K.KTY] = ef["track_flexibility"]["k_lateral_MN_m"] * 1e6
    xs = vehicle.sensor_x()
    SC[K.XS1], SC[K.XS2] = xs
    SC[K.ZSENS] = p["h_sensor"] - hcb
    if "carbody_flexibility" in ef:
        fl = ef["carbody_flexibility"]
        SC[K.FLEX] = 1.0
        SC[K.FLEX_W] = 2 * math.pi * fl["frequency_Hz"]
        SC[K.FLEX_Z] = fl["damping_ratio"]
        SC[K.FLEX_M] = vehicle.masses()["carbody"]
        L = p["L_carbody"]
        SC[K.PHI_S1], SC[K.PHI_S2] = bending_mode_shape(np.array(xs), L)
        for r in CONN:
            if r[K.C_P] == 0:
                r[K.C_PHIF] = float(bending_mode_shape(r[K.C_X], L))
    return SC


def _contact_slope(eps: float, b0: float) -> float:
    """Change of the contact angle with lateral displacement, rad/m: ε/b0 (Wickens' contact angle
    parameter ε, so that the gravitational stiffness of the wheelset is W·ε/b0)."""
    return eps / b0


def channel_names(vehicle: VehicleModel) -> list[str]:
    """Output channels in kernel column order (core/types.py vocabulary).

    Parameters
    ----------
    vehicle : VehicleModel

    Returns
    -------
    list of str
        Channel names such as ``Y_w1L``.
    """
    names = []
    for i in range(vehicle.n_wheelsets):
        names += [f"Y_w{i + 1}L", f"Y_w{i + 1}R", f"Q_w{i + 1}L", f"Q_w{i + 1}R"]
    names += ["ay_cb_b1", "ay_cb_b2", "az_cb_b1", "az_cb_b2"]
    for j in range(vehicle.n_bogies):
        names += [f"ay_bg_b{j + 1}", f"az_bg_b{j + 1}"]
    return names


#: accuracy limits of the step: ω·dt for the oscillatory (spring–mass) rates, r·dt for the
#: explicitly integrated damping rates (checked by tests/test_sim_numerics.py: halving the step
#: moves none of the 12 EN 14363 quantities by more than 2 %, every effect at both bounds)
OMEGA_DT = 0.5
RATE_DT = 0.5
#: with track flexibility the wheelsets bounce and roll on the track springs and the flange
#: contact couples into their roll (r0·Y): measured first-order step error ≈ 3 % at ω·dt = 0.5
#: (Y_qst at k_lateral = 200 MN/m), hence the finer limit for these track oscillators
OMEGA_DT_TRACK = 0.18
#: the step also resolves the track input: 2π·(v/λ_min)·dt ≤ INPUT_DT with λ_min = 3 m, the
#: shortest irregularity wavelength (EN 13848-1 D1 band) — the wheelsets follow it through the
#: creep forces, and the first-order error of the scheme in their response scales with it
INPUT_DT = 0.1
LAMBDA_MIN_INPUT = 3.0


def choose_substeps(asm: Assembly, fs_out: float) -> int:
    """Integer number of steps per output sample so that the step resolves every stiff element
    for ACCURACY (not only stability): ω·dt ≤ ``OMEGA_DT`` for every spring on the mass it moves
    (flange contact in series with the lateral rail stiffness, vertical track springs, bump stops,
    friction stick springs, suspension springs, traction rods), r·dt ≤ ``RATE_DT`` for every
    explicitly integrated damping rate (suspension and yaw dampers c/m, vertical track damping)
    and for a Maxwell element the smaller of its relaxation rate k/c and its spring's ω (at
    high k/c it acts as a dashpot, the exponential update is exact; at low k/c as a spring).
    The wheelsets' creep damping is integrated exponentially and sets no limit; the track input
    sets ``INPUT_DT`` (the response to the shortest wavelengths). Semi-implicit Euler
    is stable for ω·dt < 2 (Hairer, Lubich & Wanner, *Geometric Numerical Integration*, 2006,
    §I.1); its frequency error is ≈ (ω·dt)²/24, 1 % at ω·dt = 0.5."""
    SC = asm.SC
    mw = asm.massd[asm.ws_body[0], 0]
    osc = [math.sqrt(SC[K.KFL] / mw)]
    rates = []
    osc_track = []
    if SC[K.TFLEX]:
        iw_roll = asm.massd[asm.ws_body[0], 2]
        kfl_s = SC[K.KFL] * SC[K.KTY] / (SC[K.KFL] + SC[K.KTY])
        osc_track += [math.sqrt(2 * SC[K.KTZ] / mw), math.sqrt(2 * SC[K.KTZ] * SC[K.B0] ** 2 / iw_roll),
                      math.sqrt(kfl_s / mw)]
        rates += [2 * SC[K.CTZ] / mw]
    for r in asm.CONN:
        mc = asm.massd[int(r[K.C_C]), 0]
        mp = asm.massd[int(r[K.C_P]), 0]
        mred = mc * mp / (mc + mp)
        for kk in (K.C_KX, K.C_KY, K.C_KZ, K.C_BSK, K.C_KSTZ, K.C_KSTY, K.C_KSTX):
            osc.append(math.sqrt(2 * r[kk] / mred))
        osc.append(math.sqrt(r[K.C_KTR] / mred))
        for kc, ks, n in ((K.C_CZ, K.C_KSZ, 2), (K.C_CY, K.C_KSY, 1)):
            c = n * r[kc]
            if c > 0:
                rates.append(min(c / mred, r[ks] / r[kc]) if r[ks] > 0 else c / mred)
        iz_c = asm.massd[int(r[K.C_C]), 4]
        iz_p = asm.massd[int(r[K.C_P]), 4]
        cyaw = 2 * r[K.C_CYD] * r[K.C_BYD] ** 2
        if cyaw > 0:
            ryaw = cyaw * (1 / iz_c + 1 / iz_p)
            rates.append(min(ryaw, r[K.C_KSYD] / r[K.C_CYD]) if r[K.C_KSYD] > 0 else ryaw)
    dt_input = INPUT_DT * LAMBDA_MIN_INPUT / (2 * math.pi * SC[K.V])
    # with track flexibility every oscillator gets the finer limit (measured: limiting only the
    # track oscillators leaves 3 % step error at k_vertical = 10 MN/m)
    omega_dt = OMEGA_DT_TRACK if osc_track else OMEGA_DT
    dt_max = min(omega_dt / max(osc + osc_track), RATE_DT / max(rates) if rates else math.inf, dt_input)
    return max(2, math.ceil(1.0 / (fs_out * dt_max)))


#: the irregularity keys each ``level`` direction of :func:`_track_arrays` scales
LEVEL_KEYS = {"vertical": ("vertical", "cross_level"), "lateral": ("alignment", "gauge")}


def _track_arrays(section: TrackSection, vehicle: VehicleModel, use_measured: bool, scale: float,
                  margin: float = 40.0, level: Mapping[str, float] | None = None) -> dict[str, np.ndarray]:
    """The track input arrays; ``level``: amplitude factor per direction of :data:`LEVEL_KEYS`
    (the generated irregularities' level, effects ``track_level_*``)."""
    reach = max(abs(x) for x in vehicle.wheelset_x()) + margin
    s0, s1 = -reach, section.length_m + reach
    irr = section.irregularity_arrays(s0, s1, scale=scale, use_measured=use_measured)
    for d, f in (level or {}).items():
        for key in LEVEL_KEYS[d]:
            irr[key] = f * irr[key]
    s = irr["s"]
    kap, phit = section.geometry(s)
    d1 = lambda a: np.gradient(a, DS)
    return {"s0": float(s[0]), "kap": kap, "phit": phit, "zv": irr["vertical"], "zv1": d1(irr["vertical"]),
            "zv2": d1(d1(irr["vertical"])), "cl": irr["cross_level"], "cl1": d1(irr["cross_level"]),
            "cl2": d1(d1(irr["cross_level"])), "ya": irr["alignment"], "ga": irr["gauge"]}


def simulate_section(vehicle: VehicleModel | Mapping | str, section: TrackSection,
                     effects: Mapping[str, Mapping[str, float]] | None = None, *, fs_out: float = 200.0,
                     seed: int | None = None, parameters: Mapping[str, float] | None = None,
                     channels: Sequence[str] | None = None, nuisance: Mapping[str, float] | None = None,
                     speed_factor: float = 1.0, refine: int = 1, end_m: float | None = None) -> SignalSet:
    """Simulate one section; return a :class:`railval.core.types.SignalSet` at ``fs_out`` Hz.

    ``effects``: ``{effect id: {param: value}}`` (see :mod:`railval.core.sim.effects`; defaults filled,
    bounds checked). Irregularities: generated from the section's ORE B176 level with the
    section's seed (``seed`` overrides it) unless ``measured_irregularities`` is on and the
    section carries measured ones. ``parameters``: vehicle template overrides (``model.NAME``
    or ``NAME``). ``nuisance`` and ``speed_factor`` are used by the synthetic-data generator
    (truth model) only. ``refine`` multiplies the number of integration steps (accuracy
    checks). Distance axis = car body centre position from the section start (m). ``end_m``:
    stop once the car body centre has travelled that far (shorter than the section: the
    samples up to it are those of the whole run — the kernel integrates forward in time and
    the track input is built for the whole section either way).

    Parameters
    ----------
    vehicle : VehicleModel, mapping or str
        Vehicle model, its record or a template name.
    section : TrackSection
    effects : mapping of str to mapping of str to float or None
    seed : int or None
    fs_out : float
        Output rate in Hz.
    parameters : mapping of str to float or None
    channels : sequence of str or None
        Channels to return; ``None`` = all of :func:`channel_names`.
    nuisance : mapping of str to float or None
    speed_factor : float
    refine : int
    end_m : float or None
        Distance (m) at which the run stops; ``None`` = the section's end.

    Returns
    -------
    SignalSet
        Channels in their registry units (kN, m/s², :data:`railval.core.types.CHANNELS`), shape
        (N,) each, with ``time_s`` (s) and ``distance_m`` (m).
    """
    veh = VehicleModel.from_any(vehicle, parameters)
    ef = resolve_effects(dict(effects or {}))
    if not (fs_out > 0):
        raise InvalidParameter(f"fs_out must be > 0 Hz, got {fs_out}")
    if seed is not None:
        section = TrackSection(**{**section.__dict__, "seed": int(seed)})
    use_meas = "measured_irregularities" in ef
    if use_meas and section.irregularities is None:
        raise InvalidParameter(f"effect 'measured_irregularities': section {section.id!r} carries no "
                               "measured irregularities (layout['irregularities'])")
    scale = ef["measured_irregularities"]["scale"] if use_meas else 1.0
    # the generated track's level per direction (effects track_level_*; not on measured geometry)
    level = None if use_meas and section.irregularities is not None else \
        {d: ef[f"track_level_{d}"]["factor"] for d in ("vertical", "lateral") if f"track_level_{d}" in ef}
    v = section.speed_ms * float(speed_factor)
    asm = assemble(veh, ef, v, nuisance)
    duration = None if end_m is None else min(float(end_m), section.length_m) / v
    ss, _ = run_assembled(asm, veh, section, fs_out=fs_out, use_measured=use_meas, scale=scale, refine=refine,
                          level=level, duration_s=duration)
    if channels is not None:
        want = set(channels)
        ss.channels = {k: x for k, x in ss.channels.items() if k in want}
    return ss


def run_assembled(asm: Assembly, veh: VehicleModel, section: TrackSection, *, fs_out: float = 200.0,
                  use_measured: bool = False, scale: float = 1.0, states: bool = False,
                  duration_s: float | None = None, refine: int = 1,
                  level: Mapping[str, float] | None = None) -> tuple[SignalSet, np.ndarray | None]:
    """Run the kernel for an assembled model. ``states=True`` also returns the wheelsets' lateral
    displacements, the car body's vertical displacement, pitch and lateral displacement and the
    bogies' lateral displacements (columns, per output sample) for verification tests.
    ``refine`` multiplies the number of steps per output sample (step-halving checks)."""
    tr = _track_arrays(section, veh, use_measured, scale, level=level)
    v = asm.SC[K.V]
    decim = choose_substeps(asm, fs_out) * int(refine)
    dt = 1.0 / (fs_out * decim)
    duration = section.length_m / v if duration_s is None else duration_s
    n_out = int(duration * fs_out)
    n_steps = n_out * decim
    names = channel_names(veh)
    extra = veh.n_wheelsets + 3 + veh.n_bogies if states else 0
    out = np.zeros((n_out, len(names) + extra))
    TR = np.ascontiguousarray(np.column_stack([tr["kap"], tr["phit"], tr["zv"], tr["zv1"], tr["zv2"], tr["cl"],
                                               tr["cl1"], tr["cl2"], tr["ya"], tr["ga"]]))
    K.run_kernel(asm.SC, asm.massd, asm.free, asm.xabs, asm.CONN, asm.ws_body, asm.bogie_body,
                 tr["s0"], DS, TR, n_steps, dt, decim, out, asm.RRD)
    t = np.arange(n_out) / fs_out + (decim - 1) / 2 * dt
    chans = {n: np.ascontiguousarray(out[:, j]) for j, n in enumerate(names)}
    ss = SignalSet(fs=float(fs_out), time_s=t, distance_m=asm.SC[K.S_START] + v * t, channels=chans)
    return ss, (out[:, len(names):] if states else None)


# ------------------------------------------------------------------------------- campaigns
POOL_MIN_SIMULATED_S = 1500.0  # s of simulated time above which simulate_campaign uses 2 processes
_POOL: ProcessPoolExecutor | None = None
_POOL_WORKERS = 0


def _pool(workers: int) -> ProcessPoolExecutor:
    global _POOL, _POOL_WORKERS
    if _POOL is None or _POOL_WORKERS != workers:
        if _POOL is not None:
            _POOL.shutdown(wait=False, cancel_futures=True)
        method = "fork" if threading.active_count() == 1 and "fork" in mp.get_all_start_methods() else "forkserver"
        _POOL = ProcessPoolExecutor(max_workers=workers, mp_context=mp.get_context(method),
                                    **pool_kwargs())
        _POOL_WORKERS = workers
    return _POOL


def _run_one(task):
    veh, sec, effects, fs, channels, nuisance, speed_factor, end_m = task
    return simulate_section(veh, sec, effects, fs_out=fs, channels=channels, nuisance=nuisance,
                            speed_factor=speed_factor, end_m=end_m)


def simulate_campaign(vehicle, sections: Sequence, *, layouts: Mapping[str, dict | None] | None = None,
                      effects: Mapping[str, Mapping[str, float]] | None = None,
                      parameters: Mapping[str, float] | None = None, channels: Sequence[str] | None = None,
                      fs: float | Mapping[str, float] = 200.0, workers: int | None = None,
                      progress=None, end_m: Mapping[str, float] | None = None,
                      **_ignored) -> dict[str, SignalSet]:
    """Simulate every section; ``sections`` are :class:`TrackSection` or
    :class:`railval.core.types.SectionInfo` (then ``layouts[id]`` gives the layout record). Returns
    ``{section id: SignalSet}``. ``fs``: one rate or ``{section id: rate}``.

    ``workers``: processes (default: 2 in the main process when more than
    ``POOL_MIN_SIMULATED_S`` of simulated time are asked for, else 1; always 1 inside a worker
    process — the diagnosis parallelises over candidates itself), or a map-like callable
    ``workers(func, tasks)`` returning the results in order (e.g. a Dask cluster's executor). Results are identical
    for any number of workers. ``progress(done, total)`` is called after each section.

    Parameters
    ----------
    vehicle : VehicleModel, mapping or str
        As in :func:`simulate_section`.
    sections : sequence of TrackSection or SectionInfo
    layouts : mapping of str to dict or None
    effects, parameters, channels
        As in :func:`simulate_section`, for every section.
    fs : float or mapping of str to float
        Output rate in Hz.
    workers : int, callable or None
    progress : callable or None
    end_m : mapping of str to float or None
        Per section id, the distance (m) at which its run stops (:func:`simulate_section`);
        sections not named, or ``None``, run to their end.
    **_ignored
        Further keywords, ignored.

    Returns
    -------
    dict of str to SignalSet
    """
    veh = VehicleModel.from_any(vehicle, parameters)
    ef = resolve_effects(dict(effects or {}))
    secs = [s if isinstance(s, TrackSection) else TrackSection.from_info(s, (layouts or {}).get(s.id))
            for s in sections]
    tasks = [(veh, s, ef, float(fs.get(s.id, 200.0) if isinstance(fs, Mapping) else fs), channels, None, 1.0,
              (end_m or {}).get(s.id)) for s in secs]
    if workers is None:
        # a process pool pays off only for long runs (measured: 12 sections / 350 s simulated
        # take 0.6–1.4 s serially, the pool's start and result transfer cost ~0.3–0.8 s)
        sim_s = sum(min(t[7] or s.length_m, s.length_m) / s.speed_ms for s, t in zip(secs, tasks, strict=True))
        big = sim_s > POOL_MIN_SIMULATED_S and len(tasks) > 2
        workers = min(2, os.cpu_count() or 1) if (mp.current_process().name == "MainProcess" and big) else 1
    out: dict[str, SignalSet] = {}
    if callable(workers):  # a map-like callable (scipy's ``workers`` convention), e.g. Dask
        for i, (t, res) in enumerate(zip(tasks, workers(_run_one, tasks), strict=True)):
            out[t[1].id] = res
            if progress:
                progress(i + 1, len(tasks))
        return out
    if workers <= 1:
        for i, t in enumerate(tasks):
            out[t[1].id] = _run_one(t)
            if progress:
                progress(i + 1, len(tasks))
        return out
    pool = _pool(workers)
    for i, (t, res) in enumerate(zip(tasks, pool.map(_run_one, tasks), strict=True)):
        out[t[1].id] = res
        if progress:
            progress(i + 1, len(tasks))
    return out
