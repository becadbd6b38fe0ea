"""EN 14363 processing of one test section into the 12 validation values (docs/design.md §3).

The same chain is applied to measured and simulated signals (Polach & Böttcher 2014 §5):

1. filter the *whole* recorded section (zero-phase Butterworth, :mod:`railval.core.filters`):
   low-pass 20 Hz for Y and Q, band-pass 0.4–10 Hz for car body accelerations;
2. form Y/Q (per wheel, sample-wise ratio) and ΣY = Y_L + Y_R (per wheelset) from the
   low-pass filtered forces;
3. cut to the evaluated (constant-curvature) range by the distance axis:
   samples with ``eval_start_m ≤ distance_m ≤ eval_end_m``;
4. statistic per quantity (registry :mod:`railval.core.quantities`):

   * 50 % value (median) — keeps its sign;
   * maximum — the larger magnitude of the 0.15 % and 99.85 % values (absolute value);
   * ``Q_max`` — the 99.85 % value;
   * rms — ``sqrt(mean(x²))`` over the evaluated samples;
   * ``YQ_max`` and ``SumY_max`` — the 2 m sliding mean evaluated every 0.5 m along the
     distance axis first (:func:`sliding_mean_distance`), then the maximum.

Percentile definition: the p-value is read from the cumulative distribution of the samples of the
evaluated part, as EN 14363 describes — the inverse of the empirical distribution function, i.e.
the smallest sample x with ``F_n(x) ≥ p`` (Hyndman & Fan type 1,
``numpy.quantile(method="inverted_cdf")``). With n samples sorted ascending this is the sample of
1-based rank ``ceil(n·p)`` (rank 1 for p·n < 1). For an even n the 50 % value is therefore the
lower of the two middle samples, not their average.

Definition sensitivity: the percentile method, the alignment of the sliding-mean grid and the
definition of the window mean are open choices of the texts (:mod:`railval.core.definitions`).
Besides the chosen reading's values, every section carries the values of the other readings
(``SectionValues.alternatives``), computed from the same filtered arrays and the same sorts —
nothing is filtered twice.

Throughput: the checks scan every channel once (one compiled integer pass for the peak
magnitude, the sections shared among the cores) and report in section order; steps 2–4 run
per section in one compiled call, the sections on the cores in parallel
(:mod:`railval.core.en_section`), with the same operations on the samples as the step-by-step
numpy code, so the same values; the PSD bands of all sections come from one batched Welch
that repeats scipy's arithmetic operation by operation, so the same bits
(:func:`railval.core.psd.welch_groups`).

Supplementary values (:mod:`railval.core.supplementary`): bogie-frame accelerations go through the
band-pass with the car body channels (rms, max); the PSD band rms of all acceleration channels come
from the unfiltered evaluated samples (``SectionValues.supplementary``).

References
----------
Polach & Böttcher 2014, §5 and Table 2.
EN 14363:2005, on-track tests: filtering, test sections, percentile values from the
cumulative frequency distribution.
Hyndman, R.J. & Fan, Y. (1996) Sample quantiles in statistical packages, Am. Stat. 50(4).
"""

from __future__ import annotations

import functools
import hashlib
import itertools
import json
import struct
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numba
import numpy as np

from railval.core.en_section import (
    SectionState,
    _evaluated_cut,
    _statistic,
    run_sections,
    section_values,
)
from railval.core.en_statistics import (  # noqa: F401 - the statistics of the chain, re-exported
    P_HIGH,
    P_LOW,
    P_MEDIAN,
    PERCENTILES,
    QUANTILE_METHOD,
    STEP_M,
    WINDOW_M,
    _row_percentiles,
    maxabs,
    percentile,
    rms,
    sliding_mean_distance,
)
from railval.core.errors import InvalidParameter, InvalidSignal
from railval.core.filters import DEFAULT_ORDER, check_order, design, filtfilt_rows
#: PROCESSING_VERSION: bump whenever the numbers this module produces can change (enters
#: result-cache keys); kept in railval.core.processing, which records read without this module
from railval.core.processing import PROCESSING_VERSION
from railval.core.quantities import QUANTITIES
from railval.core.supplementary import (
    BOGIE_KINDS,
    PSD_KINDS,
    SUPPLEMENTARY,
    psd_band_values_batch,
)
from railval.core.types import CHANNELS, SectionInfo, SignalSet, channel_name

