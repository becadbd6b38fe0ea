"""``compare`` one measured/simulated pair and ``compare_signalsets`` for whole sections.

Every metric is reported twice (docs/design.md §4): **raw** — on the common grid as given — and
**synchronised** — after removing the lag that maximises the cross-correlation within
±``max_lag_s`` (:mod:`railval.core.metrics.sync`), on the overlapping samples only. Distribution
metrics (KS, area, Anderson–Darling) ignore time order, so their synchronised values differ
from the raw ones only through the trimmed ends.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from railval.core import filters, lazy
from railval.core.errors import InvalidParameter, InvalidSignal, NotFound
from railval.core.metrics.grid import common_grid
from railval.core.metrics.iso18571 import ISOParameters
from railval.core.metrics.registry import FAMILIES, METRICS, metric_names, resolve_families
from railval.core.metrics.sync import DEFAULT_MAX_LAG_S, SyncResult, apply_lag, estimate_lag
from railval.core.types import SectionInfo, SignalSet

#: imported when first used (railval.core.lazy): a command that never reaches it does not load it
scipy_signal = lazy.module("scipy.signal")

#: deferred (railval.core.lazy): only the tables of :func:`compare_signalsets` and
#: :meth:`ComparisonResult.to_pandas` need pandas (≈ 0.7 s to import); the review plots'
#: Sprague–Geers values import this package and never reach them
pd = lazy.module("pandas")

DEFAULT_LOWPASS_HZ = 20.0


@dataclass(frozen=True)
class ComparisonResult:
    """Metrics of one simulated signal against one measured signal.

    ``raw``/``synced``: metric name → value (see ``railval.core.metrics.registry.METRICS``);
    ``sync``: the lag estimate (``sync.lag_s`` in s, positive = simulated delayed);
    ``fs``: common sampling rate in Hz; ``n``: samples of the raw comparison; ``n_synced``:
    samples of the synchronised overlap; ``resampled``/``grid_note``: what the common-grid
    helper did; ``unit``: unit of the signals (for the area metric).
    """

    raw: dict[str, Any]
    synced: dict[str, Any]
    sync: SyncResult
    fs: float
    n: int
    n_synced: int
    resampled: bool
    grid_note: str
    families: tuple[str, ...]
    unit: str = ""
    notes: tuple[str, ...] = field(default_factory=tuple)

    @property
    def lag_s(self) -> float:
        return self.sync.lag_s

    def to_dict(self) -> dict[str, Any]:
        return {
            "fs_hz": self.fs,
            "n_samples": self.n,
            "n_synced": self.n_synced,
            "lag_s": self.sync.lag_s,
            "lag_samples": self.sync.lag_samples,
            "sync_correlation": self.sync.correlation,
            "lag_at_bound": self.sync.at_bound,
            "lag_near_bound": self.sync.near_bound,
            "lag_reliable": self.sync.reliable,
            "max_lag_s": self.sync.max_lag_samples / self.fs,
            "resampled": self.resampled,
            "grid_note": self.grid_note,
            "unit": self.unit,
            "families": list(self.families),
            "raw": {k: _jsonable(v) for k, v in self.raw.items()},
            "synced": {k: _jsonable(v) for k, v in self.synced.items()},
            "notes": list(self.notes),
        }

    def to_pandas(self) -> pd.DataFrame:
        """One row per metric: label, unit, raw, synced (index: metric name)."""
        rows = []
        for name in self.raw:
            info = METRICS[name]
            unit = self.unit if info.unit == "signal" else info.unit
            rows.append({"metric": name, "label": info.label, "unit": unit,
                         "raw": self.raw[name], "synced": self.synced[name]})
        return pd.DataFrame(rows).set_index("metric")


def _jsonable(v: Any) -> Any:
    if isinstance(v, np.generic):
        v = v.item()
    if isinstance(v, float) and not np.isfinite(v):
        return None
    return v


def _evaluate(m: np.ndarray, c: np.ndarray, fs: float, families: tuple[str, ...],
              opts: dict[str, Any]) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for fam in families:
        out.update(FAMILIES[fam].compute(m, c, fs, opts))
    return out


def compare(measured: np.ndarray, simulated: np.ndarray, fs: float, *,
            fs_simulated: float | None = None, t0_measured: float = 0.0,
            t0_simulated: float = 0.0, max_lag_s: float = DEFAULT_MAX_LAG_S,
            subsample: bool = False, families: Iterable[str] | str | None = None,
            iso_params: ISOParameters | None = None, neff_method: str = "bartlett",
            unit: str = "") -> ComparisonResult:
    """Compare a simulated signal with a measured one; every metric raw and synchronised.

    Parameters
    ----------
    measured, simulated : 1-D signals in the same unit.
    fs : sampling rate of ``measured`` in Hz (and of ``simulated`` unless ``fs_simulated``).
    fs_simulated, t0_measured, t0_simulated : rate (Hz) and start times (s) when the records
        differ; the simulated signal is then put on the measured grid (``resampled`` says so).
    max_lag_s : synchronisation window ±max_lag_s in s (default 2 s).
    subsample : refine the lag below one sample (parabolic peak, linear interpolation).
    families : metric families to compute (``railval.core.metrics.registry.FAMILIES``; default all).
    iso_params : ISO/TS 18571 parameters (default: the standard's).
    neff_method : effective-sample-size estimator of the KS p-value (``"bartlett"``/``"ar1"``).
    unit : unit of the signals, carried into the result.

    Returns
    -------
    ComparisonResult
        Every metric of ``families`` raw and after synchronisation, with the lag found.
    """
    fams = resolve_families(families)
    grid = common_grid(measured, simulated, fs, fs_simulated, t0_measured=t0_measured,
                       t0_simulated=t0_simulated, min_len=16)
    m, c, f = grid.measured, grid.simulated, grid.fs
    opts = {"iso_params": iso_params, "neff_method": neff_method}
    sync = estimate_lag(m, c, f, max_lag_s=max_lag_s, subsample=subsample)
    ms, cs = apply_lag(m, c, sync.lag_samples)
    notes = [grid.note]
    if sync.near_bound:
        where = "on" if sync.at_bound else "near"
        notes.append(f"lag {sync.lag_s:+.3g} s lies {where} the search bound "
                     f"±{sync.max_lag_samples / f:g} s: unreliable, the true lag may be larger")
    raw = _evaluate(m, c, f, fams, opts)
    synced = _evaluate(ms, cs, f, fams, opts) if sync.lag_samples != 0 else dict(raw)
    return ComparisonResult(raw=raw, synced=synced, sync=sync, fs=f, n=len(grid),
                            n_synced=int(ms.shape[0]), resampled=grid.resampled,
                            grid_note=grid.note, families=fams, unit=unit, notes=tuple(notes))


def lowpass(data: np.ndarray, fs: float, cutoff_hz: float, order: int = 4) -> np.ndarray:
    """Zero-phase Butterworth low-pass of the rows of ``data`` (docs/design.md §3 processing).

    At the EN cut-off of 20 Hz the shared EN implementation ``railval.core.filters.filtfilt_rows``
    is used (identical processing to the EN quantities); other cut-offs use
    ``scipy.signal.butter`` + ``sosfiltfilt`` with the same order and zero phase.

    Parameters
    ----------
    data : numpy.ndarray
        Shape (n_signals, N) or (N,), any unit.
    fs, cutoff_hz : float
        Sampling rate and cut-off in Hz.
    order : int
        Butterworth prototype order.

    Returns
    -------
    numpy.ndarray
        Same shape and unit as ``data``.
    """
    if not np.isfinite(cutoff_hz) or not 0 < cutoff_hz < fs / 2:
        raise InvalidParameter(f"low-pass cut-off must lie in (0, fs/2 = {fs / 2:g}) Hz, got {cutoff_hz!r}")
    data = np.atleast_2d(np.asarray(data, dtype=np.float64))
    if cutoff_hz == filters.LOWPASS_HZ:
        return filters.filtfilt_rows(data, fs, "lowpass", order)
    sos = scipy_signal.butter(order, cutoff_hz, btype="lowpass", fs=fs, output="sos")
    return scipy_signal.sosfiltfilt(sos, data, axis=-1)


def compare_signalsets(measured: SignalSet, simulated: SignalSet, channels: Iterable[str] | None = None,
                       lowpass_hz: float | None = DEFAULT_LOWPASS_HZ, **options: Any) -> pd.DataFrame:
    """Compare every common channel of two signal sets of one section.

    Both records are low-passed (``lowpass_hz``, default 20 Hz as for Polach & Böttcher 2014's plots;
    ``None`` = no filter) at their own rate, then put on a common grid aligned by
    ``time_s[0]``. Returns one row per channel with ``channel``, ``n``, ``fs_hz``,
    ``lag_s``, ``sync_correlation``, ``lag_reliable`` (False when the lag lies at or within
    5 % of the ±max_lag bound), ``resampled``, ``error`` (message when the channel
    could not be compared, else empty) and each metric ``<name>`` (raw) and ``<name>_sync``.
    ``options`` go to :func:`compare`.

    Parameters
    ----------
    measured, simulated : SignalSet
        The section's measured and simulated records (own sampling rates allowed).
    channels : iterable of str or None
        Channels to compare; ``None`` = all common channels.
    lowpass_hz : float or None
        Low-pass cut-off in Hz.
    **options
        Keyword arguments of :func:`compare`.

    Returns
    -------
    pandas.DataFrame
        One row per channel, columns as above.
    """
    if channels is None:
        names = [ch for ch in measured.channels if ch in simulated.channels]
    else:
        names = list(channels)
        for ch in names:
            for label, ss in (("measured", measured), ("simulated", simulated)):
                if ch not in ss.channels:
                    raise NotFound(f"channel {ch!r} not in the {label} signal set "
                                   f"(has {sorted(ss.channels)})")
    fams = resolve_families(options.get("families"))
    metric_cols = metric_names(fams)
    columns = ["channel", "n", "fs_hz", "lag_s", "sync_correlation", "lag_reliable", "resampled",
               "error"]
    columns += [c for name in metric_cols for c in (name, f"{name}_sync")]
    if not names:
        return pd.DataFrame(columns=columns)

    def stack(ss: SignalSet) -> np.ndarray:
        data = np.vstack([np.asarray(ss.channels[ch], dtype=np.float64) for ch in names])
        return data if lowpass_hz is None else lowpass(data, ss.fs, lowpass_hz)

    mdata, cdata = stack(measured), stack(simulated)
    t0m = float(measured.time_s[0]) if len(measured) else 0.0
    t0c = float(simulated.time_s[0]) if len(simulated) else 0.0
    rows = []
    for i, ch in enumerate(names):
        row: dict[str, Any] = {"channel": ch, "error": ""}
        try:
            res = compare(mdata[i], cdata[i], measured.fs, fs_simulated=simulated.fs,
                          t0_measured=t0m, t0_simulated=t0c, **options)
        except InvalidSignal as exc:
            row.update({"n": len(measured), "fs_hz": measured.fs, "lag_s": np.nan,
                        "sync_correlation": np.nan, "lag_reliable": False, "resampled": False,
                        "error": str(exc)})
            row.update({c: np.nan for c in columns if c not in row})
        else:
            row.update({"n": res.n, "fs_hz": res.fs, "lag_s": res.sync.lag_s,
                        "sync_correlation": res.sync.correlation,
                        "lag_reliable": res.sync.reliable, "resampled": res.resampled})
            for name in metric_cols:
                row[name] = res.raw[name]
                row[f"{name}_sync"] = res.synced[name]
        rows.append(row)
    return pd.DataFrame(rows, columns=columns)


def cut_evaluated(ss: SignalSet, info: SectionInfo, lowpass_hz: float | None) -> SignalSet:
    """The evaluated (constant-curvature) range of a section's signals on their own distance
    axis, after filtering the whole section (:func:`lowpass` at ``lowpass_hz``, none when
    None) so the cut carries no filter transient; time restarts at 0. Raises
    :class:`NotFound` when the range holds fewer than 16 samples."""
    names = list(ss.channels)
    data = np.vstack([np.asarray(ss.channels[c], dtype=np.float64) for c in names]) if names else None
    if data is not None and lowpass_hz is not None:
        data = lowpass(data, ss.fs, lowpass_hz)
    keep = (ss.distance_m >= info.eval_start_m) & (ss.distance_m <= info.eval_end_m)
    idx = np.flatnonzero(keep)
    if idx.size < 16:
        raise NotFound(f"section {info.id}: evaluated range {info.eval_start_m:g}–{info.eval_end_m:g} m "
                       f"holds {idx.size} samples, need at least 16")
    lo, hi = int(idx[0]), int(idx[-1]) + 1
    chans = {c: data[i, lo:hi] for i, c in enumerate(names)} if data is not None else {}
    return SignalSet(fs=ss.fs, time_s=ss.time_s[lo:hi] - ss.time_s[lo], distance_m=ss.distance_m[lo:hi],
                     channels=chans, hashes=dict(ss.hashes))
