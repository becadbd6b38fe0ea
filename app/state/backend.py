"""Data access of the web app: one unit of work per call against the database and the
services (docs/design.md §2). Pages and states reach stored data only through :class:`Backend`.
"""

from __future__ import annotations

import threading
from collections.abc import Callable
from typing import Any

from railval.app.services import calibration as calibration_service
from railval.app.services import diagnosis as diagnosis_service
from railval.app.services import metrics as metrics_service
from railval.app.services import overview as overview_service
from railval.app.services import simulation as simulation_service
from railval.app.services.overview import CampaignOverview, ConfigInfo
from railval.core.sim.effects import EFFECTS

__all__ = ["Backend", "CampaignOverview", "ConfigInfo"]


class Backend:
    """Every call opens one unit of work on ``database`` (``railval.db.engine.Database``)."""

    def __init__(self, database: Any):
        self.database = database
        self._cache: dict[tuple, Any] = {}
        self._lock = threading.Lock()

    # -- plumbing
    def session(self):
        return self.database.session()

    def invalidate(self) -> None:
        with self._lock:
            self._cache.clear()

    def _cached(self, key: tuple, make: Callable[[], Any]) -> Any:
        with self._lock:
            if key in self._cache:
                return self._cache[key]
        value = make()
        with self._lock:
            self._cache[key] = value
        return value

    # -- campaign data (railval.app.services.overview)
    def campaigns(self) -> list[str]:
        """Campaign names, shared by the sessions of this process while the database's
        catalogue is unchanged (:func:`railval.app.services.overview.shared`)."""
        return overview_service.shared_campaign_names(self.database)

    def configurations(self, campaign: str) -> list[ConfigInfo]:
        return overview_service.configurations(self.database, campaign)

    def overview(self, campaign: str) -> CampaignOverview:
        """The campaign's layout, shared read-only by the sessions of this process while the
        database's catalogue is unchanged (:func:`railval.app.services.overview.shared`)."""
        return overview_service.shared_overview(self.database, campaign)

    def signals(self, campaign: str, config: str | None, section: str,
                channels: list[str] | None = None):
        """One section's SignalSet of the measurement (``config`` None) or a configuration."""
        return overview_service.signals(self.database, campaign, config, section, channels)

    def hashes(self, campaign: str, config: str | None) -> dict[str, dict[str, str]]:
        """section → channel → SHA-256 of the stored samples (no blob read)."""
        return overview_service.hashes(self.database, campaign, config)

    def lineage(self, campaign: str, config: str) -> list[str]:
        """Names from the root configuration down to ``config``."""
        return overview_service.lineage(self.database, campaign, config)

    # -- services
    def validation(self, campaign: str, config: str, refresh: bool = False):
        key = ("validation", campaign, config)
        if refresh:
            with self._lock:
                self._cache.pop(key, None)

        return self._cached(key, lambda: overview_service.validation(self.database, campaign, config))

    def metrics(self, campaign: str, config: str, sections: list[str] | None = None,
                families: list[str] | None = None):
        """DataFrame of ``railval.app.services.metrics.metrics_for_configuration`` (stored in
        the database with its inputs' hashes; cached in memory too)."""

        def make():
            return overview_service.metrics(self.database, campaign, config, sections=sections,
                                            families=families)
        return self._cached(("metrics", campaign, config, tuple(sections or ()), tuple(families or ())), make)

    def stored_metrics(self, campaign: str, config: str, sections: list[str] | None = None,
                       families: list[str] | None = None):
        """The stored metrics of these sections with the current data and default settings,
        or None (nothing computed)."""
        return overview_service.in_session(self.database, metrics_service.stored_metrics, campaign, config,
                                           sections=sections, families=families)

    def metrics_runs(self, campaign: str, config: str) -> list[dict[str, Any]]:
        """Stored metrics runs of the configuration, newest first."""
        return overview_service.in_session(self.database, metrics_service.metrics_runs, campaign, config)

    def latest_diagnosis(self, campaign: str, config: str):
        """The newest stored diagnosis of the configuration (DiagnosisResult) or None."""
        return overview_service.in_session(self.database, diagnosis_service.latest_diagnosis, campaign, config)

    def diagnosis_runs(self, campaign: str, config: str) -> list[dict[str, Any]]:
        """Stored diagnoses of the configuration, newest first (time, settings, top candidate)."""
        return overview_service.in_session(self.database, diagnosis_service.diagnosis_runs, campaign, config)

    def effects(self) -> list[dict[str, Any]]:
        """The effect registry (``railval.core.sim.effects``) as plain dicts for the UI."""
        return [_effect_dict(e) for e in EFFECTS.values()]

    def diagnose(self, campaign: str, config: str, progress: Callable | None = None, **kw: Any):
        """``railval.app.services.diagnosis.diagnose`` → DiagnosisResult (ranked candidates)."""
        return diagnosis_service.diagnose(self.database, campaign, config, progress=_stage_progress(progress), **kw)

    def diagnose_and_list(self, campaign: str, config: str, progress: Callable | None = None, **kw: Any):
        """(DiagnosisResult, the stored diagnoses of the configuration): the names resolved
        once for both (``railval.app.services.diagnosis.diagnose_and_list``)."""
        return diagnosis_service.diagnose_and_list(self.database, campaign, config,
                                                   progress=_stage_progress(progress), **kw)

    def calibrate(self, campaign: str, config: str, effect: str, new_name: str,
                  progress: Callable | None = None, start: dict | None = None, **kw: Any):
        """Add ``effect``, fit its parameters (differential evolution + polish, starting from
        ``start``), store ``new_name`` with parent ``config``; returns the CalibrationResult."""
        result = calibration_service.calibrate(self.database, campaign, config, [effect], new_name,
                               progress=_stage_progress(progress),
                               start={effect: dict(start)} if start else None, **kw)
        self.invalidate()
        return result

    def simulate(self, campaign: str, config: str, effects: dict[str, dict], new_name: str,
                 progress: Callable | None = None):
        """Re-simulate ``config`` plus ``effects`` with the given parameters (no fit) and
        store it as ``new_name`` (``railval.app.services.simulation``). Values the newest
        diagnosis of ``config`` fitted (on every section) are recorded as such, so the new
        configuration's verdict is labelled in-sample
        (``railval.app.services.diagnosis.diagnosis_fit_record``)."""
        record = None
        for effect, values in effects.items():
            record = record or diagnosis_service.diagnosis_fit_record(self.database, campaign, config, effect,
                                                                      dict(values or {}))
        result = simulation_service.simulate_configuration(self.database, campaign, new_name, parent=config, effects=effects,
                    progress=_stage_progress(progress), calibration=record)
        self.invalidate()
        return result


def _stage_progress(progress: Callable | None) -> Callable | None:
    """Adapt a ``progress(fraction, message)`` to the services' ``progress(stage, fraction, info)``."""
    if progress is None:
        return None

    def cb(stage: str, fraction: float, info: dict | None = None) -> None:
        extra = ""
        if info and "done" in info and "total" in info:
            extra = f" {info['done']}/{info['total']}"
        progress(fraction, f"{stage}{extra}")
    return cb


def _effect_dict(effect: Any) -> dict[str, Any]:
    """An entry of ``railval.core.sim.effects.EFFECTS`` as a plain dict for the views."""
    return {
        "name": effect.id,
        "title": effect.title,
        "explanation": effect.explanation,
        "quantities": list(effect.quantities),
        "parameters": [{"name": p.name, "unit": p.unit, "default": p.default,
                        "bounds": (p.lower, p.upper), "doc": p.description}
                       for p in effect.parameters.values()],
    }


