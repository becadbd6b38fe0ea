"""State of the Compare page: configurations × view (time/distance/PSD) × processing for one
section/channel → :class:`CompareData` (arrays, axis labels with units, evaluated range)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
import param

from railval.app.scales import unit_label
from railval.app.state.app import AppState
from railval.core.errors import NotFound
from railval.core.filters import filtfilt_rows
from railval.core.psd import welch_psd
from railval.core.quantities import DERIVED_SIGNALS, combine_derived, derived_signals
from railval.core.types import SectionInfo, channel_kind

MEASURED = "measurement"


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
            cache[key] = self._fetch(config)
        return cache[key]

    def _components(self) -> tuple[str, ...] | None:
        """The raw channels of a derived signal (Y/Q, ΣY), None for a raw channel."""
        ov = self.app.overview
        return derived_signals([c["name"] for c in ov.channels] if ov else []).get(self.app.channel)

    def _fetch(self, config: str | None):
        """The SignalSet of the channel; a derived signal is carried as its components and
        formed in :meth:`_values` (after filtering them, as the EN evaluation does)."""
        app = self.app
        parts = self._components()
        return app.backend.signals(app.campaign, config, app.section, list(parts or [app.channel]))

    def _has(self, ss) -> bool:
        parts = self._components()
        return all(c in ss.channels for c in parts) if parts else self.app.channel in ss.channels

    def _values(self, ss, processing: str) -> np.ndarray:
        """The channel as shown: raw or EN-filtered; a derived signal formed from its
        components (EN-filtered: from the low-pass filtered components, as
        ``railval.core.en14363`` forms Y/Q and ΣY)."""
        parts = self._components()
        if not parts:
            return self._process(ss, np.asarray(ss.channels[self.app.channel], dtype=float), processing)
        rows = np.vstack([np.asarray(ss.channels[c], dtype=float) for c in parts])
        if processing != "raw":
            rows = filtfilt_rows(rows, float(ss.fs), "lowpass")
        return combine_derived(self.app.channel, rows)

    def _unit_and_filter(self) -> tuple[str, str]:
        ch = self.app.channel
        if self._components():
            fam = ch.split("_", 1)[0]
            return DERIVED_SIGNALS[fam][2].replace("-", ""), "low-pass 20 Hz (components)"
        entry = channel_kind(ch)
        return (entry.unit if entry else ""), (entry.filter_label if entry else "filtered")

    def _process(self, sigset, values: np.ndarray, processing: str) -> np.ndarray:
        """``values`` as shown: raw, or EN-filtered (``railval.core.filters.filtfilt_rows``); the
        filtered array is cached per (SignalSet, channel) while that SignalSet is cached."""
        if processing == "raw":
            return values
        entry = channel_kind(self.app.channel)
        fkind = entry.en_filter if entry else "lowpass"
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
        unit, filter_label = self._unit_and_filter()
        traces = []
        eval_range = None
        for label, ss in sources or self.sources():
            if not self._has(ss):
                continue
            y = self._values(ss, processing)
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
        proc_label = "raw" if processing == "raw" else filter_label
        return CompareData(
            title=f"{ch} — section {sec.id} (zone {sec.zone}) — {proc_label}",
            x_label="time (s)" if self.axis == "time" else "distance (m)",
            y_label=f"{ch} ({unit_label(unit)})" if unit else f"{ch} (–)",
            traces=traces, eval_range=eval_range,
        )

    def psd(self, sources=None) -> CompareData:
        """Welch PSD (core.psd) of the evaluated part, EN-filtered, every source alike."""
        sec = self._section_info()
        ch = self.app.channel
        unit, filter_label = self._unit_and_filter()
        traces = []
        for label, ss in sources or self.sources():
            if not self._has(ss):
                continue
            y = self._values(ss, "EN-filtered")
            d = np.asarray(ss.distance_m, dtype=float)
            mask = (d >= sec.eval_start_m) & (d <= sec.eval_end_m)
            part = y[mask] if mask.sum() >= 64 else y
            p = welch_psd(part, float(ss.fs), self.psd_segment_s)
            keep = p.frequency_hz > 0
            traces.append(Trace(label, p.frequency_hz[keep], np.maximum(p.density[keep], 1e-30),
                                measured=(label == MEASURED)))
        return CompareData(
            title=f"PSD of {ch} — section {sec.id}, evaluated range, {filter_label}",
            x_label="frequency (Hz)", y_label=f"PSD ({unit_label(unit)})²/Hz",
            traces=traces, eval_range=None, log_axes=True,
            note=f"Welch, Hann window, {self.psd_segment_s:g} s segments, 50 % overlap",
        )


