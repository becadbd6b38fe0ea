"""Steps 2–4 of the EN 14363 chain for many sections at once (:mod:`railval.core.en14363`):
derived signals, the evaluated cut, percentile values, rms, the sliding-mean maxima and the
values under the other readings.

Per section, one compiled call (:func:`_section_kernel`, run for the sections of a batch on
the cores in parallel, :func:`railval.core.workers.split_rows`) forms Y/Q (per wheel,
sample-wise ratio) and ΣY = Y_L + Y_R (per wheelset) from the low-pass filtered rows over the
evaluated range plus one sample on each side, checks Q ≠ 0 inside the evaluated range and
selects the order statistics every percentile reading needs from all evaluated rows — the
filtered forces and the derived rows read in place, without row copies
(:func:`railval.core.orderstat.select_ranks`: the samples a full sort gives at those
positions, so the percentiles are those of ``numpy.quantile``); of the band-pass rows only
those of the 0.15 % and 99.85 % values (their maxima read no median), near the two ends of
the row (:func:`railval.core.en_kernels._end_stats`) — and reads the percentiles off
these order statistics by the recipe of :func:`railval.core.definitions.percentile_recipe`
(the operations of :func:`railval.core.definitions.percentiles_from_order`). The same call
finds the sliding-mean window ends of every grid (a walk along the distance axis that
makes the comparisons of ``numpy.searchsorted``) and forms the sliding means of every
reading, and reads their 0.15 % and 99.85 % values (all the sliding-mean maxima use) off
the few order statistics at the two ends of each row, selected in one pass without sorting
the row (:func:`railval.core.en_kernels._row_extremes`; the numbers a sort puts there).
What is left to Python per section is reading the values out (a few numpy calls and one
dict entry per value); a section whose chosen sliding means are not all finite, or whose
range does not fit the grid, takes the step-by-step numpy path (:func:`_sliding_values`).

The operations on the samples are those of the former per-step numpy code, in the same order
(IEEE division and addition for Y/Q and ΣY, the same order statistics, numpy's rms), so the
values are the same numbers (docs/validation.md, Throughput).

The compiled step itself (:func:`_section_kernel`) and the compiled functions it calls live
in :mod:`railval.core.en_kernels` (one file: numba's on-disk cache keys a kernel to its own
file).

References
----------
Polach & Böttcher 2014, §5 and Table 2. EN 14363:2005, on-track tests: filtering, test
sections, percentile values from the cumulative frequency distribution.
Floyd, R.W. & Rivest, R.L. (1975) Algorithm 489: SELECT, Comm. ACM 18(3) — selection of a few
order statistics without sorting.
"""

from __future__ import annotations

import functools
import threading

import numpy as np

from railval.core.buffers import BufferPool
from railval.core.definitions import (
    CHOSEN,
    READINGS,
    SLIDING_VARIANTS,
    Reading,
    percentile_ranks,
    percentile_recipe,
    window_centres,
    window_count,
)
from railval.core.en_kernels import (  # noqa: F401
    _derive,
    _sample_window_means,
    _section_kernel,
)
from railval.core.en_statistics import (
    P_HIGH,
    P_LOW,
    PERCENTILES,
    QUANTILE_METHOD,
    STEP_M,
    WINDOW_M,
    _check_sliding_range,
    _interpolant_means,
    _means_from_integrals,
    _percentiles_of,
    _row_percentiles,
    _window_ends,
    maxabs,
)
from railval.core.errors import InvalidSignal
from railval.core.filters import design, settling_check
from railval.core.quantities import QUANTITIES, WHEELSET_POSITIONS
from railval.core.supplementary import BOGIE_KINDS, SUPPLEMENTARY
from railval.core.types import WHEEL_POSITIONS, SectionInfo, SignalSet

#: the reading that differs from the chosen one only in the percentile method
_LINEAR = Reading("linear", CHOSEN.grid, CHOSEN.window)
_NO_ROWS = np.empty((0, 0))
_NO_INTS = np.empty(0, np.int64)
_NO_FLOATS = np.empty(0)
#: the evaluated samples among (first, first evaluated, last evaluated, last) sample
_END_MASK = np.array([False, True, True, False])
#: the percentiles of the sliding means and of the band-pass rows the values read (maxabs of
#: the 0.15 % and 99.85 % values, :func:`_sliding_values_compiled`, :func:`_bandpass_values`;
#: their medians are not values of the chain)
_END_PERCENTILES = (P_LOW, P_HIGH)
#: the sliding-percentile ranks, their numbers and recipe (cols, mode, g, 1 − g) of no grid
#: (shapes of one grid's; read-only as those of :func:`_sliding_recipe`: one compiled type)
_NO_SLIDING_RECIPE = (np.zeros((0, 1), np.int64), np.zeros(0, np.int64),
                      (np.zeros((0, 1, 2, 2), np.int64), np.zeros((0, 1, 2), np.int64),
                       np.zeros((0, 1, 2)), np.zeros((0, 1, 2))))
