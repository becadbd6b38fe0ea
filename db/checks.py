"""Shared checks of one recording (time axis, distance axis, channel arrays).

Used by the importer (errors become :class:`railval.core.errors.CampaignFormatError` naming the
file) and by :func:`railval.db.repo.store_configuration` (errors become
:class:`railval.core.errors.InvalidSignal`). Both paths therefore accept and reject the same data.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping

import numpy as np

#: tolerated deviation of a time stamp from the uniform grid t0 + i/fs, as a fraction of
#: the sampling period (a logger with 1 % jitter is still "equally spaced")
TIME_JITTER_FRACTION = 0.01


class RecordingProblem(Exception):
    """A check failed; ``field`` names the column or key, the message says bound and value."""

    def __init__(self, field: str, message: str):
        self.field = field
        super().__init__(message)


def estimate_fs(time_s: np.ndarray) -> float:
    """Sampling rate in Hz from an equally spaced time axis: (n − 1)/(t[-1] − t[0]).

    Rounded to 1 µHz so that a time axis rebuilt as ``t0 + i/fs`` and read back gives the
    same ``fs`` (export → import reproduces the record exactly).
    """
    span = float(time_s[-1] - time_s[0])
    return float(np.round((time_s.shape[0] - 1) / span, 6))


def check_recording(
    time_s: np.ndarray,
    distance_m: np.ndarray,
    channels: Mapping[str, np.ndarray],
    known_channels: Iterable[str],
) -> float:
    """Check one (section, source) table and return its sampling rate ``fs`` in Hz.

    Rules: every array 1-D, numeric and of the same length ≥ 2; no NaN/inf; ``time_s``
    strictly increasing and equally spaced within :data:`TIME_JITTER_FRACTION` of a period;
    ``distance_m`` strictly increasing; channel names among ``known_channels``; at least
    one channel.
    """
    known = set(known_channels)
    if not channels:
        raise RecordingProblem("channels", "no channel column (need at least one of "
                               f"{sorted(known)[:6]}...)")
    unknown = sorted(set(channels) - known)
    if unknown:
        raise RecordingProblem(unknown[0], f"unknown channel column {unknown[0]!r}; the "
                               f"campaign declares {sorted(known)}")
    columns = {"time_s": time_s, "distance_m": distance_m, **channels}
    n = None
    for name, values in columns.items():
        a = np.asarray(values)
        if a.ndim != 1:
            raise RecordingProblem(name, f"column {name!r} has shape {a.shape}, expected 1-D")
        if a.dtype.kind not in "fiu":
            raise RecordingProblem(name, f"column {name!r} has dtype {a.dtype}, expected numbers")
        if a.shape[0] == 0:
            raise RecordingProblem(name, f"column {name!r} is empty")
        if n is None:
            n = a.shape[0]
        elif a.shape[0] != n:
            raise RecordingProblem(name, f"column {name!r} has {a.shape[0]} samples, "
                                   f"time_s has {n}")
        if a.dtype.kind == "f":
            finite = np.isfinite(a)
            if not finite.all():
                i = int(np.flatnonzero(~finite)[0])
                raise RecordingProblem(name, f"column {name!r} holds {a[i]} at sample {i}; "
                                       "values must be finite")
    assert n is not None
    if n < 2:
        raise RecordingProblem("time_s", f"table has {n} sample, at least 2 are needed")
    t = np.asarray(time_s, dtype=np.float64)
    dt = np.diff(t)
    if not (dt > 0).all():
        i = int(np.flatnonzero(dt <= 0)[0])
        raise RecordingProblem("time_s", f"time_s is not strictly increasing at sample {i + 1} "
                               f"({t[i]} then {t[i + 1]})")
    d = np.asarray(distance_m, dtype=np.float64)
    dd = np.diff(d)
    if not (dd > 0).all():
        i = int(np.flatnonzero(dd <= 0)[0])
        raise RecordingProblem("distance_m", "distance_m is not strictly increasing at sample "
                               f"{i + 1} ({d[i]} then {d[i + 1]})")
    fs = estimate_fs(t)
    grid = t[0] + np.arange(n) / fs
    dev = np.abs(t - grid)
    worst = int(np.argmax(dev))
    if dev[worst] > TIME_JITTER_FRACTION / fs:
        raise RecordingProblem(
            "time_s",
            f"time_s is not equally spaced: sample {worst} is {dev[worst]:.3g} s off the "
            f"{fs:g} Hz grid (bound {TIME_JITTER_FRACTION / fs:.3g} s = "
            f"{TIME_JITTER_FRACTION:.0%} of a period)",
        )
    return fs
