"""Service: car body modes identified from the measured accelerations (SSI-COV,
:func:`railval.core.modal.ssi_cov`) and the coach modal parameters fitted to them ([ref 3],
:func:`railval.core.calibration.calibrate_modal`).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from railval.app.services.campaign_context import Progress, report, session_of
from railval.core.calibration import (
    COACH_MODAL_PARAMETERS,
    ParameterSpec,
    calibrate_modal,
    coach_modal_base,
)
from railval.core.errors import InvalidParameter, NotFound
from railval.core.modal import decimated_records, ssi_cov
from railval.db import repo


def identify_modes(database_or_session: Any, campaign: repo.CampaignArg, *, sections: Sequence[str] | None = None,
                   config: str | None = None, channels: Sequence[str] = ("az_cb_b1", "az_cb_b2"),
                   fs_target: float = 20.0, f_min: float = 0.5, f_max: float = 4.0):
    """SSI-COV modes of the car body from the accelerations of the measurement (or of a
    configuration) over the chosen sections (all by default; covariances averaged over the
    sections). Signals are decimated to about ``fs_target`` Hz with an anti-alias FIR
    (``scipy.signal.resample_poly``)."""
    with session_of(database_or_session) as s:
        camp, conf = repo.resolve(s, campaign, config)
        sets = repo.load_signalsets(s, camp, conf, sections=list(sections) if sections else None,
                                    channels=list(channels))
    records, fs_used = decimated_records(sets.values(), channels, fs_target)
    if not records:
        raise NotFound(f"campaign {camp.name!r}: no recordings with channels {list(channels)}")
    return ssi_cov(records, fs_used, channels=list(channels), f_min=f_min, f_max=f_max)


def modal(database_or_session: Any, campaign: str, *, sections: Sequence[str] | None = None,
          calibrate_params: Sequence[str] | None = None, progress: Progress | None = None,
          n_modes: int = 2) -> dict[str, Any]:
    """Identify the car body modes and, with ``calibrate_params``, fit those coach modal
    parameters (:data:`railval.core.calibration.COACH_MODAL_PARAMETERS`) to the ``n_modes`` best
    supported modes ([ref 3]). Returns a JSON-ready dict with ``modes`` and ``calibration``
    (the before/after frequency error table). The campaign is resolved once here."""
    report(progress, "identify", 0.0)
    with session_of(database_or_session) as s:
        camp, _ = repo.resolve(s, campaign)
    ident = identify_modes(database_or_session, camp, sections=sections)
    out: dict[str, Any] = {"campaign": campaign, "identification": ident.to_dict(),
                           "stabilisation": ident.stabilisation_diagram()}
    if calibrate_params:
        unknown = [p for p in calibrate_params if p not in COACH_MODAL_PARAMETERS]
        if unknown:
            raise InvalidParameter(f"unknown modal parameter(s) {unknown}; known: {sorted(COACH_MODAL_PARAMETERS)}")
        with session_of(database_or_session) as s:
            vinfo = repo.vehicle_info(s, camp)
        if (vinfo.get("template") or "coach") != "coach":
            raise InvalidParameter(
                f"modal calibration models the coach template; campaign {camp.name!r} uses "
                f"template {vinfo.get('template')!r} (identification alone works for any vehicle)")
        vparams = vinfo["parameters"]
        base = coach_modal_base(vparams)
        best = sorted(ident.modes, key=lambda m: -m.n_stable)[:n_modes]
        best.sort(key=lambda m: m.freq_hz)
        if len(best) < 1:
            raise NotFound(f"campaign {camp.name!r}: no stable mode identified between 0.5 and 4 Hz")
        specs = [ParameterSpec(p, *COACH_MODAL_PARAMETERS[p]) for p in calibrate_params]
        res = calibrate_modal([m.freq_hz for m in best], np.column_stack([m.shape for m in best]), specs,
                              base=base, progress=progress)
        out["calibration"] = res.to_dict()
    report(progress, "done", 1.0)
    return out
