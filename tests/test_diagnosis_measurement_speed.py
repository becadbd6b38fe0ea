"""The measurement candidates built without repeated work (docs/diagnosis.md "Packed
re-evaluations") give the evidence of the straightforward computation bit for
bit: every force-channel gain group re-evaluated on its own (its channels divided by g, one
:func:`remapped_measurement` per group and node) and corrected record by record
(:func:`corrected_pairs` + :func:`section_evidence`), every sign and swap candidate re-evaluated
by its own call — against the shared records, the packed signal sets
(:func:`packed_measurements`) and the array evidence of the service. A fault planted in the
packing (one candidate's signals remapped as another's) is seen."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from railval.app.services import diagnosis_ranking as dr
from railval.app.services.diagnosis_measurement import DISCRETE_DEFAULTS, discrete_families
from railval.core.diagnosis.evidence import section_evidence
from railval.core.diagnosis.measurement import (
    FORCE_GAIN_NODES,
    corrected_pairs,
    discrete_evidence,
    force_gain_groups,
    gain_degree,
    offset_components,
    remapped_measurement,
    sign_blind,
    signed_measured,
    swap_pairs,
    swapped_bands,
    swapped_measured,
)


@pytest.fixture(scope="module")
def campaign(tmp_path_factory):
    """A synthetic coach campaign of 12 sections (hidden friction damping), the configuration's
    simulated validation pairs and band powers and their evidence, as a diagnosis has them
    when it builds the measurement candidates."""
    from railval.app.services.campaign_context import band_sums, residual_pattern, section_values
    from railval.app.services.synth import synth
    from railval.db.engine import connect

    db = connect(f"sqlite:///{tmp_path_factory.mktemp('meas') / 'm.db'}")
    db.init()
    try:
        synth(db, name="ms", hidden=["friction_damping"], seed=5)
        req = dr._load(db, "ms", "baseline", None, None, True, True)
    finally:
        db.dispose()
    ctx = req.ctx
    _, vr = residual_pattern(ctx, section_values(req.config_sets, ctx.sections), band_sums(req.config_sets, ctx.bands))
    tasks, _ = dr._tasks(req, 3)
    result = dr._evaluate_sections(ctx, tasks[0])
    sections = [(s.id, int(s.zone)) for s in ctx.sections]
    base = section_evidence(result[0], result[1], req.meas_bands, sections, value_key="D_norm")
    limits = {q: r.std_limit for q, r in vr.quantities.items()}
    return req, result, base, sections, limits


def _mismatches(got: dict, want: dict) -> dict[str, list[str]]:
    """Name → what differs between two sets of candidate families: the names, values, texts and,
    node by node, every evidence array bit for bit (sums, counts, band powers) and its layout."""
    out: dict[str, list[str]] = {}
    if list(got) != list(want):
        out["names"] = [str(list(got)), str(list(want))]
    for name in set(got) & set(want):
        a, b = got[name], want[name]
        diff = [f.name for f in dataclasses.fields(a) if f.name != "evidence" and getattr(a, f.name) != getattr(b, f.name)]
        if len(a.evidence) != len(b.evidence):
            diff.append("evidence count")
        for k, (ea, eb) in enumerate(zip(a.evidence, b.evidence)):
            diff += [f"node {k} {x}" for x in ("sums", "counts", "sim_power", "meas_power")
                     if not (getattr(ea, x).shape == getattr(eb, x).shape
                             and np.array_equal(getattr(ea, x), getattr(eb, x), equal_nan=True))]
            diff += [f"node {k} {x}" for x in ("sections", "zones", "labels", "groups", "n_pair", "components")
                     if getattr(ea, x) != getattr(eb, x)]
        if diff:
            out[name] = diff
    return out


def _reference_force_gains(req, result, base, sections, limits) -> dict:
    """The ``gain GROUP`` families the straightforward way: per group and node, the group's own
    re-evaluation of the components without a power law (its channels divided by g) and M/g^d
    for the others, record by record."""
    pairs, sim_bands = result
    comps = sorted({(str(r["quantity"]), str(r["position"])) for r in pairs})
    out = {}
    for name, group in force_gain_groups(req.ctx.channels).items():
        deg = {c: d for c in comps if (d := gain_degree(*c, group)) != 0}
        if not deg:
            continue
        other = [c for c, d in deg.items() if d is None]
        evidence = []
        for g in FORCE_GAIN_NODES:
            redo = remapped_measurement(req.measured_sets, req.ctx.sections, lambda _s, ch, _ss, g=g, group=group: {
                c: (x / g if c in group else x) for c, x in ch.items()}, other) if other else {}

            def measured(r, g=g, redo=redo, deg=deg):
                key = (str(r["section"]), str(r["quantity"]), str(r["position"]))
                if key[1:] not in deg:
                    return None
                return redo.get(key) if deg[key[1:]] is None else float(r["M"]) / g ** deg[key[1:]]
            evidence.append(section_evidence(corrected_pairs(pairs, measured, limits), sim_bands, req.meas_bands,
                                             sections, bands=req.ctx.bands, value_key="D_norm", like=base))
        out[f"gain {name}"] = (list(FORCE_GAIN_NODES), evidence)
    return out


def _reference_discrete(req, result, base, sections, limits) -> dict:
    """The evidence of the default sign and swap candidates, each re-evaluated by its own call
    (:func:`signed_measured`, :func:`swapped_measured`) and corrected record by record
    (:func:`discrete_evidence`); the candidates that change nothing left out."""
    pairs, sim_bands = result
    ctx, sets = req.ctx, req.measured_sets
    out = {}
    for ch in sorted(c for c in ctx.channels if c.startswith(("Y_", "Q_"))):
        comps = offset_components(pairs, ch)
        if not sign_blind(ch, comps):
            out[f"sign {ch}"] = discrete_evidence(base, pairs, sim_bands, req.meas_bands, sections,
                                                  signed_measured(sets, ctx.sections, ch, comps), limits,
                                                  bands=ctx.bands)
    wheels = sorted({c.split("_", 1)[1][:-1] for c in ctx.channels if c.startswith(("Y_w", "Q_w"))})
    for a, b in [("b1", "b2")] + [(f"{w}L", f"{w}R") for w in wheels]:
        pp = swap_pairs(a, b, ctx.channels)
        comps = sorted({c for x, y in pp for c in (*offset_components(pairs, x), *offset_components(pairs, y))})
        if pp and comps:
            out[f"swap {a} {b}"] = discrete_evidence(base, pairs, sim_bands, swapped_bands(req.meas_bands, pp), sections,
                                                     swapped_measured(sets, ctx.sections, pp, comps), limits,
                                                     bands=ctx.bands)
    return {k: ev for k, ev in out.items() if not np.array_equal(ev.values(), base.values())}


def _force_gains(req, result, base, sections, limits) -> dict:
    groups = force_gain_groups(req.ctx.channels)
    return dr.force_gain_families(req, result, base, sections, limits, groups, None)


def _discrete(req, result, base, sections, limits) -> dict:
    return discrete_families(req.ctx, req.measured_sets, req.config_sets, True, base, result, req.meas_bands,
                             sections, limits, [], defaults=DISCRETE_DEFAULTS)


def _as_families(got: dict, ref: dict) -> dict:
    """The reference's evidence in the families' shape (values and evidence compared, the texts
    taken from ``got``)."""
    return {n: dataclasses.replace(got[n], values=list(ref[n][0]), evidence=list(ref[n][1])) if n in got else None
            for n in ref}


def test_force_gain_families_equal_each_groups_own_reevaluation_bit_for_bit(campaign):
    """Every ``gain GROUP`` family — 32 groups, 8 nodes — equals its group's own re-evaluation
    corrected record by record, every evidence array bit for bit."""
    got = _force_gains(*campaign)
    ref = _reference_force_gains(*campaign)
    assert len(got) == 32 and set(got) == set(ref)
    assert _mismatches(got, _as_families(got, ref)) == {}


def test_discrete_families_equal_each_candidates_own_reevaluation_bit_for_bit(campaign):
    """The default sign and swap candidates (re-evaluated together, packed into shared signal
    sets) equal each candidate's own re-evaluation through :func:`discrete_evidence`, bit for
    bit, at the candidate's node and at the two tilted outer nodes."""
    got = _discrete(*campaign)
    ref = _reference_discrete(*campaign)
    assert set(got) == set(ref) and any(n.startswith("sign ") for n in got) and any(n.startswith("swap ") for n in got)
    want = {n: dataclasses.replace(got[n], evidence=[dataclasses.replace(ev, sums=ev.sums * f) for f in
                                                     (1.0 + 1e-6, 1.0, 1.0 + 1e-6)])
            for n, ev in ref.items()}
    assert _mismatches(got, want) == {}


