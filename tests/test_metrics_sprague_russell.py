"""Sprague–Geers and Russell error factors against closed forms and hand computations.

Closed forms: for ``m = sin(ω t)`` sampled uniformly over whole periods (N > 2·periods),
``Σ sin(a_i) sin(a_i + φ) = N/2 · cos φ`` and ``Σ sin²(a_i + φ) = N/2`` exactly (discrete
orthogonality), so ``c = sin(ωt + φ)`` gives M = 0, P = φ/π; ``c = k·m`` gives M = k − 1,
P = 0. Tolerances: 1e-12 for M (sums of O(N) terms); 1e-7 for P near 0 because arccos has
infinite slope at 1 (a rounding error of 1e-16 in the cosine gives ~1.5e-8 in P).
"""

import math

import numpy as np
import pytest

from railval.core.errors import InvalidSignal
from railval.core.metrics import russell, sprague_geers

N = 1000
PERIODS = 7
A = 2 * np.pi * PERIODS * np.arange(N) / N


@pytest.mark.parametrize("k", [0.5, 0.9, 1.0, 1.3, 2.0])
def test_sg_scaling_closed_form(k):
    r = sprague_geers(np.sin(A), k * np.sin(A))
    assert r.M == pytest.approx(k - 1, abs=1e-12)
    assert r.P == pytest.approx(0.0, abs=1e-7)
    assert r.C == pytest.approx(abs(k - 1), abs=1e-7)


@pytest.mark.parametrize("phi", [0.1, 0.5, 1.0, np.pi / 2, 2.5, np.pi])
def test_sg_phase_shift_closed_form(phi):
    r = sprague_geers(np.sin(A), np.sin(A + phi))
    assert r.M == pytest.approx(0.0, abs=1e-12)
    assert r.P == pytest.approx(phi / np.pi, abs=1e-7)
    assert r.C == pytest.approx(phi / np.pi, abs=1e-7)


def test_sg_hand_example():
    # m = [1, 2, 3], c = [2, 2, 2]: Σm² = 14, Σc² = 12, Σcm = 12
    r = sprague_geers([1.0, 2.0, 3.0], [2.0, 2.0, 2.0])
    m_expected = math.sqrt(12 / 14) - 1
    p_expected = math.acos(12 / math.sqrt(12 * 14)) / math.pi
    assert r.M == pytest.approx(m_expected, rel=1e-14)
    assert r.P == pytest.approx(p_expected, rel=1e-12)
    assert r.C == pytest.approx(math.hypot(m_expected, p_expected), rel=1e-12)


@pytest.mark.parametrize("k", [0.5, 0.8, 1.0, 1.25, 2.0, 3.0])
def test_russell_scaling_closed_form(k):
    r = russell(np.sin(A), k * np.sin(A))
    rel = (k * k - 1) / k  # (A − B)/sqrt(AB) with A = k²B
    rm = math.copysign(math.log10(1 + abs(rel)), rel) if rel else 0.0
    assert r.RM == pytest.approx(rm, abs=1e-12)
    assert r.RP == pytest.approx(0.0, abs=1e-7)
    assert r.RC == pytest.approx(math.sqrt(math.pi / 4) * abs(rm), abs=1e-7)


@pytest.mark.parametrize("phi", [0.2, 1.0, 3.0])
def test_russell_phase_closed_form(phi):
    r = russell(np.sin(A), np.sin(A + phi))
    assert r.RM == pytest.approx(0.0, abs=1e-12)
    assert r.RP == pytest.approx(phi / np.pi, abs=1e-7)
    assert r.RC == pytest.approx(math.sqrt(math.pi / 4 * (phi / np.pi) ** 2), abs=1e-7)


@pytest.mark.parametrize("k", [1.5, 2.0, 4.0])
def test_russell_magnitude_is_symmetric(k):
    # Russell's log form: over- and under-prediction by the same factor give ±RM
    up = russell(np.sin(A), k * np.sin(A)).RM
    down = russell(np.sin(A), np.sin(A) / k).RM
    assert up == pytest.approx(-down, rel=1e-12)
    assert up > 0


def test_zero_signal_raises():
    with pytest.raises(InvalidSignal, match="measured signal is identically zero"):
        sprague_geers(np.zeros(5), np.ones(5))
    with pytest.raises(InvalidSignal, match="simulated"):
        russell(np.ones(5), np.zeros(5))


def test_unequal_length_raises():
    with pytest.raises(InvalidSignal, match="equal length"):
        sprague_geers(np.ones(5), np.ones(6))


def test_nan_raises():
    with pytest.raises(InvalidSignal, match="non-finite"):
        sprague_geers(np.array([1.0, np.nan]), np.ones(2))
