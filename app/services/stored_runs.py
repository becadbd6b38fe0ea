"""Inputs of a diagnosis or metrics run and its stored record (``railval.db.runs``).

A run is found again by the SHA-256 of everything its result depends on: the content hashes
of the measured and simulated signals it reads (``railval.db.repo.signal_hashes``, no blob
read), the section records, the configuration's effects and parameters, the run's settings
and the processing version. The services (:mod:`railval.app.services.diagnosis`,
:mod:`railval.app.services.metrics`) return a stored run with the same digest instead of
recomputing and store every run they compute; the pages show the latest stored run on every
new session and list the earlier ones.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from typing import Any

from railval.db import repo, runs


def _plain(value: Any) -> Any:
    """JSON-safe copy for hashing: non-finite floats as their text (``inf`` radius = straight)."""
    if isinstance(value, float) and not math.isfinite(value):
        return repr(value)
    if isinstance(value, dict):
        return {str(k): _plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    return value


def data_inputs(session: Any, campaign: repo.CampaignArg, config: repo.ConfigArg,
                sections: Sequence[str] | None = None,
                channels: Sequence[str] | None = None) -> dict[str, Any]:
    """What a run of ``config`` reads from the database: signal content hashes of the
    measurement and of the configuration (restricted to ``sections``/``channels`` when
    given), the section records and the configuration's effects and parameters.
    ``campaign``/``config``: the references of :func:`railval.db.repo.resolve` (or names,
    resolved here once)."""
    keep_s = set(sections) if sections is not None else None
    keep_c = set(channels) if channels is not None else None

    def cut(h: dict[str, dict[str, str]]) -> dict[str, dict[str, str]]:
        return {sid: {c: v for c, v in chans.items() if keep_c is None or c in keep_c}
                for sid, chans in h.items() if keep_s is None or sid in keep_s}

    campaign, config = repo.resolve(session, campaign, config)
    conf = repo.get_configuration(session, campaign, config)
    infos = [dataclasses.asdict(s) for s in repo.section_infos(session, campaign)
             if keep_s is None or s.id in keep_s]
    return _plain({"measured": cut(repo.signal_hashes(session, campaign, None)),
                   "simulated": cut(repo.signal_hashes(session, campaign, config)),
                   "sections": infos, "effects": dict(conf.effects or {}),
                   "parameters": dict(conf.parameters or {})})


def digests(data: dict[str, Any], settings: dict[str, Any], version: str) -> tuple[str, str]:
    """(digest of the data alone, digest of data + settings + version): the first tells a
    stored run whose data changed since (stale), the second finds a run to reuse."""
    data_sha = runs.inputs_digest(data)
    return data_sha, runs.inputs_digest({"data": data_sha, "settings": _plain(settings), "version": version})


def run_info(run: Any, reused: bool, current_data_sha256: str | None = None) -> dict[str, Any]:
    """What the pages show about a stored run: id, time (ISO, UTC), seconds it took, its
    settings, whether it was reused, and whether its data still match the database."""
    settings = dict(run.settings or {})
    info = {"id": run.id, "created_at": run.created_at.isoformat(timespec="seconds") if run.created_at else "",
            "seconds": float(run.seconds or 0.0), "settings": settings, "reused": bool(reused)}
    if current_data_sha256 is not None:
        info["current"] = settings.get("data_sha256") == current_data_sha256
    return info
