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

import hashlib
import json
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from railval.core.definitions import (
    CHOSEN,
    SLIDING_VARIANTS,
    Reading,
    sample_window_means,
    window_centres,
)
from railval.core.en_statistics import (  # noqa: F401 - the statistics of the chain, re-exported
    P_HIGH,
    P_LOW,
    P_MEDIAN,
    PERCENTILES,
    QUANTILE_METHOD,
    STEP_M,
    WINDOW_M,
    _check_sliding_range,
    _interpolant_means,
    _row_percentiles,
    maxabs,
    percentile,
    rms,
    sliding_mean_distance,
)
from railval.core.errors import InvalidParameter, InvalidSignal
from railval.core.filters import DEFAULT_ORDER, check_order, design, filtfilt_rows, settling_check
from railval.core.quantities import QUANTITIES, WHEELSET_POSITIONS
from railval.core.supplementary import BOGIE_KINDS, PSD_KINDS, SUPPLEMENTARY, psd_band_values
from railval.core.types import CHANNELS, WHEEL_POSITIONS, SectionInfo, SignalSet, channel_name

#: bump whenever the numbers this module produces can change (enters result-cache keys)
PROCESSING_VERSION = "en14363/2"
#: largest sample magnitude processed: squares and filter states of larger values overflow
#: float64 (±1.8e308) and turn statistics into inf or NaN
MAX_ABS_SAMPLE = 1e100
#: the reading that differs from the chosen one only in the percentile method
_LINEAR = Reading("linear", CHOSEN.grid, CHOSEN.window)


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

def _check_signalset(ss: SignalSet, sec: SectionInfo) -> None:
    n = len(ss)
    if not (np.isfinite(ss.fs) and ss.fs > 0):
        raise InvalidSignal(f"section {sec.id}: fs must be a positive number of Hz, got {ss.fs}")
    d = np.asarray(ss.distance_m)
    if d.shape != (n,):
        raise InvalidSignal(
            f"section {sec.id}: distance_m has shape {d.shape}, expected ({n},) like time_s")
    if n < 2 or not np.all(np.diff(d) > 0):
        raise InvalidSignal(f"section {sec.id}: distance_m must be strictly increasing")
    for name, arr in ss.channels.items():
        if np.shape(arr) != (n,):
            raise InvalidSignal(
                f"section {sec.id}: channel {name} has shape {np.shape(arr)}, expected ({n},)")
        peak = max(float(np.max(arr)), -float(np.min(arr))) if n else 0.0
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
    for i, (ss, sec) in enumerate(zip(signalsets, sections)):
        _check_signalset(ss, sec)
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
    return [_section_stats(signalsets[i], sections[i], plans[i], filtered_lp.get(i),
                           filtered_bp.get(i), order, alternatives, supplementary, clock)
            for i in range(len(signalsets))]


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


def _evaluated_cut(d: np.ndarray, sec: SectionInfo) -> tuple[np.ndarray, slice, int]:
    """Step 3 of the chain: the samples with ``eval_start_m ≤ distance_m ≤ eval_end_m`` as a
    mask and as the slice from the first to the last of them, and their number (≥ 2)."""
    mask = (d >= sec.eval_start_m) & (d <= sec.eval_end_m)
    n_eval = int(mask.sum())
    if n_eval < 2:
        raise InvalidSignal(
            f"section {sec.id}: evaluated range {sec.eval_start_m}–{sec.eval_end_m} m holds "
            f"{n_eval} samples, needs at least 2")
    lo_idx, hi_idx = np.flatnonzero(mask)[[0, -1]]
    return mask, slice(int(lo_idx), int(hi_idx) + 1), n_eval


def _statistic(processing: str, p_lo, p_med, p_hi, rms_value=None):
    """Step 4: a quantity's value from the (0.15 %, 50 %, 99.85 %) values and the rms by the
    registry's ``Quantity.processing`` (:mod:`railval.core.quantities`; Polach & Böttcher 2014
    Table 2): ``median`` the 50 % value with sign, ``p99.85`` the 99.85 % value, ``maxabs``
    the larger magnitude of the 0.15 % and 99.85 % values, ``rms`` the rms."""
    if processing == "maxabs":
        return maxabs(p_lo, p_hi)
    return {"median": p_med, "p99.85": p_hi, "rms": rms_value}[processing]


