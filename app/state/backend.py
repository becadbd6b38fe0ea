"""Data access of the web app: one unit of work per call against the database and the
services (docs/design.md §2). Pages and states reach stored data only through :class:`Backend`.
"""

from __future__ import annotations

import threading
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from railval.app.services import calibration as calibration_service
from railval.app.services import diagnosis as diagnosis_service
from railval.app.services import metrics as metrics_service
from railval.app.services import simulation as simulation_service
from railval.app.services import validation as validation_service
from railval.core.errors import NotFound
from railval.core.sim.effects import EFFECTS
from railval.core.types import SectionInfo
from railval.core.validation import MIN_POSITIONS, MIN_SECTIONS, MIN_SECTIONS_PER_ZONE
from railval.db import repo


@dataclass
class ConfigInfo:
    name: str
    parent: str | None
    effects: dict[str, Any] = field(default_factory=dict)
    description: str = ""


@dataclass
class CampaignOverview:
    name: str
    description: str
    vehicle: dict[str, Any]
    sections: list[SectionInfo]
    channels: list[dict[str, str]]
    configurations: list[ConfigInfo]

    def zone_counts(self) -> dict[int, int]:
        counts = {z: 0 for z in (1, 2, 3, 4)}
        for s in self.sections:
            counts[s.zone] = counts.get(s.zone, 0) + 1
        return counts

    def coverage_shortfalls(self, min_sections: int = MIN_SECTIONS,
                            min_per_zone: int = MIN_SECTIONS_PER_ZONE,
                            min_signals: int = MIN_POSITIONS) -> list[str]:
        """Coverage rules of docs/design.md §3 (Polach & Böttcher 2014 §5) checked on the campaign layout alone.

        ≥ ``min_sections`` sections, every zone 1–4 with ≥ ``min_per_zone`` sections and
        ≥ ``min_signals`` channels per channel kind. Returns precise messages, empty when met.
        """
        out = []
        if len(self.sections) < min_sections:
            out.append(f"{len(self.sections)} sections, needs {min_sections}")
        for zone, n in self.zone_counts().items():
            if n < min_per_zone:
                out.append(f"zone {zone} has {n} section{'s' if n != 1 else ''}, needs {min_per_zone}")
        kinds: dict[str, int] = {}
        for ch in self.channels:
            kinds[ch["kind"]] = kinds.get(ch["kind"], 0) + 1
        for kind in ("Y", "Q", "ay_cb", "az_cb"):
            n = kinds.get(kind, 0)
            if n < min_signals:
                out.append(f"channel kind {kind} has {n} signal{'s' if n != 1 else ''}, needs {min_signals}")
        return out

    def children(self) -> dict[str | None, list[str]]:
        tree: dict[str | None, list[str]] = {}
        for c in self.configurations:
            tree.setdefault(c.parent, []).append(c.name)
        return tree


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

    # -- campaign data
    def campaigns(self) -> list[str]:
        with self.session() as s:
            return [c.name for c in repo.list_campaigns(s)]

    def configurations(self, campaign: str) -> list[ConfigInfo]:
        with self.session() as s:
            confs = list(repo.list_configurations(s, campaign))
            names = {c.id: c.name for c in confs}
            return [ConfigInfo(name=c.name, parent=names.get(c.parent_id),
                               effects=dict(c.effects or {}), description=c.description or "")
                    for c in confs]

    def overview(self, campaign: str) -> CampaignOverview:
        with self.session() as s:
            camp = repo.get_campaign(s, campaign)
            sections = list(repo.section_infos(s, camp))
            vehicle = dict(repo.vehicle_info(s, camp))
            chans = [{"name": ch.name, "kind": ch.kind, "position": ch.position, "unit": ch.unit}
                     for ch in repo.channels(s, camp)]
            name, desc = camp.name, camp.description or ""
        return CampaignOverview(name=name, description=desc, vehicle=vehicle, sections=sections,
                                channels=chans, configurations=self.configurations(campaign))

    def signals(self, campaign: str, config: str | None, section: str,
                channels: list[str] | None = None):
        """One section's SignalSet of the measurement (``config`` None) or a configuration."""
        with self.session() as s:
            camp = repo.get_campaign(s, campaign)
            sets = repo.load_signalsets(s, camp, config=config, sections=[section], channels=channels)
        if section not in sets:
            raise NotFound(f"section {section!r} has no recording for "
                           f"{'the measurement' if config is None else 'configuration ' + repr(config)}")
        return sets[section]

    def hashes(self, campaign: str, config: str | None) -> dict[str, dict[str, str]]:
        """section → channel → SHA-256 of the stored samples (no blob read)."""
        with self.session() as s:
            return repo.signal_hashes(s, campaign, config)

    def lineage(self, campaign: str, config: str) -> list[str]:
        """Names from the root configuration down to ``config``."""
        with self.session() as s:
            camp = repo.get_campaign(s, campaign)
            return [c.name for c in repo.lineage(s, camp, config)]

    # -- services
    def validation(self, campaign: str, config: str, refresh: bool = False):
        key = ("validation", campaign, config)
        if refresh:
            with self._lock:
                self._cache.pop(key, None)

        def make():
            with self.session() as s:
                return validation_service.validate_configuration(s, campaign, config)
        return self._cached(key, make)

    def metrics(self, campaign: str, config: str, sections: list[str] | None = None,
                families: list[str] | None = None):
        """DataFrame of ``railval.app.services.metrics.metrics_for_configuration`` (stored in
        the database with its inputs' hashes; cached in memory too)."""

        def make():
            with self.session() as s:
                return metrics_service.metrics_for_configuration(s, campaign, config, sections=sections,
                                                                 families=families)
        return self._cached(("metrics", campaign, config, tuple(sections or ()), tuple(families or ())), make)

    def stored_metrics(self, campaign: str, config: str, sections: list[str] | None = None,
                       families: list[str] | None = None):
        """The stored metrics of these sections with the current data and default settings,
        or None (nothing computed)."""
        with self.session() as s:
            return metrics_service.stored_metrics(s, campaign, config, sections=sections, families=families)

    def metrics_runs(self, campaign: str, config: str) -> list[dict[str, Any]]:
        """Stored metrics runs of the configuration, newest first."""
        with self.session() as s:
            return metrics_service.metrics_runs(s, campaign, config)

    def latest_diagnosis(self, campaign: str, config: str):
        """The newest stored diagnosis of the configuration (DiagnosisResult) or None."""
        with self.session() as s:
            return diagnosis_service.latest_diagnosis(s, campaign, config)

    def diagnosis_runs(self, campaign: str, config: str) -> list[dict[str, Any]]:
        """Stored diagnoses of the configuration, newest first (time, settings, top candidate)."""
        with self.session() as s:
            return diagnosis_service.diagnosis_runs(s, campaign, config)

    def effects(self) -> list[dict[str, Any]]:
        """The effect registry (``railval.core.sim.effects``) as plain dicts for the UI."""
        return [_effect_dict(e) for e in EFFECTS.values()]

    def diagnose(self, campaign: str, config: str, progress: Callable | None = None, **kw: Any):
        """``railval.app.services.diagnosis.diagnose`` → DiagnosisResult (ranked candidates)."""
        return diagnosis_service.diagnose(self.database, campaign, config, progress=_stage_progress(progress), **kw)

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
        store it as ``new_name`` (``railval.app.services.simulation``)."""
        result = simulation_service.simulate_configuration(self.database, campaign, new_name, parent=config, effects=effects,
                    progress=_stage_progress(progress))
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


