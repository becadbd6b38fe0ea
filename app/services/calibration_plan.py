"""What a calibration announces and states around its fit (docs/diagnosis.md "Calibration"):
the one estimate of its cost in campaign simulations (:func:`calibration_simulations`, read by
the CLI, the Diagnose page and the job cost cap), where it starts — the user's values or those
the newest stored diagnosis of the parent fitted (:func:`diagnosis_start`) — and the lines the
CLI and the page print on the start and the tolerance reached (:func:`start_text`,
:func:`tolerance_text`), and whether a stored diagnosis supports the candidates (:func:`diagnosis_flags`).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

from railval.core import lazy
from railval.core.calibration import max_evaluations
from railval.core.calibration_local import local_max_evaluations
from railval.core.errors import InvalidParameter

#: deferred (railval.core.lazy): the diagnosis service and the stored runs (the ORM models;
#: 170–450 more modules) only for a plan that reads the newest diagnosis (app/views.py
#: imports this module for two texts)
runs = lazy.module("railval.db.runs")
latest_diagnosis = lazy.function("railval.app.services.diagnosis", "latest_diagnosis")


def calibration_simulations(n_parameters: int, method: str = "local", *, popsize: int = 5, maxiter: int = 5,
                            polish_maxfev: int = 20) -> int:
    """The one estimate of a calibration's cost, in campaign simulations, for the CLI, the
    Diagnose page and the job cost cap: the optimiser's bound — the local fit's
    (:func:`railval.core.calibration_local.local_max_evaluations`: scan, start, trust-region
    stage) or, for ``method="global"``, differential evolution's
    (:func:`railval.core.calibration.max_evaluations` with ``popsize``, ``maxiter``,
    ``polish_maxfev``) — plus the final run that is stored."""
    n = max(1, int(n_parameters))
    if method == "global":
        return max_evaluations(n, popsize, maxiter, polish_maxfev) + 1
    if method != "local":
        raise InvalidParameter(f"calibrate method must be 'local' or 'global', got {method!r}")
    return local_max_evaluations(n) + 1


def diagnosis_start(session: Any, conf: Any, candidates: Sequence[str],
                    given: Mapping[str, Mapping[str, float]]) -> tuple[dict[str, dict[str, float]], dict[str, Any]]:
    """Start values of a calibration: ``given`` (the user's, :func:`_start_values` form) and,
    for every candidate without a given start, the values the newest stored diagnosis of the
    parent ``conf`` that has that candidate fitted (an effect's fitted parameters, a
    ``model.NAME`` candidate's fitted value; docs/diagnosis.md "Calibration"). Returns the
    start values and where they came from: ``{"given": [...], "diagnoses": [{"candidate",
    "diagnosis" (stored run id), "created_at", "values"}], "defaults": [...]}``."""

    out = {k: dict(v) for k, v in given.items()}
    source: dict[str, Any] = {"given": [], "diagnoses": [], "defaults": []}
    rows = None
    for cand in candidates:
        owner, pname = ("model", cand[6:]) if cand.startswith("model.") else (cand, None)
        if (pname in given.get("model", {})) if pname else cand in given:
            source["given"].append(cand)
            continue
        rows = runs.list_runs(session, conf.id, "diagnosis") if rows is None else rows
        found = next(((r, c) for r in rows for c in (r.result or {}).get("candidates") or []
                      if cand in (c.get("effect"), c.get("name"))), None)
        values = {}
        if found is not None:
            c = found[1]
            values = ({pname: float(c["fitted"])} if pname and c.get("fitted") is not None
                      else {k: float(v) for k, v in (c.get("parameters") or {}).items()
                            if v is not None} if not pname else {})
        if not values:
            source["defaults"].append(cand)
            continue
        out.setdefault(owner, {}).update(values)
        row = found[0]
        source["diagnoses"].append({"candidate": cand, "diagnosis": row.id, "values": values,
                                    "created_at": row.created_at.isoformat(timespec="seconds")
                                    if row.created_at else ""})
    return out, source


def start_text(d: Mapping[str, Any]) -> str:
    """One line on where a calibration started (``to_dict()`` of its result): the stored
    diagnosis whose fitted values were the start, the user's values, or the defaults, and
    whether the fit began there or at a better scan point."""
    src = d.get("start_source") or {}
    parts = [f"{x['candidate']} from diagnosis #{x['diagnosis']} of {d.get('parent')}"
             + (f" ({x['created_at']})" if x.get("created_at") else "") + ": "
             + ", ".join(f"{k} = {v:.5g}" for k, v in x["values"].items()) for x in src.get("diagnoses") or []]
    parts += [f"{', '.join(src['given'])} as given"] if src.get("given") else []
    parts += [f"{', '.join(src['defaults'])} at the configuration's values or defaults (no stored diagnosis "
              "has it)"] if src.get("defaults") else []
    began = str(src.get("started_from") or "start")
    where = "the fit began there" if began == "start" else f"the fit began at the {began}"
    return "start: " + "; ".join(parts) + f" — {where}" if parts else ""


def tolerance_text(d: Mapping[str, Any]) -> str:
    """One line on the tolerance the fit reached (``to_dict()`` of a calibration result):
    which criterion stopped it, the tolerances, and the simulations spent against the bound
    announced before it ran (:func:`calibration_simulations`)."""
    tol = d.get("tolerance") or {}
    stopped = tol.get("stopped_by", "?")
    limits = ", ".join(f"{k} {tol[k]:g}" for k in ("ftol", "xtol", "gtol", "tol") if k in tol)
    reached = "converged" if d.get("converged") else "not converged"
    sims = d.get("simulations")
    bound = d.get("simulations_at_most")
    spent = (f"; {sims} campaign simulations" + (f" (at most {bound} announced)" if bound else "")
             if sims is not None else "")
    return f"tolerance: stopped by {stopped} ({limits}), {reached}{spent}"


def diagnosis_flags(session: Any, camp: Any, conf: Any,
                     candidates: Sequence[str]) -> list[str]:
    """Whether the newest stored diagnosis of the parent ``conf`` supports calibrating
    ``candidates`` (effect ids or ``model.NAME``): no flag when its verdict is ``cause`` for one
    of them; a flag when it answered ``none`` or ``uncertain`` or named another cause; a note
    when the parent was never diagnosed (docs/diagnosis.md "Calibration")."""

    campaign, config = camp.name, conf.name
    diag = latest_diagnosis(session, campaign, config)
    names = ", ".join(candidates)
    if diag is None:
        return [(f"note: {config} has no stored diagnosis, so nothing here shows that {names} is the "
                f"cause; run railval diagnose {campaign} --config {config}")]
    d = diag.to_dict()
    verdict = d.get("verdict") or ""
    top = diag.candidates[0].name if diag.candidates else ""  # effect id or model.NAME
    run = d.get("run") or {}
    when = f" of {run['created_at']}" if run.get("created_at") else ""
    stale = " (computed on data that have changed since)" if run.get("current") is False else ""
    if verdict == "cause" and top in candidates:
        return []
    if verdict == "none":
        why = "found no cause beyond the section-to-section scatter (verdict none)"
    elif verdict == "uncertain":
        why = f"could not single out a cause (verdict uncertain, best {top})"
    elif verdict == "cause":
        why = f"named {top}, not {names}, as the cause"
    else:  # a diagnosis stored before verdicts existed
        return []
    return [(f"the diagnosis of {config}{when}{stale} {why}: no diagnostic evidence that {names} is a cause; "
            "the model may be compensating for something else")]
