"""Supplementary comparison quantities: bogie-frame accelerations and acceleration PSD bands.

Polach & Böttcher 2014 §3.1 compared 48 EN 14363 values per configuration — wheel–rail forces,
car body *and bogie frame* accelerations — and "10 quantities based on power spectral
densities of bogie and vehicle body accelerations" before settling on the 12 quantities of
the verdict (§5, Table 2). railval reports these as **supplementary** results next to the
verdict; they never change it (no limits exist for them) but show where a model departs
from the measurement beyond the 12 quantities, and the diagnosis uses the bogie-frame ones in
its residual pattern (:func:`supplementary_pattern`).

The registry :data:`SUPPLEMENTARY` (one list, read by the processing, the validation, the CLI,
the dashboard and the report):

* **bogie-frame accelerations** ``ay_bg_rms``, ``ay_bg_max``, ``az_bg_rms``, ``az_bg_max``
  (positions ``b1``, ``b2``, channels ``ay_bg_*``/``az_bg_*``, m/s²): the EN 14363 chain of
  the acceleration quantities — zero-phase Butterworth band-pass 0.4–10 Hz of the whole
  section (the same filter call as the car body channels), cut to the evaluated range, then
  the rms value and the larger magnitude of the 0.15 %/99.85 % values (inverted CDF).
  Source: EN 14363:2005, acceleration quantities of the normal measuring method (band-pass
  0.4–10 Hz; rms and 0.15 %/99.85 % values) applied to the bogie-frame sensors, as Polach &
  Böttcher 2014 §3.1 did for their bogie-frame comparisons. EN 14363's own bogie-frame
  criterion (sliding rms over 100 m after a band-pass f₀ ± 2 Hz around the instability
  frequency f₀) judges running stability, needs f₀, and is not used here.
* **PSD band rms** ``psd_<channel kind>_<lo>-<hi>Hz`` for the car body and bogie-frame
  accelerations (``ay_cb``, ``az_cb``, ``ay_bg``, ``az_bg``; positions ``b1``, ``b2``) in the
  bands 0.4–1, 1–2, 2–5 and 5–10 Hz (:data:`railval.core.diagnosis.DEFAULT_BANDS_HZ`: body
  modes, bogie/suspension range, upper EN band): the Welch PSD G(f) of the *unfiltered*
  evaluated samples (:func:`railval.core.psd.welch_psd`: Hann window, 50 % overlap, linear
  detrend, 10 s segments or the evaluated length if shorter) and the band rms
  ``sqrt(Σ_{lo ≤ f < hi} G(f)·Δf)`` in m/s² (Parseval: the rms of the signal's content in
  the band). Source: Welch 1967; Bendat & Piersol 2010 §5.2 (band-limited mean square from
  the one-sided PSD). 4 kinds × 4 bands = 16 quantities (the seed's 10 are not itemised in
  the paper; these bands are railval's choice, shared with the diagnosis).

Per quantity and (section, position) pair the statistics of the verdict are used: D_v =
(S_v − M_v)·sign(M_v) (Polach & Böttcher 2014 eq. 4), its mean and sample standard deviation
(ddof = 1); for lack of a Table 2 limit both are also given relative to the mean measured
magnitude, ``mean_rel = mean(D_v)/mean(|M_v|)``, ``std_rel = std(D_v)/mean(|M_v|)``, and the
mean log₂ ratio ``mean(log₂(S_v/M_v))`` (1 = the simulation doubles the value).

References
----------
Polach & Böttcher 2014 §3.1 (the 48 EN values and 10 PSD quantities), §5 eq. 4.
EN 14363:2005, acceleration quantities: band-pass 0.4–10 Hz, rms and 0.15 %/99.85 % values.
Welch, P.D. (1967) IEEE Trans. Audio Electroacoust. 15, 70–73.
Bendat, J.S. & Piersol, A.G. (2010) Random Data, 4th ed., Wiley, §5.2.
"""

from __future__ import annotations

import math
from collections import defaultdict
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np

from railval.core.diagnosis import DEFAULT_BANDS_HZ, Component, Pattern
from railval.core.errors import InvalidParameter
from railval.core.psd import welch_groups
from railval.core.types import BODY_POSITIONS

PSD_SEGMENT_S = 10.0
PSD_KINDS: tuple[str, ...] = ("ay_cb", "az_cb", "ay_bg", "az_bg")
BOGIE_KINDS: tuple[str, ...] = ("ay_bg", "az_bg")
STD_DDOF = 1

