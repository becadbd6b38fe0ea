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

import threading
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from functools import lru_cache

import numba
import numpy as np
import scipy

from railval.core import design_store, lazy
from railval.core.en_kernels import _welch_density

#: imported when first used: ``scipy.signal`` for :func:`welch_rows` and for a window not yet
#: in :mod:`railval.core.design_store` (a process that estimates PSDs with the windows made
#: before does not load it), ``scipy.fft`` for the transforms of :func:`welch_blocks`
_signal = lazy.module("scipy.signal")
_fft = lazy.module("scipy.fft")
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
    rows = x[np.newaxis, :]
    nperseg = _checked_nperseg(rows, x.size, fs, segment_s)
    f, p = welch_blocks([rows], fs, segment_s)[0]  # = welch_rows bit for bit (tests/test_supp_exact.py)
    return PSD(frequency_hz=f, density=p[0], segment_s=nperseg / fs)


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
    nperseg = _checked_nperseg(x, x.shape[-1], fs, segment_s)
    f, p = _signal.welch(x, fs=fs, nperseg=nperseg, detrend=detrend_linear, scaling="density",
                         axis=-1)
    return f, p, nperseg / fs


def _checked_nperseg(x, n: int, fs: float, segment_s: float, finite: bool = True) -> int:
    """The checks of :func:`welch_rows` on rows ``x`` of length ``n`` (a 2-D array or a list
    of 1-D arrays), in its order (``finite=False``: all but the finite values); the segment
    length in samples."""
    if n < 8:
        raise InvalidSignal(f"welch_psd: values must hold at least 8 samples, got {n}")
    if finite and not (np.all(np.isfinite(x)) if isinstance(x, np.ndarray)
            else all(np.isfinite(r).all() for r in x)):
        raise InvalidSignal("welch_psd: values contain NaN or inf")
    if not (fs > 0 and np.isfinite(fs)):
        raise InvalidParameter(f"welch_psd: fs must be a positive finite number of Hz, got {fs!r}")
    if not (segment_s > 0):
        raise InvalidParameter(f"welch_psd: segment_s must be > 0 s, got {segment_s!r}")
    return int(min(n, max(8, round(segment_s * fs))))


def _rows(block) -> np.ndarray | list[np.ndarray]:
    """A block of :func:`welch_blocks` as a C-contiguous 2-D float array, or as a list of
    C-contiguous 1-D float arrays of equal length when given as a sequence of rows (not
    stacked: its rows are copied segment by segment); contiguous rows keep the compiled
    copy to one signature."""
    if not isinstance(block, np.ndarray):
        rows = [np.ascontiguousarray(r, dtype=float) for r in block]
        if rows and all(r.ndim == 1 and r.size == rows[0].size for r in rows):
            return rows
        block = np.asarray(rows, dtype=float)
    return np.ascontiguousarray(np.atleast_2d(np.asarray(block, dtype=float)))


