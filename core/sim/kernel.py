"""The numba-compiled time integration loop of the built-in simulator.

Bodies (car body, bogie frames, wheelsets) each carry six coordinates relative to the local
track frame at their own position along the track (y lateral, z vertical, φ roll, θ pitch,
ψ yaw, x longitudinal; x forward, y left, z up; small rotations). Wheelsets have no
longitudinal freedom (held by the longitudinal creep forces). Connections (secondary: car
body → bogie or car body → wheelset; primary: bogie → wheelset) are springs, dampers
(optionally Maxwell with a series stiffness), Saint-Venant friction elements, bump stops,
anti-roll bars, yaw stiffnesses, traction rods (longitudinal restraint at the secondary
attachment height) and yaw dampers with a force limit, acting between attachment points; the
track frame of a child differs from its parent's by the curve geometry (lateral offset
x²(2κ_p+κ_c)/6, yaw x(κ_p+κ_c)/2, exact for a linear curvature ramp, and the cant difference).

Static load path (lateral and longitudinal weight shift): the static vertical load ``w`` of a
connection acts upwards on the parent at the parent's attachment point and downwards on the
child at the SAME point (a collinear pair), so a lateral or longitudinal offset of the car body
relative to a bogie (or of a bogie relative to a wheelset) moves the load with it: wheel-load
transfer w·Δy/b0 (and the P-Δ moments of rolled or pitched bodies).

Integration: semi-implicit (symplectic) Euler with a fixed step. Stiff terms get exact or
exponential updates: Maxwell dampers the exact exponential solution of their spring deflection
for a constant relative velocity over the step (Δₙ₊₁ = Δₙ·e^(−a) + v·(c/k)·(1 − e^(−a)),
a = k·dt/c; force k·Δₙ₊₁ from the updated state), friction sliders a return map, the
wheelsets' creep damping (lateral f22/v, yaw f11·b0²/v per wheel, the saturation factor
included) exponentially on the wheelset's own velocity. The step is chosen by the caller for accuracy
(:func:`railval.core.sim.model.choose_substeps`). Output: block means over ``decim`` steps
(anti-alias boxcar).

The equations (quasi-static acceleration in the track plane a_q = v²κ − g·φ_t, Kalker linear
creep with Shen–Hedrick–Elkins saturation (or, selected by the template parameter
``creep_law`` = 1, Polach's law with reduction factors), gravitational stiffness via the contact angle,
flange contact as a stiff spring beyond the clearance, lateral track compliance as a massless
spring per rail) are documented in ``docs/simulator.md`` and in :mod:`railval.core.sim.model`.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

# --- scalar parameter indices (SC array)
V, GRAV, NW, R0, B0, LAM, LAM2, YFR, CLEAR, KFL, GAM0, EPSG = range(12)
F11, F22, Q0, MU, SAT, TFLEX, KTZ, CTZ, KTY = range(12, 21)
FLEX, FLEX_W, FLEX_Z, FLEX_M, ZSENS, S_START, PHI_S1, PHI_S2, XS1, XS2 = range(21, 31)
Y_INIT, Z_INIT, TH_INIT = range(31, 34)  # initial conditions (verification tests)
POL_KA, POL_KS = range(34, 36)  # Polach reduction factors (SC[SAT] == 2: Polach creep law)
# contact geometry as data (core/sim/profiles.py): > 0 = Δr (and Δγ) from the table RRD
RRD_ON, RRD_GAM = range(36, 38)
NSC = 38

# --- connection columns (CONN array)
(C_P, C_C, C_X, C_B, C_ZP, C_ZC, C_KX, C_KY, C_KZ, C_CZ, C_CY, C_BYD, C_CYD, C_KSYD, C_KSZ,
 C_KSY, C_KROLL, C_KPYAW, C_BSCL, C_BSK, C_FZ, C_FY, C_FX, C_KSTZ, C_KSTY, C_ASYM, C_W,
 C_PHIF, C_KTR, C_FYD, C_KSTX) = range(31)
NCC = 31
NDOF = 6  # y, z, roll, pitch, yaw, x
# --- track array columns (TR array, one row per grid point)
T_KAP, T_PHI, T_ZV, T_ZV1, T_ZV2, T_CL, T_CL1, T_CL2, T_YA, T_GA = range(10)
NTC = 10


#: 2^(1/3), 2^(2/3) and the factors 2^(r/3), r = −2…2, of :func:`cbrt_positive`
_CBRT2 = 1.2599210498948731648
_SQR_CBRT2 = 1.5874010519681994748
_CBRT_F = (1.0 / _SQR_CBRT2, 1.0 / _CBRT2, 1.0, _CBRT2, _SQR_CBRT2)


@njit(cache=True, inline="always")
def cbrt_positive(x):
    """Cube root of a positive finite ``x``, bit for bit the value of the GNU C Library's
    ``cbrt`` (the generic double-precision one, ``sysdeps/ieee754/dbl-64/s_cbrt.c``, which
    ``np.cbrt`` calls on glibc), computed inline: x = m·2^e with m in [0.5, 1) (exact halvings
    and doublings instead of ``frexp``), a degree-6 polynomial u ≈ m^(1/3) with that file's
    coefficients, one Halley step u·(u³ + 2m)/(2u³ + m), the factor 2^(r/3) of the remainder
    r of e/3 (truncated, as C divides) and 2^(e div 3) by exact doublings (instead of
    ``ldexp``). Every operation is the library's, in its order, so the result is the same bits
    (tests/test_sim_kernel_cbrt.py: 2 million arguments over 10⁻³⁰⁰…10³⁰⁰; within 3 ulp of the
    true root); the library call it replaces cost the contact loop ≈ 14 % of the kernel's time
    (8 calls per step, every live register saved around each; docs/diagnosis.md, round 8).
    Inlined into :func:`run_kernel` it is compiled with that kernel's :data:`KERNEL_FASTMATH`,
    so there its last bits may differ from the library's (the tests check this function on its
    own). Zero, negative, infinite and NaN arguments go to ``np.cbrt``."""
    if not (0.0 < x < 1.7976931348623157e308):
        return np.cbrt(x)
    xm = x
    xe = 0
    while xm >= 1.0:
        xm *= 0.5
        xe += 1
    while xm < 0.5:
        xm *= 2.0
        xe -= 1
    u = (0.354895765043919860 + ((1.50819193781584896 + ((-2.11499494167371287 + ((2.44693122563534430 + (
        (-1.83469277483613086 + (0.784932344976639262 - 0.145263899385486377 * xm) * xm) * xm)) * xm)) * xm))
        * xm))
    t2 = u * u * u
    qe = xe // 3 if xe >= 0 else -((-xe) // 3)
    ym = u * (t2 + 2.0 * xm) / (2.0 * t2 + xm) * _CBRT_F[2 + xe - 3 * qe]
    while qe > 0:
        ym *= 2.0
        qe -= 1
    while qe < 0:
        ym *= 0.5
        qe += 1
    return ym


@njit(cache=True, inline="always")
def _sat_factor(fx, fy, mu_q):
    """Shen–Hedrick–Elkins factor by which the linear creep force resultant is scaled (1 below
    saturation onset, → μQ/|F| far beyond it)."""
    f = math.sqrt(fx * fx + fy * fy)
    if mu_q <= 0.0:
        return 0.0
    if f <= 1e-12:
        return 1.0
    b = f / mu_q
    if b < 3.0:
        return (b - b * b / 3.0 + b * b * b / 27.0) / b
    return 1.0 / b


@njit(cache=True, inline="always")
def _polach_factor(fx, fy, mu_q, ka, ks):
    """Polach's creep law as a factor on the linear Kalker force resultant |F_lin|: with the
    gradient of the tangential stress ε = π·|F_lin|/(4μQ) (so that kA = kS = 1 has Kalker's
    initial slope), F = (2μQ/π)·(kA·ε/(1 + (kA·ε)²) + arctan(kS·ε)), i.e. the factor
    (kA·ε/(1 + (kA·ε)²) + arctan(kS·ε))/(2ε): (kA + kS)/2 at small creep, → μQ/|F_lin| far
    beyond saturation. Reduction factors kA (adhesion area) and kS (slip area) below 1 model a
    contaminated or rough contact (dry rail kA = 1, kS ≈ 0.4). Polach, O., Creep forces in
    simulations of traction vehicles running on adhesion limit, Wear 258 (2005) 992–1000, §2
    (without the slip-velocity dependence of μ); Polach, O., A fast wheel–rail forces
    calculation computer code, Veh. Syst. Dyn. 33 suppl. (1999) 728–739."""
    f = math.sqrt(fx * fx + fy * fy)
    if mu_q <= 0.0:
        return 0.0
    e = 0.7853981633974483 * f / mu_q
    if e <= 1e-9:
        return 0.5 * (ka + ks)
    ea = ka * e
    return (ea / (1.0 + ea * ea) + math.atan(ks * e)) / (2.0 * e)


@njit(cache=True, inline="always")
def slider(d, s_prev, kst, ff):
    """Saint-Venant element (stick spring ``kst`` in series with a Coulomb slider of breakaway
    force ``ff``), return map: elastic trial force kst·(d − s); beyond ±ff the slider moves so
    the force stays at ±ff. Returns (force, new slider position). Iwnicki (ed.) 2006 (friction
    elements); Simo & Hughes, *Computational Inelasticity*, 1998 §1.2 (return mapping)."""
    fr = kst * (d - s_prev)
    if fr > ff:
        return ff, d - ff / kst
    if fr < -ff:
        return -ff, d + ff / kst
    return fr, s_prev


@njit(cache=True, inline="always")
def maxwell(delta, vrel, k, c, dt):
    """Spring deflection of a Maxwell element (spring k in series with dashpot c) after one step
    of ``dt`` with the relative velocity ``vrel`` of its end points held constant: the exact
    solution of dΔ/dt = v − (k/c)·Δ, Δₙ₊₁ = Δₙ·e^(−a) + v·(c/k)·(1 − e^(−a)), a = k·dt/c. The force
    is k·Δₙ₊₁. Limits: k → ∞ gives the dashpot force c·v, c → ∞ the spring k·∫v dt."""
    a = k * dt / c
    return delta * math.exp(-a) - vrel * (c / k) * math.expm1(-a)


@njit(cache=True, inline="always")
def _maxwell_e(delta, vrel, k, c, e):
    """:func:`maxwell` with e = exp(−k·dt/c) precomputed."""
    return delta * e + vrel * (c / k) * (1.0 - e)


@njit(cache=True, inline="always")
def _damper(delta, vrel, k, c, asym, e_sym, e_ext, e_com):
    """Damper with optional series stiffness ``k`` (> 0: Maxwell element, else a plain dashpot) and
    asymmetry ``asym`` (c·(1 + asym) in extension, c·(1 − asym) in compression, by the sign of
    the damper's own velocity = sign of the force); ``e_*`` = exp(−k·dt/c) for c, c·(1 + asym),
    c·(1 − asym). Returns (force, new spring deflection)."""
    if k > 0.0:
        d1 = _maxwell_e(delta, vrel, k, c, e_sym)
        if asym != 0.0:
            if d1 > 0.0:
                d1 = _maxwell_e(delta, vrel, k, c * (1.0 + asym), e_ext)
            else:
                d1 = _maxwell_e(delta, vrel, k, c * (1.0 - asym), e_com)
        return k * d1, d1
    return c * vrel * (1.0 + asym * (1.0 if vrel > 0.0 else -1.0)), 0.0


@njit(cache=True, inline="always")
def _locate(s, s0, inv_ds, n):
    """Grid index and weight of distance ``s`` for linear interpolation (clamped at the ends)."""
    f = (s - s0) * inv_ds
    if f <= 0.0:
        return 0, 0.0
    i = int(f)
    if i >= n - 1:
        return n - 2, 1.0
    return i, f - i


@njit(cache=True, inline="always")
def table_value(T, col, y):
    """Column ``col`` of the table ``T`` (rows sorted by ``T[:, 0]``) at ``y``: linear
    interpolation, the end segments extended beyond the table (binary search for the segment)."""
    n = T.shape[0]
    lo = 0
    if y >= T[n - 1, 0]:
        lo = n - 2
    elif y > T[0, 0]:
        hi = n - 1
        while hi - lo > 1:
            mid = (lo + hi) >> 1
            if T[mid, 0] <= y:
                lo = mid
            else:
                hi = mid
    w = (y - T[lo, 0]) / (T[lo + 1, 0] - T[lo, 0])
    return T[lo, col] + w * (T[lo + 1, col] - T[lo, col])


#: LLVM's floating-point freedoms for the step (docs/simulator.md "Numerical scheme"): fused
#: multiply–add (``contract``), reassociation (``reassoc``), reciprocals of divisors
#: (``arcp``) and the sign of zero (``nsz``) — not ``nnan``/``ninf``, so non-finite values are
#: still seen as such. They move a run's values by rounding (≤ 3·10⁻¹³ of a channel's largest
#: value on the bench campaign) and make the kernel ≈ 17 % faster (docs/diagnosis.md round 13);
#: the bits then follow the compiler and the processor, no longer the IEEE operation order
#: alone (the same installation on the same machine still gives the same bits, serial or on
#: any number of workers). The inlined helpers above are compiled into the step with them.
KERNEL_FASTMATH = frozenset({"contract", "reassoc", "arcp", "nsz"})


@njit(cache=True, fastmath=set(KERNEL_FASTMATH))
def run_kernel(SC, massd, free, xabs, CONN, ws_body, bogie_body, s_arr0, ds, TR, n_steps, dt, decim, out, RRD):
    """Integrate ``n_steps`` steps of ``dt`` s; write ``out[n_steps // decim, nch]`` block means.

    ``massd``/``free``: (n_bodies, 6) masses/inertias and free flags for y, z, φ, θ, ψ, x.
    ``TR``: track arrays on the grid ``s_arr0 + k·ds`` (columns ``T_*``: curvature, cant angle,
    vertical level and its first two derivatives in s, cross level and derivatives, alignment,
    gauge).
    ``RRD``: the contact geometry table (n, 3): y (m), Δr = r_L − r_R (m), Δγ = γ_L − γ_R (rad),
    used when ``SC[RRD_ON]`` > 0 instead of the conicity and flange-root slopes (Δγ when
    ``SC[RRD_GAM]`` > 0 instead of the contact-angle slope); any (≥ 2, 3) array otherwise.
    Output columns: per wheelset i: Y_L, Y_R, Q_L, Q_R (kN) at 4i..4i+3; then car body ay at
    sensor 1, 2, az at sensor 1, 2 (m/s²); then per bogie ay, az (m/s²); if ``out`` has more
    columns: the wheelsets' lateral displacements (m), car body z (m), pitch (rad), lateral y
    (m), then per bogie lateral y (m).
    """
    nbody = massd.shape[0]
    nc = CONN.shape[0]
    nw = ws_body.shape[0]
    nb = bogie_body.shape[0]
    ngrid = TR.shape[0]
    inv_ds = 1.0 / ds
    v = SC[V]
    g = SC[GRAV]
    b0 = SC[B0]
    r0 = SC[R0]
    q0 = SC[Q0]
    q = np.zeros((nbody, NDOF))
    u = np.zeros((nbody, NDOF))
    F = np.zeros((nbody, NDOF))
    acc = np.zeros((nbody, NDOF))
    cimp = np.zeros((nbody, NDOF))  # creep damping coefficients integrated exponentially
    st = np.zeros((nc, 12))  # internal states of Maxwell dampers and friction sliders
    # exp(−k·dt/c) of every Maxwell element: vertical (symmetric, extension, compression),
    # lateral, yaw
    emx = np.zeros((nc, 5))
    for c in range(nc):
        ks = CONN[c, C_KSZ]
        cz = CONN[c, C_CZ]
        asym = CONN[c, C_ASYM]
        if ks > 0.0 and cz > 0.0:
            emx[c, 0] = math.exp(-ks * dt / cz)
            emx[c, 1] = math.exp(-ks * dt / (cz * (1.0 + asym)))
            emx[c, 2] = math.exp(-ks * dt / (cz * (1.0 - asym)))
        if CONN[c, C_KSY] > 0.0 and CONN[c, C_CY] > 0.0:
            emx[c, 3] = math.exp(-CONN[c, C_KSY] * dt / CONN[c, C_CY])
        if CONN[c, C_KSYD] > 0.0 and CONN[c, C_CYD] > 0.0:
            emx[c, 4] = math.exp(-CONN[c, C_KSYD] * dt / CONN[c, C_CYD])
    bi = np.zeros(nbody, dtype=np.int64)
    bw = np.zeros(nbody)
    qf = 0.0
    uf = 0.0
    dtr = np.zeros((nw, 2))  # quasi-static lateral rail deflection under the tread forces, L/R
    Qw = np.full((nw, 2), q0)
    Yw = np.zeros((nw, 2))
    sb = np.zeros(nbody)
    kb = np.zeros(nbody)
    pb = np.zeros(nbody)
    aqb = np.zeros(nbody)
    nch = out.shape[1]
    acc_blk = np.zeros(nch)
    k_out = 0
    cnt = 0
    ws_az = np.zeros(nw)
    ws_aphi = np.zeros(nw)
    for i in range(nw):
        q[ws_body[i], 0] = SC[Y_INIT]
    q[0, 1] = SC[Z_INIT]
    q[0, 3] = SC[TH_INIT]
    ncol_std = 4 * nw + 4 + 2 * nb
    tflex = SC[TFLEX] > 0.0
    rrd = SC[RRD_ON] > 0.0
    rgam = SC[RRD_GAM] > 0.0
    kty = SC[KTY]
    # flange contact in series with the rail's lateral stiffness (track_flexibility): counted once,
    # the tread forces deflect the rail by Y/k_rail (dtr), the flange force through the series spring
    kfl = SC[KFL] * kty / (SC[KFL] + kty) if tflex else SC[KFL]
    if tflex:
        # wheelsets start ON the rails (vertical and roll at the track input of their start
        # position): starting at zero on stiff track springs (300 MN/m per wheel) under 1–2 mm
        # of initial irregularity gave wheel-load jumps of ±400 kN and, with soft lateral rails,
        # a non-finite run from the first sample
        for i in range(nw):
            k = ws_body[i]
            i0, w1 = _locate(SC[S_START] + xabs[k], s_arr0, inv_ds, ngrid)
            w0 = 1.0 - w1
            q[k, 1] = TR[i0, T_ZV] * w0 + TR[i0 + 1, T_ZV] * w1
            u[k, 1] = v * (TR[i0, T_ZV1] * w0 + TR[i0 + 1, T_ZV1] * w1)
            q[k, 2] = (TR[i0, T_CL] * w0 + TR[i0 + 1, T_CL] * w1) / (2.0 * b0)
            u[k, 2] = v * (TR[i0, T_CL1] * w0 + TR[i0 + 1, T_CL1] * w1) / (2.0 * b0)
    for step in range(n_steps):
        s_cb = SC[S_START] + v * step * dt
        for k in range(nbody):
            sb[k] = s_cb + xabs[k]
            i0, w1 = _locate(sb[k], s_arr0, inv_ds, ngrid)
            bi[k] = i0
            bw[k] = w1
            kb[k] = TR[i0, T_KAP] * (1.0 - w1) + TR[i0 + 1, T_KAP] * w1
            pb[k] = TR[i0, T_PHI] * (1.0 - w1) + TR[i0 + 1, T_PHI] * w1
            aqb[k] = v * v * kb[k] - g * pb[k]
        # prescribed wheelset vertical/roll on rigid track (evaluated at the new time)
        if not tflex:
            for i in range(nw):
                k = ws_body[i]
                i0 = bi[k]
                w1 = bw[k]
                w0 = 1.0 - w1
                q[k, 1] = TR[i0, T_ZV] * w0 + TR[i0 + 1, T_ZV] * w1
                u[k, 1] = v * (TR[i0, T_ZV1] * w0 + TR[i0 + 1, T_ZV1] * w1)
                ws_az[i] = v * v * (TR[i0, T_ZV2] * w0 + TR[i0 + 1, T_ZV2] * w1)
                q[k, 2] = (TR[i0, T_CL] * w0 + TR[i0 + 1, T_CL] * w1) / (2.0 * b0)
                u[k, 2] = v * (TR[i0, T_CL1] * w0 + TR[i0 + 1, T_CL1] * w1) / (2.0 * b0)
                ws_aphi[i] = v * v * (TR[i0, T_CL2] * w0 + TR[i0 + 1, T_CL2] * w1) / (2.0 * b0)
        for k in range(nbody):
            for j in range(NDOF):
                F[k, j] = 0.0
            F[k, 0] = -massd[k, 0] * aqb[k]
        Fq = 0.0
        # ---------------------------------------------------------------- connections
        for c in range(nc):
            p = int(CONN[c, C_P])
            ch = int(CONN[c, C_C])
            x = CONN[c, C_X]
            zp = CONN[c, C_ZP]
            zc = CONN[c, C_ZC]
            phif = CONN[c, C_PHIF]
            kp_ = kb[p]
            kc_ = kb[ch]
            dy = x * x * (2.0 * kp_ + kc_) / 6.0
            dpsi = x * (kp_ + kc_) * 0.5
            dphi = pb[ch] - pb[p]
            py, pz, pph, pth, pps, px = q[p, 0], q[p, 1], q[p, 2], q[p, 3], q[p, 4], q[p, 5]
            vy, vz, vph, vth, vps, vx = u[p, 0], u[p, 1], u[p, 2], u[p, 3], u[p, 4], u[p, 5]
            cy_, cz_, cph, cth, cps, cx = (q[ch, 0] + dy, q[ch, 1], q[ch, 2] + dphi, q[ch, 3],
                                           q[ch, 4] + dpsi, q[ch, 5])
            wy, wz_, wph, wth, wps, wx = u[ch, 0], u[ch, 1], u[ch, 2], u[ch, 3], u[ch, 4], u[ch, 5]
            pfl = phif * qf
            pflv = phif * uf
            asym = CONN[c, C_ASYM]
            for side in range(3):
                # side 0: left spring (+b), 1: right spring (-b), 2: centre (lateral damper,
                # bump stop, traction rod)
                if side == 0:
                    yo = CONN[c, C_B]
                elif side == 1:
                    yo = -CONN[c, C_B]
                else:
                    yo = 0.0
                # relative displacement child point (0, yo, zc) minus parent point (x, yo, zp)
                dX = (cx + cth * zc - cps * yo) - (px + pth * zp - pps * yo)
                dY = (cy_ - cph * zc) - (py + pps * x - pph * zp)
                dZ = (cz_ + cph * yo) - (pz + pph * yo - pth * x + pfl)
                vX = (wx + wth * zc - wps * yo) - (vx + vth * zp - vps * yo)
                vY = (wy - wph * zc) - (vy + vps * x - vph * zp)
                vZ = (wz_ + wph * yo) - (vz + vph * yo - vth * x + pflv)
                fx = 0.0
                fy = 0.0
                fz = 0.0
                if side < 2:
                    fx = -CONN[c, C_KX] * dX
                    fy = -CONN[c, C_KY] * dY
                    fz = -CONN[c, C_KZ] * dZ
                    cz = CONN[c, C_CZ]
                    if cz > 0.0:
                        fd, st[c, side] = _damper(st[c, side], vZ, CONN[c, C_KSZ], cz, asym, emx[c, 0],
                                                  emx[c, 1], emx[c, 2])
                        fz -= fd
                    ff = CONN[c, C_FZ]
                    if ff > 0.0:
                        fr, st[c, 5 + side] = slider(dZ, st[c, 5 + side], CONN[c, C_KSTZ], ff)
                        fz -= fr
                    ff = CONN[c, C_FY]
                    if ff > 0.0:
                        fr, st[c, 7 + side] = slider(dY, st[c, 7 + side], CONN[c, C_KSTY], ff)
                        fy -= fr
                    ff = CONN[c, C_FX]
                    if ff > 0.0:
                        fr, st[c, 9 + side] = slider(dX, st[c, 9 + side], CONN[c, C_KSTX], ff)
                        fx -= fr
                else:
                    cyd = CONN[c, C_CY]
                    if cyd > 0.0:
                        fd, st[c, 2] = _damper(st[c, 2], vY, CONN[c, C_KSY], cyd, 0.0, emx[c, 3], 0.0, 0.0)
                        fy -= fd
                    bsk = CONN[c, C_BSK]
                    if bsk > 0.0:
                        clr = CONN[c, C_BSCL]
                        if dY > clr:
                            fy -= bsk * (dY - clr)
                        elif dY < -clr:
                            fy -= bsk * (dY + clr)
                    fx = -CONN[c, C_KTR] * dX
                # apply to child at (0, yo, zc) and the reaction to parent at (x, yo, zp)
                F[ch, 0] += fy
                F[ch, 1] += fz
                F[ch, 2] += yo * fz - zc * fy
                F[ch, 3] += zc * fx
                F[ch, 4] += -yo * fx
                F[ch, 5] += fx
                F[p, 0] -= fy
                F[p, 1] -= fz
                F[p, 2] -= yo * fz - zp * fy
                F[p, 3] -= zp * fx - x * fz
                F[p, 4] -= x * fy - yo * fx
                F[p, 5] -= fx
                Fq -= phif * fz
            # yaw dampers (longitudinal, at +-b_yd), with series stiffness and force limit
            cyd = CONN[c, C_CYD]
            if cyd > 0.0:
                byd = CONN[c, C_BYD]
                ks = CONN[c, C_KSYD]
                flim = CONN[c, C_FYD]
                for side in range(2):
                    yo = byd if side == 0 else -byd
                    vX = (wx + wth * zc - wps * yo) - (vx + vth * zp - vps * yo)
                    fd, d1 = _damper(st[c, 3 + side], vX, ks, cyd, 0.0, emx[c, 4], 0.0, 0.0)
                    if flim > 0.0 and abs(fd) > flim:
                        # blow-off: the force stays at the limit, the dashpot takes the excess stroke
                        fd = flim if fd > 0.0 else -flim
                        if ks > 0.0:
                            d1 = fd / ks
                    st[c, 3 + side] = d1
                    fx = -fd
                    F[ch, 3] += zc * fx
                    F[ch, 4] += -yo * fx
                    F[ch, 5] += fx
                    F[p, 3] -= zp * fx
                    F[p, 4] -= -yo * fx
                    F[p, 5] -= fx
            kr = CONN[c, C_KROLL]
            if kr > 0.0:
                m = -kr * (cph - pph)
                F[ch, 2] += m
                F[p, 2] -= m
            kpy = CONN[c, C_KPYAW]
            if kpy > 0.0:
                m = -kpy * (cps - pps)
                F[ch, 4] += m
                F[p, 4] -= m
            # static load w: up on the parent at its attachment point, down on the child at the
            # same point (lateral/longitudinal weight shift and P-Δ of rolled/pitched bodies)
            w = CONN[c, C_W]
            if w != 0.0:
                F[p, 2] += -w * zp * pph
                F[p, 3] += -w * zp * pth
                F[ch, 2] += -w * ((py + pps * x - pph * zp) - cy_)
                F[ch, 3] += w * ((px + pth * zp) - cx)
        # ---------------------------------------------------------------- wheel–rail contact
        for i in range(nw):
            k = ws_body[i]
            i0 = bi[k]
            w1 = bw[k]
            w0 = 1.0 - w1
            yai = TR[i0, T_YA] * w0 + TR[i0 + 1, T_YA] * w1
            gai = TR[i0, T_GA] * w0 + TR[i0 + 1, T_GA] * w1
            yw = q[k, 0] - yai
            if not tflex:
                # wheel loads at this step from the wheelset's vertical/roll equilibrium with the
                # suspension forces of this step (lateral forces of the previous step in r0·ΣY)
                sumdq = massd[k, 1] * ws_az[i] - F[k, 1]
                difdq = (massd[k, 2] * ws_aphi[i] - F[k, 2] - r0 * (Yw[i, 0] + Yw[i, 1])) / b0
                Qw[i, 0] = q0 + 0.5 * (sumdq + difdq)
                Qw[i, 1] = q0 + 0.5 * (sumdq - difdq)
            else:
                # flexible track: wheel loads from the track springs at this step's positions
                zr = TR[i0, T_ZV] * w0 + TR[i0 + 1, T_ZV] * w1
                zr1 = v * (TR[i0, T_ZV1] * w0 + TR[i0 + 1, T_ZV1] * w1)
                cr = 0.5 * (TR[i0, T_CL] * w0 + TR[i0 + 1, T_CL] * w1)
                cr1 = 0.5 * v * (TR[i0, T_CL1] * w0 + TR[i0 + 1, T_CL1] * w1)
                dQL = SC[KTZ] * (zr + cr - q[k, 1] - b0 * q[k, 2]) + SC[CTZ] * (zr1 + cr1 - u[k, 1] - b0 * u[k, 2])
                dQR = SC[KTZ] * (zr - cr - q[k, 1] + b0 * q[k, 2]) + SC[CTZ] * (zr1 - cr1 - u[k, 1] + b0 * u[k, 2])
                Qw[i, 0] = q0 + dQL
                Qw[i, 1] = q0 + dQR
            yrel = yw - 0.5 * (dtr[i, 0] + dtr[i, 1])
            eL = yrel - 0.5 * gai - SC[YFR]
            eR = -yrel - 0.5 * gai - SC[YFR]
            if rrd:
                # measured profiles: Δr(y) interpolated in the table, each wheel's position on its
                # rail shifted by half the gauge deviation (r_L − r0 = Δr(y − g/2)/2, r_R − r0 =
                # −Δr(y + g/2)/2 for a symmetric pair); only the difference enters the creepages
                # (the wheelset's free spin takes the mean radius), split ±1/2 over the wheels
                drL = 0.25 * (table_value(RRD, 1, yrel - 0.5 * gai) + table_value(RRD, 1, yrel + 0.5 * gai))
                drR = -drL
            else:
                drL = SC[LAM] * yrel + (SC[LAM2] * eL if eL > 0.0 else 0.0)
                drR = -SC[LAM] * yrel + (SC[LAM2] * eR if eR > 0.0 else 0.0)
            xiL = -drL / r0 - b0 * u[k, 4] / v - b0 * kb[k]
            xiR = -drR / r0 + b0 * u[k, 4] / v + b0 * kb[k]
            xiy = u[k, 0] / v - q[k, 4]
            QL = Qw[i, 0]
            QR = Qw[i, 1]
            fL = cbrt_positive(QL / q0) ** 2 if QL > 0.0 else 0.0
            fR = cbrt_positive(QR / q0) ** 2 if QR > 0.0 else 0.0
            fxL = -SC[F11] * fL * xiL
            fyL = -SC[F22] * fL * xiy
            fxR = -SC[F11] * fR * xiR
            fyR = -SC[F22] * fR * xiy
            sL = 1.0
            sR = 1.0
            if SC[SAT] == 2.0:
                sL = _polach_factor(fxL, fyL, SC[MU] * max(QL, 0.0), SC[POL_KA], SC[POL_KS])
                sR = _polach_factor(fxR, fyR, SC[MU] * max(QR, 0.0), SC[POL_KA], SC[POL_KS])
                fxL *= sL
                fyL *= sL
                fxR *= sR
                fyR *= sR
            elif SC[SAT] > 0.0:
                sL = _sat_factor(fxL, fyL, SC[MU] * max(QL, 0.0))
                sR = _sat_factor(fxR, fyR, SC[MU] * max(QR, 0.0))
                fxL *= sL
                fyL *= sL
                fxR *= sR
                fyR *= sR
            # creep damping coefficients (secant, saturation included), integrated exponentially
            cimp[k, 0] = SC[F22] * (fL * sL + fR * sR) / v
            cimp[k, 4] = SC[F11] * b0 * b0 * (fL * sL + fR * sR) / v
            eg = 0.5 * table_value(RRD, 2, yrel) if rgam else SC[EPSG] * yrel
            YL = fyL - max(QL, 0.0) * (SC[GAM0] + eg)
            YR = fyR + max(QR, 0.0) * (SC[GAM0] - eg)
            if tflex:
                # each rail deflects quasi-statically under its tread force (massless lateral track;
                # the wheel pushes the rail with −Y: a rail deflects by −Y/k_rail); a second pass
                # makes the normal-force component consistent with the deflection (contraction
                # ≈ Q·ε/(b0·k)); the creep forces keep the first pass's rolling-radius difference
                dtr[i, 0] = -YL / kty
                dtr[i, 1] = -YR / kty
                yrel = yw - 0.5 * (dtr[i, 0] + dtr[i, 1])
                eg = 0.5 * table_value(RRD, 2, yrel) if rgam else SC[EPSG] * yrel
                YL = fyL - max(QL, 0.0) * (SC[GAM0] + eg)
                YR = fyR + max(QR, 0.0) * (SC[GAM0] - eg)
                dtr[i, 0] = -YL / kty
                dtr[i, 1] = -YR / kty
            dL = (yw - dtr[i, 0]) - 0.5 * gai - SC[CLEAR]
            if dL > 0.0:
                YL -= kfl * dL
            dR = -(yw - dtr[i, 1]) - 0.5 * gai - SC[CLEAR]
            if dR > 0.0:
                YR += kfl * dR
            Yw[i, 0] = YL
            Yw[i, 1] = YR
            F[k, 0] += YL + YR
            F[k, 4] += -b0 * fxL + b0 * fxR
            if tflex:
                F[k, 1] += Qw[i, 0] + Qw[i, 1] - 2.0 * q0
                F[k, 2] += b0 * (Qw[i, 0] - Qw[i, 1]) + r0 * (YL + YR)
            else:
                # rigid track: rail forces from the wheelset's vertical and roll equilibrium
                sumdq = massd[k, 1] * ws_az[i] - F[k, 1]
                difdq = (massd[k, 2] * ws_aphi[i] - F[k, 2] - r0 * (YL + YR)) / b0
                Qw[i, 0] = q0 + 0.5 * (sumdq + difdq)
                Qw[i, 1] = q0 + 0.5 * (sumdq - difdq)
        # flexible car body: first vertical bending mode
        if SC[FLEX] > 0.0:
            w0 = SC[FLEX_W]
            aq = Fq / SC[FLEX_M] - 2.0 * SC[FLEX_Z] * w0 * uf - w0 * w0 * qf
            uf += dt * aq
            qf += dt * uf
        else:
            aq = 0.0
        # ---------------------------------------------------------------- integrate
        for k in range(nbody):
            for j in range(NDOF):
                if free[k, j]:
                    ci = cimp[k, j]
                    if ci > 0.0:
                        # exponential update: exact for the damping term −c·u with the other forces
                        # held over the step
                        ee = math.exp(-ci * dt / massd[k, j])
                        un = u[k, j] * ee + (F[k, j] + ci * u[k, j]) / ci * (1.0 - ee)
                        a = (un - u[k, j]) / dt
                        u[k, j] = un
                    else:
                        a = F[k, j] / massd[k, j]
                        u[k, j] += dt * a
                    acc[k, j] = a
                    q[k, j] += dt * u[k, j]
        # ---------------------------------------------------------------- outputs
        col = 0
        for i in range(nw):
            acc_blk[col] += Yw[i, 0] * 1e-3
            acc_blk[col + 1] += Yw[i, 1] * 1e-3
            acc_blk[col + 2] += Qw[i, 0] * 1e-3
            acc_blk[col + 3] += Qw[i, 1] * 1e-3
            col += 4
        zs = SC[ZSENS]
        for si in range(2):
            xs = SC[XS1] if si == 0 else SC[XS2]
            phs = SC[PHI_S1] if si == 0 else SC[PHI_S2]
            ss = s_cb + xs
            i0, w1 = _locate(ss, s_arr0, inv_ds, ngrid)
            aqs = (v * v * (TR[i0, T_KAP] * (1.0 - w1) + TR[i0 + 1, T_KAP] * w1)
                   - g * (TR[i0, T_PHI] * (1.0 - w1) + TR[i0 + 1, T_PHI] * w1))
            acc_blk[col + si] += acc[0, 0] + xs * acc[0, 4] - zs * acc[0, 2] + aqs + g * q[0, 2]
            acc_blk[col + 2 + si] += acc[0, 1] - xs * acc[0, 3] + phs * aq
        col += 4
        for j in range(nb):
            k = bogie_body[j]
            acc_blk[col + 2 * j] += acc[k, 0] + aqb[k] + g * q[k, 2]
            acc_blk[col + 2 * j + 1] += acc[k, 1]
        if nch > ncol_std:
            for i in range(nw):
                acc_blk[ncol_std + i] += q[ws_body[i], 0]
            acc_blk[ncol_std + nw] += q[0, 1]
            acc_blk[ncol_std + nw + 1] += q[0, 3]
            acc_blk[ncol_std + nw + 2] += q[0, 0]
            for j in range(nb):
                acc_blk[ncol_std + nw + 3 + j] += q[bogie_body[j], 0]
        cnt += 1
        if cnt == decim:
            if k_out < out.shape[0]:
                for j in range(nch):
                    out[k_out, j] = acc_blk[j] / decim
            for j in range(nch):
                acc_blk[j] = 0.0
            k_out += 1
            cnt = 0
    return k_out