_EN_ACC = "EN 14363:2005 acceleration quantities (band-pass 0.4–10 Hz, rms, 0.15 %/99.85 % values); Polach & Böttcher 2014 §3.1"
_PSD_SRC = "Welch 1967; Bendat & Piersol 2010 §5.2; Polach & Böttcher 2014 §3.1"
_KIND_TEXT = {"ay_cb": "car body lateral", "az_cb": "car body vertical",
              "ay_bg": "bogie frame lateral", "az_bg": "bogie frame vertical"}


@dataclass(frozen=True)
class SupplementaryQuantity:
    """One supplementary quantity: ``kind`` is the channel kind (``ay_bg`` …, channel
    ``f"{kind}_{position}"``), ``statistic`` ``rms``/``maxabs``/``band_rms``, ``band_hz`` the
    frequency band of a PSD quantity."""

    id: str
    name: str
    unit: str
    kind: str
    statistic: str
    filtering: str
    processing: str
    source: str
    band_hz: tuple[float, float] | None = None

    def positions(self) -> tuple[str, ...]:
        return BODY_POSITIONS

    def channel(self, position: str) -> str:
        if position not in BODY_POSITIONS:
            raise InvalidParameter(f"position {position!r} is not one of {BODY_POSITIONS} "
                                   f"(supplementary quantity {self.id})")
        return f"{self.kind}_{position}"

    @property
    def group(self) -> str:
        return "bogie frame" if self.band_hz is None else "PSD band"

    def to_dict(self) -> dict:
        d = asdict(self)
        d["band_hz"] = list(self.band_hz) if self.band_hz else None
        d["group"] = self.group
        return d


def _build() -> dict[str, SupplementaryQuantity]:
    out: list[SupplementaryQuantity] = []
    for kind in BOGIE_KINDS:
        for stat, label, proc in (("rms", "rms", "rms value"),
                                  ("maxabs", "maximum", "max(|0.15 % value|, |99.85 % value|)")):
            out.append(SupplementaryQuantity(
                f"{kind}_{'rms' if stat == 'rms' else 'max'}",
                f"{_KIND_TEXT[kind]} acceleration, {label}", "m/s^2", kind, stat,
                "band-pass 0.4–10 Hz (whole section), evaluated range", proc, _EN_ACC))
    for kind in PSD_KINDS:
        for lo, hi in DEFAULT_BANDS_HZ:
            out.append(SupplementaryQuantity(
                f"psd_{kind}_{lo:g}-{hi:g}Hz",
                f"{_KIND_TEXT[kind]} acceleration, PSD band rms {lo:g}–{hi:g} Hz", "m/s^2", kind,
                "band_rms", f"unfiltered evaluated range; Welch PSD (Hann, 50 % overlap, linear "
                f"detrend, {PSD_SEGMENT_S:g} s segments)",
                f"band rms sqrt(Σ G(f)·Δf) over {lo:g} ≤ f < {hi:g} Hz", _PSD_SRC, (lo, hi)))
    return {q.id: q for q in out}


SUPPLEMENTARY: dict[str, SupplementaryQuantity] = _build()
SUPPLEMENTARY_IDS: tuple[str, ...] = tuple(SUPPLEMENTARY)


def psd_band_values(evaluated: Mapping[str, np.ndarray], fs: float) -> dict[tuple[str, str], float]:
    """PSD band rms values of one section: ``evaluated[channel]`` = the unfiltered samples of
    the evaluated range (m/s²) for channels ``{kind}_{position}``. Returns
    ``{(quantity id, position): band rms}``; channels shorter than 8 samples are skipped and
    bands without a frequency bin give no value.

    Parameters
    ----------
    evaluated : mapping of str to numpy.ndarray
        Channel name → unfiltered evaluated samples in m/s², shape (N,).
    fs : float
        Sampling rate in Hz.

    Returns
    -------
    dict of (str, str) to float
        ``{(quantity id, position): band rms in m/s²}``.
    """
    return psd_band_values_batch([evaluated], [fs])[0]