for _a in (*_NO_SLIDING_RECIPE[:2], *_NO_SLIDING_RECIPE[2]):
    _a.flags.writeable = False
#: every reading by its (percentile, grid, window)
_READING = {(r.percentile, r.grid, r.window): r for r in READINGS}
_READING_ID = {r: r.id for r in READINGS}


def _evaluated_cut(d: np.ndarray, sec: SectionInfo) -> tuple[slice, int]:
    """Step 3 of the chain: the samples with ``eval_start_m ≤ distance_m ≤ eval_end_m`` (on
    the strictly increasing distance axis a contiguous run) as a slice, and their number
    (≥ 2)."""
    lo = int(np.searchsorted(d, sec.eval_start_m, side="left"))
    hi = int(np.searchsorted(d, sec.eval_end_m, side="right"))
    n_eval = max(hi - lo, 0)
    if n_eval < 2:
        raise InvalidSignal(
            f"section {sec.id}: evaluated range {sec.eval_start_m}–{sec.eval_end_m} m holds "
            f"{n_eval} samples, needs at least 2")
    return slice(lo, hi), n_eval


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


_SCRATCH = threading.local()


def _scratch(n: int) -> np.ndarray:
    """``n`` float64 of this thread's scratch (grown as needed; its content is the caller's
    until its next call in this thread: first-touched memory costs more than reused)."""
    buf = getattr(_SCRATCH, "buf", None)
    if buf is None or buf.size < n:
        buf = _SCRATCH.buf = np.empty(max(n, 1 << 17))
    return buf[:n]


@functools.lru_cache(maxsize=256)
def _sliding_recipe(n_cs: tuple[int, ...], methods: tuple[str, ...]) -> tuple:
    """The order statistics the sliding-mean percentiles of grids of ``n_cs`` windows read
    and how (:func:`railval.core.definitions.percentile_recipe` of each grid, stacked for
    the compiled step): ``(ranks, n_ranks, (cols, mode, g, 1 − g))``, ``ranks[q,
    :n_ranks[q]]`` those of grid q. Formed once per numbers of windows (the arrays must not
    be written to)."""
    recs = [percentile_recipe(c, _END_PERCENTILES, methods) for c in n_cs]
    n_ranks = np.array([r[0].size for r in recs], dtype=np.int64)
    ranks = np.zeros((len(recs), int(n_ranks.max())), np.int64)
    for q, r in enumerate(recs):
        ranks[q, :r[0].size] = r[0]
    recipe = tuple(np.stack([r[i] for r in recs]) for i in range(1, 5))
    for a in (ranks, n_ranks, *recipe):
        a.flags.writeable = False
    return ranks, n_ranks, recipe


@functools.lru_cache(maxsize=64)
def _channel_layout(lp_names: tuple[str, ...]) -> tuple:
    """The rows of the low-pass channels ``lp_names`` the compiled step reads:
    ``(index, wheels_yq, wsets, families, sel, yq, sy)`` — the row of each channel, the
    wheels with Y and Q, the wheelsets with both Y, the force families in value order, the
    Y then Q rows selected, the (Y, Q) rows of each Y/Q and the (Y_L, Y_R) rows of each ΣY.
    Formed once per set of names (the arrays must not be written to)."""
    index = {c: r for r, c in enumerate(lp_names)}
    wy = [p for p in WHEEL_POSITIONS if f"Y_{p}" in index]
    wq = [p for p in WHEEL_POSITIONS if f"Q_{p}" in index]
    wheels_yq = [p for p in wy if p in wq]
    wsets = [ws for ws in WHEELSET_POSITIONS
             if f"Y_w{ws[2:]}L" in index and f"Y_w{ws[2:]}R" in index]
    families = (("Y", wy), ("Q", wq), ("YQ", wheels_yq), ("SumY", wsets))
    sel = np.array([index[f"Y_{p}"] for p in wy] + [index[f"Q_{p}"] for p in wq],
                   dtype=np.int64)
    yq = np.array([[index[f"Y_{p}"], index[f"Q_{p}"]] for p in wheels_yq],
                  dtype=np.int64).reshape(-1, 2)
    sy = np.array([[index[f"Y_w{w[2:]}L"], index[f"Y_w{w[2:]}R"]] for w in wsets],
                  dtype=np.int64).reshape(-1, 2)
    for a in (sel, yq, sy):
        a.flags.writeable = False
    return index, wheels_yq, wsets, families, sel, yq, sy


