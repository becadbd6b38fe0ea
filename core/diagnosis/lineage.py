"""What is left after a calibration: the diagnosis of a calibrated configuration read against the
diagnosis of its parent (docs/diagnosis.md "Lineage").

A configuration made by ``railval calibrate … --effect E`` from a diagnosed parent carries the
names of the parameters it fitted (``Configuration.calibration["parameters"]``). Its own
diagnosis then answers: how much of the parent's residual is left (``remaining_share``, the
ratio of the squared residual norms ‖r_child‖² / ‖r_parent‖², the same measure as a
candidate's "explained" share 1 − ‖r − s‖² / ‖r‖², docs/diagnosis.md "Ranking"), what the
parent's diagnosis expected to be left (1 − the explained share of the calibrated cause), and
whether the rest is within the section scatter, explained by a candidate of the library, or
beyond what the library can fix. Pure: the service reads the stored runs and passes plain dicts.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

__all__ = ["LINEAGE_STATUSES", "ancestor_entry", "lineage_statement", "remaining_share"]

#: what the remainder after a calibration is: within the section scatter, explained by a
#: candidate (verdict ``cause``), possibly explained (``uncertain``), or beyond the library
LINEAGE_STATUSES = ("within scatter", "explained", "uncertain", "beyond library")


def _norm2(result: Mapping[str, Any]) -> float | None:
    res = result.get("residual") or {}
    n = res.get("norm")
    if n is None or not math.isfinite(float(n)):
        return None
    return float(n) ** 2


def remaining_share(child: Mapping[str, Any], parent: Mapping[str, Any]) -> float | None:
    """‖r_child‖² / ‖r_parent‖² over the quantity components both residuals share (the stored
    residual ``labels``/``values``), else the ratio of the stored norms; None when the parent's
    residual is zero or unknown."""
    c_res, p_res = child.get("residual") or {}, parent.get("residual") or {}
    cl, pl = c_res.get("labels"), p_res.get("labels")
    if cl and pl and c_res.get("values") is not None and p_res.get("values") is not None:
        cv = {tuple(k) if isinstance(k, list) else k: v for k, v in zip(cl, c_res["values"])}
        pv = {tuple(k) if isinstance(k, list) else k: v for k, v in zip(pl, p_res["values"])}
        common = [k for k in pv if k in cv and cv[k] is not None and pv[k] is not None]
        if common:
            den = sum(float(pv[k]) ** 2 for k in common)
            return sum(float(cv[k]) ** 2 for k in common) / den if den > 0 else None
    c2, p2 = _norm2(child), _norm2(parent)
    if c2 is None or not p2:
        return None
    return c2 / p2


def _top(result: Mapping[str, Any]) -> dict[str, Any] | None:
    cands = result.get("candidates") or []
    return cands[0] if cands else None


def ancestor_entry(configuration: str, run_id: int | None, result: Mapping[str, Any] | None,
                   created_at: str = "") -> dict[str, Any]:
    """One line of the lineage of diagnoses: the configuration, its diagnosis run (None: never
    diagnosed), the verdict, the top candidate and the share it explains on held-out sections."""
    if result is None:
        return {"configuration": configuration, "diagnosis": None, "verdict": None, "top": None,
                "held_out_explained": None, "created_at": created_at}
    top = _top(result)
    return {"configuration": configuration, "diagnosis": run_id, "verdict": result.get("verdict"),
            "top": (top.get("name") or top.get("effect")) if top else None,
            "held_out_explained": top.get("held_out_explained") if top else None, "created_at": created_at}


def _calibrated_candidate(parent: Mapping[str, Any], fitted: Sequence[str]) -> dict[str, Any] | None:
    """The parent's candidate that the calibration fitted (``model.NAME`` or ``effect.param``)."""
    owners = {p if p.startswith("model.") else p.split(".", 1)[0] for p in fitted}
    for c in parent.get("candidates") or []:
        if (c.get("name") or c.get("effect")) in owners or c.get("effect") in owners:
            return c
    return None


def lineage_statement(child: Mapping[str, Any], parent: Mapping[str, Any] | None, *, parent_configuration: str,
                      parent_run: int | None, fitted: Sequence[str],
                      fitted_values: Mapping[str, float] | None = None) -> dict[str, Any]:
    """The ``lineage`` statement of a diagnosis of a calibrated configuration.

    ``child``/``parent``: the diagnoses as dicts (:meth:`DiagnosisResult.to_dict`; ``parent``
    None when the parent was never diagnosed); ``fitted``: the calibrated parameter names
    (``Configuration.calibration["parameters"]``); ``fitted_values``: their values in the child.
    ``status`` is one of :data:`LINEAGE_STATUSES`: ``within scatter`` when the child's verdict
    is ``none`` because its residual is within the section scatter or no candidate exceeds the
    noise floor while the remainder is at most the share the parent's diagnosis left
    unexplained (plus the noise floor); ``explained``/``uncertain`` when the child's diagnosis
    names a cause; otherwise ``beyond library``."""
    owners = sorted({p if p.startswith("model.") else p.split(".", 1)[0] for p in fitted})
    out: dict[str, Any] = {"parent_configuration": parent_configuration, "parent_diagnosis": parent_run,
                           "calibrated": owners, "fitted_parameters": dict(fitted_values or {}),
                           "remaining_share": None, "expected_remaining": None, "status": None,
                           "candidate": None, "text": ""}
    what = ", ".join(owners) or "parameters"
    if parent is None:
        out["text"] = (f"after calibrating {what}: the parent configuration {parent_configuration} "
                       "has no stored diagnosis, so the remaining share is unknown")
        return out
    share = remaining_share(child, parent)
    cand = _calibrated_candidate(parent, fitted)
    expected = (1.0 - float(cand["held_out_explained"])) if cand and cand.get("held_out_explained") is not None \
        else None
    out.update({"remaining_share": share, "expected_remaining": expected})
    verdict, top = child.get("verdict"), _top(child)
    floor = float(child.get("noise_floor") or 0.0)
    if verdict in ("cause", "uncertain") and top is not None:
        name = top.get("name") or top.get("effect")
        out.update({"status": "explained" if verdict == "cause" else "uncertain", "candidate": name})
        rest = (f"it is explained by {name} ({float(top.get('held_out_explained') or 0):.2f} on held-out sections)"
                if verdict == "cause" else f"it may be explained by {name} (uncertain: {child.get('note', '')})")
    elif child.get("residual_within_noise") or (share is not None and expected is not None
                                                 and share <= expected + floor):
        out["status"] = "within scatter"
        rest = "it is within the section scatter: nothing in the library explains more"
    else:
        out["status"] = "beyond library"
        rest = "nothing in the library explains it (the remainder is beyond what the library can fix)"
    share_txt = f"{share:.2f}" if share is not None else "an unknown share"
    exp_txt = f"; the parent's diagnosis left {expected:.2f} unexplained" if expected is not None else ""
    out["text"] = (f"after calibrating {what} (parent {parent_configuration}, diagnosis #{parent_run}), "
                   f"the remaining residual is {share_txt} of the parent's{exp_txt}; {rest}")
    return out