def psd_band_values_batch(evaluated: Sequence[Mapping[str, np.ndarray]], fs: Sequence[float]
                          ) -> list[dict[tuple[str, str], float]]:
    """:func:`psd_band_values` of many sections at once, every value the same float as one
    section at a time: per section, the channels of equal length form one block of rows
    (one :func:`railval.core.psd.welch_rows` call each, as the values a sign-off binds were
    computed); all blocks go through :func:`railval.core.psd.welch_groups` (the computation
    of :func:`~railval.core.psd.welch_blocks`: each block's
    :func:`~railval.core.psd.welch_rows` result bit for bit, without its per-call cost), the
    band powers of all blocks through :func:`_band_powers`, then ``math.sqrt``. A value that
    changes in its last bit makes a signed result read as changed (tests/test_upgrade.py;
    tests/test_supp_exact.py holds the equality with the former per-section code).

    Parameters
    ----------
    evaluated : sequence of mapping of str to numpy.ndarray
        Per section: channel name → unfiltered evaluated samples in m/s², shape (N,).
    fs : sequence of float
        Per section: sampling rate in Hz.

    Returns
    -------
    list of dict of (str, str) to float
        Per section ``{(quantity id, position): band rms in m/s²}``.
    """
    plan: list[list[tuple[list[str], int]]] = []
    blocks: list[list[np.ndarray]] = []
    rates: list[float] = []
    for ev, rate in zip(evaluated, fs, strict=True):
        by_length: dict[int, list[str]] = defaultdict(list)
        for ch, x in ev.items():
            if ch.rpartition("_")[0] in PSD_KINDS and np.asarray(x).size >= 8:
                by_length[np.asarray(x).size].append(ch)
        groups = []
        for chans in by_length.values():  # one block of rows per channel length
            groups.append((chans, len(blocks)))
            blocks.append([np.asarray(ev[c], dtype=np.float64) for c in chans])
            rates.append(float(rate))
        plan.append(groups)
    band_rms: list = [None] * len(blocks)
    for members, f, density in welch_groups(blocks, rates, PSD_SEGMENT_S):
        powers = _band_powers(f, density)
        for j, i in enumerate(members):
            band_rms[i] = [(label, [math.sqrt(pw) for pw in p[j].tolist()])
                           for label, p in powers]
    out = []
    for groups in plan:
        values: dict[tuple[str, str], float] = {}
        for chans, i in groups:
            keys = [ch.rpartition("_") for ch in chans]
            for label, rms in band_rms[i]:
                for (kind, _, pos), v in zip(keys, rms, strict=True):
                    values[(f"psd_{kind}_{label}", pos)] = v
        out.append(values)
    return out


def _band_powers(f: np.ndarray, density: np.ndarray) -> list[tuple[str, np.ndarray]]:
    """Band power ``Σ_{lo ≤ f < hi} G(f)·Δf`` of every row of every block of ``density``
    (n_blocks, n_rows, n_freq) for the bands of :data:`DEFAULT_BANDS_HZ` with a bin:
    ``(label "lo-hiHz", powers (n_blocks, n_rows))``. Each the number of the former
    per-block expression ``numpy.sum(g[:, inside], axis=1) · (f[1] − f[0])`` (``inside`` the
    bins ``(f >= lo) & (f < hi)`` of :func:`railval.core.diagnosis.band_powers`, a run of
    consecutive bins), computed for all blocks at once on the layout numpy gives that
    expression: the boolean index copies the bins bin-major (memory (n_bins, n_rows)), so
    numpy sums the bins of a row in order when a block has several rows, and pairwise (one
    contiguous run) when it has one; here the same sums on the same layouts
    (tests/test_supp_exact.py holds them equal to the former expression)."""
    df = f[1] - f[0]
    out = []
    for lo, hi in DEFAULT_BANDS_HZ:
        idx = np.flatnonzero((f >= lo) & (f < hi))
        if not idx.size:
            continue
        run = density[..., idx[0]:idx[-1] + 1]
        if density.shape[1] > 1:  # bins in order: the sum over the outer axis
            power = np.ascontiguousarray(np.moveaxis(run, -1, 0)).sum(axis=0) * df
        else:  # one contiguous run per row: numpy's pairwise sum
            power = run.sum(axis=-1) * df
        out.append((f"{lo:g}-{hi:g}Hz", power))
    return out


_UNSET = object()


def _pairs(measured: Mapping[str, Mapping[tuple[str, str], float]],
           simulated: Mapping[str, Mapping[tuple[str, str], float]],
           zones: Mapping[str, int] | None = None) -> list[dict]:
    recs = []
    nan = float("nan")
    for sid in sorted(set(measured) & set(simulated)):
        mv, sv = measured[sid], simulated[sid]
        zone: Any = _UNSET
        for key, m in mv.items():
            s = sv.get(key)
            if s is None:
                continue
            m, s = float(m), float(s)  # finite as numpy.isfinite says of the values
            if not (math.isfinite(m) and math.isfinite(s)):
                continue
            qid, pos = key
            if qid not in SUPPLEMENTARY:
                raise InvalidParameter(f"unknown supplementary quantity {qid!r} in section {sid}")
            d = s if m == 0.0 else (s - m) * math.copysign(1.0, m)
            if zone is _UNSET:  # looked up at the section's first pair, as before
                zone = None if zones is None else int(zones[sid])
            recs.append({"quantity": qid, "section": sid, "position": pos, "zone": zone,
                         "M": m, "S": s, "D": d,
                         "log2_ratio": (math.log2(s / m) if m > 0 and s > 0 else nan)})
    return recs


