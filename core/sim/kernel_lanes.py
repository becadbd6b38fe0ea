"""Several parameter sets of one model structure integrated side by side (lanes).

A diagnosis simulates one section under many parameter sets (its candidates' scan points); runs
that share the step, the step count, the track input, the contact table and the model's
structure differ only in numbers. :func:`run_lanes` integrates such runs together and writes each
run's output exactly as :func:`railval.core.sim.kernel.run_kernel` writes it alone (the same
operations in the same order per run, so the same bits: tests/test_sim_kernel_lanes.py).
:func:`lane_key` says which runs may share a call.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from railval.core.sim import kernel as K

#: runs integrated in one compiled call (the processor's vector width in doubles)
LANES = 4

#: connection columns whose presence (> 0) selects a branch of the step
_PRESENT = (K.C_CZ, K.C_KSZ, K.C_FZ, K.C_FY, K.C_FX, K.C_CY, K.C_KSY, K.C_BSK, K.C_CYD, K.C_KSYD, K.C_FYD,
            K.C_KROLL, K.C_KPYAW)


def lane_key(SC: np.ndarray, massd: np.ndarray, free: np.ndarray, xabs: np.ndarray, CONN: np.ndarray,
             ws_body: np.ndarray, bogie_body: np.ndarray, RRD: np.ndarray) -> bytes:
    """What runs must share to be integrated in one :func:`run_lanes` call, besides the step,
    the step count, the output decimation and the track input (the caller's): the bodies and
    connections (which body each connects, which elements each has: dampers, series springs,
    asymmetry, friction, bump stops, yaw dampers and their limit, anti-roll bars, yaw
    stiffnesses, static loads), the kernel's switches (flexible track, contact table, creep law,
    flexible car body), the speed, gravity, start position and body positions (the track is
    located once for all lanes) and the contact table. Everything else is a number per lane."""
    flags = np.concatenate([(CONN[:, _PRESENT] > 0.0).ravel(), CONN[:, K.C_ASYM] != 0.0, CONN[:, K.C_W] != 0.0])
    switches = np.array([SC[K.TFLEX] > 0.0, SC[K.RRD_ON] > 0.0, SC[K.RRD_GAM] > 0.0, SC[K.FLEX] > 0.0])
    shared = np.array([SC[K.V], SC[K.GRAV], SC[K.S_START], SC[K.SAT]])
    return b"|".join([
        np.asarray(massd.shape, dtype=np.int64).tobytes(), np.asarray(CONN.shape, dtype=np.int64).tobytes(),
        CONN[:, [K.C_P, K.C_C]].tobytes(), flags.tobytes(), switches.tobytes(), shared.tobytes(),
        np.ascontiguousarray(free).tobytes(), np.ascontiguousarray(xabs).tobytes(),
        np.ascontiguousarray(ws_body).tobytes(), np.ascontiguousarray(bogie_body).tobytes(),
        np.ascontiguousarray(RRD).tobytes()])


def run_lanes(SCs: Sequence[np.ndarray], massds: Sequence[np.ndarray], free: np.ndarray, xabs: np.ndarray,
              CONNs: Sequence[np.ndarray], ws_body: np.ndarray, bogie_body: np.ndarray, s_arr0: float, ds: float,
              TR: np.ndarray, n_steps: int, dt: float, decim: int, outs: Sequence[np.ndarray],
              RRD: np.ndarray) -> list[int]:
    """Integrate one run per lane (``SCs[i]``, ``massds[i]``, ``CONNs[i]`` into ``outs[i]``; every
    run with the same :func:`lane_key`, the same step ``dt``, ``n_steps``, ``decim`` and track
    input) and fill each ``outs[i]`` as :func:`railval.core.sim.kernel.run_kernel` does; returns
    each run's number of output blocks."""
    return [K.run_kernel(SCs[i], massds[i], free, xabs, CONNs[i], ws_body, bogie_body, s_arr0, ds, TR, n_steps,
                         dt, decim, outs[i], RRD) for i in range(len(SCs))]