_DERIVE_TEXT = {"YQ": "Y/Q formed sample-wise from the low-pass filtered Y and Q",
                "SumY": "ΣY = Y_L + Y_R formed from the low-pass filtered forces"}


class _SectionState:
    """One section's values while :func:`_section_stats` forms them: the evaluated cut, the
    values, their provenance, warnings, values under the other readings and supplementary
    values."""

    def __init__(self, ss: SignalSet, sec: SectionInfo, order: int, with_alternatives: bool,
                 clock: _Clock):
        self.ss, self.sec, self.order, self.clock = ss, sec, order, clock
        self.d = np.asarray(ss.distance_m, dtype=np.float64)
        self.mask, self.cut, n_eval = _evaluated_cut(self.d, sec)
        self.fs = float(ss.fs)
        self.cut_text = (f"cut to evaluated range {sec.eval_start_m:g}–{sec.eval_end_m:g} m "
                         f"by distance ({n_eval} samples)")
        self.pct_text = (f"percentiles: np.quantile method='{QUANTILE_METHOD}' (EN 14363 "
                         "cumulative distribution)")
        self.values: dict[tuple[str, str], float] = {}
        self.prov: dict[tuple[str, str], tuple[str, ...]] = {}
        self.warnings: list[str] = []
        self.alts: dict[str, dict[tuple[str, str], float]] = {}
        self.supp: dict[tuple[str, str], float] = {}
        self.with_alternatives = with_alternatives
        self.methods = ((QUANTILE_METHOD, _LINEAR.percentile) if with_alternatives
                        else (QUANTILE_METHOD,))

    def alternative(self, reading: Reading, key: tuple[str, str], value: float) -> None:
        """Keep ``value`` under ``reading`` where it differs from the chosen value (NaN:
        undefined under the reading)."""
        if self.with_alternatives and value != self.values[key]:  # True for NaN as well
            self.alts.setdefault(reading.id, {})[key] = float(value)

    def settle(self, kind: str) -> str:
        """Settling warnings of filter ``kind``; returns the filter's provenance label."""
        self.warnings += [w.message for w in settling_check(
            self.ss.time_s, self.mask, self.fs, kind, self.order, self.sec.id)]
        return design(self.fs, kind, self.order).label + ", whole section"

    def result(self) -> SectionValues:
        order_keys = [(q, p) for q, quantity in QUANTITIES.items() for p in quantity.positions()]
        supp_keys = [(q, p) for q, sq in SUPPLEMENTARY.items() for p in sq.positions()]
        return SectionValues(self.sec.id, {k: self.values[k] for k in order_keys
                                           if k in self.values},
                             self.prov, self.warnings, self.alts,
                             {k: self.supp[k] for k in supp_keys if k in self.supp})


def _section_stats(ss: SignalSet, sec: SectionInfo, plan: _Plan, lp: np.ndarray | None,
                   bp: np.ndarray | None, order: int, with_alternatives: bool = True,
                   with_supplementary: bool = True, clock: _Clock | None = None
                   ) -> SectionValues:
    """Steps 2–4 of the chain for one section from its filtered rows (``lp``/``bp`` in the
    channel order of ``plan``)."""
    st = _SectionState(ss, sec, order, with_alternatives, clock or _Clock(None))
    if lp is not None and lp.shape[0]:
        _lowpass_values(st, plan, lp)
    if bp is not None and bp.shape[0]:
        _bandpass_values(st, plan, bp)
    st.clock.lap("statistics")
    if with_supplementary:
        raw_acc = {name: np.asarray(arr, dtype=np.float64)[st.cut]
                   for name, arr in ss.channels.items() if name.rpartition("_")[0] in PSD_KINDS}
        st.supp.update(psd_band_values(raw_acc, st.fs))
    st.clock.lap("supplementary")
    return st.result()