def _finite(x: float) -> float | None:
    return float(x) if np.isfinite(x) else None


def supplementary_results(measured: Mapping[str, Mapping[tuple[str, str], float]],
                          simulated: Mapping[str, Mapping[tuple[str, str], float]],
                          zones: Mapping[str, int] | None = None) -> dict:
    """D_v statistics of every supplementary quantity over its (section, position) pairs.

    ``measured[section][(quantity, position)]``/``simulated[…]``: supplementary values (e.g.
    ``SectionValues.supplementary``). Returns ``{"quantities": [...], "pairs": [...],
    "note": ...}``; per quantity ``quantity``, ``name``, ``group``, ``unit``, ``n``,
    ``n_positions``, ``n_sections``, ``mean``, ``std`` (ddof = 1), ``mean_abs_measured``,
    ``mean_rel``, ``std_rel``, ``log2_ratio_mean``, ``filtering``, ``processing``,
    ``source``. Quantities without pairs are omitted.

    Parameters
    ----------
    measured, simulated : mapping of str to mapping of (str, str) to float
        Section id → ``{(quantity, position): value}`` in the quantity's unit.
    zones : mapping of str to int or None
        Section id → EN 14363 zone, written into the pairs.

    Returns
    -------
    dict
        ``{"quantities": [...], "pairs": [...], "note": ...}`` as above.
    """
    recs = _pairs(measured, simulated, zones)
    by_q: dict[str, list[dict]] = defaultdict(list)
    for r in recs:
        by_q[r["quantity"]].append(r)
    rows = []
    for qid, q in SUPPLEMENTARY.items():
        rs = by_q.get(qid)
        if not rs:
            continue
        d = np.array([r["D"] for r in rs])
        m = np.array([r["M"] for r in rs])
        lr = np.array([r["log2_ratio"] for r in rs])
        n = d.size
        mean = float(d.mean())
        std = float(d.std(ddof=STD_DDOF)) if n >= 2 else float("nan")
        scale = float(np.mean(np.abs(m)))
        lr = lr[np.isfinite(lr)]
        rows.append({
            "quantity": qid, "name": q.name, "group": q.group, "unit": q.unit,
            "band_hz": list(q.band_hz) if q.band_hz else None,
            "n": n, "n_positions": len({r["position"] for r in rs}),
            "n_sections": len({r["section"] for r in rs}),
            "mean": _finite(mean), "std": _finite(std), "std_ddof": STD_DDOF,
            "mean_abs_measured": _finite(scale),
            "mean_rel": _finite(mean / scale) if scale > 0 else None,
            "std_rel": _finite(std / scale) if scale > 0 else None,
            "log2_ratio_mean": _finite(float(lr.mean())) if lr.size else None,
            "filtering": q.filtering, "processing": q.processing, "source": q.source})
    return {"quantities": rows, "pairs": recs,
            "note": "supplementary results: shown next to the verdict, they do not change it "
                    "(no validation limits exist for them)"}


def supplementary_pattern(pairs: Iterable[Mapping], kinds: Sequence[str] = BOGIE_KINDS) -> Pattern:
    """Diagnosis pattern of the bogie-frame supplementary quantities (rms, max and PSD bands).

    Component per (quantity, position): the mean over the sections of ``2·log₂(S_v/M_v)``,
    the log₂ *power* ratio — the convention of the car body PSD components of
    :mod:`railval.core.diagnosis` (a factor-2 power error counts 1). Label ``"supp ay_bg_rms
    b1"``, group ``"bogie ay"``/``"bogie az"`` (each direction weighs like one quantity).
    Car body PSD bands are not repeated here: the diagnosis already holds them.
    ``pairs``: the ``pairs`` records of :func:`supplementary_results`.

    Parameters
    ----------
    pairs : iterable of mapping
        The ``pairs`` records of :func:`supplementary_results`.
    kinds : sequence of str
        Channel kinds to include (bogie-frame lateral and vertical by default).

    Returns
    -------
    Pattern
        Components in log₂ power ratio (dimensionless).
    """
    acc: dict[tuple[str, str], list[float]] = defaultdict(list)
    for r in pairs:
        q = SUPPLEMENTARY.get(str(r["quantity"]))
        v = float(r["log2_ratio"])
        if q is None or q.kind not in kinds or not math.isfinite(v):
            continue
        acc[(q.id, str(r["position"]))].append(2.0 * v)
    keys = sorted(acc, key=lambda k: (SUPPLEMENTARY_IDS.index(k[0]), k[1]))
    return Pattern.of([Component.supplementary(q, p, SUPPLEMENTARY[q].kind) for q, p in keys],
                      np.array([float(np.mean(acc[k])) for k in keys]))
