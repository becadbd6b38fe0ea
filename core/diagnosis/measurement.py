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
    evidence = []
    for g in values:
        mb = {sid: {ch: (np.asarray(p, float) / g ** 2 if ch == channel else p) for ch, p in chans.items()}
              for sid, chans in meas_bands.items()}
        evidence.append(section_evidence(gain_pairs(pairs, components, g, std_limits), sim_bands, mb, sections,
                                         bands=bands, value_key="D_norm", like=base))
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
                  std_limits: Mapping[str, float], *, bands: Sequence[tuple[float, float]] = DEFAULT_BANDS_HZ
                  ) -> CandidateFamily:
    """The measurement candidate "``channel`` reads the true value + c" along c (linear scale):
    ``measured`` — (c, :func:`offset_measured` at c) per node — corrects the pairs
    (:func:`corrected_pairs`); the band powers are unchanged (the Welch segments remove the
    mean)."""
    evidence = _reevaluated_evidence(base, pairs, sim_bands, meas_bands, sections, measured, std_limits, bands)
    values = [c for c, _ in measured]
    comps = sorted({(q, p) for _, m in measured for _, q, p in m})
    return CandidateFamily(
        "measurement", f"offset {channel}", "offset", values, evidence, (min(values), max(values)), log=False,
        reference=0.0, unit=unit, title=f"channel {channel} reads",
        explanation=(f"the measurement, not the model: channel {channel} reads the true value + c (a zero set "
                     f"wrong, a bridge out of balance); it changes {', '.join(sorted({q for q, _ in comps}))} "
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
