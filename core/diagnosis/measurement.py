"""Measurement-side candidates (docs/diagnosis.md "Model or measurement?"): a channel whose
gain is wrong, judged by the same held-out rules as the model candidates — without any new
simulation, because a gain acts on the measured values only.

A channel that reads g times the true value: the EN statistics of a quantity formed from that
channel alone scale exactly by g (the filters are linear and the statistics — r.m.s., maximum
of the absolute value, median of the sliding mean — are positively homogeneous), so the
corrected measurement is M/g and D_v = (S − M/g)·sign(M) (Polach & Böttcher 2014 §5); the
channel's band powers scale by g², so the corrected log₂ ratio of the PSD component rises by
2·log₂ g. Only channels every quantity of which uses that channel alone are candidates (car
body and bogie accelerations; not the wheel forces, which also enter Y/Q and ΣY with a second
channel). The campaign's redundancy does the separating: a gain changes one position (one
car body end, one bogie), a model error changes both.

References: EN 14363:2016 §7.5 (quantities and their channels) and Table 2; Polach &
Böttcher 2014 §5 (D_v); Welch 1967 (band powers).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable, Mapping, Sequence
from typing import Any

import numpy as np

from railval.core.diagnosis.evidence import SectionEvidence, section_evidence
from railval.core.diagnosis.fit import CandidateFamily
from railval.core.diagnosis.patterns import DEFAULT_BANDS_HZ
from railval.core.diagnosis.reevaluation import packed_measurements, remapped_measurement
from railval.core.types import SectionInfo, SignalSet

#: search range of a channel gain (reads g × the true value), log scale; simulated nodes
GAIN_BOUNDS = (0.5, 2.0)
GAIN_NODES = (0.5, 0.63, 0.8, 0.9, 1.0, 1.12, 1.25, 1.4, 1.6, 2.0)


def gain_channels(pairs: Iterable[Mapping[str, Any]]) -> dict[str, list[tuple[str, str]]]:
    """Channel → the (quantity, position) components formed from it alone, for the channels
    whose every quantity uses them alone (module docstring)."""
    from railval.core.quantities import QUANTITIES

    uses: dict[str, list[tuple[str, str]]] = {}
    shared: set[str] = set()
    for q, p in sorted({(str(r["quantity"]), str(r["position"])) for r in pairs}):
        chans = QUANTITIES[q].channels(p) if q in QUANTITIES else ()
        if len(chans) == 1:
            uses.setdefault(chans[0], []).append((q, p))
        else:
            shared.update(chans)
    return {c: v for c, v in uses.items() if c not in shared}


def corrected_pairs(pairs: Iterable[Mapping[str, Any]], measured: Callable[[Mapping[str, Any]], float | None],
                    std_limits: Mapping[str, float]) -> list[dict[str, Any]]:
    """The validation pairs with the measurement corrected where ``measured(record)`` gives the
    corrected value M' (None: unchanged): D' = (S − M')·sign(M') (D' = S where M' = 0),
    ``D_norm`` = D'/std limit (Polach & Böttcher 2014 §5). Records need ``quantity``,
    ``position``, ``M``, ``S``."""
    out = []
    for r in pairs:
        r = dict(r)
        m = measured(r)
        if m is not None:
            s = float(r["S"])
            d = (s - m) * math.copysign(1.0, m) if m != 0 else s
            r["M"], r["D_norm"] = m, d / float(std_limits[str(r["quantity"])])
        out.append(r)
    return out


class PairRecords:
    """The validation pairs as arrays, for the evidence of many corrected measurements
    (:meth:`evidence`) without copying the records: per record its section and component
    (``section``, ``quantity``, ``zone``, ``position``), S, M, ``D_norm`` and the quantity's
    std limit."""

    def __init__(self, pairs: Iterable[Mapping[str, Any]], std_limits: Mapping[str, float]):
        self.pairs = list(pairs)
        p = self.pairs
        self.S = np.array([float(r["S"]) for r in p])
        self.M = np.array([float(r["M"]) for r in p])
        self.D = np.array([float(r["D_norm"]) for r in p])
        self.limit = np.array([float(std_limits.get(str(r["quantity"]), np.nan)) for r in p])
        self.where = [(str(r["section"]), f"{r['quantity']} zone {int(r['zone'])} {r['position']}") for r in p]
        #: (section, quantity, position) of every record, the keys of a re-evaluated measurement
        self.keys = [(str(r["section"]), str(r["quantity"]), str(r["position"])) for r in p]

    def evidence(self, like: SectionEvidence, measured: Sequence[float | None]) -> SectionEvidence:
        """:func:`section_evidence` (``value_key="D_norm"``, layout and band powers of ``like``)
        of :func:`corrected_pairs` with record k's measurement corrected to ``measured[k]``
        (None: unchanged): the same IEEE operations element-wise — D' = (S − M')·sign(M'),
        = S where M' = 0, divided by the std limit — and the sums added in record order
        (``np.add.at``), so the result equals the per-record computation exactly."""
        changed = np.array([m is not None for m in measured], bool)
        m = np.array([np.nan if x is None else float(x) for x in measured])[changed]
        return self.evidence_of(like, changed, m)

    def reevaluated(self, like: SectionEvidence, measured: Mapping[tuple[str, str, str], float]) -> SectionEvidence:
        """:meth:`evidence` with the measurement of each record whose ``(section, quantity,
        position)`` ``measured`` holds corrected to that value (a re-evaluation from the signals,
        :func:`remapped_measurement`): :func:`section_evidence` of :func:`corrected_pairs` with
        ``measured.get`` of the key, exactly."""
        return self.evidence(like, [measured.get(k) for k in self.keys])

    def evidence_of(self, like: SectionEvidence, changed: np.ndarray, m: np.ndarray) -> SectionEvidence:
        """:meth:`evidence` with the records ``changed`` (boolean, one per record) corrected to
        ``m`` (their corrected measurements M', in record order)."""
        from dataclasses import replace

        s = self.S[changed]
        v = self.D.copy()
        with np.errstate(invalid="ignore"):
            v[changed] = np.where(m != 0, (s - m) * np.copysign(1.0, m), s) / self.limit[changed]
        ij = self._cells(like)
        ok = np.isfinite(v) & (ij[:, 0] >= 0) & (ij[:, 1] >= 0)
        sums, counts = np.zeros_like(like.sums), np.zeros_like(like.counts)
        np.add.at(sums, (ij[ok, 0], ij[ok, 1]), v[ok])
        np.add.at(counts, (ij[ok, 0], ij[ok, 1]), 1.0)
        return replace(like, sums=sums, counts=counts)

    def _cells(self, like: SectionEvidence) -> np.ndarray:
        """(section row, component column) of every record in ``like``'s layout (−1: not in it)."""
        layout = (tuple(like.sections), tuple(like.labels[:like.n_pair]))
        if getattr(self, "_layout", None) != layout:
            row = {sid: k for k, sid in enumerate(like.sections)}
            col = {lab: j for j, lab in enumerate(like.labels[:like.n_pair])}
            self._ij = np.array([(row.get(sid, -1), col.get(lab, -1)) for sid, lab in self.where], int).reshape(-1, 2)
            self._layout = layout
        return self._ij


def gain_pairs(pairs: Iterable[Mapping[str, Any]], components: Sequence[tuple[str, str]], gain: float,
               std_limits: Mapping[str, float]) -> list[dict[str, Any]]:
    """The validation pairs with the measurement of ``components`` corrected for a channel
    reading ``gain`` × the truth: M' = M/g (:func:`corrected_pairs`)."""
    comp = set(components)
    return corrected_pairs(pairs, lambda r: float(r["M"]) / gain if (str(r["quantity"]), str(r["position"])) in comp
                           else None, std_limits)


def gain_family(base: SectionEvidence, pairs: Sequence[Mapping[str, Any]],
                sim_bands: Mapping[str, Mapping[str, np.ndarray]], meas_bands: Mapping[str, Mapping[str, np.ndarray]],
                sections: Sequence[tuple[str, int]], channel: str, components: Sequence[tuple[str, str]],
                std_limits: Mapping[str, float], *, bands: Sequence[tuple[float, float]] = DEFAULT_BANDS_HZ,
                values: Sequence[float] = GAIN_NODES) -> CandidateFamily:
    """The measurement candidate "``channel`` reads g × the true value" along g (log scale):
    its evidence at every node of ``values`` (module docstring)."""
    plain = section_evidence(pairs, sim_bands, meas_bands, sections, bands=bands, value_key="D_norm", like=base)
    recs = PairRecords(pairs, std_limits)
    comp = set(components)
    inside = [(str(r["quantity"]), str(r["position"])) in comp for r in recs.pairs]
    cols = [j for j, lab in enumerate(plain.labels[plain.n_pair:]) if lab.startswith(f"psd {channel} ")]
    evidence = []
    for g in values:  # M' = M/g (gain_pairs); the channel's band powers P/g² element by element
        ev = recs.evidence(plain, [float(r["M"]) / g if k else None for r, k in zip(recs.pairs, inside, strict=True)])
        ev.meas_power = plain.meas_power.copy()
        ev.meas_power[:, cols] = plain.meas_power[:, cols] / g ** 2
        evidence.append(ev)
    return CandidateFamily(
        "measurement", f"gain {channel}", "gain", list(values), evidence, GAIN_BOUNDS, log=True, reference=1.0,
        unit="×", title=f"channel {channel} reads",
        explanation=(f"the measurement, not the model: channel {channel} reads g × the true value (a sensor "
                     f"sensitivity or amplifier gain set wrong); it changes only "
                     f"{', '.join(sorted({q for q, _ in components}))} at {components[0][1]} and the channel's "
                     "band powers — the other end, bogie or wheel measures what the model should match"))


# ----------------------------------------------------------------------------- offset
#: offset nodes, as fractions of the channel's scale (:func:`offset_scale`)
OFFSET_NODES = (-2.0, -1.0, -0.5, -0.25, -0.1, 0.0, 0.1, 0.25, 0.5, 1.0, 2.0)


def offset_blind(channel: str) -> str | None:
    """Why a constant offset of ``channel`` cannot be seen, or None when it can: the EN
    band-pass 0.4–10 Hz of the car body accelerations is zero at 0 Hz, and the zero-phase
    filtering with steady-state initial conditions (:mod:`railval.core.filters`) maps a
    constant to zero exactly; the Welch band powers remove the segment mean. So an offset
    there changes no quantity and no band power — it cannot be diagnosed, and it does not
    touch the validation."""
    from railval.core.types import channel_kind

    kind = channel_kind(channel)
    if kind is not None and kind.en_filter == "bandpass":
        return ("a constant offset is removed by the EN band-pass 0.4–10 Hz of every quantity formed from this "
                "channel and by the mean removal of its band powers: it changes nothing the validation sees")
    return None


def offset_components(pairs: Iterable[Mapping[str, Any]], channel: str) -> list[tuple[str, str]]:
    """The (quantity, position) components of ``pairs`` formed (also) from ``channel``."""
    from railval.core.quantities import QUANTITIES

    return [(q, p) for q, p in sorted({(str(r["quantity"]), str(r["position"])) for r in pairs})
            if q in QUANTITIES and channel in QUANTITIES[q].channels(p)]


def offset_scale(signalsets: Mapping[str, SignalSet], channel: str) -> float:
    """The channel's scale for the offset search: the median over sections of the standard
    deviation of its samples (an offset of that size is as large as the signal's variation)."""
    sd = [float(np.std(ss.channels[channel])) for ss in signalsets.values() if channel in ss.channels]
    return float(np.median(sd)) if sd else 0.0


def reevaluated_measurement(signalsets: Mapping[str, SignalSet], sections: Sequence[SectionInfo], channel: str,
                            correct: Callable[[np.ndarray], np.ndarray], components: Sequence[tuple[str, str]]
                            ) -> dict[tuple[str, str, str], float]:
    """The measurement's EN values of ``components`` with ``channel`` corrected by ``correct``
    (the samples → the true samples), re-evaluated from the signals; only the channels the
    components use are evaluated. ``(section, quantity, position)`` → M'."""
    from dataclasses import replace

    from railval.core.en14363 import evaluate_present
    from railval.core.quantities import QUANTITIES

    need = {c for q, p in components for c in QUANTITIES[q].channels(p)}  # only what the components use
    fixed = {sid: replace(ss, channels={c: (correct(np.asarray(x, float)) if c == channel else x)
                                        for c, x in ss.channels.items() if c in need})
             for sid, ss in signalsets.items() if channel in ss.channels}
    vals = evaluate_present(fixed, sections)
    return {(sid, q, p): float(v[(q, p)]) for sid, v in vals.items() for q, p in components if (q, p) in v}


def offset_measured(signalsets: Mapping[str, SignalSet], sections: Sequence[SectionInfo], channel: str,
                    offset: float, components: Sequence[tuple[str, str]]) -> dict[tuple[str, str, str], float]:
    """The measurement's EN values of ``components`` with the offset removed from ``channel``
    (the channel reads the truth + ``offset``): the statistics re-evaluated from the signals
    (Y/Q, ΣY and the maxima are not shifted by the offset itself; :func:`reevaluated_measurement`)."""
    return reevaluated_measurement(signalsets, sections, channel, lambda x: x - offset, components)


def _reevaluated_evidence(base: SectionEvidence, pairs: Sequence[Mapping[str, Any]], sim_bands: Mapping,
                          meas_bands: Mapping, sections: Sequence[tuple[str, int]],
                          measured: Sequence[tuple[float, Mapping[tuple[str, str, str], float]]],
                          std_limits: Mapping[str, float], bands: Sequence[tuple[float, float]]) -> list[SectionEvidence]:
    return [section_evidence(corrected_pairs(pairs, lambda r, m=m: m.get(
        (str(r["section"]), str(r["quantity"]), str(r["position"]))), std_limits), sim_bands, meas_bands, sections,
        bands=bands, value_key="D_norm", like=base) for _, m in measured]


def offset_family(base: SectionEvidence, pairs: Sequence[Mapping[str, Any]],
                  sim_bands: Mapping[str, Mapping[str, np.ndarray]], meas_bands: Mapping[str, Mapping[str, np.ndarray]],
                  sections: Sequence[tuple[str, int]], channel: str, unit: str,
                  measured: Sequence[tuple[float, Mapping[tuple[str, str, str], float]]],
                  std_limits: Mapping[str, float], *, bands: Sequence[tuple[float, float]] = DEFAULT_BANDS_HZ,
                  group: Sequence[str] | None = None) -> CandidateFamily:
    """The measurement candidate "``channel`` reads the true value + c" along c (linear scale);
    with ``group`` (a wheel-force group named ``channel``, :func:`force_gain_groups`) every
    channel of the group reads the truth + the same c:
    ``measured`` — (c, :func:`offset_measured` at c) per node — corrects the pairs
    (:func:`corrected_pairs`); the band powers are unchanged (the Welch segments remove the
    mean)."""
    evidence = _reevaluated_evidence(base, pairs, sim_bands, meas_bands, sections, measured, std_limits, bands)
    values = [c for c, _ in measured]
    comps = sorted({(q, p) for _, m in measured for _, q, p in m})
    return CandidateFamily(
        "measurement", f"offset {channel}", "offset", values, evidence, (min(values), max(values)), log=False,
        reference=0.0, unit=unit, title=f"channel {channel} reads" if not group else f"channels {', '.join(group)} read",
        explanation=("the measurement, not the model: "
                     + (f"channel {channel} reads" if not group else f"the channels {', '.join(group)} read")
                     + " the true value + c (a zero set "
                     f"wrong, a bridge out of balance{'' if not group else ', one amplifier zeroed wrong'}); it changes {', '.join(sorted({q for q, _ in comps}))} "
                     "— the other wheel or wheelset measures what the model should match"))


def shared_gain_family(base: SectionEvidence, pairs: Sequence[Mapping[str, Any]], sim_bands: Mapping,
                       meas_bands: Mapping, sections: Sequence[tuple[str, int]], channel: str,
                       measured: Sequence[tuple[float, Mapping[tuple[str, str, str], float]]],
                       std_limits: Mapping[str, float], *, bands: Sequence[tuple[float, float]] = DEFAULT_BANDS_HZ
                       ) -> CandidateFamily:
    """The candidate "``channel`` reads g × the true value" for a channel that enters its
    quantities with a second one (a wheel force: Y/Q, ΣY), where M/g does not hold:
    ``measured`` — (g, :func:`reevaluated_measurement` with x/g) per node of
    :data:`GAIN_NODES`."""
    evidence = _reevaluated_evidence(base, pairs, sim_bands, meas_bands, sections, measured, std_limits, bands)
    comps = sorted({(q, p) for _, m in measured for _, q, p in m})
    return CandidateFamily(
        "measurement", f"gain {channel}", "gain", [g for g, _ in measured], evidence, GAIN_BOUNDS, log=True,
        reference=1.0, unit="×", title=f"channel {channel} reads",
        explanation=(f"the measurement, not the model: channel {channel} reads g × the true value (a sensor "
                     f"sensitivity or amplifier gain set wrong); it changes {', '.join(sorted({q for q, _ in comps}))} "
                     "(re-evaluated from the signals) — the other wheel or wheelset measures what the model should match"))


# ----------------------------------------------------------------------------- discrete candidates
#: relative excess of the pattern's D_v part at the two neighbour nodes of a discrete candidate
#: (:func:`discrete_family`): it makes the fit pick the candidate's own value, and changes no
#: reported share by more than ~1e-6
DISCRETE_TILT = 1e-6


def _tilted(ev: SectionEvidence, factor: float) -> SectionEvidence:
    from dataclasses import replace

    return replace(ev, sums=ev.sums * factor)


def discrete_family(name: str, parameter: str, value: float, evidence: SectionEvidence, *, half_width: float,
                    unit: str = "", title: str = "", explanation: str = "") -> CandidateFamily:
    """A measurement candidate without a residual-fitted value (a sign or position swap, a time
    shift fitted from the signals): the evidence is the corrected measurement's, the same at every
    node, so the share it explains on held-out sections is the share of their residual the
    correction removes — nothing is fitted to those sections (Hastie, Tibshirani & Friedman
    2009 §7.10, the held-out rule of the other candidates). The family holds three nodes
    ``value ∓ half_width`` and ``value``; the D_v part at the two outer nodes is (1 +
    :data:`DISCRETE_TILT`) × the corrected one, so that the fit along the family lands on
    ``value`` (not at a bound of the search range) on any subset of sections; the fitted
    value's interval is ``value ± half_width`` (for a time shift: the spread of the lags of the
    section's channels)."""
    h = float(half_width) if half_width > 0 else 1e-3 * max(1.0, abs(value))
    edge = _tilted(evidence, 1.0 + DISCRETE_TILT)
    return CandidateFamily("measurement", name, parameter, [value - h, value, value + h], [edge, evidence, edge],
                           (value - h, value + h), log=False, reference=None, unit=unit, title=title,
                           explanation=explanation)


def discrete_evidence(base: SectionEvidence, pairs: Sequence[Mapping[str, Any]], sim_bands: Mapping,
                      meas_bands: Mapping, sections: Sequence[tuple[str, int]],
                      measured: Mapping[tuple[str, str, str], float], std_limits: Mapping[str, float], *,
                      bands: Sequence[tuple[float, float]] = DEFAULT_BANDS_HZ) -> SectionEvidence:
    """The evidence of the measurement corrected to ``measured`` (:func:`corrected_pairs`)."""
    return _reevaluated_evidence(base, pairs, sim_bands, meas_bands, sections, [(0.0, measured)], std_limits,
                                 bands)[0]


# ----------------------------------------------------------------------------- sign
def sign_blind(channel: str, components: Sequence[tuple[str, str]]) -> str | None:
    """Why a reversed sign of ``channel`` cannot be seen, or None when it can. The EN statistics
    of the car body and bogie accelerations are the r.m.s. and the larger magnitude of the
    0.15 %/99.85 % values (Polach & Böttcher 2014 Table 2; :data:`railval.core.quantities.PROCESSINGS`)
    and band powers — all even in the signal; Y_max is a maximum of the magnitude too. Only
    the medians with sign (Y_qst, Q_qst, (Y/Q)_qst, ΣY_qst), the 99.85 % value Q_max and the
    quantities formed with a second channel ((Y/Q)_max, ΣY_max) keep the sign."""
    from railval.core.quantities import QUANTITIES

    if not components:
        return "not a channel of this campaign that a measured quantity is formed from"
    seen = [(q, p) for q, p in components
            if QUANTITIES[q].processing in ("median", "p99.85") or len(QUANTITIES[q].channels(p)) > 1]
    if not seen:
        qs = ", ".join(sorted({q for q, _ in components}))
        return (f"a reversed sign is invisible to the EN quantities formed from this channel ({qs}: r.m.s., "
                "maxima of the magnitude) and to its band powers: it changes nothing the validation sees")
    return None


def signed_measured(signalsets: Mapping[str, SignalSet], sections: Sequence[SectionInfo], channel: str,
                    components: Sequence[tuple[str, str]]) -> dict[tuple[str, str, str], float]:
    """The measurement's EN values of ``components`` with ``channel`` read with the opposite
    sign (the channel's polarity reversed: x → −x), re-evaluated from the signals."""
    return remapped_measurement(signalsets, sections, *signed_request(channel, components))


def signed_request(channel: str, components: Sequence[tuple[str, str]]) -> tuple[Callable, Sequence[tuple[str, str]]]:
    """The ``(remap, components)`` request of :func:`signed_measured` (for
    :func:`packed_measurements`)."""
    return (lambda _s, ch, _ss: {c: (-x if c == channel else x) for c, x in ch.items()}), components


# ----------------------------------------------------------------------------- position swap
def swap_pairs(a: str, b: str, channels: Iterable[str]) -> list[tuple[str, str]]:
    """The channel pairs ``swap A B`` exchanges: two channel names (``az_cb_b1 az_cb_b2``), or two
    positions (``w1L w1R``: every channel kind the campaign has at both — Y and Q of the two
    wheels; ``b1 b2``: the car body and bogie accelerometers of both ends). Empty when nothing
    matches."""
    from railval.core.types import split_channel

    chans = set(channels)
    if a in chans and b in chans:
        return [(a, b)] if split_channel(a)[0] == split_channel(b)[0] and a != b else []
    kinds = {split_channel(c)[0] for c in chans}
    return [(f"{k}_{a}", f"{k}_{b}") for k in sorted(kinds) if f"{k}_{a}" in chans and f"{k}_{b}" in chans and a != b]


def swapped_measured(signalsets: Mapping[str, SignalSet], sections: Sequence[SectionInfo],
                     pairs: Sequence[tuple[str, str]], components: Sequence[tuple[str, str]]
                     ) -> dict[tuple[str, str, str], float]:
    """The measurement's EN values of ``components`` with the channels of every pair exchanged
    (the sensors recorded each other's position), re-evaluated from the signals."""
    return remapped_measurement(signalsets, sections, *swapped_request(pairs, components))


def swapped_request(pairs: Sequence[tuple[str, str]], components: Sequence[tuple[str, str]]
                    ) -> tuple[Callable, Sequence[tuple[str, str]]]:
    """The ``(remap, components)`` request of :func:`swapped_measured` (for
    :func:`packed_measurements`): each channel of a pair reads its partner's recorded samples."""
    other = {**{x: y for x, y in pairs}, **{y: x for x, y in pairs}}

    def remap(_sid: str, ch: Mapping[str, np.ndarray], ss: SignalSet) -> dict[str, np.ndarray]:
        full = {c: np.asarray(ss.channels[other.get(c, c)], float) for c in ch}
        return full

    return remap, components


def swapped_bands(meas_bands: Mapping[str, Mapping[str, np.ndarray]], pairs: Sequence[tuple[str, str]]
                  ) -> dict[str, dict[str, np.ndarray]]:
    """The measured band powers with the channels of every pair exchanged."""
    other = {**{x: y for x, y in pairs}, **{y: x for x, y in pairs}}
    return {sid: {c: chans.get(other.get(c, c), p) for c, p in chans.items()} for sid, chans in meas_bands.items()}


# ----------------------------------------------------------------------------- time shift
#: largest lag searched (s), smallest normalised correlation peak a channel's lag counts with,
#: and the fewest channels a section's lag needs
MAX_LAG_S = 2.0
MIN_PEAK = 0.3
MIN_CHANNELS = 3


def estimate_lag(measured: np.ndarray, simulated: np.ndarray, fs: float, max_lag_s: float = MAX_LAG_S
                 ) -> tuple[float, float]:
    """The lag in s by which ``measured`` trails ``simulated`` (positive: recorded late) and the
    normalised correlation at the peak: the maximum of the cross-correlation of the two
    mean-free signals (``scipy.signal.correlate``/``correlation_lags``: z[k] = Σ_n x[n+k]·y[n],
    so x[n] = y[n − L] peaks at k = L) within ± ``max_lag_s``, divided by the number of
    overlapping samples (the unbiased estimate, Bendat & Piersol, Random Data, 4th ed. 2010,
    §8.4: the plain sum falls off linearly with |k| and pulls a broad peak towards 0), refined to a fraction of a sample
    by the vertex of the parabola through the peak and its two neighbours (J. O. Smith,
    Spectral Audio Signal Processing, 2011, "Quadratic Interpolation of Spectral Peaks")."""
    from scipy.signal import correlate, correlation_lags

    x = np.asarray(measured, float) - float(np.mean(measured))
    y = np.asarray(simulated, float) - float(np.mean(simulated))
    n = min(x.size, y.size)
    x, y = x[:n], y[:n]
    den = float(np.linalg.norm(x) * np.linalg.norm(y))
    if n < 3 or not den > 0:
        return 0.0, 0.0
    lags = correlation_lags(n, n, mode="full")
    z = correlate(x, y, mode="full", method="fft") * n / (n - np.abs(lags))  # unbiased: per overlapping sample
    keep = np.abs(lags) <= max_lag_s * fs
    z, lags = z[keep], lags[keep]
    i = int(np.argmax(z))
    frac = 0.0
    if 0 < i < z.size - 1:
        a, b, c = z[i - 1], z[i], z[i + 1]
        d = a - 2 * b + c
        frac = 0.5 * (a - c) / d if d < 0 else 0.0
    return float((lags[i] + frac) / fs), float(z[i] / den)


def on_distance(ss: SignalSet, grid: np.ndarray, channel: str) -> np.ndarray:
    """A channel's samples at the distances ``grid`` (linear interpolation along ``distance_m``)."""
    return np.interp(grid, np.asarray(ss.distance_m, float), np.asarray(ss.channels[channel], float))


def section_lag(measured: SignalSet, simulated: SignalSet, *, max_lag_s: float = MAX_LAG_S,
                min_peak: float = MIN_PEAK, min_channels: int = MIN_CHANNELS) -> dict[str, Any]:
    """The time shift of one section's measured signals against the simulation. Both records
    are taken onto one distance grid first (the measured run's speed differs from the
    simulated one, so the same stretch of track is passed at other times; the EN evaluation
    too takes its range on the distance axis), at the measurement's mean sample spacing over
    the common distance range; the lag of every channel both hold (:func:`estimate_lag` along
    distance) whose correlation peak reaches ``min_peak`` is turned into seconds with the
    measured run's mean speed. The section's lag is their median, ``spread`` the largest
    distance of a channel's lag from it. ``consistent`` when at least ``min_channels`` channels
    count and every one lies within max(1 sample, 25 % of the lag) of the median — one channel
    group recorded late is not a shift of the section. ``reason`` says why not."""
    def fail(why: str, lags: dict | None = None) -> dict[str, Any]:
        return {"lag": 0.0, "spread": 0.0, "lags": lags or {}, "consistent": False, "reason": why}

    dm, ds = np.asarray(measured.distance_m, float), np.asarray(simulated.distance_m, float)
    lo, hi = max(dm[0], ds[0]), min(dm[-1], ds[-1])
    if dm.size < 3 or not hi > lo or not dm[-1] > dm[0]:
        return fail("the measured and simulated records share no stretch of track")
    speed = float((dm[-1] - dm[0]) / (dm.size - 1) * measured.fs)  # m/s
    step = speed / measured.fs  # m per sample
    grid = np.arange(lo, hi, step)
    lags = {}
    for c in sorted(set(measured.channels) & set(simulated.channels)):
        lag_m, peak = estimate_lag(on_distance(measured, grid, c), on_distance(simulated, grid, c), 1.0 / step,
                                   max_lag_s * speed)
        if peak >= min_peak:
            lags[c] = lag_m / speed  # the content comes a distance farther on: recorded late
    if len(lags) < min_channels:
        return fail(f"only {len(lags)} channel(s) correlate with the simulation (peak ≥ {min_peak})", lags)
    med = float(np.median(list(lags.values())))
    spread = float(max(abs(v - med) for v in lags.values()))
    tol = max(1.0 / measured.fs, 0.25 * abs(med))
    ok = spread <= tol
    return {"lag": med, "spread": spread, "lags": lags, "consistent": ok,
            "reason": "" if ok else (f"the channels' lags disagree (median {med:+.3f} s, spread {spread:.3f} s "
                                     f"> {tol:.3f} s): not one shift of the section")}


def shifted(x: np.ndarray, lag_s: float, fs: float) -> np.ndarray:
    """The samples of a channel recorded ``lag_s`` late, re-aligned: x'(t) = x(t + lag), linear
    interpolation between samples, the end values held beyond the record."""
    x = np.asarray(x, float)
    t = np.arange(x.size) / fs
    return np.interp(t + lag_s, t, x)


def shifted_measured(signalsets: Mapping[str, SignalSet], sections: Sequence[SectionInfo], section: str,
                     lag_s: float, components: Sequence[tuple[str, str]]) -> dict[tuple[str, str, str], float]:
    """The measurement's EN values of ``components`` of ``section`` with all its channels
    re-aligned by ``lag_s`` (:func:`shifted`); the evaluated range stays on the distance axis."""
    one = {section: signalsets[section]} if section in signalsets else {}
    return remapped_measurement(one, sections, lambda _s, ch, ss: {c: shifted(x, lag_s, ss.fs) for c, x in ch.items()},
                                components)


# ----------------------------------------------------------------------------- force-channel gains
#: gain nodes of the force-channel groups (fewer than :data:`GAIN_NODES`: a group whose ΣY needs
#: re-evaluating from the signals costs one EN evaluation per node)
FORCE_GAIN_NODES = (0.5, 0.7, 0.85, 1.0, 1.15, 1.3, 1.5, 2.0)


def force_gain_groups(channels: Iterable[str]) -> dict[str, tuple[str, ...]]:
    """The wheel-force channel groups that may read g × the truth together (one amplifier, one
    calibration of an instrumented wheelset, one data-acquisition card), per kind Y and Q:
    every wheel (``Y_w1L``), every wheelset (``Y_w1``: both wheels), every side (``Y_L``: the
    wheels of that side) and every bogie (``Y_bogie1``: the wheels of wheelsets 1–2; with four
    wheelsets). A group of one channel of a wheelset with one wheel measured is the wheel's."""
    chans = set(channels)
    out: dict[str, tuple[str, ...]] = {}
    for k in ("Y", "Q"):
        wheels = sorted(c for c in chans if c.startswith(f"{k}_w") and c[-1] in "LR" and c[len(k) + 2:-1].isdigit())
        sets = {n: tuple(sorted(c for c in wheels if c[len(k) + 2:-1] == n))
                for n in sorted({c[len(k) + 2:-1] for c in wheels})}
        out.update({c: (c,) for c in wheels})
        out.update({f"{k}_w{n}": g for n, g in sets.items() if len(g) == 2})
        for side in "LR":
            g = tuple(c for c in wheels if c.endswith(side))
            if len(g) > 1:
                out[f"{k}_{side}"] = g
        if len(sets) == 4:
            for b, ns in (("1", ("1", "2")), ("2", ("3", "4"))):
                out[f"{k}_bogie{b}"] = tuple(c for n in ns for c in sets[n])
    return out


def gain_degree(quantity: str, position: str, group: Iterable[str]) -> int | None:
    """The power d with which a quantity's measured statistic scales when every channel of
    ``group`` reads g × the truth: M(g) = g^d · M(1). The EN statistics are positively
    homogeneous of degree 1 in the filtered signal (linear filters; median, percentile, r.m.s.,
    maximum of the magnitude), Y/Q is the sample-wise ratio (degree +1 in Y, −1 in Q) and ΣY
    the sum of the two wheels' Y (degree 1 when both read g, exact then;
    :func:`railval.core.en14363` ``evaluate``). None when only one of ΣY's two wheels is in the
    group (not a power law: re-evaluate from the signals)."""
    from railval.core.quantities import QUANTITIES

    g = set(group)
    q = QUANTITIES[quantity]
    chans = q.channels(position)
    if q.signal == "YQ":
        return int(chans[0] in g) - int(chans[1] in g)
    inside = sum(c in g for c in chans)
    if inside in (0, len(chans)):
        return 1 if inside else 0
    return None


def group_gain_reevaluations(signalsets: Mapping[str, SignalSet], sections: Sequence[SectionInfo],
                              groups: Mapping[str, Sequence[str]], components: Sequence[tuple[str, str]],
                              values: Sequence[float] = FORCE_GAIN_NODES
                              ) -> dict[str, Callable[[float, Sequence[tuple[str, str]]], dict]]:
    """The ``reevaluate`` of :func:`group_gain_families` for every group at once: the components
    of ``components`` without a power law for a group (:func:`gain_degree` None: ΣY with one
    of its wheels in the group) re-evaluated from the signals with the group's channels
    divided by each g of ``values``, all in one batched EN evaluation
    (:func:`packed_measurements`). A component's value depends only on its own channels, so
    it is evaluated once per (its channels in the group, g) — a wheel and the side holding it
    share ΣY of that wheelset — and those of other wheelsets at the same g share one signal
    set (ΣY of wheelsets 1–4 with their left wheels divided by g: one evaluation, not four);
    each group reads the value the per-group re-evaluation gives, exactly."""
    from railval.core.quantities import QUANTITIES

    units: dict[frozenset, set[tuple[str, str]]] = {}
    for group in groups.values():
        for q, p in components:
            if gain_degree(q, p, group) is None:
                units.setdefault(frozenset(set(QUANTITIES[q].channels(p)) & set(group)), set()).add((q, p))
    keys = [(u, g) for u in sorted(units, key=sorted) for g in values]
    reqs = [(lambda _s, ch, _ss, u=u, g=g: {c: (x / g if c in u else x) for c, x in ch.items()}, sorted(units[u]))
            for u, g in keys]
    found = dict(zip(keys, packed_measurements(signalsets, sections, reqs), strict=True))

    def reevaluate_for(group: Sequence[str]) -> Callable[[float, Sequence[tuple[str, str]]], dict]:
        def reevaluate(g: float, comps: Sequence[tuple[str, str]]) -> dict:
            out = {}
            for q, p in comps:
                vals = found[(frozenset(set(QUANTITIES[q].channels(p)) & set(group)), g)]
                out.update({k: v for k, v in vals.items() if k[1:] == (q, p)})
            return out
        return reevaluate

    return {name: reevaluate_for(group) for name, group in groups.items()}


def group_gain_families(base: SectionEvidence, pairs: Sequence[Mapping[str, Any]], sim_bands: Mapping,
                        meas_bands: Mapping, sections: Sequence[tuple[str, int]], groups: Mapping[str, Sequence[str]],
                        std_limits: Mapping[str, float],
                        reevaluations: Mapping[str, Callable[[float, Sequence[tuple[str, str]]],
                                                             Mapping[tuple[str, str, str], float]]],
                        *, bands: Sequence[tuple[float, float]] = DEFAULT_BANDS_HZ,
                        values: Sequence[float] = FORCE_GAIN_NODES) -> dict[str, CandidateFamily]:
    """The measurement candidates "the channels of group G read g × the true value" along g (log
    scale), one per group of ``groups`` (name → channels), the groups no measured quantity uses
    left out: the measured statistics corrected to M/g^d (:func:`gain_degree`), those without a
    power law from the group's ``reevaluations[name](g, components)`` (the signals re-evaluated
    with the group's channels divided by g, :func:`group_gain_reevaluations`). The records (:class:`PairRecords`), their components and the
    band powers and component layout of the evidence are formed once for all groups (they
    are the same at every node of every group); per group and node the corrected measurement
    M/g^d is one array division per degree d — g^d the same Python power, M/g^d the same IEEE
    division as per record — so the evidence equals the per-record computation exactly."""
    comps = sorted({(str(r["quantity"]), str(r["position"])) for r in pairs})
    recs = PairRecords(pairs, std_limits)
    comp_index = {c: j for j, c in enumerate(comps)}
    rec_comp = np.array([comp_index[k[1:]] for k in recs.keys], dtype=np.int64)
    plain: list[SectionEvidence] = []
    out: dict[str, CandidateFamily] = {}
    for name, group in groups.items():
        deg = {c: d for c in comps if (d := gain_degree(c[0], c[1], group)) != 0}
        if not deg:
            continue
        if not plain:  # the band powers and the component layout: the same at every node of every group
            plain.append(section_evidence([], sim_bands, meas_bands, sections, bands=bands, value_key="D_norm",
                                          like=base))
        other = [c for c, d in deg.items() if d is None]
        powers = {d: np.isin(rec_comp, [comp_index[c] for c, e in deg.items() if e == d])
                  for d in sorted({d for d in deg.values() if d is not None})}
        redone = np.flatnonzero(np.isin(rec_comp, [comp_index[c] for c in other]))
        evidence = []
        for gv in values:
            redo = reevaluations[name](gv, other) if other else {}
            changed = np.zeros(rec_comp.size, bool)
            m = np.zeros(rec_comp.size)
            for d, where in powers.items():  # M/g^d (the records' own division, Python g ** d)
                m[where] = recs.M[where] / gv ** d
                changed |= where
            for k in redone:  # ΣY re-evaluated; a record without a value stays as measured
                x = redo.get(recs.keys[k])
                if x is not None:
                    m[k], changed[k] = float(x), True
            evidence.append(recs.evidence_of(plain[0], changed, m[changed]))
        qs = ", ".join(sorted({q for q, _ in deg}))
        out[name] = CandidateFamily(
            "measurement", f"gain {name}", "gain", list(values), evidence, GAIN_BOUNDS, log=True, reference=1.0,
            unit="×", title=f"channel(s) {', '.join(group)} read",
            explanation=(f"the measurement, not the model: the force channel(s) {', '.join(group)} read g × the "
                         f"true value (a transducer calibration or amplifier gain of an instrumented wheelset set "
                         f"wrong); it changes {qs} — the other wheels measure what the model should match"))
    return out