class SectionState:
    """One section's values while they are formed: the evaluated cut, the rows the compiled
    call reads and writes, the values, their provenance, warnings, values under the other
    readings and supplementary values. ``error``: the section's InvalidSignal, raised when
    its values are asked for (sections are reported in order)."""

    def __init__(self, ss: SignalSet, sec: SectionInfo, order: int, with_alternatives: bool,
                 clock, plan, lp: np.ndarray | None, bp: np.ndarray | None):
        self.ss, self.sec, self.order, self.clock, self.plan = ss, sec, order, clock, plan
        self.values: dict[tuple[str, str], float] = {}
        self.prov: dict[tuple[str, str], tuple[str, ...]] = {}
        self.warnings: list[str] = []
        self.alts: dict[str, dict[tuple[str, str], float]] = {}
        self.supp: dict[tuple[str, str], float] = {}
        self.with_alternatives = with_alternatives
        self.methods = ((QUANTILE_METHOD, _LINEAR.percentile) if with_alternatives
                        else (QUANTILE_METHOD,))
        self.error: InvalidSignal | None = None
        self.zero_q = -1
        self.d = np.asarray(ss.distance_m, dtype=np.float64)
        self.fs = float(ss.fs)
        try:
            self.cut, self.n_eval = _evaluated_cut(self.d, sec)
        except InvalidSignal as exc:
            self.error = exc
            return
        self.cut_text = (f"cut to evaluated range {sec.eval_start_m:g}–{sec.eval_end_m:g} m "
                         f"by distance ({self.n_eval} samples)")
        self.pct_text = (f"percentiles: np.quantile method='{QUANTILE_METHOD}' (EN 14363 "
                         "cumulative distribution)")
        self._rows(lp, bp)

    def _rows(self, lp: np.ndarray | None, bp: np.ndarray | None) -> None:
        """The inputs and outputs of :func:`_section_kernel` (the row indices come from
        :func:`_channel_layout`, formed once per set of channel names)."""
        plan, cut = self.plan, self.cut
        self.lp = lp if lp is not None and lp.shape[0] else None
        self.bp = bp if bp is not None and bp.shape[0] else None
        lay = _channel_layout(tuple(plan.lp_names) if self.lp is not None else ())
        self.index, self.wheels_yq, self.wsets, self.families, self.sel, self.yq, self.sy = lay
        n = self.d.size
        self.wide = slice(max(cut.start - 1, 0), min(cut.stop + 1, n))
        n_der = self.yq.shape[0] + self.sy.shape[0]
        self.derived = _NO_ROWS  # (with at and sampled: allocate_rows)
        self.row_shapes = [(n_der, self.wide.stop - self.wide.start)]
        rec = percentile_recipe(self.n_eval, PERCENTILES, self.methods)
        self.ranks, self.recipe = rec[0], rec[1:]
        k = self.ranks.size
        m = len(self.methods)
        self.out_lp = np.empty((self.sel.size + n_der, k))
        self.bp_recipe = percentile_recipe(self.n_eval, _END_PERCENTILES, self.methods)
        n_bp = 0 if self.bp is None else self.bp.shape[0]
        self.out_bp = np.empty((n_bp, self.bp_recipe[0].size))
        self.out_rms = np.empty(n_bp)
        self.pct_lp = np.empty((m, self.out_lp.shape[0], 3))
        self.pct_bp = np.empty((m, n_bp, len(_END_PERCENTILES)))
        self._window_ends(n_der)

    def _window_ends(self, n_der: int) -> None:
        """What the compiled step needs for the sliding means: the grid origins (the chosen
        grid's and, with the alternatives, the grid from the first evaluated sample), their
        numbers of windows, room for the window ends (filled by the compiled step,
        :func:`railval.core.en_kernels._window_bounds`), the integrals, the sample-window
        means and the sliding percentiles with their recipes per number of windows. A range
        the grid does not fit leaves ``n_cs`` empty (the error is raised in section order by
        :func:`_sliding_values`)."""
        sec = self.sec
        self.origins, self.n_cs = _NO_FLOATS, _NO_INTS
        self.j = self.win_lo = self.win_hi = _NO_INTS
        self.u = _NO_FLOATS
        sizes: list[int] = []
        m = len(self.methods)
        n_var = 0
        if n_der:
            origins = [sec.eval_start_m] + (
                [float(self.d[self.cut.start])] if self.with_alternatives else [])
            try:
                d_wide = self.d[self.wide]
                _check_sliding_range(d_wide, sec.eval_start_m, sec.eval_end_m, WINDOW_M, STEP_M)
                n_cs = [window_count(sec.eval_start_m, sec.eval_end_m, o, WINDOW_M, STEP_M)
                        for o in origins]
            except InvalidSignal:
                n_cs = []
            if n_cs:
                self.origins = np.array(origins, dtype=np.float64)
                self.n_cs = np.array(n_cs, dtype=np.int64)
                total = sum(n_cs)
                self.j = np.empty(2 * total, np.int64)
                self.u = np.empty(2 * total)
                if self.with_alternatives:
                    sizes = [c for c in n_cs for _ in range(2)]
                    self.win_lo = np.empty(2 * total, np.int64)
                    self.win_hi = np.empty(2 * total, np.int64)
                self.s_ranks, self.s_n_ranks, self.s_recipe = _sliding_recipe(
                    tuple(n_cs), self.methods)
                n_var = len(n_cs) * (3 if self.with_alternatives else 1)
        if not n_var:
            self.s_ranks, self.s_n_ranks, self.s_recipe = _NO_SLIDING_RECIPE
        self.s_pct = np.empty((n_var, m, n_der, len(_END_PERCENTILES)))
        self.s_bad = np.empty((n_var, n_der), dtype=np.bool_)
        self.at = _NO_ROWS
        self.sampled = (sizes, _NO_ROWS)
        self.row_shapes += [(n_der, self.j.size), (n_der, self.win_lo.size)]

    @property
    def grids(self) -> list[np.ndarray] | None:
        """The window centres of each grid (None: the range does not fit the grid)."""
        if not self.n_cs.size:
            return None
        return [window_centres(self.sec.eval_start_m, self.sec.eval_end_m, float(o), WINDOW_M,
                               STEP_M) for o in self.origins]

    def run(self) -> None:
        """The compiled step (releases the GIL; sections run on the cores in parallel): the
        sliding means of every reading formed into this thread's scratch rows and their
        percentiles read off the order statistics selected from them."""
        if self.error is not None:
            return
        n_var, rows = self.s_bad.shape
        kmax = int(self.n_cs.max()) if self.n_cs.size else 0
        means = _scratch(n_var * rows * kmax).reshape(n_var * rows, kmax)
        slot = np.empty(n_var, np.int64)
        ret = _section_kernel(
            _NO_ROWS if self.lp is None else self.lp, self.sel, self.yq, self.sy,
            _NO_ROWS if self.bp is None else self.bp, self.cut.start, self.cut.stop,
            self.wide.start, self.ranks, self.derived, self.out_lp, self.out_bp,
            self.out_rms, self.d, self.j, self.u, self.at, self.win_lo,
            self.win_hi, self.sampled[1], self.origins, self.n_cs, WINDOW_M, STEP_M,
            self.recipe, self.bp_recipe, self.pct_lp, self.pct_bp, means, self.s_bad, slot,
            self.s_ranks, self.s_n_ranks, self.s_recipe, self.s_pct)
        self.zero_q = max(ret, -1)

    def release(self) -> None:
        """Drop the rows once the values are formed (a batch keeps only the values)."""
        self.lp = self.bp = None
        self.derived = self.at = _NO_ROWS
        self.sampled = ([], _NO_ROWS)

    def percentiles(self, stats: np.ndarray) -> list[np.ndarray]:
        """(0.15 %, 50 %, 99.85 %) values of each row under each method from the selected
        order statistics (columns in the order of ``self.ranks``)."""
        return _percentiles_of(stats, [int(r) for r in self.ranks], self.n_eval, self.methods)

    def alternative(self, reading: Reading, key: tuple[str, str], value: float) -> None:
        """Keep ``value`` under ``reading`` where it differs from the chosen value (NaN:
        undefined under the reading)."""
        if self.with_alternatives and value != self.values[key]:  # True for NaN as well
            rid = _READING_ID.get(reading) or reading.id
            self.alts.setdefault(rid, {})[key] = float(value)

    def alternatives(self, rid: str, keys, values: list[float]) -> None:
        """:meth:`alternative` of every key of ``keys`` with its value (Python floats) under
        the reading of id ``rid``, in that order."""
        if not self.with_alternatives:
            return
        chosen = self.values
        into = self.alts.get(rid)
        for key, value in zip(keys, values, strict=True):
            if value != chosen[key]:  # True for NaN as well
                if into is None:
                    into = self.alts[rid] = {}
                into[key] = value

    def settle(self, kind: str) -> str:
        """Settling warnings of filter ``kind``; returns the filter's provenance label.
        The check reads only the first and last sample times and those of the first and
        last evaluated samples, so it is given these four (the same differences)."""
        t = np.asarray(self.ss.time_s)
        ends = t[[0, self.cut.start, self.cut.stop - 1, t.shape[0] - 1]]
        self.warnings += [w.message for w in settling_check(
            ends, _END_MASK, self.fs, kind, self.order, self.sec.id)]
        return design(self.fs, kind, self.order).label + ", whole section"

    def result(self) -> tuple:
        """``(values, provenance, warnings, alternatives, supplementary)`` in registry order."""
        order_keys, supp_keys = _registry_keys()
        values, supp = self.values, self.supp
        return ({k: values[k] for k in order_keys if k in values}, self.prov,
                self.warnings, self.alts, {k: supp[k] for k in supp_keys if k in supp})


