"""Measurement-side candidates of the diagnosis service that need the campaign's recorded
signals or its redundancy (docs/diagnosis.md "Model or measurement?"): named ``offset
CHANNEL`` candidates and gains of wheel force channels, both judged on the measurement
re-evaluated from the signals (:mod:`railval.core.diagnosis.measurement`), and the relative
gain of a car body sensor against its redundant channel at the other end.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

from railval.core.diagnosis import CandidateFamily, DiagnosisResult, SectionEvidence


def offset_families(ctx: Any, sets: Mapping[str, Any], measurement: bool | Sequence[str], base: SectionEvidence,
                     result: tuple, meas_bands: Mapping, sections: Sequence[tuple[str, int]], limits: Mapping[str, float],
                     skipped: list[dict]) -> dict[str, CandidateFamily]:
    """The ``offset CHANNEL`` candidates (:mod:`railval.core.diagnosis.measurement`) named in
    ``measurement`` (not part of the default set); a channel whose offset the EN filter removes
    is left out with that reason. The measured statistics are
    re-evaluated from the recorded signals at every offset node (no simulation)."""
    from railval.core.diagnosis.measurement import (
        OFFSET_NODES,
        offset_blind,
        offset_components,
        offset_family,
        offset_measured,
        offset_scale,
    )
    from railval.core.types import channel_kind

    pairs, sim_bands = result
    used = {ch: offset_components(pairs, ch) for ch in ctx.channels}
    used = {ch: comps for ch, comps in used.items() if comps}
    if measurement is True:  # by name only (docs/diagnosis.md: a gain of a wheel force channel,
        return {}            # for which there is no candidate, is taken for an offset with confidence)
    wanted = sorted(m.removeprefix("offset ") for m in measurement if m.startswith("offset "))
    out: dict[str, CandidateFamily] = {}
    todo = []
    for ch in wanted:
        why = (offset_blind(ch) if ch in used else
               "not a channel of this campaign that a measured quantity is formed from")
        if why:
            skipped.append({"name": f"offset {ch}", "kind": "measurement", "reason": why})
        else:
            todo.append(ch)
    if not todo:
        return out
    for ch in todo:
        scale = offset_scale(sets, ch)
        if not scale > 0:
            skipped.append({"name": f"offset {ch}", "kind": "measurement", "reason": "the channel is constant"})
            continue
        comps = used[ch]
        measured = [(f * scale, offset_measured(sets, ctx.sections, ch, f * scale, comps)) for f in OFFSET_NODES]
        kind = channel_kind(ch)
        out[f"offset {ch}"] = offset_family(base, pairs, sim_bands, meas_bands, sections, ch,
                                            kind.unit if kind else "", measured, limits, bands=ctx.bands)
    return out


def shared_gain(ctx: Any, sets: Mapping[str, Any], channel: str, base: SectionEvidence, result: tuple,
                 meas_bands: Mapping, sections: Sequence[tuple[str, int]], limits: Mapping[str, float]
                 ) -> CandidateFamily | None:
    """``gain CHANNEL`` named for a low-pass channel that shares its quantities (a wheel force):
    the measurement re-evaluated from the signals at every gain node; None where the channel is
    not one (:mod:`railval.core.diagnosis.measurement`)."""
    from railval.core.diagnosis.measurement import (
        GAIN_NODES,
        offset_blind,
        offset_components,
        reevaluated_measurement,
        shared_gain_family,
    )

    pairs, sim_bands = result
    comps = offset_components(pairs, channel) if channel in ctx.channels else []
    if not comps or offset_blind(channel) or not sets:
        return None
    measured = [(g, reevaluated_measurement(sets, ctx.sections, channel, lambda x, g=g: x / g, comps))
                for g in GAIN_NODES]
    return shared_gain_family(base, pairs, sim_bands, meas_bands, sections, channel, measured, limits,
                              bands=ctx.bands)


def _partner(channel: str) -> str | None:
    """The redundant channel of a gain candidate: the same direction at the other car body
    end (``az_cb_b1`` ↔ ``az_cb_b2``) or bogie."""
    stem, _, end = channel.rpartition("_")
    other = {"b1": "b2", "b2": "b1"}.get(end)
    return f"{stem}_{other}" if stem and other else None


def relative_gains(res: DiagnosisResult) -> None:
    """Use the campaign's redundancy: a gain candidate's fitted value also absorbs any model
    error common to both ends; its ratio to the fitted gain of the redundant channel is what
    the one sensor reads more than the other (``parameters["relative_gain"]``, said in the
    summary)."""
    by = {c.name: c for c in res.candidates if c.kind == "measurement"}
    for c in by.values():
        other = by.get(f"gain {_partner(c.name.removeprefix('gain '))}")
        if other is None or not (other.fitted > 0):
            continue
        rel = c.fitted / other.fitted
        c.parameters["relative_gain"] = rel
        c.summary += (f"; {rel:.3g} × what {other.name.removeprefix('gain ')} (the redundant channel) implies "
                      f"— what this sensor reads more than the other")
