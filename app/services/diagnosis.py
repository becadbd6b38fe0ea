"""Service: rank the effects missing from a configuration and the vehicle-template
parameters that may be mis-set by the share of its residual they explain on held-out
sections (docs/design.md §7, docs/diagnosis.md, :mod:`railval.core.diagnosis`); the
simulations and the scoring are in :mod:`railval.app.services.diagnosis_evidence`.

The Panel app calls :func:`diagnose` from a background thread with a ``progress(stage,
fraction, info)`` callback; the CLI prints the same callbacks on stderr. The simulations of
the campaign for many candidate effect values run through
:class:`railval.app.services.batch.BatchExecutor` (local process pool, or Dask with
``scheduler="tcp://…"``). Calibration is in :mod:`railval.app.services.calibration`, the
modal identification of [ref 3] in :mod:`railval.app.services.modal`.
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from typing import Any

from railval.app.services.campaign_context import Progress
from railval.app.services.diagnosis_evidence import diagnose as diagnose_evidence_service
from railval.app.services.diagnosis_evidence import scan_points
from railval.core.diagnosis import PARAMETER_CANDIDATES, DiagnosisResult
from railval.core.sim.effects import EFFECTS

__all__ = ["diagnose", "diagnosis_simulations", "scan_points"]


def diagnosis_simulations(effects: Sequence[str], values_per_parameter: int = 3,
                          template: str | None = None, parameters: bool | int = True, refine: int = 3) -> int:
    """How many campaign simulations :func:`diagnose` runs for ``effects`` (the configuration
    itself once, plus every distinct scan point of the effects that apply to the vehicle
    ``template``, plus one per template parameter candidate (``parameters``: all of the
    template's, or that many) and at most ``refine`` refinements): shown before a user starts it."""
    n_par = len(PARAMETER_CANDIDATES.get(template or "coach", {})) if parameters is True else int(parameters)
    n = 1 + (n_par + min(refine, n_par) if n_par else 0)
    for e in effects:
        if template and template not in EFFECTS[e].templates:
            continue
        n += len({json.dumps(point, sort_keys=True)
                  for _, _, point, _ in scan_points(EFFECTS[e], values_per_parameter)})
    return n


def diagnose(database_or_session: Any, campaign: str, config: str, *, progress: Progress | None = None,
             scheduler: Any = None, values_per_parameter: int = 3, effects: Sequence[str] | None = None,
             workers: int | None = None, **options: Any) -> DiagnosisResult:
    """Rank the causes of the residual of configuration ``config``: the effects it lacks and
    the vehicle-template parameters that may be mis-set, by the share of the residual they
    explain on held-out sections, with noise floor, plausibility, identifiability and a
    verdict (:func:`railval.app.services.diagnosis_evidence.diagnose`). ``effects``: candidate
    names — effect ids and ``model.NAME`` parameters; given without any ``model.`` name, only
    those effects are tried."""
    if effects is not None:
        names = list(effects)
        params = [n for n in names if n.startswith("model.")]
        options.setdefault("parameters", params or None)
        options.setdefault("include_parameters", bool(params))
        effects = [n for n in names if not n.startswith("model.")]
    return diagnose_evidence_service(database_or_session, campaign, config, progress=progress, scheduler=scheduler,
                                     values_per_parameter=values_per_parameter, effects=effects, workers=workers,
                                     **options)