@functools.lru_cache(maxsize=1)
def _registry_keys() -> tuple[list, list]:
    """Every (quantity, position) of the registry and of the supplementary values, in
    registry order."""
    return ([(q, p) for q, quantity in QUANTITIES.items() for p in quantity.positions()],
            [(q, p) for q, sq in SUPPLEMENTARY.items() for p in sq.positions()])


#: the derived rows, integrals and sample-window means of the sections of a chunk (one
#: buffer per chunk, reused once the chunk's values are formed: fresh memory costs a page
#: fault and a zero fill per page, :mod:`railval.core.buffers`)
_ROWS_POOL = BufferPool(keep=4, max_bytes=128 << 20, min_bytes=1 << 20,
                        max_total_bytes=256 << 20)


def allocate_rows(states: list[SectionState]) -> None:
    """The derived rows, integrals and sample-window means (``row_shapes``) of every
    section of ``states`` as views of one pooled buffer (the buffer is free again once
    every section is released, :meth:`SectionState.release`)."""
    live = [st for st in states if st.error is None]
    total = sum(a * b for st in live for a, b in st.row_shapes)
    block = _ROWS_POOL.take((total,))
    pos = 0
    for st in live:
        views = []
        for a, b in st.row_shapes:
            views.append(block[pos:pos + a * b].reshape(a, b))
            pos += a * b
        st.derived, st.at = views[0], views[1]
        st.sampled = (st.sampled[0], views[2])


