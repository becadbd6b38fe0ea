"""Zero-phase Butterworth filters of EN 14363 processing (docs/design.md §3, Polach & Böttcher 2014 Table 2).

Two filters are used by the 12 validation quantities:

* ``"lowpass"`` — low-pass 20 Hz: wheel–rail forces Y, Q (and Y/Q, ΣY formed from them);
* ``"bandpass"`` — band-pass 0.4–10 Hz: car body accelerations.

Both are Butterworth designs (``scipy.signal.butter``, second-order sections) applied
forward and backward (zero phase). ``order`` is the Butterworth order ``N`` of the prototype
(default 4): the low-pass has order ``N``; the band-pass, built by the low-pass→band-pass
transform, has order ``2N``. Forward–backward filtering squares the magnitude response, so
the amplitude gain of the applied filter is ``|H(f)|²``; for the low-pass
``|H(f)|² = 1 / (1 + (Ω/Ω_c)^(2N))`` with the bilinear-transform warped frequencies
``Ω = tan(π f / fs)``, ``Ω_c = tan(π f_c / fs)``.

:func:`filtfilt_rows` filters every row of a 2-D array (many signals at once) with a compiled
kernel that reproduces ``scipy.signal.sosfiltfilt`` exactly (odd extension of
``3·(2·n_sections + 1)`` samples at each end, steady-state initial conditions from
``scipy.signal.sosfilt_zi``); designs are cached per ``(fs, kind, order)`` in the process
and, as scipy made them, on disk (:mod:`railval.core.design_store`).

:func:`settling_check` reports — never silently — when the run-in before (or run-out after)
the evaluated range is shorter than the filter settling time.

References
----------
Polach & Böttcher 2014, §5 and Table 2: filtering of the 12 quantities.
EN 14363:2005, on-track tests: filtering of wheel–rail forces (low-pass 20 Hz) and car body
accelerations (band-pass 0.4–10 Hz).
Gustafsson, F. (1996) Determining the initial states in forward-backward filtering, IEEE
Trans. Signal Processing 44(4) — the steady-state initial conditions used by scipy.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numba
import numba.extending
import numpy as np
import scipy

from railval.core import design_store, lazy
from railval.core.buffers import BufferPool
from railval.core.errors import InvalidParameter, InvalidSignal
from railval.core.processing import DEFAULT_ORDER, check_order

LOWPASS_HZ = 20.0
BANDPASS_HZ = (0.4, 10.0)
#: relative impulse-response level below which a filter counts as settled
SETTLING_LEVEL = 0.01

FILTER_KINDS = ("lowpass", "bandpass")

#: imported when a design is first computed in this folder (railval.core.design_store keeps
#: the designs made before: a process that only filters does not load scipy.signal)
_signal = lazy.module("scipy.signal")


@dataclass(frozen=True)
class FilterDesign:
    """A cached zero-phase Butterworth design.

    ``sos``: second-order sections (scipy layout, ``a0 = 1``); ``zi``: steady-state initial
    conditions per section for a unit step (``sosfilt_zi``); ``edge``: odd-extension length in
    samples at each end; ``settling_s``: time in s after which the impulse response of one
    pass stays below ``SETTLING_LEVEL`` of its peak.
    """

    kind: str
    fs: float
    order: int
    sos: np.ndarray
    zi: np.ndarray
    edge: int
    settling_s: float

    @property
    def label(self) -> str:
        if self.kind == "lowpass":
            return f"Butterworth low-pass {LOWPASS_HZ:g} Hz, order {self.order}, zero-phase"
        lo, hi = BANDPASS_HZ
        return (f"Butterworth band-pass {lo:g}–{hi:g} Hz, prototype order {self.order} "
                f"(order {2 * self.order}), zero-phase")


def _check_design_args(fs: float, kind: str, order: int) -> None:
    if kind not in FILTER_KINDS:
        raise InvalidParameter(f"filter kind must be one of {FILTER_KINDS}, got {kind!r}")
    check_order(order)
    nyquist_needed = LOWPASS_HZ if kind == "lowpass" else BANDPASS_HZ[1]
    if not np.isfinite(fs) or fs <= 2.0 * nyquist_needed:
        raise InvalidParameter(
            f"sampling rate fs must exceed {2.0 * nyquist_needed:g} Hz for the {kind} filter "
            f"(corner {nyquist_needed:g} Hz), got {fs!r} Hz"
        )


@lru_cache(maxsize=64)
def design(fs: float, kind: str, order: int = DEFAULT_ORDER) -> FilterDesign:
    """Return the (cached) Butterworth design for sampling rate ``fs`` in Hz.

    ``kind`` is ``"lowpass"`` (20 Hz) or ``"bandpass"`` (0.4–10 Hz); ``order`` the
    Butterworth prototype order N (band-pass → order 2N).

    Parameters
    ----------
    fs : float
        Sampling rate in Hz (above twice the upper corner).
    kind : str
        ``"lowpass"`` or ``"bandpass"``.
    order : int
        Butterworth prototype order (1–10).

    Returns
    -------
    FilterDesign

    Raises
    ------
    InvalidParameter
        An unknown kind, an order outside 1–10 or too low a sampling rate.

    Examples
    --------
    >>> design(200.0, "lowpass").sos.shape
    (2, 6)
    """
    fs = float(fs)
    _check_design_args(fs, kind, order)
    order = int(order)
    got = design_store.arrays(f"butterworth {kind} order {order} fs {fs!r} scipy {scipy.__version__}",
                              lambda: _designed(fs, kind, order), ("sos", "zi", "settling_s"),
                              check=lambda a: _plausible(a, kind, order))
    sos = np.ascontiguousarray(got["sos"], dtype=np.float64)
    zi = np.ascontiguousarray(got["zi"], dtype=np.float64)
    n_sections = sos.shape[0]
    ntaps = 2 * n_sections + 1 - min(int((sos[:, 2] == 0).sum()), int((sos[:, 5] == 0).sum()))
    edge = 3 * ntaps
    return FilterDesign(kind, fs, order, sos, zi, edge, float(got["settling_s"]))


def _designed(fs: float, kind: str, order: int) -> dict[str, np.ndarray]:
    """The design as ``scipy.signal`` makes it: ``butter`` in second-order sections, their
    ``sosfilt_zi`` and the settling time of one pass (:func:`_settling_time`)."""
    if kind == "lowpass":
        sos = _signal.butter(order, LOWPASS_HZ, btype="lowpass", fs=fs, output="sos")
    else:
        sos = _signal.butter(order, list(BANDPASS_HZ), btype="bandpass", fs=fs, output="sos")
    sos = np.ascontiguousarray(sos, dtype=np.float64)
    zi = np.ascontiguousarray(_signal.sosfilt_zi(sos), dtype=np.float64)
    return {"sos": sos, "zi": zi, "settling_s": np.float64(_settling_time(sos, fs))}


def _plausible(a, kind: str, order: int) -> bool:
    """A stored design of this kind and order: the shapes of ``butter``'s sections
    (⌈N/2⌉ low-pass, N band-pass), finite numbers, a0 = 1 and a positive settling time."""
    sos, zi, settling = a["sos"], a["zi"], a["settling_s"]
    n = (order + 1) // 2 if kind == "lowpass" else order
    return (sos.shape == (n, 6) and zi.shape == (n, 2) and settling.shape == ()
            and bool(np.isfinite(sos).all() and np.isfinite(zi).all())
            and bool((sos[:, 3] == 1.0).all()) and float(settling) > 0.0)


def _settling_time(sos: np.ndarray, fs: float) -> float:
    """Time (s) after which |h(t)| of one forward pass stays below SETTLING_LEVEL·max|h|."""
    n = int(fs * 4.0)
    while True:
        impulse = np.zeros(n)
        impulse[0] = 1.0
        h = np.abs(_signal.sosfilt(sos, impulse))
        above = np.flatnonzero(h > SETTLING_LEVEL * h.max())
        last = int(above[-1])
        if last < n - 10 or n > fs * 600:
            return (last + 1) / fs
        n *= 2


#: signals filtered in lockstep by one thread (the inner loop of the kernel runs over them).
#: 16, not 32: the time-major buffer of the forward pass (n × 16 × 8 B, 2.6 MB for 20 000
#: samples) is half as large, so more of it is still in the core's L2 cache when the backward
#: pass reads it from its end, and a partial last block wastes fewer lanes; 16 lanes still keep
#: the recursion throughput-bound, 8 do not (branch filt2, 2026-11-26, loaded 2-core machine,
#: same process: 272 low-pass rows × 20 000 samples 4.8 instead of 5.1 CPU ns/sample, 68
#: band-pass rows 8.5 instead of 10.3; 8 lanes 7.9 and 14.5; tests/test_filt2_copies.py)
_BLOCK = 16


#: samples per chunk of :func:`_cascade_pass`: all sections run over one chunk (16 signals ×
#: 256 samples × 8 B = 32 KiB, held in the core's cache) before the next
_CHUNK = 256
#: samples per tile of :func:`_filter_block`: 16 signals × 64 samples × 8 B = 8 KiB, held in
#: the L1 cache while it is transposed and every section runs over it (64 measured faster
#: than 32, 128 and 256 with 32 signals on the bench machine, and not slower than 128 with 16,
#: 2026-11-26)
_TILE = 64


@numba.njit(cache=True, nogil=True)
def _cascade_pass(sos, zi, ext, first, stop, step):  # pragma: no cover - compiled
    """One in-place pass of the cascade over ``ext[first:stop:step]`` (shape ``(m, _BLOCK)``,
    time-major), every section starting in the steady state ``zi`` scaled by the first sample
    of the pass (``scipy.signal.sosfilt`` with ``zi·x0``), the sections running one after
    another over chunks of ``_CHUNK`` samples (:func:`_sections_over`). Used by the machine
    limits of ``app/bench/bench_en.py``."""
    z0 = np.empty((sos.shape[0], _BLOCK))
    z1 = np.empty((sos.shape[0], _BLOCK))
    _start_state(zi, ext[first], z0, z1)
    length = (stop - first) // step
    for k0 in range(0, length, _CHUNK):
        k1 = min(k0 + _CHUNK, length)
        _sections_over(sos, z0, z1, ext, first + k0 * step, first + k1 * step, step)


@numba.njit(cache=True, nogil=True, inline="always")
def _start_state(zi, x0, z0, z1):  # pragma: no cover - compiled
    """Steady-state start of every section for the first samples ``x0`` (``zi·x0``, scipy's
    ``sosfiltfilt``)."""
    for s in range(zi.shape[0]):
        for c in range(_BLOCK):
            z0[s, c] = zi[s, 0] * x0[c]
            z1[s, c] = zi[s, 1] * x0[c]


@numba.njit(cache=True, nogil=True)
def _sections_over(sos, z0, z1, ext, first, stop, step):  # pragma: no cover - compiled
    """Every section in turn over ``ext[first:stop:step]`` (time-major, ``_BLOCK`` signals),
    in place, continuing from and updating the section states ``z0``, ``z1``. The recursion is
    scipy's sosfilt (direct form II transposed, the same operations in the same order); the
    inner loop runs over the ``_BLOCK`` independent signals, so it is vectorised and the
    latency of each recursion is hidden by the others. The states are copied into local
    arrays, known not to alias ``ext`` (measured 0.46 instead of 0.69 ns per sample and
    section when working on ``z0``, ``z1`` directly)."""
    zs0 = np.empty(_BLOCK)
    zs1 = np.empty(_BLOCK)
    length = (stop - first) // step
    for s in range(sos.shape[0]):
        b0, b1, b2, a1, a2 = sos[s, 0], sos[s, 1], sos[s, 2], sos[s, 4], sos[s, 5]
        zs0[:] = z0[s]
        zs1[:] = z1[s]
        for k in range(length):
            row = ext[first + k * step]
            for c in range(_BLOCK):
                x = row[c]
                y = b0 * x + zs0[c]
                zs0[c] = b1 * x - a1 * y + zs1[c]
                zs1[c] = b2 * x - a2 * y
                row[c] = y
        z0[s] = zs0
        z1[s] = zs1


@numba.njit(cache=True, nogil=True, inline="always")
def _as_row(address, n):  # pragma: no cover - compiled
    """The float64 row of ``n`` samples at ``address`` (see :func:`_row_addresses`)."""
    return numba.carray(_address_to_pointer(address), (n,))


@numba.extending.intrinsic
def _address_to_pointer(typingctx, address):
    """A ``float64*`` from an integer address (LLVM ``inttoptr``)."""
    sig = numba.types.CPointer(numba.types.float64)(numba.types.intp)

    def codegen(context, builder, signature, args):
        return builder.inttoptr(args[0], context.get_value_type(signature.return_type))

    return sig, codegen


@numba.njit(cache=True, nogil=True, inline="always")
def _rows_into_tile(src, b, nb, n, fwd, t0, t1):  # pragma: no cover - compiled
    """``fwd[t0:t1, c] = row_c[t0:t1]`` for the ``nb`` rows at addresses ``src[b:b + nb]``,
    eight rows at a time: each time step of the tile receives eight contiguous values (one
    cache line of ``fwd``, written whole) instead of eight separate strided stores (alone,
    256 rows × 20 000 samples into a 32-wide buffer: 0.96 instead of 1.19 CPU ns per element,
    tests/test_filt2_copies.py). Values are moved, not computed: bit for bit the same."""
    c = 0
    while c + 8 <= nb:
        r0, r1 = _as_row(src[b + c], n), _as_row(src[b + c + 1], n)
        r2, r3 = _as_row(src[b + c + 2], n), _as_row(src[b + c + 3], n)
        r4, r5 = _as_row(src[b + c + 4], n), _as_row(src[b + c + 5], n)
        r6, r7 = _as_row(src[b + c + 6], n), _as_row(src[b + c + 7], n)
        for i in range(t0, t1):
            f = fwd[i]
            f[c], f[c + 1], f[c + 2], f[c + 3] = r0[i], r1[i], r2[i], r3[i]
            f[c + 4], f[c + 5], f[c + 6], f[c + 7] = r4[i], r5[i], r6[i], r7[i]
        c += 8
    for k in range(c, nb):
        row = _as_row(src[b + k], n)
        for i in range(t0, t1):
            fwd[i, k] = row[i]


@numba.njit(cache=True, nogil=True, inline="always")
def _tile_into_rows(fwd, out, b, nb, t0, t1):  # pragma: no cover - compiled
    """``out[b + c, t0:t1] = fwd[t0:t1, c]`` for ``c < nb``, eight rows at a time (each time
    step of the tile read as one contiguous group of eight values). Alone 1.31 instead of
    1.35 CPU ns per element: the cost is the writing of ``out`` itself (a plain row-to-row
    copy of the same size takes 1.33)."""
    c = 0
    while c + 8 <= nb:
        d0, d1, d2, d3 = out[b + c], out[b + c + 1], out[b + c + 2], out[b + c + 3]
        d4, d5, d6, d7 = out[b + c + 4], out[b + c + 5], out[b + c + 6], out[b + c + 7]
        for i in range(t0, t1):
            f = fwd[i]
            d0[i], d1[i], d2[i], d3[i] = f[c], f[c + 1], f[c + 2], f[c + 3]
            d4[i], d5[i], d6[i], d7[i] = f[c + 4], f[c + 5], f[c + 6], f[c + 7]
        c += 8
    for k in range(c, nb):
        dst = out[b + k]
        for i in range(t0, t1):
            dst[i] = fwd[i, k]


@numba.njit(cache=True, nogil=True)
def _filter_block(sos, zi, edge, src, out, b, nb, tile, fwd, z0, z1):  # pragma: no cover
    """Forward–backward filter of the ``nb`` (≤ ``_BLOCK``) rows at addresses ``src[b:b + nb]``
    into ``out[b:b + nb]``, tile by tile: the forward pass over the odd extension of ``edge``
    samples at the start (in ``tile``, scipy's ``padtype="odd"``), over the signal (each tile
    transposed into its place in the time-major ``fwd`` and filtered there, in the cache) and
    over the end extension (in ``tile``); then the backward pass from the steady state of the
    last forward output over the end extension and over ``fwd`` from its end, each tile
    transposed into ``out`` once filtered. Every sample is read once from the rows, written
    and read once in ``fwd`` and written once to ``out`` (32 bytes). The backward outputs over
    the start extension are never used, so that part is not run. Columns ``nb:`` hold values
    of an earlier block (or zeros): filtered, never written out."""
    n = out.shape[1]
    for c in range(nb):  # start extension, forward
        row = _as_row(src[b + c], n)
        for i in range(edge):
            tile[i, c] = 2.0 * row[0] - row[edge - i]
    _start_state(zi, tile[0], z0, z1)
    _sections_over(sos, z0, z1, tile, 0, edge, 1)
    for t0 in range(0, n, _TILE):  # the signal, forward
        t1 = min(t0 + _TILE, n)
        _rows_into_tile(src, b, nb, n, fwd, t0, t1)
        _sections_over(sos, z0, z1, fwd, t0, t1, 1)
    for c in range(nb):  # end extension, forward
        row = _as_row(src[b + c], n)
        for i in range(edge):
            tile[i, c] = 2.0 * row[n - 1] - row[n - 2 - i]
    _sections_over(sos, z0, z1, tile, 0, edge, 1)
    _start_state(zi, tile[edge - 1], z0, z1)  # backward: from the last forward output
    _sections_over(sos, z0, z1, tile, edge - 1, -1, -1)
    for t1 in range(n, 0, -_TILE):  # the signal, backward
        t0 = max(t1 - _TILE, 0)
        _sections_over(sos, z0, z1, fwd, t1 - 1, t0 - 1, -1)
        _tile_into_rows(fwd, out, b, nb, t0, t1)


@numba.njit(cache=True, nogil=True)
def _filtfilt_kernel(sos, zi, edge, src, out, r0, r1):  # pragma: no cover - compiled
    """:func:`_filtfilt_into` with a time-major buffer of its own (``n × _BLOCK`` float64)."""
    _filtfilt_into(sos, zi, edge, src, out, r0, r1, np.empty((out.shape[1], _BLOCK)))


@numba.njit(cache=True, nogil=True)
def _filtfilt_into(sos, zi, edge, src, out, r0, r1, fwd):  # pragma: no cover - compiled
    """Forward–backward filter the rows ``r0:r1`` (addresses ``src``, ``out.shape[1]`` samples
    each) into ``out``, ``_BLOCK`` rows at a time (:func:`_filter_block`); ``fwd`` (shape
    ``(n, _BLOCK)``, any content) is the time-major buffer of the forward pass, reused from
    block to block."""
    tile = np.empty((edge, _BLOCK))
    if r1 - r0 < _BLOCK:  # a first, partial block: its unused columns start at zero
        tile[:, :] = 0.0
        fwd[:, :] = 0.0
    z0 = np.empty((sos.shape[0], _BLOCK))
    z1 = np.empty((sos.shape[0], _BLOCK))
    for b in range(r0, r1, _BLOCK):
        _filter_block(sos, zi, edge, src, out, b, min(_BLOCK, r1 - b), tile, fwd, z0, z1)


#: the outputs of :func:`filtfilt_rows` (docs/validation.md, Throughput): mapped once and
#: reused when their arrays are gone — the EN chain holds a low-pass and a band-pass output
#: at once (``railval bench en``: 43 and 11 MB); ≤ 256 MB kept per process
_OUTPUTS = BufferPool(keep=4, max_bytes=128 << 20, min_bytes=1 << 20, max_total_bytes=256 << 20)
#: the time-major buffers of the forward pass (one per thread part, n × _BLOCK × 8 bytes; the
#: kernel's own allocation page-faulted afresh in some calls); pooled from 512 KiB (4096
#: samples of 16 signals, the signal length pooled before with 32); ≤ 128 MB kept per process
_SCRATCH = BufferPool(keep=4, max_bytes=64 << 20, min_bytes=1 << 19, max_total_bytes=128 << 20)


def _filter_part(d: FilterDesign, src: np.ndarray, out: np.ndarray, r0: int, r1: int) -> None:
    """Rows ``r0:r1`` into ``out`` with a pooled time-major buffer (held for the call)."""
    fwd = _SCRATCH.take((out.shape[1], _BLOCK), np.float64)
    _filtfilt_into(d.sos, d.zi, d.edge, src, out, r0, r1, fwd)


def _row_addresses(rows: list) -> np.ndarray:
    """Addresses of the first samples of C-contiguous float64 rows (kept alive by the
    caller) for :func:`_filtfilt_kernel`: for 340 rows 0.35 ms, less than a numba typed List
    (0.47 ms) and than copying the rows block by block (3.9 ms, the previous list path)."""
    return np.array([r.ctypes.data for r in rows], dtype=np.intp)


def filtfilt_rows(data, fs: float, kind: str, order: int = DEFAULT_ORDER) -> np.ndarray:
    """Zero-phase filter every row of ``data`` (shape ``(n_signals, n_samples)``, 1-D, or a
    list of equally long 1-D arrays).

    Equal to ``scipy.signal.sosfiltfilt(design(fs, kind, order).sos, data, axis=-1)`` (same
    padding and initial conditions) to rounding; returns a float64 array of shape
    ``(n_signals, n_samples)`` (1-D for 1-D input) that shares memory with no other live
    array: large outputs are placed in a buffer of a previous call once every array of that
    call is gone (:class:`railval.core.buffers.BufferPool`, no page faults of fresh memory). Units are those of ``data``; ``fs`` in Hz.
    Blocks of ``_BLOCK`` signals run in lockstep; the blocks are shared among the cores
    (:func:`railval.core.workers.split_rows`; the kernel releases the GIL).

    Parameters
    ----------
    data : array_like or list of array_like
        Shape (n_signals, n_samples), (n_samples,), or equally long 1-D arrays; any unit.
    fs : float
        Sampling rate in Hz.
    kind : str
        ``"lowpass"`` (20 Hz, forces) or ``"bandpass"`` (0.4–10 Hz, accelerations), see
        :func:`design`.
    order : int
        Butterworth prototype order (1–10).

    Returns
    -------
    numpy.ndarray
        Filtered float64 copy, shape (n_signals, n_samples) (1-D for 1-D input).

    Raises
    ------
    InvalidSignal
        Rows of unequal length.
    """
    d = design(float(fs), kind, order)
    if isinstance(data, (list, tuple)):
        rows = [np.asarray(r, dtype=np.float64) for r in data]
        if not rows:
            return np.empty((0, 0))
        n = rows[0].shape[0]
        if any(r.shape != (n,) for r in rows):
            raise InvalidSignal("filtfilt_rows: all signals must be 1-D and equally long")
        arr = None  # read in place through the row addresses (no copy of the rows)
        one_d = False
    else:
        arr = np.asarray(data, dtype=np.float64)
        one_d = arr.ndim == 1
        if arr.ndim not in (1, 2):
            raise InvalidSignal(f"filtfilt_rows expects a 1-D or 2-D array, got shape {arr.shape}")
        if one_d:
            arr = arr[np.newaxis, :]
        if arr.shape[0] == 0:
            return np.empty((0, 0))
        arr = np.ascontiguousarray(arr)
    n = arr.shape[1] if arr is not None else rows[0].shape[0]
    if n <= d.edge:
        raise InvalidSignal(
            f"signal length {n} samples must exceed the filter padding {d.edge} "
            f"samples ({d.label})"
        )
    from railval.core.workers import split_rows

    if arr is not None:  # row addresses without a Python object per row
        src = arr.__array_interface__["data"][0] + arr.strides[0] * np.arange(arr.shape[0],
                                                                             dtype=np.intp)
    else:
        rows = [np.ascontiguousarray(r) for r in rows]
        src = _row_addresses(rows)
    out = _OUTPUTS.take((src.shape[0], n), np.float64)
    split_rows(lambda a, b: _filter_part(d, src, out, a, b), src.shape[0], min_rows=_BLOCK,
               align=_BLOCK)
    return out[0] if one_d else out


@dataclass(frozen=True)
class SettlingWarning:
    """Run-in or run-out shorter than the filter settling time (a filter transient may reach
    the evaluated range). Times in s."""

    filter_label: str
    side: str  # "run-in" or "run-out"
    available_s: float
    settling_s: float
    section: str = ""

    @property
    def message(self) -> str:
        where = f"section {self.section}: " if self.section else ""
        return (f"{where}{self.side} {'before' if self.side == 'run-in' else 'after'} the "
                f"evaluated range is {self.available_s:.2f} s, shorter than the settling time "
                f"{self.settling_s:.2f} s of the {self.filter_label}; filter transients may "
                f"reach the evaluated part")

    def to_dict(self) -> dict:
        return {"section": self.section, "filter": self.filter_label, "side": self.side,
                "available_s": self.available_s, "settling_s": self.settling_s,
                "message": self.message}


def settling_check(time_s: np.ndarray, eval_mask: np.ndarray, fs: float, kind: str,
                   order: int = DEFAULT_ORDER, section: str = "") -> list[SettlingWarning]:
    """Compare run-in/run-out around the evaluated samples with the filter settling time.

    ``time_s``: sample times in s; ``eval_mask``: boolean mask of the evaluated samples.
    Returns one :class:`SettlingWarning` per short side (empty list when both suffice).

    Parameters
    ----------
    time_s : numpy.ndarray
        Sample times in s, shape (N,).
    eval_mask : numpy.ndarray
        Boolean mask of the evaluated samples, shape (N,).
    fs, kind, order : float, str, int
        Sampling rate in Hz, filter kind and Butterworth order as in :func:`design`.
    section : str
        Section id written into the warnings.

    Returns
    -------
    list of SettlingWarning
    """
    d = design(float(fs), kind, order)
    idx = np.flatnonzero(eval_mask)
    if idx.size == 0:
        return []
    run_in = float(time_s[idx[0]] - time_s[0])
    run_out = float(time_s[-1] - time_s[idx[-1]])
    out = []
    if run_in < d.settling_s:
        out.append(SettlingWarning(d.label, "run-in", run_in, d.settling_s, section))
    if run_out < d.settling_s:
        out.append(SettlingWarning(d.label, "run-out", run_out, d.settling_s, section))
    return out


#: multiple of the slowest EN filter's settling time (+ padding) a shortened run keeps after the
#: evaluated range (:func:`run_out_s`); measured on the bench campaign (12 sections, 768 EN and
#: supplementary values, 2026-11-28): largest relative change against the whole run 5.0·10⁻²
#: at 1×, 1.8·10⁻² at 1.5×, 5.7·10⁻³ at 2×, 1.3·10⁻³ at 2.5×, 6.8·10⁻⁴ at 3× (docs/diagnosis.md
#: "Only the evaluated span (issue 41, round 5)")
RUN_OUT_FACTOR = 2.0


def run_out_s(fs: float, order: int = DEFAULT_ORDER, factor: float | None = None) -> float:
    """The run-out (s) after the evaluated range that a simulation ending early must keep so
    the EN values in the range are those of the whole section: ``factor`` (default
    :data:`RUN_OUT_FACTOR`, ≥ 1) × the longest settling time of the EN filters
    (:data:`FILTER_KINDS`, :attr:`FilterDesign.settling_s`: one pass's impulse response below
    :data:`SETTLING_LEVEL` of its peak; at 200 Hz the band-pass 0.4–10 Hz, 2.44 s, against the
    low-pass 20 Hz, 0.12 s) plus the odd extension of the filtfilt padding (:attr:`FilterDesign.edge`
    samples) and one sample.

    Why: the only step of the EN chain that reads samples after the evaluated range is the
    backward pass of the zero-phase filtering (EN 14363:2005 on-track tests: low-pass 20 Hz for
    the forces, band-pass 0.4–10 Hz for the accelerations; Polach & Böttcher 2014 Table 2); the
    forward pass is causal and the sliding means and percentiles use the range only
    (:mod:`railval.core.en_section`). A backward pass started ``run_out_s`` after the range
    has decayed below ``SETTLING_LEVEL`` of its start transient when it reaches the range — the
    same criterion :func:`settling_check` applies to every section's run-out, so a shortened run
    raises no settling warning a whole one would not."""
    f = RUN_OUT_FACTOR if factor is None else float(factor)
    if not f >= 1.0:
        raise InvalidParameter(f"run-out factor must be >= 1 (the settling time itself), got {factor!r}")
    longest = max(design(float(fs), k, order).settling_s + design(float(fs), k, order).edge / float(fs)
                  for k in FILTER_KINDS)
    return f * longest + 1.0 / float(fs)
