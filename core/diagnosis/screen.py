"""Screening of simulated candidates (docs/diagnosis.md "Screened diagnosis"): every effect and
parameter candidate is simulated on a few sections first — one per EN 14363 test zone present,
then further ones zone by zone — and only the ``keep`` candidates that explain most of the
residual on those sections are simulated on the rest of the campaign and ranked; the others are
reported with their share on the screen.

A candidate's per-section evidence does not depend on which other sections were simulated (each
section is its own run), so a kept candidate's evidence, fitted value, explained and held-out
shares equal those of the whole diagnosis. What screening changes: the screened-out candidates
are not ranked, and the noise floor (the 95th percentile of the largest share of pure section
scatter any candidate explains) counts a screened-out candidate through a stand-in
(:func:`stand_in`): its own evidence on the screen sections, and on the others the change it
makes on its test zone's screen section — an estimate where the whole diagnosis has the run.
Without the stand-ins the floor would be a maximum over fewer candidates, so never higher than
the whole diagnosis's (lower in 13 of 45 trust-bench cases, by up to 0.064). Measured on the
trust bench (docs/diagnosis.md).

References: EN 14363:2016 §7.6 (test zones); Hastie, Tibshirani & Friedman 2009 §7.10 (the
in-sample share is optimistic: it orders the candidates here, it does not judge them).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import replace
from typing import Any

import numpy as np

from railval.core.diagnosis.engine import diagnose_evidence
from railval.core.diagnosis.evidence import SectionEvidence
from railval.core.diagnosis.fit import CandidateFamily
from railval.core.errors import InvalidParameter

#: sections a screen simulates (one per test zone present first, then zone by zone)
SCREEN_SECTIONS = 4
#: candidates the Diagnose page's screened diagnosis keeps (the command line's ``--screen K``
#: chooses); 8 kept the verdict, top and cause set of every trust-bench case measured (45)
SCREEN_KEEP = 8


def check_keep(keep: Any) -> int:
    """The number of candidates a screen keeps, checked: a whole number ≥ 1."""
    if isinstance(keep, bool) or not isinstance(keep, int) or keep < 1:
        raise InvalidParameter(f"screen: the number of candidates kept after the screen must be a whole "
                               f"number ≥ 1, got {keep!r}")
    return keep


def screen_sections(sections: Sequence[tuple[str, int]], n: int = SCREEN_SECTIONS) -> list[str]:
    """Ids of the ``n`` screen sections of ``sections`` (``(id, zone)`` in campaign order): the
    first section of every zone present, in zone order, then the second of every zone, and so
    on — every zone the campaign covers is on the screen when ``n`` ≥ the number of zones."""
    by_zone: dict[int, list[str]] = {}
    for sid, zone in sections:
        by_zone.setdefault(int(zone), []).append(sid)
    out: list[str] = []
    depth = 0
    while len(out) < min(n, len(sections)):
        for zone in sorted(by_zone):
            if depth < len(by_zone[zone]) and len(out) < n:
                out.append(by_zone[zone][depth])
        depth += 1
    return [sid for sid, _ in sections if sid in set(out)]


def screen_order(base: SectionEvidence, families: Sequence[CandidateFamily], keep: int, *, validated: bool,
                 folds: int, seed: int) -> tuple[list[str], list[dict[str, Any]]]:
    """(names kept, the others as ``{"name", "kind", "explained_on_screen",
    "held_out_on_screen"}``) of candidate ``families`` whose evidence covers the screen
    sections only, ``base`` the configuration's on the same sections: ordered by the share of the
    residual each explains in-sample on the screen (:func:`diagnose_evidence`, no bootstrap), the
    best ``keep`` kept. A family that moves nothing on the screen explains 0 there."""
    res = diagnose_evidence(base, families, validated=validated, n_boot=0, folds=folds, seed=seed)
    order = sorted(res.candidates, key=lambda c: -c.explained)
    kind = {f.name: f.kind for f in families}
    out = [{"name": c.name, "kind": kind[c.name], "explained_on_screen": round(float(c.explained), 4),
            "held_out_on_screen": round(float(c.held_out_explained), 4)} for c in order[keep:]]
    return [c.name for c in order[:keep]], out


def stand_in(base: SectionEvidence, screen_base: SectionEvidence, candidate: SectionEvidence) -> SectionEvidence:
    """A screened-out candidate's evidence on every section of ``base`` (the configuration's),
    for its part in the noise floor only (docs/diagnosis.md "Screened diagnosis"): on a screen
    section its own evidence (``candidate``, over the screen sections of ``screen_base``, the
    configuration's on them); on any other section the configuration's evidence moved by the
    change the candidate makes on the screen section of the same EN 14363 test zone (the first
    of that zone on the screen, or the first screen section when the zone is not on it) — the
    mean normalised difference of each quantity component shifted by the same amount (sums
    shifted by that change × the section's own count) and each band's simulated power scaled
    by the same factor; the measured powers are the measurement's. Components without data on
    either section are left as the configuration's. Exact where every section of a zone
    changes alike; an estimate otherwise (measured against the whole diagnosis on the trust
    bench, docs/diagnosis.md)."""
    on = {sid: i for i, sid in enumerate(screen_base.sections)}
    zone_of = dict(zip(screen_base.sections, screen_base.zones, strict=True))
    first = {}
    for sid in screen_base.sections:
        first.setdefault(zone_of[sid], on[sid])
    rows = np.array([on[sid] if sid in on else first.get(z, 0) for sid, z in zip(base.sections, base.zones,
                                                                                   strict=True)])
    cs, cc = candidate.sums[rows], candidate.counts[rows]
    bs, bc = screen_base.sums[rows], screen_base.counts[rows]
    ok = (cc > 0) & (bc > 0) & (base.counts > 0)
    with np.errstate(divide="ignore", invalid="ignore"):
        shift = np.where(ok, cs / np.where(cc > 0, cc, 1.0) - bs / np.where(bc > 0, bc, 1.0), 0.0)
        scale = np.where((screen_base.sim_power[rows] > 0) & (candidate.sim_power[rows] > 0),
                         candidate.sim_power[rows] / np.where(screen_base.sim_power[rows] > 0,
                                                              screen_base.sim_power[rows], 1.0), 1.0)
    sums, counts = base.sums + shift * base.counts, base.counts.copy()
    sim_power = base.sim_power * scale
    own = np.array([sid in on for sid in base.sections])
    sums[own], counts[own], sim_power[own] = cs[own], cc[own], candidate.sim_power[rows][own]
    return SectionEvidence(list(base.sections), list(base.zones), list(base.labels), list(base.groups), base.n_pair,
                           sums, counts, sim_power, base.meas_power.copy(),
                           None if base.components is None else list(base.components))


def floor_stand_ins(base: SectionEvidence, screen_base: SectionEvidence,
                    families: Sequence[CandidateFamily]) -> list[CandidateFamily]:
    """The screened-out candidate ``families`` (evidence over the screen sections) as
    floor-only families over every section (:func:`stand_in`; ``floor_only``: counted in the
    noise floor, never ranked)."""
    out = []
    for f in families:
        ev = [base if e is screen_base else stand_in(base, screen_base, e) for e in f.evidence]
        out.append(replace(f, evidence=ev, floor_only=True))
    return out