def run_sections(states: list[SectionState]) -> None:
    """The compiled step of every section, the sections shared among the cores (the first
    one in the calling thread first: a first call compiles or loads the kernel once); the
    rows of the chunk allocated first (:func:`allocate_rows`)."""
    from railval.core.workers import split_rows

    if not states:
        return
    allocate_rows(states)
    states[0].run()

    def part(a: int, b: int) -> None:
        for st in states[1 + a:1 + b]:
            st.run()

    split_rows(part, len(states) - 1)


def section_values(st: SectionState) -> None:
    """Steps 2–4 from the compiled step's rows and order statistics (in the channel order of
    ``st.plan``); raises the section's InvalidSignal."""
    if st.error is not None:
        raise st.error
    if st.zero_q >= 0:
        raise InvalidSignal(
            f"section {st.sec.id}: Q_{st.wheels_yq[st.zero_q]} is exactly 0 kN inside the "
            f"evaluated range; Y/Q is undefined")
    if st.lp is not None:
        _lowpass_values(st)
    if st.bp is not None:
        _bandpass_values(st)
    st.clock.lap("statistics")


def _lowpass_values(st: SectionState) -> None:
    """The force quantities (Y, Q, Y/Q, ΣY: percentiles, then the sliding-mean maxima)."""
    lp_label = st.settle("lowpass")
    if st.out_lp.shape[0]:
        _force_percentile_values(st, st.families, st.pct_lp[0], st.pct_lp[-1], lp_label)
    if st.derived.shape[0]:
        keys = ([("YQ_max", p) for p in st.wheels_yq] + [("SumY_max", w) for w in st.wsets])
        if st.n_cs.size and not st.s_bad[0].any():
            _sliding_values_compiled(st, keys, lp_label)
        else:
            _sliding_values(st, st.derived, st.d[st.wide], keys, lp_label)