#: the cached form of a section's values (:func:`pack_values`); enters the result-cache keys
#: so that a cache written in another form is never read (the numbers do not change with it)
CACHE_FORM = "packed/2"
#: largest sample magnitude processed: squares and filter states of larger values overflow
#: float64 (±1.8e308) and turn statistics into inf or NaN
MAX_ABS_SAMPLE = 1e100


class SectionValues(dict):
    """``{(quantity_id, position): value}`` of one section and one source, plus provenance.

    ``provenance[(quantity_id, position)]`` is the list of processing steps (filter, derived
    signal, cut, statistic) that produced the value; ``warnings`` lists filter settling
    warnings (run-in/run-out shorter than the settling time) as messages.

    ``alternatives[reading_id][(quantity_id, position)]``: the value under another reading of
    the open definitions (:mod:`railval.core.definitions`), stored only where it differs from
    the chosen value (:meth:`value_under` fills the rest); NaN where the reading is undefined
    (a sample window without samples). ``supplementary[(quantity_id, position)]``: the
    supplementary values (:mod:`railval.core.supplementary`).
    """

    def __init__(self, section_id: str, values=(), provenance=None, warnings=None,
                 alternatives=None, supplementary=None):
        super().__init__(values)
        self.section_id = section_id
        self.provenance: dict[tuple[str, str], tuple[str, ...]] = dict(provenance or {})
        self.warnings: list[str] = list(warnings or [])
        self.alternatives: dict[str, dict[tuple[str, str], float]] = {
            k: dict(v) for k, v in (alternatives or {}).items()}
        self.supplementary: dict[tuple[str, str], float] = dict(supplementary or {})

    @classmethod
    def _adopt(cls, section_id: str, values: dict, provenance: dict, warnings: list,
               alternatives: dict, supplementary: dict) -> SectionValues:
        """A SectionValues holding the given containers themselves (no copies): for the
        fresh containers of :func:`evaluate_batch`, which keeps no other reference."""
        out = cls.__new__(cls)
        dict.__init__(out, values)
        out.section_id = section_id
        out.provenance = provenance
        out.warnings = warnings
        out.alternatives = alternatives
        out.supplementary = supplementary
        return out

    def value_under(self, reading_id: str, key: tuple[str, str]) -> float:
        """The value of ``key`` under the reading ``reading_id`` (the chosen value where the
        reading does not change it)."""
        return self.alternatives.get(reading_id, {}).get(key, self[key])

    def to_dict(self) -> dict:
        return {
            "section": self.section_id,
            "values": [{"quantity": q, "position": p, "value": float(v),
                        "unit": QUANTITIES[q].unit,
                        "processing": list(self.provenance.get((q, p), ()))}
                       for (q, p), v in self.items()],
            "warnings": list(self.warnings),
            "processing_version": PROCESSING_VERSION,
            "alternatives": {rid: [{"quantity": q, "position": p,
                                    "value": None if not np.isfinite(v) else float(v)}
                                   for (q, p), v in vals.items()]
                             for rid, vals in self.alternatives.items()},
            "supplementary": [{"quantity": q, "position": p, "value": float(v),
                               "unit": SUPPLEMENTARY[q].unit}
                              for (q, p), v in self.supplementary.items()],
        }

    def to_pandas(self):
        import pandas as pd

        return pd.DataFrame([{"section": self.section_id, "quantity": q, "position": p,
                              "value": float(v), "unit": QUANTITIES[q].unit}
                             for (q, p), v in self.items()])


# --------------------------------------------------------------------------- validation

@numba.njit(cache=True, nogil=True)
def _increasing(d):  # pragma: no cover - compiled
    """Whether ``d`` is strictly increasing (``numpy.all(numpy.diff(d) > 0)``: False at NaN).
    Every comparison is made (no early exit), so the loop is vectorised."""
    ok = True
    for i in range(1, d.shape[0]):
        ok &= d[i] > d[i - 1]
    return ok


