"""Stored analysis runs (diagnosis, metrics): results that outlive the browser session.

A run is stored with the SHA-256 of its inputs (:func:`inputs_digest`): the services ask
:func:`latest_run` for a run with the same inputs before computing, so a reload, a second tab
or another user sees the result at once, and a changed input (a re-imported signal, other
settings) computes afresh. Every run is kept; :func:`list_runs` lists them newest first.
"""

from __future__ import annotations

import hashlib
import json
import math
from typing import Any

from sqlalchemy import select
from sqlalchemy.orm import Session

from railval.db.models import AnalysisRun

#: kinds of stored runs (one home: the services and pages use these names)
RUN_KINDS = ("diagnosis", "metrics")


def inputs_digest(inputs: Any) -> str:
    """SHA-256 (hex) of the canonical JSON of ``inputs`` (sorted keys, no whitespace)."""
    text = json.dumps(inputs, sort_keys=True, separators=(",", ":"), default=str,
                      allow_nan=False)
    return hashlib.sha256(text.encode("utf-8")).hexdigest()


def json_safe(value: Any) -> Any:
    """A copy that every JSON column accepts (PostgreSQL rejects NaN): non-finite floats and
    numpy scalars become None/plain numbers, tuples lists."""
    if hasattr(value, "item") and not isinstance(value, (list, tuple, dict)):
        value = value.item()  # numpy scalar
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, dict):
        return {str(k): json_safe(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [json_safe(v) for v in value]
    return value


def _check_kind(kind: str) -> None:
    if kind not in RUN_KINDS:
        raise ValueError(f"run kind {kind!r} is not one of {', '.join(RUN_KINDS)}")


def store_run(session: Session, *, campaign_id: int, configuration_id: int, kind: str,
              inputs_sha256: str, settings: dict[str, Any], result: dict[str, Any],
              seconds: float = 0.0, actor: str = "") -> AnalysisRun:
    """Append one run; returns the stored row (its ``id`` set). Non-finite numbers in
    ``settings``/``result`` are stored as null (:func:`json_safe`)."""
    _check_kind(kind)
    run = AnalysisRun(campaign_id=campaign_id, configuration_id=configuration_id, kind=kind,
                      inputs_sha256=inputs_sha256, settings=json_safe(settings), result=json_safe(result),
                      seconds=float(seconds), actor=actor)
    session.add(run)
    session.flush()
    return run


def latest_run(session: Session, configuration_id: int, kind: str,
               inputs_sha256: str | None = None) -> AnalysisRun | None:
    """Newest run of ``kind`` for the configuration; with ``inputs_sha256`` only a run
    computed from exactly those inputs."""
    _check_kind(kind)
    q = select(AnalysisRun).where(AnalysisRun.configuration_id == configuration_id,
                                  AnalysisRun.kind == kind)
    if inputs_sha256 is not None:
        q = q.where(AnalysisRun.inputs_sha256 == inputs_sha256)
    return session.scalars(q.order_by(AnalysisRun.created_at.desc(), AnalysisRun.id.desc())
                           .limit(1)).first()


def list_runs(session: Session, configuration_id: int, kind: str) -> list[AnalysisRun]:
    """Every run of ``kind`` for the configuration, newest first."""
    _check_kind(kind)
    q = (select(AnalysisRun)
         .where(AnalysisRun.configuration_id == configuration_id, AnalysisRun.kind == kind)
         .order_by(AnalysisRun.created_at.desc(), AnalysisRun.id.desc()))
    return list(session.scalars(q))
