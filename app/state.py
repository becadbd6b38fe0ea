"""UI state of the engineers' web app, apart from any view (docs/design.md §2).

Nothing here imports Panel: every class is a :class:`param.Parameterized` that a test can
drive without a browser. Pages (``app/pages/*.py``) are thin views bound to these states.

::

    Backend            one unit of work per call against db + app.services; says plainly
                       when a service is not installed ("not available: ...")
    AppState           campaign, configuration, section, channel, page, status area
    CompareState       configurations × view (time/distance/PSD) × processing for one
                       section/channel → CompareData (arrays + axis labels + evaluated range)
    DashboardState     validation of the selected configuration, selected quantity →
                       drill-down rows; open_pair() jumps to Compare
    MetricsState       metric tables (raw and synchronised)
    DiagnoseState      ranked candidates, chosen effect, calibrate/re-simulate job in a
                       background thread with progress, lineage of the error
    ReportState        HTML/PDF of a configuration's validation

Long work runs through :meth:`AppState.run_job`: a thread calls the work function with a
``progress(fraction, message)`` callback; every state change is handed to ``dispatch`` (the
view passes one that schedules on the Bokeh document's event loop; tests pass the default,
which calls directly). Errors land in ``AppState.status`` with level ``"error"``.
"""

from __future__ import annotations

import importlib
import math
import threading
import traceback
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import param

from railval.core.errors import NotFound, RailvalError
from railval.core.types import CHANNEL_KINDS, SectionInfo, split_channel

PAGES = ("overview", "compare", "dashboard", "metrics", "diagnose", "report")
PAGE_TITLES = {
    "overview": "Campaign overview",
    "compare": "Compare signals",
    "dashboard": "Validation dashboard",
    "metrics": "Curve metrics",
    "diagnose": "Diagnose & model workshop",
    "report": "Report",
}
MEASURED = "measurement"

#: channel kind → (EN processing filter kind of core.filters, human label)
EN_FILTER_OF_KIND = {
    "Y": ("lowpass", "low-pass 20 Hz"),
    "Q": ("lowpass", "low-pass 20 Hz"),
    "ay_cb": ("bandpass", "band-pass 0.4–10 Hz"),
    "az_cb": ("bandpass", "band-pass 0.4–10 Hz"),
    "ay_bg": ("lowpass", "low-pass 20 Hz"),
    "az_bg": ("lowpass", "low-pass 20 Hz"),
}


def service(name: str):
    """Import ``railval.app.services.<name>`` or raise :class:`ServiceUnavailable` naming it."""
    try:
        return importlib.import_module(f"railval.app.services.{name}")
    except ImportError as exc:
        raise ServiceUnavailable(f"not available: app.services.{name} ({exc})") from exc


class ServiceUnavailable(RailvalError):
    """A part of railval this page needs is not installed in this build."""