@numba.njit(cache=True, nogil=True)
def _peak_bits(x):  # pragma: no cover - compiled
    """The largest magnitude of ``x`` as the bits of a float64: the sign bit cleared, the bit
    patterns of non-negative floats order as their values, NaN above +inf — so the float of
    the result is max|x| (= ``max(max(x), −min(x))``), inf if any ±inf, NaN if any NaN (one
    integer pass, vectorised)."""
    bits = x.view(np.int64)
    peak = 0
    for i in range(bits.shape[0]):
        peak = max(peak, bits[i] & 0x7FFFFFFFFFFFFFFF)
    return peak


def _peak(arr) -> float:
    """``max(max(arr), −min(arr))`` of a 1-D channel of at least one sample (NaN if it holds
    NaN, else inf if it holds ±inf)."""
    if _compiled_layout(arr):
        return _float_of_bits(_peak_bits(arr))
    return max(float(np.max(arr)), -float(np.min(arr)))


def _compiled_layout(arr) -> bool:
    return (isinstance(arr, np.ndarray) and arr.ndim == 1 and arr.dtype == np.float64
            and arr.flags.c_contiguous and arr.size > 0)


def _float_of_bits(bits: int) -> float:
    return struct.unpack("<d", struct.pack("<q", int(bits)))[0]


def _bits_of(value: float) -> int:
    """The bits of a non-negative float64 as :func:`_peak_bits` gives them (their order is
    that of the values; every NaN and +inf lie above a finite limit)."""
    return struct.unpack("<q", struct.pack("<d", float(value)))[0]


def _scan_signalsets(signalsets: Sequence[SignalSet]) -> list[tuple[bool | None, dict]]:
    """Per section: whether ``distance_m`` is strictly increasing (None: not scanned) and the
    peak bits (:func:`_peak_bits`) of its float64 channels — one integer pass per channel,
    the sections shared among the cores (the pass is bound by memory reads). The checks
    then read them in section order (:func:`_check_signalset`), so the same error comes
    first."""
    from railval.core.workers import split_rows

    out: list[tuple[bool | None, dict]] = [(None, {}) for _ in signalsets]

    def part(a: int, b: int) -> None:
        for i in range(a, b):
            try:
                ss = signalsets[i]
                d = ss.distance_m
                incr = _increasing(d) if _compiled_layout(d) and d.size >= 2 else None
                out[i] = (incr, {name: _peak_bits(arr) for name, arr in ss.channels.items()
                                 if _compiled_layout(arr)})
            except Exception:  # noqa: BLE001 - left to the checks, raised in section order
                out[i] = (None, {})

    if signalsets:
        part(0, 1)  # the first in the calling thread: a first call compiles the scans once
        split_rows(lambda a, b: part(a + 1, b + 1), len(signalsets) - 1)
    return out


def _check_signalset(ss: SignalSet, sec: SectionInfo,
                     scanned: tuple[bool | None, dict] = (None, {})) -> None:
    n = len(ss)
    if not (np.isfinite(ss.fs) and ss.fs > 0):
        raise InvalidSignal(f"section {sec.id}: fs must be a positive number of Hz, got {ss.fs}")
    d = np.asarray(ss.distance_m)
    if d.shape != (n,):
        raise InvalidSignal(
            f"section {sec.id}: distance_m has shape {d.shape}, expected ({n},) like time_s")
    increasing, peaks = scanned
    if increasing is None:
        increasing = n >= 2 and bool(np.all(np.diff(d) > 0))
    if n < 2 or not increasing:
        raise InvalidSignal(f"section {sec.id}: distance_m must be strictly increasing")
    limit = _bits_of(MAX_ABS_SAMPLE)
    for name, arr in ss.channels.items():
        bits = peaks.get(name)
        if bits is not None and bits <= limit and arr.shape == (n,):
            continue  # scanned (a float64 array): finite and within the limit
        if np.shape(arr) != (n,):
            raise InvalidSignal(
                f"section {sec.id}: channel {name} has shape {np.shape(arr)}, expected ({n},)")
        peak = _float_of_bits(peaks[name]) if name in peaks else _peak(arr)
        if not np.isfinite(peak):
            raise InvalidSignal(f"section {sec.id}: channel {name} holds non-finite values "
                                f"({peak:g})")
        if not peak <= MAX_ABS_SAMPLE:
            raise InvalidSignal(
                f"section {sec.id}: channel {name} holds {peak:g}; samples must be finite and "
                f"within ±{MAX_ABS_SAMPLE:g} (MAX_ABS_SAMPLE)")
    if not sec.eval_start_m < sec.eval_end_m:
        raise InvalidSignal(
            f"section {sec.id}: evaluated range start {sec.eval_start_m} m must be below end "
            f"{sec.eval_end_m} m")
    if sec.eval_start_m < d[0] or sec.eval_end_m > d[-1]:
        raise InvalidSignal(
            f"section {sec.id}: evaluated range {sec.eval_start_m}–{sec.eval_end_m} m exceeds "
            f"the recorded distance {d[0]:.3f}–{d[-1]:.3f} m")


