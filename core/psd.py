"""Power spectral density of measured and simulated signals (docs/design.md §5: PSD plots).

One function, :func:`welch_psd`, used by the Compare page and the report so that a
measurement and a simulation are always estimated with identical settings (same segment
length, window and overlap) — otherwise their PSDs would not be comparable.

References
----------
P. D. Welch, "The use of fast Fourier transform for the estimation of power spectra",
IEEE Trans. Audio Electroacoust. 15 (1967) 70–73; implemented by :func:`scipy.signal.welch`
(one-sided density, Hann window, 50 % overlap). Seed 000 §5 shows car-body acceleration
PSDs of measurement and simulation side by side.
"""

from __future__ import annotations

from dataclasses import dataclass

import numba
import numpy as np
from scipy import signal as _signal

from railval.core.en_kernels import _detrend_taper
from railval.core.errors import InvalidParameter, InvalidSignal


@dataclass(frozen=True)
class PSD:
    """A one-sided power spectral density.

    ``frequency_hz`` in Hz; ``density`` in unit²/Hz of the input signal (e.g. (m/s²)²/Hz);
    ``segment_s`` the Welch segment length in s (frequency resolution 1/segment_s Hz).
    """

    frequency_hz: np.ndarray
    density: np.ndarray
    segment_s: float

    def to_dict(self) -> dict:
        return {
            "frequency_hz": self.frequency_hz.tolist(),
            "density": self.density.tolist(),
            "segment_s": self.segment_s,
        }


def welch_psd(values: np.ndarray, fs: float, segment_s: float = 10.0) -> PSD:
    """One-sided Welch PSD of ``values`` sampled at ``fs`` Hz.

    Parameters
    ----------
    values : 1-D array in the signal's unit.
    fs : sampling rate in Hz (> 0).
    segment_s : Welch segment length in s (> 0); shortened to the signal length when the
        signal is shorter. Hann window, 50 % overlap, linear detrend per segment
        (``scipy.signal.welch`` defaults apart from the detrend).

    Returns
    -------
    PSD with ``density`` in unit²/Hz; integrating it over frequency gives the variance of
    the (detrended) signal (Parseval).

    References
    ----------
    Welch (1967); :func:`scipy.signal.welch`.
    """
    x = np.asarray(values, dtype=float)
    if x.ndim != 1 or x.size < 8:
        raise InvalidSignal(f"welch_psd: values must be 1-D with at least 8 samples, got shape {x.shape}")
    if not np.all(np.isfinite(x)):
        raise InvalidSignal("welch_psd: values contain NaN or inf")
    if not (fs > 0 and np.isfinite(fs)):
        raise InvalidParameter(f"welch_psd: fs must be a positive finite number of Hz, got {fs!r}")
    if not (segment_s > 0):
        raise InvalidParameter(f"welch_psd: segment_s must be > 0 s, got {segment_s!r}")
    f, p, seg = welch_rows(x[np.newaxis, :], fs, segment_s)
    return PSD(frequency_hz=f, density=p[0], segment_s=seg)


def detrend_linear(segments: np.ndarray) -> np.ndarray:
    """Remove the least-squares straight line from every segment (last axis).

    Closed form of the regression on the centred sample index t: slope = Σ t·x / Σ t²; equal
    to ``scipy.signal.detrend(type="linear")`` to rounding, without its per-call least-squares
    solve (≈ 4× faster for a section's acceleration channels at once).

    Parameters
    ----------
    segments : numpy.ndarray
        Shape (..., n); any unit.

    Returns
    -------
    numpy.ndarray
        Same shape, float64, each segment minus its fitted line.

    Examples
    --------
    >>> detrend_linear(np.array([1.0, 2.0, 3.0, 5.0])).round(3)
    array([ 0.2, -0.1, -0.4,  0.3])
    """
    seg = np.asarray(segments, dtype=np.float64)
    n = seg.shape[-1]
    if n < 2:
        return seg - seg.mean(axis=-1, keepdims=True)
    t = np.arange(n) - (n - 1) / 2.0
    slope = (seg @ t) / float(t @ t)
    return seg - seg.mean(axis=-1, keepdims=True) - slope[..., np.newaxis] * t


