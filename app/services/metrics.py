"""Curve-comparison metrics of a configuration against the measurement, from the database.

``metrics_for_configuration(session, campaign, config, sections=None, channels=None, ...)``
reads the measured and simulated signal sets of the chosen sections (one query each,
``railval.db.repo.load_signalsets``) and runs :func:`railval.core.metrics.compare_signalsets` per section:
low-pass (default 20 Hz, Polach & Böttcher 2014's plots), common grid, synchronisation within ±max_lag_s,
every metric raw and synchronised. Returns one row per (section, channel).

``part="section"`` (default) compares the whole recorded section, like Polach & Böttcher 2014's time plots
(Polach & Böttcher 2014 §3.4); ``part="evaluated"`` filters the whole section first and then compares only
the constant-curvature part (the EN-evaluated range on each record's own distance axis,
both cut records starting at time 0 so the remaining offset is left to synchronisation).
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from typing import Any

import numpy as np
import pandas as pd

from railval.app.services.stored_runs import data_inputs, digests, run_info
from railval.core.errors import InvalidParameter, NotFound
from railval.core.metrics import compare_signalsets, cut_evaluated, metric_names
from railval.core.metrics.compare import DEFAULT_LOWPASS_HZ
from railval.core.metrics.sync import DEFAULT_MAX_LAG_S
from railval.core.types import CHANNEL_KINDS, SectionInfo, split_channel
from railval.db import repo, runs

PARTS = ("section", "evaluated")

#: version of the metric computation in the stored runs' digest: a change of the metrics
#: computes afresh instead of reusing an older stored run
METRICS_VERSION = "metrics/1"


def frame_to_json(df: pd.DataFrame) -> dict[str, Any]:
    """A metrics frame as JSON (columns, rows, dtypes); NaN becomes null when stored."""
    return {"columns": [str(c) for c in df.columns], "dtypes": {str(c): str(t) for c, t in df.dtypes.items()},
            "data": df.astype(object).where(pd.notna(df), None).values.tolist()}


def frame_from_json(d: dict[str, Any]) -> pd.DataFrame:
    """Inverse of :func:`frame_to_json` (null numbers back to NaN, dtypes restored)."""
    df = pd.DataFrame(d["data"], columns=d["columns"])
    for c, t in d.get("dtypes", {}).items():
        if t.startswith("float"):
            df[c] = pd.to_numeric(df[c], errors="coerce").astype(float)
        elif t.startswith("int") and df[c].notna().all():
            df[c] = df[c].astype(t)
        elif t == "bool" and df[c].notna().all():
            df[c] = df[c].astype(bool)
    return df


def _run_settings(sections, channels, lowpass_hz, max_lag_s, families, part, subsample) -> dict[str, Any]:
    return {"sections": sorted(sections) if sections is not None else None,
            "channels": sorted(channels) if channels is not None else None,
            "lowpass_hz": lowpass_hz, "max_lag_s": float(max_lag_s),
            "families": sorted(families) if families is not None else None,
            "part": part, "subsample": bool(subsample)}


def channel_unit(channel: str) -> str:
    """Unit of a channel from the channel vocabulary (``railval.core.types.CHANNEL_KINDS``)."""
    return CHANNEL_KINDS.get(split_channel(channel)[0], "")


def metrics_for_configuration(session: Any, campaign: repo.CampaignArg, config: repo.ConfigArg,
                              sections: Sequence[str] | None = None,
                              channels: Sequence[str] | None = None, *,
                              lowpass_hz: float | None = DEFAULT_LOWPASS_HZ,
                              max_lag_s: float = DEFAULT_MAX_LAG_S,
                              families: Sequence[str] | None = None,
                              part: str = "section",
                              subsample: bool = False,
                              refresh: bool = False, store: bool = True,
                              actor: str = "") -> pd.DataFrame:
    """Metrics of configuration ``config`` against the measurement: one row per
    (section, channel) with ``section``, ``zone``, ``unit`` and the columns of
    :func:`railval.core.metrics.compare_signalsets` (``<metric>`` raw, ``<metric>_sync``, ``lag_s`` …).

    A stored run with the same inputs (signal content hashes of both sides for these
    sections and channels, section records, settings, :data:`METRICS_VERSION`) is returned
    without computing unless ``refresh``; every computed run is stored (``store``).
    ``df.attrs["run"]`` describes the stored run (:func:`railval.app.services.stored_runs.run_info`).
    Campaign and configuration are resolved once here (:func:`railval.db.repo.resolve`).
    """
    if part not in PARTS:
        raise InvalidParameter(f"part must be one of {PARTS}, got {part!r}")
    campaign, _ = repo.resolve(session, campaign)
    infos = {s.id: s for s in repo.section_infos(session, campaign)}
    if sections is not None:
        missing = [s for s in sections if s not in infos]
        if missing:
            raise NotFound(f"section(s) {missing} not in campaign {campaign.name!r}; has {sorted(infos)}")
    _, config = repo.resolve(session, campaign, config)
    conf = repo.get_configuration(session, campaign, config)
    settings = _run_settings(sections, channels, lowpass_hz, max_lag_s, families, part, subsample)
    data_sha, inputs_sha = digests(data_inputs(session, campaign, config, sections, channels),
                                   settings, METRICS_VERSION)
    stored = None if refresh else runs.latest_run(session, conf.id, "metrics", inputs_sha)
    if stored is not None:
        df = frame_from_json(stored.result["frame"])
        df.attrs["run"] = run_info(stored, reused=True, current_data_sha256=data_sha)
        return df
    started = time.perf_counter()
    df = _compute(session, campaign, config, infos, sections, channels, lowpass_hz, max_lag_s,
                  families, part, subsample)
    if store:
        row = runs.store_run(session, campaign_id=conf.campaign_id, configuration_id=conf.id, kind="metrics",
                             inputs_sha256=inputs_sha,
                             settings={**settings, "data_sha256": data_sha, "version": METRICS_VERSION},
                             result={"frame": frame_to_json(df), "rows": len(df)},
                             seconds=time.perf_counter() - started,
                             actor=actor or str(session.info.get("actor") or ""))
        df.attrs["run"] = run_info(row, reused=False, current_data_sha256=data_sha)
    return df


def stored_metrics(session: Any, campaign: repo.CampaignArg, config: repo.ConfigArg,
                   sections: Sequence[str] | None = None,
                   channels: Sequence[str] | None = None, *,
                   lowpass_hz: float | None = DEFAULT_LOWPASS_HZ, max_lag_s: float = DEFAULT_MAX_LAG_S,
                   families: Sequence[str] | None = None, part: str = "section",
                   subsample: bool = False) -> pd.DataFrame | None:
    """The stored metrics of exactly these inputs (as :func:`metrics_for_configuration`
    would return them), or None when they were never computed: nothing is computed."""
    campaign, config = repo.resolve(session, campaign, config)
    conf = repo.get_configuration(session, campaign, config)
    settings = _run_settings(sections, channels, lowpass_hz, max_lag_s, families, part, subsample)
    data_sha, inputs_sha = digests(data_inputs(session, campaign, config, sections, channels),
                                   settings, METRICS_VERSION)
    stored = runs.latest_run(session, conf.id, "metrics", inputs_sha)
    if stored is None:
        return None
    df = frame_from_json(stored.result["frame"])
    df.attrs["run"] = run_info(stored, reused=True, current_data_sha256=data_sha)
    return df


def metrics_runs(session: Any, campaign: repo.CampaignArg, config: repo.ConfigArg) -> list[dict[str, Any]]:
    """Stored metrics runs of ``config``, newest first (:func:`run_info` plus the rows);
    ``current`` is false when the signals or sections it read changed since."""
    campaign, config = repo.resolve(session, campaign, config)
    conf = repo.get_configuration(session, campaign, config)
    data_sha: dict[str, str] = {}
    out = []
    for r in runs.list_runs(session, conf.id, "metrics"):
        st = r.settings or {}
        key = repr((st.get("sections"), st.get("channels")))
        if key not in data_sha:
            data_sha[key] = digests(data_inputs(session, campaign, config, st.get("sections"),
                                                st.get("channels")), {}, METRICS_VERSION)[0]
        out.append({**run_info(r, reused=True, current_data_sha256=data_sha[key]),
                    "rows": int((r.result or {}).get("rows", 0))})
    return out


def _compute(session: Any, campaign: repo.CampaignRef, config: repo.ConfigRef, infos: dict[str, SectionInfo],
             sections: Sequence[str] | None, channels: Sequence[str] | None,
             lowpass_hz: float | None, max_lag_s: float, families: Sequence[str] | None,
             part: str, subsample: bool) -> pd.DataFrame:
    ch = list(channels) if channels is not None else None
    sec = list(sections) if sections is not None else None
    measured = repo.load_signalsets(session, campaign, None, sec, ch)
    simulated = repo.load_signalsets(session, campaign, config, sec, ch)
    frames = []
    for sid in (list(sections) if sections is not None else list(infos)):
        info = infos[sid]
        if sid not in measured or sid not in simulated:
            if sections is not None:
                side = "measurement" if sid not in measured else f"configuration {config.name!r}"
                raise NotFound(f"section {sid} has no recording in the {side}")
            continue
        m, c = measured[sid], simulated[sid]
        filt: float | None = lowpass_hz
        if part == "evaluated":
            m, c = cut_evaluated(m, info, lowpass_hz), cut_evaluated(c, info, lowpass_hz)
            filt = None  # already filtered over the whole section
        df = compare_signalsets(m, c, ch, lowpass_hz=filt, max_lag_s=max_lag_s,
                                families=families, subsample=subsample)
        df.insert(0, "zone", info.zone)
        df.insert(0, "section", sid)
        df.insert(3, "unit", [channel_unit(x) for x in df["channel"]])
        frames.append(df)
    if not frames:
        cols = ["section", "zone", "channel", "unit"]
        return pd.DataFrame(columns=cols + [c for n in metric_names(families) for c in (n, f"{n}_sync")])
    return pd.concat(frames, ignore_index=True)


def summary(df: pd.DataFrame) -> dict[str, dict[str, float | None]]:
    """Median and mean of every numeric metric column over the rows (NaN rows skipped)."""
    out: dict[str, dict[str, float | None]] = {}
    for col in df.columns:
        if col in ("zone", "n", "fs_hz") or not pd.api.types.is_numeric_dtype(df[col]):
            continue
        if pd.api.types.is_bool_dtype(df[col]):
            continue
        vals = df[col].to_numpy(dtype=float)
        vals = vals[np.isfinite(vals)]
        out[col] = {"median": float(np.median(vals)) if vals.size else None,
                    "mean": float(np.mean(vals)) if vals.size else None,
                    "n": int(vals.size)}
    return out