#: the values a force family's percentiles give: (quantity, provenance of the statistic)
_FORCE_PERCENTILE_QUANTITIES = {
    "Y": (("Y_qst", "50 % value (median, with sign)"),
          ("Y_max", "max(|0.15 % value|, |99.85 % value|)")),
    "Q": (("Q_qst", "50 % value (median, with sign)"), ("Q_max", "99.85 % value")),
    "YQ": (("YQ_qst", "50 % value (median, with sign)"),),
    "SumY": (("SumY_qst", "50 % value (median, with sign)"),),
}


@functools.lru_cache(maxsize=64)
def _force_layout(families: tuple) -> tuple:
    """For the force rows of ``families``: ``(keys, rows, processing, texts, derive)`` —
    every (quantity, position) in value order, the row and processing of its statistic,
    the provenance text of the statistic and of the derived signal (None: none)."""
    keys, rows, procs, texts, derive = [], [], [], [], []
    r = 0
    for fam, positions in families:
        for p in positions:
            for qid, text in _FORCE_PERCENTILE_QUANTITIES[fam]:
                keys.append((qid, p))
                rows.append(r)
                procs.append(QUANTITIES[qid].processing)
                texts.append(text)
                derive.append(_DERIVE_TEXT.get(fam))
            r += 1
    return keys, rows, procs, texts, derive


def _force_percentile_values(st: SectionState, families, pct: np.ndarray,
                             pct_lin: np.ndarray, lp_label: str) -> None:
    """The percentile values of the force rows (in ``families`` order) under the chosen
    reading (``pct``) and the linear one (``pct_lin``): each statistic formed for all rows
    at once (:func:`_statistic` on columns), then read out as floats."""
    keys, rows, procs, texts, derive = _force_layout(
        tuple((fam, tuple(positions)) for fam, positions in families))
    chosen, linear = _by_processing(pct), _by_processing(pct_lin)
    values, prov = st.values, st.prov
    bases = {None: (lp_label, st.cut_text)}
    tail = st.pct_text
    for key, r, proc, text, der in zip(keys, rows, procs, texts, derive):
        base = bases.get(der)
        if base is None:
            base = bases[der] = (lp_label, der, st.cut_text)
        values[key] = chosen[proc][r]
        prov[key] = base + (text, tail)
    st.alternatives(_LINEAR.id, keys, [linear[proc][r] for r, proc in zip(rows, procs)])


def _by_processing(pct: np.ndarray) -> dict[str, list[float]]:
    """:func:`_statistic` of every row of (0.15 %, 50 %, 99.85 %) values, per processing."""
    return {proc: _statistic(proc, pct[:, 0], pct[:, 1], pct[:, 2]).tolist()
            for proc in ("median", "p99.85", "maxabs")}


def _slide_text(sec: SectionInfo, n_windows: int) -> str:
    return (f"sliding mean over {WINDOW_M:g} m every {STEP_M:g} m along distance "
            f"(windows inside {sec.eval_start_m:g}–{sec.eval_end_m:g} m, "
            f"{n_windows} values; exact integral of the linear interpolant)")


def _sliding_values_compiled(st: SectionState, keys: list[tuple[str, str]],
                             lp_label: str) -> None:
    """:func:`_sliding_values` from the percentiles the compiled step formed of the sliding
    means of every grid and window (:func:`railval.core.en_kernels._sliding_percentiles`;
    the chosen means all finite): the maximum magnitude of the 0.15 % and 99.85 % values
    (:func:`maxabs` on all of them at once), NaN under a reading whose means of that row are
    not all finite — the values and the order of :func:`_sliding_values`."""
    sec = st.sec
    pct, bad = st.s_pct, st.s_bad
    vals = maxabs(pct[..., 0], pct[..., 1])
    if bad.any():
        vals[np.broadcast_to(bad[:, None, :], vals.shape)] = np.nan
    chosen = vals[0, 0].tolist()
    slide_text = _slide_text(sec, int(st.n_cs[0]))
    values, prov = st.values, st.prov
    for key, v in zip(keys, chosen):
        values[key] = v
        prov[key] = (lp_label, _DERIVE_TEXT[key[0].split("_")[0]], slide_text,
                     "max(|0.15 % value|, |99.85 % value|)", st.pct_text)
    st.clock.lap("statistics")
    if st.with_alternatives:
        per = vals.tolist()
        for v, m, rid in _sliding_readings(st.methods):
            st.alternatives(rid, keys, per[v][m])
    st.clock.lap("alternatives")


