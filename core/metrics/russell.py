"""Russell magnitude, phase and comprehensive error measures.

With ``A = Σ c_i²`` (simulated), ``B = Σ m_i²`` (measured) and ``ψ_cm = Σ c_i m_i``
(Russell 1997, Part I, eqs. for the "relative magnitude" and "phase correlation"):

* relative magnitude ``m = (A − B) / sqrt(A B)``
* magnitude error ``RM = sign(m) · log10(1 + |m|)``  (symmetric in over/under-prediction:
  ``c = k·m`` and ``c = m/k`` give ``|RM|`` equal with opposite sign)
* phase error ``RP = arccos(ψ_cm / sqrt(A B)) / π``  (0 in phase … 1 opposite; identical to
  the Sprague–Geers phase factor)
* comprehensive error ``RC = sqrt(π/4 · (RM² + RP²))``

All dimensionless. For ``c = k·m`` (k > 0): ``m = (k² − 1)/k``, ``RP = 0``.

References
----------
Russell, D. M. (1997) Error measures for comparing transient data: Part I: Development of a
comprehensive error measure; Part II: Error measures case study. Proc. 68th Shock and
Vibration Symposium, Hunt Valley MD, 175–198.
Schwer, L. E. (2007) Validation metrics for response histories: perspectives and case
studies. Engineering with Computers 23, 295–309 (comparison of Sprague–Geers and Russell).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

from railval.core.metrics.sprague_geers import energies, normalised_correlation


@dataclass(frozen=True)
class Russell:
    """Russell error measures (dimensionless): ``RM`` magnitude, ``RP`` phase, ``RC`` comprehensive."""

    RM: float
    RP: float
    RC: float

    def to_dict(self) -> dict[str, float]:
        return asdict(self)


def russell(measured: np.ndarray, simulated: np.ndarray) -> Russell:
    """Russell (1997) error measures of ``simulated`` against ``measured``.

    Parameters
    ----------
    measured, simulated : 1-D arrays of equal length on one uniform grid (same unit).

    Returns
    -------
    Russell with ``RM`` (signed, log10 scale), ``RP`` (0…1), ``RC`` (≥ 0).
    """
    b, a, psi_cm = energies(measured, simulated)  # b = Σm², a = Σc²
    rel = (a - b) / np.sqrt(a * b)
    rm = float(np.sign(rel) * np.log10(1.0 + abs(rel)))
    rp = float(np.arccos(normalised_correlation(b, a, psi_cm)) / np.pi)
    rc = float(np.sqrt(np.pi / 4.0 * (rm * rm + rp * rp)))
    return Russell(RM=rm, RP=rp, RC=rc)