def test_a_fault_planted_in_the_packing_is_seen(campaign, monkeypatch):
    """Planted faults: one force group's re-evaluation made with the other wheel's signals
    divided by g (the remaps of the requests of Y_w1L and Y_w1R at the first node exchanged),
    and the sign of Y_w1L re-evaluated with Y_w1R's polarity reversed — the comparisons above
    report exactly the families that read them."""
    from railval.core.diagnosis import measurement

    real = measurement.packed_measurements

    def exchanged(first: int, second: int):
        def packed(sets, secs, requests):
            reqs = list(requests)
            reqs[first], reqs[second] = (reqs[second][0], reqs[first][1]), (reqs[first][0], reqs[second][1])
            return real(sets, secs, reqs)
        return packed

    n = len(FORCE_GAIN_NODES)  # requests: (unit, node), units Y_w1L, Y_w1R, … in order
    monkeypatch.setattr(measurement, "packed_measurements", exchanged(0, n))
    got = _force_gains(*campaign)
    bad = _mismatches(got, _as_families(got, _reference_force_gains(*campaign)))
    assert set(bad) == {"gain Y_w1L", "gain Y_w1R", "gain Y_L", "gain Y_R"}
    assert all(d == ["node 0 sums"] for d in bad.values())

    import railval.app.services.diagnosis_measurement as service

    signs = sorted(c for c in campaign[0].ctx.channels if c.startswith(("Y_", "Q_")))
    monkeypatch.setattr(service, "packed_measurements", exchanged(signs.index("Y_w1L"), signs.index("Y_w1R")))
    got = _discrete(*campaign)
    ref = _reference_discrete(*campaign)
    want = {n: dataclasses.replace(got[n], evidence=[dataclasses.replace(ev, sums=ev.sums * f) for f in
                                                     (1.0 + 1e-6, 1.0, 1.0 + 1e-6)])
            for n, ev in ref.items() if n in got}
    assert set(_mismatches(got, want)) == {"sign Y_w1L", "sign Y_w1R"}