# ----------------------------------------------------------------------------- backend
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

    def coverage_shortfalls(self, min_sections: int = 12, min_per_zone: int = 3,
                            min_signals: int = 2) -> list[str]:
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
    @staticmethod
    def repo():
        return importlib.import_module(f"railval.db.repo")

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
        repo = self.repo()
        with self.session() as s:
            return [c.name for c in repo.list_campaigns(s)]

    def configurations(self, campaign: str) -> list[ConfigInfo]:
        repo = self.repo()
        with self.session() as s:
            confs = list(repo.list_configurations(s, campaign))
            names = {c.id: c.name for c in confs}
            return [ConfigInfo(name=c.name, parent=names.get(c.parent_id),
                               effects=dict(c.effects or {}), description=c.description or "")
                    for c in confs]

    def overview(self, campaign: str) -> CampaignOverview:
        repo = self.repo()
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
        repo = self.repo()
        with self.session() as s:
            camp = repo.get_campaign(s, campaign)
            sets = repo.load_signalsets(s, camp, config=config, sections=[section], channels=channels)
        if section not in sets:
            raise NotFound(f"section {section!r} has no recording for "
                           f"{'the measurement' if config is None else 'configuration ' + repr(config)}")
        return sets[section]

    def hashes(self, campaign: str, config: str | None) -> dict[str, dict[str, str]]:
        """section → channel → SHA-256 of the stored samples (no blob read)."""
        repo = self.repo()
        with self.session() as s:
            return repo.signal_hashes(s, campaign, config)

    def lineage(self, campaign: str, config: str) -> list[str]:
        """Names from the root configuration down to ``config``."""
        repo = self.repo()
        with self.session() as s:
            camp = repo.get_campaign(s, campaign)
            return [c.name for c in repo.lineage(s, camp, config)]

    # -- services
    def validation(self, campaign: str, config: str, refresh: bool = False):
        mod = service("validation")
        key = ("validation", campaign, config)
        if refresh:
            with self._lock:
                self._cache.pop(key, None)

        def make():
            with self.session() as s:
                return mod.validate_configuration(s, campaign, config)
        return self._cached(key, make)

    def metrics(self, campaign: str, config: str, sections: list[str] | None = None):
        """DataFrame of ``railval.app.services.metrics.metrics_for_configuration`` (cached)."""
        mod = service("metrics")

        def make():
            with self.session() as s:
                return mod.metrics_for_configuration(s, campaign, config, sections=sections)
        return self._cached(("metrics", campaign, config, tuple(sections or ())), make)

    def effects(self) -> list[dict[str, Any]]:
        """The effect registry (``railval.core.sim.effects``) as plain dicts for the UI."""
        try:
            mod = importlib.import_module(f"railval.core.sim.effects")
        except ImportError as exc:
            raise ServiceUnavailable(f"not available: core.sim.effects ({exc})") from exc
        return [_effect_dict(e) for e in mod.EFFECTS.values()]

    def diagnose(self, campaign: str, config: str, progress: Callable | None = None, **kw: Any):
        """``railval.app.services.diagnosis.diagnose`` → DiagnosisResult (ranked candidates)."""
        mod = service("diagnosis")
        return mod.diagnose(self.database, campaign, config, progress=_stage_progress(progress), **kw)

    def calibrate(self, campaign: str, config: str, effect: str, new_name: str,
                  progress: Callable | None = None, start: dict | None = None, **kw: Any):
        """Add ``effect``, fit its parameters (differential evolution + polish, starting from
        ``start``), store ``new_name`` with parent ``config``; returns the CalibrationResult."""
        mod = service("diagnosis")
        result = mod.calibrate(self.database, campaign, config, [effect], new_name,
                               progress=_stage_progress(progress),
                               start={effect: dict(start)} if start else None, **kw)
        self.invalidate()
        return result

    def simulate(self, campaign: str, config: str, effects: dict[str, dict], new_name: str,
                 progress: Callable | None = None):
        """Re-simulate ``config`` plus ``effects`` with the given parameters (no fit) and
        store it as ``new_name`` (``railval.app.services.simulation``)."""
        mod = service("simulation")
        fn = getattr(mod, "simulate_configuration", None) or getattr(mod, "simulate", None)
        if fn is None:
            raise ServiceUnavailable("not available: app.services.simulation has no simulate_configuration")
        result = fn(self.database, campaign, new_name, parent=config, effects=effects,
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


# ----------------------------------------------------------------------------- app state
class AppState(param.Parameterized):
    """What the engineer has selected, shared by all pages."""

    campaign = param.Selector(default=None, objects=[], allow_None=True)
    configuration = param.Selector(default=None, objects=[], allow_None=True)
    page = param.Selector(default="overview", objects=list(PAGES))
    section = param.Selector(default=None, objects=[], allow_None=True)
    channel = param.Selector(default=None, objects=[], allow_None=True)
    status = param.String(default="", doc="message of the status area")
    status_level = param.Selector(default="info", objects=["info", "success", "warning", "error"])
    busy = param.Boolean(default=False, doc="a background job is running")
    progress = param.Number(default=0.0, bounds=(0.0, 1.0))
    revision = param.Integer(default=0, doc="bumped when the database changed (new configuration)")

    def __init__(self, backend: Backend, **params):
        super().__init__(**params)
        self.backend = backend
        self._job: threading.Thread | None = None
        self.refresh_campaigns()

    # -- selections
    def refresh_campaigns(self) -> None:
        try:
            names = self.backend.campaigns()
        except Exception as exc:  # noqa: BLE001 - UI boundary: shown in the status area
            self.set_status(f"cannot list campaigns: {exc}", "error")
            names = []
        self.param.campaign.objects = names
        if names and self.campaign not in names:
            self.campaign = names[0]
        elif self.campaign is not None:
            self._campaign_changed()

    @param.depends("campaign", watch=True)
    def _campaign_changed(self) -> None:
        if self.campaign is None:
            return
        try:
            ov = self.backend.overview(self.campaign)
        except Exception as exc:  # noqa: BLE001 - UI boundary: shown in the status area
            self.set_status(f"cannot open campaign {self.campaign!r}: {exc}", "error")
            return
        self.overview = ov
        configs = [c.name for c in ov.configurations]
        sections = [s.id for s in ov.sections]
        chans = [c["name"] for c in ov.channels]
        with param.parameterized.batch_call_watchers(self):
            self.param.configuration.objects = configs
            self.param.section.objects = sections
            self.param.channel.objects = chans
            if self.configuration not in configs:
                self.configuration = configs[0] if configs else None
            if self.section not in sections:
                self.section = sections[0] if sections else None
            if self.channel not in chans:
                self.channel = chans[0] if chans else None

    overview: CampaignOverview | None = None

    def reload_configurations(self, select: str | None = None) -> None:
        """Re-read configurations after a job stored a new one; optionally select it."""
        self.backend.invalidate()
        self._campaign_changed()
        if select is not None and select in self.param.configuration.objects:
            self.configuration = select
        self.revision += 1

    def open_compare(self, section: str, channel: str, configuration: str | None = None) -> None:
        """Jump to the Compare page for one section/channel (dashboard drill-down)."""
        with param.parameterized.batch_call_watchers(self):
            if configuration is not None and configuration in self.param.configuration.objects:
                self.configuration = configuration
            if section in self.param.section.objects:
                self.section = section
            if channel in self.param.channel.objects:
                self.channel = channel
            self.page = "compare"

    def set_status(self, message: str, level: str = "info") -> None:
        self.status_level = level
        self.status = message

    # -- background jobs
    def run_job(self, title: str, work: Callable[[Callable[[float, str], None]], Any],
                on_done: Callable[[Any], None] | None = None,
                dispatch: Callable[[Callable[[], None]], None] | None = None,
                background: bool = True) -> threading.Thread | None:
        """Run ``work(progress)`` in a thread; ``progress(fraction, message)`` updates the
        progress bar and status; ``on_done(result)`` runs through ``dispatch`` afterwards.
        Refuses (status warning) while another job runs so the page never double-submits."""
        if self.busy:
            self.set_status(f"{title}: another job is still running — wait for it to finish", "warning")
            return None
        call = dispatch or (lambda f: f())
        self.busy = True
        self.progress = 0.0
        self.set_status(f"{title}: started", "info")

        def progress(fraction: float, message: str = "") -> None:
            frac = float(min(1.0, max(0.0, fraction if math.isfinite(fraction) else 0.0)))

            def apply():
                self.progress = frac
                self.set_status(f"{title}: {message}" if message else f"{title}: {frac:.0%}", "info")
            call(apply)

        def body():
            try:
                result = work(progress)
            except Exception as exc:  # noqa: BLE001 - UI boundary: shown in the status area
                detail = "".join(traceback.format_exception_only(type(exc), exc)).strip()

                def fail():
                    self.busy = False
                    self.set_status(f"{title} failed: {detail}", "error")
                call(fail)
                return

            def done():
                self.busy = False
                self.progress = 1.0
                self.set_status(f"{title}: done", "success")
                if on_done is not None:
                    try:
                        on_done(result)
                    except Exception as exc:  # noqa: BLE001 - UI boundary: shown in the status area
                        self.set_status(f"{title}: finished but showing the result failed: {exc}", "error")
            call(done)

        if not background:
            body()
            return None
        self._job = threading.Thread(target=body, name=f"railval-job-{title}", daemon=True)
        self._job.start()
        return self._job

    def wait(self, timeout: float | None = None) -> None:
        if self._job is not None:
            self._job.join(timeout)


# ----------------------------------------------------------------------------- compare
@dataclass
class Trace:
    label: str
    x: np.ndarray
    y: np.ndarray
    measured: bool = False


@dataclass
class CompareData:
    """What the Compare plot shows: traces, axis labels with units, evaluated range."""

    title: str
    x_label: str
    y_label: str
    traces: list[Trace]
    eval_range: tuple[float, float] | None
    log_axes: bool = False
    note: str = ""


class CompareState(param.Parameterized):
    configurations = param.ListSelector(default=[], objects=[])
    axis = param.Selector(default="time", objects=["time", "distance"])
    processing = param.Selector(default="EN-filtered and raw", objects=["EN-filtered and raw", "EN-filtered", "raw"])
    psd_segment_s = param.Number(default=10.0, bounds=(1.0, 60.0), doc="Welch segment length (s)")

    def __init__(self, app: AppState, **params):
        super().__init__(**params)
        self.app = app
        self.app.param.watch(self._sync_configs, ["configuration", "campaign", "revision"])
        self._sync_configs()

    def _sync_configs(self, *events) -> None:
        objs = list(self.app.param.configuration.objects)
        self.param.configurations.objects = objs
        keep = [c for c in self.configurations if c in objs]
        if self.app.configuration and self.app.configuration not in keep:
            keep = [self.app.configuration] + keep
        self.configurations = keep[:4]

    def _section_info(self) -> SectionInfo:
        ov = self.app.overview
        for s in ov.sections if ov else []:
            if s.id == self.app.section:
                return s
        raise NotFound(f"section {self.app.section!r} not in campaign {self.app.campaign!r}")

    #: entries kept by the per-session caches of loaded SignalSets and EN-filtered arrays
    CACHE_SIZE = 48

    def _load(self, config: str | None):
        """The SignalSet of one source for the current section and channel, cached per
        (campaign, revision, configuration, section, channel) — a database change bumps
        ``AppState.revision`` and so invalidates the entries."""
        app = self.app
        key = (app.campaign, app.revision, config, app.section, app.channel)
        cache = self.__dict__.setdefault("_signal_cache", {})
        if key not in cache:
            if len(cache) >= self.CACHE_SIZE:
                cache.pop(next(iter(cache)))
            cache[key] = app.backend.signals(app.campaign, config, app.section, [app.channel])
        return cache[key]

    def _process(self, sigset, values: np.ndarray, processing: str) -> np.ndarray:
        """``values`` as shown: raw, or EN-filtered (``railval.core.filters.filtfilt_rows``); the
        filtered array is cached per (SignalSet, channel) while that SignalSet is cached."""
        if processing == "raw":
            return values
        from railval.core.filters import filtfilt_rows

        kind = split_channel(self.app.channel)[0]
        fkind = EN_FILTER_OF_KIND.get(kind, ("lowpass", ""))[0]
        cache = self.__dict__.setdefault("_filter_cache", {})
        key = (id(sigset), self.app.channel, fkind)
        hit = cache.get(key)
        if hit is not None and hit[0] is sigset and hit[1] is values:
            return hit[2]
        out = filtfilt_rows(values[None, :], float(sigset.fs), fkind)[0]
        if len(cache) >= self.CACHE_SIZE:
            cache.pop(next(iter(cache)))
        cache[key] = (sigset, values, out)
        return out

    def sources(self) -> list[tuple[str, Any]]:
        """[(label, SignalSet)] — the measurement first (drawn beneath), then configurations."""
        out = [(MEASURED, self._load(None))]
        for c in self.configurations:
            try:
                out.append((c, self._load(c)))
            except NotFound:
                continue
        return out

    def processings(self) -> list[str]:
        """The processings to show, EN-filtered first."""
        return ["EN-filtered", "raw"] if self.processing == "EN-filtered and raw" else [self.processing]

    def series(self, processing: str | None = None, sources=None) -> CompareData:
        """Time or distance series of the selected channel for every source."""
        processing = processing or self.processings()[0]
        sec = self._section_info()
        ch = self.app.channel
        kind = split_channel(ch)[0]
        unit = CHANNEL_KINDS.get(kind, "")
        traces = []
        eval_range = None
        for label, ss in sources or self.sources():
            if ch not in ss.channels:
                continue
            y = self._process(ss, np.asarray(ss.channels[ch], dtype=float), processing)
            if self.axis == "time":
                x = np.asarray(ss.time_s, dtype=float)
                if label == MEASURED:
                    d = np.asarray(ss.distance_m, dtype=float)
                    eval_range = (float(np.interp(sec.eval_start_m, d, x)),
                                  float(np.interp(sec.eval_end_m, d, x)))
            else:
                x = np.asarray(ss.distance_m, dtype=float)
                eval_range = (sec.eval_start_m, sec.eval_end_m)
            traces.append(Trace(label, x, y, measured=(label == MEASURED)))
        proc_label = "raw" if processing == "raw" else EN_FILTER_OF_KIND.get(kind, ("", "filtered"))[1]
        return CompareData(
            title=f"{ch} — section {sec.id} (zone {sec.zone}) — {proc_label}",
            x_label="time (s)" if self.axis == "time" else "distance (m)",
            y_label=f"{ch} ({unit_label(unit)})",
            traces=traces, eval_range=eval_range,
        )

    def psd(self, sources=None) -> CompareData:
        """Welch PSD (core.psd) of the evaluated part, EN-filtered, every source alike."""
        from railval.core.psd import welch_psd

        sec = self._section_info()
        ch = self.app.channel
        kind = split_channel(ch)[0]
        unit = CHANNEL_KINDS.get(kind, "")
        traces = []
        for label, ss in sources or self.sources():
            if ch not in ss.channels:
                continue
            y = self._process(ss, np.asarray(ss.channels[ch], dtype=float), "EN-filtered")
            d = np.asarray(ss.distance_m, dtype=float)
            mask = (d >= sec.eval_start_m) & (d <= sec.eval_end_m)
            part = y[mask] if mask.sum() >= 64 else y
            p = welch_psd(part, float(ss.fs), self.psd_segment_s)
            keep = p.frequency_hz > 0
            traces.append(Trace(label, p.frequency_hz[keep], np.maximum(p.density[keep], 1e-30),
                                measured=(label == MEASURED)))
        return CompareData(
            title=f"PSD of {ch} — section {sec.id}, evaluated range, "
                  f"{EN_FILTER_OF_KIND.get(kind, ('', 'filtered'))[1]}",
            x_label="frequency (Hz)", y_label=f"PSD ({unit_label(unit)})²/Hz",
            traces=traces, eval_range=None, log_axes=True,
            note=f"Welch, Hann window, {self.psd_segment_s:g} s segments, 50 % overlap",
        )


def nice_step(lo: float, hi: float, intervals: int = 5) -> float:
    """A 'nice' step (1, 2, 2.5, 5 × 10^k) giving about ``intervals`` intervals on [lo, hi]."""
    raw = (hi - lo) / intervals
    mag = 10.0 ** math.floor(math.log10(raw))
    return next(m * mag for m in (1.0, 2.0, 2.5, 5.0, 10.0) if m * mag >= raw)


def nice_limits(lo: float, hi: float) -> tuple[float, float]:
    """Round ``[lo, hi]`` outwards to a multiple of :func:`nice_step` (~5 intervals).

    Used for fixed, consistent axis scaling (docs/design.md §5). Degenerate ranges are widened
    symmetrically by one unit of their magnitude (or ±1 around 0).
    """
    if not (math.isfinite(lo) and math.isfinite(hi)):
        return (-1.0, 1.0)
    if hi < lo:
        lo, hi = hi, lo
    if hi == lo:
        pad = abs(lo) or 1.0
        lo, hi = lo - pad, hi + pad
    step = nice_step(lo, hi)
    return (math.floor(lo / step + 1e-9) * step, math.ceil(hi / step - 1e-9) * step)


def nice_ticks(lo: float, hi: float) -> list[float]:
    """Tick positions: the multiples of :func:`nice_step` within [lo, hi]."""
    step = nice_step(lo, hi)
    first = math.ceil(lo / step - 1e-9)
    return [k * step for k in range(first, math.floor(hi / step + 1e-9) + 1)]


def unit_label(unit: str) -> str:
    """A stored unit as shown to a reader: ``m/s^2`` → ``m/s²``, ``kN*m/rad`` → ``kN·m/rad``."""
    return unit.replace("m/s^2", "m/s²").replace("*", "·")


# ----------------------------------------------------------------------------- dashboard
def _q_rows(result: Any) -> list[dict[str, Any]]:
    d = result.to_dict() if hasattr(result, "to_dict") else dict(result)
    rows = d.get("quantities", d.get("results", []))
    if isinstance(rows, dict):
        rows = [dict(v, quantity=k) if "quantity" not in v else v for k, v in rows.items()]
    return list(rows)


class DashboardState(param.Parameterized):
    quantity = param.Selector(default=None, objects=[], allow_None=True,
                              doc="quantity whose drill-down is shown")
    top_n = param.Integer(default=15, bounds=(5, 200))

    def __init__(self, app: AppState, **params):
        super().__init__(**params)
        self.app = app

    def result(self, config: str | None = None):
        config = config or self.app.configuration
        return self.app.backend.validation(self.app.campaign, config)

    def summary(self, config: str | None = None) -> dict[str, Any]:
        """``{"validated", "coverage", "quantities": [rows]}`` of the validation contract."""
        res = self.result(config)
        d = res.to_dict() if hasattr(res, "to_dict") else dict(res)
        rows = _q_rows(res)
        self.param.quantity.objects = [r["quantity"] for r in rows]
        return {"validated": bool(d.get("validated")), "coverage": d.get("coverage", {}),
                "quantities": rows, "raw": d}

    def drilldown(self, quantity: str | None = None, config: str | None = None) -> list[dict[str, Any]]:
        """Pairs of one quantity ranked by their contribution |D_v|/std limit (largest first).

        Each row: section, position, channel, zone, M_v, S_v, D_v, norm (= D_v / std limit).
        """
        quantity = quantity or self.quantity
        if quantity is None:
            return []
        res = self.result(config)
        rows = _pairs_of(res, quantity)
        limit = next((r.get("std_limit") for r in _q_rows(res) if r["quantity"] == quantity), None)
        for r in rows:
            r["norm"] = (r["D_v"] / limit) if limit else float("nan")
        rows.sort(key=lambda r: -abs(r["D_v"]))
        return rows[: self.top_n]

    def where(self, config: str | None = None) -> PatternGrid:
        """Where the configuration fails: mean of D_v / std limit over the sections and
        positions of each quantity × EN zone (``ValidationResult.pairs``), as a grid."""
        return where_grid(self.result(config))

    def open_row(self, row: dict[str, Any]) -> None:
        channel = _channel_for(row.get("quantity"), row.get("position"), self.app.param.channel.objects)
        self.app.open_compare(row["section"], channel)


def _pairs_of(result: Any, quantity: str) -> list[dict[str, Any]]:
    """All pairs of one quantity from ``ValidationResult.pairs`` (a DataFrame with columns
    quantity, section, zone, position, M, S, D, D_norm — core.validation)."""
    pairs = result.pairs
    sub = pairs[pairs["quantity"] == quantity]
    return [{
        "quantity": quantity, "section": str(r.section), "position": str(r.position),
        "zone": int(r.zone), "M_v": float(r.M), "S_v": float(r.S), "D_v": float(r.D),
    } for r in sub.itertuples(index=False)]


def _channel_for(quantity: str | None, position: str | None, channels: list[str]) -> str | None:
    """The raw channel to compare for a quantity at a position, from the quantity registry
    (``railval.core.quantities``): Y/Q at w1L → ``Y_w1L``; ΣY at ws1 → ``Y_w1L``; ay_rms at b1 →
    ``ay_cb_b1``."""
    from railval.core.quantities import QUANTITIES

    if quantity in QUANTITIES and position:
        try:
            for c in QUANTITIES[quantity].channels(position):
                if c in channels:
                    return c
        except RailvalError:
            pass
    return channels[0] if channels else None


def _num(x: Any) -> float:
    return float("nan") if x is None else float(x)


# ----------------------------------------------------------------------------- metrics
class MetricsState(param.Parameterized):
    """Curve metrics of the selected configuration (``railval.app.services.metrics``), computed per
    section in a background job (≈ 3 s per section of 12 channels on one core)."""

    scope = param.Selector(default="selected section", objects=["selected section", "all sections"])
    view = param.Selector(default="raw", objects=["raw", "synchronised", "raw and synchronised"])
    frame = param.DataFrame(default=None, allow_None=True, doc="metrics of the last computation")
    computed_for = param.String(default="", doc="what ``frame`` holds (campaign/config/scope)")

    ID_COLUMNS = ("section", "zone", "channel", "unit")

    def __init__(self, app: AppState, **params):
        super().__init__(**params)
        self.app = app

    def key(self) -> str:
        scope = self.app.section if self.scope == "selected section" else "all sections"
        return f"{self.app.campaign} / {self.app.configuration} / {scope}"

    def compute(self, dispatch=None, background: bool = True):
        app = self.app
        campaign, config = app.campaign, app.configuration
        sections = [app.section] if self.scope == "selected section" else list(app.param.section.objects)
        key = self.key()

        def work(progress):
            import pandas as pd

            frames = []
            for i, sid in enumerate(sections):
                progress(i / len(sections), f"section {sid} ({i + 1}/{len(sections)})")
                frames.append(app.backend.metrics(campaign, config, [sid]))
            return pd.concat(frames, ignore_index=True) if frames else None

        def done(df):
            self.computed_for = key  # first: the view refreshes when ``frame`` changes
            self.frame = df
        return app.run_job("metrics", work, done, dispatch=dispatch, background=background)

    def table(self):
        """The metric table in the chosen view: raw columns, synchronised columns (``*_sync``
        shown under the raw name, with the lag), or both side by side."""
        df = self.frame
        if df is None:
            return None
        ids = [c for c in self.ID_COLUMNS if c in df.columns]
        metric_cols = [c for c in df.columns if c not in ids and f"{c}_sync" in df.columns]
        if self.view == "raw":
            cols = ids + metric_cols
            out = df[cols]
        elif self.view == "synchronised":
            out = df[ids + ["lag_s"] + [f"{c}_sync" for c in metric_cols]]
            out = out.rename(columns={f"{c}_sync": c for c in metric_cols})
        else:
            cols = ids + ["lag_s"] + [x for c in metric_cols for x in (c, f"{c}_sync")]
            out = df[cols]
        return out.reset_index(drop=True)


# ----------------------------------------------------------------------------- diagnose
class DiagnoseState(param.Parameterized):
    effect = param.Selector(default=None, objects=[], allow_None=True)
    new_name = param.String(default="")
    candidates = param.List(default=[])
    parameters = param.Dict(default={}, doc="manually set parameters of the chosen effect")
    last_new_configuration = param.String(default="")
    last_result = param.Dict(default={}, doc="to_dict() of the last calibration or re-simulation")
    diagnosis_run = param.Dict(default={}, doc="settings and simulation count of the last diagnosis")
    residual = param.Dict(default={}, doc="residual pattern of the diagnosed configuration (labels, values)")
    diagnosis_note = param.String(default="", doc="separability note of the diagnosis")
    separable = param.Boolean(default=True, doc="the two best candidates are told apart")
    # diagnosis settings (app.services.diagnosis.diagnose)
    candidate_effects = param.ListSelector(default=[], objects=[], doc=(
        "effects the diagnosis tries; none chosen = every effect the configuration lacks"))
    values_per_parameter = param.Integer(default=3, bounds=(2, 9), doc=(
        "values of each effect parameter simulated over its bounds (plus its default)"))
    # calibration settings (app.services.diagnosis.calibrate → core.calibration.calibrate)
    fit_parameters = param.ListSelector(default=[], objects=[], doc=(
        "parameters of the chosen effect to fit; none chosen = all; the others keep the values set"))
    popsize = param.Integer(default=5, bounds=(2, 40), doc="differential evolution: population per parameter")
    maxiter = param.Integer(default=5, bounds=(1, 200), doc="differential evolution: generations at most")
    polish_maxfev = param.Integer(default=20, bounds=(0, 1000), doc="local polish: simulations at most")
    seed = param.Integer(default=0, bounds=(0, None), doc="random seed of the global search")

    def __init__(self, app: AppState, **params):
        super().__init__(**params)
        self.app = app
        self.app.param.watch(lambda e: self._reset(), ["campaign", "configuration"])
        self.param.watch(lambda e: self._effect_changed(), ["effect"])

    def _reset(self) -> None:
        self.candidates = []
        self.residual = {}

    def where(self, effect: str | None = None) -> dict[str, PatternGrid]:
        """Where the configuration fails and what ``effect`` (a ranked candidate, default
        the selected effect) leaves: the residual pattern now and after adding the fitted
        candidate (residual − its signature), each as a quantity × zone grid and a PSD
        band grid (:func:`pattern_grids`). Empty before a diagnosis."""
        effect = effect or self.effect
        cand = next((c for c in self.candidates if c["effect"] == effect), None)
        res = self.residual
        if cand is None or "values" not in res or "signature" not in cand:
            return {}
        now = np.asarray(res["values"], float)
        after = now - np.asarray(cand["signature"]["values"], float)
        return {"now": pattern_grids(res["labels"], now), "after": pattern_grids(res["labels"], after)}

    def _effect_changed(self) -> None:
        eff = next((e for e in self.effect_catalogue() if e["name"] == self.effect), None)
        names = [p["name"] for p in eff["parameters"]] if eff else []
        self.param.fit_parameters.objects = names
        self.fit_parameters = []

    def refresh_choices(self) -> None:
        """Candidate effects to choose from: those the configuration lacks (a choice no
        longer available is dropped)."""
        available = self.available_effects()
        self.param.candidate_effects.objects = available
        self.candidate_effects = [e for e in self.candidate_effects if e in available]

    def diagnosis_simulations(self) -> int:
        """Campaign simulations the diagnosis will run with the current settings."""
        effects = self.candidate_effects or self.available_effects()
        ov = self.app.overview
        template = str(ov.vehicle.get("template") or "coach") if ov else None
        return service("diagnosis").diagnosis_simulations(effects, self.values_per_parameter, template)

    def calibration_simulations(self) -> int:
        """Upper bound of the campaign simulations a calibration runs: the optimiser's
        (``railval.core.calibration.max_evaluations``) plus the final stored run."""
        from railval.core.calibration import max_evaluations

        n = len(self.fit_parameters or self.param.fit_parameters.objects) or 1
        return max_evaluations(n, self.popsize, self.maxiter, self.polish_maxfev) + 1

    def effect_catalogue(self) -> list[dict[str, Any]]:
        return self.app.backend.effects()

    def available_effects(self) -> list[str]:
        """Effects not yet in the current configuration."""
        ov = self.app.overview
        present = set()
        for c in ov.configurations if ov else []:
            if c.name == self.app.configuration:
                present = set(c.effects)
        names = [e["name"] for e in self.effect_catalogue()]
        return [n for n in names if n not in present]

    def suggested_name(self) -> str:
        base = f"{self.app.configuration}+{self.effect}" if self.effect else f"{self.app.configuration}-new"
        existing = set(self.app.param.configuration.objects)
        name, i = base, 2
        while name in existing:
            name, i = f"{base}-{i}", i + 1
        return name

    def run_diagnosis(self, dispatch=None, background=True):
        app = self.app
        campaign, config = app.campaign, app.configuration

        settings = {"values_per_parameter": self.values_per_parameter,
                    "effects": list(self.candidate_effects) or None}

        def work(progress):
            return app.backend.diagnose(campaign, config, progress=progress, **settings)

        def done(result):
            d = result.to_dict(with_signatures=True) if hasattr(result, "to_dict") else result
            cands = list(d.get("candidates", []))
            self.residual = dict(d.get("residual") or {})
            note = d.get("note") or ""
            if not d.get("separable", True) and not note:
                note = "the two best candidates explain nearly the same; see the evidence"
            self.diagnosis_note = note
            self.separable = bool(d.get("separable", True))
            self.diagnosis_run = {k: d.get(k) for k in ("simulations", "values_per_parameter", "configuration")}
            names = self.available_effects() if cands else []
            order = [c["effect"] for c in cands] + [n for n in names if n not in {c["effect"] for c in cands}]
            self.param.effect.objects = order
            if order:  # the top candidate chosen before the ranking is shown
                self.effect = order[0]
                self.new_name = self.suggested_name()
            self.candidates = cands
        return app.run_job("diagnosis", work, done, dispatch=dispatch, background=background)

    def run_calibration(self, dispatch=None, background=True, calibrate: bool = True):
        """Add ``effect`` to the configuration, calibrate it (or use ``parameters``),
        re-simulate and store as ``new_name`` whose parent is the current configuration."""
        app = self.app
        campaign, config, effect = app.campaign, app.configuration, self.effect
        name = self.new_name or self.suggested_name()
        params = dict(self.parameters)
        if effect is None:
            app.set_status("choose an effect to add first", "warning")
            return None

        settings = {"popsize": self.popsize, "maxiter": self.maxiter, "polish_maxfev": self.polish_maxfev,
                    "seed": self.seed, "params": [f"{effect}.{p}" for p in self.fit_parameters] or None}

        def work(progress):
            if calibrate:
                return app.backend.calibrate(campaign, config, effect, name, progress=progress,
                                             start=params or None, **settings)
            return app.backend.simulate(campaign, config, {effect: params or {}}, name, progress=progress)

        def done(result):
            d = result.to_dict() if hasattr(result, "to_dict") else dict(result or {})
            self.last_result = {**d, "kind": "calibration" if calibrate else "re-simulation",
                                "effect": effect, "configuration": name, "parent": config}
            self.last_new_configuration = name
            app.reload_configurations(select=name)
        return app.run_job("calibration" if calibrate else "re-simulation", work, done,
                           dispatch=dispatch, background=background)

    def lineage_errors(self, config: str | None = None) -> list[dict[str, Any]]:
        """Along the lineage root → config: the largest normalised error (max over quantities
        of |mean|/mean limit and std/std limit) and whether the configuration is validated."""
        app = self.app
        config = config or app.configuration
        out = []
        for name in app.backend.lineage(app.campaign, config):
            res = app.backend.validation(app.campaign, name)
            d = res.to_dict() if hasattr(res, "to_dict") else res
            rows = _q_rows(res)
            worst = max((max(abs(_num(r["mean_norm"])), abs(_num(r["std_norm"]))) for r in rows),
                        default=float("nan"))
            out.append({"configuration": name, "max_norm": worst, "validated": bool(d.get("validated"))})
        return out


def where_grid(result: Any) -> PatternGrid:
    """Mean of D_v / std limit over the sections and positions of each quantity × EN zone of
    a validation result (``ValidationResult.pairs``): where a configuration fails."""
    pairs = result.pairs
    labels = [f"{q} zone {int(z)} {p}" for q, z, p in zip(pairs["quantity"], pairs["zone"],
                                                           pairs["position"], strict=True)]
    return pattern_grids(labels, pairs["D_norm"].to_numpy(float))[0]


@dataclass
class PatternGrid:
    """Components of a residual pattern arranged for a heat map: ``rows`` × ``cols`` with
    ``values[i][j]`` the mean over positions (NaN where nothing was evaluated)."""

    rows: list[str]
    cols: list[str]
    values: np.ndarray


def pattern_grids(labels: list[str], values) -> tuple[PatternGrid, PatternGrid]:
    """Arrange a diagnosis pattern (``railval.core.diagnosis``: components ``"Y_qst zone 4 w1L"`` =
    mean normalised D_v of a quantity in a zone at a position, and ``"psd az_cb_b1 5-10 Hz"``
    = log2 PSD ratio simulation/measurement in a band) into (quantity × zone, car body
    acceleration direction × band) grids, averaging over positions. Quantities in the order
    of ``railval.core.quantities``."""
    from railval.core.quantities import QUANTITY_IDS

    q_acc: dict[tuple[str, str], list[float]] = {}
    p_acc: dict[tuple[str, str], list[float]] = {}
    bands: list[str] = []
    for label, v in zip(labels, np.asarray(values, float), strict=True):
        if not math.isfinite(v):
            continue
        parts = label.split()
        if parts[0] == "psd":  # psd <channel> <lo-hi> Hz
            kind = parts[1].split("_")[0]
            band = f"{parts[2]} Hz"
            if band not in bands:
                bands.append(band)
            p_acc.setdefault((kind, band), []).append(v)
        elif len(parts) >= 3 and parts[1] == "zone":
            q_acc.setdefault((parts[0], f"zone {parts[2]}"), []).append(v)
    zones = [f"zone {z}" for z in (1, 2, 3, 4)]
    quantities = [q for q in QUANTITY_IDS if any((q, z) in q_acc for z in zones)]

    def grid(rows, cols, acc):
        m = np.full((len(rows), len(cols)), np.nan)
        for i, r in enumerate(rows):
            for j, c in enumerate(cols):
                if (r, c) in acc:
                    m[i, j] = float(np.mean(acc[(r, c)]))
        return PatternGrid(list(rows), list(cols), m)

    bands.sort(key=lambda b: float(b.split("-")[0]))
    kinds = [k for k in ("ay", "az") if any((k, b) in p_acc for b in bands)]
    return grid(quantities, zones, q_acc), grid(kinds, bands, p_acc)


# ----------------------------------------------------------------------------- report
class ReportState(param.Parameterized):
    fmt = param.Selector(default="html", objects=["html", "pdf"])
    worst_cases = param.Integer(default=3, bounds=(0, 12))

    def __init__(self, app: AppState, **params):
        super().__init__(**params)
        self.app = app

    def build(self):
        from railval.app.report import build_report

        return build_report(self.app.backend, self.app.campaign, self.app.configuration,
                            worst_cases=self.worst_cases)
