"""Plausibility and separation of candidate causes (docs/diagnosis.md): whether a fitted value
lies in the physically plausible range or at a bound of the search (the model may then be
compensating for something else), and where the signatures of two candidates differ most —
what measurement would tell them apart.

References: plausible ranges cite their source per candidate (railval.core.sim effect and
vehicle-template registries); Polach & Böttcher 2014 §5 (quantities, zones, positions).
"""

from __future__ import annotations

import numpy as np

from railval.core.diagnosis.patterns import Pattern, component_parts
from railval.core.diagnosis.result import TrustedCandidate


def plausibility_flags(name: str, value: float, *, bounds: tuple[float, float] | None,
                       plausible: tuple[float, float] | None, source: str = "", unit: str = "",
                       at_bound: bool | None = None, interval: tuple[float, float] | None = None,
                       kind: str = "effect") -> tuple[bool, list[str]]:
    """(plausible, flags) of a fitted value: outside the physically plausible range, or at a
    bound of the search box, is flagged ("the model may be compensating for something else").
    ``interval``: the value's bootstrap interval, said in the flag (whether it reaches into the
    plausible range); ``kind="parameter"``: a vehicle part outside the range of serviceable
    parts may also be worn or failed — the flag says to check the vehicle."""
    flags: list[str] = []
    ok = True
    if plausible is not None and not (plausible[0] <= value <= plausible[1]):
        ok = False
        spread = ""
        if interval is not None and np.all(np.isfinite(interval)):
            lo, hi = min(interval[0], value), max(interval[1], value)
            reaches = not (hi < plausible[0] or lo > plausible[1])
            spread = (f" (bootstrap interval {lo:.4g}–{hi:.4g} {unit}, "
                      + ("reaching into the range)" if reaches else "entirely outside it)"))
        part = (" — check the vehicle (a worn or failed part) or" if kind == "parameter" else ":")
        flags.append(f"{name} = {value:.4g} {unit} is outside the physically plausible range "
                     f"[{plausible[0]:.4g}, {plausible[1]:.4g}] {unit}"
                     + (f" ({source})" if source else "") + spread
                     + f"{part} the model may be compensating for something else")
    if at_bound is None and bounds is not None:
        span = bounds[1] - bounds[0]
        at_bound = bool(span > 0 and min(abs(value - bounds[0]), abs(bounds[1] - value)) <= 1e-3 * span)
    if at_bound:
        ok = False
        flags.append(f"{name} = {value:.4g} {unit} lies at a bound of the search range "
                     f"[{bounds[0]:.4g}, {bounds[1]:.4g}] {unit}: the model may be compensating for "
                     "something else" if bounds else f"{name} lies at a bound of its search range")
    return ok, flags


_MEASUREMENT = {"Y": "guiding forces Y (instrumented wheelsets)", "Q": "wheel forces Q (instrumented wheelsets)",
                "YQ": "derailment ratio Y/Q (instrumented wheelsets)", "SumY": "track shifting force ΣY",
                "ay": "car body lateral accelerations", "az": "car body vertical accelerations"}


def separating_evidence(a: TrustedCandidate, b: TrustedCandidate, residual: Pattern, n: int = 3) -> tuple[list[dict], str]:
    """The components where the signatures of two candidates differ most (weighted), as
    structured records, and a plain-language advice on what tells them apart."""
    w = residual.weights()
    diff = (a.signature.values - b.signature.values) * w
    out = []
    for k in np.argsort(-np.abs(diff))[:n]:
        parts = component_parts(residual.labels[k], residual.groups[k])
        out.append({"component": residual.labels[k], **parts, a.name: float(a.signature.values[k]),
                    b.name: float(b.signature.values[k]), "residual": float(residual.values[k])})
    if not out:
        return out, ""
    top = out[0]
    if top["band"]:
        kind = top["quantity"].split()[-1]
        where = f"the {top['band']} band of {top['channel']}"
        meas = f"a longer record or more sections with {_MEASUREMENT.get(kind, kind)} ({top['band']})"
    else:
        kind = top["quantity"].split("_")[0]
        where = f"{top['quantity']} in zone {top['zone']} at {top['position']}"
        meas = f"more sections in zone {top['zone']} with {_MEASUREMENT.get(kind, top['quantity'])}"
    advice = (f"{a.name} and {b.name} differ most in {where} ({a.name} {top[a.name]:+.2f}, "
              f"{b.name} {top[b.name]:+.2f}, residual {top['residual']:+.2f}); {meas} would tell them apart")
    return out, advice