@functools.lru_cache(maxsize=4)
def _sliding_readings(methods: tuple[str, ...]) -> list[tuple[int, int, str]]:
    """``(variant, method, reading id)`` of every reading other than the chosen one, in the
    order :func:`_sliding_alternatives` takes them (variants in ``SLIDING_VARIANTS`` order,
    then methods)."""
    return [(v, m, _READING_ID[_READING[(method, grid, window)]])
            for v, (grid, window) in enumerate(SLIDING_VARIANTS)
            for m, method in enumerate(methods)
            if _READING[(method, grid, window)] != CHOSEN]


def _sliding_values(st: SectionState, slide_rows: np.ndarray, d_wide: np.ndarray,
                    keys: list[tuple[str, str]], lp_label: str) -> None:
    """``YQ_max`` and ``SumY_max``: the maxima of the 2 m sliding means (step 6 of
    docs/validation.md), then, with the alternatives, their values under the other readings.
    The chosen grid (from the section start) and the grid from the first evaluated sample
    come from one cumulative integral. (The path of a section whose range does not fit the
    grid — it raises — or whose chosen means are not all finite; the others take
    :func:`_sliding_values_compiled`.)"""
    sec = st.sec
    _check_sliding_range(d_wide, sec.eval_start_m, sec.eval_end_m, WINDOW_M, STEP_M)
    origins = [sec.eval_start_m] + ([float(st.d[st.cut.start])] if st.with_alternatives else [])
    grids = st.grids
    interp = (_means_from_integrals(st.at, grids, WINDOW_M) if grids is not None
              else _interpolant_means(slide_rows, d_wide, sec.eval_start_m, sec.eval_end_m,
                                      WINDOW_M, STEP_M, origins))
    means = interp[0][1]
    # the order statistics of every percentile method in one selection (the linear
    # reading's values of the chosen means are used by the alternatives)
    chosen_pcts = _row_percentiles(means, st.methods)
    spct = chosen_pcts[0]
    slide_text = _slide_text(sec, means.shape[1])
    for r, key in enumerate(keys):
        st.values[key] = float(_statistic(QUANTITIES[key[0]].processing, *spct[r]))
        st.prov[key] = (lp_label, _DERIVE_TEXT[key[0].split("_")[0]], slide_text,
                        "max(|0.15 % value|, |99.85 % value|)", st.pct_text)
    st.clock.lap("statistics")
    if st.with_alternatives:
        _sliding_alternatives(slide_rows, d_wide, st.d[st.cut.start], sec, keys,
                              (means, chosen_pcts), interp[1][1], st.methods, st.alternative,
                              st.sampled if grids is not None else None)
    st.clock.lap("alternatives")


def _bandpass_values(st: SectionState) -> None:
    """The car body accelerations (rms, maximum) and, from the same filter call and
    statistics, the supplementary bogie-frame values."""
    bp_label = st.settle("bandpass")
    pct, pct_lin = st.pct_bp[0], st.pct_bp[-1]
    rmsv = st.out_rms.tolist()
    mx = maxabs(pct[:, 0], pct[:, 1]).tolist()
    mx_lin = maxabs(pct_lin[:, 0], pct_lin[:, 1]).tolist()
    values, prov, supp = st.values, st.prov, st.supp
    alt_keys, alt_vals = [], []
    for r, name in enumerate(st.plan.bp_names):
        kind, _, pos = name.rpartition("_")
        if kind in BOGIE_KINDS:  # supplementary: same filter call, same statistics
            supp[(f"{kind}_rms", pos)] = rmsv[r]
            supp[(f"{kind}_max", pos)] = mx[r]
            continue
        q = kind.split("_")[0]
        values[(f"{q}_rms", pos)] = rmsv[r]
        prov[(f"{q}_rms", pos)] = (bp_label, st.cut_text, "rms value")
        values[(f"{q}_max", pos)] = mx[r]
        prov[(f"{q}_max", pos)] = (bp_label, st.cut_text,
                                   "max(|0.15 % value|, |99.85 % value|)", st.pct_text)
        alt_keys.append((f"{q}_max", pos))
        alt_vals.append(mx_lin[r])
    st.alternatives(_LINEAR.id, alt_keys, alt_vals)