@dataclass
class _Plan:
    """Which rows of the stacked filter inputs belong to which section."""

    lp_names: list[str]
    bp_names: list[str]
    lp_rows: slice
    bp_rows: slice


#: channel kinds the EN chain processes: those the validation quantities are formed from
#: (Polach & Böttcher 2014 Table 2), then the supplementary bogie-frame accelerations
EN_CHAIN_KINDS = ("Y", "Q", "ay_cb", "az_cb", *BOGIE_KINDS)


def _needed_channels(ss: SignalSet) -> tuple[list[str], list[str]]:
    """The channels of :data:`EN_CHAIN_KINDS` present, split by their EN filter
    (:data:`railval.core.types.CHANNELS`): (low-pass, band-pass), in channel-kind order."""
    names = set(ss.channels)
    present = [(CHANNELS[k].en_filter, channel_name(k, p)) for k in EN_CHAIN_KINDS
               for p in CHANNELS[k].positions if channel_name(k, p) in names]
    return ([c for f, c in present if f == "lowpass"], [c for f, c in present if f == "bandpass"])


class _Clock:
    """Wall time per stage of :func:`evaluate_batch` (``lap(stage)`` adds the time since the
    previous lap to ``stage``) into the caller's dict, else into the active stage collector
    (:mod:`railval.core.stages`); no-op without either."""

    def __init__(self, into: dict[str, float] | None):
        from railval.core import stages

        collector = stages.current() if into is None else None
        self.add = (None if into is None and collector is None
                    else collector.add if collector is not None
                    else lambda k, v: into.__setitem__(k, into.get(k, 0.0) + v))
        self.last = time.perf_counter() if self.add is not None else 0.0

    def lap(self, stage: str) -> None:
        if self.add is not None:
            now = time.perf_counter()
            self.add(stage, now - self.last)
            self.last = now


def evaluate_batch(signalsets: Sequence[SignalSet], sections: Sequence[SectionInfo], *,
                   order: int = DEFAULT_ORDER, alternatives: bool = True,
                   supplementary: bool = True,
                   timings: dict[str, float] | None = None) -> list[SectionValues]:
    """Process many sections at once (vectorised path); returns one SectionValues each.

    Sections with equal sampling rate and length are filtered together (one compiled
    zero-phase call per filter kind over all their channels, 16 channels in lockstep, the
    cores sharing the blocks); each section's percentiles come from the order statistics
    selected once for all its evaluated rows (:mod:`railval.core.orderstat`). Results equal
    :func:`evaluate_section` on each section alone.

    Parameters
    ----------
    signalsets, sections : sequence of SignalSet, sequence of SectionInfo
        One signal set (channels of N samples, ``distance_m`` in m) per section.
    order, alternatives, supplementary : int, bool, bool
        Butterworth order; ``False`` leaves out the other readings' / PSD band values.
    timings : dict or None
        Receives the wall time in s per stage (``checks``, ``filter``, ...).

    Returns
    -------
    list of SectionValues
        In the order of ``sections`` (see :func:`evaluate_section`).
    """
    clock = _Clock(timings)
    check_order(order)
    if len(signalsets) != len(sections):
        raise InvalidParameter(
            f"evaluate_batch needs one SectionInfo per SignalSet, got {len(signalsets)} "
            f"signal sets and {len(sections)} sections")
    plans: list[_Plan] = []
    groups: dict[tuple[float, int], list[int]] = {}
    for i, (ss, sec, scanned) in enumerate(zip(signalsets, sections,
                                               _scan_signalsets(signalsets))):
        _check_signalset(ss, sec, scanned)
        lp, bp = _needed_channels(ss)
        plans.append(_Plan(lp, bp, slice(0, 0), slice(0, 0)))
        groups.setdefault((float(ss.fs), len(ss)), []).append(i)

    clock.lap("checks")
    filtered_lp: dict[int, np.ndarray] = {}
    filtered_bp: dict[int, np.ndarray] = {}
    for (fs, n), members in groups.items():
        for kind, attr, store in (("lowpass", "lp_names", filtered_lp),
                                  ("bandpass", "bp_names", filtered_bp)):
            rows = [np.asarray(signalsets[i].channels[c], dtype=np.float64)
                    for i in members for c in getattr(plans[i], attr)]
            if not rows:  # (non-finite samples were refused by _check_signalset)
                continue
            out = filtfilt_rows(rows, fs, kind, order)
            pos = 0
            for i in members:
                k = len(getattr(plans[i], attr))
                store[i] = out[pos:pos + k]
                pos += k
    clock.lap("filter")
    out: list[SectionValues] = []
    for c0 in range(0, len(signalsets), SECTIONS_PER_CHUNK):
        states = [SectionState(signalsets[i], sections[i], order, alternatives, clock, plans[i],
                               filtered_lp.pop(i, None), filtered_bp.pop(i, None))
                  for i in range(c0, min(c0 + SECTIONS_PER_CHUNK, len(signalsets)))]
        out += _chunk_values(states, supplementary, clock)
    return out


