"""Coverage rules of a validation (Polach & Böttcher 2014 §5; docs/design.md §3) — their one
home: the verdict's :func:`coverage` over the pairs of a validation and
:func:`layout_shortfalls` over a campaign's layout before any validation apply the same
thresholds and the same zone rule.

A configuration's evidence covers the vehicle's running when it has ≥ 12 sections with
comparisons, each of the 4 EN 14363 test zones with ≥ 3 sections, and per quantity ≥ 2
signals (positions) and ≥ 24 values. Every shortfall is one sentence ("zone 3 has 2
sections, needs 3").

References
----------
Polach & Böttcher 2014, §5; EN 14363:2005, test zones for on-track tests.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

from railval.core.quantities import QUANTITIES, QUANTITY_IDS
from railval.core.types import ZONES, split_channel

MIN_SECTIONS = 12
MIN_SECTIONS_PER_ZONE = 3
MIN_POSITIONS = 2
MIN_VALUES = MIN_SECTIONS * MIN_POSITIONS


@dataclass
class Coverage:
    """Coverage rules of Polach & Böttcher 2014 §5 and their shortfalls (one sentence each)."""

    n_sections: int
    zones: dict[int, int]
    positions: dict[str, int]
    values: dict[str, int]
    shortfalls: list[str]

    @property
    def ok(self) -> bool:
        return not self.shortfalls

    #: the rules' thresholds (Polach & Böttcher 2014 §5), as the views show them
    sections_required = MIN_SECTIONS
    sections_per_zone_required = MIN_SECTIONS_PER_ZONE
    signals_per_quantity_required = MIN_POSITIONS
    values_per_quantity_required = MIN_VALUES

    def to_dict(self) -> dict:
        return {
            "ok": self.ok, "sections": self.n_sections, "sections_required": self.sections_required,
            "zones": {str(z): n for z, n in self.zones.items()},
            "sections_per_zone_required": self.sections_per_zone_required,
            "signals_per_quantity": dict(self.positions),
            "signals_per_quantity_required": self.signals_per_quantity_required,
            "values_per_quantity": dict(self.values),
            "values_per_quantity_required": self.values_per_quantity_required,
            "shortfalls": list(self.shortfalls),
        }


def coverage(pair_sections: Mapping[str, set], pair_positions: Mapping[str, set],
             pair_counts: Mapping[str, int], zone_of: Mapping[str, int]) -> Coverage:
    """Check the coverage rules of Polach & Böttcher 2014 §5 on the pairs of a validation.

    Parameters
    ----------
    pair_sections, pair_positions : mapping of quantity id → set
        Sections and positions with a pair for each quantity.
    pair_counts : mapping of quantity id → int
        Number of pairs of each quantity.
    zone_of : mapping of section id → int
        EN 14363 test zone of every section.

    Returns
    -------
    Coverage
        Counts and one sentence per shortfall (empty when the coverage holds).
    """
    sections = set().union(*pair_sections.values()) if pair_sections else set()
    zones = {z: sum(1 for s in sections if zone_of[s] == z) for z in ZONES}
    shortfalls = []
    if len(sections) < MIN_SECTIONS:
        shortfalls.append(f"{len(sections)} sections have comparisons, needs {MIN_SECTIONS}")
    shortfalls += zone_shortfalls(zones)
    positions = {q: len(pair_positions.get(q, ())) for q in QUANTITY_IDS}
    values = {q: int(pair_counts.get(q, 0)) for q in QUANTITY_IDS}
    for q in QUANTITY_IDS:
        if positions[q] < MIN_POSITIONS:
            shortfalls.append(f"quantity {q} has {positions[q]} signal"
                              f"{'s' if positions[q] != 1 else ''}, needs {MIN_POSITIONS}")
        if values[q] < MIN_VALUES:
            shortfalls.append(f"quantity {q} has {values[q]} values, needs {MIN_VALUES}")
    return Coverage(len(sections), zones, positions, values, shortfalls)


def zone_shortfalls(zones: Mapping[int, int], min_per_zone: int = MIN_SECTIONS_PER_ZONE) -> list[str]:
    """The zone rule of Polach & Böttcher 2014 §5: every EN 14363 zone (1–4) with at least
    ``min_per_zone`` sections; one sentence per zone short of it ("zone 3 has 2 sections,
    needs 3").

    Parameters
    ----------
    zones : mapping of zone → number of sections
        Zones missing from the mapping count 0.
    min_per_zone : int
        Sections each zone needs.

    Returns
    -------
    list of str
        The shortfalls in zone order, empty when the rule holds.
    """
    out = []
    for z in ZONES:
        n = int(zones.get(z, 0))
        if n < min_per_zone:
            out.append(f"zone {z} has {n} section{'s' if n != 1 else ''}, needs {min_per_zone}")
    return out


def verdict_channel_kinds() -> tuple[str, ...]:
    """The raw channel kinds the verdict quantities are formed from, in registry order
    (``Y``, ``Q``, ``ay_cb``, ``az_cb``; :data:`railval.core.quantities.QUANTITIES`)."""
    kinds: dict[str, None] = {}
    for q in QUANTITIES.values():
        for ch in q.channels(q.positions()[0]):
            kinds[split_channel(ch)[0]] = None
    return tuple(kinds)


def layout_shortfalls(section_zones: Sequence[int], channel_kinds: Sequence[str], *,
                      min_sections: int = MIN_SECTIONS, min_per_zone: int = MIN_SECTIONS_PER_ZONE,
                      min_signals: int = MIN_POSITIONS) -> list[str]:
    """The coverage rules of Polach & Böttcher 2014 §5 checked on a campaign's layout alone,
    before any validation: enough sections, every zone 1–4 with enough sections, and enough
    signals (channels) of every raw channel kind the verdict quantities use.

    Parameters
    ----------
    section_zones : sequence of int
        The EN 14363 zone of every section of the campaign.
    channel_kinds : sequence of str
        The kind of every stored channel (one entry per channel).
    min_sections, min_per_zone, min_signals : int
        The thresholds (defaults: the validation's own).

    Returns
    -------
    list of str
        One precise sentence per shortfall, empty when the layout can meet the rules.
    """
    out = []
    if len(section_zones) < min_sections:
        out.append(f"{len(section_zones)} sections, needs {min_sections}")
    counts: dict[int, int] = {}
    for z in section_zones:
        counts[z] = counts.get(z, 0) + 1
    out += zone_shortfalls(counts, min_per_zone)
    for kind in verdict_channel_kinds():
        n = sum(1 for k in channel_kinds if k == kind)
        if n < min_signals:
            out.append(f"channel kind {kind} has {n} signal{'s' if n != 1 else ''}, needs {min_signals}")
    return out
