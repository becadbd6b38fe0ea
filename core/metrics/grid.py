"""Bring a measured and a simulated signal onto one uniform grid of equal length.

Every curve metric of docs/design.md §4 needs equally sampled, equally long signals. The common grid
is the measured grid (``fs_measured``, time ``t0_measured + i/fs_measured``) restricted to the
time span both records cover; the simulated signal is evaluated on it by linear
interpolation when its rate or time origin differ. The result says what was done (``resampled``,
``truncated`` and a human-readable ``note``) so the UI and CLI can tell the user.

Linear interpolation of a signal sampled well above its content (e.g. low-passed at 20 Hz and
sampled at ≥ 200 Hz) changes it negligibly; down-sampling a signal with content above the
new Nyquist frequency would alias, so low-pass first (``compare_signalsets`` does).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from railval.core.errors import InvalidSignal
from railval.core.metrics._checks import as_signal, positive


@dataclass(frozen=True)
class CommonGrid:
    """Measured and simulated samples on one grid: ``fs`` (Hz), ``t0`` (s) of the first sample."""

    measured: np.ndarray
    simulated: np.ndarray
    fs: float
    t0: float
    resampled: bool
    truncated: bool
    note: str

    def __len__(self) -> int:
        return int(self.measured.shape[0])


def common_grid(measured: np.ndarray, simulated: np.ndarray, fs_measured: float,
                fs_simulated: float | None = None, *, t0_measured: float = 0.0,
                t0_simulated: float = 0.0, min_len: int = 2) -> CommonGrid:
    """Put ``simulated`` on the grid of ``measured`` over their common time span.

    Parameters
    ----------
    measured, simulated : 1-D signals (same unit).
    fs_measured, fs_simulated : sampling rates in Hz (``fs_simulated`` defaults to
        ``fs_measured``).
    t0_measured, t0_simulated : time of the first sample of each record in s.
    min_len : minimum number of common samples.
    """
    m = as_signal(measured, "measured", min_len=1)
    c = as_signal(simulated, "simulated", min_len=1)
    fm = positive(fs_measured, "fs_measured", "Hz")
    fc = fm if fs_simulated is None else positive(fs_simulated, "fs_simulated", "Hz")
    same_rate = fc == fm
    same_origin = float(t0_measured) == float(t0_simulated)
    if same_rate and same_origin:
        n = min(m.shape[0], c.shape[0])
        truncated = m.shape[0] != c.shape[0]
        note = (f"both signals cut to the common {n} samples (measured {m.shape[0]}, "
                f"simulated {c.shape[0]})" if truncated else "common grid: no resampling")
        if n < min_len:
            raise InvalidSignal(f"common grid has {n} samples, needs at least {min_len}")
        return CommonGrid(m[:n], c[:n], fm, float(t0_measured), False, truncated, note)
    tm = float(t0_measured) + np.arange(m.shape[0]) / fm
    tc = float(t0_simulated) + np.arange(c.shape[0]) / fc
    lo, hi = max(tm[0], tc[0]), min(tm[-1], tc[-1])
    eps = 1e-9 / fm
    keep = (tm >= lo - eps) & (tm <= hi + eps)
    n = int(np.count_nonzero(keep))
    if n < min_len:
        raise InvalidSignal(
            f"measured ({tm[0]:g}–{tm[-1]:g} s) and simulated ({tc[0]:g}–{tc[-1]:g} s) "
            f"overlap in {n} samples, need at least {min_len}")
    cs = np.interp(np.clip(tm[keep], tc[0], tc[-1]), tc, c)
    note = (f"simulated resampled from {fc:g} Hz (t0 {float(t0_simulated):g} s) onto the measured "
            f"grid {fm:g} Hz (t0 {float(t0_measured):g} s) by linear interpolation; "
            f"common span {n} samples")
    return CommonGrid(m[keep], cs, fm, float(tm[keep][0]), True, n != m.shape[0], note)
