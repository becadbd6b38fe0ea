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
from collections.abc import Iterable, Mapping, Sequence
from typing import Any

import numpy as np

from railval.core.diagnosis.evidence import SectionEvidence, section_evidence
from railval.core.diagnosis.fit import CandidateFamily
from railval.core.diagnosis.patterns import DEFAULT_BANDS_HZ

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


def gain_pairs(pairs: Iterable[Mapping[str, Any]], components: Sequence[tuple[str, str]], gain: float,
               std_limits: Mapping[str, float]) -> list[dict[str, Any]]:
    """The validation pairs with the measurement of ``components`` corrected for a channel
    reading ``gain`` × the truth: M' = M/g, D' = (S − M')·sign(M') (D' = S where M = 0),
    ``D_norm`` = D'/std limit. Records need ``quantity``, ``position``, ``M``, ``S``."""
    comp = set(components)
    out = []
    for r in pairs:
        r = dict(r)
        if (str(r["quantity"]), str(r["position"])) in comp:
            m = float(r["M"]) / gain
            s = float(r["S"])
            d = (s - m) * math.copysign(1.0, m) if m != 0 else s
            r["M"], r["D_norm"] = m, d / float(std_limits[str(r["quantity"])])
        out.append(r)
    return out


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
