"""The measurement re-evaluated from the recorded signals with some channels corrected (a gain,
an offset, a reversed sign, two channels exchanged): the EN 14363 values of the quantities
formed from those channels, evaluated again by the EN chain (:mod:`railval.core.en14363`) —
the measured side of the measurement candidates (:mod:`railval.core.diagnosis.measurement`,
docs/diagnosis.md "Model or measurement?").

References: EN 14363:2016 §7.5 (quantities and their channels); Polach & Böttcher 2014 Table 2
(statistics of each quantity).
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Iterator, Mapping, Sequence

import numpy as np

from railval.core.types import SectionInfo, SignalSet


def remapped_measurement(signalsets: Mapping[str, SignalSet], sections: Sequence[SectionInfo],
                         remap: Callable[[str, Mapping[str, np.ndarray], SignalSet], Mapping[str, np.ndarray]],
                         components: Sequence[tuple[str, str]]) -> dict[tuple[str, str, str], float]:
    """The measurement's EN values of ``components`` re-evaluated from the signals after
    ``remap(section, channels, signalset)`` → the corrected channels of that section (only the
    channels the components use are passed and evaluated; a section whose remap returns the
    channels unchanged is evaluated as stored). ``(section, quantity, position)`` → M'."""
    return remapped_measurements(signalsets, sections, [(remap, components)])[0]


#: channels (filtered rows) per EN call of :func:`remapped_measurements` (bounds the memory of one
#: call; the rows of the former bound of 96 signal sets with the 2 channels of a force-gain ΣY)
REMAP_ROWS = 192


def remapped_measurements(signalsets: Mapping[str, SignalSet], sections: Sequence[SectionInfo],
                          requests: Sequence[tuple[Callable[[str, Mapping[str, np.ndarray], SignalSet],
                                                            Mapping[str, np.ndarray]], Sequence[tuple[str, str]]]]
                          ) -> list[dict[tuple[str, str, str], float]]:
    """:func:`remapped_measurement` of many ``(remap, components)`` requests in few EN calls:
    the remapped signal sets of all requests go to :func:`railval.core.en14363.evaluate_batch`
    together (:data:`REMAP_ROWS` channels at a time). Each section's values depend on its own
    signals only ("Results equal :func:`evaluate_section` on each section alone"), so every
    request's values equal those of its own call exactly. Only the readings of the components
    are wanted: the other readings and the PSD bands are not computed."""
    out: list[dict[tuple[str, str, str], float]] = [{} for _ in requests]
    for i, sid, v in _remapped_values(signalsets, sections, [(remap, _channels_of(comps)) for remap, comps in requests]):
        out[i].update({(sid, q, p): float(v[(q, p)]) for q, p in requests[i][1] if (q, p) in v})
    return out


def _channels_of(components: Iterable[tuple[str, str]]) -> set[str]:
    """The channels the EN quantities ``components`` are formed from."""
    from railval.core.quantities import QUANTITIES

    return {c for q, p in components for c in QUANTITIES[q].channels(p)}


def _remapped_values(signalsets: Mapping[str, SignalSet], sections: Sequence[SectionInfo],
                     remaps: Sequence[tuple[Callable[[str, Mapping[str, np.ndarray], SignalSet],
                                                     Mapping[str, np.ndarray]], set[str]]]
                     ) -> Iterator[tuple[int, str, Mapping[tuple[str, str], float]]]:
    """``(remap index, section id, EN values)`` of every section holding a channel of ``need``,
    for every ``(remap, need)`` of ``remaps`` in order: the section's channels of ``need``
    remapped, evaluated in batches of :data:`REMAP_ROWS` channels (primary readings only)."""
    from dataclasses import replace

    from railval.core.en14363 import evaluate_batch

    by_id = {s.id: s for s in sections}
    jobs = []  # (remap index, section id, signal set)
    for i, (remap, need) in enumerate(remaps):
        for sec in sections:
            ss = signalsets.get(sec.id)
            chans = {c: np.asarray(x, float) for c, x in ss.channels.items() if c in need} if ss is not None else {}
            if chans:
                jobs.append((i, sec.id, replace(ss, channels=dict(remap(sec.id, chans, ss)))))
    j0 = 0
    while j0 < len(jobs):
        j1, rows = j0 + 1, len(jobs[j0][2].channels)
        while j1 < len(jobs) and rows + len(jobs[j1][2].channels) <= REMAP_ROWS:
            rows += len(jobs[j1][2].channels)
            j1 += 1
        part = jobs[j0:j1]
        vals = evaluate_batch([ss for _, _, ss in part], [by_id[sid] for _, sid, _ in part],
                              alternatives=False, supplementary=False)
        for (i, sid, _), v in zip(part, vals, strict=True):
            yield i, sid, v
        j0 = j1


def packed_measurements(signalsets: Mapping[str, SignalSet], sections: Sequence[SectionInfo],
                        requests: Sequence[tuple[Callable[[str, Mapping[str, np.ndarray], SignalSet],
                                                          Mapping[str, np.ndarray]], Sequence[tuple[str, str]]]]
                        ) -> list[dict[tuple[str, str, str], float]]:
    """:func:`remapped_measurements` with the requests whose channels are disjoint evaluated in
    one signal set: requests are packed in order, each into the first pack none of whose
    channels its components use (its channels remapped by its own ``remap``, the pack's others
    by theirs), so a pack of k requests is one EN evaluation per section instead of k. Exact:
    every EN value of a (quantity, position) is formed from the rows of its own channels only
    — each channel filtered on its own row (:func:`railval.core.filters.filtfilt_rows`, the
    rows of a block in lockstep, no operation across rows), Y/Q per wheel and ΣY per wheelset
    from their own rows, every percentile and sliding mean per row
    (:mod:`railval.core.en_section`) — so a component's value does not depend on the other
    channels of its signal set, and every request reads the value of its own call
    (tests/test_diagnosis_measurement_speed.py compares them bit for bit)."""
    needs = [_channels_of(comps) for _, comps in requests]
    packs: list[tuple[set[str], list[int]]] = []
    for i, need in enumerate(needs):
        home = next((p for p in packs if not (p[0] & need)), None)
        if home is None:
            packs.append((set(need), [i]))
        else:
            home[0].update(need)
            home[1].append(i)

    def remap_of(members: list[int]) -> Callable[[str, Mapping[str, np.ndarray], SignalSet], dict]:
        def remap(sid: str, ch: Mapping[str, np.ndarray], ss: SignalSet) -> dict[str, np.ndarray]:
            out: dict[str, np.ndarray] = {}
            for i in members:
                own = {c: x for c, x in ch.items() if c in needs[i]}
                if own:
                    out.update(requests[i][0](sid, own, ss))
            return out
        return remap

    out: list[dict[tuple[str, str, str], float]] = [{} for _ in requests]
    for k, sid, v in _remapped_values(signalsets, sections, [(remap_of(m), used) for used, m in packs]):
        for i in packs[k][1]:
            out[i].update({(sid, q, p): float(v[(q, p)]) for q, p in requests[i][1] if (q, p) in v})
    return out