def welch_rows(rows: np.ndarray, fs: float, segment_s: float = 10.0) -> tuple[np.ndarray, np.ndarray, float]:
    """:func:`welch_psd` of every row of ``rows`` (shape (n_rows, n), equal lengths) in one
    call: returns ``(frequency_hz, density of shape (n_rows, n_freq), segment_s used)`` with
    the settings of :func:`welch_psd` (Hann, 50 % overlap, linear detrend per segment,
    ``round(segment_s·fs)`` samples per segment, at least 8, at most the record).

    Parameters
    ----------
    rows : numpy.ndarray
        Shape (n_rows, n), n ≥ 8, finite; unit u (e.g. m/s²).
    fs : float
        Sampling rate in Hz.
    segment_s : float
        Segment length in s.

    Returns
    -------
    tuple of (numpy.ndarray, numpy.ndarray, float)
        Frequencies in Hz (n_freq,), one-sided density in u²/Hz (n_rows, n_freq), segment
        length used in s.

    Raises
    ------
    InvalidSignal, InvalidParameter
        Fewer than 8 samples or non-finite values; ``fs`` or ``segment_s`` not positive.
    """
    x = np.atleast_2d(np.asarray(rows, dtype=float))
    if x.shape[-1] < 8:
        raise InvalidSignal(f"welch_psd: values must hold at least 8 samples, got {x.shape[-1]}")
    if not np.all(np.isfinite(x)):
        raise InvalidSignal("welch_psd: values contain NaN or inf")
    if not (fs > 0 and np.isfinite(fs)):
        raise InvalidParameter(f"welch_psd: fs must be a positive finite number of Hz, got {fs!r}")
    if not (segment_s > 0):
        raise InvalidParameter(f"welch_psd: segment_s must be > 0 s, got {segment_s!r}")
    nperseg = int(min(x.shape[-1], max(8, round(segment_s * fs))))
    f, p = _signal.welch(x, fs=fs, nperseg=nperseg, detrend=detrend_linear, scaling="density",
                         axis=-1)
    return f, p, nperseg / fs


def welch_blocks(blocks: list[np.ndarray], fs: float, segment_s: float = 10.0
                 ) -> list[tuple[np.ndarray, np.ndarray]]:
    """:func:`welch_rows` of many blocks of rows (``blocks[i]`` of shape (n_rows_i, n_i),
    n_i ≥ 8, finite) at once: the segments of all blocks with the same segment length are
    detrended, windowed and transformed in one call each (Welch 1967: Hann window, 50 %
    overlap, segments starting every ``nperseg − nperseg//2`` samples, one-sided density
    ``2·|X|²/(fs·Σw²)`` — DC and an even length's Nyquist bin not doubled — averaged over
    the segments), the steps :func:`scipy.signal.welch` takes. Equal to :func:`welch_rows`
    of each block to rounding (measured: ≤ 1.3e-12 relative per bin of a trend-dominated
    record, ≤ 2.1e-15 for the band values of the EN chain).

    Parameters
    ----------
    blocks : list of numpy.ndarray
        Rows of equal length within a block; unit u.
    fs, segment_s : float, float
        Sampling rate in Hz; segment length in s.

    Returns
    -------
    list of tuple of (numpy.ndarray, numpy.ndarray)
        Per block: frequencies in Hz (n_freq,), density in u²/Hz (n_rows_i, n_freq).
    """
    from scipy import fft as _fft

    blocks = [np.atleast_2d(np.asarray(b, dtype=np.float64)) for b in blocks]
    nper = [int(min(b.shape[-1], max(8, round(segment_s * fs)))) for b in blocks]
    out: list = [None] * len(blocks)
    for m in sorted(set(nper)):
        members = [i for i, v in enumerate(nper) if v == m]
        hop = m - m // 2
        n_segs = [(blocks[i].shape[-1] - m // 2) // hop for i in members]
        seg = np.empty((sum(blocks[i].shape[0] * k for i, k in zip(members, n_segs)), m))
        pos = 0
        for i, n_seg in zip(members, n_segs, strict=True):  # segment-major per block
            rows = blocks[i].shape[0]
            for k in range(n_seg):
                seg[pos:pos + rows] = blocks[i][:, k * hop:k * hop + m]
                pos += rows
        win = _signal.get_window("hann", m)
        t = np.arange(m) - (m - 1) / 2.0
        _detrend_taper(seg, seg.mean(axis=-1), t, win, seg)
        spec = _fft.rfft(seg, axis=-1)
        f = _fft.rfftfreq(m, 1.0 / fs)
        pos = 0
        for i, n_seg in zip(members, n_segs, strict=True):
            rows = blocks[i].shape[0]
            density = np.empty((rows, f.size))
            _segment_mean_power(spec[pos:pos + rows * n_seg], n_seg,
                                1.0 / (fs * float(np.sum(win * win))), m % 2 == 0,
                                density)
            out[i] = (f, density)
            pos += rows * n_seg
    return out


@numba.njit(cache=True, nogil=True)
def _segment_mean_power(spec, n_seg, scale, even, out):  # pragma: no cover - compiled
    """One-sided density of each row (``spec`` segment-major: row r of segment k at
    ``k·rows + r``): ``|X|²·scale``, doubled except DC and an even length's Nyquist bin,
    averaged over the segments."""
    rows = out.shape[0]
    n_f = out.shape[1]
    for r in range(rows):
        for j in range(n_f):
            acc = 0.0
            for k in range(n_seg):
                x = spec[k * rows + r, j]
                acc += (x.real * x.real + x.imag * x.imag) * scale
            if j > 0 and not (even and j == n_f - 1):
                acc *= 2.0
            out[r, j] = acc / n_seg
    return out