#: sections whose intermediate rows (derived rows, integrals, PSD segments) exist at once
SECTIONS_PER_CHUNK = 16


def _chunk_values(states: list[SectionState], supplementary: bool, clock: _Clock
                  ) -> list[SectionValues]:
    """Steps 2–4 of a chunk of sections (the compiled step on the cores, then the values in
    section order), then their PSD bands in one Welch call per segment length."""
    run_sections(states)
    for st in states:
        section_values(st)
        st.release()
    if supplementary:
        raw = [{name: np.asarray(arr, dtype=np.float64)[st.cut]
                for name, arr in st.ss.channels.items() if name.rpartition("_")[0] in PSD_KINDS}
               for st in states]
        for st, bands in zip(states, psd_band_values_batch(raw, [st.fs for st in states]),
                             strict=True):
            st.supp.update(bands)
    clock.lap("supplementary")
    return [SectionValues._adopt(st.sec.id, *st.result()) for st in states]


def evaluate_section(signalset: SignalSet, section_info: SectionInfo, *,
                     order: int = DEFAULT_ORDER) -> SectionValues:
    """The 12 quantities at every available position of one section (docs/design.md §3).

    Parameters
    ----------
    signalset, section_info, order : SignalSet, SectionInfo, int
        Channels (N samples each); evaluated span in m; Butterworth order of both filters.

    Returns
    -------
    SectionValues
        ``{(qty, position): value}`` (kN, –, m/s²), processing steps, settling warnings.
    """
    return evaluate_batch([signalset], [section_info], order=order)[0]


@dataclass
class QuantityTrace:
    """The processed signal one EN 14363 quantity is evaluated on, with its statistic.

    ``distance_m``/``values``: the filtered signal of the quantity over the whole section
    (Y/Q formed sample-wise from the low-pass filtered Y and Q, ΣY = Y_L + Y_R of the
    low-pass filtered forces, band-pass for accelerations); ``sliding_centres_m``/
    ``sliding_means``: the 2 m sliding means over the evaluated range where the quantity uses
    them (else None); ``marks``: the evaluated statistic(s) by name (``"50 % value"``,
    ``"0.15 % value"``, ``"99.85 % value"``, ``"rms value"``), in the quantity's unit;
    ``value``: the quantity's value in the section (as :func:`evaluate_section` gives it).
    """

    quantity: str
    position: str
    signal_label: str
    unit: str
    distance_m: np.ndarray
    values: np.ndarray
    eval_range_m: tuple[float, float]
    sliding_centres_m: np.ndarray | None
    sliding_means: np.ndarray | None
    marks: dict[str, float]
    value: float