def _derived_rows(st: _SectionState, lp: np.ndarray, index: dict[str, int],
                  wheels_yq: list[str], wsets: list[str]):
    """Step 2: Y/Q per wheel and ΣY per wheelset, only where needed: the evaluated samples
    plus one on each side (the sliding-mean windows lie inside the evaluated range). Returns
    ``(ratio, sumy, wide, inner)``: the rows, their slice of the section and the evaluated
    part within them."""
    cut = st.cut
    wide = slice(max(cut.start - 1, 0), min(cut.stop + 1, lp.shape[1]))
    inner = slice(cut.start - wide.start, cut.stop - wide.start)
    n_wide = wide.stop - wide.start
    ratio = np.empty((len(wheels_yq), n_wide))
    for r, p in enumerate(wheels_yq):
        q = lp[index[f"Q_{p}"], wide]
        if np.any(q[inner] == 0.0):
            raise InvalidSignal(
                f"section {st.sec.id}: Q_{p} is exactly 0 kN inside the evaluated range; "
                f"Y/Q is undefined")
        np.divide(lp[index[f"Y_{p}"], wide], q, out=ratio[r])
    sumy = np.empty((len(wsets), n_wide))
    for r, ws in enumerate(wsets):
        np.add(lp[index[f"Y_w{ws[2:]}L"], wide], lp[index[f"Y_w{ws[2:]}R"], wide], out=sumy[r])
    return ratio, sumy, wide, inner


def _lowpass_values(st: _SectionState, plan: _Plan, lp: np.ndarray) -> None:
    """The force quantities (Y, Q, Y/Q, ΣY: percentiles, then the sliding-mean maxima)."""
    lp_label = st.settle("lowpass")
    index = {c: r for r, c in enumerate(plan.lp_names)}
    wheels_y = [p for p in WHEEL_POSITIONS if f"Y_{p}" in index]
    wheels_q = [p for p in WHEEL_POSITIONS if f"Q_{p}" in index]
    wheels_yq = [p for p in wheels_y if p in wheels_q]
    wsets = [ws for ws in WHEELSET_POSITIONS
             if f"Y_w{ws[2:]}L" in index and f"Y_w{ws[2:]}R" in index]
    ratio, sumy, wide, inner = _derived_rows(st, lp, index, wheels_yq, wsets)
    families = (("Y", wheels_y), ("Q", wheels_q), ("YQ", wheels_yq), ("SumY", wsets))
    rows = np.empty((sum(len(p) for _, p in families), st.cut.stop - st.cut.start))
    r = 0
    for name in [f"Y_{p}" for p in wheels_y] + [f"Q_{p}" for p in wheels_q]:
        rows[r] = lp[index[name], st.cut]
        r += 1
    rows[r:r + len(wheels_yq)] = ratio[:, inner]
    rows[r + len(wheels_yq):] = sumy[:, inner]
    both = (_row_percentiles(rows, st.methods) if rows.shape[0]
            else [np.empty((0, 3))] * len(st.methods))
    _force_percentile_values(st, families, both[0], both[-1], lp_label)
    slide_rows = np.vstack([ratio, sumy])
    if slide_rows.shape[0]:
        keys = [("YQ_max", p) for p in wheels_yq] + [("SumY_max", w) for w in wsets]
        _sliding_values(st, slide_rows, st.d[wide], keys, lp_label)


#: the values a force family's percentiles give: (quantity, provenance of the statistic)
_FORCE_PERCENTILE_QUANTITIES = {
    "Y": (("Y_qst", "50 % value (median, with sign)"),
          ("Y_max", "max(|0.15 % value|, |99.85 % value|)")),
    "Q": (("Q_qst", "50 % value (median, with sign)"), ("Q_max", "99.85 % value")),
    "YQ": (("YQ_qst", "50 % value (median, with sign)"),),
    "SumY": (("SumY_qst", "50 % value (median, with sign)"),),
}


