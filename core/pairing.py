"""The pairs of a DynoTRAIN validation as columns (Polach & Böttcher 2014 §5; docs/design.md §3).

A pair is one (section, quantity, position) where the measurement and the simulation both
hold a finite value (eq. 4 is formed over the pairs of a quantity). :func:`gather_pairs`
collects them once per configuration as flat columns (sections sorted, keys in the
measurement's order — the order :func:`railval.core.validation.validate` reports them in);
:func:`values_under` reads every pair's value under the other readings of the open
definitions (:mod:`railval.core.definitions`) with one lookup per section and reading
instead of one call per pair.

References
----------
Polach & Böttcher 2014, §5, eq. (4).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np

from railval.core.definitions import CHOSEN, READINGS
from railval.core.en14363 import SectionValues
from railval.core.errors import InvalidParameter
from railval.core.quantities import QUANTITY_IDS
from railval.core.types import SectionInfo

_SECTION_VALUE_UNDER = SectionValues.value_under


@dataclass
class QuantityPairs:
    """The pairs of one quantity as columns, in gathering order (sections sorted, keys in the
    measurement's order): section, zone, position, M, S and the indices of the pairs in the
    gathered table (:class:`Pairs`)."""

    section: list[str]
    zone: list[int]
    position: list[str]
    m: np.ndarray
    s: np.ndarray
    index: np.ndarray

    @property
    def n(self) -> int:
        return int(self.m.size)


@dataclass
class Pairs:
    """Every pair of one configuration as flat columns (gathering order) plus, per section,
    the kept keys and their M and S values (to look the values up under other readings)."""

    section: list[str]
    zone: list[int]
    position: list[str]
    qindex: np.ndarray
    m: np.ndarray
    s: np.ndarray
    by_section: list[tuple[str, list, list, list]]
    _split: dict[int, QuantityPairs] = field(default_factory=dict)

    def of(self, qi: int) -> QuantityPairs:
        """The pairs of quantity ``QUANTITY_IDS[qi]`` (order kept)."""
        if qi not in self._split:
            idx = np.flatnonzero(self.qindex == qi)
            il = idx.tolist()
            self._split[qi] = QuantityPairs([self.section[i] for i in il],
                                            [self.zone[i] for i in il],
                                            [self.position[i] for i in il],
                                            self.m[idx], self.s[idx], idx)
        return self._split[qi]


_QINDEX = {q: i for i, q in enumerate(QUANTITY_IDS)}


def gather_pairs(measured_values, simulated_values, secs: Mapping[str, SectionInfo],
                 common: Sequence[str], memo: dict | None = None) -> Pairs:
    """Every pair ``(section, zone, position, M, S)`` where both sides hold a finite value
    (sections in ``common`` order, keys in the measurement's order), as columns.
    ``memo``: a dict kept by the caller across calls with the same measured values (one
    run's configurations; they must not change meanwhile): each measured section's keys,
    M column and the columns of its keys are kept there, per section object, and reused
    when every key makes a pair (the same lists and float64s as built here)."""
    section, zone, position, qindex, ms, ss, by_section = [], [], [], [], [], [], []
    nan = float("nan")
    for sid in common:
        if sid not in secs:
            raise InvalidParameter(f"section {sid!r} has values but no SectionInfo")
        z = int(secs[sid].zone)
        mv, sv = measured_values[sid], simulated_values[sid]
        side = memo.get(("gather", sid)) if memo is not None else None
        if side is None or side[0] is not mv:
            keys = list(mv)
            m = np.fromiter((float(mv[k]) for k in keys), dtype=np.float64, count=len(keys))
            side = (mv, keys, m, np.isfinite(m), None)
            if memo is not None:
                memo[("gather", sid)] = side
        _mv, keys, m, m_ok, cols = side
        s_raw = list(map(sv.get, keys))
        s = np.fromiter(s_raw if None not in s_raw else  # a missing key: NaN
                        (nan if v is None else v for v in s_raw), dtype=np.float64,
                        count=len(keys))
        ok = m_ok & np.isfinite(s)
        if cols is not None and ok.all():  # every key a pair: the kept columns
            kept, pos, qi, m_kept = cols
            ms.append(m)
            ss.append(s)
            section += [sid] * len(kept)
            zone += [z] * len(kept)
            position += pos
            qindex += qi
            by_section.append((sid, kept, m_kept, s_raw))
            continue
        keep = np.flatnonzero(ok).tolist()
        kept = [keys[i] for i in keep]
        for qid, _pos in kept:
            if qid not in _QINDEX:
                raise InvalidParameter(f"unknown quantity {qid!r} in section {sid}")
        pos = [k[1] for k in kept]
        qi = [_QINDEX[k[0]] for k in kept]
        m_kept = [mv[k] for k in kept]
        section += [sid] * len(kept)
        zone += [z] * len(kept)
        position += pos
        qindex += qi
        ms.append(m[keep])
        ss.append(s[keep])
        by_section.append((sid, kept, m_kept, [s_raw[i] for i in keep]))
        if memo is not None and len(keep) == len(keys):  # reused while every key pairs
            memo[("gather", sid)] = (mv, keys, m, m_ok, (kept, pos, qi, m_kept))
    cat = (lambda xs: np.concatenate(xs) if xs else np.empty(0))
    return Pairs(section, zone, position, np.array(qindex, dtype=np.intp), cat(ms), cat(ss),
                  by_section)

def values_under(pairs: Pairs, values, column: int, memo: dict | None = None
                 ) -> dict[str, np.ndarray]:
    """Reading id → every pair's value of one side under that reading (gathering order;
    ``SectionValues.value_under``: the chosen value where the reading does not change it).
    ``column``: 2 for the measured, 3 for the simulated side of ``pairs.by_section``.
    A :class:`SectionValues` stores only the values a reading changes, so each reading's
    column is the chosen column with those values written over it (the same float64s).
    ``memo`` (see :func:`gather_pairs`): the columns are kept there and returned again
    (read-only) while the sections, their value objects and their pairs' keys are the
    same — the measured side of every configuration of a run."""
    if memo is not None:
        got = memo.get(("under", column))
        if got is not None and len(got[0]) == len(pairs.by_section) and all(
                sid == row[0] and obj is values[row[0]] and kept == row[1]
                for (sid, obj, kept), row in zip(got[0], pairs.by_section)):
            return got[1]
        out = values_under(pairs, values, column)
        for col in out.values():
            col.setflags(write=False)
        memo[("under", column)] = ([(row[0], values[row[0]], row[1])
                                    for row in pairs.by_section], out)
        return out
    base = np.array([v for row in pairs.by_section for v in row[column]], dtype=np.float64)
    plain, offsets, at = [], [], 0
    for row in pairs.by_section:
        sv = values[row[0]]
        plain.append(type(sv).value_under is _SECTION_VALUE_UNDER)
        offsets.append(at)
        at += len(row[1])
    where: list = [None] * len(pairs.by_section)  # per section: key → position, on first use
    out = {}
    for reading in READINGS:
        if reading == CHOSEN:
            continue
        rid = reading.id
        col = base.copy()
        pos: list[int] = []
        got: list = []
        for j, row in enumerate(pairs.by_section):
            sv = values[row[0]]
            if not plain[j]:
                col[offsets[j]:offsets[j] + len(row[1])] = [sv.value_under(rid, k)
                                                            for k in row[1]]
                continue
            alt = sv.alternatives.get(rid)
            if not alt:
                continue
            if where[j] is None:
                where[j] = {k: offsets[j] + i for i, k in enumerate(row[1])}
            # positions of the changed values (None: the key is no pair), looked up in C
            at_pair = list(map(where[j].get, alt))
            if None in at_pair:
                kept = [(i, v) for i, v in zip(at_pair, alt.values(), strict=True)
                        if i is not None]
                pos += [i for i, _ in kept]
                got += [v for _, v in kept]
            else:
                pos += at_pair
                got += alt.values()
        col[pos] = got
        out[rid] = col
    return out
