"""Tests of core.modal: MAC, pairing and SSI-COV on a system with known modes."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.linalg import eigh, expm

from railval.core.errors import InvalidParameter, InvalidSignal
from railval.core.modal import (
    mac,
    mac_matrix,
    modes_from_matrices,
    output_covariances,
    pair_modes,
    ssi_cov,
)


def chain_system(m=(1.0, 1.5, 1.0), k=(4000.0, 3000.0, 3000.0), zeta=0.02):
    """3-DOF spring–mass chain fixed at one end, Rayleigh-free modal damping ``zeta`` on every
    mode. Returns M, K, C, the undamped natural frequencies (Hz) and mass-normalised shapes —
    the expectation computed independently by ``scipy.linalg.eigh`` (generalised problem)."""
    M = np.diag(m)
    k1, k2, k3 = k
    K = np.array([[k1 + k2, -k2, 0.0], [-k2, k2 + k3, -k3], [0.0, -k3, k3]])
    w2, Phi = eigh(K, M)
    w = np.sqrt(w2)
    # modal damping matrix C = M Φ diag(2ζω) Φᵀ M (Φ mass-normalised)
    C = M @ Phi @ np.diag(2 * zeta * w) @ Phi.T @ M
    return M, K, C, w / (2 * np.pi), Phi


def simulate_accelerations(M, K, C, fs, n, seed=0, noise=0.02):
    """Accelerations of the chain under independent white-noise forces at every mass, exact
    zero-order-hold discretisation (matrix exponential), plus white sensor noise."""
    rng = np.random.default_rng(seed)
    nd = M.shape[0]
    Minv = np.linalg.inv(M)
    Ac = np.block([[np.zeros((nd, nd)), np.eye(nd)], [-Minv @ K, -Minv @ C]])
    Bc = np.vstack([np.zeros((nd, nd)), Minv])
    dt = 1.0 / fs
    big = expm(np.block([[Ac, Bc], [np.zeros((nd, 2 * nd + nd))]]) * dt)
    Ad, Bd = big[: 2 * nd, : 2 * nd], big[: 2 * nd, 2 * nd:]
    Cc = np.hstack([-Minv @ K, -Minv @ C])
    u = rng.standard_normal((n, nd))
    x = np.zeros(2 * nd)
    y = np.empty((n, nd))
    for t in range(n):
        y[t] = Cc @ x + Minv @ u[t]
        x = Ad @ x + Bd @ u[t]
    y += noise * y.std(axis=0) * rng.standard_normal(y.shape)
    return y


def test_mac_identical_scaled_and_orthogonal():
    a = np.array([1.0, 2.0, -0.5])
    assert mac(a, a) == pytest.approx(1.0)
    assert mac(a, -3.7 * a) == pytest.approx(1.0)
    assert mac(a, (2 - 1j) * a) == pytest.approx(1.0)
    b = np.array([2.0, -1.0, 0.0])  # a·b = 0 by hand
    assert mac(a, b) == pytest.approx(0.0, abs=1e-15)
    # hand computation: (1·1 + 2·1)² / ((1+4)(1+1)) = 9/10
    assert mac([1.0, 2.0], [1.0, 1.0]) == pytest.approx(0.9)
    M = mac_matrix(np.column_stack([a, b]), np.column_stack([b, a]))
    np.testing.assert_allclose(M, [[0.0, 1.0], [1.0, 0.0]], atol=1e-15)


def test_mac_rejects_bad_shapes():
    with pytest.raises(InvalidSignal):
        mac([1.0, 2.0], [1.0, 2.0, 3.0])
    with pytest.raises(InvalidSignal):
        mac([0.0, 0.0], [1.0, 2.0])


def test_pair_modes_by_highest_mac_one_to_one():
    ref = np.array([[1.0, 1.0], [1.0, -1.0]])
    other = np.array([[1.0, 0.9, 1.0], [-1.0, 1.0, 0.1]])
    pairs = pair_modes(np.array([1.0, 2.0]), ref, np.array([2.1, 0.95, 5.0]), other)
    assert [(i, j) for i, j, _ in pairs] == [(0, 1), (1, 0)]
    assert pairs[1][2] == pytest.approx(1.0)


def test_output_covariances_against_direct_sum():
    rng = np.random.default_rng(3)
    y = rng.standard_normal((200, 2))
    R = output_covariances(y, 5)
    for k in range(6):
        direct = y[k:].T @ y[: 200 - k] / (200 - k)
        np.testing.assert_allclose(R[k], direct, atol=1e-12)
    with pytest.raises(InvalidParameter):
        output_covariances(y, 200)


def test_modes_from_matrices_single_oscillator():
    # discrete model of one oscillator: λ = exp(μ/fs), μ = −ζω ± iω√(1−ζ²)
    fs, f, z = 100.0, 2.0, 0.05
    w = 2 * np.pi * f
    mu = -z * w + 1j * w * np.sqrt(1 - z * z)
    lam = np.exp(mu / fs)
    A = np.array([[lam.real, -lam.imag], [lam.imag, lam.real]])
    freq, damp, _shapes = modes_from_matrices(A, np.array([[1.0, 0.0]]), fs)
    assert freq[0] == pytest.approx(f, rel=1e-10)
    assert damp[0] == pytest.approx(z, rel=1e-10)


def test_ssi_cov_identifies_three_dof_chain():
    M, K, C, f_true, Phi = chain_system()
    fs = 100.0
    y = simulate_accelerations(M, K, C, fs, 30_000, seed=1)
    res = ssi_cov(y, fs, f_min=0.5, f_max=30.0, block_rows=40, max_order=30)
    assert len(res.modes) >= 3
    # damped natural frequency = f·√(1−ζ²); with ζ = 0.02 that is 0.02 % below f
    for f, phi in zip(f_true, Phi.T, strict=True):
        k = int(np.argmin(np.abs(res.frequencies - f)))
        mode = res.modes[k]
        assert mode.freq_hz == pytest.approx(f, rel=0.02)
        assert 0.01 < mode.damping < 0.04  # true 0.02; random-error spread of SSI damping
        assert mac(mode.shape, phi) > 0.98
    diagram = res.stabilisation_diagram()
    assert any(r["stable"] for r in diagram) and any(not r["stable"] for r in diagram)
    d = res.to_dict()
    assert len(d["modes"]) == len(res.modes) and d["criteria"]["mac_min"] == 0.98


def test_ssi_cov_rejects_nan_and_too_high_order():
    y = np.zeros((100, 2))
    y[5, 0] = np.nan
    with pytest.raises(InvalidSignal):
        ssi_cov(y, 50.0)
    with pytest.raises(InvalidParameter):
        ssi_cov(np.random.default_rng(0).standard_normal((500, 2)), 50.0, block_rows=3, max_order=10)


def test_ssi_cov_several_records_equal_one_long_record_modes():
    M, K, C, f_true, _ = chain_system()
    y = simulate_accelerations(M, K, C, 100.0, 30_000, seed=2)
    parts = [y[:10_000], y[10_000:20_000], y[20_000:]]
    res = ssi_cov(parts, 100.0, f_min=0.5, f_max=30.0, block_rows=40, max_order=30)
    for f in f_true:
        assert np.min(np.abs(res.frequencies - f)) < 0.02 * f
    with pytest.raises(InvalidSignal):
        ssi_cov([y[:1000, :2], y[:1000]], 100.0)