def _force_percentile_values(st: _SectionState, families, pct: np.ndarray,
                             pct_lin: np.ndarray, lp_label: str) -> None:
    """The percentile values of the force rows (in ``families`` order) under the chosen
    reading (``pct``) and the linear one (``pct_lin``)."""
    r = 0
    for fam, positions in families:
        derive = _DERIVE_TEXT.get(fam)
        base = (lp_label,) + ((derive,) if derive else ()) + (st.cut_text,)
        for p in positions:
            for qid, text in _FORCE_PERCENTILE_QUANTITIES[fam]:
                processing = QUANTITIES[qid].processing
                st.values[(qid, p)] = float(_statistic(processing, *pct[r]))
                st.prov[(qid, p)] = base + (text, st.pct_text)
                st.alternative(_LINEAR, (qid, p), _statistic(processing, *pct_lin[r]))
            r += 1


def _sliding_values(st: _SectionState, slide_rows: np.ndarray, d_wide: np.ndarray,
                    keys: list[tuple[str, str]], lp_label: str) -> None:
    """``YQ_max`` and ``SumY_max``: the maxima of the 2 m sliding means (step 6 of
    docs/validation.md), then, with the alternatives, their values under the other readings.
    The chosen grid (from the section start) and the grid from the first evaluated sample
    come from one cumulative integral."""
    sec = st.sec
    _check_sliding_range(d_wide, sec.eval_start_m, sec.eval_end_m, WINDOW_M, STEP_M)
    origins = [sec.eval_start_m] + ([float(st.d[st.cut.start])] if st.with_alternatives else [])
    interp = _interpolant_means(slide_rows, d_wide, sec.eval_start_m, sec.eval_end_m,
                                WINDOW_M, STEP_M, origins)
    means = interp[0][1]
    # the order statistics of every percentile method in one selection (the linear
    # reading's values of the chosen means are used by the alternatives)
    chosen_pcts = _row_percentiles(means, st.methods)
    spct = chosen_pcts[0]
    slide_text = (f"sliding mean over {WINDOW_M:g} m every {STEP_M:g} m along distance "
                  f"(windows inside {sec.eval_start_m:g}–{sec.eval_end_m:g} m, "
                  f"{means.shape[1]} values; exact integral of the linear interpolant)")
    for r, key in enumerate(keys):
        st.values[key] = float(_statistic(QUANTITIES[key[0]].processing, *spct[r]))
        st.prov[key] = (lp_label, _DERIVE_TEXT[key[0].split("_")[0]], slide_text,
                        "max(|0.15 % value|, |99.85 % value|)", st.pct_text)
    st.clock.lap("statistics")
    if st.with_alternatives:
        _sliding_alternatives(slide_rows, d_wide, st.d[st.cut.start], sec, keys,
                              (means, chosen_pcts), interp[1][1], st.methods, st.alternative)
    st.clock.lap("alternatives")


def _bandpass_values(st: _SectionState, plan: _Plan, bp: np.ndarray) -> None:
    """The car body accelerations (rms, maximum) and, from the same filter call and
    statistics, the supplementary bogie-frame values."""
    bp_label = st.settle("bandpass")
    rows = bp[:, st.cut]
    both = _row_percentiles(rows, st.methods)
    pct, pct_lin = both[0], both[-1]
    rmsv = rms(rows)
    for r, name in enumerate(plan.bp_names):
        kind, _, pos = name.rpartition("_")
        if kind in BOGIE_KINDS:  # supplementary: same filter call, same statistics
            st.supp[(f"{kind}_rms", pos)] = float(rmsv[r])
            st.supp[(f"{kind}_max", pos)] = float(maxabs(pct[r, 0], pct[r, 2]))
            continue
        q = kind.split("_")[0]
        st.values[(f"{q}_rms", pos)] = float(rmsv[r])
        st.prov[(f"{q}_rms", pos)] = (bp_label, st.cut_text, "rms value")
        st.values[(f"{q}_max", pos)] = float(_statistic("maxabs", *pct[r]))
        st.prov[(f"{q}_max", pos)] = (bp_label, st.cut_text,
                                      "max(|0.15 % value|, |99.85 % value|)", st.pct_text)
        st.alternative(_LINEAR, (f"{q}_max", pos), _statistic("maxabs", *pct_lin[r]))