@lru_cache(maxsize=32)
def _welch_setup(nperseg: int, fs: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
    """What :func:`scipy.signal.welch` derives from (``nperseg``, ``fs``) alone, built by the
    same scipy calls (``scipy.signal.csd``: ``get_window("hann_periodic", nperseg)`` in a
    ``ShortTimeFFT`` scaled to ``"psd"``, i.e. divided by ``sqrt(Σw²·fs)`` summed by Python's
    ``sum``, one-sided, ``mfft = nperseg``): the scaled window, the frequencies, and the
    centred index ``t`` of :func:`detrend_linear` with ``float(t @ t)``. Read only. The window
    and the frequencies, as scipy made them, are kept on disk (:mod:`railval.core.design_store`)."""
    got = design_store.arrays(f"welch hann_periodic nperseg {int(nperseg)} fs {float(fs)!r} "
                              f"scipy {scipy.__version__}", lambda: _scipy_window(nperseg, fs),
                              ("win", "f"), check=lambda a: _plausible_window(a, nperseg))
    win, f = got["win"], got["f"]
    t = np.arange(nperseg) - (nperseg - 1) / 2.0
    tt = float(t @ t)
    for a in (win, f, t):
        a.setflags(write=False)
    return win, f, t, tt


def _scipy_window(nperseg: int, fs: float) -> dict[str, np.ndarray]:
    sft = _signal.ShortTimeFFT(_signal.get_window("hann_periodic", nperseg),
                               nperseg - nperseg // 2, fs, fft_mode="onesided", mfft=nperseg,
                               scale_to="psd", phase_shift=None)
    return {"win": np.array(sft.win), "f": np.array(sft.f)}


def _plausible_window(a, nperseg: int) -> bool:
    """A stored window of ``nperseg`` samples: its length, nperseg//2 + 1 frequencies from 0
    Hz up, finite and non-negative."""
    win, f = a["win"], a["f"]
    return (win.shape == (nperseg,) and f.shape == (nperseg // 2 + 1,)
            and bool(np.isfinite(win).all() and np.isfinite(f).all())
            and bool((win >= 0.0).all()) and f[0] == 0.0 and bool((np.diff(f) > 0.0).all()))


def welch_blocks(blocks: Sequence, fs: float | Sequence[float], segment_s: float = 10.0
                 ) -> list[tuple[np.ndarray, np.ndarray]]:
    """:func:`welch_rows` of many blocks of rows at once, bit for bit: ``blocks[i]`` an array
    of shape (n_rows_i, n_i) or a sequence of n_rows_i 1-D arrays of length n_i; ``fs`` one
    rate for all blocks or one per block. Returns per block ``(frequency_hz, density of shape
    (n_rows_i, n_freq))``, every number equal (same float bits) to
    ``welch_rows(blocks[i], fs_i, segment_s)[:2]``; raises what :func:`welch_rows` raises,
    for the first block that fails.

    The steps of :func:`scipy.signal.welch` (scipy's ``csd`` and ``ShortTimeFFT.spectrogram``;
    Welch 1967: Hann window, 50 % overlap, one-sided density, mean over the segments), each
    the same operations on the same numbers, but over the segments of all blocks with the
    same segment length, rate and row count at once (in chunks of about
    :data:`CHUNK_BYTES`), where that leaves every result unchanged:

    * window, frequencies, ``t``: :func:`_welch_setup` (scipy's own calls, cached);
    * segments ``x[:, p·hop : p·hop + nperseg]``, ``hop = nperseg − nperseg//2``,
      ``p < (n − nperseg//2)//hop`` (scipy's zero padding is never reached), copied by
      :func:`_gather_segments`;
    * linear detrend as :func:`detrend_linear`: row means by ``numpy.mean`` (a row's pairwise
      sum does not depend on the other rows) and ``seg @ t`` as one BLAS product per segment
      of a block *with that block's rows in their order*, as scipy calls it (a stacked
      ``matmul``: one gemv per block segment) — the BLAS result of a row depends on the
      number of rows of the call, so blocks are never merged into one product; then
      ``((seg − mean) − slope·t)·win`` (:func:`_detrend_window`);
    * ``scipy.fft.rfft`` of all segment rows of a chunk in one call (a row's transform does
      not depend on the other rows);
    * power, doubling and mean over the segments:
      :func:`railval.core.en_kernels._welch_density`.

    ``tests/test_supp_exact.py`` holds it equal to :func:`welch_rows` (``numpy.array_equal``)
    over random lengths (odd and even), rates, segment lengths and row counts.

    Parameters
    ----------
    blocks : sequence of numpy.ndarray or of sequences of numpy.ndarray
        Rows of equal length within a block (n ≥ 8, finite); unit u.
    fs : float or sequence of float
        Sampling rate in Hz, for all blocks or per block.
    segment_s : float
        Segment length in s (as :func:`welch_rows`).

    Returns
    -------
    list of tuple of (numpy.ndarray, numpy.ndarray)
        Per block: frequencies in Hz (n_freq,), density in u²/Hz (n_rows_i, n_freq).

    Raises
    ------
    InvalidSignal, InvalidParameter
        As :func:`welch_rows`.

    References
    ----------
    Welch (1967); :func:`scipy.signal.welch`.
    """
    out: list = [None] * len(blocks)
    for members, f, density in welch_groups(blocks, fs, segment_s):
        for j, i in enumerate(members):
            out[i] = (f, density[j])
    return out


def welch_groups(blocks: Sequence, fs: float | Sequence[float], segment_s: float = 10.0
                 ) -> list[tuple[list[int], np.ndarray, np.ndarray]]:
    """:func:`welch_blocks` as computed: per group of blocks with the same segment length,
    rate and row count, ``(block indices, frequency_hz, density of shape (n_blocks, n_rows,
    n_freq))``."""
    rates = [fs] * len(blocks) if np.ndim(fs) == 0 else list(fs)
    if len(rates) != len(blocks):
        raise InvalidParameter(f"welch_blocks: {len(blocks)} blocks but {len(rates)} rates")
    xs: list = []
    groups: dict[tuple, list[tuple[int, int]]] = {}
    try:
        for i, (b, rate) in enumerate(zip(blocks, rates, strict=True)):
            x = _rows(b)
            n = len(x[0]) if len(x) else 0
            m = _checked_nperseg(x, n, rate, segment_s, finite=False)
            xs.append(x)
            groups.setdefault((m, rate, len(x)), []).append((i, (n - m // 2) // (m - m // 2)))
    except (InvalidSignal, InvalidParameter):
        _raise_first(blocks, rates, segment_s)
        raise
    res = []
    for (m, rate, rows), members in groups.items():
        win, f, t, tt = _welch_setup(m, rate)
        density = np.empty((len(members), rows, f.size))
        j0 = 0
        while j0 < len(members):  # blocks in chunks of about CHUNK_BYTES of segments
            j1, size = j0 + 1, members[j0][1] * rows * m * 8
            while j1 < len(members) and size + members[j1][1] * rows * m * 8 <= CHUNK_BYTES:
                size += members[j1][1] * rows * m * 8
                j1 += 1
            _welch_chunk([xs[i] for i, _ in members[j0:j1]], [k for _, k in members[j0:j1]],
                         win, t, tt, density[j0:j1],
                         lambda: _raise_first(blocks, rates, segment_s))
            j0 = j1
        res.append(([i for i, _ in members], f, density))
    return res


#: Segments processed at once, in bytes: the chunk and its spectra stay in a core's cache.
CHUNK_BYTES = 1 << 20
_SCRATCH = threading.local()


def _scratch(n: int) -> np.ndarray:
    """A float64 buffer of ``n`` values for this thread's segments, kept between calls up to
    4·:data:`CHUNK_BYTES` (a buffer of a size the allocator maps afresh on every call costs
    its page faults each time)."""
    buf = getattr(_SCRATCH, "buf", None)
    if buf is None or buf.size < n:
        buf = np.empty(max(n, CHUNK_BYTES // 8))
        if buf.size * 8 <= 4 * CHUNK_BYTES:
            _SCRATCH.buf = buf
    return buf[:n]


def _welch_chunk(xs: list, n_seg: list[int], win: np.ndarray, t: np.ndarray, tt: float,
                 out: np.ndarray, check: Callable[[], None]) -> None:
    """The densities of blocks ``xs`` (rows of equal count and length, ``n_seg`` segments of
    ``len(win)`` samples each) into ``out`` (n_blocks, n_rows, n_freq), the steps listed in
    :func:`welch_blocks`; ``check()`` (the checks of every block, raising the first error)
    when a sample may not be finite (a non-finite sample after the last segment, or a
    non-finite segment mean, which finite samples can also give by overflow)."""
    m = win.size
    hop = m - m // 2
    rows = out.shape[1]
    k = np.array(n_seg, dtype=np.int64)
    first = np.zeros(k.size, dtype=np.int64)
    np.cumsum(k[:-1], out=first[1:])
    seg = _scratch(int(k.sum()) * rows * m).reshape(-1, m)
    finite = True
    for x, n, j in zip(xs, n_seg, first.tolist(), strict=True):
        for r, row in enumerate(x):
            finite &= _gather_segments(row, hop, n, seg, j * rows + r, rows)
    mean = seg.mean(axis=-1)
    if not (finite and np.isfinite(mean).all()):
        check()
    slope = (seg.reshape(-1, rows, m) @ t).reshape(-1) / tt
    _detrend_window(seg, mean, slope, t, win)
    _welch_density(_fft.rfft(seg, n=m, axis=-1), first, k, rows, m % 2 == 0, out)


def _raise_first(blocks: Sequence, rates: Sequence[float], segment_s: float) -> None:
    """Every check of :func:`welch_rows`, block by block: raises the error of the first block
    that fails, as one :func:`welch_rows` call per block would."""
    for b, rate in zip(blocks, rates, strict=True):
        x = _rows(b)
        _checked_nperseg(x, len(x[0]) if len(x) else 0, rate, segment_s)


@numba.njit(cache=True, nogil=True)
def _gather_segments(row, hop, k, seg, first, rows):  # pragma: no cover - compiled
    """``seg[first + p·rows] = row[p·hop : p·hop + m]`` for the k segments (m =
    ``seg.shape[1]``); whether the samples after the last segment are finite (those of the
    segments are checked through their means)."""
    m = seg.shape[1]
    for p in range(k):
        o = first + p * rows
        for i in range(m):
            seg[o, i] = row[p * hop + i]
    for i in range((k - 1) * hop + m, row.shape[0]):
        if not np.isfinite(row[i]):
            return False
    return True


@numba.njit(cache=True, nogil=True)
def _detrend_window(seg, mean, slope, t, win):  # pragma: no cover - compiled
    """``seg[r] = ((seg[r] − mean[r]) − slope[r]·t)·win`` in place: :func:`detrend_linear`
    (``seg − mean − slope·t``) and scipy's window product, the same operations in the same
    order."""
    for r in range(seg.shape[0]):
        a = mean[r]
        b = slope[r]
        for i in range(seg.shape[1]):
            seg[r, i] = ((seg[r, i] - a) - b * t[i]) * win[i]
