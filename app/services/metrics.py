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

from collections.abc import Sequence
from typing import Any

import numpy as np
import pandas as pd

from railval.core.errors import InvalidParameter, NotFound
from railval.core.metrics import compare_signalsets, cut_evaluated, metric_names
from railval.core.metrics.compare import DEFAULT_LOWPASS_HZ
from railval.core.metrics.sync import DEFAULT_MAX_LAG_S
from railval.core.types import CHANNEL_KINDS, split_channel

PARTS = ("section", "evaluated")


def channel_unit(channel: str) -> str:
    """Unit of a channel from the channel vocabulary (``railval.core.types.CHANNEL_KINDS``)."""
    return CHANNEL_KINDS.get(split_channel(channel)[0], "")


def metrics_for_configuration(session: Any, campaign: Any, config: str,
                              sections: Sequence[str] | None = None,
                              channels: Sequence[str] | None = None, *,
                              lowpass_hz: float | None = DEFAULT_LOWPASS_HZ,
                              max_lag_s: float = DEFAULT_MAX_LAG_S,
                              families: Sequence[str] | None = None,
                              part: str = "section",
                              subsample: bool = False) -> pd.DataFrame:
    """Metrics of configuration ``config`` against the measurement: one row per
    (section, channel) with ``section``, ``zone``, ``unit`` and the columns of
    :func:`railval.core.metrics.compare_signalsets` (``<metric>`` raw, ``<metric>_sync``, ``lag_s`` …).
    """
    from railval.db import repo

    if part not in PARTS:
        raise InvalidParameter(f"part must be one of {PARTS}, got {part!r}")
    infos = {s.id: s for s in repo.section_infos(session, campaign)}
    if sections is not None:
        missing = [s for s in sections if s not in infos]
        if missing:
            raise NotFound(f"section(s) {missing} not in campaign {campaign!r}; has {sorted(infos)}")
    ch = list(channels) if channels is not None else None
    sec = list(sections) if sections is not None else None
    measured = repo.load_signalsets(session, campaign, None, sec, ch)
    simulated = repo.load_signalsets(session, campaign, config, sec, ch)
    frames = []
    for sid in (list(sections) if sections is not None else list(infos)):
        info = infos[sid]
        if sid not in measured or sid not in simulated:
            if sections is not None:
                side = "measurement" if sid not in measured else f"configuration {config!r}"
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