def _sliding_alternatives(slide_rows: np.ndarray, d_wide: np.ndarray, first_m: float,
                          sec: SectionInfo, keys: list[tuple[str, str]], chosen: tuple,
                          first_interp: np.ndarray, methods: tuple[str, ...],
                          alternative) -> None:
    """Values of the sliding-mean maxima under every other reading (grid alignment × window
    mean × percentile method, :mod:`railval.core.definitions`) from the same derived rows;
    the prefix sums and the cumulative integral are formed once for all readings, and the
    percentiles of the chosen means (``chosen``: means and their percentiles under each
    method) are not selected again."""
    origins = {"section_start": sec.eval_start_m, "first_sample": float(first_m)}
    prefix = np.empty((slide_rows.shape[0], slide_rows.shape[1] + 1))
    prefix[:, 0] = 0.0
    prefix[:, 1:] = slide_rows
    np.cumsum(prefix, axis=1, out=prefix)  # in place: the same sums, a contiguous cumsum
    for grid, window in SLIDING_VARIANTS:
        pcts = None
        if (grid, window) == CHOSEN.sliding:
            means, pcts = chosen
        elif window == "interpolant":
            means = first_interp
        else:
            centres = window_centres(sec.eval_start_m, sec.eval_end_m, origins[grid], WINDOW_M,
                                     STEP_M)
            means = sample_window_means(slide_rows, d_wide, centres, WINDOW_M,
                                        closed=(window == "samples_closed"), prefix=prefix)
        undefined = ~np.all(np.isfinite(means), axis=1)
        pcts = _row_percentiles(means, methods) if pcts is None else pcts
        for method, pct in zip(methods, pcts, strict=True):
            reading = Reading(method, grid, window)
            if reading == CHOSEN:
                continue
            vals = maxabs(pct[:, 0], pct[:, 2])
            for r, key in enumerate(keys):
                alternative(reading, key, float("nan") if undefined[r] else float(vals[r]))


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
    _, cut, _ = _evaluated_cut(d, section)
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
    version, filter order, section id, evaluated range, fs, n, the distance-axis hash and the
    sorted (channel, content hash) pairs. Any change of samples, axis, range, order or
    processing code changes the key."""
    h = hashlib.sha256()
    parts = [PROCESSING_VERSION, f"order={int(order)}", f"section={section.id}",
             f"eval={section.eval_start_m!r}:{section.eval_end_m!r}", f"fs={float(fs)!r}",
             f"n={int(n)}", f"distance={distance_sha}"]
    parts += [f"{c}={channel_hashes[c]}" for c in sorted(channel_hashes)]
    h.update("\n".join(parts).encode())
    return "en14363:" + h.hexdigest()


def pack_values(values: SectionValues) -> bytes:
    """A section's values, warnings, values under the alternative readings and supplementary
    values as JSON bytes (the cached form; provenance not kept)."""
    return json.dumps({
        "values": [[q, p, float(v)] for (q, p), v in values.items()],
        "warnings": values.warnings,
        "alternatives": {rid: [[q, p, float(v) if np.isfinite(v) else None]
                               for (q, p), v in vals.items()]
                         for rid, vals in values.alternatives.items()},
        "supplementary": [[q, p, float(v)] for (q, p), v in values.supplementary.items()],
    }, allow_nan=False).encode()


def unpack_values(section_id: str, blob: bytes) -> SectionValues:
    """The inverse of :func:`pack_values`."""
    doc = json.loads(blob)
    alts = {rid: {(q, p): (float("nan") if v is None else v) for q, p, v in vals}
            for rid, vals in doc.get("alternatives", {}).items()}
    return SectionValues(section_id, {(q, p): v for q, p, v in doc["values"]},
                         warnings=doc["warnings"], alternatives=alts,
                         supplementary={(q, p): v for q, p, v in doc.get("supplementary", [])})