def quantity_trace(signalset: SignalSet, section: SectionInfo, quantity: str, position: str, *,
                   order: int = DEFAULT_ORDER) -> QuantityTrace:
    """The signal quantity ``quantity`` at ``position`` is evaluated on and its statistic, for
    plotting what a row of the validation is about (Polach & Böttcher 2014 Table 2; EN 14363).

    Processing as :func:`evaluate_section` (:func:`_evaluated_cut`, :func:`_statistic`).

    Parameters
    ----------
    signalset, section : SignalSet, SectionInfo
        The section's channels (N samples each) and its evaluated span in m.
    quantity, position, order : str, str, int
        Quantity id (e.g. ``"YQ_max"``), position (e.g. ``"11"``), Butterworth order.

    Returns
    -------
    QuantityTrace
        Signal (N,) over ``distance_m``, sliding means, marks, value (quantity's unit).
    """
    if quantity not in QUANTITIES:
        raise InvalidParameter(f"unknown quantity {quantity!r}; known: {', '.join(QUANTITIES)}")
    q = QUANTITIES[quantity]
    names = q.channels(position)
    missing = [c for c in names if c not in signalset.channels]
    if missing:
        raise InvalidSignal(f"section {section.id}: {quantity} at {position} needs channel(s) {missing}")
    fs = float(signalset.fs)
    data = np.vstack([np.asarray(signalset.channels[c], dtype=np.float64) for c in names])
    filt = filtfilt_rows(data, fs, q.filter, order)
    if q.signal == "YQ":
        sig = filt[0] / filt[1]
        label = f"Y/Q {position} ({design(fs, q.filter, order).label}, Y/Q sample-wise)"
    elif q.signal == "SumY":
        sig = filt[0] + filt[1]
        label = f"ΣY {position} = {names[0]} + {names[1]} ({design(fs, q.filter, order).label})"
    else:
        sig = filt[0]
        label = f"{names[0]} ({design(fs, q.filter, order).label})"
    d = np.asarray(signalset.distance_m, dtype=np.float64)
    cut, _ = _evaluated_cut(d, section)
    centres = means = None
    src = sig[cut]
    if q.sliding_mean:
        centres, means = sliding_mean_distance(sig, d, section.eval_start_m, section.eval_end_m)
        src = means
    lo, med, hi = (float(v) for v in _row_percentiles(src)[0][0])
    value = float(_statistic(q.processing, lo, med, hi, float(rms(src))))
    marks = {"median": {"50 % value": med}, "p99.85": {"99.85 % value": hi},
             "rms": {"rms value": value},
             "maxabs": {"0.15 % value": lo, "99.85 % value": hi}}[q.processing]
    return QuantityTrace(quantity, position, label, q.unit, d, sig,
                         (float(section.eval_start_m), float(section.eval_end_m)),
                         centres, means, marks, value)


def evaluate_present(signalsets: Mapping[str, SignalSet], sections: Sequence[SectionInfo], *,
                     order: int = DEFAULT_ORDER) -> dict[str, SectionValues]:
    """:func:`evaluate_batch` of the sections of ``sections`` that ``signalsets`` holds.

    Parameters
    ----------
    signalsets, sections, order : mapping of str to SignalSet, sequence of SectionInfo, int

    Returns
    -------
    dict of str to SectionValues
        Keyed by section id in the order of ``sections``.
    """
    present = [s for s in sections if s.id in signalsets]
    values = evaluate_batch([signalsets[s.id] for s in present], present, order=order)
    return {s.id: v for s, v in zip(present, values, strict=True)}


def section_cache_key(section: SectionInfo, fs: float, n: int, distance_sha: str,
                      channel_hashes: Mapping[str, str], order: int) -> str:
    """Key of the processed values of one section of one source: SHA-256 over the processing
    version, the cached form (:data:`CACHE_FORM`), filter order, section id, evaluated range, fs, n, the distance-axis hash and the
    sorted (channel, content hash) pairs. Any change of samples, axis, range, order or
    processing code changes the key."""
    h = hashlib.sha256()
    parts = [PROCESSING_VERSION, CACHE_FORM, f"order={int(order)}", f"section={section.id}",
             f"eval={section.eval_start_m!r}:{section.eval_end_m!r}", f"fs={float(fs)!r}",
             f"n={int(n)}", f"distance={distance_sha}"]
    parts += [f"{c}={channel_hashes[c]}" for c in sorted(channel_hashes)]
    h.update("\n".join(parts).encode())
    return "en14363:" + h.hexdigest()


