"""Measurement-side candidates of the diagnosis service that need the campaign's recorded
signals or its redundancy (docs/diagnosis.md "Model or measurement?"): named ``offset
CHANNEL`` candidates and gains of wheel force channels, both judged on the measurement
re-evaluated from the signals (:mod:`railval.core.diagnosis.measurement`), and the relative
gain of a car body sensor against its redundant channel at the other end.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from railval.core.diagnosis import CandidateFamily, DiagnosisResult, SectionEvidence
from railval.core.diagnosis.evidence import section_evidence
from railval.core.diagnosis.measurement import (
    GAIN_NODES,
    OFFSET_NODES,
    PairRecords,
    discrete_family,
    force_gain_groups,
    offset_blind,
    offset_components,
    offset_family,
    offset_measured,
    offset_scale,
    packed_measurements,
    reevaluated_measurement,
    remapped_measurement,
    section_lag,
    shared_gain_family,
    shifted_measured,
    sign_blind,
    signed_request,
    swap_pairs,
    swapped_bands,
    swapped_request,
)
from railval.core.types import channel_kind


def offset_families(ctx: Any, sets: Mapping[str, Any], measurement: bool | Sequence[str], base: SectionEvidence,
                     result: tuple, meas_bands: Mapping, sections: Sequence[tuple[str, int]], limits: Mapping[str, float],
                     skipped: list[dict]) -> dict[str, CandidateFamily]:
    """The ``offset CHANNEL`` and ``offset GROUP`` candidates (:mod:`railval.core.diagnosis.measurement`)
    named in ``measurement`` (not part of the default set): one channel, or a wheel-force group
    of :func:`railval.core.diagnosis.measurement.force_gain_groups` (wheelset ``Q_w1``, side
    ``Y_L``, bogie ``Q_bogie1``: every channel of it reads the truth + the same c — one
    amplifier zeroed wrong); a channel whose offset the EN filter removes is left out with that
    reason. The measured statistics are re-evaluated from the recorded signals at every offset
    node (no simulation)."""
    if measurement is True:  # by name only (docs/diagnosis.md: a gain of a wheel force channel,
        return {}            # for which there is no candidate, is taken for an offset with confidence)
    pairs, _ = result
    used = {ch: offset_components(pairs, ch) for ch in ctx.channels}
    used = {ch: comps for ch, comps in used.items() if comps}
    groups = {g: tuple(c for c in chans if c in used) for g, chans in force_gain_groups(ctx.channels).items()}
    out: dict[str, CandidateFamily] = {}
    for ch in sorted(m.removeprefix("offset ") for m in measurement if m.startswith("offset ")):
        members = (ch,) if ch in used else groups.get(ch) or ()
        why = (offset_blind(ch) if ch in used else "" if members else
               "not a channel (nor a wheel-force group) of this campaign that a measured quantity is formed from")
        scale = float(np.median([_offset_scale(sets, c) for c in members])) if members and not why else 0.0
        if not why and not scale > 0:
            why = "the channel is constant"
        if why:
            skipped.append({"name": f"offset {ch}", "kind": "measurement", "reason": why})
            continue
        out[f"offset {ch}"] = _offset_group_family(ctx, sets, base, result, meas_bands, sections, limits, ch,
                                                   members, sorted({x for c in members for x in used[c]}),
                                                   [f * scale for f in OFFSET_NODES])
    return out


def _offset_scale(sets: Mapping[str, Any], channel: str) -> float:
    return offset_scale(sets, channel)


def _offset_group_family(ctx: Any, sets: Mapping[str, Any], base: SectionEvidence, result: tuple,
                         meas_bands: Mapping, sections: Sequence[tuple[str, int]], limits: Mapping[str, float],
                         name: str, members: Sequence[str], comps: Sequence[tuple[str, str]],
                         offsets: Sequence[float]) -> CandidateFamily:
    """``offset NAME``: every channel of ``members`` reads the truth + c, the measurement's
    statistics re-evaluated at every c of ``offsets``."""
    pairs, sim_bands = result
    g_set = set(members)
    if len(members) == 1:
        measured = [(c, offset_measured(sets, ctx.sections, members[0], c, comps)) for c in offsets]
    else:
        measured = [(c, remapped_measurement(sets, ctx.sections, lambda _s, ch, _ss, c=c: {
            k: (x - c if k in g_set else x) for k, x in ch.items()}, comps)) for c in offsets]
    kind = channel_kind(members[0])
    return offset_family(base, pairs, sim_bands, meas_bands, sections, name, kind.unit if kind else "", measured,
                         limits, bands=ctx.bands, group=None if len(members) == 1 and name == members[0] else members)


def shared_gain(ctx: Any, sets: Mapping[str, Any], channel: str, base: SectionEvidence, result: tuple,
                 meas_bands: Mapping, sections: Sequence[tuple[str, int]], limits: Mapping[str, float]
                 ) -> CandidateFamily | None:
    """``gain CHANNEL`` named for a low-pass channel that shares its quantities (a wheel force):
    the measurement re-evaluated from the signals at every gain node; None where the channel is
    not one (:mod:`railval.core.diagnosis.measurement`)."""
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


#: prefixes of the measurement candidates' names (``--candidates``)
MEASUREMENT_PREFIXES = ("gain ", "offset ", "sign ", "swap ", "shift ")
#: the discrete measurement candidates of the default set (docs/diagnosis.md "Sign, position
#: swap and time shift"; ``shift`` by name only: what it finds the EN residual does not see)
DISCRETE_DEFAULTS: tuple[str, ...] = ("swap", "sign")


def _wanted(ctx: Any, measurement: bool | Sequence[str], defaults: Sequence[str]) -> tuple[list[str], bool]:
    """(the discrete candidates asked for, whether those that cannot apply stay unsaid): named
    in ``measurement``, or with ``measurement=True`` the kinds in ``defaults``."""
    if measurement is not True:
        return [m for m in measurement if m.startswith(("sign ", "swap ", "shift "))], False
    wanted: list[str] = []
    if "sign" in defaults:
        wanted += [f"sign {c}" for c in sorted(ctx.channels) if c.startswith(("Y_", "Q_"))]
    if "swap" in defaults:
        wheels = sorted({c.split("_", 1)[1][:-1] for c in ctx.channels if c.startswith(("Y_w", "Q_w"))})
        wanted += ["swap b1 b2"] + [f"swap {w}L {w}R" for w in wheels]
    if "shift" in defaults:
        wanted += [f"shift {s.id}" for s in ctx.sections]
    return wanted, True  # a default candidate that does not apply is not worth a line


def _sign_family(name: str, arg: str, k: dict[str, Any]) -> _Plan | str:
    """``sign CHANNEL``: how to build the family, or why it cannot apply."""
    ctx, pairs = k["ctx"], k["pairs"]
    comps = offset_components(pairs, arg) if arg in ctx.channels else []
    why = sign_blind(arg, comps)
    if why:
        return why
    return _Plan(signed_request(arg, comps), None, k["meas_bands"], lambda ev: discrete_family(
        name, "sign", -1.0, ev, half_width=0.01, title=f"channel {arg} reads with reversed sign",
        explanation=(f"the measurement, not the model: channel {arg} reads −1 × the true value (polarity of "
                     f"the sensor or bridge reversed); it changes {', '.join(sorted({q for q, _ in comps}))}")))


def _swap_family(name: str, arg: str, k: dict[str, Any]) -> _Plan | str:
    """``swap A B``: how to build the family, or why it cannot apply."""
    ctx, pairs = k["ctx"], k["pairs"]
    a, _, b = arg.partition(" ")
    pp = swap_pairs(a, b, ctx.channels)
    comps = sorted({c for x, y in pp for c in (*offset_components(pairs, x), *offset_components(pairs, y))})
    if not pp or not comps:
        return (f"{a} and {b} are not two channels (or positions) of the same kind this campaign "
                "measures a quantity with")
    mb = swapped_bands(k["meas_bands"], pp)
    which = ", ".join(f"{x}↔{y}" for x, y in pp)
    bands = any(x in ctx.channels and x[:2] in ("ay", "az") for x, _ in pp)
    return _Plan(swapped_request(pp, comps), None, mb, lambda ev: discrete_family(
        name, "swap", 1.0, ev, half_width=0.01, title=f"{a} and {b} recorded each other's position ({which})",
        explanation=(f"the measurement, not the model: the sensors of {a} and {b} are exchanged ({which}); "
                     f"it changes {', '.join(sorted({q for q, _ in comps}))} at both positions"
                     + (" and their band powers" if bands else ""))))


def _shift_family(name: str, arg: str, k: dict[str, Any]) -> _Plan | str:
    """``shift SECTION``: how to build the family, or why it cannot apply."""
    ctx, sets, sim_sets = k["ctx"], k["sets"], k["sim_sets"]
    sec = next((s for s in ctx.sections if s.id == arg), None)
    if sec is None or arg not in sets or arg not in sim_sets:
        return f"{arg} is not a section of this campaign with measured and simulated signals"
    lag = section_lag(sets[arg], sim_sets[arg])
    fs = float(sets[arg].fs)
    if not lag["consistent"]:
        return lag["reason"]
    if abs(lag["lag"]) < 1.0 / fs:
        return f"the channels agree on a lag of {lag['lag']:+.4f} s, less than one sample"
    comps = sorted({(q, p) for r in k["pairs"] if str(r["section"]) == arg
                    for q, p in [(str(r["quantity"]), str(r["position"]))]})

    def family(ev: SectionEvidence) -> CandidateFamily:
        return discrete_family(
            name, "shift", lag["lag"], ev, half_width=max(lag["spread"], 0.5 / fs), unit="s",
            title=f"section {arg} recorded {lag['lag']:+.3f} s late",
            explanation=(f"the measurement, not the model: every channel of section {arg} trails the simulation "
                         f"by {lag['lag']:+.3f} s (cross-correlation of {len(lag['lags'])} channels, spread "
                         f"{lag['spread']:.3f} s — a time base or trigger set wrong); re-aligned, the section's "
                         "quantities are evaluated on the right stretch of track"))

    # one section re-evaluated (the others stay as measured): a call of its own
    return _Plan(None, lambda: shifted_measured(sets, ctx.sections, arg, lag["lag"], comps), k["meas_bands"], family)


@dataclass
class _Plan:
    """A discrete candidate that applies: its re-evaluation — a ``(remap, components)``
    request of all sections (evaluated with the other candidates' requests,
    :func:`railval.core.diagnosis.reevaluation.packed_measurements`) or a call of its own
    (``measure``) — the measured band powers its evidence takes, and the family of the evidence."""

    request: tuple | None
    measure: Callable[[], Mapping[tuple[str, str, str], float]] | None
    meas_bands: Mapping
    family: Callable[[SectionEvidence], CandidateFamily]


_DISCRETE_BUILDERS = {"sign": _sign_family, "swap": _swap_family, "shift": _shift_family}


def discrete_families(ctx: Any, sets: Mapping[str, Any], sim_sets: Mapping[str, Any],
                      measurement: bool | Sequence[str], base: SectionEvidence, result: tuple, meas_bands: Mapping,
                      sections: Sequence[tuple[str, int]], limits: Mapping[str, float], skipped: list[dict],
                      *, defaults: Sequence[str] = ()) -> dict[str, CandidateFamily]:
    """The discrete measurement candidates (:mod:`railval.core.diagnosis.measurement`):
    ``sign CHANNEL`` (polarity reversed), ``swap A B`` (two channels or two positions exchanged)
    and ``shift SECTION`` (all channels of a section recorded late by the lag fitted from the
    cross-correlation with the configuration's simulation ``sim_sets``); named in
    ``measurement``, or with ``measurement=True`` the kinds in ``defaults`` (``"swap"``: both
    car body ends and the two wheels of every wheelset; ``"shift"``: every section whose
    channels agree on a lag of at least one sample; ``"sign"``: every wheel force channel).
    What cannot apply is left out with its reason in ``skipped``; a named shift of a section
    without a consistent lag too. The sign and swap re-evaluations of all candidates run in one
    batched EN evaluation, those touching disjoint channels in one signal set
    (:func:`railval.core.diagnosis.reevaluation.packed_measurements`), and each evidence is
    built from the records as arrays (:class:`railval.core.diagnosis.measurement.PairRecords`,
    equal to :func:`railval.core.diagnosis.measurement.discrete_evidence` exactly)."""
    wanted, quiet = _wanted(ctx, measurement, defaults)
    if not wanted or not sets:
        return {}
    pairs, sim_bands = result
    k = {"ctx": ctx, "sets": sets, "sim_sets": sim_sets, "base": base, "pairs": pairs, "sim_bands": sim_bands,
         "meas_bands": meas_bands, "sections": sections, "limits": limits}
    plans = [(name, _DISCRETE_BUILDERS[name.partition(" ")[0]](name, name.partition(" ")[2], k)) for name in wanted]
    batched = [p for _, p in plans if isinstance(p, _Plan) and p.request is not None]
    measured = dict(zip(map(id, batched), packed_measurements(sets, ctx.sections, [p.request for p in batched]),
                        strict=True))
    recs = PairRecords(pairs, limits) if any(isinstance(p, _Plan) for _, p in plans) else None
    likes: dict[int, SectionEvidence] = {}  # the band powers and layout of the evidence, per measured bands
    out: dict[str, CandidateFamily] = {}
    for name, plan in plans:
        fam: CandidateFamily | str = plan
        if isinstance(plan, _Plan):
            m = measured[id(plan)] if plan.request is not None else plan.measure()
            if id(plan.meas_bands) not in likes:
                likes[id(plan.meas_bands)] = section_evidence([], sim_bands, plan.meas_bands, sections,
                                                              bands=ctx.bands, value_key="D_norm", like=base)
            fam = plan.family(recs.reevaluated(likes[id(plan.meas_bands)], m))
            if np.array_equal(fam.evidence[1].values(), base.values()):
                fam = "changes none of the quantities the campaign measures"
        if isinstance(fam, str):
            if not quiet:
                skipped.append({"name": name, "kind": "measurement", "reason": fam})
        else:
            out[fam.name] = fam
    return out


def _gain_kind(name: str) -> tuple[str, bool]:
    """(kind, single channel) of a ``gain X`` or ``offset X`` candidate: ``Y``/``Q`` for the
    wheel-force groups (single: one wheel ``Y_w1L``), the channel stem for an accelerometer (``az_cb``)."""
    x = name.partition(" ")[2]
    if x[:2] in ("Y_", "Q_"):
        return x[0], x[-1] in "LR" and x[3:-1].isdigit() and x[2] == "w"
    stem, _, _end = x.rpartition("_")
    return stem or x, True


#: share of a kind's channels whose gains all lie on one side of 1 that marks a common model error
MOST = 0.75

#: the measurement candidates the redundancy rule judges: parameter → (value of a sensor that
#: reads right, what it reads wrong by: the logarithm of a gain, the offset itself)
_READS_RIGHT: dict[str, tuple[float, Any]] = {"gain": (1.0, math.log), "offset": (0.0, float)}


def not_sensor_faults(res: DiagnosisResult) -> dict[str, str]:
    """The campaign's redundancy rule (docs/diagnosis.md "Model or measurement?"), for the gain
    candidates (reference 1) and the offset candidates (reference 0) alike: a candidate is no
    sensor fault when its interval of fitted values contains the reference (the sensor may read
    right), or when every channel of its kind wants the same value — each single channel's
    fitted value inside every other one's interval, on one side of the reference: a model error
    common to all those sensors (a mass, a stiffness) scales or shifts them alike, a sensor
    fault one; likewise when at least :data:`MOST` of three or more channels of the kind want a
    value on the same side (bootstrap interval beyond the reference: on the trust bench another
    creep law in the truth lowered every guiding force, and a side group's gain absorbed it);
    and when the same group on the other bogie (wheelset 1 ↔ 3, 2 ↔ 4: they run in the same
    conditions) wants a value on the same side, at least half as far from the reference (in log
    for a gain) — the wheels' analogue of the two car body ends (a softer flange contact in the
    truth lowered both leading wheelsets' Y). The interval is the bootstrap one (refit on
    resampled sections, Efron & Tibshirani 1993 §8.2): the widened interval also holds the
    lack-of-fit region, which grows with any model error the candidate cannot remove. Name → reason."""
    out: dict[str, str] = {}
    for parameter, (ref, dev) in _READS_RIGHT.items():
        cands = [c for c in res.candidates if c.kind == "measurement" and c.parameter == parameter]
        _no_fault_of(cands, parameter, ref, dev, out)
    return out


def _no_fault_of(cands: Sequence[Any], parameter: str, ref: float, dev: Any, out: dict[str, str]) -> None:
    """:func:`not_sensor_faults` for the candidates of one ``parameter`` (``gain``/``offset``)."""
    what = {"gain": "gains", "offset": "offsets"}[parameter]
    a = {"gain": "a gain", "offset": "an offset"}[parameter]
    by_name = {c.name: c for c in cands}
    by_kind: dict[str, list] = {}
    for c in cands:
        kind, single = _gain_kind(c.name)
        if single:
            by_kind.setdefault(kind, []).append(c)
        lo, hi = c.fitted_ci_bootstrap
        if lo is not None and hi is not None and lo <= ref <= hi:
            out[c.name] = (f"its bootstrap interval of fitted {what} {lo:.3g}–{hi:.3g} contains {ref:g}: the sensor "
                           "may read right")
    for kind, singles in by_kind.items():
        if len(singles) < 2:
            continue
        alike = all(o.fitted_ci_bootstrap[0] <= c.fitted <= o.fitted_ci_bootstrap[1] for c in singles for o in singles)
        same = alike and (all(c.fitted > ref for c in singles) or all(c.fitted < ref for c in singles))
        up = sum(c.fitted_ci_bootstrap[0] > ref for c in singles)
        down = sum(c.fitted_ci_bootstrap[1] < ref for c in singles)
        vals = sorted(c.fitted for c in singles)
        why = (f"every {kind} channel wants the same {parameter} ({vals[0]:.3g}–{vals[-1]:.3g})" if same else
               f"{max(up, down)} of the {len(singles)} {kind} channels want {a} "
               f"{'above' if up > down else 'below'} {ref:g}"
               if len(singles) >= 3 and max(up, down) >= MOST * len(singles) else "")
        for c in cands:
            if why and _gain_kind(c.name)[0] == kind:
                out.setdefault(c.name, why + ": a model error common to those sensors, not a sensor fault")
    for c in cands:
        other = by_name.get(f"{parameter} {_counterpart(c.name.partition(' ')[2])}")
        if other is None or c.name in out or (parameter == "gain" and not (c.fitted > 0 and other.fitted > 0)):
            continue
        lo, hi = other.fitted_ci_bootstrap
        same_side = (lo > ref and c.fitted > ref) or (hi < ref and c.fitted < ref)
        if same_side and abs(dev(other.fitted)) >= 0.5 * abs(dev(c.fitted)):
            out[c.name] = (f"{other.name.partition(' ')[2]} of the other bogie wants {a} alike "
                           f"({other.fitted:.3g} against {c.fitted:.3g}): a model error common to both bogies "
                           "(a contact, a creep law), not a sensor fault")


def _counterpart(group: str) -> str | None:
    """The same force group on the other bogie of a four-wheelset vehicle: wheelset 1 ↔ 3,
    2 ↔ 4 (``Y_w1L`` ↔ ``Y_w3L``, ``Q_w2`` ↔ ``Q_w4``), ``Y_bogie1`` ↔ ``Y_bogie2``."""
    k, _, rest = group.partition("_")
    if rest in ("bogie1", "bogie2"):
        return f"{k}_bogie{3 - int(rest[-1])}"
    if rest[:1] == "w" and rest[1:2] in "1234" and rest[1:2]:
        return f"{k}_w{ {'1': '3', '2': '4', '3': '1', '4': '2'}[rest[1]] }{rest[2:]}"
    return None


def apply_redundancy_rule(res: DiagnosisResult) -> dict[str, str]:
    """Flag the gain and offset candidates that are no sensor fault (:func:`not_sensor_faults`); a top
    ``cause`` among them becomes ``uncertain``. Returns name → reason (left out of the cause set)."""
    out = not_sensor_faults(res)
    for c in res.candidates:
        if c.name in out:
            c.flags.append("not a sensor fault: " + out[c.name])
    if res.candidates and res.verdict == "cause" and res.candidates[0].name in out:
        res.verdict = "uncertain"
        res.note = f"uncertain: {res.candidates[0].name} is not a sensor fault — {out[res.candidates[0].name]}"
    return out
