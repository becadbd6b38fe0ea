"""Sprague–Geers magnitude, phase and comprehensive error factors.

For a measured signal ``m_i`` and a simulated signal ``c_i`` (same sampling rate, same length,
``i = 1 … n``), with ``ψ_mm = Σ m_i²``, ``ψ_cc = Σ c_i²``, ``ψ_cm = Σ c_i m_i``:

* magnitude  ``M = sqrt(ψ_cc / ψ_mm) − 1``                       (Polach & Böttcher 2014 eq. 1)
* phase      ``P = arccos(ψ_cm / sqrt(ψ_cc ψ_mm)) / π``           (Polach & Böttcher 2014 eq. 2)
* comprehensive ``C = sqrt(M² + P²)``                             (Polach & Böttcher 2014 eq. 3)

``M`` is dimensionless, ``M ∈ (−1, ∞)``, 0 for equal energy (``c = k·m`` gives ``M = k − 1``);
``P ∈ [0, 1]``, 0 for curves in phase, 1 for opposite sign (a sinusoid shifted by ``φ`` over
whole periods gives ``P = φ/π``); ``C ≥ 0``. Sprague & Geers define these with time integrals;
on a common uniform grid the sampling interval cancels and the sums are exact equivalents
(Polach & Böttcher 2014 §3.3, citing [10]).

References
----------
Sprague, M. A. & Geers, T. L. (2004) A spectral-element method for modelling cavitation in
transient fluid–structure interaction. Int. J. Numer. Meth. Engng 60, 2467–2499 (error factors).
Polach, O. & Böttcher, A. (2014) A new approach to define criteria for rail vehicle model
validation. Vehicle System Dynamics 52 sup1, 125–141 (Polach & Böttcher 2014), §3.3 eq. (1)–(3).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

from railval.core.errors import InvalidSignal
from railval.core.metrics._checks import as_pair


@dataclass(frozen=True)
class SpragueGeers:
    """Sprague–Geers error factors (dimensionless): ``M`` magnitude, ``P`` phase, ``C`` comprehensive."""

    M: float
    P: float
    C: float

    def to_dict(self) -> dict[str, float]:
        return asdict(self)


def energies(measured: np.ndarray, simulated: np.ndarray) -> tuple[float, float, float]:
    """Return ``(ψ_mm, ψ_cc, ψ_cm)``; raises :class:`InvalidSignal` if a signal is all zero.

    Parameters
    ----------
    measured, simulated : numpy.ndarray
        Signals, shape (N,), same unit u.

    Returns
    -------
    tuple of float
        ``(ψ_mm, ψ_cc, ψ_cm)`` in u².
    """
    m, c = as_pair(measured, simulated, min_len=1)
    psi_mm = float(np.dot(m, m))
    psi_cc = float(np.dot(c, c))
    psi_cm = float(np.dot(c, m))
    if psi_mm == 0.0:
        raise InvalidSignal("measured signal is identically zero: Σm² = 0, magnitude and phase undefined")
    if psi_cc == 0.0:
        raise InvalidSignal("simulated signal is identically zero: Σc² = 0, phase undefined")
    return psi_mm, psi_cc, psi_cm


def normalised_correlation(psi_mm: float, psi_cc: float, psi_cm: float) -> float:
    """``ψ_cm / sqrt(ψ_cc ψ_mm)`` clipped to [−1, 1] (rounding can exceed 1 by ~1e-16).

    Parameters
    ----------
    psi_mm, psi_cc, psi_cm : float
        The energies of :func:`energies`.

    Returns
    -------
    float
        In [−1, 1].
    """
    return float(np.clip(psi_cm / np.sqrt(psi_cc * psi_mm), -1.0, 1.0))


def sprague_geers(measured: np.ndarray, simulated: np.ndarray) -> SpragueGeers:
    """Sprague–Geers error factors of ``simulated`` against ``measured`` (Polach & Böttcher 2014 eq. 1–3).

    Parameters
    ----------
    measured, simulated : 1-D arrays of equal length on one uniform grid (any unit, the same
        for both).

    Returns
    -------
    SpragueGeers with ``M`` (≥ −1), ``P`` (0…1), ``C`` (≥ 0), all dimensionless.

    Examples
    --------
    >>> t = np.linspace(0, 1, 1000, endpoint=False)
    >>> r = sprague_geers(np.sin(2*np.pi*5*t), 1.2*np.sin(2*np.pi*5*t))
    >>> round(r.M, 12), round(r.P, 6)
    (0.2, 0.0)
    """
    psi_mm, psi_cc, psi_cm = energies(measured, simulated)
    mag = float(np.sqrt(psi_cc / psi_mm) - 1.0)
    phase = float(np.arccos(normalised_correlation(psi_mm, psi_cc, psi_cm)) / np.pi)
    return SpragueGeers(M=mag, P=phase, C=float(np.hypot(mag, phase)))