_PACK_MAGIC = b"RVP2"
_PACK_HEAD = struct.Struct("<4sII")  # magic, bytes of the layout, bytes of the warnings


def pack_values(values: SectionValues) -> bytes:
    """A section's values, warnings, values under the alternative readings and supplementary
    values (the cached form; provenance not kept): a header, the layout (every key, in
    order) and the warnings as JSON, then every value as one little-endian float64 block in
    layout order (the same float64s; non-finite values under an alternative reading are
    stored as NaN, as the former JSON form did). The layout is the same for every section
    with the same channels, so :func:`unpack_values` parses it once."""
    alts = values.alternatives
    supp_vals = values.supplementary
    shape = (tuple(values), tuple((rid, tuple(vals)) for rid, vals in alts.items()),
             tuple(supp_vals))
    layout = _LAYOUTS.get(shape)
    if layout is None:
        layout = json.dumps([[list(k) for k in shape[0]],
                             [[rid, [list(k) for k in keys]] for rid, keys in shape[1]],
                             [list(k) for k in shape[2]]]).encode()
        if len(_LAYOUTS) >= 256:
            _LAYOUTS.clear()
        _LAYOUTS[shape] = layout
    n_main, n_supp = len(values), len(supp_vals)
    n_alt = sum(len(vals) for vals in alts.values())
    flat = np.fromiter(itertools.chain(values.values(), supp_vals.values(),
                                       *(vals.values() for vals in alts.values())),
                       dtype=np.float64, count=n_main + n_supp + n_alt)
    if not np.isfinite(flat[:n_main + n_supp]).all():
        raise ValueError(f"section {values.section_id}: a value is not finite")
    alt = flat[n_main + n_supp:]
    warnings = json.dumps(values.warnings).encode() if values.warnings else b"[]"
    return b"".join([_PACK_HEAD.pack(_PACK_MAGIC, len(layout), len(warnings)), layout, warnings,
                     flat[:n_main].astype("<f8").tobytes(),
                     np.where(np.isfinite(alt), alt, np.nan).astype("<f8").tobytes(),
                     flat[n_main:n_main + n_supp].astype("<f8").tobytes()])


#: layout JSON of :func:`pack_values` by its keys (sections with the same channels share it)
_LAYOUTS: dict[tuple, bytes] = {}


@functools.lru_cache(maxsize=256)
def _pack_layout(layout: bytes) -> tuple[tuple, tuple, tuple]:
    """The keys of a packed layout as tuples (parsed once per distinct layout)."""
    main, alts, supp = json.loads(layout)
    return (tuple(tuple(k) for k in main),
            tuple((rid, tuple(tuple(k) for k in keys)) for rid, keys in alts),
            tuple(tuple(k) for k in supp))


def unpack_values(section_id: str, blob: bytes) -> SectionValues:
    """The inverse of :func:`pack_values` (also reads the former JSON form)."""
    if blob[:4] != _PACK_MAGIC:
        return _unpack_json(section_id, blob)
    _magic, n_layout, n_warn = _PACK_HEAD.unpack_from(blob)
    start = _PACK_HEAD.size
    main, alts, supp = _pack_layout(bytes(blob[start:start + n_layout]))
    warnings = json.loads(blob[start + n_layout:start + n_layout + n_warn])
    flat = np.frombuffer(blob, dtype="<f8", offset=start + n_layout + n_warn).tolist()
    out = SectionValues(section_id, zip(main, flat), warnings=warnings)
    at = len(main)
    for rid, keys in alts:
        out.alternatives[rid] = dict(zip(keys, flat[at:at + len(keys)]))
        at += len(keys)
    out.supplementary = dict(zip(supp, flat[at:]))
    return out


def _unpack_json(section_id: str, blob: bytes) -> SectionValues:
    """The former JSON form of the cached values."""
    doc = json.loads(blob)
    alts = {rid: {(q, p): (float("nan") if v is None else v) for q, p, v in vals}
            for rid, vals in doc.get("alternatives", {}).items()}
    return SectionValues(section_id, {(q, p): v for q, p, v in doc["values"]},
                         warnings=doc["warnings"], alternatives=alts,
                         supplementary={(q, p): v for q, p, v in doc.get("supplementary", [])})
