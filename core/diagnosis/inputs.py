"""Input-side statements (docs/diagnosis.md "Track input" and "Contact geometry"): when what
explains the residual is an input of the simulation rather than the vehicle, the diagnosis says
which input differs and what data would replace the assumption, instead of naming a vehicle
parameter or an effect value as the cause.

* **Track input.** A campaign without measured track geometry is simulated on irregularities
  generated from the ORE B176 low-level spectrum (ERRI B176 RP1 1989). Their level per
  direction is a candidate (effects ``track_level_vertical`` / ``track_level_lateral``,
  :mod:`railval.core.sim.effects`). When a track-level candidate explains the residual — it is
  significant and its held-out share is within ``ALIKE_MARGIN`` of the best candidate's, or it is
  the best — the statement is "the track input differs: supply measured track geometry"; the
  stochastic quantities (r.m.s. and maxima of accelerations, dynamic forces) that a damper, a
  stiffness or the track level all move cannot then name a vehicle parameter as ``cause``: the
  verdict is at most ``uncertain`` unless the best is the track input itself, and the cause set
  holds only the track input and measurement candidates (a vehicle value fitted on a wrong
  input absorbs the input's error).
* **Contact geometry.** The equivalent conicity (EN 15302) summarises a wheel–rail profile pair
  by one number at one amplitude; a real or worn pair has a rolling-radius difference that is
  not linear in the lateral displacement. When the best candidate is ``conicity`` and its fit
  sits at a bound of the search range, outside the plausible range, or leaves a residual
  beyond the section scatter (it explains only part), the statement is "the contact geometry
  differs: supply measured wheel and rail profiles (or their rolling-radius difference)" and
  the verdict is at most ``uncertain``. A conicity that explains everything gets the same
  statement and verdict: a profile difference is never answered by a single conicity as the
  ``cause`` (one conicity stands for a profile pair at one amplitude only; issue 40); under a
  ``none`` verdict a significant conicity on top gets the statement as a note; so does an
  interface candidate on top that is not the ``cause`` (a friction, track stiffness or
  primary guidance stiffness supported by the guiding forces only) when a significant conicity
  explains alike (held-out within ``ALIKE_MARGIN``): the guiding forces cannot tell them from a
  contact difference, the verdict stays. A
  configuration that carries measured profiles (a Δr(y) table) has no conicity candidate
  (``app/services/diagnosis_ranking.py``, ``profile_skipped``).

Section scatter: the 95th percentile of the weighted norm² of the bootstrap deviation of the
residual (Efron & Tibshirani 1993 §8.2, zone-stratified resamples as in
:mod:`railval.core.diagnosis.engine`), times n/(n − 1) with n the fewest sections of a zone —
the plug-in (bootstrap) variance of a mean is (n − 1)/n times the unbiased one (Efron &
Tibshirani 1993 ch. 5, the plug-in estimate of a standard error). "Explains only part": what
the candidate leaves is beyond that level and its held-out share is below :data:`FULL`
(0.9, an assumption of this rule: a candidate that explains less than nine tenths of a
residual the sections agree on is no complete answer).
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from typing import Any

import numpy as np

from railval.core.diagnosis.engine import ALIKE_MARGIN
from railval.core.diagnosis.evidence import SectionEvidence, zone_bootstrap
from railval.core.diagnosis.result import DiagnosisResult, TrustedCandidate

#: the contact-geometry candidates (effects of :mod:`railval.core.sim.effects`)
CONTACT_CANDIDATES = frozenset({"conicity"})
TRACK_TEXT = "the track input differs: supply measured track geometry"
#: held-out share below which a candidate whose remainder is beyond the scatter "explains only part"
FULL = 0.9
CONTACT_TEXT = ("the contact geometry differs: supply measured wheel and rail profiles "
                "(or their rolling-radius difference)")


def scatter_level(base: SectionEvidence, n_boot: int = 100, seed: int = 0) -> float:
    """95th percentile of ‖w·(r_b − r)‖² over zone-stratified bootstrap resamples b (module
    docstring): a remaining residual below it is section scatter."""
    if n_boot <= 0:
        return 0.0
    r = base.values()
    w = base.pattern().weights()
    R = base.values(zone_bootstrap(base.zones, n_boot, seed))
    n = min(int(np.sum(np.asarray(base.zones) == z)) for z in set(base.zones))
    return float(np.percentile(np.sum(((R - r[None, :]) * w) ** 2, axis=1), 95)) * (n / (n - 1) if n > 1 else 1.0)


def track_explains(res: DiagnosisResult, track: Iterable[str]) -> list[TrustedCandidate]:
    """The track-level candidates that explain the residual (module docstring), best first."""
    names = set(track)
    cands = [c for c in res.candidates if c.name in names and c.significant]
    if not cands or not res.candidates:
        return []
    best = res.candidates[0]
    return [c for c in cands if c is best or c.held_out_explained >= best.held_out_explained - ALIKE_MARGIN]


def _fixed(c: TrustedCandidate) -> str:
    return f"; it fixes {', '.join(c.fixes)}" if c.fixes else ""


def track_statement(res: DiagnosisResult, track: Iterable[str]) -> dict[str, Any] | None:
    """Apply the track-input rule to ``res`` (verdict and note); the statement or None."""
    found = track_explains(res, track) if res.verdict != "none" else []
    if not found:
        return None
    levels = "; ".join(f"{c.name.removeprefix('track_level_')} level ≈ {c.fitted:.2f} × the ORE B176 low level "
                       f"explains {c.held_out_explained:.2f} held-out{_fixed(c)}" for c in found)
    text = f"{TRACK_TEXT} (generated irregularities: {levels})"
    best = res.candidates[0]
    if res.verdict == "cause" and best.name not in {c.name for c in found}:
        res.verdict = "uncertain"
        res.note = (f"uncertain: {text} — {best.name} is not named as the cause while the simulated track is "
                    "generated, not measured")
    elif best.name in {c.name for c in found}:
        res.note = (res.note + "; " if res.note else "") + text
    return {"kind": "track input", "candidates": [c.name for c in found], "text": text}


def _contact_alike(res: DiagnosisResult, interface: Iterable[str]) -> dict[str, Any] | None:
    """The statement when an interface candidate that is not the ``cause`` leads and a
    significant conicity explains alike (within ``ALIKE_MARGIN`` held-out): the guiding forces
    cannot tell that candidate from a contact difference (module docstring)."""
    best = res.candidates[0]
    cone = next((c for c in res.candidates if c.name in CONTACT_CANDIDATES), None)
    if (res.verdict == "cause" or best.name not in set(interface) or cone is None or not cone.significant
            or cone.held_out_explained < best.held_out_explained - ALIKE_MARGIN):
        return None
    text = (f"{CONTACT_TEXT}: {best.name} ({best.held_out_explained:.2f} held-out) and the equivalent conicity "
            f"{cone.fitted:.3g} ({cone.held_out_explained:.2f}) explain alike, and one conicity stands for a profile "
            "pair at one amplitude only (EN 15302)")
    res.note = (res.note + "; " if res.note else "") + text
    return {"kind": "contact geometry", "candidates": [cone.name, best.name], "text": text}


def contact_statement(res: DiagnosisResult, base: SectionEvidence, scatter: float,
                      covered: bool = False, interface: Iterable[str] = ()) -> dict[str, Any] | None:
    """Apply the contact-geometry rule to ``res`` (verdict and note); the statement or None
    (None when the best candidate is no contact candidate, or the verdict is ``none`` and the
    conicity is not significant; a significant conicity under a ``none`` verdict — the
    configuration passes and it explains less than half — gets the statement, the verdict stays).
    ``covered``: the conicity is in a cause set that leaves only section scatter (the rest is
    explained by the set's other causes, so the conicity does not explain "only part").
    ``interface``: the interface candidates; one of them on top, not the ``cause``, with a
    significant conicity alike gets the statement too (:func:`_contact_alike`)."""
    if not res.candidates:
        return None
    if res.candidates[0].name not in CONTACT_CANDIDATES:
        return _contact_alike(res, interface)
    c = res.candidates[0]
    if res.verdict == "none" and not c.significant:
        return None
    w = base.pattern().weights()
    left = float(np.sum((w * c.remaining(res.residual)) ** 2))
    why = ("its fit lies at a bound of the search range" if c.at_bound else
           "its fitted value is outside the plausible range" if not c.plausible else
           f"it explains only part of the residual ({c.held_out_explained:.2f} held-out; what remains is beyond "
           "the section scatter)" if left > scatter and c.held_out_explained < FULL and not covered else
           f"it explains {c.held_out_explained:.2f} held-out, but one conicity stands for a profile pair at one "
           "amplitude only (EN 15302); measured profiles decide")
    text = f"{CONTACT_TEXT}: the best equivalent conicity {c.fitted:.3g} is no answer — {why}"
    if res.verdict == "cause":
        res.verdict = "uncertain"
        res.note = "uncertain: " + text
    else:
        res.note = (res.note + "; " if res.note else "") + text
    return {"kind": "contact geometry", "candidates": [c.name], "text": text}


def track_first_pool(pool: Sequence[Any], res: DiagnosisResult, track: Iterable[str]) -> tuple[list, list[dict]]:
    """With the track-input statement, the cause set's pool: the track-level and measurement
    candidates; the others left out with the reason (module docstring)."""
    found = {c.name for c in track_explains(res, track)}
    if not found:
        return list(pool), []
    keep = [f for f in pool if f.name in found or f.kind == "measurement"]
    out = [{"name": f.name, "reason": f"{TRACK_TEXT}: a vehicle value fitted on a generated track absorbs the "
            "input's error"} for f in pool if f not in keep]
    return keep, out