def _sliding_alternatives(slide_rows: np.ndarray, d_wide: np.ndarray, first_m: float,
                          sec: SectionInfo, keys: list[tuple[str, str]], chosen: tuple,
                          first_interp: np.ndarray, methods: tuple[str, ...],
                          alternative, sampled: tuple | None = None) -> None:
    """Values of the sliding-mean maxima under every other reading (grid alignment × window
    mean × percentile method, :mod:`railval.core.definitions`) from the same derived rows:
    the sample-window means of both grids and both window ends in one compiled pass over the
    rows (:func:`_sample_window_means`, the prefix sums of
    :func:`railval.core.definitions.sample_window_means`), the means of all readings with
    the same number of windows sorted in one call, and the percentiles of the chosen means
    (``chosen``: means and their percentiles under each method) not formed again.
    ``sampled``: the sample-window means (:func:`_sample_bounds` sizes, values) when the
    compiled step formed them."""
    others = [v for v in SLIDING_VARIANTS if v != CHOSEN.sliding]
    if sampled is None:
        sizes, lo, hi = _sample_bounds(d_wide, sec, first_m)
        sampled = (sizes, np.empty((slide_rows.shape[0], lo.size)))
        _sample_window_means(slide_rows, lo, hi, sampled[1])
    sizes, values = sampled
    means_of, pos, b = {}, 0, 0
    for variant in others:
        if variant[1] == "interpolant":
            means_of[variant] = first_interp
        else:
            means_of[variant] = values[:, pos:pos + sizes[b]]
            pos, b = pos + sizes[b], b + 1
    pcts_of = _percentiles_by_length(means_of, methods)
    pcts_of[CHOSEN.sliding] = chosen[1]
    means_of[CHOSEN.sliding] = chosen[0]
    for grid, window in SLIDING_VARIANTS:
        undefined = (~np.all(np.isfinite(means_of[(grid, window)]), axis=1)).tolist()
        for method, pct in zip(methods, pcts_of[(grid, window)], strict=True):
            reading = _READING[(method, grid, window)]
            if reading == CHOSEN:
                continue
            vals = maxabs(pct[:, 0], pct[:, 2]).tolist()
            for r, key in enumerate(keys):
                alternative(reading, key, float("nan") if undefined[r] else vals[r])


def _sample_bounds(d_wide: np.ndarray, sec: SectionInfo, first_m: float
                   ) -> tuple[list[int], np.ndarray, np.ndarray]:
    """The sample windows of the readings with a sample-window mean, in
    ``SLIDING_VARIANTS`` order: their counts and, concatenated, the first sample in and the
    first sample past each window on ``d_wide``
    (:func:`railval.core.definitions.sample_window_means`)."""
    origins = {"section_start": sec.eval_start_m, "first_sample": float(first_m)}
    half = WINDOW_M / 2.0
    sizes, los, his = [], [], []
    for grid, window in SLIDING_VARIANTS:
        if window == "interpolant":
            continue
        centres = window_centres(sec.eval_start_m, sec.eval_end_m, origins[grid], WINDOW_M,
                                 STEP_M)
        sizes.append(centres.size)
        los.append(np.searchsorted(d_wide, centres - half, side="left"))
        his.append(np.searchsorted(d_wide, centres + half,
                                   side="right" if window == "samples_closed" else "left"))
    return sizes, np.concatenate(los).astype(np.int64), np.concatenate(his).astype(np.int64)


def _percentiles_by_length(means_of: dict, methods: tuple[str, ...]) -> dict:
    """The (0.15 %, 50 %, 99.85 %) values under each method of every block of means in
    ``means_of`` (rows × windows); the blocks with the same number of windows are sorted in
    one call (a full sort gives the order statistics the selection gives)."""
    by_k: dict[int, list] = {}
    for variant, means in means_of.items():
        by_k.setdefault(means.shape[1], []).append(variant)
    out = {}
    for k, variants in by_k.items():
        srt = np.sort(np.vstack([means_of[v] for v in variants]), axis=-1)
        ranks = sorted({r for m in methods for r in percentile_ranks(k, PERCENTILES, m)})
        pcts = _percentiles_of(srt[:, ranks], ranks, k, methods)
        rows = next(iter(means_of.values())).shape[0]
        for i, v in enumerate(variants):
            out[v] = [p[i * rows:(i + 1) * rows] for p in pcts]
    return out

