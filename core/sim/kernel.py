"""The numba-compiled time integration loop of the built-in simulator.

Bodies (car body, bogie frames, wheelsets) each carry five coordinates relative to the local
track frame at their own position along the track (y lateral, z vertical, φ roll, θ pitch,
ψ yaw; x forward, y left, z up; small rotations). Connections (secondary: car body → bogie or
car body → wheelset; primary: bogie → wheelset) are springs, dampers (optionally Maxwell with a
series stiffness), Saint-Venant friction elements, bump stops, anti-roll bars and yaw
stiffnesses acting between attachment points; the track frame of a child differs from its
parent's by the curve geometry (lateral offset x²(2κ_p+κ_c)/6, yaw x(κ_p+κ_c)/2, exact for a
linear curvature ramp, and the cant difference).

Integration: semi-implicit (symplectic) Euler with a fixed step; Maxwell dampers use the exact
exponential update of their internal stroke and friction sliders a return map, so the
integration is stable with the flange, bump-stop and track springs for ω·dt < 2 (checked by
the caller's choice of dt). Output: block means over ``decim`` steps (anti-alias boxcar).

The equations (quasi-static acceleration in the track plane a_q = v²κ − g·φ_t, Kalker linear
creep with Shen–Hedrick–Elkins saturation, gravitational stiffness via the contact angle,
flange contact as a stiff spring beyond the clearance) are documented in ``docs/simulator.md``
and in :mod:`railval.core.sim.model`.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

# --- scalar parameter indices (SC array)
V, GRAV, NW, R0, B0, LAM, LAM2, YFR, CLEAR, KFL, GAM0, EPSG = range(12)
F11, F22, Q0, MU, SAT, TFLEX, KTZ, CTZ, KTY, CTY, MTY = range(12, 23)
FLEX, FLEX_W, FLEX_Z, FLEX_M, ZSENS, S_START, PHI_S1, PHI_S2, XS1, XS2 = range(23, 33)
Y_INIT, Z_INIT, TH_INIT = range(33, 36)  # initial conditions (verification tests)
NSC = 36

# --- connection columns (CONN array)
(C_P, C_C, C_X, C_B, C_ZP, C_ZC, C_KX, C_KY, C_KZ, C_CZ, C_CY, C_BYD, C_CYD, C_KSYD, C_KSZ,
 C_KSY, C_KROLL, C_KPYAW, C_BSCL, C_BSK, C_FZ, C_FY, C_FX, C_KSTZ, C_KSTY, C_ASYM, C_W,
 C_PHIF) = range(28)
NCC = 28


@njit(cache=True, inline="always")
def _interp(arr, s, s0, inv_ds, n):
    f = (s - s0) * inv_ds
    if f <= 0.0:
        return arr[0]
    i = int(f)
    if i >= n - 1:
        return arr[n - 1]
    w = f - i
    return arr[i] * (1.0 - w) + arr[i + 1] * w


@njit(cache=True, inline="always")
def _sat(fx, fy, mu_q):
    """Shen–Hedrick–Elkins (1983) saturation of the linear creep force resultant at μ·Q."""
    f = math.sqrt(fx * fx + fy * fy)
    if mu_q <= 0.0:
        return 0.0, 0.0
    if f <= 1e-12:
        return fx, fy
    b = f / mu_q
    if b < 3.0:
        fac = (b - b * b / 3.0 + b * b * b / 27.0) / b
    else:
        fac = 1.0 / b
    return fx * fac, fy * fac


@njit(cache=True)
def run_kernel(SC, massd, free, xabs, CONN, ws_body, bogie_body, s_arr0, ds, kap, phit, zv, zv1, zv2,
               cl, cl1, cl2, ya, ga, n_steps, dt, decim, out):
    """Integrate ``n_steps`` steps of ``dt`` s; write ``out[n_steps // decim, nch]`` block means.

    Output columns: per wheelset i: Y_L, Y_R, Q_L, Q_R (kN) at 4i..4i+3; then car body ay at
    sensor 1, 2, az at sensor 1, 2 (m/s²); then per bogie ay, az (m/s²); if ``out`` has more
    columns: the wheelsets' lateral displacements (m), then car body z (m) and pitch (rad).
    """
    nbody = massd.shape[0]
    nc = CONN.shape[0]
    nw = ws_body.shape[0]
    nb = bogie_body.shape[0]
    ngrid = kap.shape[0]
    inv_ds = 1.0 / ds
    v = SC[V]
    g = SC[GRAV]
    b0 = SC[B0]
    r0 = SC[R0]
    q = np.zeros((nbody, 5))
    u = np.zeros((nbody, 5))
    F = np.zeros((nbody, 5))
    acc = np.zeros((nbody, 5))
    st = np.zeros((nc, 12))  # internal states of Maxwell dampers and friction sliders
    qf = 0.0
    uf = 0.0
    dtr = np.zeros(nw)  # lateral track deflection per wheelset
    dtrv = np.zeros(nw)
    Qw = np.full((nw, 2), SC[Q0])
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
    for step in range(n_steps):
        s_cb = SC[S_START] + v * (step + 1) * dt
        for k in range(nbody):
            sb[k] = s_cb + xabs[k]
            kb[k] = _interp(kap, sb[k], s_arr0, inv_ds, ngrid)
            pb[k] = _interp(phit, sb[k], s_arr0, inv_ds, ngrid)
            aqb[k] = v * v * kb[k] - g * pb[k]
        # prescribed wheelset vertical/roll on rigid track (evaluated at the new time)
        for i in range(nw):
            k = ws_body[i]
            s = sb[k]
            if SC[TFLEX] == 0.0:
                q[k, 1] = _interp(zv, s, s_arr0, inv_ds, ngrid)
                u[k, 1] = v * _interp(zv1, s, s_arr0, inv_ds, ngrid)
                ws_az[i] = v * v * _interp(zv2, s, s_arr0, inv_ds, ngrid)
                q[k, 2] = _interp(cl, s, s_arr0, inv_ds, ngrid) / (2.0 * b0)
                u[k, 2] = v * _interp(cl1, s, s_arr0, inv_ds, ngrid) / (2.0 * b0)
                ws_aphi[i] = v * v * _interp(cl2, s, s_arr0, inv_ds, ngrid) / (2.0 * b0)
        for k in range(nbody):
            for j in range(5):
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
            # parent pose
            py, pz, pph, pth, pps = q[p, 0], q[p, 1], q[p, 2], q[p, 3], q[p, 4]
            vy, vz, vph, vth, vps = u[p, 0], u[p, 1], u[p, 2], u[p, 3], u[p, 4]
            cy_, cz_, cph, cth, cps = q[ch, 0] + dy, q[ch, 1], q[ch, 2] + dphi, q[ch, 3], q[ch, 4] + dpsi
            wy, wz_, wph, wth, wps = u[ch, 0], u[ch, 1], u[ch, 2], u[ch, 3], u[ch, 4]
            pfl = phif * qf
            pflv = phif * uf
            for side in range(3):
                # side 0: left spring (+b), 1: right spring (-b), 2: centre (lateral damper/bump stop)
                if side == 0:
                    yo = CONN[c, C_B]
                elif side == 1:
                    yo = -CONN[c, C_B]
                else:
                    yo = 0.0
                # relative displacement child point (0, yo, zc) minus parent point (x, yo, zp)
                dX = (cth * zc - cps * yo) - (pth * zp - pps * yo)
                dY = (cy_ - cph * zc) - (py + pps * x - pph * zp)
                dZ = (cz_ + cph * yo) - (pz + pph * yo - pth * x + pfl)
                vX = (wth * zc - wps * yo) - (vth * zp - vps * yo)
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
                        asym = CONN[c, C_ASYM]
                        ks = CONN[c, C_KSZ]
                        if ks > 0.0:
                            e = st[c, side]
                            fd = ks * (dZ - e)
                            ceff = cz * (1.0 + asym * (1.0 if fd > 0 else -1.0))
                            st[c, side] = dZ - (dZ - e) * math.exp(-ks * dt / ceff)
                            fz -= fd
                        else:
                            fz -= cz * vZ * (1.0 + asym * (1.0 if vZ > 0 else -1.0))
                    ff = CONN[c, C_FZ]
                    if ff > 0.0:
                        kst = CONN[c, C_KSTZ]
                        fr = kst * (dZ - st[c, 5 + side])
                        if fr > ff:
                            fr = ff
                            st[c, 5 + side] = dZ - ff / kst
                        elif fr < -ff:
                            fr = -ff
                            st[c, 5 + side] = dZ + ff / kst
                        fz -= fr
                    ff = CONN[c, C_FY]
                    if ff > 0.0:
                        kst = CONN[c, C_KSTY]
                        fr = kst * (dY - st[c, 7 + side])
                        if fr > ff:
                            fr = ff
                            st[c, 7 + side] = dY - ff / kst
                        elif fr < -ff:
                            fr = -ff
                            st[c, 7 + side] = dY + ff / kst
                        fy -= fr
                    ff = CONN[c, C_FX]
                    if ff > 0.0:
                        kst = CONN[c, C_KSTY]
                        fr = kst * (dX - st[c, 9 + side])
                        if fr > ff:
                            fr = ff
                            st[c, 9 + side] = dX - ff / kst
                        elif fr < -ff:
                            fr = -ff
                            st[c, 9 + side] = dX + ff / kst
                        fx -= fr
                else:
                    cyd = CONN[c, C_CY]
                    if cyd > 0.0:
                        ks = CONN[c, C_KSY]
                        if ks > 0.0:
                            e = st[c, 2]
                            fd = ks * (dY - e)
                            st[c, 2] = dY - (dY - e) * math.exp(-ks * dt / cyd)
                            fy -= fd
                        else:
                            fy -= cyd * vY
                    bsk = CONN[c, C_BSK]
                    if bsk > 0.0:
                        clr = CONN[c, C_BSCL]
                        if dY > clr:
                            fy -= bsk * (dY - clr)
                        elif dY < -clr:
                            fy -= bsk * (dY + clr)
                # apply to child at (0, yo, zc) and the reaction to parent at (x, yo, zp)
                F[ch, 0] += fy
                F[ch, 1] += fz
                F[ch, 2] += yo * fz - zc * fy
                F[ch, 3] += zc * fx
                F[ch, 4] += -yo * fx
                F[p, 0] -= fy
                F[p, 1] -= fz
                F[p, 2] -= yo * fz - zp * fy
                F[p, 3] -= zp * fx - x * fz
                F[p, 4] -= x * fy - yo * fx
                Fq -= phif * fz
            # yaw dampers (longitudinal, at +-b_yd)
            cyd = CONN[c, C_CYD]
            if cyd > 0.0:
                byd = CONN[c, C_BYD]
                ks = CONN[c, C_KSYD]
                for side in range(2):
                    yo = byd if side == 0 else -byd
                    dX = (cth * zc - cps * yo) - (pth * zp - pps * yo)
                    vX = (wth * zc - wps * yo) - (vth * zp - vps * yo)
                    if ks > 0.0:
                        e = st[c, 3 + side]
                        fx = -ks * (dX - e)
                        st[c, 3 + side] = dX - (dX - e) * math.exp(-ks * dt / cyd)
                    else:
                        fx = -cyd * vX
                    F[ch, 3] += zc * fx
                    F[ch, 4] += -yo * fx
                    F[p, 3] -= zp * fx
                    F[p, 4] -= -yo * fx
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
            # static preload acting on rotated attachment points (destabilising, P-delta)
            w = CONN[c, C_W]
            F[p, 2] += -w * zp * pph
            F[p, 3] += -w * zp * pth
            F[ch, 2] += w * zc * q[ch, 2]
            F[ch, 3] += w * zc * q[ch, 3]
        # ---------------------------------------------------------------- wheel–rail contact
        for i in range(nw):
            k = ws_body[i]
            s = sb[k]
            yai = _interp(ya, s, s_arr0, inv_ds, ngrid)
            gai = _interp(ga, s, s_arr0, inv_ds, ngrid)
            yrel = q[k, 0] - yai - dtr[i]
            eL = yrel - 0.5 * gai - SC[YFR]
            eR = -yrel - 0.5 * gai - SC[YFR]
            drL = SC[LAM] * yrel + (SC[LAM2] * eL if eL > 0.0 else 0.0)
            drR = -SC[LAM] * yrel + (SC[LAM2] * eR if eR > 0.0 else 0.0)
            xiL = -drL / r0 - b0 * u[k, 4] / v - b0 * kb[k]
            xiR = -drR / r0 + b0 * u[k, 4] / v + b0 * kb[k]
            xiy = (u[k, 0] - dtrv[i]) / v - q[k, 4]
            QL = Qw[i, 0]
            QR = Qw[i, 1]
            fL = (QL / SC[Q0]) ** (2.0 / 3.0) if QL > 0.0 else 0.0
            fR = (QR / SC[Q0]) ** (2.0 / 3.0) if QR > 0.0 else 0.0
            fxL = -SC[F11] * fL * xiL
            fyL = -SC[F22] * fL * xiy
            fxR = -SC[F11] * fR * xiR
            fyR = -SC[F22] * fR * xiy
            if SC[SAT] > 0.0:
                fxL, fyL = _sat(fxL, fyL, SC[MU] * max(QL, 0.0))
                fxR, fyR = _sat(fxR, fyR, SC[MU] * max(QR, 0.0))
            YL = fyL - max(QL, 0.0) * (SC[GAM0] + SC[EPSG] * yrel)
            YR = fyR + max(QR, 0.0) * (SC[GAM0] - SC[EPSG] * yrel)
            kfl = SC[KFL]
            if SC[TFLEX] > 0.0:
                # flange contact in series with the rail's own lateral (head/fastening) stiffness
                kfl = kfl * SC[KTY] / (kfl + SC[KTY])
            dL = yrel - 0.5 * gai - SC[CLEAR]
            if dL > 0.0:
                YL -= kfl * dL
            dR = -yrel - 0.5 * gai - SC[CLEAR]
            if dR > 0.0:
                YR += kfl * dR
            Yw[i, 0] = YL
            Yw[i, 1] = YR
            F[k, 0] += YL + YR
            F[k, 4] += -b0 * fxL + b0 * fxR
            if SC[TFLEX] > 0.0:
                # lateral track mass: m δ'' = -(Y_L + Y_R) - 2 k_rail δ - c δ'
                a_t = (-(YL + YR) - 2.0 * SC[KTY] * dtr[i] - SC[CTY] * dtrv[i]) / SC[MTY]
                dtrv[i] += dt * a_t
                dtr[i] += dt * dtrv[i]
                zr = _interp(zv, s, s_arr0, inv_ds, ngrid)
                zr1 = v * _interp(zv1, s, s_arr0, inv_ds, ngrid)
                cr = 0.5 * _interp(cl, s, s_arr0, inv_ds, ngrid)
                cr1 = 0.5 * v * _interp(cl1, s, s_arr0, inv_ds, ngrid)
                dQL = SC[KTZ] * (zr + cr - q[k, 1] - b0 * q[k, 2]) + SC[CTZ] * (zr1 + cr1 - u[k, 1] - b0 * u[k, 2])
                dQR = SC[KTZ] * (zr - cr - q[k, 1] + b0 * q[k, 2]) + SC[CTZ] * (zr1 - cr1 - u[k, 1] + b0 * u[k, 2])
                F[k, 1] += dQL + dQR
                F[k, 2] += b0 * (dQL - dQR) + r0 * (YL + YR)
                Qw[i, 0] = SC[Q0] + dQL
                Qw[i, 1] = SC[Q0] + dQR
            else:
                # rigid track: rail forces from the wheelset's vertical and roll equilibrium
                sumdq = massd[k, 1] * ws_az[i] - F[k, 1]
                difdq = (massd[k, 2] * ws_aphi[i] - F[k, 2] - r0 * (YL + YR)) / b0
                Qw[i, 0] = SC[Q0] + 0.5 * (sumdq + difdq)
                Qw[i, 1] = SC[Q0] + 0.5 * (sumdq - difdq)
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
            for j in range(5):
                if free[k, j]:
                    a = F[k, j] / massd[k, j]
                    acc[k, j] = a
                    u[k, j] += dt * a
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
            aqs = v * v * _interp(kap, ss, s_arr0, inv_ds, ngrid) - g * _interp(phit, ss, s_arr0, inv_ds, ngrid)
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
